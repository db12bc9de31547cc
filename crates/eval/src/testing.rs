//! Test helpers: ABW-convention label strategies and injective relabelling.

use proptest::prelude::*;
use rangeimage::{Grid, LabelImage};
use std::collections::BTreeMap;

/// A label image in the ABW convention: labels 0..=3 (unlabelled) and `10..10 + n_regions`.
pub(crate) fn abw_labels(
    width: std::ops::Range<u32>,
    height: std::ops::Range<u32>,
    n_regions: u32,
) -> impl Strategy<Value = LabelImage> {
    rangeimage::testing::arbitrary_label_image(width, height, 4 + n_regions)
        .prop_map(|g| g.map(|&l| if l < 4 { l } else { l - 4 + 10 }))
}

/// Relabels the regions of `labels` (as told by `is_region`) injectively and in shuffled order
/// to labels `≥ base`, leaving the other pixels unchanged; returns the image and the map.
pub(crate) fn relabel(
    labels: &LabelImage,
    seed: u64,
    is_region: impl Fn(u32) -> bool,
    base: u32,
) -> (LabelImage, BTreeMap<u32, u32>) {
    let mut distinct: Vec<u32> = labels.as_slice().iter().copied().filter(|&l| is_region(l)).collect();
    distinct.sort_unstable();
    distinct.dedup();
    // Fisher–Yates with a splitmix64 stream.
    let mut state = seed;
    let mut next = move || {
        state = state.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = state;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    };
    let mut slots: Vec<u32> = (0..distinct.len() as u32).collect();
    for i in (1..slots.len()).rev() {
        let j = (next() % (i as u64 + 1)) as usize;
        slots.swap(i, j);
    }
    let gap = 1 + (seed % 3) as u32;
    let map: BTreeMap<u32, u32> = distinct.iter().zip(&slots).map(|(&l, &s)| (l, base + s * gap)).collect();
    let out = Grid::from_fn(labels.width(), labels.height(), |x, y| {
        let l = labels[(x, y)];
        map.get(&l).copied().unwrap_or(l)
    });
    (out, map)
}
