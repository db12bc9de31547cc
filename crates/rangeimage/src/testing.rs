//! Proptest strategies for images, shared by the stages' property tests, and the benches' scene.

use crate::{Grid, LabelImage, RangeImage};
use proptest::prelude::*;

/// A range image of width and height drawn from the ranges, with about 10% NaN pixels.
pub fn arbitrary_range_image(
    width: std::ops::Range<u32>,
    height: std::ops::Range<u32>,
) -> impl Strategy<Value = RangeImage> {
    (width, height).prop_flat_map(|(w, h)| {
        proptest::collection::vec(prop_oneof![9 => 0.0f32..255.0, 1 => Just(f32::NAN)], (w * h) as usize)
            .prop_map(move |data| Grid::from_vec(w, h, data).expect("length matches"))
    })
}

/// A label image with labels in `0..max_label`.
pub fn arbitrary_label_image(
    width: std::ops::Range<u32>,
    height: std::ops::Range<u32>,
    max_label: u32,
) -> impl Strategy<Value = LabelImage> {
    (width, height).prop_flat_map(move |(w, h)| {
        proptest::collection::vec(0..max_label, (w * h) as usize)
            .prop_map(move |data| Grid::from_vec(w, h, data).expect("length matches"))
    })
}

/// The stages' benchmark scene, `side`×`side` (512 is the reference size), 8-bit-like (whole numbers): a
/// tilted floor, a roof-shaped box (creases and jumps), a slanted box and a shadow of no data.
#[must_use]
pub fn bench_scene(side: u32) -> RangeImage {
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
