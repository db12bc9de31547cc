//! Boundary precision, recall and F-measure of an edge map against ground-truth region boundaries.
//!
//! # Rules
//! - **GT boundary** ([`gt_boundaries`]): a pixel labelled as a GT region (label ≥ 10) with a
//!   4-neighbour labelled as a *different* GT region. Both sides of a crack are boundary pixels.
//! - **Don't-care** ([`dont_care`]): GT labels 0..=9 are unlabelled (0..=3 = no data, noise or
//!   too small in the ABW convention; 4..=9 are illegal there and treated the same). Every pixel
//!   within `τ` (Euclidean, inclusive) of an unlabelled GT pixel is don't-care, and is removed from
//!   *both* the detected set and the GT boundary set before anything is counted or matched.
//! - **Within τ**: Euclidean distance between pixel centres ≤ `τ` (squared distances are compared,
//!   exactly). `τ = 0` means "same pixel".
//! - **Simple** ([`simple`]): `P` = detected pixels within `τ` of some GT boundary pixel ÷ detected
//!   pixels; `R` = GT boundary pixels within `τ` of some detected pixel ÷ GT boundary pixels. Many
//!   detected pixels may be explained by one GT pixel.
//! - **Matched** ([`matched`]): one-to-one, as in the BSDS benchmark. Both maps are first
//!   thinned to one-pixel-wide lines with [`thin::thin`] (BSDS thins the machine map with
//!   `bwmorph(…, 'thin', Inf)`; its GT boundaries are one pixel wide, so our two-pixel GT band is
//!   thinned the same way), on the whole image, before the don't-care pixels are removed. Then a
//!   maximum-cardinality bipartite matching between the thinned detected and GT pixels, where a
//!   pair may be matched only if the two pixels are within `τ`. `P` = matched ÷ detected,
//!   `R` = matched ÷ GT, both counted after thinning. Without the thinning, two parallel lines
//!   (C1 beside C2) would match the two sides of the GT band and score as one perfect edge.
//!   Two consequences: the thinned band keeps one side of the crack (for a straight vertical or
//!   horizontal one, the left or lower side), so a detection on the other side is matched at up
//!   to `τ − 1` px of it; and a segmentation's own boundaries ([`rangeimage::boundary::label_boundaries`]) hold its
//!   unlabelled separator pixels, which can move the thinned line near unlabelled GT, so even a
//!   segmentation equal to the GT may score slightly below 1 there.
//!   BSDS solves a min-cost assignment with an outlier cost; its cardinality is the maximum one,
//!   which is all `P` and `R` depend on. We compute it with Hopcroft–Karp on the sparse graph of
//!   pairs within `τ` (deterministic: vertices in raster order, each vertex's candidates nearest
//!   first).
//! - **Conventions** (BSDS `collect_eval_bdry`): a ratio with a zero denominator is 0 (so `P = 0`
//!   when nothing is detected, `R = 0` when there is no GT boundary), and
//!   `F = 2PR / (P + R)`, 0 when `P + R = 0`. The counts in [`Prf`] let a caller tell these apart.

use crate::distance::{dilate, edt_squared, radius_squared};
use crate::thin;
use rangeimage::{EdgeMap, Grid, LabelImage};

/// Smallest label that names a region in the ABW convention (docs/method.md §2.1).
pub const FIRST_REGION_LABEL: u32 = 10;

/// Precision, recall and F-measure with the counts they come from.
#[derive(Debug, Clone, Copy, PartialEq, Default, serde::Serialize)]
pub struct Prf {
    /// Detected pixels explained by the GT ÷ detected pixels (0 if nothing is detected).
    pub precision: f64,
    /// GT boundary pixels found ÷ GT boundary pixels (0 if there is no GT boundary).
    pub recall: f64,
    /// `2PR / (P + R)`, 0 if both are 0.
    pub f: f64,
    /// Detected edge pixels outside the don't-care zone.
    pub n_detected: u64,
    /// Detected pixels counted as correct (within τ of the GT, or matched one-to-one).
    pub n_detected_matched: u64,
    /// GT boundary pixels outside the don't-care zone.
    pub n_gt: u64,
    /// GT boundary pixels counted as found.
    pub n_gt_matched: u64,
}

impl Prf {
    /// Builds the ratios from the four counts with the BSDS conventions (x / 0 = 0).
    pub fn from_counts(n_detected: u64, n_detected_matched: u64, n_gt: u64, n_gt_matched: u64) -> Self {
        let ratio = |a: u64, b: u64| if b == 0 { 0.0 } else { a as f64 / b as f64 };
        let precision = ratio(n_detected_matched, n_detected);
        let recall = ratio(n_gt_matched, n_gt);
        let f = if precision + recall > 0.0 { 2.0 * precision * recall / (precision + recall) } else { 0.0 };
        Self { precision, recall, f, n_detected, n_detected_matched, n_gt, n_gt_matched }
    }
}

/// GT boundary: pixels labelled ≥ 10 with a 4-neighbour labelled ≥ 10 and different.
pub fn gt_boundaries(gt: &LabelImage) -> EdgeMap {
    rangeimage::boundary::region_borders(gt, |l| l >= FIRST_REGION_LABEL)
}

/// Don't-care mask for `gt`: pixels within `tolerance_px` of a GT pixel labelled 0..=9.
///
/// # Panics
/// If `tolerance_px` is negative or not finite.
pub fn dont_care(gt: &LabelImage, tolerance_px: f64) -> Grid<bool> {
    dilate(&gt.map(|&l| l < FIRST_REGION_LABEL), tolerance_px)
}

/// Simple-distance boundary P/R/F of `detected` against the boundaries of `gt` (see the module rules).
///
/// # Panics
/// If the sizes differ or `tolerance_px` is negative or not finite.
pub fn simple(detected: &EdgeMap, gt: &LabelImage, tolerance_px: f64) -> Prf {
    simple_masked(detected, &gt_boundaries(gt), &dont_care(gt, tolerance_px), tolerance_px)
}

/// One-to-one matched boundary P/R/F of `detected` against the boundaries of `gt` (see the module rules).
///
/// # Panics
/// If the sizes differ or `tolerance_px` is negative or not finite.
pub fn matched(detected: &EdgeMap, gt: &LabelImage, tolerance_px: f64) -> Prf {
    matched_masked(detected, &gt_boundaries(gt), &dont_care(gt, tolerance_px), tolerance_px)
}

/// [`simple`] with an explicit GT boundary map and don't-care mask (`true` = ignore this pixel).
///
/// The mask is used as given (not dilated): pass [`dont_care`] or your own.
///
/// # Panics
/// If the sizes differ or `tolerance_px` is negative or not finite.
pub fn simple_masked(
    detected: &EdgeMap,
    gt_boundary: &EdgeMap,
    dont_care: &Grid<bool>,
    tolerance_px: f64,
) -> Prf {
    let _s = tracing::info_span!("eval::boundary::simple").entered();
    let r2 = radius_squared(tolerance_px);
    let (d, g) = cared(detected, gt_boundary, dont_care);
    let dist_to_g = edt_squared(&g);
    let dist_to_d = edt_squared(&d);
    let count = |set: &Grid<bool>, dist: &Grid<f64>| -> (u64, u64) {
        let mut n = 0;
        let mut hit = 0;
        for (&b, &d2) in set.as_slice().iter().zip(dist.as_slice()) {
            if b {
                n += 1;
                hit += u64::from(d2 <= r2);
            }
        }
        (n, hit)
    };
    let (nd, nd_hit) = count(&d, &dist_to_g);
    let (ng, ng_hit) = count(&g, &dist_to_d);
    let prf = Prf::from_counts(nd, nd_hit, ng, ng_hit);
    tracing::debug!(?prf, "simple boundary score");
    prf
}

/// [`matched`] with an explicit GT boundary map and don't-care mask (`true` = ignore this pixel).
///
/// Both `detected` and `gt_boundary` are thinned ([`thin::thin`]) before the mask is applied.
/// The mask is used as given (not dilated): pass [`dont_care`] or your own.
///
/// # Panics
/// If the sizes differ or `tolerance_px` is negative or not finite.
pub fn matched_masked(
    detected: &EdgeMap,
    gt_boundary: &EdgeMap,
    dont_care: &Grid<bool>,
    tolerance_px: f64,
) -> Prf {
    let _s = tracing::info_span!("eval::boundary::matched").entered();
    let r2 = radius_squared(tolerance_px);
    let (d, g) = cared(&thin::thin(detected), &thin::thin(gt_boundary), dont_care);
    let (w, h) = d.dimensions();
    // Right side: GT pixels, indexed in raster order.
    const NIL: u32 = u32::MAX;
    let mut g_index = vec![NIL; g.len()];
    let mut n_g = 0u32;
    for (i, &b) in g.as_slice().iter().enumerate() {
        if b {
            g_index[i] = n_g;
            n_g += 1;
        }
    }
    // Left side: detected pixels in raster order, each with its GT candidates nearest first.
    // No two pixels are farther apart than the corners, so a larger τ changes nothing but the cost.
    let corners2 = f64::from(w.saturating_sub(1)).powi(2) + f64::from(h.saturating_sub(1)).powi(2);
    let offsets = disk_offsets(r2.min(corners2));
    let mut start = vec![0u32];
    let mut adj = Vec::new();
    for (x, y, &b) in d.enumerate() {
        if !b {
            continue;
        }
        for &(dx, dy) in &offsets {
            let (gx, gy) = (i64::from(x) + dx, i64::from(y) + dy);
            if gx >= 0 && gy >= 0 && gx < i64::from(w) && gy < i64::from(h) {
                let j = g_index[gy as usize * w as usize + gx as usize];
                if j != NIL {
                    adj.push(j);
                }
            }
        }
        start.push(u32::try_from(adj.len()).expect("fewer than 2^32 candidate pairs"));
    }
    let n_d = start.len() - 1;
    let size = max_matching(&start, &adj, n_g as usize) as u64;
    let prf = Prf::from_counts(n_d as u64, size, u64::from(n_g), size);
    tracing::debug!(?prf, pairs = adj.len(), "matched boundary score");
    prf
}

/// The detected and GT sets with the don't-care pixels removed.
fn cared(detected: &EdgeMap, gt_boundary: &EdgeMap, dont_care: &Grid<bool>) -> (EdgeMap, EdgeMap) {
    assert!(
        detected.same_size(gt_boundary) && detected.same_size(dont_care),
        "detected {:?}, GT boundary {:?} and don't-care {:?} must have the same size",
        detected.dimensions(),
        gt_boundary.dimensions(),
        dont_care.dimensions()
    );
    let keep = |set: &EdgeMap| {
        let v = set.as_slice().iter().zip(dont_care.as_slice()).map(|(&b, &dc)| b && !dc).collect();
        Grid::from_vec(set.width(), set.height(), v).expect("same size")
    };
    (keep(detected), keep(gt_boundary))
}

/// Integer offsets with `dx² + dy² ≤ r2`, nearest first (ties by `dy`, then `dx`).
fn disk_offsets(r2: f64) -> Vec<(i64, i64)> {
    let r = r2.sqrt().floor() as i64;
    let mut v: Vec<(i64, i64)> = (-r..=r)
        .flat_map(|dy| (-r..=r).map(move |dx| (dx, dy)))
        .filter(|&(dx, dy)| (dx * dx + dy * dy) as f64 <= r2)
        .collect();
    v.sort_by_key(|&(dx, dy)| (dx * dx + dy * dy, dy, dx));
    v
}

/// Size of a maximum matching of the bipartite graph given in CSR form (Hopcroft–Karp).
///
/// Left vertex `u` has neighbours `adj[start[u]..start[u + 1]]`, right vertices are `0..n_right`.
/// A greedy pass (each left vertex takes its first free neighbour) seeds the matching; then
/// phases of BFS layering and iterative DFS augment along shortest augmenting paths.
fn max_matching(start: &[u32], adj: &[u32], n_right: usize) -> usize {
    const NIL: u32 = u32::MAX;
    const INF: u32 = u32::MAX;
    let n_left = start.len() - 1;
    let edges = |u: usize| start[u] as usize..start[u + 1] as usize;
    let mut match_l = vec![NIL; n_left];
    let mut match_r = vec![NIL; n_right];
    let mut size = 0;
    for u in 0..n_left {
        if let Some(&r) = adj[edges(u)].iter().find(|&&r| match_r[r as usize] == NIL) {
            match_l[u] = r;
            match_r[r as usize] = u as u32;
            size += 1;
        }
    }
    let mut dist = vec![INF; n_left];
    let mut queue = Vec::with_capacity(n_left);
    let mut it = vec![0usize; n_left];
    let mut stack: Vec<usize> = Vec::new();
    loop {
        // BFS layering from every free left vertex.
        queue.clear();
        for u in 0..n_left {
            if match_l[u] == NIL {
                dist[u] = 0;
                queue.push(u);
            } else {
                dist[u] = INF;
            }
        }
        let mut found = false;
        let mut head = 0;
        while head < queue.len() {
            let u = queue[head];
            head += 1;
            for &r in &adj[edges(u)] {
                let v = match_r[r as usize];
                if v == NIL {
                    found = true;
                } else if dist[v as usize] == INF {
                    dist[v as usize] = dist[u] + 1;
                    queue.push(v as usize);
                }
            }
        }
        if !found {
            break;
        }
        // DFS along the layers from every free left vertex; dead ends get dist = INF.
        for u in 0..n_left {
            it[u] = start[u] as usize;
        }
        for root in 0..n_left {
            if match_l[root] != NIL {
                continue;
            }
            stack.clear();
            stack.push(root);
            while let Some(&u) = stack.last() {
                if it[u] == start[u + 1] as usize {
                    dist[u] = INF;
                    stack.pop();
                    if let Some(&p) = stack.last() {
                        it[p] += 1;
                    }
                    continue;
                }
                let r = adj[it[u]];
                let v = match_r[r as usize];
                if v == NIL {
                    // Augment: every vertex on the stack takes the edge it is currently on.
                    for &s in &stack {
                        let rs = adj[it[s]];
                        match_l[s] = rs;
                        match_r[rs as usize] = s as u32;
                    }
                    size += 1;
                    break;
                }
                if dist[v as usize] != INF && dist[v as usize] == dist[u] + 1 {
                    stack.push(v as usize);
                } else {
                    it[u] += 1;
                }
            }
        }
    }
    size
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    /// Two regions side by side: label 10 for x < split, 11 for x ≥ split.
    fn two_regions(w: u32, h: u32, split: u32) -> LabelImage {
        Grid::from_fn(w, h, |x, _| if x < split { 10 } else { 11 })
    }

    #[test]
    fn gt_boundary_is_two_sided_and_ignores_unlabelled() {
        let gt = Grid::from_rows(vec![vec![10, 10, 11, 11, 0, 12], vec![10, 10, 11, 11, 0, 12]]).unwrap();
        let b = gt_boundaries(&gt);
        let row: Vec<bool> = b.rows().next().unwrap().to_vec();
        assert_eq!(row, vec![false, true, true, false, false, false]);
    }

    #[test]
    fn perfect_detection_scores_one() {
        let gt = two_regions(12, 8, 6);
        let det = gt_boundaries(&gt);
        for tau in [0.0, 1.0, 2.0] {
            let s = simple(&det, &gt, tau);
            let m = matched(&det, &gt, tau);
            for prf in [s, m] {
                assert_eq!((prf.precision, prf.recall, prf.f), (1.0, 1.0, 1.0));
            }
            // Simple counts the 2-px band (16 px); matched its thinned line: column 5, rows 1..=7.
            assert_eq!((s.n_gt, m.n_gt), (16, 7));
        }
    }

    #[test]
    fn nothing_detected_follows_bsds_conventions() {
        let gt = two_regions(6, 4, 3);
        let prf = matched(&Grid::new(6, 4, false), &gt, 2.0);
        // The 8-px GT band thins to column 2, rows 1..=3.
        assert_eq!((prf.precision, prf.recall, prf.f, prf.n_detected, prf.n_gt), (0.0, 0.0, 0.0, 0, 3));
        let one_region = Grid::new(6, 4, 10u32);
        let prf = simple(&Grid::new(6, 4, true), &one_region, 2.0);
        assert_eq!((prf.precision, prf.recall, prf.n_gt, prf.n_detected), (0.0, 0.0, 0, 24));
    }

    /// GT boundary at columns 5|6 of a 12×10 image (20 GT pixels; thinned: column 5, rows 1..=9,
    /// 9 pixels); the detection is the single column x = 8, i.e. 2 px right of column 6 and 3 px
    /// right of column 5 (10 detected pixels, already thin).
    #[test]
    fn shifted_boundary_by_hand() {
        let gt = two_regions(12, 10, 6);
        let det = Grid::from_fn(12, 10, |x, _| x == 8);
        // τ = 1: nothing is within 1 px.
        let s = simple(&det, &gt, 1.0);
        assert_eq!((s.n_detected, s.n_detected_matched, s.n_gt, s.n_gt_matched), (10, 0, 20, 0));
        let m = matched(&det, &gt, 1.0);
        assert_eq!((m.n_detected, m.n_detected_matched, m.n_gt, m.n_gt_matched), (10, 0, 9, 0));
        // τ = 2, simple (unthinned band): every detected pixel is 2 px from column 6 → P = 1;
        // only column 6 is within 2 px of the detection (column 5 is 3 px away) → R = 10 / 20.
        let s = simple(&det, &gt, 2.0);
        assert_eq!((s.n_detected_matched, s.n_gt_matched), (10, 10));
        assert_relative_eq!(s.precision, 1.0);
        assert_relative_eq!(s.recall, 0.5);
        assert_relative_eq!(s.f, 2.0 / 3.0);
        // τ = 2, matched: the thinned GT line is column 5, 3 px away → nothing matches.
        let m = matched(&det, &gt, 2.0);
        assert_eq!((m.n_detected, m.n_detected_matched, m.n_gt, m.n_gt_matched), (10, 0, 9, 0));
        // τ = 3: simple R = 1; matched pairs the 9 GT pixels → P = 9 / 10, R = 1.
        let s = simple(&det, &gt, 3.0);
        let m = matched(&det, &gt, 3.0);
        assert_relative_eq!(s.recall, 1.0);
        assert_eq!((m.n_detected_matched, m.n_gt_matched), (9, 9));
        assert_relative_eq!(m.precision, 0.9);
        assert_relative_eq!(m.recall, 1.0);
    }

    /// A thick detection (columns 4..=7) thins to one line; two parallel lines stay two.
    #[test]
    fn thick_and_doubled_detections_by_hand() {
        let gt = two_regions(12, 10, 6);
        let thick = Grid::from_fn(12, 10, |x, _| (4..=7).contains(&x));
        let s = simple(&thick, &gt, 1.0);
        assert_eq!((s.n_detected, s.n_detected_matched, s.n_gt, s.n_gt_matched), (40, 40, 20, 20));
        // Thinned: column 5, rows 2..=8 (7 px), on the GT's thinned line (column 5, rows 1..=9).
        let m = matched(&thick, &gt, 1.0);
        assert_eq!((m.n_detected, m.n_detected_matched, m.n_gt, m.n_gt_matched), (7, 7, 9, 7));
        assert_relative_eq!(m.precision, 1.0);
        assert_relative_eq!(m.recall, 7.0 / 9.0);
        // Two parallel lines, columns 4 and 7 (C1 beside C2, say), τ = 2: each lies within 1 px
        // of one side of the GT band, so simple scores them perfect; unthinned one-to-one matching
        // would too (column 4 ↔ 5, column 7 ↔ 6). After thinning, the 9 GT pixels take 9 of the
        // 20 detected ones: P = 0.45.
        let doubled = Grid::from_fn(12, 10, |x, _| x == 4 || x == 7);
        let s = simple(&doubled, &gt, 2.0);
        assert_eq!((s.precision, s.recall), (1.0, 1.0));
        let m = matched(&doubled, &gt, 2.0);
        assert_eq!((m.n_detected, m.n_detected_matched, m.n_gt, m.n_gt_matched), (20, 9, 9, 9));
        assert_relative_eq!(m.precision, 0.45);
        assert_relative_eq!(m.recall, 1.0);
    }

    /// A τ beyond the image's extent gives the same result as the farthest pixel pair, at the same cost
    /// (τ = 1e9 used to enumerate about 4·10¹⁸ offsets).
    #[test]
    fn huge_tolerance_is_clamped_to_the_image() {
        let gt = two_regions(12, 10, 6);
        let det = Grid::from_fn(12, 10, |x, y| x == 2 || (x + y) % 5 == 0);
        let far = (11.0f64 * 11.0 + 9.0 * 9.0).sqrt();
        let m = matched_masked(&det, &gt_boundaries(&gt), &Grid::new(12, 10, false), far);
        for tau in [far + 0.5, 1e9, f64::MAX.sqrt()] {
            assert_eq!(matched_masked(&det, &gt_boundaries(&gt), &Grid::new(12, 10, false), tau), m, "{tau}");
        }
    }

    #[test]
    fn dont_care_removes_pixels_near_unlabelled() {
        // Column 0 unlabelled; regions 10 | 11 split at x = 2.
        let gt = Grid::from_fn(8, 4, |x, _| match x {
            0 => 0,
            1 => 10,
            _ => 11,
        });
        let dc = dont_care(&gt, 1.0);
        assert!(dc[(0, 0)] && dc[(1, 0)] && !dc[(2, 0)]);
        // Boundary pixels are columns 1 and 2; column 1 is don't-care at τ = 1.
        let det = Grid::from_fn(8, 4, |x, _| x == 1 || x == 6);
        let s = simple(&det, &gt, 1.0);
        assert_eq!((s.n_detected, s.n_detected_matched, s.n_gt, s.n_gt_matched), (4, 0, 4, 0));
    }

    #[test]
    fn matching_needs_augmenting_paths() {
        // Left 0 may take right 0 or 1, left 1 only right 0: greedy gives 1, the maximum is 2.
        let start = [0, 2, 3];
        let adj = [0, 1, 0];
        assert_eq!(max_matching(&start, &adj, 2), 2);
        // A longer chain where greedy picks the wrong first edge at every step.
        let start = [0, 2, 4, 5];
        let adj = [0, 1, 1, 2, 0];
        assert_eq!(max_matching(&start, &adj, 3), 3);
    }

    mod proptests {
        use super::*;
        use proptest::prelude::*;
        use rangeimage::testing::arbitrary_label_image;

        /// Exhaustive maximum matching by augmenting paths (Kuhn), for small graphs.
        fn kuhn(start: &[u32], adj: &[u32], n_right: usize) -> usize {
            fn try_kuhn(u: usize, start: &[u32], adj: &[u32], seen: &mut [bool], mr: &mut [usize]) -> bool {
                for &r in &adj[start[u] as usize..start[u + 1] as usize] {
                    let r = r as usize;
                    if !seen[r] {
                        seen[r] = true;
                        if mr[r] == usize::MAX || try_kuhn(mr[r], start, adj, seen, mr) {
                            mr[r] = u;
                            return true;
                        }
                    }
                }
                false
            }
            let mut mr = vec![usize::MAX; n_right];
            (0..start.len() - 1)
                .filter(|&u| try_kuhn(u, start, adj, &mut vec![false; n_right], &mut mr))
                .count()
        }

        proptest! {
            #[test]
            fn proptest_hopcroft_karp_is_maximum(
                lists in proptest::collection::vec(proptest::collection::vec(0u32..12, 0..5), 0..14)
            ) {
                let mut start = vec![0u32];
                let mut adj = Vec::new();
                for l in &lists {
                    adj.extend_from_slice(l);
                    start.push(adj.len() as u32);
                }
                prop_assert_eq!(max_matching(&start, &adj, 12), kuhn(&start, &adj, 12));
            }

            #[test]
            fn proptest_gt_against_itself_is_perfect(gt in arbitrary_label_image(1..20, 1..20, 14), tau in 0.0f64..3.0) {
                let det = gt_boundaries(&gt);
                for prf in [simple(&det, &gt, tau), matched(&det, &gt, tau)] {
                    prop_assert_eq!(prf.n_detected_matched, prf.n_detected);
                    prop_assert_eq!(prf.n_gt_matched, prf.n_gt);
                    if prf.n_gt > 0 {
                        prop_assert_eq!((prf.precision, prf.recall, prf.f), (1.0, 1.0, 1.0));
                    }
                }
            }

            #[test]
            fn proptest_matched_never_beats_simple(
                gt in arbitrary_label_image(2..16, 2..16, 13),
                bits in proptest::collection::vec(any::<bool>(), 256),
                tau in 0.0f64..3.0,
            ) {
                let det = Grid::from_fn(gt.width(), gt.height(), |x, y| bits[(y * 16 + x) as usize]);
                let s = simple(&det, &gt, tau);
                let m = matched(&det, &gt, tau);
                // Thinning only deletes; a thinned pixel matched within τ is within τ of the GT.
                prop_assert!(m.n_detected <= s.n_detected && m.n_gt <= s.n_gt);
                prop_assert!(m.n_detected_matched <= s.n_detected_matched);
                prop_assert!(m.n_gt_matched <= s.n_gt_matched);
                prop_assert!(m.n_detected_matched <= m.n_gt.min(m.n_detected));
            }
        }
    }
}
