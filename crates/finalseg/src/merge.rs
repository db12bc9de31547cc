//! Step 4 of the final segmentation (`regions` mode): adjacent regions merged over borders the
//! edges do not support, or inside one region-growing region, where their planes agree.

use crate::plane::{Plane, fit_plane, mean_sq_residual};
use crate::{Params, Pieces, Scene};
use planefit::Moments;
use rangeimage::EdgeMap;
use rangeimage::union_find::find;
use std::collections::BTreeMap;

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

/// Per adjacent pair of components (smaller label, larger label): their border.
type Borders = BTreeMap<(u32, u32), Border>;

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
    /// cos of `bend_max_angle_deg`, or `None` (bend merges off).
    cos_bend: Option<f64>,
    /// `bend_fit_ratio²`.
    fit2: f64,
}

/// Union-find merging of adjacent components of `pieces` over borders weakly supported by
/// `edges` or, with `merge_within_region`, inside one region-growing region. `parent` is the
/// union-find forest over labels `0..=n`; roots are the smaller label, and the root's moments and
/// plane become the merged group's.
pub(crate) fn merge_unsupported(
    scene: &Scene<'_>,
    edges: &EdgeMap,
    pieces: &mut Pieces,
    parent: &mut [u32],
    params: &Params,
    bufs: &mut Buffers,
) {
    let Buffers { hor, near, candidates } = bufs;
    near_edges(edges, scene.w, scene.h, hor, near);
    let bends = params.bend_max_angle_deg > 0.0;
    let borders = borders(scene, &pieces.comp, near, bends.then_some(&pieces.planes[..]));
    candidates_into(&borders, (&pieces.guide, &pieces.planes), params, candidates);
    let test = PlaneTest {
        cos_max: params.merge_max_angle_deg.to_radians().cos(),
        r2: params.merge_max_residual * params.merge_max_residual,
        k2: params.within_max_rms_ratio * params.within_max_rms_ratio,
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
    candidates: Candidates,
}

/// Into `near`, the pixels within 1 px (8-neighbourhood) of an edge pixel: a horizontal 3-wide OR
/// per row (into `hor`), then a vertical 3-high OR of those rows.
fn near_edges(edges: &EdgeMap, w: usize, h: usize, hor: &mut Vec<bool>, near: &mut Vec<bool>) {
    let ed = edges.as_slice();
    hor.clear();
    hor.extend_from_slice(ed);
    for (hrow, erow) in hor.chunks_exact_mut(w.max(1)).zip(ed.chunks_exact(w.max(1))) {
        for x in 1..w {
            hrow[x] |= erow[x - 1];
            hrow[x - 1] |= erow[x];
        }
    }
    near.clear();
    near.resize(w * h, false);
    for (y, nrow) in near.chunks_exact_mut(w.max(1)).enumerate() {
        for yy in y.saturating_sub(1)..(y + 2).min(h) {
            for (n, &v) in nrow.iter_mut().zip(&hor[yy * w..(yy + 1) * w]) {
                *n |= v;
            }
        }
    }
}

/// The borders between adjacent components of `comp`, with their support by `near` and, given the
/// components' `planes` (`planes[l − 1]` for label `l`), their gaps.
fn borders(scene: &Scene<'_>, comp: &[u32], near: &[bool], planes: Option<&[Plane]>) -> Borders {
    let (w, h) = (scene.w, scene.h);
    let mut pairs = Borders::new();
    // Distance of pixel i's 3D point to the plane of label l.
    let gap = |i: usize, l: u32, planes: &[Plane]| {
        scene.point(i % w, i / w).map_or(0.0, |p| planes[l as usize - 1].residual(p))
    };
    let mut add = |i: usize, j: usize| {
        let (a, b) = (comp[i], comp[j]);
        if a != 0 && b != 0 && a != b {
            let entry = pairs.entry((a.min(b), a.max(b))).or_default();
            entry.n += 2;
            entry.near += u32::from(near[i]) + u32::from(near[j]);
            if let Some(planes) = planes {
                entry.gap += gap(i, b, planes) + gap(j, a, planes);
            }
        }
    };
    for y in 0..h {
        let row = y * w;
        for x in 1..w {
            if comp[row + x - 1] != comp[row + x] {
                add(row + x - 1, row + x);
            }
        }
        if y + 1 < h {
            for x in 0..w {
                if comp[row + x] != comp[row + w + x] {
                    add(row + x, row + w + x);
                }
            }
        }
    }
    pairs
}

/// Candidates: weakly supported borders, and (with `merge_within_region`) any border between two
/// pieces of one region-growing region (`comp_guide[l − 1]` is the region-growing label of `l`).
/// Into `out`, whose memory is reused.
/// With `bend_max_angle_deg` > 0, also any border whose mean gap is below `bend_max_gap` times the larger RMS
/// residual of the two components (`planes[l − 1]` is the plane of `l`).
fn candidates_into(
    borders: &Borders,
    (comp_guide, planes): (&[u32], &[Plane]),
    params: &Params,
    out: &mut Candidates,
) {
    let Candidates { pairs, kinds } = out;
    pairs.clear();
    kinds.clear();
    for (&(a, b), border) in borders {
        let n = f64::from(border.n);
        let weak = f64::from(border.near) < params.min_border_support * n;
        let same_region = params.merge_within_region && {
            let g = comp_guide[a as usize - 1];
            g != 0 && g == comp_guide[b as usize - 1]
        };
        let scatter = planes[a as usize - 1].rms.max(planes[b as usize - 1].rms);
        let bend = params.bend_max_angle_deg > 0.0 && border.gap < params.bend_max_gap * scatter * n;
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
            let agree = kind.agree.is_some_and(|weak| test.agree(&pa, &pb, &moments[ia], &moments[ib], weak));
            let bend = || kind.bend && test.bend(&pa, &pb, &moments[ia], &moments[ib], scene);
            if !(agree || bend()) {
                continue;
            }
            let (root, other) = (ra.min(rb), ra.max(rb));
            parent[other as usize] = root;
            let m = moments[other as usize - 1];
            moments[root as usize - 1].merge(&m);
            planes[root as usize - 1] = fit_plane(&moments[root as usize - 1], scene.camera);
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
    /// is `weak`ly supported or not.
    fn agree(&self, pa: &Plane, pb: &Plane, ma: &Moments, mb: &Moments, weak: bool) -> bool {
        let dot: f64 = (0..3).map(|k| pa.normal[k] * pb.normal[k]).sum();
        let (ea, eb) = (mean_sq_residual(ma, pb), mean_sq_residual(mb, pa));
        if dot.abs() < self.cos_max || ea > self.r2 || eb > self.r2 {
            return false;
        }
        // Within one region-growing region over a supported border: merge only pieces that lie on
        // one plane within their own noise. (+1e-12: noise-free pieces of one plane have RMS 0 and
        // rounding-level residuals.)
        weak || !(ea > self.k2 * pa.rms * pa.rms + 1e-12 || eb > self.k2 * pb.rms * pb.rms + 1e-12)
    }

    /// Whether groups a and b, whose border is continuous, may merge as two sides of a bend: one
    /// plane through both within `merge_max_residual`, and normals within `bend_max_angle_deg` or
    /// that joint plane explaining each group within `bend_fit_ratio` times the larger of their RMS.
    fn bend(&self, pa: &Plane, pb: &Plane, ma: &Moments, mb: &Moments, scene: &Scene<'_>) -> bool {
        let Some(cos_bend) = self.cos_bend else { return false };
        let dot: f64 = (0..3).map(|k| pa.normal[k] * pb.normal[k]).sum();
        let within_angle = dot.abs() >= cos_bend;
        if !within_angle && self.fit2 == 0.0 {
            return false;
        }
        let mut joint = *ma;
        joint.merge(mb);
        let pj = fit_plane(&joint, scene.camera);
        if pj.rms * pj.rms > self.r2 {
            return false;
        }
        // A sharper bend: each group's own normal is unreliable (a thin terrace of a quantised slope)
        // when the joint plane explains it nearly as well as its own plane does.
        let scatter = pa.rms.max(pb.rms);
        let limit = self.fit2 * scatter * scatter;
        within_angle || (mean_sq_residual(ma, &pj) <= limit && mean_sq_residual(mb, &pj) <= limit)
    }
}
