//! Benchmarks of the features stage on a 512×512 quantised scene of planes with no-data holes.

use rangeimage::{Grid, RangeImage};

fn main() {
    divan::main();
}

/// A 512×512 8-bit-like scene: a tilted floor, two boxes (roof creases and jumps) and a shadow of no data.
fn scene(side: u32) -> RangeImage {
    let s = f64::from(side) / 512.0;
    Grid::from_fn(side, side, |x, y| {
        let (xf, yf) = (f64::from(x) / s, f64::from(y) / s);
        if (300.0..330.0).contains(&xf) && (100.0..400.0).contains(&yf) {
            return f32::NAN;
        }
        let z = if (100.0..300.0).contains(&xf) && (100.0..400.0).contains(&yf) {
            120.0 + 0.3 * (xf - 200.0).abs() - 0.1 * yf
        } else if (350.0..480.0).contains(&xf) && (50.0..200.0).contains(&yf) {
            90.0 + 0.2 * xf - 0.15 * yf
        } else {
            200.0 - 0.2 * yf + 0.05 * xf
        };
        z.round() as f32
    })
}

#[divan::bench(args = [128, 512])]
fn compute(b: divan::Bencher, side: u32) {
    let img = scene(side);
    let p = features::Params::default();
    b.bench(|| features::compute(divan::black_box(&img), &p));
}

/// `compute_into` with the output grids of the previous frame reused (a stream of frames of one size).
#[divan::bench(args = [512])]
fn compute_into(b: divan::Bencher, side: u32) {
    let img = scene(side);
    let p = features::Params::default();
    let mut out = features::compute(&img, &p);
    b.bench_local(|| features::compute_into(divan::black_box(&img), &p, &mut out));
}

#[divan::bench(args = [512])]
fn fit_planes(b: divan::Bencher, side: u32) {
    let img = scene(side);
    b.bench(|| features::fit_planes(divan::black_box(&img), 5));
}

/// The quadratic fit's derivatives alone (`features::derivatives`, not part of `compute`'s output).
#[divan::bench(args = [512])]
fn derivatives(b: divan::Bencher, side: u32) {
    let img = scene(side);
    let p = features::Params::default();
    b.bench(|| features::derivatives(divan::black_box(&img), &p));
}
