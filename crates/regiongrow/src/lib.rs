//! Multi-seed region growing with a curvature homogeneity criterion, and region borders C1.
//!
//! This is the paper's Algorithm 1 (docs/method.md §3.2), completed where the paper is silent:
//!
//! 1. **Seeds.** Every pixel that can grow (finite range and finite features; in
//!    [`Mode::Default`] also curvedness ≤ `max_curvedness`) and whose `k_std` ≤ `t_sigma` is a
//!    candidate. The candidates are visited in a random order (a Fisher–Yates permutation from
//!    `Xoshiro256PlusPlus::seed_from_u64(seed)`), i.e. random draws without replacement; a
//!    candidate that is still unlabelled when drawn becomes a seed and its region is grown to
//!    completion before the next draw. Drawing stops at `max_seeds` seeds or when the candidates
//!    run out, or when fewer than `min_region_px` growable pixels are left unlabelled.
//!    Candidates are taken from every `seed_stride_px`-th pixel in x and y, and a drawn candidate
//!    seeds only if its whole `(2·seed_radius_px + 1)²` window is unlabelled, growable and passes
//!    the mode's growth test against the seed (this rejects seeds on noise, creases and jump
//!    bands, which used to grow thousands of tiny regions that were dropped). If fewer than
//!    `min_seeds` seeds were accepted, `t_sigma` is doubled and the still-unlabelled pixels (all
//!    of them, without the window test, in the last round) are drawn again (at most [`MAX_RELAXATIONS`] times); the threshold
//!    actually used is reported in [`Info::t_sigma_used`].
//! 2. **Growth** is breadth-first over 4- (or 8-) neighbours. [`Mode::Paper`]: a neighbour joins if
//!    `|K − mean K of the region| ≤ max_k_diff` (Gaussian curvature only, so regions leak across
//!    creases, where K ≈ 0, see docs/method.md §3.1). [`Mode::Default`]: a neighbour joins if its curvedness
//!    ≤ `max_curvedness` and its local normal is within `max_slant_deg` of the line of sight
//!    (seed and growth condition), its local normal is within `max_angle_deg` of the region's plane normal,
//!    and its 3D point lies within `max(max_residual, residual_rms_ratio × RMS)` of the region's
//!    plane, RMS being the region's distance to its own plane at the last refit. The region plane starts
//!    as the seed's local plane and is refitted from running 3D moments after
//!    `max(refit_every_px, n / 4)` additions (so O(log n) refits per region). A region that stops at
//!    `release_max_px` pixels or fewer is fitted to all of them, and those that fail the test against that
//!    plane are released (unlabelled, free for later seeds), again while any is.
//!    Local normals come from the features' local plane slopes `(a, b)` back-projected through the
//!    camera at the pixel's range value.
//! 3. **Merge**: adjacent regions with `|mean K₁ − mean K₂| < t_m` (default mode: and normals within
//!    `merge_max_angle_deg`, and the RMS distance of each region's points to the other's plane
//!    ≤ `merge_max_residual`; or, whatever their normals and mean K, the one plane fitted to both
//!    has an RMS distance ≤ `merge_max_residual` and ≤ `merge_joint_rms_ratio` × the pixel-weighted
//!    RMS of their own fits) are merged by a deterministic fixpoint over the region adjacency
//!    graph. Each pass sorts the candidate pairs by a dissimilarity score, ties broken by the
//!    regions' first pixel in raster order (never by label value, so relabelling the input does
//!    not change the result), and merges with union–find, re-checking each pair on the merged
//!    statistics; passes repeat until one merges nothing.
//! 4. Regions under `min_region_px` become 0. Optionally (`fill_unlabelled`) the left-over
//!    valid pixels (crease bands, dropped fragments) are given, by a breadth-first flood from the
//!    regions' borders, to the 4-adjacent region whose plane is nearest, if that distance is
//!    ≤ `fill_max_residual`; then (`merge_after_fill`) the merge runs again, since regions that a band
//!    of non-growable pixels kept apart (crease bands, staircase steps) now touch. Labels are renumbered 1..n in raster order of first pixel.
//! 5. **C1** = [`borders`] of the final labels.
//!
//! The stage is single-threaded and fully deterministic for a given input, params and seed.
//! Internally every per-pixel array carries a one-pixel frame so that the growth loops use fixed
//! neighbour index deltas without border tests (see the `grow` module).

mod grow;
mod merge;
mod plane;

#[cfg(test)]
mod testutil;

use rangeimage::ParamError;
use rangeimage::{Camera, EdgeMap, Grid, LabelImage, RangeImage, Region, SurfaceFeatures};

/// Stride of the rows [`Params::for_steps`] reads the depth step from (a quarter of them).
const STEP_STRIDE: usize = 4;

/// How many times `t_sigma` is doubled at most when fewer than `min_seeds` seeds were accepted.
pub const MAX_RELAXATIONS: u32 = 8;

/// The homogeneity criterion of region growth.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Mode {
    /// The paper's criterion: Gaussian curvature K close to the region's mean K.
    Paper,
    /// Curvedness under a threshold plus consistency with the region's 3D plane.
    #[default]
    Default,
}

/// The `[regiongrow]` table of a config file.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Params {
    /// Homogeneity criterion.
    pub mode: Mode,
    /// T_σ: a seed is accepted only where the std of K over its window is ≤ this.
    pub t_sigma: f32,
    /// T_m: adjacent regions merge only if their mean K differ by less than this.
    pub t_m: f32,
    /// Minimum number of seeds (`t_sigma` is relaxed to reach it, see the crate docs).
    pub min_seeds: u32,
    /// Maximum number of seeds (regions grown).
    pub max_seeds: u32,
    /// Paper mode: a pixel joins if `|K − mean K of the region|` ≤ this.
    pub max_k_diff: f32,
    /// Default mode: a pixel grows (or seeds) only if its curvedness is ≤ this.
    pub max_curvedness: f32,
    /// Default mode: maximum angle between a pixel's local normal and the region's normal.
    pub max_angle_deg: f32,
    /// Default mode: maximum distance of a pixel's 3D point to the region's plane, in camera units.
    pub max_residual: f32,
    /// Default mode, on depth quantised in steps (`planefit::noise::step_from_smallest`: a uniform step or
    /// the highest riser): the normal-angle limit is at least the tilt of this many steps per pixel and the residual
    /// limit at least one step, both in 3D at the image centre and its mean depth (0 = off). A slanted plane in
    /// coarse steps is a staircase of flat terraces; 0.3 is the slope a 5 × 5 plane fit finds across a single
    /// step, so the normals of windows on a step edge stay within the limit and the next terrace within the
    /// residual.
    pub step_tilt: f32,
    /// Default mode: the residual limit of growth is `max(max_residual, this × the region's RMS
    /// distance to its own plane)` (0 = `max_residual` alone). The region's own scatter, measured
    /// at each refit, holds the image's noise and what of its surface a plane does not model
    /// (depth encodings that bend planes, staircases, stripes), so the limit follows the image
    /// instead of one absolute noise level.
    pub residual_rms_ratio: f32,
    /// Default mode: a pixel grows (or seeds) only if its local normal is within this angle of the
    /// direction toward the sensor. Rejects the steep "walls" that local fits across depth jumps
    /// produce (their curvature is tiny because of the gradient term in K and H).
    pub max_slant_deg: f32,
    /// Default mode: the region plane is refitted after `max(refit_every_px, n / 4)` additions.
    pub refit_every_px: u32,
    /// Default mode: a region that stops growing with at most this many pixels is fitted to all of them, and its
    /// pixels that fail the growth test (normal angle, residual limit) against that plane go back to the pool,
    /// again while any does (0 = never). Such a region is a seed on a crease, whose local plane lies between the
    /// two faces, or on a face whose noise exceeds its pixel spacing, where a fit on a few pixels is mostly noise
    /// and growth stops: it would be dropped under `min_region_px` unless a merge saved it, and meanwhile its
    /// pixels kept the regions grown later from the crease or the face.
    pub release_max_px: u32,
    /// Default mode: adjacent regions merge only if their normals are within this angle.
    pub merge_max_angle_deg: f32,
    /// Default mode: adjacent regions merge only if each one's RMS distance to the other's plane
    /// is ≤ this, in camera units.
    pub merge_max_residual: f32,
    /// Default mode: adjacent regions also merge, whatever their normals and mean K, when the one
    /// plane fitted to both has an RMS distance ≤ `merge_max_residual` and ≤ this × the
    /// pixel-weighted RMS distance of their own fits (0 = off). Thin regions (stripes, strips of a staircase) have normals
    /// the angle test cannot trust; the joint fit can.
    pub merge_joint_rms_ratio: f32,
    /// Regions with fewer pixels become unlabelled (0).
    pub min_region_px: u32,
    /// Neighbourhood of growth and of the region adjacency graph: 4 or 8.
    pub connectivity: u8,
    /// Give left-over valid pixels to the adjacent region whose plane fits them (see crate docs).
    pub fill_unlabelled: bool,
    /// Maximum plane distance for `fill_unlabelled`, in camera units.
    pub fill_max_residual: f32,
    /// After the fill step, merge again: regions that a band of non-growable pixels (a crease
    /// band, a staircase step, a stripe) kept apart are adjacent now.
    pub merge_after_fill: bool,
    /// C1 one pixel thick (one side of each border) instead of both sides.
    pub c1_one_sided: bool,
    /// Seed candidates are drawn from every `seed_stride_px`-th pixel in x and y (1 = all pixels).
    pub seed_stride_px: u32,
    /// A seed needs every pixel of its `(2r+1)²` window (r = this) growable and passing the growth
    /// test against the seed (0 = no neighbourhood test). Skipped in the last relaxation round.
    pub seed_radius_px: u32,
}

/// Defaults tuned on the 10 training images of the synthetic ABW-like benchmark
/// (`examples/regions_eval.rs --tune`, Hoover T = 0.8).
impl Default for Params {
    fn default() -> Self {
        Self {
            mode: Mode::Default,
            t_sigma: 0.08,
            t_m: 0.005,
            min_seeds: 1,
            max_seeds: 10_000,
            max_k_diff: 0.01,
            max_curvedness: 1.0,
            max_angle_deg: 40.0,
            max_residual: 3.0,
            step_tilt: 0.3,
            residual_rms_ratio: 3.0,
            max_slant_deg: 80.0,
            refit_every_px: 16,
            release_max_px: 16,
            merge_max_angle_deg: 10.0,
            merge_max_residual: 4.0,
            merge_joint_rms_ratio: 1.2,
            min_region_px: 200,
            connectivity: 4,
            fill_unlabelled: true,
            fill_max_residual: 3.0,
            merge_after_fill: true,
            c1_one_sided: false,
            seed_stride_px: 1,
            seed_radius_px: 1,
        }
    }
}

impl Params {
    /// The paper's faithful configuration: Gaussian-curvature growth and merge, no fill step,
    /// no seed-neighbourhood test
    /// (`t_sigma`, `max_k_diff` tuned on the training split like the default mode).
    pub fn paper() -> Self {
        Self {
            mode: Mode::Paper,
            t_sigma: 0.005,
            max_k_diff: 0.003,
            fill_unlabelled: false,
            seed_radius_px: 0,
            ..Self::default()
        }
    }

    /// These parameters with the normal-angle and residual limits raised for the depth steps of `range` (see
    /// `step_tilt`); unchanged if the depth has no step (`planefit::noise::step_from_smallest`) or
    /// `step_tilt` is 0.
    #[must_use]
    pub fn for_steps(&self, range: &RangeImage, camera: &Camera) -> Params {
        let mut p = self.clone();
        if self.step_tilt <= 0.0 {
            return p;
        }
        // The smallest difference first; whether it is the step (a second pass) only if it would change a limit.
        let Some(step) = planefit::noise::smallest_difference(range, STEP_STRIDE) else { return p };
        // The step in 3D at the image centre and its mean depth, and the tilt of `step_tilt` steps per pixel there.
        let limits = |step: f64| {
            let (step_3d, pitch) = planefit::noise::step_geometry(range, camera, step)?;
            let tilt_deg = ((f64::from(self.step_tilt) * step_3d / pitch).atan().to_degrees()) as f32;
            Some((step_3d, pitch, tilt_deg))
        };
        let raises = |(step_3d, _, tilt_deg): (f64, f64, f32)| {
            tilt_deg > p.max_angle_deg || step_3d as f32 > p.max_residual
        };
        // Steps are never smaller than the smallest difference, so nothing to raise there means nothing at all.
        if !limits(step).is_some_and(raises) {
            return p;
        }
        let Some((step, (step_3d, pitch, tilt_deg))) =
            planefit::noise::step_from_smallest(range, STEP_STRIDE, step)
                .and_then(|s| Some((s, limits(s)?)))
                .filter(|&(_, l)| raises(l))
        else {
            return p;
        };
        tracing::debug!(step, step_3d, pitch, tilt_deg, "depth in steps");
        p.max_angle_deg = p.max_angle_deg.max(tilt_deg);
        p.max_residual = p.max_residual.max(step_3d as f32);
        p
    }

    /// Checks every value; the message names the offending field.
    pub fn validate(&self) -> Result<(), ParamError> {
        let nonneg = [
            ("regiongrow.t_sigma", self.t_sigma),
            ("regiongrow.t_m", self.t_m),
            ("regiongrow.max_k_diff", self.max_k_diff),
            ("regiongrow.max_curvedness", self.max_curvedness),
            ("regiongrow.max_residual", self.max_residual),
            ("regiongrow.step_tilt", self.step_tilt),
            ("regiongrow.residual_rms_ratio", self.residual_rms_ratio),
            ("regiongrow.merge_max_residual", self.merge_max_residual),
            ("regiongrow.merge_joint_rms_ratio", self.merge_joint_rms_ratio),
            ("regiongrow.fill_max_residual", self.fill_max_residual),
        ];
        for (name, v) in nonneg {
            if v.is_nan() || v < 0.0 {
                return Err(ParamError::new(name, format!("must be a number ≥ 0, got {v}")));
            }
        }
        ParamError::in_range("regiongrow.max_angle_deg", self.max_angle_deg, 0.0, 180.0)?;
        ParamError::in_range("regiongrow.merge_max_angle_deg", self.merge_max_angle_deg, 0.0, 180.0)?;
        ParamError::in_range("regiongrow.max_slant_deg", self.max_slant_deg, 0.0, 90.0)?;
        for (name, v) in [
            ("regiongrow.max_seeds", self.max_seeds),
            ("regiongrow.seed_stride_px", self.seed_stride_px),
            ("regiongrow.refit_every_px", self.refit_every_px),
        ] {
            if v == 0 {
                return Err(ParamError::new(name, "must be ≥ 1"));
            }
        }
        if self.min_seeds > self.max_seeds {
            return Err(ParamError::new(
                "regiongrow.min_seeds",
                format!("({}) must be ≤ max_seeds ({})", self.min_seeds, self.max_seeds),
            ));
        }
        if !matches!(self.connectivity, 4 | 8) {
            return Err(ParamError::new(
                "regiongrow.connectivity",
                format!("must be 4 or 8, got {}", self.connectivity),
            ));
        }
        ParamError::in_range("regiongrow.seed_radius_px", self.seed_radius_px, 0, 16)?;
        Ok(())
    }
}

/// Diagnostics of one [`grow`] call.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Info {
    /// Seeds accepted (= regions grown).
    pub n_seeds: u32,
    /// Candidate pixels drawn (accepted or found already labelled).
    pub n_draws: u32,
    /// How many times `t_sigma` was doubled to reach `min_seeds`.
    pub n_relaxations: u32,
    /// The seed threshold finally used.
    pub t_sigma_used: f32,
    /// Regions after growth (before merging).
    pub n_regions_grown: u32,
    /// Merge operations performed.
    pub n_merged: u32,
    /// Merge passes over the region adjacency graph (the last one merges nothing).
    pub n_merge_passes: u32,
    /// Regions dropped for being under `min_region_px`.
    pub n_dropped: u32,
    /// Pixels given to a region by the fill step.
    pub n_filled_px: u32,
    /// Final number of regions.
    pub n_regions: u32,
    /// Valid (finite-range) pixels left unlabelled.
    pub n_unlabelled_valid_px: u32,
}

/// The output of [`grow`].
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Segmentation {
    /// 0 = none, regions 1..=n numbered in raster order of their first pixel.
    pub labels: LabelImage,
    /// `regions[i]` describes label `i + 1`.
    pub regions: Vec<Region>,
    /// Region borders C1 (see [`borders`]).
    pub c1: EdgeMap,
}

/// Segments `range` into regions by multi-seed region growing (see the crate docs).
///
/// # Panics
/// If any grid of `features` differs in size from `range`; in debug builds also if `params` fail
/// [`Params::validate`] (callers validate once, at the edge).
#[must_use]
pub fn grow(
    range: &RangeImage,
    features: &SurfaceFeatures,
    camera: &Camera,
    params: &Params,
    seed: u64,
) -> (Segmentation, Info) {
    let mut out = Segmentation::default();
    let info = grow_into(range, features, camera, params, seed, &mut Scratch::default(), &mut out);
    (out, info)
}

/// The working buffers of [`grow_into`] (padded geometry, labels and K, the growth queue), kept between
/// frames so a stream of same-sized images allocates them once.
#[derive(Debug, Clone, Default)]
pub struct Scratch {
    geo: Vec<[f32; 6]>,
    labels: Vec<u32>,
    k: Vec<f32>,
    queue: Vec<u32>,
    cand: Vec<u32>,
    merge: merge::MergeBufs,
    fill_planes: Vec<Option<plane::Plane>>,
}

/// [`grow`] into `out` (its grids reused when they have the image's size) with the buffers of `scratch`;
/// the same result, bit for bit.
///
/// # Panics
/// As [`grow`].
pub fn grow_into(
    range: &RangeImage,
    features: &SurfaceFeatures,
    camera: &Camera,
    params: &Params,
    seed: u64,
    scratch: &mut Scratch,
    out: &mut Segmentation,
) -> Info {
    let _s = tracing::info_span!("regiongrow", w = range.width(), h = range.height()).entered();
    debug_assert_eq!(params.validate(), Ok(()), "regiongrow::grow: invalid params");
    let need_sizes = [
        ("k", features.k.same_size(range)),
        ("k_std", features.k_std.same_size(range)),
        ("curvedness", params.mode == Mode::Paper || features.curvedness.same_size(range)),
        ("plane", params.mode == Mode::Paper || features.plane.same_size(range)),
    ];
    for (name, ok) in need_sizes {
        assert!(ok, "regiongrow::grow: features.{name} differs in size from the range image");
    }
    let stepped;
    let params = if params.mode == Mode::Default && params.step_tilt > 0.0 {
        stepped = params.for_steps(range, camera);
        &stepped
    } else {
        params
    };
    // Compiled for the best instruction set of this CPU (bit-identical on every one).
    isa::dispatch(
        #[inline(always)]
        || grow::run(range, features, camera, params, seed, scratch, out),
    )
}

/// Region border pixels C1 of a label image.
///
/// Two-sided (`one_sided = false`, the paper's C1): a pixel with label ≠ 0 is a border pixel if a
/// 4-neighbour has a different label (including 0: unlabelled or no data). Label-0 pixels are never
/// border pixels, and the image frame is not a border.
///
/// One-sided: between two regions only the upper/left pixel of each differing 4-neighbour pair is
/// marked (the pixel whose right or lower neighbour has another non-zero label), giving a 1-pixel
/// line; a labelled pixel next to label 0 is still marked (the 0 side cannot carry the border).
#[must_use]
pub fn borders(labels: &LabelImage, one_sided: bool) -> EdgeMap {
    let mut out = EdgeMap::default();
    borders_into(labels, one_sided, &mut out);
    out
}

/// [`borders`] into `out`, whose memory is reused.
pub fn borders_into(labels: &LabelImage, one_sided: bool, out_map: &mut EdgeMap) {
    let (w, h) = labels.dimensions();
    let l = labels.as_slice();
    let (w, h) = (w as usize, h as usize);
    let mut out = std::mem::take(out_map).into_vec();
    out.clear();
    out.resize(w * h, false);
    // One pixel given its four neighbours; a missing neighbour (image frame) is passed as the
    // pixel's own label, which never differs from it and is never 0 where it is labelled.
    let test = |a: u32, left: u32, right: u32, up: u32, down: u32| -> bool {
        let border = if one_sided {
            (right != a) | (down != a) | (left == 0) | (up == 0)
        } else {
            (right != a) | (down != a) | (left != a) | (up != a)
        };
        (a != 0) & border
    };
    for y in 0..h {
        let row = &l[y * w..(y + 1) * w];
        let up = if y > 0 { &l[(y - 1) * w..y * w] } else { row };
        let down = if y + 1 < h { &l[(y + 1) * w..(y + 2) * w] } else { row };
        let o = &mut out[y * w..(y + 1) * w];
        if w == 1 {
            o[0] = test(row[0], row[0], row[0], up[0], down[0]);
            continue;
        }
        o[0] = test(row[0], row[0], row[1], up[0], down[0]);
        o[w - 1] = test(row[w - 1], row[w - 2], row[w - 1], up[w - 1], down[w - 1]);
        // Interior columns: equal-length slices, no bounds tests (vectorises).
        let mid =
            row[1..w - 1].iter().zip(&row[..w - 2]).zip(&row[2..]).zip(&up[1..w - 1]).zip(&down[1..w - 1]);
        for (((((&a, &lf), &rt), &u), &d), o) in mid.zip(&mut o[1..w - 1]) {
            *o = test(a, lf, rt, u, d);
        }
    }
    *out_map = Grid::from_vec(labels.width(), labels.height(), out).expect("same size");
}

#[cfg(test)]
mod tests;
