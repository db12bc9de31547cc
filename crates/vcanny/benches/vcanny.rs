//! Benchmarks of the vectorial Canny detector on a 512×512 quantised scene of planes with no-data holes.

use rangeimage::{Grid, PlaneMap, RangeImage};

fn main() {
    divan::main();
}

/// Plane parameters of the scene: the analytic planes plus quantisation-like wobble (bench setup only).
fn planes(range: &RangeImage) -> PlaneMap {
    let (w, h) = range.dimensions();
    Grid::from_fn(w, h, |x, y| {
        let z = range[(x, y)];
        if !z.is_finite() {
            return [f32::NAN; 3];
        }
        let wob = ((x * 7 + y * 13) % 11) as f32 / 11.0 - 0.5;
        let (a, b) = if x > 100 && x < 300 { (if x < 200 { -0.3 } else { 0.3 }, -0.1) } else { (0.05, -0.2) };
        [a + 0.02 * wob, b - 0.02 * wob, z - a * (x as f32 - 255.5) - b * (y as f32 - 255.5)]
    })
}

#[divan::bench(args = [512])]
fn detect_planes(b: divan::Bencher, side: u32) {
    let img = rangeimage::testing::bench_scene(side);
    let pl = planes(&img);
    let valid = img.map(|v| v.is_finite());
    let p = vcanny::Params::default();
    b.bench(|| vcanny::detect_planes(divan::black_box(&pl), &valid, &p));
}

#[divan::bench(args = [512])]
fn detect_raw(b: divan::Bencher, side: u32) {
    let img = rangeimage::testing::bench_scene(side);
    let p = vcanny::Params::default();
    b.bench(|| vcanny::detect_raw(divan::black_box(&img), &p));
}
