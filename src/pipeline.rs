//! The whole method on one in-memory range image: features → regions (C1) and Canny (C2) → relaxation → labels;
//! [`Segmenter`] runs it on a stream of frames with the working buffers of the previous frame.

use crate::config::{C1Strength, Config, FinalEdges};
use crate::units::WorkingUnits;
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
#[derive(Debug, Clone, Default)]
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
    /// The image's working units ([`crate::units`]): `features`, the regions' plane offsets and RMS and the
    /// final regions' planes are in units of depth × `units.factor`, seen through `units.camera`; the regions' normals
    /// are those of the input's geometry (a grid image's scale changes its slopes, so its normals are those of the
    /// scaled depth).
    pub units: Option<WorkingUnits>,
    /// The step of the depth if it was a staircase, dequantised before the stages ran ([`crate::dequantise`]);
    /// `features` and the regions' planes then describe the dequantised depth (`rangeseg::planes` fits the input
    /// as given).
    pub dequantised: Option<f64>,
}

/// What the last stage produces: relaxed edges and the final segmentation.
#[derive(Debug, Clone, Default)]
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

/// Runs the whole method on one range image (a [`Segmenter`] used once).
///
/// # Panics
/// If `config` is invalid ([`Config::validate`]; [`Config::load`] returns only valid ones).
pub fn segment(range: &RangeImage, camera: &Camera, config: &Config) -> Output {
    let mut s = Segmenter::new(config.clone());
    s.segment(range, camera);
    s.into_output()
}

/// The whole method on a stream of frames: owns the output of the last frame and every working buffer of the
/// stages, and overwrites them for the next frame, so frames of one size allocate no image-sized memory after
/// the first (they also skip the page faults of fresh memory). The results are bit-identical to [`segment`].
#[derive(Debug, Default)]
pub struct Segmenter {
    config: Config,
    out: Output,
    scratch: Scratch,
}

/// The working buffers of every stage, and the pipeline's own per-pixel maps.
#[derive(Debug, Default)]
struct Scratch {
    /// The frame in working units, when they are not its own.
    work: RangeImage,
    /// The dequantisation's buffers (the frame dequantised when it is a staircase).
    dequantise: crate::dequantise::Scratch,
    /// The noise estimate's window RMS values.
    noise: Vec<f64>,
    valid: Grid<bool>,
    s1: Grid<f32>,
    union: EdgeMap,
    regiongrow: regiongrow::Scratch,
    vcanny: vcanny::Scratch,
    relax: relax::Scratch,
    finalseg: finalseg::Scratch,
    /// The labels the final edge map is drawn from ([`finalseg::edge_labels_into`]), and its working list.
    gaps: (LabelImage, Vec<u32>),
}

impl Segmenter {
    /// A segmenter running `config`; it allocates its buffers on the first frame.
    ///
    /// # Panics
    /// If `config` is invalid ([`Config::validate`]; [`Config::load`] returns only valid ones).
    pub fn new(config: Config) -> Self {
        check(&config, "Segmenter::new");
        Self { config, ..Self::default() }
    }

    /// The configuration it runs.
    pub fn config(&self) -> &Config {
        &self.config
    }

    /// Segments one frame; the result lives until the next call (see [`Segmenter::into_output`]).
    pub fn segment(&mut self, range: &RangeImage, camera: &Camera) -> &Output {
        let _s = tracing::info_span!("segment", w = range.width(), h = range.height()).entered();
        let Self { config, out, scratch } = self;
        let t = Instant::now();
        // A staircase (depth rounded to steps above its noise) runs dequantised, in working units of its own;
        // other images reuse the σ the test read.
        let prepared =
            crate::dequantise::for_config(range, camera, config, &mut scratch.noise, &mut scratch.dequantise);
        let floor = prepared.sigma_floor();
        let (step, dequantised) = prepared.dequantised.unzip();
        let range = dequantised.as_ref().unwrap_or(range);
        let units =
            crate::units::for_config_given(range, camera, config, prepared.sigma, floor, &mut scratch.noise);
        let mut work = std::mem::take(&mut scratch.work);
        let range = if units.is_identity() {
            range
        } else {
            units.scale_into(range, &mut work);
            &work
        };
        let camera = &units.camera;
        features::compute_into(range, &config.features, &mut out.features);
        let t_features = elapsed_ms(t);

        let t = Instant::now();
        out.regions_info = regiongrow::grow_into(
            range,
            &out.features,
            camera,
            &config.regiongrow,
            config.seed,
            &mut scratch.regiongrow,
            &mut out.regions,
        );
        let t_regions = elapsed_ms(t);

        let t = Instant::now();
        scratch.valid.map_from(range, |v| v.is_finite());
        vcanny::detect_planes_into(
            &out.features.plane,
            &scratch.valid,
            &config.vcanny,
            &mut scratch.vcanny,
            &mut out.canny,
        );
        let t_canny = elapsed_ms(t);

        let t = Instant::now();
        finish_into(range, camera, config, (&out.features, &out.regions, &out.canny), scratch, &mut out.fin);
        let t_relax = elapsed_ms(t);

        out.timings =
            StageTimings { features: t_features, regiongrow: t_regions, vcanny: t_canny, relax: t_relax };
        // The regions' normals in the input's geometry (a stretched image's working normals are tilted).
        units.input_normals(&mut out.regions.regions);
        units.input_normals(&mut out.fin.final_regions);
        out.units = Some(units);
        out.dequantised = step;
        scratch.work = work;
        if let Some(d) = dequantised {
            scratch.dequantise.recycle(d);
        }
        &self.out
    }

    /// The output of the last frame (empty before the first frame).
    pub fn output(&self) -> &Output {
        &self.out
    }

    /// The output of the last frame, without copying it (empty before the first frame).
    pub fn into_output(self) -> Output {
        self.out
    }
}

/// One [`Segmenter`] per worker thread of a rayon pool, kept for the whole run: every frame a thread segments
/// reuses the buffers of that thread's previous frame, however rayon splits the work (`map_init` makes a fresh
/// `Segmenter` per job split, each paying the first frame's allocations and page faults again).
#[derive(Debug)]
pub struct Segmenters {
    config: Config,
    slots: Vec<std::sync::Mutex<Segmenter>>,
}

impl Segmenters {
    /// `threads` slots (at least one) running `config`; each allocates its buffers on its first frame.
    ///
    /// # Panics
    /// If `config` is invalid ([`Config::validate`]; [`Config::load`] returns only valid ones).
    pub fn new(config: &Config, threads: usize) -> Self {
        check(config, "Segmenters::new");
        let slots =
            (0..threads.max(1)).map(|_| std::sync::Mutex::new(Segmenter::new(config.clone()))).collect();
        Self { config: config.clone(), slots }
    }

    /// Slots for the threads of the current rayon pool ([`rayon::current_num_threads`]).
    ///
    /// # Panics
    /// If `config` is invalid ([`Config::validate`]).
    pub fn for_current_pool(config: &Config) -> Self {
        Self::new(config, rayon::current_num_threads())
    }

    /// Runs `f` with the calling thread's `Segmenter` (slot [`rayon::current_thread_index`] modulo the slots; slot 0
    /// outside a pool). If that slot is busy (`f` itself ran rayon work that came back to this thread, or a thread
    /// of another pool shares the slot), `f` gets a fresh `Segmenter` instead; after a panic in `f` the slot starts
    /// afresh. The results are the same either way.
    pub fn with<R>(&self, f: impl FnOnce(&mut Segmenter) -> R) -> R {
        let slot = &self.slots[rayon::current_thread_index().unwrap_or(0) % self.slots.len()];
        match slot.try_lock() {
            Ok(mut seg) => f(&mut seg),
            Err(std::sync::TryLockError::Poisoned(p)) => {
                let mut seg = p.into_inner();
                *seg = Segmenter::new(self.config.clone());
                slot.clear_poison();
                f(&mut seg)
            }
            Err(std::sync::TryLockError::WouldBlock) => f(&mut Segmenter::new(self.config.clone())),
        }
    }

    /// The configuration every slot runs.
    pub fn config(&self) -> &Config {
        &self.config
    }
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
    let mut fin = Finish::default();
    let mut scratch = Scratch { valid: rangeimage::valid_mask(range), ..Scratch::default() };
    finish_into(range, camera, config, (features, regions, canny), &mut scratch, &mut fin);
    fin
}

/// [`finish`] into `fin` with the buffers of `scratch`, whose `valid` holds the valid mask of `range`.
fn finish_into(
    range: &RangeImage,
    camera: &Camera,
    config: &Config,
    (features, regions, canny): (&SurfaceFeatures, &regiongrow::Segmentation, &vcanny::Edges),
    scratch: &mut Scratch,
    fin: &mut Finish,
) {
    let valid = &scratch.valid;
    if config.pipeline.relax {
        c1_strength_into(features, config.pipeline.c1_strength, &mut scratch.s1);
        let input = relax::Input {
            c1: &regions.c1,
            s1: &scratch.s1,
            c2: &canny.edges,
            magnitude: &canny.magnitude,
            valid,
        };
        fin.relax_info =
            relax::relax_into(&input, &config.relax, config.seed, &mut scratch.relax, &mut fin.relaxed);
    } else {
        relax::union_into(&regions.c1, &canny.edges, &mut fin.relaxed.edges);
        fin.relaxed.c1.copy_from(&regions.c1);
        fin.relaxed.c2.copy_from(&canny.edges);
        fin.relax_info = relax::Info::default();
    }
    // The segmentation sees both relaxed sets in full (before the support test): a border between
    // two faces that region growing merged has only C2 to show it.
    relax::union_into(&fin.relaxed.c1, &fin.relaxed.c2, &mut scratch.union);
    finalseg::segment_into(
        range,
        camera,
        &scratch.union,
        Some(&regions.labels),
        &config.segment,
        &mut scratch.finalseg,
        (&mut fin.labels, &mut fin.final_regions),
    );
    match config.pipeline.final_edges {
        FinalEdges::Relaxed => fin.edges.copy_from(&fin.relaxed.edges),
        // The boundary rule eval scores segmentations by (region pixels next to another region, and
        // unlabelled pixels between two regions; a region's edge against unlabelled pixels is no border),
        // drawn after the gaps the final segmentation leaves between regions are split between them.
        FinalEdges::Segmentation => {
            let (gap_labels, gaps) = &mut scratch.gaps;
            let gap_px = config.pipeline.edge_gap_px;
            let (labels, regions) = (&fin.labels, &fin.final_regions);
            finalseg::edge_labels_into((range, camera, valid), labels, regions, gap_px, gap_labels, gaps);
            rangeimage::boundary::label_boundaries_into(gap_labels, |l| l != 0, &mut fin.edges)
        }
    }
}

/// The C1 strength map s1 for the relaxation energy; 0 where undefined.
pub fn c1_strength(features: &SurfaceFeatures, which: C1Strength) -> Grid<f32> {
    let mut s1 = Grid::default();
    c1_strength_into(features, which, &mut s1);
    s1
}

/// [`c1_strength`] into `s1`, whose memory is reused.
fn c1_strength_into(features: &SurfaceFeatures, which: C1Strength, s1: &mut Grid<f32>) {
    let finite = |v: f32| if v.is_finite() { v } else { 0.0 };
    match which {
        C1Strength::AbsK => s1.map_from(&features.k, |k| finite(k.abs())),
        C1Strength::Curvedness => s1.map_from(&features.curvedness, |&c| finite(c)),
    }
}
