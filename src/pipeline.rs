//! The whole method on one in-memory range image: features → regions (C1) and Canny (C2) → relaxation → labels.

use crate::config::{C1Strength, Config, FinalEdges};
use rangeimage::{Camera, EdgeMap, Grid, LabelImage, RangeImage, Region, SurfaceFeatures};
use serde::Serialize;
use std::path::Path;
use std::time::Instant;

/// Wall-clock time spent in each stage, in milliseconds.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize)]
pub struct StageTimings {
    /// Local planes, derivatives and curvatures.
    pub features: f64,
    /// Region growing and C1.
    pub regiongrow: f64,
    /// Canny on plane parameters (C2).
    pub vcanny: f64,
    /// Pruning, annealing and the final segmentation.
    pub relax: f64,
}

/// Everything the pipeline computed for one image.
#[derive(Debug, Clone)]
pub struct Output {
    /// Per-pixel geometry.
    pub features: SurfaceFeatures,
    /// Region-growing segmentation and its borders C1.
    pub regions: regiongrow::Segmentation,
    /// Region-growing diagnostics.
    pub regions_info: regiongrow::Info,
    /// Canny edges C2 and the gradient magnitude.
    pub canny: vcanny::Edges,
    /// Relaxation and final segmentation.
    pub fin: Finish,
    /// Time per stage.
    pub timings: StageTimings,
}

/// What the last stage produces: relaxed edges and the final segmentation.
#[derive(Debug, Clone)]
pub struct Finish {
    /// C1 and C2 after relaxation, and their union with C2 restricted by the support test.
    pub relaxed: relax::Relaxed,
    /// Relaxation diagnostics (energies, acceptance).
    pub relax_info: relax::Info,
    /// The final segmentation (0 = none, regions 1..).
    pub labels: LabelImage,
    /// Geometry of each final region.
    pub final_regions: Vec<Region>,
    /// The final edge map C (`pipeline.final_edges`: the final segmentation's borders, or `relaxed.edges`).
    pub edges: EdgeMap,
}

impl Finish {
    /// The final edge map C.
    pub fn edges(&self) -> &EdgeMap {
        &self.edges
    }
}

fn elapsed_ms(t: Instant) -> f64 {
    t.elapsed().as_secs_f64() * 1e3
}

/// Panics with the configuration error if `config` is invalid: the facade's entry points check the
/// parameters once here, the stages only in debug builds.
fn check(config: &Config, entry: &str) {
    if let Err(e) = config.validate(Path::new("configuration")) {
        panic!("rangeseg::{entry}: {e}");
    }
}

/// Runs the whole method on one range image.
///
/// # Panics
/// If `config` is invalid ([`Config::validate`]; [`Config::load`] returns only valid ones).
pub fn segment(range: &RangeImage, camera: &Camera, config: &Config) -> Output {
    let _s = tracing::info_span!("segment", w = range.width(), h = range.height()).entered();
    check(config, "segment");
    let t = Instant::now();
    let features = features::compute(range, &config.features);
    let t_features = elapsed_ms(t);

    let t = Instant::now();
    let (regions, regions_info) = regiongrow::grow(range, &features, camera, &config.regiongrow, config.seed);
    let t_regions = elapsed_ms(t);

    let t = Instant::now();
    let valid = rangeimage::valid_mask(range);
    let canny = vcanny::detect_planes(&features.plane, &valid, &config.vcanny);
    let t_canny = elapsed_ms(t);

    let t = Instant::now();
    let fin = finish(range, camera, config, &features, &regions, &canny);
    let t_relax = elapsed_ms(t);

    let timings =
        StageTimings { features: t_features, regiongrow: t_regions, vcanny: t_canny, relax: t_relax };
    Output { features, regions, regions_info, canny, fin, timings }
}

/// The last stage: relaxes C1 (from `regions`) and C2 (from `canny`), then derives the final segmentation.
///
/// # Panics
/// If `config` is invalid ([`Config::validate`]).
pub fn finish(
    range: &RangeImage,
    camera: &Camera,
    config: &Config,
    features: &SurfaceFeatures,
    regions: &regiongrow::Segmentation,
    canny: &vcanny::Edges,
) -> Finish {
    check(config, "finish");
    let valid = rangeimage::valid_mask(range);
    let s1 = c1_strength(features, config.pipeline.c1_strength);
    let (relaxed, relax_info) = if config.pipeline.relax {
        let input = relax::Input {
            c1: &regions.c1,
            s1: &s1,
            c2: &canny.edges,
            magnitude: &canny.magnitude,
            valid: &valid,
        };
        relax::relax(&input, &config.relax, config.seed)
    } else {
        let edges = relax::union(&regions.c1, &canny.edges);
        let relaxed = relax::Relaxed { c1: regions.c1.clone(), c2: canny.edges.clone(), edges };
        (relaxed, relax::Info::default())
    };
    // The segmentation sees both relaxed sets in full (before the support test): a border between
    // two faces that region growing merged has only C2 to show it.
    let (labels, final_regions) =
        finalseg::segment(range, camera, &relaxed.union(), Some(&regions.labels), &config.segment);
    let edges = match config.pipeline.final_edges {
        FinalEdges::Relaxed => relaxed.edges.clone(),
        // The boundary rule eval scores segmentations by: region pixels next to another region, and
        // unlabelled pixels between two regions; a region's edge against unlabelled pixels is no border.
        FinalEdges::Segmentation => rangeimage::boundary::label_boundaries(&labels, |l| l != 0),
    };
    Finish { relaxed, relax_info, labels, final_regions, edges }
}

/// The C1 strength map s1 for the relaxation energy; 0 where undefined.
pub fn c1_strength(features: &SurfaceFeatures, which: C1Strength) -> Grid<f32> {
    let src = match which {
        C1Strength::AbsK => features.k.map(|k| k.abs()),
        C1Strength::Curvedness => features.curvedness.clone(),
    };
    src.map(|v| if v.is_finite() { *v } else { 0.0 })
}
