//! Benchmarks of the vectorial Canny detector on a 512×512 quantised scene of planes with no-data holes.

use rangeimage::{Grid, PlaneMap, RangeImage};

fn main() {
    divan::main();
}

/// A 512×512 8-bit-like scene: a tilted floor, a roof-shaped box and a slanted box, plus a shadow of no data.
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
    let img = scene(side);
    let pl = planes(&img);
    let valid = img.map(|v| v.is_finite());
    let p = vcanny::Params::default();
    b.bench(|| vcanny::detect_planes(divan::black_box(&pl), &valid, &p));
}

#[divan::bench(args = [512])]
fn detect_raw(b: divan::Bencher, side: u32) {
    let img = scene(side);
    let p = vcanny::Params::default();
    b.bench(|| vcanny::detect_raw(divan::black_box(&img), &p));
}
