//! Proptest strategies for images, shared by the stages' property tests.

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
