//! Benchmarks of relax on a 512×512 scene of rectangle borders (C1) and a shifted, noisy copy (C2).

use rand::{RngExt, SeedableRng};
use rangeimage::{EdgeMap, Grid};

fn main() {
    divan::main();
}

struct Case {
    c1: EdgeMap,
    s1: Grid<f32>,
    c2: EdgeMap,
    mag: Grid<f32>,
    valid: Grid<bool>,
}

/// 8×8 rectangles of ~56 px: two-pixel-thick borders as C1, one-pixel Canny-like lines offset by
/// one pixel with 10% dropouts and 1% clutter as C2.
fn case(side: u32) -> Case {
    let mut rng = rand::rngs::Xoshiro256PlusPlus::seed_from_u64(1);
    let cell = side / 8;
    let on_border = |v: u32, lo: u32| v % cell == lo || v % cell == lo + 1;
    let c1 = Grid::from_fn(side, side, |x, y| on_border(x, 0) || on_border(y, 0));
    let c2 = Grid::from_fn(side, side, |x, y| {
        let line = x % cell == 2 || y % cell == 2;
        (line && rng.random_bool(0.9)) || rng.random_bool(0.01)
    });
    let s1 = Grid::from_fn(side, side, |x, y| if on_border(x, 0) || on_border(y, 0) { 0.5 } else { 0.05 });
    let mag = Grid::from_fn(side, side, |x, y| {
        let dx = (x % cell).abs_diff(1).min((x % cell).abs_diff(cell + 1));
        let dy = (y % cell).abs_diff(1).min((y % cell).abs_diff(cell + 1));
        10.0 / (1.0 + dx.min(dy) as f32)
    });
    Case { c1, s1, c2, mag, valid: Grid::new(side, side, true) }
}

#[divan::bench(args = [128, 512])]
fn relax(b: divan::Bencher, side: u32) {
    let c = case(side);
    let params = relax::Params::default();
    let input = relax::Input { c1: &c.c1, s1: &c.s1, c2: &c.c2, magnitude: &c.mag, valid: &c.valid };
    b.bench(|| relax::relax(&input, &params, 0));
}
