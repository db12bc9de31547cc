//! Benchmarks of `regiongrow::grow` on an ABW-like synthetic scene with precomputed features.

#[path = "../src/testutil.rs"]
mod testutil;

use rangeimage::Camera;

fn main() {
    divan::main();
}

/// Growth, merge, fill and C1 of one `side × side` image; features are computed outside the loop.
#[divan::bench(args = [128, 512])]
fn grow_default(b: divan::Bencher, side: u32) {
    let s = testutil::abw_like_scene(side);
    let params = regiongrow::Params::default();
    b.bench(|| regiongrow::grow(&s.range, &s.features, &Camera::ABW0, &params, 0));
}

/// The same with the paper's Gaussian-curvature criterion.
#[divan::bench(args = [512])]
fn grow_paper(b: divan::Bencher, side: u32) {
    let s = testutil::abw_like_scene(side);
    let params = regiongrow::Params::paper();
    b.bench(|| regiongrow::grow(&s.range, &s.features, &Camera::ABW0, &params, 0));
}
