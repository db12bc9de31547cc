//! Benchmarks of the boundary and Hoover metrics on a 512×512 Voronoi scene.

use rangeimage::{EdgeMap, Grid, LabelImage};

fn main() {
    divan::main();
}

/// Deterministic pseudo-random numbers (splitmix64), so the bench needs no RNG crate.
fn splitmix(state: &mut u64) -> u64 {
    *state = state.wrapping_add(0x9E37_79B9_7F4A_7C15);
    let mut z = *state;
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// Voronoi labels (from 10) of `n` random sites, with each site jittered by up to `jitter` px.
fn voronoi(side: u32, n: usize, jitter: i64, seed: u64) -> LabelImage {
    let mut s = 7;
    let mut j = seed;
    let sites: Vec<(i64, i64)> = (0..n)
        .map(|_| {
            let x = (splitmix(&mut s) % u64::from(side)) as i64;
            let y = (splitmix(&mut s) % u64::from(side)) as i64;
            let dx = (splitmix(&mut j) % (2 * jitter as u64 + 1)) as i64 - jitter;
            let dy = (splitmix(&mut j) % (2 * jitter as u64 + 1)) as i64 - jitter;
            (x + dx, y + dy)
        })
        .collect();
    Grid::from_fn(side, side, |x, y| {
        let (x, y) = (i64::from(x), i64::from(y));
        let best = (0..n).min_by_key(|&i| (sites[i].0 - x).pow(2) + (sites[i].1 - y).pow(2)).unwrap_or(0);
        10 + best as u32
    })
}

struct Case {
    gt: LabelImage,
    seg: LabelImage,
    edges: EdgeMap,
}

fn case(side: u32) -> Case {
    let gt = voronoi(side, 100, 0, 1);
    let seg = voronoi(side, 100, 3, 2);
    let edges = eval::boundary::gt_boundaries(&seg);
    Case { gt, seg, edges }
}

/// Throughput is counted in detected + GT boundary pixels (≈ 20k of each at 512×512).
#[divan::bench(args = [512])]
fn boundary_matched(b: divan::Bencher, side: u32) {
    let c = case(side);
    let n = c.edges.as_slice().iter().filter(|&&e| e).count()
        + eval::boundary::gt_boundaries(&c.gt).as_slice().iter().filter(|&&e| e).count();
    b.counter(divan::counter::ItemsCount::new(n))
        .bench(|| eval::boundary::matched(divan::black_box(&c.edges), &c.gt, 2.0));
}

#[divan::bench(args = [512])]
fn boundary_simple(b: divan::Bencher, side: u32) {
    let c = case(side);
    b.bench(|| eval::boundary::simple(divan::black_box(&c.edges), &c.gt, 2.0));
}

#[divan::bench(args = [512])]
fn hoover_compare(b: divan::Bencher, side: u32) {
    let c = case(side);
    b.bench(|| eval::hoover::compare(divan::black_box(&c.gt), &c.seg, 0.8, None, None));
}

#[divan::bench(args = [512])]
fn edt(b: divan::Bencher, side: u32) {
    let c = case(side);
    b.bench(|| eval::distance::edt(divan::black_box(&c.edges)));
}
