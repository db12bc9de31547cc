//! Integration tests of the rangeseg workspace: configuration, the whole pipeline, and the CLI end to end.

mod cli;
mod config;
mod pipeline;

/// Training image `index` of the synthetic benchmark, generated in memory (tests never use the test split).
pub(crate) fn small_scene(index: u32) -> scenegen::Scene {
    let (params, seed) = scenegen::benchmark_image(false, index);
    scenegen::generate(&params, seed)
}

/// The scene's range as a RangeImage (0 = no data → NaN), as rangeio reads it.
pub(crate) fn range_of(scene: &scenegen::Scene) -> rangeimage::RangeImage {
    scene.range.map(|&v| if v == 0 { f32::NAN } else { f32::from(v) })
}
