//! Step 4 of the final segmentation (`regions` mode): adjacent regions merged over borders the
//! edges do not support, or inside one region-growing region, where their planes agree.

use crate::plane::{Plane, fit_plane, mean_sq_residual};
use crate::{Params, Pieces, Scene};
use planefit::Moments;
use rangeimage::union_find::find;
use rangeimage::{Camera, EdgeMap, RangeImage};

/// The border between two adjacent components, over 4-adjacencies.
#[derive(Debug, Clone, Copy, Default)]
struct Border {
    /// Border pixels (each 4-adjacency counts its two pixels).
    n: u32,
    /// Those within 1 px of an edge pixel.
    near: u32,
    /// The sum of their distances to the other component's plane.
    gap: f64,
}

/// Per adjacent pair of components (smaller label, larger label): their border; the pairs in sorted order once
/// [`borders_into`] has finished. Each pair's sums take its border pixels in raster order, as a map would.
#[derive(Debug, Default)]
struct Borders {
    /// The pairs and their borders.
    entries: Vec<((u32, u32), Border)>,
    /// While collecting: per smaller label, 1 + the index in `entries` of its latest pair (0 = none).
    head: Vec<u32>,
    /// While collecting: per entry, 1 + the index of the previous pair with the same smaller label (0 = none).
    next: Vec<u32>,
}

impl Borders {
    /// Empties the table for labels `1..=n`; `room` pairs are reserved (untouched memory) so that later frames
    /// reuse it.
    fn reset(&mut self, n: usize, room: usize) {
        self.head.clear();
        self.head.reserve(room);
        self.head.resize(n + 1, 0);
        self.entries.clear();
        self.entries.reserve(room * 3);
        self.next.clear();
        self.next.reserve(room * 3);
    }

    /// The index in `entries` of pair `key` (smaller label first), appended if new.
    #[inline]
    fn index(&mut self, key: (u32, u32)) -> usize {
        let mut k = self.head[key.0 as usize];
        while k != 0 {
            if self.entries[k as usize - 1].0 == key {
                return k as usize - 1;
            }
            k = self.next[k as usize - 1];
        }
        self.entries.push((key, Border::default()));
        self.next.push(self.head[key.0 as usize]);
        self.head[key.0 as usize] = self.entries.len() as u32;
        self.entries.len() - 1
    }

    /// The number of adjacent pairs.
    fn len(&self) -> usize {
        self.entries.len()
    }
}

/// How a candidate pair may merge.
#[derive(Debug, Clone, Copy)]
struct Kind {
    /// The plane test of [`PlaneTest::agree`] applies: the border is weakly supported (`Some(true)`)
    /// or lies inside one region-growing region (`Some(false)`); `None`: neither.
    agree: Option<bool>,
    /// The border is continuous (a bend candidate, [`PlaneTest::bend`]).
    bend: bool,
}

/// The merge candidates: adjacent pairs in sorted order, and how each one may merge.
#[derive(Debug, Default)]
struct Candidates {
    pairs: Vec<(u32, u32)>,
    kinds: Vec<Kind>,
}

/// The plane agreement a merge needs, from [`Params`].
struct PlaneTest {
    /// cos of `merge_max_angle_deg`.
    cos_max: f64,
    /// `merge_max_residual²`.
    r2: f64,
    /// `within_max_rms_ratio²`.
    k2: f64,
    /// `within_joint_rms_ratio²` (0 = off).
    j2: f64,
    /// cos of `bend_max_angle_deg`, or `None` (bend merges off).
    cos_bend: Option<f64>,
    /// `bend_fit_ratio²`.
    fit2: f64,
}

/// Union-find merging of adjacent components of `pieces` over borders weakly supported by
/// `edges` or, with `merge_within_region`, inside one region-growing region. `parent` is the
/// union-find forest over labels `0..=n`; roots are the smaller label, and the root's moments and
/// plane become the merged group's. `step_3d` is the 3D length of the depth's step, if it has one.
pub(crate) fn merge_unsupported(
    scene: &Scene<'_>,
    edges: &EdgeMap,
    pieces: &mut Pieces,
    parent: &mut [u32],
    (params, step_3d): (&Params, Option<f64>),
    bufs: &mut Buffers,
) {
    let Buffers { hor, near, borders, candidates, close } = bufs;
    near_edges(edges, scene.w, scene.h, hor, near);
    let bends = params.bend_max_angle_deg > 0.0;
    let room = params.most_regions(scene.w * scene.h);
    borders.reset(pieces.planes.len(), room);
    // Pieces of one region-growing region that a gap of unlabelled pixels separates are candidates too.
    let close = (params.merge_within_region && params.within_close_px > 0).then_some((
        pieces.guide.as_slice(),
        params.within_close_px as usize,
        close,
    ));
    borders_into(scene, &pieces.comp, near, (&pieces.planes, bends), close, borders);
    let components = (&pieces.guide[..], &pieces.planes[..], &pieces.moments[..]);
    candidates_into(borders, components, (params, step_3d), candidates);
    let test = PlaneTest {
        cos_max: params.merge_max_angle_deg.to_radians().cos(),
        r2: params.merge_max_residual * params.merge_max_residual,
        k2: params.within_max_rms_ratio * params.within_max_rms_ratio,
        j2: params.within_joint_rms_ratio * params.within_joint_rms_ratio,
        cos_bend: bends.then(|| params.bend_max_angle_deg.to_radians().cos()),
        fit2: params.bend_fit_ratio * params.bend_fit_ratio,
    };
    let merges = merge_fixpoint(candidates, &test, parent, &mut pieces.moments, &mut pieces.planes, scene);
    tracing::debug!(pairs = borders.len(), candidates = candidates.pairs.len(), merges, "merged");
}

/// The working memory of [`merge_unsupported`], kept between frames.
#[derive(Debug, Default)]
pub(crate) struct Buffers {
    /// Per pixel: the horizontal pass of [`near_edges`], and its result.
    hor: Vec<bool>,
    near: Vec<bool>,
    /// The borders between adjacent components.
    borders: Borders,
    candidates: Candidates,
    /// The working memory of [`close_pairs_into`].
    close: Close,
}

/// The working memory of [`close_pairs_into`], kept between frames.
#[derive(Debug, Default)]
struct Close {
    /// (region-growing label, label) of every component with a region-growing label.
    by_guide: Vec<(u32, u32)>,
    /// Per label (index 0: no label): whether its region-growing region holds another component.
    multi: Vec<bool>,
}

/// Into `near`, the pixels within 1 px (8-neighbourhood) of an edge pixel: a horizontal 3-wide OR
/// per row (into `hor`), then a vertical 3-high OR of those rows, each written in one pass of slices.
fn near_edges(edges: &EdgeMap, w: usize, h: usize, hor: &mut Vec<bool>, near: &mut Vec<bool>) {
    let ed = edges.as_slice();
    hor.clear();
    hor.extend_from_slice(ed);
    near.clear();
    near.resize(w * h, false);
    if w == 0 {
        return;
    }
    for (hrow, erow) in hor.chunks_exact_mut(w).zip(ed.chunks_exact(w)) {
        if w > 1 {
            for ((o, &l), &r) in hrow[1..w - 1].iter_mut().zip(&erow[..w - 2]).zip(&erow[2..]) {
                *o |= l | r;
            }
            hrow[0] |= erow[1];
            hrow[w - 1] |= erow[w - 2];
        }
    }
    for (y, nrow) in near.chunks_exact_mut(w).enumerate() {
        let row = |yy: usize| &hor[yy * w..(yy + 1) * w];
        let (up, mid, dn) = (row(y.saturating_sub(1)), row(y), row((y + 1).min(h - 1)));
        for (((o, &u), &m), &d) in nrow.iter_mut().zip(up).zip(mid).zip(dn) {
            *o = u | m | d;
        }
    }
}

/// Calls `f(i, j)` for every pair of 4-adjacent pixels of `labels` (`w` × `h`, row-major) whose labels differ, in
/// raster order of `i`: each row's pixels with their right neighbours, then with the ones below. Chunks of pairs
/// that all match are skipped by one test without branches.
pub(crate) fn differing_pairs(labels: &[u32], w: usize, h: usize, mut f: impl FnMut(usize, usize)) {
    // Pixel pairs (row + x + d₀, row + x + d₁), x in `xs`, in order.
    let mut scan = |row: usize, xs: std::ops::Range<usize>, (d0, d1): (usize, usize)| {
        const CHUNK: usize = 16;
        let mut x = xs.start;
        while x + CHUNK <= xs.end {
            let (a, b) =
                (&labels[row + x + d0..row + x + d0 + CHUNK], &labels[row + x + d1..row + x + d1 + CHUNK]);
            if a.iter().zip(b).fold(0u32, |acc, (&p, &q)| acc | (p ^ q)) != 0 {
                for k in x..x + CHUNK {
                    if labels[row + k + d0] != labels[row + k + d1] {
                        f(row + k + d0, row + k + d1);
                    }
                }
            }
            x += CHUNK;
        }
        for k in x..xs.end {
            if labels[row + k + d0] != labels[row + k + d1] {
                f(row + k + d0, row + k + d1);
            }
        }
    };
    for y in 0..h {
        let row = y * w;
        scan(row, 0..w.saturating_sub(1), (0, 1));
        if y + 1 < h {
            scan(row, 0..w, (0, w));
        }
    }
}

/// Into `out` (reset for the labels of `comp`), the borders between adjacent components of `comp`, with their
/// support by `near` and, with `gaps`, their gaps to the components' `planes` (`planes[l − 1]` for label `l`);
/// with `close` (the region-growing label of each component), also the pairs of [`close_pairs_into`]; the pairs
/// sorted at the end.
fn borders_into(
    scene: &Scene<'_>,
    comp: &[u32],
    near: &[bool],
    (planes, gaps): (&[Plane], bool),
    close: Option<(&[u32], usize, &mut Close)>,
    out: &mut Borders,
) {
    let (w, h) = (scene.w, scene.h);
    // Distance of pixel i's 3D point to the plane of label l.
    let gap =
        |i: usize, l: u32| scene.point(i % w, i / w).map_or(0.0, |p| planes[l as usize - 1].residual(p));
    // The pair of the previous border pixel and its entry: a border is mostly met pair after pair.
    let mut last = ((0u32, 0u32), 0usize);
    let mut add = |i: usize, j: usize| {
        let (a, b) = (comp[i], comp[j]);
        if a != 0 && b != 0 {
            let key = (a.min(b), a.max(b));
            if key != last.0 {
                last = (key, out.index(key));
            }
            let entry = &mut out.entries[last.1].1;
            entry.n += 2;
            entry.near += u32::from(near[i]) + u32::from(near[j]);
            if gaps {
                entry.gap += gap(i, b) + gap(j, a);
            }
        }
    };
    differing_pairs(comp, w, h, &mut add);
    if let Some((guide, r, bufs)) = close {
        close_pairs_into((comp, scene.range), guide, (w, h, r), bufs, out);
    }
    out.entries.sort_unstable_by_key(|e| e.0);
}

/// Adds to `out` (with empty borders) the pairs of components of one region-growing region (`guide[l − 1]`, ≠ 0)
/// that come within `r` px (Chebyshev) of each other, seen from a pixel beside a valid unlabelled pixel (`range`
/// finite, label 0): a thin face seen edge-on that an edge crosses falls into pieces that the fill leaves apart.
/// Only components that share their region-growing region with another look around.
fn close_pairs_into(
    (comp, range): (&[u32], &[f32]),
    guide: &[u32],
    (w, h, r): (usize, usize, usize),
    bufs: &mut Close,
    out: &mut Borders,
) {
    // The components whose region-growing region holds another component.
    let Close { by_guide, multi } = bufs;
    by_guide.clear();
    by_guide.extend(guide.iter().enumerate().filter(|&(_, &g)| g != 0).map(|(k, &g)| (g, k as u32 + 1)));
    by_guide.sort_unstable();
    multi.clear();
    multi.resize(guide.len() + 1, false);
    for run in by_guide.chunk_by(|p, q| p.0 == q.0).filter(|run| run.len() > 1) {
        for &(_, l) in run {
            multi[l as usize] = true;
        }
    }
    let gap = |i: usize| comp[i] == 0 && range[i].is_finite();
    // The pair found last (already in `out`): a window finds the same pair many times, so it is looked up once.
    let mut last = (0u32, 0u32);
    for y in 0..h {
        let rows = y.saturating_sub(r)..(y + r + 1).min(h);
        for x in 0..w {
            let i = y * w + x;
            let a = comp[i];
            if !multi[a as usize] {
                continue;
            }
            let beside = (x > 0 && gap(i - 1))
                || (x + 1 < w && gap(i + 1))
                || (y > 0 && gap(i - w))
                || (y + 1 < h && gap(i + w));
            if !beside {
                continue;
            }
            let g = guide[a as usize - 1];
            let cols = x.saturating_sub(r)..(x + r + 1).min(w);
            for ny in rows.clone() {
                for &b in &comp[ny * w + cols.start..ny * w + cols.end] {
                    if b != a && multi[b as usize] && guide[b as usize - 1] == g {
                        let key = (a.min(b), a.max(b));
                        if key != last {
                            out.index(key);
                            last = key;
                        }
                    }
                }
            }
        }
    }
}

/// A component whose depths spread (standard deviation along the camera's depth axis) by less than this share of
/// the rounding error of the depth's step (`|Δq| / √12`) holds one depth value: a terrace of a quantised slope, whose
/// plane is the terrace, not the surface.
const TERRACE_SPREAD_SHARE: f64 = 0.5;

/// Every how many rows [`terrace_step`] looks for the depth's step (as region growing looks for it).
const STEP_STRIDE: usize = 4;

/// The 3D length of the step of `range`'s depth (`planefit::noise::step_from_smallest`, at the image centre) if the
/// depth has one and a component (`moments`) may be a terrace of it ([`is_terrace`]); `None` otherwise.
pub(crate) fn terrace_step(range: &RangeImage, camera: &Camera, moments: &[Moments]) -> Option<f64> {
    let smallest = planefit::noise::smallest_difference(range, STEP_STRIDE)?;
    // A step is under twice the smallest difference, so a component is no terrace if it is none of a step that long;
    // the costlier test of the step itself runs only if one may be.
    let (longest, _) = planefit::noise::step_geometry(range, camera, 2.0 * smallest)?;
    if !moments.iter().any(|m| is_terrace(m, longest)) {
        return None;
    }
    let step = planefit::noise::step_from_smallest(range, STEP_STRIDE, smallest)?;
    planefit::noise::step_geometry(range, camera, step).map(|(step_3d, _)| step_3d)
}

/// Whether the points of moments `m` are one terrace of depth rounded to steps of 3D length `step_3d`: their spread
/// along the depth axis (the third coordinate of every camera: Z, or the grid's value) is below
/// [`TERRACE_SPREAD_SHARE`] of the step's rounding error.
fn is_terrace(m: &Moments, step_3d: f64) -> bool {
    let limit = TERRACE_SPREAD_SHARE * step_3d / 12f64.sqrt();
    m.n >= 3.0 && m.covariance_rows()[2][2] < limit * limit
}

/// Candidates: weakly supported borders, and (with `merge_within_region`) any border between two
/// pieces of one region-growing region (`comp_guide[l − 1]` is the region-growing label of `l`).
/// Into `out`, whose memory is reused.
/// With `bend_max_angle_deg` > 0, also any border whose mean gap is below `bend_max_gap` times the larger RMS
/// residual of the two components (`planes[l − 1]` is the plane of `l`, `moments[l − 1]` its points' moments), plus
/// `terrace_gap_steps` times `step_3d` (the 3D length of the depth's step, if it has one) where one of them is a
/// single terrace ([`is_terrace`]).
fn candidates_into(
    borders: &Borders,
    (comp_guide, planes, moments): (&[u32], &[Plane], &[Moments]),
    (params, step_3d): (&Params, Option<f64>),
    out: &mut Candidates,
) {
    let Candidates { pairs, kinds } = out;
    pairs.clear();
    kinds.clear();
    // (The step, the extra gap allowed beside a terrace); none without a step.
    let terrace =
        step_3d.filter(|_| params.terrace_gap_steps > 0.0).map(|q| (q, params.terrace_gap_steps * q));
    for &((a, b), ref border) in &borders.entries {
        let n = f64::from(border.n);
        let weak = f64::from(border.near) < params.min_border_support * n;
        let same_region = params.merge_within_region && {
            let g = comp_guide[a as usize - 1];
            g != 0 && g == comp_guide[b as usize - 1]
        };
        let scatter = planes[a as usize - 1].rms.max(planes[b as usize - 1].rms);
        let beside_terrace =
            |q| is_terrace(&moments[a as usize - 1], q) || is_terrace(&moments[b as usize - 1], q);
        let extra = terrace.map_or(0.0, |(q, gap)| if beside_terrace(q) { gap } else { 0.0 });
        let bend =
            params.bend_max_angle_deg > 0.0 && border.gap < (params.bend_max_gap * scatter + extra) * n;
        if weak || same_region || bend {
            pairs.push((a, b));
            kinds.push(Kind { agree: (weak || same_region).then_some(weak), bend });
        }
    }
}

/// Passes over the candidates in order, merging every pair whose current groups pass `test`
/// (planes refitted on merge), until a pass merges nothing. Returns the number of merges.
fn merge_fixpoint(
    candidates: &Candidates,
    test: &PlaneTest,
    parent: &mut [u32],
    moments: &mut [Moments],
    planes: &mut [Plane],
    scene: &Scene<'_>,
) -> u32 {
    let mut merges = 0u32;
    loop {
        let mut changed = false;
        for (k, &(a, b)) in candidates.pairs.iter().enumerate() {
            let (ra, rb) = (find(parent, a), find(parent, b));
            if ra == rb {
                continue;
            }
            let (ia, ib) = (ra as usize - 1, rb as usize - 1);
            let (pa, pb) = (planes[ia], planes[ib]);
            let kind = candidates.kinds[k];
            let agree = || {
                kind.agree.and_then(|weak| test.agree(&pa, &pb, (&moments[ia], &moments[ib]), weak, scene))
            };
            let bend = || kind.bend.then(|| test.bend(&pa, &pb, &moments[ia], &moments[ib], scene)).flatten();
            let Some(joint) = agree().or_else(|| bend().map(Some)) else { continue };
            let (root, other) = (ra.min(rb), ra.max(rb));
            parent[other as usize] = root;
            let m = moments[other as usize - 1];
            moments[root as usize - 1].merge(&m);
            // The test's joint plane, where it fitted one, is this fit: its moments are these, field by field the
            // same sum of two (f64 addition is commutative), so the same bits.
            planes[root as usize - 1] =
                joint.unwrap_or_else(|| fit_plane(&moments[root as usize - 1], scene.camera));
            changed = true;
            merges += 1;
        }
        if !changed {
            return merges;
        }
    }
}

impl PlaneTest {
    /// Whether groups a and b (planes `pa`, `pb`, moments `ma`, `mb`) may merge over a border that
    /// is `weak`ly supported or not: `None` if not, else the plane fitted to both if the test fitted it.
    fn agree(
        &self,
        pa: &Plane,
        pb: &Plane,
        (ma, mb): (&Moments, &Moments),
        weak: bool,
        scene: &Scene<'_>,
    ) -> Option<Option<Plane>> {
        let dot: f64 = (0..3).map(|k| pa.normal[k] * pb.normal[k]).sum();
        let (ea, eb) = (mean_sq_residual(ma, pb), mean_sq_residual(mb, pa));
        if dot.abs() < self.cos_max || ea > self.r2 || eb > self.r2 {
            return None;
        }
        // Within one region-growing region over a supported border: merge only pieces that lie on
        // one plane within their own noise. (+1e-12: noise-free pieces of one plane have RMS 0 and
        // rounding-level residuals.)
        if weak || !(ea > self.k2 * pa.rms * pa.rms + 1e-12 || eb > self.k2 * pb.rms * pb.rms + 1e-12) {
            return Some(None);
        }
        // Or one plane through both explains each nearly as well as its own: a thin piece's plane, extrapolated
        // to the other piece, strays by its tilt error.
        if self.j2 == 0.0 {
            return None;
        }
        // And the two planes meet between the pieces: halfway between their centroids they lie within the
        // larger RMS of each other (parallel faces at two depths do not; a joint plane can tilt across a step).
        let (ca, cb) = (ma.centroid(), mb.centroid());
        let mid = [0.5 * (ca[0] + cb[0]), 0.5 * (ca[1] + cb[1]), 0.5 * (ca[2] + cb[2])];
        let apart = (pa.signed(mid) - dot.signum() * pb.signed(mid)).abs();
        if apart > pa.rms.max(pb.rms) {
            return None;
        }
        let pj = fit_plane(&ma.combined(mb), scene.camera);
        (mean_sq_residual(ma, &pj) <= self.j2 * pa.rms * pa.rms + 1e-12
            && mean_sq_residual(mb, &pj) <= self.j2 * pb.rms * pb.rms + 1e-12)
            .then_some(Some(pj))
    }

    /// Whether groups a and b, whose border is continuous, may merge as two sides of a bend: one
    /// plane through both within `merge_max_residual`, and normals within `bend_max_angle_deg` or
    /// that joint plane explaining each group within `bend_fit_ratio` times the larger of their RMS. Returns that
    /// joint plane if they may.
    fn bend(&self, pa: &Plane, pb: &Plane, ma: &Moments, mb: &Moments, scene: &Scene<'_>) -> Option<Plane> {
        let cos_bend = self.cos_bend?;
        let dot: f64 = (0..3).map(|k| pa.normal[k] * pb.normal[k]).sum();
        let within_angle = dot.abs() >= cos_bend;
        if !within_angle && self.fit2 == 0.0 {
            return None;
        }
        let pj = fit_plane(&ma.combined(mb), scene.camera);
        if pj.rms * pj.rms > self.r2 {
            return None;
        }
        // A sharper bend: each group's own normal is unreliable (a thin terrace of a quantised slope)
        // when the joint plane explains it nearly as well as its own plane does.
        let scatter = pa.rms.max(pb.rms);
        let limit = self.fit2 * scatter * scatter;
        (within_angle || (mean_sq_residual(ma, &pj) <= limit && mean_sq_residual(mb, &pj) <= limit))
            .then_some(pj)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{RngExt, SeedableRng};
    use std::collections::BTreeMap;

    /// The borders as a sorted map, one pixel pair at a time (the code before the table).
    fn borders_by_map(
        scene: &Scene<'_>,
        comp: &[u32],
        near: &[bool],
        planes: &[Plane],
        gaps: bool,
    ) -> Vec<u8> {
        let (w, h) = (scene.w, scene.h);
        let mut pairs: BTreeMap<(u32, u32), Border> = BTreeMap::new();
        let gap =
            |i: usize, l: u32| scene.point(i % w, i / w).map_or(0.0, |p| planes[l as usize - 1].residual(p));
        // Per row: its horizontal pairs, then its vertical pairs with the row below.
        let events = (0..h).flat_map(|y| {
            let hor = (1..w).map(move |x| (y * w + x - 1, y * w + x));
            let ver = (0..w).filter(move |_| y + 1 < h).map(move |x| (y * w + x, y * w + w + x));
            hor.chain(ver)
        });
        for (i, j) in events {
            let (a, b) = (comp[i], comp[j]);
            if a != 0 && b != 0 && a != b {
                let e = pairs.entry((a.min(b), a.max(b))).or_default();
                e.n += 2;
                e.near += u32::from(near[i]) + u32::from(near[j]);
                if gaps {
                    e.gap += gap(i, b) + gap(j, a);
                }
            }
        }
        format!("{:?}", pairs.iter().map(|(k, b)| (*k, b.n, b.near, b.gap.to_bits())).collect::<Vec<_>>())
            .into_bytes()
    }

    /// The near-edge mask is the 3 × 3 dilation of the edges, pixel by pixel.
    #[test]
    fn near_edges_is_the_3x3_dilation() {
        let mut rng = rand::rngs::Xoshiro256PlusPlus::seed_from_u64(37);
        let (mut hor, mut near) = (Vec::new(), Vec::new());
        for case in 0..200 {
            let (w, h) = (rng.random_range(1..50usize), rng.random_range(1..30usize));
            let p = [0.01, 0.05, 0.2][case % 3];
            let edges = rangeimage::Grid::from_fn(w as u32, h as u32, |_, _| rng.random_bool(p));
            near_edges(&edges, w, h, &mut hor, &mut near);
            for y in 0..h {
                for x in 0..w {
                    let want = (y.saturating_sub(1)..(y + 2).min(h)).any(|yy| {
                        (x.saturating_sub(1)..(x + 2).min(w)).any(|xx| edges[(xx as u32, yy as u32)])
                    });
                    assert_eq!(near[y * w + x], want, "case {case} ({w}×{h}) at ({x}, {y})");
                }
            }
        }
    }

    /// A border a mean gap of 1.6 × the larger RMS from the other plane is no bend candidate (the limit is 1.5 ×),
    /// unless the depth has a step and one of the two regions is a single terrace of it (its depths spread by under
    /// half the step's rounding error): then the gap may be one step more.
    #[test]
    fn a_terrace_may_meet_its_slope_on_a_riser() {
        let params = Params { min_border_support: 0.0, merge_within_region: false, ..Params::default() };
        let plane = |rms: f64| Plane { normal: [0.0, 0.0, 1.0], offset: -100.0, rms };
        // 100 points whose depth alternates by ± `spread` about 100 (standard deviation `spread`).
        let points = |spread: f64| {
            let mut m = Moments::default();
            for i in 0..100 {
                m.add([
                    f64::from(i % 10),
                    f64::from(i / 10),
                    100.0 + if i % 2 == 0 { spread } else { -spread },
                ]);
            }
            m
        };
        let candidate = |spread_a: f64, gap: f64, step_3d: Option<f64>, terrace_gap_steps: f64| {
            let borders = Borders {
                entries: vec![((1, 2), Border { n: 100, near: 100, gap: gap * 100.0 })],
                head: Vec::new(),
                next: Vec::new(),
            };
            let mut out = Candidates::default();
            let params = Params { terrace_gap_steps, ..params.clone() };
            let (planes, moments) = ([plane(0.0), plane(1.0)], [points(spread_a), points(2.0)]);
            candidates_into(&borders, (&[0, 0], &planes, &moments), (&params, step_3d), &mut out);
            out.pairs == [(1, 2)] && out.kinds[0].bend
        };
        // Step 3.6: rounding error 3.6 / √12 ≈ 1.04, a terrace under 0.52.
        assert!(candidate(0.0, 1.4, None, 1.0), "within bend_max_gap × scatter");
        assert!(!candidate(0.0, 1.6, None, 1.0), "no step: no terrace");
        assert!(candidate(0.0, 1.6, Some(3.6), 1.0), "a terrace beside its slope");
        assert!(candidate(0.3, 5.0, Some(3.6), 1.0), "up to 1.5 + 3.6");
        assert!(!candidate(0.3, 5.2, Some(3.6), 1.0), "beyond 1.5 + 3.6");
        assert!(!candidate(0.6, 1.6, Some(3.6), 1.0), "a spread of 0.6 is no terrace");
        assert!(!candidate(0.0, 1.6, Some(3.6), 0.0), "terrace_gap_steps 0: off");
    }

    /// The step is looked for only when a component may be a terrace: a staircase of 2-unit risers every 4 columns
    /// (enough of them on every 4th row to count as a step) gives its step's 3D length (2 on the grid camera) beside
    /// a one-value component, nothing beside a spread one or on continuous depth.
    #[test]
    fn the_step_is_found_only_beside_a_possible_terrace() {
        let stairs = rangeimage::Grid::from_fn(80, 60, |x, _| 100.0 + 2.0 * (x / 4) as f32);
        let moments = |depths: &[f64]| {
            let mut m = Moments::default();
            for (i, &z) in depths.iter().enumerate() {
                m.add([i as f64, 0.0, z]);
            }
            m
        };
        let (flat, spread) = (moments(&[100.0; 8]), moments(&[100.0, 102.0, 104.0, 106.0]));
        let grid = rangeimage::Camera::Grid;
        assert_eq!(terrace_step(&stairs, &grid, &[spread, flat]), Some(2.0));
        assert_eq!(terrace_step(&stairs, &grid, &[spread]), None, "no component may be a terrace");
        let slope = rangeimage::Grid::from_fn(40, 30, |x, y| {
            100.0 + 0.37 * x as f32 + 0.11 * y as f32 + 0.013 * (x * y) as f32
        });
        assert_eq!(terrace_step(&slope, &grid, &[flat]), None, "continuous depth has no step");
    }

    /// The chunked scan gives every differing 4-adjacent pair once, in its documented order (each row's right pairs,
    /// then its pairs below), on random block images wider and narrower than a chunk.
    #[test]
    fn differing_pairs_lists_every_differing_pair_in_order() {
        let mut rng = rand::rngs::Xoshiro256PlusPlus::seed_from_u64(31);
        for case in 0..200 {
            let (w, h) = (rng.random_range(1..80usize), rng.random_range(1..30usize));
            let bw = rng.random_range(1..40usize);
            let noise = [0.0, 0.02, 0.3][case % 3];
            let block = |i: usize| ((i % w) / bw) as u32 % 3;
            let labels: Vec<u32> = (0..w * h)
                .map(|i| if rng.random_bool(noise) { rng.random_range(0..4) } else { block(i) })
                .collect();
            let mut want = Vec::new();
            for y in 0..h {
                for x in 0..w.saturating_sub(1) {
                    let i = y * w + x;
                    if labels[i] != labels[i + 1] {
                        want.push((i, i + 1));
                    }
                }
                for x in 0..w {
                    let i = y * w + x;
                    if y + 1 < h && labels[i] != labels[i + w] {
                        want.push((i, i + w));
                    }
                }
            }
            let mut got = Vec::new();
            differing_pairs(&labels, w, h, |i, j| got.push((i, j)));
            assert_eq!(got, want, "case {case}");
        }
    }

    /// The pair table gives the map's pairs, counts and gap sums (bit for bit) on random label images of
    /// patches with scattered noise and zeros, with one table reused throughout.
    #[test]
    fn border_table_matches_a_sorted_map() {
        let mut rng = rand::rngs::Xoshiro256PlusPlus::seed_from_u64(29);
        let mut table = Borders::default();
        for case in 0..200 {
            let (w, h) = (rng.random_range(1..70usize), rng.random_range(1..40usize));
            let (bw, bh) = (rng.random_range(1..20usize), rng.random_range(1..12usize));
            let n = rng.random_range(1..30u32);
            let noise = [0.0, 0.01, 0.1, 0.4][case % 4];
            let comp: Vec<u32> = (0..w * h)
                .map(|i| {
                    let block = ((i % w) / bw * 7 + 3 * ((i / w) / bh)) as u32 % (n + 1);
                    if rng.random_bool(noise) { rng.random_range(0..=n) } else { block }
                })
                .collect();
            let near: Vec<bool> = (0..w * h).map(|_| rng.random_bool(0.3)).collect();
            let range: Vec<f32> = (0..w * h)
                .map(|_| if rng.random_bool(0.05) { f32::NAN } else { rng.random_range(50.0..90.0) })
                .collect();
            let planes: Vec<Plane> = (0..n)
                .map(|_| Plane {
                    normal: [rng.random_range(-0.5..0.5), rng.random_range(-0.5..0.5), 1.0],
                    offset: rng.random_range(-80.0..-40.0),
                    rms: 0.5,
                })
                .collect();
            let mut points = Vec::new();
            let scene = Scene::new(&range, (w, h), &rangeimage::Camera::Grid, &mut points);
            for gaps in [false, true] {
                table.reset(n as usize, 4);
                borders_into(&scene, &comp, &near, (&planes, gaps), None, &mut table);
                let got = format!(
                    "{:?}",
                    table.entries.iter().map(|(k, b)| (*k, b.n, b.near, b.gap.to_bits())).collect::<Vec<_>>()
                )
                .into_bytes();
                assert_eq!(got, borders_by_map(&scene, &comp, &near, &planes, gaps), "case {case}");
            }
        }
    }

    /// Two pieces of one region-growing region that a gap of one unlabelled pixel separates become a candidate pair
    /// (with an empty border) within 2 px, pieces of two regions or farther apart do not, and 4-adjacent pairs keep
    /// their borders.
    #[test]
    fn close_pieces_of_one_region_become_candidates() {
        // 1 1 0 2 2 | 3 (a different guide) … ; row 2: 4 far away.
        let (w, h) = (8usize, 2usize);
        #[rustfmt::skip]
        let comp: Vec<u32> = vec![
            1, 1, 0, 2, 2, 3, 0, 0,
            1, 1, 0, 2, 2, 0, 0, 4,
        ];
        let guide = [9, 9, 8, 9];
        let range = vec![100.0f32; w * h];
        let mut points = Vec::new();
        let scene = Scene::new(&range, (w, h), &rangeimage::Camera::Grid, &mut points);
        let planes = vec![Plane { normal: [0.0, 0.0, 1.0], offset: -100.0, rms: 0.1 }; 4];
        let near = vec![false; w * h];
        let mut table = Borders::default();
        table.reset(4, 4);
        let mut close = Close::default();
        borders_into(&scene, &comp, &near, (&planes, false), Some((&guide, 2, &mut close)), &mut table);
        let pairs: Vec<_> = table.entries.iter().map(|(k, b)| (*k, b.n)).collect();
        // (1, 2): close, same guide, no border; (2, 3): 4-adjacent (its border); (2, 4): 3 px apart; (3, 4): two guides.
        assert_eq!(pairs, vec![((1, 2), 0), ((2, 3), 2)]);
        // Within 1 px only, or off: only the 4-adjacent pair.
        table.reset(4, 4);
        borders_into(&scene, &comp, &near, (&planes, false), Some((&guide, 1, &mut close)), &mut table);
        assert_eq!(table.entries.iter().map(|(k, b)| (*k, b.n)).collect::<Vec<_>>(), vec![((2, 3), 2)]);
        table.reset(4, 4);
        borders_into(&scene, &comp, &near, (&planes, false), None, &mut table);
        assert_eq!(table.entries.iter().map(|(k, b)| (*k, b.n)).collect::<Vec<_>>(), vec![((2, 3), 2)]);
    }

    /// The joint-plane test merges two pieces of one tilted plane whose own planes are too poorly determined for
    /// the cross test, and keeps a step between parallel faces.
    #[test]
    fn joint_plane_test_merges_coplanar_pieces_but_not_a_step() {
        let range = vec![0.0f32; 1];
        let mut points = Vec::new();
        let scene = Scene::new(&range, (1, 1), &rangeimage::Camera::Grid, &mut points);
        // Two thin strips (3 px wide, 30 long) of z = 0.5 x + noise, the second 30 px farther along.
        let strip = |x0: f64, dz: f64| {
            let mut m = Moments::default();
            for x in 0..30 {
                for y in 0..3 {
                    let noise = [0.3, -0.3, 0.0, 0.25, -0.25][(x * 3 + y * 2) % 5];
                    let xf = x0 + f64::from(x as u32);
                    m.add([xf, f64::from(y as u32), 0.5 * xf + noise + dz]);
                }
            }
            m
        };
        let test = |ratio: f64, dz: f64| {
            let (ma, mb) = (strip(0.0, 0.0), strip(30.0, dz));
            let (pa, pb) = (fit_plane(&ma, scene.camera), fit_plane(&mb, scene.camera));
            let t = PlaneTest {
                cos_max: 10f64.to_radians().cos(),
                r2: 9.0,
                k2: 1.0,
                j2: ratio * ratio,
                cos_bend: None,
                fit2: 0.0,
            };
            t.agree(&pa, &pb, (&ma, &mb), false, &scene)
        };
        assert!(test(0.0, 0.0).is_none(), "the cross test alone (ratio 1) refuses");
        // One plane explains both; the test gives that plane, the same bits as the union's fit in either order
        // (the merge takes it instead of fitting again).
        let (ma, mb) = (strip(0.0, 0.0), strip(30.0, 0.0));
        let joint = test(1.1, 0.0).expect("one plane explains both").expect("the joint plane was fitted");
        for union in [ma.combined(&mb), mb.combined(&ma)] {
            let fit = fit_plane(&union, scene.camera);
            let bits = |p: &Plane| (p.normal.map(f64::to_bits), p.offset.to_bits(), p.rms.to_bits());
            assert_eq!(bits(&fit), bits(&joint));
        }
        assert!(test(1.1, 1.0).is_none(), "a step of about five times the noise stays");
    }
}
