//! Benchmarks of the features stage on a 512×512 quantised scene of planes with no-data holes.

fn main() {
    divan::main();
}

#[divan::bench(args = [128, 512])]
fn compute(b: divan::Bencher, side: u32) {
    let img = rangeimage::testing::bench_scene(side);
    let p = features::Params::default();
    b.bench(|| features::compute(divan::black_box(&img), &p));
}

/// `compute_into` with the output grids of the previous frame reused (a stream of frames of one size).
#[divan::bench(args = [512])]
fn compute_into(b: divan::Bencher, side: u32) {
    let img = rangeimage::testing::bench_scene(side);
    let p = features::Params::default();
    let mut out = features::compute(&img, &p);
    b.bench_local(|| features::compute_into(divan::black_box(&img), &p, &mut out));
}

#[divan::bench(args = [512])]
fn fit_planes(b: divan::Bencher, side: u32) {
    let img = rangeimage::testing::bench_scene(side);
    b.bench(|| features::fit_planes(divan::black_box(&img), 5));
}

/// The quadratic fit's derivatives alone (`features::derivatives`, not part of `compute`'s output).
#[divan::bench(args = [512])]
fn derivatives(b: divan::Bencher, side: u32) {
    let img = rangeimage::testing::bench_scene(side);
    let p = features::Params::default();
    b.bench(|| features::derivatives(divan::black_box(&img), &p));
}
