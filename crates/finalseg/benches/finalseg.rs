//! Benchmarks of the final segmentation on a 512×512 scene of 8×8 planar cells (one range step per
//! cell) with Canny-like edge lines.

use rand::{RngExt, SeedableRng};
use rangeimage::{Camera, EdgeMap, Grid, RangeImage};

fn main() {
    divan::main();
}

/// The range image (a constant per cell), two-pixel-thick cell borders as C1, and one-pixel
/// lines offset by one pixel with 10% dropouts and 1% clutter as C2.
fn case(side: u32) -> (RangeImage, EdgeMap, EdgeMap) {
    let mut rng = rand::rngs::Xoshiro256PlusPlus::seed_from_u64(1);
    let cell = side / 8;
    let range = Grid::from_fn(side, side, |x, y| 100.0 + ((x / cell) * 3 + (y / cell)) as f32);
    let c1 = Grid::from_fn(side, side, |x, y| x % cell < 2 || y % cell < 2);
    let c2 = Grid::from_fn(side, side, |x, y| {
        let line = x % cell == 2 || y % cell == 2;
        (line && rng.random_bool(0.9)) || rng.random_bool(0.01)
    });
    (range, c1, c2)
}

/// `regions` mode as the pipeline runs it: region-growing labels (here the 8×8 cells) as guide.
#[divan::bench(args = [512])]
fn regions_mode(b: divan::Bencher, side: u32) {
    let (range, _, c2) = case(side);
    let cell = side / 8;
    let guide = Grid::from_fn(side, side, |x, y| 1 + (x / cell) + 8 * (y / cell));
    let params = finalseg::Params::default();
    b.bench(|| finalseg::segment(&range, &Camera::ABW0, &c2, Some(&guide), &params));
}

/// Without region-growing labels (`regions` mode falls back to plain components).
#[divan::bench(args = [512])]
fn components_mode(b: divan::Bencher, side: u32) {
    let (range, c1, _) = case(side);
    let params = finalseg::Params::default();
    b.bench(|| finalseg::segment(&range, &Camera::ABW0, &c1, None, &params));
}
