//! Per-region statistics and the deterministic merge fixpoint over the region adjacency graph.

use crate::plane::{Moments, Plane, dot, smallest_axis_exceeds};
use crate::{Mode, Params};
use rangeimage::union_find::find;

/// Statistics of one region, accumulated in raster order (so they do not depend on label values).
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct Stats {
    /// Pixel count.
    pub(crate) count: u32,
    /// Σ K over pixels with finite K.
    pub(crate) sum_k: f64,
    /// Number of pixels with finite K.
    pub(crate) n_k: u32,
    /// Moments of the 3D points (relative to the image origin point).
    pub(crate) mom: Moments,
    /// Raster index of the first pixel (`u32::MAX` for an empty region).
    pub(crate) first: u32,
}

impl Stats {
    /// Mean K; NaN if no pixel has a finite K.
    pub(crate) fn mean_k(&self) -> f64 {
        if self.n_k == 0 { f64::NAN } else { self.sum_k / f64::from(self.n_k) }
    }

    /// Union of two disjoint regions; `self` must be the one with the smaller `first`.
    fn combined(&self, o: &Stats) -> Stats {
        Stats {
            count: self.count + o.count,
            sum_k: self.sum_k + o.sum_k,
            n_k: self.n_k + o.n_k,
            mom: self.mom.combined(&o.mom),
            first: self.first.min(o.first),
        }
    }
}

/// Statistics of labels `0..=max_label` (entry 0 unused) in raster order. `pts[i]` starts with
/// the 3D point of pixel `i` (`N ≥ 3`; the growth stage stores the normal after it).
///
/// Runs of equal labels along the raster are accumulated in a local copy (same addition order as
/// pixel by pixel, so the sums are bit-identical), which keeps the hot loop out of memory.
#[cfg(test)]
pub(crate) fn region_stats<const N: usize>(
    labels: &[u32],
    max_label: u32,
    pts: &[[f32; N]],
    k: &[f32],
) -> Vec<Stats> {
    let mut st = Vec::new();
    region_stats_into(labels, max_label, pts, k, &mut st);
    st
}

/// [`region_stats`] into `st`, whose memory is reused.
#[inline(always)] // into `grow::run`, compiled for each instruction set
pub(crate) fn region_stats_into<const N: usize>(
    labels: &[u32],
    max_label: u32,
    pts: &[[f32; N]],
    k: &[f32],
    st: &mut Vec<Stats>,
) {
    st.clear();
    st.resize(max_label as usize + 1, Stats { first: u32::MAX, ..Stats::default() });
    let n = labels.len();
    assert!(pts.len() == n && k.len() == n && N >= 3, "region_stats: array sizes differ");
    let mut i = 0;
    while i < n {
        let l = labels[i];
        if l == 0 {
            i += 1;
            continue;
        }
        i = add_run(labels, pts, k, i, &mut st[l as usize]);
    }
}

/// [`region_stats_into`] for the labels marked in `dirty` only (one flag per entry of `st`, label 0 unmarked):
/// their entries are recomputed from `labels` by the same runs and additions (so to the same bits), the others
/// are kept; the unmarked labels' runs are skipped without reading their points.
#[inline(always)] // into `grow::run`, compiled for each instruction set
pub(crate) fn region_stats_update<const N: usize>(
    labels: &[u32],
    pts: &[[f32; N]],
    k: &[f32],
    st: &mut [Stats],
    dirty: &[bool],
) {
    let n = labels.len();
    assert!(pts.len() == n && k.len() == n && N >= 3, "region_stats: array sizes differ");
    assert!(
        st.len() == dirty.len() && !dirty.first().copied().unwrap_or(false),
        "region_stats_update: bad marks"
    );
    for (s, &d) in st.iter_mut().zip(dirty) {
        if d {
            *s = Stats { first: u32::MAX, ..Stats::default() };
        }
    }
    let mut i = 0;
    while i < n {
        let l = labels[i];
        if !dirty[l as usize] {
            i += 1;
            while i < n && labels[i] == l {
                i += 1;
            }
            continue;
        }
        i = add_run(labels, pts, k, i, &mut st[l as usize]);
    }
}

/// Adds the run of pixels with the label of pixel `i` that starts there to that label's statistics `st`
/// (pixel by pixel in raster order); returns the index after the run.
#[inline(always)]
fn add_run<const N: usize>(
    labels: &[u32],
    pts: &[[f32; N]],
    k: &[f32],
    mut i: usize,
    st: &mut Stats,
) -> usize {
    let n = labels.len();
    let l = labels[i];
    let mut s = *st;
    if s.count == 0 {
        s.first = i as u32;
    }
    // [Σx, Σy, Σz, Σxx, Σxy, Σxz, Σyy, Σyz, Σzz, ΣK]: adding 0 for a non-finite K leaves the
    // (never −0) sum unchanged, and integer counts in f64 are exact, so this equals the
    // pixel-by-pixel `Moments::add` sequence bit for bit.
    let mut acc = [
        s.mom.s[0],
        s.mom.s[1],
        s.mom.s[2],
        s.mom.ss[0],
        s.mom.ss[1],
        s.mom.ss[2],
        s.mom.ss[3],
        s.mom.ss[4],
        s.mom.ss[5],
        s.sum_k,
    ];
    let start = i;
    let mut n_k = 0u32;
    while i < n && labels[i] == l {
        let p = &pts[i];
        let (x, y, z) = (f64::from(p[0]), f64::from(p[1]), f64::from(p[2]));
        let kv = k[i];
        let fin = kv.is_finite();
        n_k += u32::from(fin);
        let kf = if fin { f64::from(kv) } else { 0.0 };
        let t = [x, y, z, x * x, x * y, x * z, y * y, y * z, z * z, kf];
        for (a, t) in acc.iter_mut().zip(t) {
            *a += t;
        }
        i += 1;
    }
    let run = (i - start) as u32;
    s.count += run;
    s.n_k += n_k;
    s.mom.n += f64::from(run);
    s.mom.s = [acc[0], acc[1], acc[2]];
    s.mom.ss = [acc[3], acc[4], acc[5], acc[6], acc[7], acc[8]];
    s.sum_k = acc[9];
    *st = s;
    i
}

/// The merge thresholds, pre-converted.
struct Criterion {
    paper: bool,
    t_m: f64,
    cos_angle: f64,
    max_angle_deg: f64,
    max_residual: f64,
    joint_ratio: f64,
}

impl Criterion {
    fn new(params: &Params) -> Self {
        Self {
            paper: params.mode == Mode::Paper,
            t_m: f64::from(params.t_m),
            cos_angle: f64::from(params.merge_max_angle_deg).to_radians().cos(),
            max_angle_deg: f64::from(params.merge_max_angle_deg),
            max_residual: f64::from(params.merge_max_residual),
            joint_ratio: f64::from(params.merge_joint_rms_ratio),
        }
    }

    /// Dissimilarity score (< 1-ish, smaller = more similar) if the two regions may merge.
    fn score(&self, a: &Stats, pa: Option<&Plane>, b: &Stats, pb: Option<&Plane>) -> Option<f64> {
        self.pairwise(a, pa, b, pb).or_else(|| self.joint(a, pa, b, pb))
    }

    /// The joint-fit test (`merge_joint_rms_ratio`): the score is the joint RMS over its limit.
    fn joint(&self, a: &Stats, pa: Option<&Plane>, b: &Stats, pb: Option<&Plane>) -> Option<f64> {
        if self.paper || self.joint_ratio <= 0.0 {
            return None;
        }
        let (pa, pb) = (pa?, pb?);
        let own = ((a.mom.n * pa.mean_sq + b.mom.n * pb.mean_sq) / (a.mom.n + b.mom.n)).max(0.0).sqrt();
        let limit = self.max_residual.min(self.joint_ratio * own);
        let joint = a.mom.combined(&b.mom);
        // A pair whose joint spread certainly exceeds the limit fails without the eigen-decomposition.
        if smallest_axis_exceeds(&joint, limit * limit) {
            return None;
        }
        let rms = Plane::fit_mean_sq(&joint)?.max(0.0).sqrt();
        (rms <= limit && limit > 0.0).then(|| 1.0 + rms / limit)
    }

    /// The pairwise test: mean K, normals and each region's points against the other's plane.
    fn pairwise(&self, a: &Stats, pa: Option<&Plane>, b: &Stats, pb: Option<&Plane>) -> Option<f64> {
        let dk = (a.mean_k() - b.mean_k()).abs();
        if dk.is_nan() || dk >= self.t_m {
            return None;
        }
        let mut s = dk / self.t_m.max(1e-300);
        if self.paper {
            return Some(s);
        }
        if let (Some(pa), Some(pb)) = (pa, pb) {
            let c = dot(pa.normal, pb.normal).abs().min(1.0);
            if c < self.cos_angle {
                return None;
            }
            s = s.max(c.acos().to_degrees() / self.max_angle_deg.max(1e-12));
        }
        for (p, m) in [(pa, &b.mom), (pb, &a.mom)] {
            if let Some(p) = p {
                let r = p.mean_sq_distance(m).sqrt();
                if r > self.max_residual {
                    return None;
                }
                s = s.max(r / self.max_residual.max(1e-12));
            }
        }
        Some(s)
    }
}

/// The per-label working vectors of [`merge`], kept between frames; `stats` holds its result.
#[derive(Debug, Clone, Default)]
pub(crate) struct MergeBufs {
    /// Statistics indexed by label; after [`merge`], valid for every label still present in the image.
    pub(crate) stats: Vec<Stats>,
    planes: Vec<Option<Plane>>,
    parent: Vec<u32>,
    pairs: Vec<(u32, u32)>,
    /// The adjacent pairs of roots, each with its score when known from an earlier pass (see [`merge`]).
    graph: Vec<((u32, u32), Known)>,
    /// Per label: its statistics changed (a region merged into it) during the current pass.
    changed: Vec<bool>,
    cand: Vec<(f64, u32, u32, u32, u32)>,
    /// Per label: the label its pixels get at the end of [`merge`].
    map: Vec<u32>,
    /// Per label: its pixels changed in the last [`merge`] ([`MergeBufs::mark_merged`]).
    pub(crate) dirty: Vec<bool>,
}

/// A cached [`Criterion::score`]: `None` until computed, then the score (itself `None` for a pair that may
/// not merge).
type Known = Option<Option<f64>>;

impl MergeBufs {
    /// Room for labels `0..n` in every per-label vector (emptied), so a later frame with more regions does
    /// not reallocate them.
    pub(crate) fn reserve(&mut self, n: usize) {
        self.stats.clear();
        self.stats.reserve(n);
        self.planes.clear();
        self.planes.reserve(n);
        self.parent.clear();
        self.parent.reserve(n);
        self.changed.clear();
        self.changed.reserve(n);
        self.dirty.clear();
        self.dirty.reserve(n);
        self.map.clear();
        self.map.reserve(n);
    }

    /// Whether label `l` is a root of the last [`merge`] (not merged into another label).
    pub(crate) fn is_root(&self, l: usize) -> bool {
        self.parent[l] as usize == l
    }

    /// After a [`merge`] of labels `0..=max_label` that merged (its root table is left in `parent`): marks in
    /// `dirty` the labels whose pixels changed, the merged-away ones and the roots that took them in. The others
    /// keep in `stats` the raster-order statistics of the merge's input, which are those of its output.
    pub(crate) fn mark_merged(&mut self, max_label: u32) {
        let n = max_label as usize + 1;
        self.dirty.clear();
        self.dirty.resize(n, false);
        for l in 0..n {
            let r = self.parent[l] as usize;
            if r != l {
                self.dirty[l] = true;
                self.dirty[r] = true;
            }
        }
    }
}

/// Outcome of [`merge`] (the statistics are left in [`MergeBufs::stats`]).
pub(crate) struct Merged {
    /// Merge operations.
    pub(crate) n_merged: u32,
    /// Passes over the adjacency graph.
    pub(crate) n_passes: u32,
}

/// Merges adjacent similar regions of `labels` (values `0..=max_label`, 0 = none) until a full
/// pass merges nothing, and rewrites `labels` with the surviving labels, or 0 for the regions of fewer than
/// `min_keep` pixels (a pass over the pixels only when a label changes).
///
/// Candidate pairs are processed in order of (score, first pixel of either region); the surviving
/// label of a union is the one whose region starts first in raster order. Nothing depends on the
/// numeric label values, so a relabelled input yields the same partition.
///
/// A score is a function of the two regions' statistics and planes alone, so it is computed once per pair
/// and pass at most: a pair whose two regions took part in no merge keeps the score of the previous pass,
/// and the re-check before a merge is skipped when neither region has changed since the pass scored it
/// (the same decisions as scoring every pair every time, at a fraction of the plane fits).
#[allow(clippy::too_many_arguments)]
pub(crate) fn merge<const N: usize>(
    labels: &mut [u32],
    max_label: u32,
    width: usize,
    eight: bool,
    pts: &[[f32; N]],
    k: &[f32],
    params: &Params,
    min_keep: u32,
    toward: &dyn Fn([f64; 3]) -> [f64; 3],
    bufs: &mut MergeBufs,
) -> Merged {
    // Compiled for the best instruction set of this CPU (the same operations in the same order: the same bits).
    isa::dispatch(
        #[inline(always)]
        || {
            let MergeBufs { stats, planes, parent, pairs, graph, changed, cand, map, .. } = bufs;
            region_stats_into(labels, max_label, pts, k, stats);
            let crit = Criterion::new(params);
            let fit = |s: &Stats| if crit.paper { None } else { Plane::fit(&s.mom, toward) };
            planes.clear();
            planes.extend(stats.iter().map(|s| if s.count > 0 { fit(s) } else { None }));
            parent.clear();
            parent.extend(0..=max_label);
            changed.clear();
            changed.resize(max_label as usize + 1, false);
            adjacent_pairs_into(labels, width, eight, pairs);
            graph.clear();
            graph.extend(pairs.iter().map(|&p| (p, None)));

            let mut n_merged = 0;
            let mut n_passes = 0;
            loop {
                n_passes += 1;
                cand.clear();
                // At the start of a pass every pair holds two distinct roots (the first pass: every label is one).
                for ((a, b), known) in graph.iter_mut() {
                    let (a, b) = (*a, *b);
                    debug_assert!(a != b && parent[a as usize] == a && parent[b as usize] == b);
                    let (sa, sb) = (&stats[a as usize], &stats[b as usize]);
                    let score = *known.get_or_insert_with(|| {
                        crit.score(sa, planes[a as usize].as_ref(), sb, planes[b as usize].as_ref())
                    });
                    if let Some(s) = score {
                        let (lo, hi) = if sa.first < sb.first { (a, b) } else { (b, a) };
                        cand.push((s, stats[lo as usize].first, stats[hi as usize].first, lo, hi));
                    }
                }
                if cand.is_empty() {
                    break;
                }
                cand.sort_unstable_by(|p, q| p.0.total_cmp(&q.0).then(p.1.cmp(&q.1)).then(p.2.cmp(&q.2)));
                cand.dedup_by(|p, q| p.1 == q.1 && p.2 == q.2);
                let mut merged_now = false;
                for &(_, _, _, a, b) in cand.iter() {
                    let (ra, rb) = (find(parent, a), find(parent, b));
                    if ra == rb {
                        continue;
                    }
                    // Both still the regions this pass scored (roots, unchanged): the score is the one found above.
                    let same = ra == a && rb == b && !changed[a as usize] && !changed[b as usize];
                    let (sa, sb) = (&stats[ra as usize], &stats[rb as usize]);
                    if !same
                        && crit
                            .score(sa, planes[ra as usize].as_ref(), sb, planes[rb as usize].as_ref())
                            .is_none()
                    {
                        continue;
                    }
                    let (lo, hi) = if sa.first < sb.first { (ra, rb) } else { (rb, ra) };
                    let u = stats[lo as usize].combined(&stats[hi as usize]);
                    stats[lo as usize] = u;
                    planes[lo as usize] = fit(&u);
                    parent[hi as usize] = lo;
                    changed[lo as usize] = true;
                    n_merged += 1;
                    merged_now = true;
                }
                if !merged_now {
                    break;
                }
                // Shrink the graph to root pairs for the next pass; a pair keeps its score when both its regions are
                // unchanged roots (a pair that maps onto another one always has a changed region, so duplicates
                // carry no score).
                for (p, known) in graph.iter_mut() {
                    let (ra, rb) = (find(parent, p.0), find(parent, p.1));
                    if ra != p.0 || rb != p.1 || changed[ra as usize] || changed[rb as usize] {
                        *known = None;
                    }
                    *p = (ra.min(rb), ra.max(rb));
                }
                graph.retain(|(p, _)| p.0 != p.1);
                graph.sort_unstable_by_key(|e| e.0);
                graph.dedup_by_key(|e| e.0);
                changed.fill(false);
            }
            rewrite(labels, max_label, min_keep, (stats, parent, map));
            Merged { n_merged, n_passes }
        },
    )
}

/// The end of [`merge`]: every label's root once into `parent` (label 0 is its own root) and the label it becomes
/// into `map` (its root, or 0 where the root has fewer than `min_keep` pixels), then, if that changes a label, one
/// table look-up per pixel (16-pixel blocks of one label that keeps its number skipped).
fn rewrite(
    labels: &mut [u32],
    max_label: u32,
    min_keep: u32,
    (stats, parent, map): (&[Stats], &mut [u32], &mut Vec<u32>),
) {
    map.clear();
    let mut changes = false;
    for l in 0..=max_label {
        let r = find(parent, l);
        parent[l as usize] = r;
        let to = if stats[r as usize].count >= min_keep { r } else { 0 };
        changes |= to != l;
        map.push(to);
    }
    if changes {
        // A 16-pixel block of one label that maps to itself (most blocks: the roots keep their labels) is left
        // as it is after one side-by-side test; the other blocks are looked up pixel by pixel.
        let (blocks, rest) = labels.as_chunks_mut::<16>();
        for b in blocks {
            let l = b[0];
            if b.iter().fold(true, |a, &v| a & (v == l)) && map[l as usize] == l {
                continue;
            }
            for v in b.iter_mut() {
                *v = map[*v as usize];
            }
        }
        for v in rest {
            *v = map[*v as usize];
        }
    }
}

/// The region adjacency graph of `labels` (rows of `width`) into `pairs`: every pair `(a, b)`,
/// `0 < a < b`, of labels on adjacent pixels (right, down, and the two lower diagonals with `eight`),
/// sorted, once.
fn adjacent_pairs_into(labels: &[u32], width: usize, eight: bool, pairs: &mut Vec<(u32, u32)>) {
    let height = labels.len().checked_div(width).unwrap_or(0);
    pairs.clear();
    // The pairs pushed lately, direct-mapped by key: a border repeats its pair pixel after pixel, and a repeat
    // found here is not pushed (the list is sorted and deduplicated at the end, so only its length changes).
    let recent = &mut [0u64; 64];
    /// Pushes pair (a, b), smaller label first, unless `recent` holds it.
    #[inline(always)]
    fn put(pairs: &mut Vec<(u32, u32)>, recent: &mut [u64; 64], a: u32, b: u32) {
        let (lo, hi) = (a.min(b), a.max(b));
        let key = (u64::from(lo) << 32) | u64::from(hi);
        let slot = &mut recent[(key.wrapping_mul(0x9E37_79B9_7F4A_7C15) >> 58) as usize];
        if *slot != key {
            *slot = key;
            pairs.push((lo, hi));
        }
    }
    // Pairs of one pixel `x` of `row` with its right and lower (and lower diagonal) neighbours.
    let scan = |row: &[u32], below: &[u32], x: usize, pairs: &mut Vec<(u32, u32)>, recent: &mut [u64; 64]| {
        let mut push = |a: u32, b: u32| {
            if a != 0 && b != 0 && a != b {
                put(pairs, recent, a, b);
            }
        };
        let a = row[x];
        if a == 0 {
            return;
        }
        if x + 1 < row.len() {
            push(a, row[x + 1]);
        }
        if let Some(&b) = below.get(x) {
            push(a, b);
            if eight {
                if x + 1 < row.len() {
                    push(a, below[x + 1]);
                }
                if x > 0 {
                    push(a, below[x - 1]);
                }
            }
        }
    };
    const CHUNK: usize = 16;
    for y in 0..height {
        let row = &labels[y * width..(y + 1) * width];
        let below = if y + 1 < height { &labels[(y + 1) * width..(y + 2) * width] } else { &[][..] };
        let mut x = 0;
        if !eight && !below.is_empty() {
            // 16 pixels at a time: the test of `scan` (two different nonzero labels) with the right and the lower
            // neighbour evaluated without branches into two bit masks, and a pair pushed per bit set (the order
            // of the pushes does not matter: the pairs are sorted below).
            while x + CHUNK < width {
                let r: &[u32; CHUNK] = row[x..x + CHUNK].try_into().expect("CHUNK labels");
                let rr: &[u32; CHUNK] = row[x + 1..x + CHUNK + 1].try_into().expect("CHUNK labels");
                let b: &[u32; CHUNK] = below[x..x + CHUNK].try_into().expect("CHUNK labels");
                let pair = |p: u32, q: u32| u32::from(p != 0) & u32::from(q != 0) & u32::from(p != q);
                let (mut right, mut down) = (0u32, 0u32);
                for k in 0..CHUNK {
                    right |= pair(r[k], rr[k]) << k;
                    down |= pair(r[k], b[k]) << k;
                }
                for (mut mask, other) in [(right, rr), (down, b)] {
                    while mask != 0 {
                        let k = mask.trailing_zeros() as usize;
                        mask &= mask - 1;
                        put(pairs, recent, r[k], other[k]);
                    }
                }
                x += CHUNK;
            }
        }
        for xx in x..width {
            scan(row, below, xx, pairs, recent);
        }
    }
    // The order of the tuples, compared as one integer.
    pairs.sort_unstable_by_key(|&(a, b)| (u64::from(a) << 32) | u64::from(b));
    pairs.dedup();
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testutil::{box_scene, canonical};
    use rand::{RngExt, SeedableRng, rngs::Xoshiro256PlusPlus};

    /// Labels = 4×4 blocks of the box scene, so faces are split into many fragments.
    fn blocks(w: u32, h: u32, valid: &[bool]) -> (Vec<u32>, u32) {
        let bw = w.div_ceil(4);
        let mut max = 0;
        let l = (0..h)
            .flat_map(|y| (0..w).map(move |x| (x, y)))
            .enumerate()
            .map(|(i, (x, y))| {
                if !valid[i] {
                    return 0;
                }
                let id = (y / 4) * bw + x / 4 + 1;
                max = max.max(id);
                id
            })
            .collect();
        (l, max)
    }

    /// `rewrite` gives every pixel the label its root maps to (0 under `min_keep`), as one look-up per pixel does,
    /// on random label images made of runs (blocks of one label that keeps or changes its number, and mixed
    /// blocks) and random union-find forests.
    #[test]
    fn rewrite_matches_the_per_pixel_look_up() {
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(21);
        for case in 0..200 {
            let max_label = rng.random_range(1..40u32);
            let n = rng.random_range(0..300usize);
            let mut labels = Vec::with_capacity(n);
            while labels.len() < n {
                let l = rng.random_range(0..=max_label);
                let run = [1, 3, 16, 40][rng.random_range(0..4usize)];
                labels.extend(std::iter::repeat_n(l, run.min(n - labels.len())));
            }
            // A forest: each label's parent is itself or a smaller label (0 stays its own root).
            let mut parent: Vec<u32> =
                (0..=max_label)
                    .map(|l| {
                        if l > 0 && case % 3 != 0 && rng.random_bool(0.4) {
                            rng.random_range(1..=l)
                        } else {
                            l
                        }
                    })
                    .collect();
            let stats: Vec<Stats> = (0..=max_label)
                .map(|_| Stats { count: rng.random_range(0..20), ..Stats::default() })
                .collect();
            let min_keep = [0, 5, 10][case % 3];
            let root = |l: u32| {
                let mut r = l;
                while parent[r as usize] != r {
                    r = parent[r as usize];
                }
                r
            };
            let want: Vec<u32> = labels
                .iter()
                .map(|&l| {
                    let r = root(l);
                    if stats[r as usize].count >= min_keep { r } else { 0 }
                })
                .collect();
            let mut map = Vec::new();
            rewrite(&mut labels, max_label, min_keep, (&stats, &mut parent, &mut map));
            assert_eq!(labels, want, "case {case}");
        }
    }

    #[test]
    fn merge_is_independent_of_label_values() {
        let s = box_scene();
        let (w, h) = s.range.dimensions();
        let pts: Vec<[f32; 3]> = s.range.enumerate().map(|(x, y, &v)| [x as f32, y as f32, v]).collect();
        let valid: Vec<bool> = s.range.as_slice().iter().map(|v| v.is_finite()).collect();
        let (base, max) = blocks(w, h, &valid);
        let params = Params::default();
        let toward = |_p: [f64; 3]| [0.0, 0.0, -1.0];
        let run = |labels: &[u32]| {
            let mut l = labels.to_vec();
            let m = merge(
                &mut l,
                max,
                w as usize,
                false,
                &pts,
                s.features.k.as_slice(),
                &params,
                0,
                &toward,
                &mut Default::default(),
            );
            (canonical(&l), m.n_merged)
        };
        let (reference, n_merged) = run(&base);
        assert!(n_merged > 0, "the block fragments must merge");
        // Each face (A, B, box) becomes essentially one region: few distinct labels remain.
        let n_regions = reference.iter().copied().max().unwrap();
        assert!(n_regions < 40, "{n_regions} regions after merging 4×4 blocks");
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(7);
        for _ in 0..5 {
            let mut perm: Vec<u32> = (1..=max).collect();
            for i in (1..perm.len()).rev() {
                let j = rng.random_range(0..=i);
                perm.swap(i, j);
            }
            let shuffled: Vec<u32> =
                base.iter().map(|&l| if l == 0 { 0 } else { perm[l as usize - 1] }).collect();
            assert_eq!(run(&shuffled).0, reference);
        }
    }

    /// The merge loop as it was before scores were kept between passes: every pair scored in every pass and
    /// re-checked before each union (the reference of [`merge`]).
    #[allow(clippy::too_many_arguments)]
    fn merge_rescoring_every_pair<const N: usize>(
        labels: &mut [u32],
        max_label: u32,
        width: usize,
        eight: bool,
        pts: &[[f32; N]],
        k: &[f32],
        params: &Params,
        toward: &dyn Fn([f64; 3]) -> [f64; 3],
    ) -> (Vec<Stats>, u32, u32) {
        let mut stats = region_stats(labels, max_label, pts, k);
        let crit = Criterion::new(params);
        let fit = |s: &Stats| if crit.paper { None } else { Plane::fit(&s.mom, toward) };
        let mut planes: Vec<_> = stats.iter().map(|s| if s.count > 0 { fit(s) } else { None }).collect();
        let mut parent: Vec<u32> = (0..=max_label).collect();
        let mut pairs = Vec::new();
        adjacent_pairs_into(labels, width, eight, &mut pairs);
        let (mut n_merged, mut n_passes) = (0, 0);
        loop {
            n_passes += 1;
            let mut cand = Vec::new();
            for &(a, b) in &pairs {
                let (ra, rb) = (find(&mut parent, a), find(&mut parent, b));
                if ra == rb {
                    continue;
                }
                let (sa, sb) = (&stats[ra as usize], &stats[rb as usize]);
                if let Some(s) =
                    crit.score(sa, planes[ra as usize].as_ref(), sb, planes[rb as usize].as_ref())
                {
                    let (lo, hi) = if sa.first < sb.first { (ra, rb) } else { (rb, ra) };
                    cand.push((s, stats[lo as usize].first, stats[hi as usize].first, lo, hi));
                }
            }
            if cand.is_empty() {
                break;
            }
            cand.sort_unstable_by(|p, q| p.0.total_cmp(&q.0).then(p.1.cmp(&q.1)).then(p.2.cmp(&q.2)));
            cand.dedup_by(|p, q| p.1 == q.1 && p.2 == q.2);
            let mut changed = false;
            for &(_, _, _, a, b) in &cand {
                let (ra, rb) = (find(&mut parent, a), find(&mut parent, b));
                if ra == rb {
                    continue;
                }
                let (sa, sb) = (&stats[ra as usize], &stats[rb as usize]);
                if crit.score(sa, planes[ra as usize].as_ref(), sb, planes[rb as usize].as_ref()).is_none() {
                    continue;
                }
                let (lo, hi) = if sa.first < sb.first { (ra, rb) } else { (rb, ra) };
                let u = stats[lo as usize].combined(&stats[hi as usize]);
                stats[lo as usize] = u;
                planes[lo as usize] = fit(&u);
                parent[hi as usize] = lo;
                n_merged += 1;
                changed = true;
            }
            if !changed {
                break;
            }
            for p in pairs.iter_mut() {
                let (ra, rb) = (find(&mut parent, p.0), find(&mut parent, p.1));
                *p = (ra.min(rb), ra.max(rb));
            }
            pairs.retain(|p| p.0 != p.1);
            pairs.sort_unstable();
            pairs.dedup();
        }
        for l in labels.iter_mut() {
            if *l != 0 {
                *l = find(&mut parent, *l);
            }
        }
        (stats, n_merged, n_passes)
    }

    /// The chunked pair scan equals a pixel-by-pixel scan of every neighbour, on random label images of
    /// patches (so that chunks are skipped) with scattered zeros and other labels, 4- and 8-connected.
    #[test]
    fn adjacent_pairs_match_a_pixelwise_scan() {
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(18);
        let mut pairs = Vec::new();
        for case in 0..400 {
            let (w, h) = (rng.random_range(1..90usize), rng.random_range(1..30usize));
            let (bw, bh) = (rng.random_range(1..40usize), rng.random_range(1..12usize));
            let noise = [0.0, 0.003, 0.03, 0.3][case % 4];
            let labels: Vec<u32> = (0..w * h)
                .map(|i| {
                    let block = ((i % w) / bw + 3 * ((i / w) / bh)) as u32 % 5;
                    if rng.random_bool(noise) { rng.random_range(0..7) } else { block }
                })
                .collect();
            for eight in [false, true] {
                adjacent_pairs_into(&labels, w, eight, &mut pairs);
                let mut want = std::collections::BTreeSet::new();
                let offsets: &[(i64, i64)] =
                    if eight { &[(1, 0), (0, 1), (1, 1), (-1, 1)] } else { &[(1, 0), (0, 1)] };
                for y in 0..h as i64 {
                    for x in 0..w as i64 {
                        for &(dx, dy) in offsets {
                            let (nx, ny) = (x + dx, y + dy);
                            if nx < 0 || nx >= w as i64 || ny >= h as i64 {
                                continue;
                            }
                            let (a, b) =
                                (labels[(y * w as i64 + x) as usize], labels[(ny * w as i64 + nx) as usize]);
                            if a != 0 && b != 0 && a != b {
                                want.insert((a.min(b), a.max(b)));
                            }
                        }
                    }
                }
                assert_eq!(
                    pairs,
                    want.into_iter().collect::<Vec<_>>(),
                    "case {case} ({w}×{h}, eight: {eight})"
                );
            }
        }
    }

    /// Random fragmentations of noisy scenes, every mode and merge rule, one `MergeBufs` for all: the same
    /// labels, counts, passes and statistics (bit for bit) as scoring every pair in every pass.
    #[test]
    fn kept_scores_give_the_same_merges_as_rescoring() {
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(18);
        let mut bufs = MergeBufs::default();
        let variants = [
            Params::default(),
            Params::paper(),
            Params { merge_joint_rms_ratio: 0.0, ..Params::default() },
            Params { merge_max_angle_deg: 40.0, merge_max_residual: 20.0, t_m: 0.05, ..Params::default() },
            Params { merge_joint_rms_ratio: 3.0, merge_max_residual: 8.0, ..Params::default() },
        ];
        let mut total_merges = 0;
        for round in 0..40 {
            let s = if round % 2 == 0 { box_scene() } else { crate::testutil::abw_like_scene(48) };
            let (w, h) = s.range.dimensions();
            // Depth noise on the points, so regions fit their planes only approximately.
            let pts: Vec<[f32; 3]> = s
                .range
                .enumerate()
                .map(|(x, y, &v)| [x as f32, y as f32, v + rng.random_range(-0.6f32..0.6)])
                .collect();
            let valid: Vec<bool> = s.range.as_slice().iter().map(|v| v.is_finite()).collect();
            // Blocks of random sizes, some pixels unlabelled, labels shuffled.
            let (bw, bh) = (rng.random_range(1..7u32), rng.random_range(1..7u32));
            let nbx = w.div_ceil(bw);
            let max = nbx * h.div_ceil(bh);
            let mut perm: Vec<u32> = (1..=max).collect();
            for i in (1..perm.len()).rev() {
                perm.swap(i, rng.random_range(0..=i));
            }
            let labels: Vec<u32> = (0..w * h)
                .map(|i| {
                    let (x, y) = (i % w, i / w);
                    if !valid[i as usize] || rng.random_range(0..50u32) == 0 {
                        0
                    } else {
                        perm[((y / bh) * nbx + x / bw) as usize]
                    }
                })
                .collect();
            let params = &variants[round % variants.len()];
            let eight = round % 3 == 0;
            let toward = |_p: [f64; 3]| [0.0, 0.0, -1.0];
            let k = s.features.k.as_slice();
            let mut l0 = labels.clone();
            let (st0, m0, p0) =
                merge_rescoring_every_pair(&mut l0, max, w as usize, eight, &pts, k, params, &toward);
            let mut l1 = labels;
            let m = merge(&mut l1, max, w as usize, eight, &pts, k, params, 0, &toward, &mut bufs);
            assert_eq!((l1.as_slice(), m.n_merged, m.n_passes), (l0.as_slice(), m0, p0), "round {round}");
            for l in (1..=max as usize).filter(|&l| l0.contains(&(l as u32))) {
                let (a, b) = (&bufs.stats[l], &st0[l]);
                assert_eq!(
                    (a.count, a.n_k, a.first, a.sum_k.to_bits()),
                    (b.count, b.n_k, b.first, b.sum_k.to_bits())
                );
                assert_eq!(a.mom, b.mom);
            }
            total_merges += m0;
        }
        assert!(total_merges > 1000, "{total_merges} merges");
    }

    #[test]
    fn paper_merge_uses_only_mean_k() {
        // Two regions with equal K but different planes merge in paper mode, not in default mode.
        let labels0: Vec<u32> = (0..16).map(|i| if i % 4 < 2 { 1 } else { 2 }).collect();
        let pts: Vec<[f32; 3]> = (0..16)
            .map(|i| [(i % 4) as f32, (i / 4) as f32, if i % 4 < 2 { 0.0 } else { 5.0 * (i % 4) as f32 }])
            .collect();
        let k = vec![0.0f32; 16];
        let toward = |_p: [f64; 3]| [0.0, 0.0, -1.0];
        let mut l = labels0.clone();
        let m = merge(&mut l, 2, 4, false, &pts, &k, &Params::paper(), 0, &toward, &mut Default::default());
        assert_eq!((m.n_merged, l.iter().all(|&v| v == 1)), (1, true));
        let mut l = labels0.clone();
        let m = merge(&mut l, 2, 4, false, &pts, &k, &Params::default(), 0, &toward, &mut Default::default());
        assert_eq!((m.n_merged, l), (0, labels0));
    }

    /// The run-wise accumulation equals `Moments::add` pixel by pixel, bit for bit.
    #[test]
    fn region_stats_match_pixelwise_sums() {
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(5);
        for _ in 0..20 {
            let n = rng.random_range(1..400usize);
            let max = rng.random_range(1..6u32);
            // Runs of equal labels, including 0.
            let mut labels = Vec::with_capacity(n);
            while labels.len() < n {
                let l = rng.random_range(0..=max);
                let run = rng.random_range(1..8usize);
                labels.extend(std::iter::repeat_n(l, run.min(n - labels.len())));
            }
            let pts: Vec<[f32; 4]> = (0..n)
                .map(|_| {
                    [
                        rng.random_range(-500.0..500.0),
                        rng.random_range(-500.0..500.0),
                        rng.random_range(0.0..300.0),
                        0.0,
                    ]
                })
                .collect();
            let k: Vec<f32> =
                (0..n).map(|i| if i % 7 == 3 { f32::NAN } else { rng.random_range(-0.1..0.1) }).collect();
            let st = region_stats(&labels, max, &pts, &k);
            for l in 1..=max {
                let mut r = Stats { first: u32::MAX, ..Stats::default() };
                for i in (0..n).filter(|&i| labels[i] == l) {
                    if r.count == 0 {
                        r.first = i as u32;
                    }
                    r.count += 1;
                    if k[i].is_finite() {
                        r.sum_k += f64::from(k[i]);
                        r.n_k += 1;
                    }
                    r.mom.add([f64::from(pts[i][0]), f64::from(pts[i][1]), f64::from(pts[i][2])]);
                }
                let s = &st[l as usize];
                assert_eq!((s.count, s.n_k, s.first), (r.count, r.n_k, r.first));
                assert_eq!(s.sum_k.to_bits(), r.sum_k.to_bits());
                assert_eq!(s.mom, r.mom);
            }
        }
    }

    /// The statistics of the pixels `x in xs, y in ys` of the surface `z(x, y)` rounded to whole units.
    fn strip(xs: std::ops::Range<i32>, ys: std::ops::Range<i32>, z: impl Fn(f64, f64) -> f64) -> Stats {
        let mut s = Stats { first: 0, ..Stats::default() };
        for y in ys {
            for x in xs.clone() {
                let (x, y) = (f64::from(x), f64::from(y));
                s.mom.add([x, y, z(x, y).round()]);
                s.count += 1;
            }
        }
        s
    }

    #[test]
    fn joint_fit_merges_thin_strips_of_one_plane_and_not_of_two() {
        let params = Params::default();
        let crit = Criterion::new(&params);
        let fit = |s: &Stats| Plane::fit(&s.mom, |_| [0.0, 0.0, 1.0]);
        let plane = |x: f64, y: f64| 0.31 * x + 0.07 * y;
        // Two 3-pixel-wide strips of one plane, one above the other, whose mean K (noise of the
        // staircase in the curvature) differ beyond `t_m`: the pairwise test refuses them, the joint fit,
        // as good as each strip's own, merges them.
        let (mut a, mut b) = (strip(0..3, 0..150, plane), strip(0..3, 150..300, plane));
        (a.n_k, a.sum_k, b.n_k, b.sum_k) = (a.count, 0.0, b.count, 2.0 * crit.t_m * f64::from(b.count));
        let (pa, pb) = (fit(&a).unwrap(), fit(&b).unwrap());
        assert!(crit.pairwise(&a, Some(&pa), &b, Some(&pb)).is_none());
        assert!(crit.score(&a, Some(&pa), &b, Some(&pb)).is_some(), "one plane: merged by the joint fit");
        // The same strips on two planes 3° apart along the strip: the joint fit is much worse than each.
        let bent = |x: f64, y: f64| plane(x, y) + (y - 150.0).max(0.0) * 3f64.to_radians().tan();
        let c = strip(0..3, 150..300, bent);
        let pc = fit(&c).unwrap();
        assert!(crit.joint(&a, Some(&pa), &c, Some(&pc)).is_none(), "two planes: kept apart");
        // Off when the ratio is 0.
        let off = Criterion::new(&Params { merge_joint_rms_ratio: 0.0, ..Params::default() });
        assert!(off.joint(&a, Some(&pa), &b, Some(&pb)).is_none());
    }
}
