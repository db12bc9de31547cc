//! Seeding, breadth-first growth, small-region removal, fill and final relabelling.

use crate::merge::{Stats, merge, region_stats};
use crate::plane::{Moments, Plane, cross, dot};
use crate::{Info, MAX_RELAXATIONS, Mode, Params, Segmentation, borders};
use rand::{RngExt, SeedableRng, rngs::Xoshiro256PlusPlus};
use rangeimage::{Camera, Grid, RangeImage, Region, SurfaceFeatures};

/// Up to 8 in-bounds neighbours of pixel `i = y·w + x`, in the fixed order left, up, right,
/// down (then the diagonals for 8-connectivity).
#[inline]
fn neighbours(i: usize, x: usize, y: usize, w: usize, h: usize, eight: bool) -> ([usize; 8], usize) {
    let mut out = [0usize; 8];
    let mut n = 0;
    let mut push = |j: usize| {
        out[n] = j;
        n += 1;
    };
    if x > 0 {
        push(i - 1);
    }
    if y > 0 {
        push(i - w);
    }
    if x + 1 < w {
        push(i + 1);
    }
    if y + 1 < h {
        push(i + w);
    }
    if eight {
        if x > 0 && y > 0 {
            push(i - w - 1);
        }
        if x + 1 < w && y > 0 {
            push(i - w + 1);
        }
        if x > 0 && y + 1 < h {
            push(i + w - 1);
        }
        if x + 1 < w && y + 1 < h {
            push(i + w + 1);
        }
    }
    (out, n)
}

#[inline]
fn f64x3(p: [f32; 3]) -> [f64; 3] {
    [f64::from(p[0]), f64::from(p[1]), f64::from(p[2])]
}

/// The per-image data growth reads.
struct Ctx<'a> {
    w: usize,
    h: usize,
    eight: bool,
    /// 3D points relative to `origin` (NaN where the range is not finite).
    pts: Vec<[f32; 3]>,
    /// Pixels that may seed and join regions.
    growable: Vec<bool>,
    /// Default mode: unit local normals toward the sensor (empty in paper mode).
    normals: Vec<[f32; 3]>,
    k: &'a [f32],
    origin: [f64; 3],
    camera: &'a Camera,
}

impl Ctx<'_> {
    fn toward(&self, p_rel: [f64; 3]) -> [f64; 3] {
        let o = self.origin;
        self.camera.toward_sensor([p_rel[0] + o[0], p_rel[1] + o[1], p_rel[2] + o[2]])
    }
}

pub(crate) fn run(
    range: &RangeImage,
    features: &SurfaceFeatures,
    camera: &Camera,
    params: &Params,
    seed: u64,
) -> (Segmentation, Info) {
    let (wu, hu) = range.dimensions();
    let (w, h) = (wu as usize, hu as usize);
    let n = w * h;
    let r = range.as_slice();
    let paper = params.mode == Mode::Paper;
    let k = features.k.as_slice();
    let k_std = features.k_std.as_slice();

    // 3D points relative to the first valid pixel's point (keeps f32 storage and f64 sums exact enough).
    let origin = (0..n)
        .find(|&i| r[i].is_finite())
        .and_then(|i| camera.point((i % w) as f64, (i / w) as f64, f64::from(r[i])))
        .unwrap_or([0.0; 3]);
    let mut pts = vec![[f32::NAN; 3]; n];
    for y in 0..h {
        for x in 0..w {
            let i = y * w + x;
            if let Some(p) = camera.point(x as f64, y as f64, f64::from(r[i])) {
                pts[i] = [(p[0] - origin[0]) as f32, (p[1] - origin[1]) as f32, (p[2] - origin[2]) as f32];
            }
        }
    }

    let mut growable = vec![false; n];
    let mut normals = Vec::new();
    if paper {
        for i in 0..n {
            growable[i] = r[i].is_finite() && k[i].is_finite();
        }
    } else {
        normals = vec![[f32::NAN; 3]; n];
        let curv = features.curvedness.as_slice();
        let plane = features.plane.as_slice();
        let max_c = params.max_curvedness;
        let cos_slant = f64::from(params.max_slant_deg).to_radians().cos();
        for y in 0..h {
            for x in 0..w {
                let i = y * w + x;
                let v = r[i];
                let [a, b, _] = plane[i];
                if !(v.is_finite() && a.is_finite() && b.is_finite() && curv[i] <= max_c) {
                    continue;
                }
                if let Some((nrm, slant_cos)) =
                    local_normal(camera, x as f64, y as f64, f64::from(v), f64::from(a), f64::from(b))
                {
                    normals[i] = [nrm[0] as f32, nrm[1] as f32, nrm[2] as f32];
                    growable[i] = slant_cos >= cos_slant;
                }
            }
        }
    }
    let ctx = Ctx { w, h, eight: params.connectivity == 8, pts, growable, normals, k, origin, camera };

    // Seeds: random draws without replacement among the candidates, grown one after the other.
    let mut info = Info::default();
    let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed);
    let mut labels = vec![0u32; n];
    let mut queue: Vec<u32> = Vec::with_capacity(n);
    let mut cand: Vec<u32> = Vec::new();
    let mut t = params.t_sigma;
    let mut next = 1u32;
    let stride = params.seed_stride_px as usize;
    let off = stride / 2;
    // Unlabelled growable pixels left; seeding stops when fewer than a kept region remain.
    let mut left = ctx.growable.iter().filter(|&&g| g).count();
    let min_left = (params.min_region_px as usize).max(1);
    for round in 0..=MAX_RELAXATIONS {
        let last = round == MAX_RELAXATIONS && round > 0;
        let t_round = if last { f32::INFINITY } else { t };
        // The last round falls back to every pixel and no neighbourhood test.
        let (st, of, radius) = if last { (1, 0, 0) } else { (stride, off, params.seed_radius_px as usize) };
        cand.clear();
        for y in (of.min(h.saturating_sub(1))..h).step_by(st) {
            for x in (of.min(w.saturating_sub(1))..w).step_by(st) {
                let i = y * w + x;
                if labels[i] == 0 && ctx.growable[i] && k_std[i] <= t_round {
                    cand.push(i as u32);
                }
            }
        }
        for i in (1..cand.len()).rev() {
            let j = rng.random_range(0..=i as u32) as usize;
            cand.swap(i, j);
        }
        for &c in &cand {
            if info.n_seeds >= params.max_seeds || left < min_left {
                break;
            }
            info.n_draws += 1;
            let c = c as usize;
            if labels[c] != 0 || !seed_ok(&ctx, params, c, radius, &labels) {
                continue;
            }
            let grown = if paper {
                grow_paper(&ctx, params, c, next, &mut labels, &mut queue)
            } else {
                grow_default(&ctx, params, c, next, &mut labels, &mut queue)
            };
            left -= grown;
            next += 1;
            info.n_seeds += 1;
        }
        info.t_sigma_used = t_round;
        if info.n_seeds >= params.min_seeds || info.n_seeds >= params.max_seeds || left == 0 {
            break;
        }
        info.n_relaxations += 1;
        t *= 2.0;
    }
    info.n_regions_grown = next - 1;
    tracing::debug!(seeds = info.n_seeds, draws = info.n_draws, relaxations = info.n_relaxations, "grown");

    // Merge.
    let toward = |p: [f64; 3]| ctx.toward(p);
    let merged = merge(&mut labels, next - 1, w, ctx.eight, &ctx.pts, k, params, &toward);
    info.n_merged = merged.n_merged;
    info.n_merge_passes = merged.n_passes;
    let stats = merged.stats;
    tracing::debug!(merged = info.n_merged, passes = info.n_merge_passes, "merged");

    // Drop small regions.
    let min = params.min_region_px;
    let mut keep = vec![false; stats.len()];
    for (l, s) in stats.iter().enumerate().skip(1) {
        // Only roots still carry their pixels; merged-away labels no longer occur in `labels`.
        keep[l] = s.count >= min;
    }
    let mut present = vec![false; stats.len()];
    for l in labels.iter_mut() {
        if *l != 0 {
            present[*l as usize] = true;
            if !keep[*l as usize] {
                *l = 0;
            }
        }
    }
    info.n_dropped = (1..stats.len()).filter(|&l| present[l] && !keep[l]).count() as u32;

    if params.fill_unlabelled {
        info.n_filled_px = fill(&ctx, params, &stats, &mut labels, &mut queue);
    }

    // Relabel 1..n in raster order of first pixel.
    let mut map = vec![0u32; stats.len()];
    let mut n_regions = 0u32;
    for l in labels.iter_mut() {
        if *l != 0 {
            let m = &mut map[*l as usize];
            if *m == 0 {
                n_regions += 1;
                *m = n_regions;
            }
            *l = *m;
        }
    }
    info.n_regions = n_regions;
    info.n_unlabelled_valid_px = (0..n).filter(|&i| labels[i] == 0 && r[i].is_finite()).count() as u32;

    let final_stats = region_stats(&labels, n_regions, &ctx.pts, k);
    let regions = (1..=n_regions).map(|l| region_of(&ctx, l, &final_stats[l as usize])).collect();
    let labels = Grid::from_vec(wu, hu, labels).expect("same size");
    let c1 = borders(&labels, params.c1_one_sided);
    tracing::debug!(regions = info.n_regions, dropped = info.n_dropped, filled = info.n_filled_px, "done");
    (Segmentation { labels, regions, c1 }, info)
}

/// Unit normal (toward the sensor) of the local plane with slopes `(a, b)` (range units per
/// pixel) at pixel `(x, y)` with range `v`, from the camera's analytic Jacobian
/// (tangents `∂P/∂x + a·∂P/∂v` and `∂P/∂y + b·∂P/∂v`), and the cosine of its angle to the
/// direction toward the sensor.
fn local_normal(camera: &Camera, x: f64, y: f64, v: f64, a: f64, b: f64) -> Option<([f64; 3], f64)> {
    if !v.is_finite() {
        return None;
    }
    let (px, py, pv) = match *camera {
        Camera::Abw(cal) => {
            let f = cal.f.abs();
            let d = v / cal.scal + cal.offset;
            (
                [d / f, 0.0, 0.0],
                [0.0, -d / (cal.c * f), 0.0],
                [(x - 255.0) / (cal.scal * f), (255.0 - y) / (cal.c * cal.scal * f), -1.0 / cal.scal],
            )
        }
        Camera::Pinhole { fx, fy, cx, cy, depth_scale } => {
            let z = v * depth_scale;
            (
                [z / fx, 0.0, 0.0],
                [0.0, z / fy, 0.0],
                [(x - cx) * depth_scale / fx, (y - cy) * depth_scale / fy, depth_scale],
            )
        }
        Camera::Grid => ([1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]),
    };
    let tx = [px[0] + a * pv[0], px[1] + a * pv[1], px[2] + a * pv[2]];
    let ty = [py[0] + b * pv[0], py[1] + b * pv[1], py[2] + b * pv[2]];
    let mut nrm = cross(tx, ty);
    let len = dot(nrm, nrm).sqrt();
    if !(len > 0.0 && len.is_finite()) {
        return None;
    }
    nrm = [nrm[0] / len, nrm[1] / len, nrm[2] / len];
    let toward = match camera {
        Camera::Abw(_) => [0.0, 0.0, 1.0],
        Camera::Grid => [0.0, 0.0, -1.0],
        Camera::Pinhole { .. } => camera.toward_sensor(camera.point(x, y, v)?),
    };
    let c = dot(nrm, toward);
    if c < 0.0 {
        nrm = [-nrm[0], -nrm[1], -nrm[2]];
    }
    Some((nrm, c.abs()))
}

/// Default mode: grows region `id` from `seed` with the curvedness, normal-angle and plane
/// residual tests, refitting the region plane on an amortised schedule.
fn grow_default(
    ctx: &Ctx<'_>,
    params: &Params,
    seed: usize,
    id: u32,
    labels: &mut [u32],
    queue: &mut Vec<u32>,
) -> usize {
    let (w, h) = (ctx.w, ctx.h);
    let cos_max = f64::from(params.max_angle_deg).to_radians().cos();
    let max_res = f64::from(params.max_residual);
    let refit_min = params.refit_every_px as usize;
    queue.clear();
    queue.push(seed as u32);
    labels[seed] = id;
    let p0 = f64x3(ctx.pts[seed]);
    let mut plane = Plane::through(p0, f64x3(ctx.normals[seed]));
    let mut mom = Moments::default();
    mom.add(p0);
    let mut count = 1usize;
    let mut last_refit = 0usize;
    let mut head = 0;
    while head < queue.len() {
        let i = queue[head] as usize;
        head += 1;
        let (nb, nn) = neighbours(i, i % w, i / w, w, h, ctx.eight);
        for &j in &nb[..nn] {
            if labels[j] != 0 || !ctx.growable[j] {
                continue;
            }
            let q = f64x3(ctx.pts[j]);
            if plane.distance(q).abs() > max_res {
                continue;
            }
            if dot(f64x3(ctx.normals[j]), plane.normal).abs() < cos_max {
                continue;
            }
            labels[j] = id;
            queue.push(j as u32);
            mom.add(q);
            count += 1;
            if count - last_refit >= refit_min.max(count / 4) {
                if let Some(p) = mom.fit(|p| ctx.toward(p)) {
                    plane = p;
                }
                last_refit = count;
            }
        }
    }
    count
}

/// Paper mode: grows region `id` from `seed`; a neighbour joins if its K is within
/// `max_k_diff` of the region's running mean K.
fn grow_paper(
    ctx: &Ctx<'_>,
    params: &Params,
    seed: usize,
    id: u32,
    labels: &mut [u32],
    queue: &mut Vec<u32>,
) -> usize {
    let (w, h) = (ctx.w, ctx.h);
    let max_dk = f64::from(params.max_k_diff);
    queue.clear();
    queue.push(seed as u32);
    labels[seed] = id;
    let mut sum_k = f64::from(ctx.k[seed]);
    let mut count = 1.0f64;
    let mut head = 0;
    while head < queue.len() {
        let i = queue[head] as usize;
        head += 1;
        let (nb, nn) = neighbours(i, i % w, i / w, w, h, ctx.eight);
        for &j in &nb[..nn] {
            if labels[j] != 0 || !ctx.growable[j] {
                continue;
            }
            let kj = f64::from(ctx.k[j]);
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

/// Whether `c` may seed: every pixel of its `(2·radius+1)²` window lies in the image, is unlabelled
/// and growable, and passes the growth test of the mode against the seed's own local plane (default
/// mode) or K (paper mode). Rejects seeds on noise, near depth jumps and on creases.
fn seed_ok(ctx: &Ctx<'_>, params: &Params, c: usize, radius: usize, labels: &[u32]) -> bool {
    if radius == 0 {
        return true;
    }
    let (w, h) = (ctx.w, ctx.h);
    let (x, y) = (c % w, c / w);
    if x < radius || y < radius || x + radius >= w || y + radius >= h {
        return false;
    }
    let paper = ctx.normals.is_empty();
    let cos_max = f64::from(params.max_angle_deg).to_radians().cos();
    let max_res = f64::from(params.max_residual);
    let max_dk = params.max_k_diff;
    let kc = ctx.k[c];
    let plane = (!paper).then(|| Plane::through(f64x3(ctx.pts[c]), f64x3(ctx.normals[c])));
    for yy in y - radius..=y + radius {
        for j in yy * w + x - radius..=yy * w + x + radius {
            if labels[j] != 0 || !ctx.growable[j] {
                return false;
            }
            match &plane {
                None => {
                    if (ctx.k[j] - kc).abs() > max_dk {
                        return false;
                    }
                }
                Some(pl) => {
                    if pl.distance(f64x3(ctx.pts[j])).abs() > max_res
                        || dot(f64x3(ctx.normals[j]), pl.normal).abs() < cos_max
                    {
                        return false;
                    }
                }
            }
        }
    }
    true
}

/// Gives unlabelled valid pixels to the 4-adjacent region whose plane is nearest (if within
/// `fill_max_residual`), flooding breadth-first from the region borders. Returns the pixel count.
fn fill(ctx: &Ctx<'_>, params: &Params, stats: &[Stats], labels: &mut [u32], queue: &mut Vec<u32>) -> u32 {
    let (w, h) = (ctx.w, ctx.h);
    let max_res = f64::from(params.fill_max_residual);
    // Planes of the surviving regions (fitted in both modes: this step is geometric).
    let mut used = vec![false; stats.len()];
    for &l in labels.iter() {
        used[l as usize] = true;
    }
    let planes: Vec<Option<Plane>> = stats
        .iter()
        .zip(&used)
        .map(|(s, &u)| if u && s.count >= 3 { s.mom.fit(|p| ctx.toward(p)) } else { None })
        .collect();
    let free = |labels: &[u32], j: usize| labels[j] == 0 && ctx.pts[j][0].is_finite();
    queue.clear();
    for i in 0..w * h {
        if free(labels, i) {
            let (nb, nn) = neighbours(i, i % w, i / w, w, h, false);
            if nb[..nn].iter().any(|&j| labels[j] != 0) {
                queue.push(i as u32);
            }
        }
    }
    let mut filled = 0;
    let mut head = 0;
    while head < queue.len() {
        let i = queue[head] as usize;
        head += 1;
        if labels[i] != 0 {
            continue;
        }
        let p = f64x3(ctx.pts[i]);
        let (nb, nn) = neighbours(i, i % w, i / w, w, h, false);
        let mut best = (f64::INFINITY, 0u32);
        for &j in &nb[..nn] {
            let l = labels[j];
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
            for &j in &nb[..nn] {
                if free(labels, j) {
                    queue.push(j as u32);
                }
            }
        }
    }
    filled
}

/// The output record of final region `label`.
fn region_of(ctx: &Ctx<'_>, label: u32, s: &Stats) -> Region {
    let o = ctx.origin;
    let plane = s.mom.fit(|p| ctx.toward(p)).unwrap_or_else(|| {
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
}
