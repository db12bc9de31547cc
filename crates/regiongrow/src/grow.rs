//! Seeding, breadth-first growth, small-region removal, fill and final relabelling.
//!
//! Every per-pixel array of the stage is stored with a one-pixel frame (padded width `w + 2`):
//! neighbours are fixed index deltas and the frame is never growable, so the hot loops need no
//! bounds or border tests. The label array doubles as the growable mask during seeding and growth
//! (non-growable pixels and the frame hold [`BLOCKED`]), and the 3D point and local normal of a
//! pixel sit next to each other, so the growth test of a neighbour touches two cache lines at most.

use crate::merge::{MergeBufs, Stats, merge, region_stats_into, region_stats_update};
use crate::plane::{Moments, Plane, cross, dot};
use crate::{Info, MAX_RELAXATIONS, Mode, Params, Scratch, Segmentation, borders_into};
use rand::{RngExt, SeedableRng, rngs::Xoshiro256PlusPlus};
use rangeimage::{AbwCalibration, Camera, Grid, RangeImage, Region, SurfaceFeatures};

/// Label of pixels that may not join a region (not growable, or the frame) during seeding and growth.
const BLOCKED: u32 = u32::MAX;

/// The 3D point (first three) and unit local normal (last three) of a geometry record, in `f64`.
#[inline]
fn point_of(g: &[f32; 6]) -> [f64; 3] {
    [f64::from(g[0]), f64::from(g[1]), f64::from(g[2])]
}

#[inline]
fn normal_of(g: &[f32; 6]) -> [f64; 3] {
    [f64::from(g[3]), f64::from(g[4]), f64::from(g[5])]
}

/// The per-image data growth reads, on the padded grid.
struct Ctx<'a> {
    /// Image width and height.
    w: usize,
    h: usize,
    /// Padded width `w + 2`.
    pw: usize,
    /// Neighbour index deltas in the fixed order left, up, right, down, then (8-connectivity)
    /// up-left, up-right, down-left, down-right.
    offs: [isize; 8],
    eight: bool,
    /// Per padded pixel: 3D point relative to `origin` (NaN where the range is not finite) and,
    /// in default mode, the unit local normal toward the sensor (NaN where not computed).
    geo: &'a [[f32; 6]],
    /// K per padded pixel (NaN on the frame).
    k: &'a [f32],
    origin: [f64; 3],
    camera: &'a Camera,
}

impl Ctx<'_> {
    fn toward(&self, p_rel: [f64; 3]) -> [f64; 3] {
        let o = self.origin;
        self.camera.toward_sensor([p_rel[0] + o[0], p_rel[1] + o[1], p_rel[2] + o[2]])
    }

    /// Padded index of pixel `(x, y)`.
    #[inline]
    fn pad(&self, x: usize, y: usize) -> usize {
        (y + 1) * self.pw + x + 1
    }
}

/// Sizes the padded buffers of a `w × h` frame for a geometry pass and returns the padded width:
/// `geo` zeroed or the previous frame's (every interior record is written by the pass) with a NaN
/// frame, every label `BLOCKED`.
#[inline(always)]
fn padded_buffers(w: usize, h: usize, (geo, labels): (&mut Vec<[f32; 6]>, &mut Vec<u32>)) -> usize {
    let pw = w + 2;
    sized(geo, pw * (h + 2));
    set_frame(geo, pw, [f32::NAN; 6]);
    filled(labels, pw * (h + 2), BLOCKED);
    pw
}

/// Sets the one-pixel frame of a padded array of width `pw` to `v`.
fn set_frame<T: Copy>(a: &mut [T], pw: usize, v: T) {
    let n = a.len();
    a[..pw + 1].fill(v);
    a[n - pw - 1..].fill(v);
    // Right frame of row y and left frame of row y + 1 are adjacent.
    let mut i = 2 * pw - 1;
    while i + 1 < n - pw {
        a[i] = v;
        a[i + 1] = v;
        i += pw;
    }
}

/// Makes `v` hold `n` elements whose values the caller overwrites: kept as it is when it already holds `n`
/// (a buffer of the previous frame), else zeroed memory (`vec!`, which the allocator serves without a fill).
fn sized<T: Copy + Default>(v: &mut Vec<T>, n: usize) {
    if v.len() != n {
        *v = Vec::new();
        *v = vec![T::default(); n];
    }
}

/// Makes `v` hold `n` copies of `value`, reusing its memory.
fn filled<T: Copy>(v: &mut Vec<T>, n: usize, value: T) {
    v.clear();
    v.resize(n, value);
}

/// A camera model with its variant resolved, so per-pixel loops carry no `match`.
/// Every formula repeats [`Camera::point`] operation for operation (bit-identical results).
trait Proj {
    /// The 3D point of pixel `(x, y)` with finite range `v`.
    fn point(&self, x: f64, y: f64, v: f64) -> [f64; 3];
    /// `∂P/∂x`, `∂P/∂y`, `∂P/∂v` at `(x, y, v)`.
    fn jacobian(&self, x: f64, y: f64, v: f64) -> [[f64; 3]; 3];
    /// Unit vector toward the sensor at `(x, y, v)`.
    fn toward(&self, x: f64, y: f64, v: f64) -> [f64; 3];
}

/// The ABW model through the general path (the reference of [`geometry_abw`]).
#[cfg(test)]
struct AbwProj(AbwCalibration);

#[cfg(test)]
impl Proj for AbwProj {
    #[inline]
    fn point(&self, x: f64, y: f64, v: f64) -> [f64; 3] {
        let cal = &self.0;
        let d = v / cal.scal + cal.offset;
        let f = cal.f.abs();
        [(x - 255.0) * d / f, (255.0 - y) / cal.c * d / f, (255.0 - v) / cal.scal]
    }

    #[inline]
    fn jacobian(&self, x: f64, y: f64, v: f64) -> [[f64; 3]; 3] {
        let cal = &self.0;
        let f = cal.f.abs();
        let d = v / cal.scal + cal.offset;
        [
            [d / f, 0.0, 0.0],
            [0.0, -d / (cal.c * f), 0.0],
            [(x - 255.0) / (cal.scal * f), (255.0 - y) / (cal.c * cal.scal * f), -1.0 / cal.scal],
        ]
    }

    #[inline]
    fn toward(&self, _x: f64, _y: f64, _v: f64) -> [f64; 3] {
        [0.0, 0.0, 1.0]
    }
}

/// A pinhole camera (always `Camera::Pinhole`).
struct PinholeProj(Camera);

impl Proj for PinholeProj {
    #[inline]
    fn point(&self, x: f64, y: f64, v: f64) -> [f64; 3] {
        self.0.point(x, y, v).unwrap_or([f64::NAN; 3])
    }

    #[inline]
    fn jacobian(&self, x: f64, y: f64, v: f64) -> [[f64; 3]; 3] {
        let Camera::Pinhole { fx, fy, cx, cy, depth_scale } = self.0 else {
            unreachable!("PinholeProj holds a pinhole camera")
        };
        let z = v * depth_scale;
        [
            [z / fx, 0.0, 0.0],
            [0.0, z / fy, 0.0],
            [(x - cx) * depth_scale / fx, (y - cy) * depth_scale / fy, depth_scale],
        ]
    }

    #[inline]
    fn toward(&self, x: f64, y: f64, v: f64) -> [f64; 3] {
        self.0.toward_sensor(self.point(x, y, v))
    }
}

/// The uncalibrated `Camera::Grid`.
struct GridProj;

impl Proj for GridProj {
    #[inline]
    fn point(&self, x: f64, y: f64, v: f64) -> [f64; 3] {
        [x, y, v]
    }

    #[inline]
    fn jacobian(&self, _x: f64, _y: f64, _v: f64) -> [[f64; 3]; 3] {
        [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]
    }

    #[inline]
    fn toward(&self, _x: f64, _y: f64, _v: f64) -> [f64; 3] {
        [0.0, 0.0, -1.0]
    }
}

/// Padded geometry records, initial labels (0 = growable, [`BLOCKED`] otherwise) and the number
/// of growable pixels.
#[inline(always)] // into `run`, compiled for each instruction set
fn geometry<P: Proj>(
    proj: &P,
    range: &[f32],
    features: &SurfaceFeatures,
    params: &Params,
    (w, h): (usize, usize),
    origin: [f64; 3],
    (geo, labels): (&mut Vec<[f32; 6]>, &mut Vec<u32>),
) -> usize {
    let pw = w + 2;
    let pn = pw * (h + 2);
    filled(geo, pn, [f32::NAN; 6]);
    filled(labels, pn, BLOCKED);
    let mut growable = 0usize;
    let paper = params.mode == Mode::Paper;
    let k = features.k.as_slice();
    let curv = features.curvedness.as_slice();
    let plane = features.plane.as_slice();
    let max_c = params.max_curvedness;
    let cos_slant = f64::from(params.max_slant_deg).to_radians().cos();
    for y in 0..h {
        let yf = y as f64;
        let src = y * w;
        let dst = (y + 1) * pw + 1;
        let rrow = &range[src..src + w];
        let grow_row = &mut geo[dst..dst + w];
        let lrow = &mut labels[dst..dst + w];
        for x in 0..w {
            let v = rrow[x];
            if !v.is_finite() {
                continue;
            }
            let (xf, vf) = (x as f64, f64::from(v));
            let p = proj.point(xf, yf, vf);
            let g = &mut grow_row[x];
            g[0] = (p[0] - origin[0]) as f32;
            g[1] = (p[1] - origin[1]) as f32;
            g[2] = (p[2] - origin[2]) as f32;
            if paper {
                if k[src + x].is_finite() {
                    lrow[x] = 0;
                    growable += 1;
                }
                continue;
            }
            let [a, b, _] = plane[src + x];
            if !(a.is_finite() && b.is_finite() && curv[src + x] <= max_c) {
                continue;
            }
            if let Some((nrm, slant_cos)) = normal_with(proj, xf, yf, vf, f64::from(a), f64::from(b)) {
                g[3] = nrm[0] as f32;
                g[4] = nrm[1] as f32;
                g[5] = nrm[2] as f32;
                if slant_cos >= cos_slant {
                    lrow[x] = 0;
                    growable += 1;
                }
            }
        }
    }
    growable
}

/// Constants of the closed-form ABW local normal (see [`geometry_abw`]).
struct AbwNormal {
    /// `−|f|`.
    af: f64,
    /// `c·|f|`.
    bf: f64,
    /// `offset·scal`.
    os: f64,
}

impl AbwNormal {
    fn new(cal: AbwCalibration) -> Self {
        let f = cal.f.abs();
        Self { af: -f, bf: cal.c * f, os: cal.offset * cal.scal }
    }
}

/// Unit local normal toward the sensor (so its z is the cosine to the line of sight) for slopes
/// `(a, b)`, range `v`, `u = x − 255`, `t = 255 − y`, and whether it is defined (finite, non-zero).
#[inline]
fn abw_normal(k: &AbwNormal, a: f64, b: f64, v: f64, u: f64, t: f64) -> ([f64; 3], bool) {
    let ds = v + k.os;
    let n = [a * k.af, b * k.bf, -(ds + a * u - b * t)];
    let len = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
    let inv = 1.0 / len;
    let inv = if n[2] < 0.0 { -inv } else { inv };
    // NaN or infinite slopes give a non-finite length.
    let ok = (len > 0.0) & (len < f64::INFINITY) & (ds != 0.0);
    ([n[0] * inv, n[1] * inv, n[2] * inv], ok)
}

/// [`geometry`] for the ABW camera, with the local normal in closed form.
///
/// With `F = |f|`, `s = scal`, `u = x − 255`, `t = 255 − y` and `ds = v + offset·s` (the camera's
/// distance term times `s`), the tangents of [`normal_with`] scaled by `s·F` and `c·s·F` are
/// `(ds + a·u, a·t/c, −a·F)` and `(b·c·u, −ds + b·t, −b·c·F)`; their cross product is
/// `ds · (−a·F, b·c·F, −(ds + a·u − b·t))`. Scale factors do not change the unit normal once it is
/// oriented toward the sensor (+z), so the normal is that last vector, normalised and flipped to
/// `z ≥ 0`: one square root and one division per pixel instead of the general path's eleven
/// divisions. Points use [`Camera::point`]'s formula with the divisions by `|f|` and `scal`
/// replaced by products with reciprocals (within an `f64` ulp, far below the `f32` storage).
#[inline(always)] // into `run`, compiled for each instruction set
fn geometry_abw(
    cal: AbwCalibration,
    range: &[f32],
    features: &SurfaceFeatures,
    params: &Params,
    (w, h): (usize, usize),
    origin: [f64; 3],
    (geo, labels): (&mut Vec<[f32; 6]>, &mut Vec<u32>),
) -> usize {
    let pw = padded_buffers(w, h, (geo, labels));
    let paper = params.mode == Mode::Paper;
    let max_c = params.max_curvedness;
    let cos_slant = f64::from(params.max_slant_deg).to_radians().cos();
    let f = cal.f.abs();
    let (inv_f, inv_s) = (1.0 / f, 1.0 / cal.scal);
    let off = cal.offset;
    let k = AbwNormal::new(cal);
    let [o0, o1, o2] = origin;
    let ux: Vec<f64> = (0..w).map(|x| x as f64 - 255.0).collect();
    let uf: Vec<f64> = ux.iter().map(|u| u * inv_f).collect();
    let nan = f32::NAN;
    let mut growable = 0usize;
    for y in 0..h {
        let t = 255.0 - y as f64;
        let tcf = t / cal.c * inv_f;
        let (src, dst) = (y * w, (y + 1) * pw + 1);
        let rrow = &range[src..src + w];
        let grow_row = &mut geo[dst..dst + w];
        let lrow = &mut labels[dst..dst + w];
        if paper {
            let krow = &features.k.as_slice()[src..src + w];
            for x in 0..w {
                let v = rrow[x];
                let vf = f64::from(v);
                let d = vf * inv_s + off;
                let g = &mut grow_row[x];
                *g = [nan; 6];
                if v.is_finite() {
                    g[0] = (uf[x] * d - o0) as f32;
                    g[1] = (tcf * d - o1) as f32;
                    g[2] = ((255.0 - vf) * inv_s - o2) as f32;
                    if krow[x].is_finite() {
                        lrow[x] = 0;
                        growable += 1;
                    }
                }
            }
            continue;
        }
        let crow = &features.curvedness.as_slice()[src..src + w];
        let prow = &features.plane.as_slice()[src..src + w];
        let cols = ux.iter().zip(&uf).zip(grow_row.iter_mut().zip(lrow.iter_mut()));
        for (((&v, pl), &c), ((&u, &ufx), (g, lab))) in rrow.iter().zip(prow).zip(crow).zip(cols) {
            let vf = f64::from(v);
            let d = vf * inv_s + off;
            let fin = v.is_finite();
            let (n, ok) = abw_normal(&k, f64::from(pl[0]), f64::from(pl[1]), vf, u, t);
            let ok = ok & fin & (c <= max_c);
            let grow = ok & (n[2] >= cos_slant);
            *g = [
                if fin { (ufx * d - o0) as f32 } else { nan },
                if fin { (tcf * d - o1) as f32 } else { nan },
                if fin { ((255.0 - vf) * inv_s - o2) as f32 } else { nan },
                if ok { n[0] as f32 } else { nan },
                if ok { n[1] as f32 } else { nan },
                if ok { n[2] as f32 } else { nan },
            ];
            *lab = if grow { 0 } else { BLOCKED };
            growable += usize::from(grow);
        }
    }
    growable
}

/// [`geometry`] for a pinhole camera in default mode: per pixel the operations of [`Camera::point`] and of
/// [`normal_with`] on [`PinholeProj`], in the same order and precision (bit-identical records, labels and
/// count), with the Jacobian's per-column and per-row terms computed once and the point computed once (the
/// general path computes it again for the direction toward the sensor), and no branch in the loop, so it
/// vectorises.
#[inline(always)] // into `run`, compiled for each instruction set
#[allow(clippy::too_many_arguments)]
fn geometry_pinhole(
    [fx, fy, cx, cy, ds]: [f64; 5],
    range: &[f32],
    features: &SurfaceFeatures,
    params: &Params,
    (w, h): (usize, usize),
    origin: [f64; 3],
    (geo, labels): (&mut Vec<[f32; 6]>, &mut Vec<u32>),
) -> usize {
    let pw = padded_buffers(w, h, (geo, labels));
    let max_c = params.max_curvedness;
    let cos_slant = f64::from(params.max_slant_deg).to_radians().cos();
    let [o0, o1, o2] = origin;
    // `x − cx` of the point, and `∂P/∂v`'s x term `(x − cx)·depth_scale / fx`.
    let ux: Vec<f64> = (0..w).map(|x| x as f64 - cx).collect();
    let jx: Vec<f64> = (0..w).map(|x| (x as f64 - cx) * ds / fx).collect();
    let nan = f32::NAN;
    let mut growable = 0usize;
    for y in 0..h {
        let uy = y as f64 - cy;
        let jy = (y as f64 - cy) * ds / fy;
        let (src, dst) = (y * w, (y + 1) * pw + 1);
        let rrow = &range[src..src + w];
        let crow = &features.curvedness.as_slice()[src..src + w];
        let prow = &features.plane.as_slice()[src..src + w];
        let grow_row = &mut geo[dst..dst + w];
        let lrow = &mut labels[dst..dst + w];
        let cols = ux.iter().zip(&jx).zip(grow_row.iter_mut().zip(lrow.iter_mut()));
        for (((&v, pl), &c), ((&uxx, &jxx), (g, lab))) in rrow.iter().zip(prow).zip(crow).zip(cols) {
            let fin = v.is_finite();
            let vf = f64::from(v);
            // Camera::point.
            let z = vf * ds;
            let p = [uxx * z / fx, uy * z / fy, z];
            // normal_with: tangents ∂P/∂x + a·∂P/∂v and ∂P/∂y + b·∂P/∂v (the Jacobian's zeros kept as terms).
            let (a, b) = (f64::from(pl[0]), f64::from(pl[1]));
            let tx = [z / fx + a * jxx, 0.0 + a * jy, 0.0 + a * ds];
            let ty = [0.0 + b * jxx, z / fy + b * jy, 0.0 + b * ds];
            let n = cross(tx, ty);
            let len = dot(n, n).sqrt();
            let n = [n[0] / len, n[1] / len, n[2] / len];
            // Camera::toward_sensor(p).
            let d = [-p[0], -p[1], -p[2]];
            let dn = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
            let toward = if dn > 0.0 { [d[0] / dn, d[1] / dn, d[2] / dn] } else { [0.0, 0.0, -1.0] };
            let cs = dot(n, toward);
            let n = if cs < 0.0 { [-n[0], -n[1], -n[2]] } else { n };
            let ok = fin
                & pl[0].is_finite()
                & pl[1].is_finite()
                & (c <= max_c)
                & (len > 0.0)
                & (len < f64::INFINITY);
            let grow = ok & (cs.abs() >= cos_slant);
            *g = [
                if fin { (p[0] - o0) as f32 } else { nan },
                if fin { (p[1] - o1) as f32 } else { nan },
                if fin { (p[2] - o2) as f32 } else { nan },
                if ok { n[0] as f32 } else { nan },
                if ok { n[1] as f32 } else { nan },
                if ok { n[2] as f32 } else { nan },
            ];
            *lab = if grow { 0 } else { BLOCKED };
            growable += usize::from(grow);
        }
    }
    growable
}

/// The stage on the buffers of `scratch`, writing `out` (whose grids are reused when of the right size).
#[inline(always)] // into `isa::dispatch` in `grow`: compiled for each instruction set
pub(crate) fn run(
    range: &RangeImage,
    features: &SurfaceFeatures,
    camera: &Camera,
    params: &Params,
    seed: u64,
    scratch: &mut Scratch,
    out_seg: &mut Segmentation,
) -> Info {
    let Scratch { geo, labels, k, queue, cand, merge: mbufs, fill_planes } = scratch;
    let (w, h) = (range.width() as usize, range.height() as usize);
    let n = w * h;
    let (origin, growable) = padded_inputs(range, features, camera, params, (geo, labels, k));
    let labels = &mut labels[..];
    // The per-label vectors get room for every label a frame of this size can have (memory that is reserved,
    // and touched only as far as used), so frames with more regions than the first reuse them too.
    let max_labels = (params.max_seeds as usize).min(n) + 1;
    mbufs.reserve(max_labels);
    fill_planes.clear();
    fill_planes.reserve(max_labels);
    let pw = w + 2;
    let p = pw as isize;
    let offs = [-1, -p, 1, p, -p - 1, -p + 1, p - 1, p + 1];
    let ctx =
        Ctx { w, h, pw, offs, eight: params.connectivity == 8, geo: &geo[..], k: &k[..], origin, camera };

    let mut info = Info::default();
    queue.clear();
    queue.reserve(n);
    let k_std = features.k_std.as_slice();
    let next = seed_and_grow(&ctx, params, seed, k_std, growable, (labels, queue, cand), &mut info);

    // Merge (on the padded grid: the frame is label 0, so it adds no adjacency).
    let toward = |p: [f64; 3]| ctx.toward(p);
    // The regions under `min_region_px` are dropped (unlabelled) by the merge's final rewrite of the labels.
    let min_px = params.min_region_px;
    let merged = merge(labels, next - 1, pw, ctx.eight, ctx.geo, ctx.k, params, min_px, &toward, mbufs);
    info.n_merged = merged.n_merged;
    info.n_merge_passes = merged.n_passes;
    // Whether `mbufs.stats` are the statistics of the current labels (as `region_stats_into` gives them): a merge
    // that merges nothing leaves them so, until the labels change.
    let mut fresh = merged.n_merged == 0;
    let mut merged_again = false;
    tracing::debug!(merged = info.n_merged, passes = info.n_merge_passes, "merged");

    let (used, n_dropped) = dropped(mbufs, min_px);
    #[cfg(test)]
    {
        // `used` names the labels left in the image (checked by every test of the crate).
        let mut scanned = vec![false; used.len()];
        labels.iter().filter(|&&l| l != 0).for_each(|&l| scanned[l as usize] = true);
        assert_eq!(used, scanned, "labels left");
    }
    info.n_dropped = n_dropped;
    fresh &= n_dropped == 0;
    if params.fill_unlabelled {
        info.n_filled_px = fill(&ctx, params, (&mbufs.stats, &used), labels, queue, fill_planes);
        fresh &= info.n_filled_px == 0;
        if params.merge_after_fill && info.n_filled_px > 0 {
            // Regions that a band of non-growable pixels kept apart touch now: merge again.
            let again = merge(labels, next - 1, pw, ctx.eight, ctx.geo, ctx.k, params, 0, &toward, mbufs);
            info.n_merged += again.n_merged;
            info.n_merge_passes += again.n_passes;
            fresh = again.n_merged == 0;
            if again.n_merged > 0 {
                // Its input's statistics were recomputed in raster order: only the regions it merged are stale.
                mbufs.mark_merged(next - 1);
                merged_again = true;
            }
        }
    }

    let MergeBufs { stats, dirty, .. } = mbufs;
    let stale = if fresh {
        Stale::None
    } else if merged_again {
        Stale::Marked(dirty)
    } else {
        Stale::All
    };
    (info.n_regions, info.n_unlabelled_valid_px) =
        relabel_into(&ctx, range, labels, (next, stale), stats, out_seg);
    borders_into(&out_seg.labels, params.c1_one_sided, &mut out_seg.c1);
    tracing::debug!(regions = info.n_regions, dropped = info.n_dropped, filled = info.n_filled_px, "done");
    info
}

/// Fills the padded buffers `(geo, labels, k)` of `run` (see [`geometry`]; K with a NaN frame) and returns the
/// origin of the 3D points, the point of the first valid pixel (relative points keep f32 storage and f64 sums
/// exact enough), and the number of growable pixels.
#[inline(always)] // into `run`, compiled for each instruction set
fn padded_inputs(
    range: &RangeImage,
    features: &SurfaceFeatures,
    camera: &Camera,
    params: &Params,
    (geo, labels, k): (&mut Vec<[f32; 6]>, &mut Vec<u32>, &mut Vec<f32>),
) -> ([f64; 3], usize) {
    let (w, h) = (range.width() as usize, range.height() as usize);
    let r = range.as_slice();
    let origin = (0..w * h)
        .find(|&i| r[i].is_finite())
        .and_then(|i| camera.point((i % w) as f64, (i / w) as f64, f64::from(r[i])))
        .unwrap_or([0.0; 3]);
    let growable = match *camera {
        Camera::Abw(cal) => geometry_abw(cal, r, features, params, (w, h), origin, (geo, labels)),
        Camera::Pinhole { fx, fy, cx, cy, depth_scale } if params.mode != Mode::Paper => {
            let cam = [fx, fy, cx, cy, depth_scale];
            geometry_pinhole(cam, r, features, params, (w, h), origin, (geo, labels))
        }
        Camera::Pinhole { .. } => {
            geometry(&PinholeProj(*camera), r, features, params, (w, h), origin, (geo, labels))
        }
        Camera::Grid => geometry(&GridProj, r, features, params, (w, h), origin, (geo, labels)),
    };
    let pw = w + 2;
    sized(k, pw * (h + 2));
    set_frame(k, pw, f32::NAN);
    for (y, row) in features.k.rows().enumerate() {
        let dst = (y + 1) * pw + 1;
        k[dst..dst + w].copy_from_slice(row);
    }
    (origin, growable)
}

/// Seeds and grows the regions: random draws without replacement among the candidates (pixels on the seed
/// stride whose `k_std` is at most the round's threshold), grown one after the other, with the threshold
/// doubled for another round while too few seeds were found. `growable` pixels are unlabelled at the start;
/// seeding stops when fewer than a kept region remain. Leaves the non-growable pixels at 0 (unlabelled) and
/// returns the next free label.
#[inline(always)] // into `run`, compiled for each instruction set
fn seed_and_grow(
    ctx: &Ctx<'_>,
    params: &Params,
    seed: u64,
    k_std: &[f32],
    growable: usize,
    (labels, queue, cand): (&mut [u32], &mut Vec<u32>, &mut Vec<u32>),
    info: &mut Info,
) -> u32 {
    let (w, h) = (ctx.w, ctx.h);
    let paper = params.mode == Mode::Paper;
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed);
    let mut t = params.t_sigma;
    let mut next = 1u32;
    let stride = params.seed_stride_px as usize;
    let off = stride / 2;
    // Unlabelled growable pixels left.
    let mut left = growable;
    let min_left = (params.min_region_px as usize).max(1);
    for round in 0..=MAX_RELAXATIONS {
        let last = round == MAX_RELAXATIONS && round > 0;
        let t_round = if last { f32::INFINITY } else { t };
        // The last round falls back to every pixel and no neighbourhood test.
        let (st, of, radius) = if last { (1, 0, 0) } else { (stride, off, params.seed_radius_px as usize) };
        let n_cand = seed_candidates(labels, k_std, (w, h), (st, of), t_round, cand);
        let cand = &mut cand[..n_cand];
        for i in (1..cand.len()).rev() {
            let j = rng.random_range(0..=i as u32) as usize;
            cand.swap(i, j);
        }
        for &c in cand.iter() {
            if info.n_seeds >= params.max_seeds || left < min_left {
                break;
            }
            info.n_draws += 1;
            let c = c as usize;
            if labels[c] != 0 || !seed_ok(ctx, params, c, radius, labels) {
                continue;
            }
            let grown = match (paper, ctx.eight) {
                (true, false) => grow_paper::<4>(ctx, params, c, next, labels, queue),
                (true, true) => grow_paper::<8>(ctx, params, c, next, labels, queue),
                (false, false) => grow_default::<4>(ctx, params, c, next, labels, queue),
                (false, true) => grow_default::<8>(ctx, params, c, next, labels, queue),
            };
            left -= grown;
            next += 1;
            info.n_seeds += 1;
        }
        info.t_sigma_used = t_round;
        if info.n_seeds >= params.max_seeds || info.n_seeds >= params.min_seeds || left == 0 {
            break;
        }
        info.n_relaxations += 1;
        t *= 2.0;
    }
    info.n_regions_grown = next - 1;
    tracing::debug!(seeds = info.n_seeds, draws = info.n_draws, relaxations = info.n_relaxations, "grown");
    for l in labels.iter_mut() {
        if *l == BLOCKED {
            *l = 0;
        }
    }
    next
}

/// Writes to `cand[..n]` the padded indices of the seed candidates of a `w × h` frame, in raster order, and returns
/// `n`: the pixels on the grid of stride `st` from `(of, of)` (clamped into the image) that are unlabelled and
/// growable (label 0) with `k_std ≤ t`. `cand` keeps at least `w·h` elements (values past `n` are left over).
/// Stride 1 (the default) tests 16 pixels of a row side by side into a bit mask and writes the indices of its set
/// bits, lowest first; the row's last `w mod 16` pixels write every index and advance by the test's outcome, without
/// branches (a test compares with the pixel-by-pixel loop).
#[inline(always)] // into `run`, compiled for each instruction set
fn seed_candidates(
    labels: &[u32],
    k_std: &[f32],
    (w, h): (usize, usize),
    (st, of): (usize, usize),
    t: f32,
    cand: &mut Vec<u32>,
) -> usize {
    let pw = w + 2;
    if cand.len() < w * h {
        cand.resize(w * h, 0);
    }
    let mut n = 0;
    if st == 1 {
        for y in 0..h {
            let src = (y + 1) * pw + 1;
            let (lrow, krow) = (&labels[src..src + w], &k_std[y * w..(y + 1) * w]);
            // At most `y·w` candidates precede this row, so its (at most `w`) fit.
            let out = &mut cand[n..n + w];
            let mut m = 0;
            let (lc, lt) = lrow.as_chunks::<16>();
            let (kc, kt) = krow.as_chunks::<16>();
            for (c, (ls, ks)) in lc.iter().zip(kc).enumerate() {
                let mut bits = 0u32;
                for j in 0..16 {
                    bits |= u32::from((ls[j] == 0) & (ks[j] <= t)) << j;
                }
                while bits != 0 {
                    out[m] = (src + 16 * c + bits.trailing_zeros() as usize) as u32;
                    m += 1;
                    bits &= bits - 1;
                }
            }
            let x0 = 16 * lc.len();
            for (x, (&l, &k)) in lt.iter().zip(kt).enumerate() {
                out[m] = (src + x0 + x) as u32;
                m += usize::from((l == 0) & (k <= t));
            }
            n += m;
        }
        return n;
    }
    for y in (of.min(h.saturating_sub(1))..h).step_by(st) {
        for x in (of.min(w.saturating_sub(1))..w).step_by(st) {
            let pi = (y + 1) * pw + x + 1;
            // Label 0 = unlabelled and growable.
            if labels[pi] == 0 && k_std[y * w + x] <= t {
                cand[n] = pi as u32;
                n += 1;
            }
        }
    }
    n
}

/// Which statistics of the last merge are not those of the current labels (see [`relabel_into`]).
#[derive(Debug, Clone, Copy)]
enum Stale<'a> {
    /// None: they are.
    None,
    /// The labels marked (one flag per label): a merge whose input statistics were recomputed merged them.
    Marked(&'a [bool]),
    /// Every label.
    All,
}

/// After a [`merge`] into `bufs` that unlabelled the regions of fewer than `min` pixels: which labels are still in
/// the image, and how many regions were dropped (the merge's roots with pixels, under `min`). The labels present
/// before the drop are the roots with pixels (a label whose pixels growth released entirely has none).
fn dropped(bufs: &MergeBufs, min: u32) -> (Vec<bool>, u32) {
    let stats = &bufs.stats;
    let present: Vec<bool> =
        (0..stats.len()).map(|l| l > 0 && stats[l].count > 0 && bufs.is_root(l)).collect();
    // Label 0 is not used.
    let used: Vec<bool> = present.iter().zip(stats).map(|(&p, s)| p & (s.count >= min)).collect();
    let n_dropped = present.iter().zip(&used).filter(|&(&p, &u)| p & !u).count() as u32;
    (used, n_dropped)
}

/// Final statistics under the current labels (labels below `next`; those `stale` does not name are kept, as
/// `stats` already holds them), then the labels relabelled 1..n in raster order of first pixel while copied out of the padded grid into
/// `out_seg.labels` (one pass), and the region records. Returns the number of regions and of valid pixels left
/// unlabelled.
fn relabel_into(
    ctx: &Ctx<'_>,
    range: &RangeImage,
    labels: &[u32],
    (next, stale): (u32, Stale<'_>),
    stats: &mut Vec<Stats>,
    out_seg: &mut Segmentation,
) -> (u32, u32) {
    let (w, h) = (ctx.w, ctx.h);
    match stale {
        Stale::None => {}
        Stale::Marked(dirty) => region_stats_update(labels, ctx.geo, ctx.k, stats, dirty),
        Stale::All => region_stats_into(labels, next - 1, ctx.geo, ctx.k, stats),
    }
    #[cfg(test)]
    {
        // The kept statistics equal recomputed ones, bit for bit (checked by every test of the crate; not in the
        // other crates' tests, where this allocation would count against the per-frame allocation test).
        let mut again = Vec::new();
        region_stats_into(labels, next - 1, ctx.geo, ctx.k, &mut again);
        let key = |s: &Stats| (s.count, s.n_k, s.first, s.sum_k.to_bits(), s.mom);
        assert!(stats.iter().map(key).eq(again.iter().map(key)), "kept statistics differ ({stale:?})");
    }
    let mut order: Vec<u32> = (1..next).filter(|&l| stats[l as usize].count > 0).collect();
    order.sort_unstable_by_key(|&l| stats[l as usize].first);
    let mut map = vec![0u32; stats.len()];
    for (new, &old) in order.iter().enumerate() {
        map[old as usize] = new as u32 + 1;
    }
    out_seg.regions.clear();
    out_seg.regions.extend(order.iter().zip(1..).map(|(&old, l)| region_of(ctx, l, &stats[old as usize])));
    let mut out = std::mem::take(&mut out_seg.labels).into_vec();
    out.clear();
    out.reserve(w * h);
    let mut unlabelled = 0u32;
    for (y, rrow) in range.as_slice().chunks_exact(w.max(1)).take(h).enumerate() {
        let src = ctx.pad(0, y);
        let lrow = &labels[src..src + w];
        out.extend(lrow.iter().map(|&l| map[l as usize]));
        unlabelled += lrow.iter().zip(rrow).map(|(&l, v)| u32::from(l == 0 && v.is_finite())).sum::<u32>();
    }
    let (wu, hu) = range.dimensions();
    out_seg.labels = Grid::from_vec(wu, hu, out).expect("same size");
    (order.len() as u32, unlabelled)
}

/// Unit normal (toward the sensor) of the local plane with slopes `(a, b)` (range units per
/// pixel) at pixel `(x, y)` with range `v`, from the camera's analytic Jacobian
/// (tangents `∂P/∂x + a·∂P/∂v` and `∂P/∂y + b·∂P/∂v`), and the cosine of its angle to the
/// direction toward the sensor.
#[cfg(test)]
fn local_normal(camera: &Camera, x: f64, y: f64, v: f64, a: f64, b: f64) -> Option<([f64; 3], f64)> {
    if !v.is_finite() {
        return None;
    }
    match *camera {
        Camera::Abw(cal) => normal_with(&AbwProj(cal), x, y, v, a, b),
        Camera::Pinhole { .. } => normal_with(&PinholeProj(*camera), x, y, v, a, b),
        Camera::Grid => normal_with(&GridProj, x, y, v, a, b),
    }
}

/// [`local_normal`] for a resolved camera model and a finite `v`.
#[inline]
fn normal_with<P: Proj>(proj: &P, x: f64, y: f64, v: f64, a: f64, b: f64) -> Option<([f64; 3], f64)> {
    let [px, py, pv] = proj.jacobian(x, y, v);
    let tx = [px[0] + a * pv[0], px[1] + a * pv[1], px[2] + a * pv[2]];
    let ty = [py[0] + b * pv[0], py[1] + b * pv[1], py[2] + b * pv[2]];
    let mut nrm = cross(tx, ty);
    let len = dot(nrm, nrm).sqrt();
    if !(len > 0.0 && len.is_finite()) {
        return None;
    }
    nrm = [nrm[0] / len, nrm[1] / len, nrm[2] / len];
    let toward = proj.toward(x, y, v);
    let c = dot(nrm, toward);
    if c < 0.0 {
        nrm = [-nrm[0], -nrm[1], -nrm[2]];
    }
    Some((nrm, c.abs()))
}

/// The region size at which the plane is refitted next, after a refit at `last` pixels: the
/// least `count > last` with `count − last ≥ max(refit_min, count / 4)`. The condition stays true
/// from there on (its left side grows by one per pixel, its right side by at most one).
fn refit_due(last: usize, refit_min: usize) -> usize {
    let ok = |d: usize| d >= refit_min && d >= (last + d) / 4;
    // `d = ⌈last / 3⌉` satisfies `d ≥ (last + d) / 4`; the least solution is at most two below.
    let mut d = refit_min.max(last.div_ceil(3)).max(1);
    while d > 1 && ok(d - 1) {
        d -= 1;
    }
    last + d
}

/// Default mode: grows region `id` from `seed` with the curvedness, normal-angle and plane
/// residual tests, refitting the region plane on an amortised schedule. `N` = connectivity.
#[inline(always)] // into `run`, compiled for each instruction set
fn grow_default<const N: usize>(
    ctx: &Ctx<'_>,
    params: &Params,
    seed: usize,
    id: u32,
    labels: &mut [u32],
    queue: &mut Vec<u32>,
) -> usize {
    let offs: [isize; N] = std::array::from_fn(|d| ctx.offs[d]);
    let cos_max = f64::from(params.max_angle_deg).to_radians().cos();
    let max_res = f64::from(params.max_residual);
    let rms_ratio = f64::from(params.residual_rms_ratio);
    // The residual limit: max_res, raised to rms_ratio × the region's RMS at each refit.
    let mut lim = max_res;
    let refit_min = params.refit_every_px as usize;
    let geo = ctx.geo;
    queue.clear();
    queue.push(seed as u32);
    labels[seed] = id;
    let mut plane = Plane::through(point_of(&geo[seed]), normal_of(&geo[seed]));
    // Moments of `queue[..summed]`. The queue holds the region's pixels in order of addition, so
    // summing it lazily at refit time gives the same sums as adding each pixel on acceptance,
    // keeps the hot loop short, and skips the pixels added after the last refit.
    let mut mom = Moments::default();
    let mut summed = 0usize;
    let mut count = 1usize;
    // The plane is refitted when the region reaches `due` pixels (see [`refit_due`]).
    let mut due = refit_due(0, refit_min);
    let mut head = 0;
    while head < queue.len() {
        let i = queue[head] as usize;
        head += 1;
        for &o in &offs {
            let j = i.wrapping_add_signed(o);
            // 0 = unlabelled and growable ([`BLOCKED`] covers the rest and the frame).
            if labels[j] != 0 {
                continue;
            }
            if rejects(&plane, &geo[j], lim, cos_max) {
                continue;
            }
            labels[j] = id;
            queue.push(j as u32);
            count += 1;
            if count >= due {
                for &p in &queue[summed..] {
                    mom.add(point_of(&geo[p as usize]));
                }
                summed = queue.len();
                if let Some(p) = Plane::fit(&mom, |p| ctx.toward(p)) {
                    plane = p;
                    lim = max_res.max(rms_ratio * plane.mean_sq.max(0.0).sqrt());
                }
                due = refit_due(count, refit_min);
            }
        }
    }
    if count <= params.release_max_px as usize {
        count = release(ctx, (id, cos_max, max_res, rms_ratio), labels, queue, count);
    }
    count
}

/// The growth test of the default mode fails for the pixel `g` against `plane`: its 3D point lies farther than `lim`
/// from the plane, or its normal makes an angle whose cosine is under `cos_max` with the plane's.
#[inline(always)] // into the growth loop, compiled for each instruction set
fn rejects(plane: &Plane, g: &[f32; 6], lim: f64, cos_max: f64) -> bool {
    plane.distance(point_of(g)).abs() > lim || dot(normal_of(g), plane.normal).abs() < cos_max
}

/// The pixels of region `id` (listed in `queue`, `count` of them still labelled `id`) that fail the growth test
/// (`cos_max`, `max(max_res, rms_ratio × RMS)`) against the plane fitted to the region are unlabelled, again while
/// any is (see `Params::release_max_px`); returns how many pixels the region keeps.
fn release(
    ctx: &Ctx<'_>,
    (id, cos_max, max_res, rms_ratio): (u32, f64, f64, f64),
    labels: &mut [u32],
    queue: &[u32],
    mut count: usize,
) -> usize {
    let geo = ctx.geo;
    loop {
        let mut mom = Moments::default();
        for &p in queue.iter().filter(|&&p| labels[p as usize] == id) {
            mom.add(point_of(&geo[p as usize]));
        }
        let Some(plane) = Plane::fit(&mom, |p| ctx.toward(p)) else { return count };
        let lim = max_res.max(rms_ratio * plane.mean_sq.max(0.0).sqrt());
        let before = count;
        for &p in queue {
            if labels[p as usize] == id && rejects(&plane, &geo[p as usize], lim, cos_max) {
                labels[p as usize] = 0;
                count -= 1;
            }
        }
        if count == before {
            return count;
        }
    }
}

/// Paper mode: grows region `id` from `seed`; a neighbour joins if its K is within
/// `max_k_diff` of the region's running mean K. `N` = connectivity.
fn grow_paper<const N: usize>(
    ctx: &Ctx<'_>,
    params: &Params,
    seed: usize,
    id: u32,
    labels: &mut [u32],
    queue: &mut Vec<u32>,
) -> usize {
    let offs: [isize; N] = std::array::from_fn(|d| ctx.offs[d]);
    let max_dk = f64::from(params.max_k_diff);
    let k = ctx.k;
    queue.clear();
    queue.push(seed as u32);
    labels[seed] = id;
    let mut sum_k = f64::from(k[seed]);
    let mut count = 1.0f64;
    let mut head = 0;
    while head < queue.len() {
        let i = queue[head] as usize;
        head += 1;
        for &o in &offs {
            let j = i.wrapping_add_signed(o);
            if labels[j] != 0 {
                continue;
            }
            let kj = f64::from(k[j]);
            if (kj - sum_k / count).abs() > max_dk {
                continue;
            }
            labels[j] = id;
            queue.push(j as u32);
            sum_k += kj;
            count += 1.0;
        }
    }
    count as usize
}

/// Whether `c` (padded index) may seed: every pixel of its `(2·radius+1)²` window lies in the
/// image, is unlabelled and growable, and passes the growth test of the mode against the seed's
/// own local plane (default mode) or K (paper mode). Rejects seeds on noise, near depth jumps and
/// on creases.
#[inline(always)] // into `run`, compiled for each instruction set
fn seed_ok(ctx: &Ctx<'_>, params: &Params, c: usize, radius: usize, labels: &[u32]) -> bool {
    if radius == 0 {
        return true;
    }
    let (w, h, pw) = (ctx.w, ctx.h, ctx.pw);
    // A window of radius 1 reaching out of the image holds a frame pixel, which is [`BLOCKED`] during seeding and
    // fails the label test below: only wider windows need the bounds test (and its two divisions).
    if radius > 1 {
        let (x, y) = (c % pw - 1, c / pw - 1);
        if x < radius || y < radius || x + radius >= w || y + radius >= h {
            return false;
        }
    }
    let paper = params.mode == Mode::Paper;
    let cos_max = f64::from(params.max_angle_deg).to_radians().cos();
    let max_res = f64::from(params.max_residual);
    let max_dk = params.max_k_diff;
    let kc = ctx.k[c];
    let plane = (!paper).then(|| Plane::through(point_of(&ctx.geo[c]), normal_of(&ctx.geo[c])));
    for dy in 0..=2 * radius {
        let row = c + dy * pw - radius * (pw + 1);
        for j in row..=row + 2 * radius {
            if labels[j] != 0 {
                return false;
            }
            match &plane {
                None => {
                    if (ctx.k[j] - kc).abs() > max_dk {
                        return false;
                    }
                }
                Some(pl) => {
                    if rejects(pl, &ctx.geo[j], max_res, cos_max) {
                        return false;
                    }
                }
            }
        }
    }
    true
}

/// Gives unlabelled valid pixels to the 4-adjacent region whose plane is nearest (if within
/// `fill_max_residual`), flooding breadth-first from the region borders. `used[l]`: label `l`
/// occurs in `labels`. Returns the pixel count.
#[inline(always)] // into `run`, compiled for each instruction set
fn fill(
    ctx: &Ctx<'_>,
    params: &Params,
    (stats, used): (&[Stats], &[bool]),
    labels: &mut [u32],
    queue: &mut Vec<u32>,
    planes: &mut Vec<Option<Plane>>,
) -> u32 {
    let max_res = f64::from(params.fill_max_residual);
    let offs: [isize; 4] = std::array::from_fn(|d| ctx.offs[d]);
    let geo = ctx.geo;
    // Planes of the surviving regions (fitted in both modes: this step is geometric).
    planes.clear();
    planes.extend(
        stats
            .iter()
            .zip(used)
            .map(|(s, &u)| if u && s.count >= 3 { Plane::fit(&s.mom, |p| ctx.toward(p)) } else { None }),
    );
    // Free = unlabelled with a 3D point; the frame has none, so a free pixel's neighbours exist.
    let free = |labels: &[u32], j: usize| labels[j] == 0 && geo[j][0].is_finite();
    queue.clear();
    // The free pixels next to a region, in index order (the frame is never free); the labels are tested before the
    // 3D point, so the points of pixels in unlabelled areas are not read.
    fill_starts(labels, geo, (ctx.w, ctx.h), queue);
    let mut filled = 0;
    let mut head = 0;
    while head < queue.len() {
        let i = queue[head] as usize;
        head += 1;
        if labels[i] != 0 {
            continue;
        }
        let p = point_of(&geo[i]);
        let mut best = (f64::INFINITY, 0u32);
        for &o in &offs {
            let l = labels[i.wrapping_add_signed(o)];
            if l == 0 {
                continue;
            }
            if let Some(pl) = &planes[l as usize] {
                let d = pl.distance(p).abs();
                if d < best.0 {
                    best = (d, l);
                }
            }
        }
        if best.0 <= max_res {
            labels[i] = best.1;
            filled += 1;
            for &o in &offs {
                let j = i.wrapping_add_signed(o);
                if free(labels, j) {
                    queue.push(j as u32);
                }
            }
        }
    }
    filled
}

/// Pushes onto `queue`, in index order, the padded indices of the free pixels (label 0 with a 3D point) that
/// have a labelled 4-neighbour, on a `w × h` padded grid. The label tests run branch-free on 16 pixels at a
/// time (a bit mask) and the 3D point is read only for the pixels they select.
#[inline(always)] // into `run`, compiled for each instruction set
fn fill_starts(labels: &[u32], geo: &[[f32; 6]], (w, h): (usize, usize), queue: &mut Vec<u32>) {
    const C: usize = 16;
    let pw = w + 2;
    for row in (pw + 1..).step_by(pw).take(h) {
        let up = &labels[row - pw..row - pw + w];
        let mid = &labels[row - 1..row + w + 1];
        let down = &labels[row + pw..row + pw + w];
        let mut x = 0;
        while x + C <= w {
            let u: &[u32; C] = up[x..x + C].try_into().expect("C labels");
            let d: &[u32; C] = down[x..x + C].try_into().expect("C labels");
            let m: &[u32; C + 2] = mid[x..x + C + 2].try_into().expect("C + 2 labels");
            let mut mask = 0u32;
            for k in 0..C {
                let hit = (m[k + 1] == 0) & ((m[k] | u[k] | m[k + 2] | d[k]) != 0);
                mask |= u32::from(hit) << k;
            }
            while mask != 0 {
                let i = row + x + mask.trailing_zeros() as usize;
                mask &= mask - 1;
                if geo[i][0].is_finite() {
                    queue.push(i as u32);
                }
            }
            x += C;
        }
        for i in row + x..row + w {
            if labels[i] == 0
                && (labels[i - 1] | labels[i - pw] | labels[i + 1] | labels[i + pw]) != 0
                && geo[i][0].is_finite()
            {
                queue.push(i as u32);
            }
        }
    }
}

/// The output record of final region `label`.
fn region_of(ctx: &Ctx<'_>, label: u32, s: &Stats) -> Region {
    let o = ctx.origin;
    let plane = Plane::fit(&s.mom, |p| ctx.toward(p)).unwrap_or_else(|| {
        let c = s.mom.centroid();
        let mut p = Plane::through(c, ctx.toward(c));
        p.mean_sq = p.mean_sq_distance(&s.mom);
        p
    });
    let nrm = plane.normal;
    Region {
        label,
        size_px: s.count,
        mean_k: s.mean_k() as f32,
        normal: [nrm[0] as f32, nrm[1] as f32, nrm[2] as f32],
        offset: (plane.offset - dot(nrm, o)) as f32,
        rms_residual: plane.mean_sq.max(0.0).sqrt() as f32,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    /// `fill_starts` pushes the pixels of the pixel-by-pixel scan, in the same order, on random label grids
    /// (widths around the 16-pixel chunk, labels mostly 0 or mostly set, points missing).
    #[test]
    fn fill_starts_matches_the_pixel_by_pixel_scan() {
        use rand::{RngExt, SeedableRng, rngs::Xoshiro256PlusPlus};
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(5);
        for (w, h) in [(1, 1), (15, 3), (16, 4), (17, 5), (40, 9), (63, 7)] {
            for zero_share in [0.1, 0.5, 0.9] {
                let pw = w + 2;
                let n = pw * (h + 2);
                let mut labels: Vec<u32> = (0..n)
                    .map(|_| if rng.random::<f64>() < zero_share { 0 } else { rng.random_range(1..5) })
                    .collect();
                set_frame(&mut labels, pw, 0);
                let geo: Vec<[f32; 6]> = (0..n)
                    .map(|_| if rng.random::<f64>() < 0.2 { [f32::NAN; 6] } else { [1.0; 6] })
                    .collect();
                let mut reference = Vec::new();
                for row in (pw + 1..).step_by(pw).take(h) {
                    for i in row..row + w {
                        let any = labels[i - 1] | labels[i - pw] | labels[i + 1] | labels[i + pw];
                        if labels[i] == 0 && any != 0 && geo[i][0].is_finite() {
                            reference.push(i as u32);
                        }
                    }
                }
                let mut queue = vec![7];
                queue.clear();
                fill_starts(&labels, &geo, (w, h), &mut queue);
                assert_eq!(queue, reference, "{w}x{h}, {zero_share}");
            }
        }
    }

    /// `release` unlabels the pixels of a region that fail the growth test against the plane fitted to the region
    /// (a normal 60° off the plane; a point 10 units off it), keeps the others, and leaves a region that passes its
    /// own test as it is.
    #[test]
    fn release_frees_what_the_region_s_own_plane_rejects() {
        let (w, h) = (12usize, 10usize);
        let pw = w + 2;
        let mut geo = vec![[f32::NAN; 6]; pw * (h + 2)];
        let mut queue = Vec::new();
        let (tilted, far) = ((2, 1), (7, 6));
        let (s, c) = (60f32.to_radians().sin(), 60f32.to_radians().cos());
        for y in 0..h {
            for x in 0..w {
                let i = (y + 1) * pw + x + 1;
                let z = if (x, y) == far { 10.0 } else { 0.01 * x as f32 };
                // Grid camera: the sensor looks along −z.
                let n = if (x, y) == tilted { [0.0, -s, -c] } else { [0.0, 0.0, -1.0] };
                geo[i] = [x as f32, y as f32, z, n[0], n[1], n[2]];
                queue.push(i as u32);
            }
        }
        let k = vec![0.0; geo.len()];
        let p = pw as isize;
        let ctx = Ctx {
            w,
            h,
            pw,
            offs: [-1, -p, 1, p, -p - 1, -p + 1, p - 1, p + 1],
            eight: false,
            geo: &geo,
            k: &k,
            origin: [0.0; 3],
            camera: &Camera::Grid,
        };
        let id = 3;
        let mut labels = vec![0u32; geo.len()];
        queue.iter().for_each(|&q| labels[q as usize] = id);
        let test = (id, 40f64.to_radians().cos(), 3.0, 3.0);
        let kept = release(&ctx, test, &mut labels, &queue, queue.len());
        let at = |labels: &[u32], (x, y): (usize, usize)| labels[(y + 1) * pw + x + 1];
        assert_eq!(kept, w * h - 2);
        assert_eq!((at(&labels, tilted), at(&labels, far)), (0, 0), "both released");
        assert_eq!(queue.iter().filter(|&&q| labels[q as usize] == id).count(), kept, "the others kept");
        let before = labels.clone();
        assert_eq!(release(&ctx, test, &mut labels, &queue, kept), kept, "a fixpoint");
        assert_eq!(labels, before);
    }

    /// `seed_candidates` gives the candidates of the pixel-by-pixel loop, in the same order, on random grids
    /// (labels 0, `BLOCKED` or a region, NaN and random `k_std`), every stride and offset, in a buffer of
    /// other values.
    #[test]
    fn seed_candidates_match_the_pixel_by_pixel_loop() {
        use rand::{RngExt, SeedableRng, rngs::Xoshiro256PlusPlus};
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(9);
        let mut cand = vec![u32::MAX; 3];
        for case in 0..300 {
            let (w, h) = (rng.random_range(1..40usize), rng.random_range(1..30usize));
            let pw = w + 2;
            let zero_share = [0.05, 0.5, 0.95, 1.0][case % 4];
            let labels: Vec<u32> = (0..pw * (h + 2))
                .map(|_| match rng.random::<f64>() {
                    r if r < zero_share => 0,
                    r if r < 0.5 + zero_share / 2.0 => BLOCKED,
                    _ => rng.random_range(1..9),
                })
                .collect();
            let k_std: Vec<f32> =
                (0..w * h).map(|i| if i % 13 == 5 { f32::NAN } else { rng.random_range(0.0..0.2) }).collect();
            let (st, of) =
                if case % 3 == 0 { (rng.random_range(2..5), rng.random_range(0..4)) } else { (1, 0) };
            let t = [0.1, f32::INFINITY][case % 2];
            let mut want = Vec::new();
            for y in (of.min(h - 1)..h).step_by(st) {
                for x in (of.min(w - 1)..w).step_by(st) {
                    let pi = (y + 1) * pw + x + 1;
                    if labels[pi] == 0 && k_std[y * w + x] <= t {
                        want.push(pi as u32);
                    }
                }
            }
            let n = seed_candidates(&labels, &k_std, (w, h), (st, of), t, &mut cand);
            assert_eq!(&cand[..n], &want[..], "case {case}: {w}x{h}, stride {st}, offset {of}");
            cand.iter_mut().for_each(|c| *c = 7);
        }
    }

    /// The analytic-Jacobian normal equals the normal of back-projected neighbours on the plane.
    #[test]
    fn local_normal_matches_back_projection() {
        let pin = Camera::Pinhole { fx: 500.0, fy: 520.0, cx: 320.0, cy: 240.0, depth_scale: 0.001 };
        for (cam, v) in [(Camera::ABW0, 120.0), (Camera::ABW1, 60.0), (pin, 2000.0), (Camera::Grid, 50.0)] {
            let (x, y, a, b) = (100.0, 300.0, 0.7, -0.4);
            let (n, c) = local_normal(&cam, x, y, v, a, b).unwrap();
            let p = |dx: f64, dy: f64| cam.point(x + dx, y + dy, v + a * dx + b * dy).unwrap();
            let (p0, p1, p2) = (p(0.0, 0.0), p(1.0, 0.0), p(0.0, 1.0));
            let t1 = [p1[0] - p0[0], p1[1] - p0[1], p1[2] - p0[2]];
            let t2 = [p2[0] - p0[0], p2[1] - p0[1], p2[2] - p0[2]];
            // The normal is perpendicular to both (nearly linear over one pixel) tangents.
            let l1 = dot(t1, t1).sqrt();
            let l2 = dot(t2, t2).sqrt();
            assert_relative_eq!(dot(n, t1) / l1, 0.0, epsilon = 1e-3);
            assert_relative_eq!(dot(n, t2) / l2, 0.0, epsilon = 1e-3);
            assert!(dot(n, cam.toward_sensor(p0)) > 0.0 && c > 0.0 && c <= 1.0);
        }
    }

    /// The closed-form ABW geometry equals the general Jacobian path: same growable pixels,
    /// points within f32 rounding, normals to 1e-6, on both calibrations and both modes.
    #[test]
    fn abw_fast_geometry_matches_general_path() {
        let s = crate::testutil::abw_like_scene(96);
        let (w, h) = (96usize, 96usize);
        let r = s.range.as_slice();
        for cal in [AbwCalibration::CAL0, AbwCalibration::CAL1] {
            for params in
                [Params::default(), Params::paper(), Params { max_slant_deg: 40.0, ..Params::default() }]
            {
                let origin = Camera::Abw(cal).point(3.0, 5.0, 100.0).unwrap();
                let (mut g0, mut l0, mut g1, mut l1) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
                let n0 = geometry(&AbwProj(cal), r, &s.features, &params, (w, h), origin, (&mut g0, &mut l0));
                let n1 = geometry_abw(cal, r, &s.features, &params, (w, h), origin, (&mut g1, &mut l1));
                assert_eq!((n0, &l0), (n1, &l1));
                assert!(n0 > 1000, "{n0} growable pixels");
                for (a, b) in g0.iter().zip(&g1) {
                    for c in 0..6 {
                        assert_eq!(a[c].is_nan(), b[c].is_nan(), "{a:?} vs {b:?}");
                        if a[c].is_finite() {
                            let tol = if c < 3 { 1e-6 * a[c].abs().max(1.0) } else { 1e-6 };
                            assert!((a[c] - b[c]).abs() <= tol, "{a:?} vs {b:?}");
                        }
                    }
                }
            }
        }
    }

    /// The pinhole fast path equals the general path bit for bit: records, labels and count, with NaN and
    /// infinite ranges and slopes, on a camera whose centre is off the image.
    #[test]
    fn pinhole_fast_geometry_is_bit_identical_to_the_general_path() {
        let mut s = crate::testutil::abw_like_scene(96);
        let (w, h) = (96usize, 96usize);
        let r = s.range.as_mut_slice();
        r[5] = f32::INFINITY;
        r[17] = f32::NAN;
        r[300] = 0.0;
        let pl = s.features.plane.as_mut_slice();
        pl[40][0] = f32::NAN;
        pl[41][1] = f32::INFINITY;
        pl[42] = [0.0, 0.0, 0.0];
        pl[43][0] = -1e30;
        for (fx, cx, ds) in [(525.0, 47.5, 0.001), (60.0, 130.0, 0.2), (80.0, -20.0, 1.0)] {
            let cam = Camera::Pinhole { fx, fy: fx * 1.1, cx, cy: cx * 0.8, depth_scale: ds };
            for params in
                [Params::default(), Params { max_slant_deg: 40.0, max_curvedness: 0.05, ..Params::default() }]
            {
                let origin = cam.point(3.0, 5.0, 100.0).unwrap();
                let (mut g0, mut l0, mut g1, mut l1) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
                let n0 =
                    geometry(&PinholeProj(cam), r, &s.features, &params, (w, h), origin, (&mut g0, &mut l0));
                // A buffer of the previous frame, full of other values.
                let mut g1b = vec![[7.0f32; 6]; g0.len()];
                std::mem::swap(&mut g1, &mut g1b);
                let cam5 = [fx, fx * 1.1, cx, cx * 0.8, ds];
                let n1 = geometry_pinhole(cam5, r, &s.features, &params, (w, h), origin, (&mut g1, &mut l1));
                assert_eq!((n0, &l0), (n1, &l1));
                assert!(n0 > 100, "{n0} growable pixels");
                let bits = |g: &[[f32; 6]]| g.iter().flatten().map(|v| v.to_bits()).collect::<Vec<_>>();
                assert_eq!(bits(&g0), bits(&g1));
            }
        }
    }

    /// Random slopes and ranges: the closed-form normal equals `normal_with` (f64, 1e-12).
    #[test]
    fn abw_closed_form_normal_matches_jacobian() {
        use rand::{RngExt, SeedableRng, rngs::Xoshiro256PlusPlus};
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(11);
        for _ in 0..1000 {
            let cal =
                if rng.random_range(0..2u32) == 0 { AbwCalibration::CAL0 } else { AbwCalibration::CAL1 };
            let (x, y) = (rng.random_range(0..512u32), rng.random_range(0..512u32));
            let v = rng.random_range(1.0f32..255.0);
            let (a, b) = (rng.random_range(-30.0f32..30.0), rng.random_range(-30.0f32..30.0));
            let (n_ref, c_ref) = normal_with(
                &AbwProj(cal),
                f64::from(x),
                f64::from(y),
                f64::from(v),
                f64::from(a),
                f64::from(b),
            )
            .unwrap();
            let (n, ok) = abw_normal(
                &AbwNormal::new(cal),
                f64::from(a),
                f64::from(b),
                f64::from(v),
                f64::from(x) - 255.0,
                255.0 - f64::from(y),
            );
            assert!(ok);
            for c in 0..3 {
                assert_relative_eq!(n[c], n_ref[c], epsilon = 1e-12);
            }
            assert_relative_eq!(n[2], c_ref, epsilon = 1e-12);
        }
    }

    /// The closed form of the refit schedule equals its definition, checked count by count.
    #[test]
    fn refit_due_is_the_first_count_meeting_the_schedule() {
        for refit_min in [1usize, 2, 3, 16, 50] {
            for last in 0..5000usize {
                let first = (last + 1..).find(|&c| c - last >= refit_min.max(c / 4)).unwrap();
                assert_eq!(refit_due(last, refit_min), first, "last {last}, refit_min {refit_min}");
            }
        }
    }

    #[test]
    fn set_frame_marks_exactly_the_frame() {
        for (w, h) in [(1usize, 1usize), (3, 2), (5, 4), (2, 7)] {
            let pw = w + 2;
            let mut a = vec![0u8; pw * (h + 2)];
            set_frame(&mut a, pw, 1);
            for (i, &v) in a.iter().enumerate() {
                let (x, y) = (i % pw, i / pw);
                let frame = x == 0 || y == 0 || x == pw - 1 || y == h + 1;
                assert_eq!(v == 1, frame, "w {w} h {h} at ({x}, {y})");
            }
        }
    }
}
