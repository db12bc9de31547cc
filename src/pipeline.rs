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
    /// The decimation the stages ran at (`pipeline.decimate`, or 1 where the camera has no decimated twin; see
    /// [`crate::decimate`]). Above 1, `features` and `canny.magnitude` are maps of the decimated frame, the planes
    /// were fitted on it, and `units.camera` sees the full frame; every label and edge map has the frame's size.
    pub decimation: u32,
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
    /// Whether it has warned that a frame could not be decimated (once per segmenter).
    warned: bool,
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
    /// The decimated frame and the maps carried back to full resolution ([`crate::decimate`]).
    decimated: Decimated,
}

/// The buffers of a decimated frame ([`crate::decimate`]).
#[derive(Debug, Default)]
struct Decimated {
    /// The frame decimated.
    range: RangeImage,
    /// The full frame in working units (when they are not its own) and its valid mask.
    work: RangeImage,
    valid: Grid<bool>,
    /// A label map and an edge map at full resolution, swapped with the output's.
    labels: LabelImage,
    edges: EdgeMap,
    /// [`crate::decimate::renumber`]'s working memory.
    map: Vec<u32>,
    /// [`crate::decimate::downsample_across_jumps_into`]'s working memory.
    misfits: Vec<f64>,
}

/// Frames decimated to fewer blocks than this on a side run at full resolution.
pub const MIN_DECIMATED_SIDE: u32 = 16;

/// The full frame a decimated one came from.
struct Full<'a> {
    range: &'a RangeImage,
    /// The decimation.
    factor: u32,
    /// The time the decimation took (ms).
    t_down: f64,
}

/// Makes room in `grid` for `px` values (its contents stay).
fn keep_room<T: Default>(grid: &mut Grid<T>, px: usize) {
    let (w, h) = grid.dimensions();
    let mut v = std::mem::take(grid).into_vec();
    v.reserve(px.saturating_sub(v.len()));
    *grid = Grid::from_vec(w, h, v).expect("the same values");
}

/// Carries the results of a frame decimated by `f` back to `full`, the frame (module docs of [`crate::decimate`]):
/// the final labels by their regions' planes, seen in working units through `units.camera` (the full frame's), and
/// the final edge map drawn from them; region growing's labels, C1 (their borders), C2 and the relaxed edge sets
/// by nearest neighbour. The features and the gradient magnitude stay at the decimated size.
fn upsample(
    full: &RangeImage,
    f: u32,
    config: &Config,
    units: &WorkingUnits,
    out: &mut Output,
    scratch: &mut Scratch,
) {
    use crate::decimate::{Limit, labels_into, nearest_into, renumber};
    let size = full.dimensions();
    let s = &mut scratch.decimated;
    let work = if units.is_identity() {
        full
    } else {
        units.scale_into(full, &mut s.work);
        &s.work
    };
    s.valid.map_from(work, |v| v.is_finite());
    let geometry = (work, &units.camera, &s.valid);
    let seg = &config.segment;
    let limit =
        Limit { max_residual: seg.fill_max_residual, rms_ratio: seg.fill_rms_ratio, factor: f64::from(f) };
    let fin = &mut out.fin;
    let px = full.len();
    // Each map at full size is swapped into the output; the stage's map swapped out gets room for a full one, so
    // that the next frame allocates nothing.
    labels_into(geometry, &fin.labels, &fin.final_regions, f, limit, &mut s.labels);
    std::mem::swap(&mut fin.labels, &mut s.labels);
    keep_room(&mut s.labels, px);
    renumber(&mut fin.labels, &mut fin.final_regions, &mut s.map);

    nearest_into(&out.regions.labels, f, size, &mut s.labels);
    std::mem::swap(&mut out.regions.labels, &mut s.labels);
    keep_room(&mut s.labels, px);
    // Nearest neighbour keeps the raster order of the regions' first pixels: only their sizes change.
    for r in &mut out.regions.regions {
        r.size_px = 0;
    }
    for &l in out.regions.labels.as_slice().iter().filter(|&&l| l != 0) {
        out.regions.regions[l as usize - 1].size_px += 1;
    }
    regiongrow::borders_into(&out.regions.labels, config.regiongrow.c1_one_sided, &mut out.regions.c1);
    for map in [&mut out.canny.edges, &mut fin.relaxed.c1, &mut fin.relaxed.c2, &mut fin.relaxed.edges] {
        nearest_into(map, f, size, &mut s.edges);
        std::mem::swap(map, &mut s.edges);
        keep_room(&mut s.edges, px);
    }
    match config.pipeline.final_edges {
        FinalEdges::Relaxed => fin.edges.copy_from(&fin.relaxed.edges),
        FinalEdges::Segmentation => {
            let (gap_labels, gaps) = &mut scratch.gaps;
            let gap_px = config.pipeline.edge_gap_px;
            finalseg::edge_labels_into(geometry, &fin.labels, &fin.final_regions, gap_px, gap_labels, gaps);
            rangeimage::boundary::label_boundaries_into(gap_labels, |l| l != 0, &mut fin.edges)
        }
    }
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
        let f = self.config.pipeline.decimate;
        let (w2, h2) = crate::decimate::size(range, f);
        let coarse =
            (f > 1 && w2.min(h2) >= MIN_DECIMATED_SIDE).then(|| crate::decimate::camera(camera, f)).flatten();
        match coarse {
            Some(coarse_camera) => {
                let t = Instant::now();
                let mut small = std::mem::take(&mut self.scratch.decimated.range);
                let misfits = &mut self.scratch.decimated.misfits;
                let dropped =
                    crate::decimate::downsample_across_jumps_into(range, camera, f, &mut small, misfits);
                tracing::debug!(dropped, "blocks across depth jumps");
                let t_down = elapsed_ms(t);
                self.run(&small, &coarse_camera, Some(Full { range, factor: f, t_down }));
                self.scratch.decimated.range = small;
            }
            None => {
                if f > 1 && !std::mem::replace(&mut self.warned, true) {
                    tracing::warn!(
                        decimate = f,
                        "pipeline.decimate needs a pinhole camera and a frame of {MIN_DECIMATED_SIDE} blocks a side: \
                         this frame (and any other such) runs at full resolution"
                    );
                }
                self.run(range, camera, None);
            }
        }
        &self.out
    }

    /// The stages on `range` seen through `camera`: the frame itself, or its decimation with the `full` frame it came
    /// from, to which the results are carried back ([`crate::decimate`]).
    fn run(&mut self, range: &RangeImage, camera: &Camera, full: Option<Full<'_>>) {
        let Self { config, out, scratch, .. } = self;
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
        // A decimated frame's final edge map is drawn at full resolution (`upsample`).
        let inputs = (&out.features, &out.regions, &out.canny);
        finish_into(range, camera, config, inputs, scratch, (&mut out.fin, full.is_none(), step.is_some()));
        let (mut units, mut t_features, mut t_relax) = (units, t_features, elapsed_ms(t));
        out.decimation = 1;
        if let Some(full) = full {
            let t = Instant::now();
            units.camera = crate::decimate::full_camera(&units.camera, full.factor);
            upsample(full.range, full.factor, config, &units, out, scratch);
            out.decimation = full.factor;
            (t_features, t_relax) = (t_features + full.t_down, t_relax + elapsed_ms(t));
        }

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
/// It makes small faces as `config` says, whatever `range` is; a [`Segmenter`] makes none on a frame it dequantised.
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
    finish_into(range, camera, config, (features, regions, canny), &mut scratch, (&mut fin, true, false));
    fin
}

/// [`finish`] into `fin` with the buffers of `scratch`, whose `valid` holds the valid mask of `range`; the final edge
/// map `fin.edges` only if `edges` (else it is left as it was). On `dequantised` depth the final segmentation makes no
/// small faces: the dequantiser's ramps along the steps, which it leaves unlabelled, would pass for them.
fn finish_into(
    range: &RangeImage,
    camera: &Camera,
    config: &Config,
    (features, regions, canny): (&SurfaceFeatures, &regiongrow::Segmentation, &vcanny::Edges),
    scratch: &mut Scratch,
    (fin, edges, dequantised): (&mut Finish, bool, bool),
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
    let mut segment = config.segment.clone();
    if dequantised {
        segment.small_face_min_px = 0;
    }
    finalseg::segment_into(
        range,
        camera,
        &scratch.union,
        Some(&regions.labels),
        &segment,
        &mut scratch.finalseg,
        (&mut fin.labels, &mut fin.final_regions),
    );
    if !edges {
        return;
    }
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
