//! Per-region statistics and the deterministic merge fixpoint over the region adjacency graph.

use crate::plane::{Moments, Plane, dot};
use crate::{Mode, Params};

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

/// Statistics of labels `0..=max_label` (entry 0 unused) in raster order.
pub(crate) fn region_stats(labels: &[u32], max_label: u32, pts: &[[f32; 3]], k: &[f32]) -> Vec<Stats> {
    let mut st = vec![Stats { first: u32::MAX, ..Stats::default() }; max_label as usize + 1];
    for (i, &l) in labels.iter().enumerate() {
        if l == 0 {
            continue;
        }
        let s = &mut st[l as usize];
        if s.count == 0 {
            s.first = i as u32;
        }
        s.count += 1;
        let kv = k[i];
        if kv.is_finite() {
            s.sum_k += f64::from(kv);
            s.n_k += 1;
        }
        let p = pts[i];
        s.mom.add([f64::from(p[0]), f64::from(p[1]), f64::from(p[2])]);
    }
    st
}

/// The merge thresholds, pre-converted.
struct Criterion {
    paper: bool,
    t_m: f64,
    cos_angle: f64,
    max_angle_deg: f64,
    max_residual: f64,
}

impl Criterion {
    fn new(params: &Params) -> Self {
        Self {
            paper: params.mode == Mode::Paper,
            t_m: f64::from(params.t_m),
            cos_angle: f64::from(params.merge_max_angle_deg).to_radians().cos(),
            max_angle_deg: f64::from(params.merge_max_angle_deg),
            max_residual: f64::from(params.merge_max_residual),
        }
    }

    /// Dissimilarity score (< 1-ish, smaller = more similar) if the two regions may merge.
    fn score(&self, a: &Stats, pa: Option<&Plane>, b: &Stats, pb: Option<&Plane>) -> Option<f64> {
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

/// Outcome of [`merge`].
pub(crate) struct Merged {
    /// Statistics indexed by label; valid for every label still present in the image.
    pub(crate) stats: Vec<Stats>,
    /// Merge operations.
    pub(crate) n_merged: u32,
    /// Passes over the adjacency graph.
    pub(crate) n_passes: u32,
}

/// Merges adjacent similar regions of `labels` (values `0..=max_label`, 0 = none) until a full
/// pass merges nothing, and rewrites `labels` with the surviving labels.
///
/// Candidate pairs are processed in order of (score, first pixel of either region); the surviving
/// label of a union is the one whose region starts first in raster order. Nothing depends on the
/// numeric label values, so a relabelled input yields the same partition.
#[allow(clippy::too_many_arguments)]
pub(crate) fn merge(
    labels: &mut [u32],
    max_label: u32,
    width: usize,
    eight: bool,
    pts: &[[f32; 3]],
    k: &[f32],
    params: &Params,
    toward: &dyn Fn([f64; 3]) -> [f64; 3],
) -> Merged {
    let mut stats = region_stats(labels, max_label, pts, k);
    let crit = Criterion::new(params);
    let fit = |s: &Stats| if crit.paper { None } else { s.mom.fit(toward) };
    let mut planes: Vec<Option<Plane>> =
        stats.iter().map(|s| if s.count > 0 { fit(s) } else { None }).collect();
    let mut parent: Vec<u32> = (0..=max_label).collect();

    // Region adjacency graph from pixel pairs (right, down, and the two diagonals for 8-connectivity).
    let height = labels.len().checked_div(width).unwrap_or(0);
    let mut pairs: Vec<(u32, u32)> = Vec::new();
    let mut push = |a: u32, b: u32| {
        if a != 0 && b != 0 && a != b {
            pairs.push((a.min(b), a.max(b)));
        }
    };
    for y in 0..height {
        for x in 0..width {
            let i = y * width + x;
            let a = labels[i];
            if a == 0 {
                continue;
            }
            if x + 1 < width {
                push(a, labels[i + 1]);
            }
            if y + 1 < height {
                push(a, labels[i + width]);
                if eight {
                    if x + 1 < width {
                        push(a, labels[i + width + 1]);
                    }
                    if x > 0 {
                        push(a, labels[i + width - 1]);
                    }
                }
            }
        }
    }
    pairs.sort_unstable();
    pairs.dedup();

    fn find(parent: &mut [u32], mut a: u32) -> u32 {
        while parent[a as usize] != a {
            let g = parent[parent[a as usize] as usize];
            parent[a as usize] = g;
            a = g;
        }
        a
    }

    let mut n_merged = 0;
    let mut n_passes = 0;
    let mut cand: Vec<(f64, u32, u32, u32, u32)> = Vec::new();
    loop {
        n_passes += 1;
        cand.clear();
        for &(a, b) in &pairs {
            let (ra, rb) = (find(&mut parent, a), find(&mut parent, b));
            if ra == rb {
                continue;
            }
            let (sa, sb) = (&stats[ra as usize], &stats[rb as usize]);
            if let Some(s) = crit.score(sa, planes[ra as usize].as_ref(), sb, planes[rb as usize].as_ref()) {
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
        // Shrink the graph to root pairs for the next pass.
        for p in pairs.iter_mut() {
            let (ra, rb) = (find(&mut parent, p.0), find(&mut parent, p.1));
            *p = (ra.min(rb), ra.max(rb));
        }
        pairs.retain(|p| p.0 != p.1);
        pairs.sort_unstable();
        pairs.dedup();
    }
    if n_merged > 0 {
        for l in labels.iter_mut() {
            if *l != 0 {
                *l = find(&mut parent, *l);
            }
        }
    }
    Merged { stats, n_merged, n_passes }
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
            let m = merge(&mut l, max, w as usize, false, &pts, s.features.k.as_slice(), &params, &toward);
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
        let m = merge(&mut l, 2, 4, false, &pts, &k, &Params::paper(), &toward);
        assert_eq!((m.n_merged, l.iter().all(|&v| v == 1)), (1, true));
        let mut l = labels0.clone();
        let m = merge(&mut l, 2, 4, false, &pts, &k, &Params::default(), &toward);
        assert_eq!((m.n_merged, l), (0, labels0));
    }
}
