//! Region boundaries of a label image, the one rule the final edge map and the evaluation share.

use crate::{EdgeMap, Grid, LabelImage};

/// Borders between regions: region pixels (`is_region(label)`) with a 4-neighbour in a different
/// region. Both sides of a border are marked; region-to-non-region transitions are not borders.
#[must_use]
pub fn region_borders(labels: &LabelImage, is_region: impl Fn(u32) -> bool) -> EdgeMap {
    let mut out = EdgeMap::default();
    boundaries_into(labels, is_region, false, &mut out);
    out
}

/// Boundaries of a segmentation: [`region_borders`], plus the non-region pixels whose 4-neighbours
/// include two different regions, so a one-pixel-wide unlabelled line between two regions (as
/// edge-based segmenters leave) counts as their boundary. Region-to-unlabelled transitions are not
/// boundaries.
#[must_use]
pub fn label_boundaries(labels: &LabelImage, is_region: impl Fn(u32) -> bool) -> EdgeMap {
    let mut out = EdgeMap::default();
    boundaries_into(labels, is_region, true, &mut out);
    out
}

/// `labels` into `out` with every valid unlabelled pixel (`valid` and label 0) that lies within `max_gap_px`
/// 4-connected steps of a region, through such pixels, given to the nearest region: step by step, each such
/// pixel takes the label its neighbours got in an earlier step, the first of up, left, right, down. The borders
/// of `out` ([`label_boundaries`]) then run through the middle of the gaps a segmentation leaves between its
/// regions, where they are narrower than `2 × max_gap_px + 1`. `gaps` ends with the pixels given a label (in no
/// particular order); its memory is reserved once to the image's size. Labels must lie below 2³¹ (the top bit marks
/// a step's new labels; checked in debug builds).
pub fn split_gaps_into(
    labels: &LabelImage,
    valid: &Grid<bool>,
    max_gap_px: u32,
    out: &mut LabelImage,
    gaps: &mut Vec<u32>,
) {
    /// Marks a label given in the current step, which the step's other pixels must not see yet.
    const FRESH: u32 = 1 << 31;
    debug_assert!(labels.same_size(valid), "labels and valid mask differ in size");
    out.copy_from(labels);
    let (w, h) = (labels.width() as usize, labels.height() as usize);
    let o = out.as_mut_slice();
    gaps.clear();
    if max_gap_px == 0 {
        return;
    }
    gaps.reserve(w * h);
    // Chunks without an unlabelled pixel are skipped by one branch-free test.
    const CHUNK: usize = 32;
    for (c, chunk) in o.chunks(CHUNK).enumerate() {
        if chunk.iter().fold(false, |any, &l| any | (l == 0)) {
            let start = c * CHUNK;
            let v = &valid.as_slice()[start..start + chunk.len()];
            let open = chunk.iter().zip(v).enumerate().filter(|&(_, (&l, &v))| l == 0 && v);
            gaps.extend(open.map(|(i, _)| (start + i) as u32));
        }
    }
    debug_assert!(o.iter().all(|&l| l < FRESH), "labels must stay below 2^31");
    // gaps[..done]: the pixels given a label so far; gaps[done..]: the others (their order does not matter: a
    // step's labels are marked fresh, so no pixel of a step sees another's).
    let mut done = 0;
    for _ in 0..max_gap_px {
        for &j in &gaps[done..] {
            let j = j as usize;
            let (x, y) = (j % w, j / w);
            // Most pixels of a wide gap have no labelled neighbour at all: one test away from the border.
            if x > 0 && x + 1 < w && y > 0 && y + 1 < h && (o[j - 1] | o[j + 1] | o[j - w] | o[j + w]) == 0 {
                continue;
            }
            let settled = |i: usize| Some(o[i]).filter(|&l| l != 0 && l & FRESH == 0);
            let up = if y > 0 { settled(j - w) } else { None };
            let left = if x > 0 { settled(j - 1) } else { None };
            let right = if x + 1 < w { settled(j + 1) } else { None };
            let down = if y + 1 < h { settled(j + w) } else { None };
            if let Some(l) = up.or(left).or(right).or(down) {
                o[j] = l | FRESH;
            }
        }
        let before = done;
        let mut k = done;
        while k < gaps.len() {
            let l = &mut o[gaps[k] as usize];
            if *l & FRESH != 0 {
                *l &= !FRESH;
                gaps.swap(k, done);
                done += 1;
            }
            k += 1;
        }
        if done == before || done == gaps.len() {
            break;
        }
    }
    gaps.truncate(done);
}

/// [`label_boundaries`] into `out`, whose memory is reused.
pub fn label_boundaries_into(labels: &LabelImage, is_region: impl Fn(u32) -> bool, out: &mut EdgeMap) {
    boundaries_into(labels, is_region, true, out);
}

/// The boundaries of [`region_borders`] (`separators = false`) or [`label_boundaries`] into `out`. An interior pixel
/// whose four neighbours all carry its own label is never one (a region pixel then has no neighbour in another
/// region; a non-region pixel has no region neighbour), so only the other pixels go through the full rule.
fn boundaries_into(
    labels: &LabelImage,
    is_region: impl Fn(u32) -> bool,
    separators: bool,
    out: &mut EdgeMap,
) {
    let (w, h) = labels.dimensions();
    out.reset(w, h, false);
    let (w, h) = (w as usize, h as usize);
    let l = labels.as_slice();
    let o = out.as_mut_slice();
    let full = |x: usize, y: usize| boundary_at(labels, &is_region, separators, x as i64, y as i64);
    for y in 0..h {
        let orow = &mut o[y * w..(y + 1) * w];
        if y == 0 || y + 1 == h || w < 3 {
            for (x, e) in orow.iter_mut().enumerate() {
                *e = full(x, y);
            }
            continue;
        }
        let (up, row, down) = (&l[(y - 1) * w..y * w], &l[y * w..(y + 1) * w], &l[(y + 1) * w..(y + 2) * w]);
        orow[0] = full(0, y);
        orow[w - 1] = full(w - 1, y);
        let mut test = |x: usize| {
            let c = row[x];
            let nb = [row[x - 1], row[x + 1], up[x], down[x]];
            if nb.iter().any(|&m| m != c) {
                orow[x] = interior_rule(c, nb, &is_region, separators);
            }
        };
        // Chunks of pixels whose four neighbours all carry their label are skipped by one test without branches.
        const CHUNK: usize = 16;
        let mut x = 1;
        while x + CHUNK < w {
            let cols = x..x + CHUNK;
            let diff = row[cols.clone()]
                .iter()
                .zip(&row[x - 1..x - 1 + CHUNK])
                .zip(&row[x + 1..x + 1 + CHUNK])
                .zip(up[cols.clone()].iter().zip(&down[cols]))
                .fold(0u32, |a, (((&c, &l), &r), (&u, &d))| a | (c ^ l) | (c ^ r) | (c ^ u) | (c ^ d));
            if diff != 0 {
                for xx in x..x + CHUNK {
                    test(xx);
                }
            }
            x += CHUNK;
        }
        for xx in x..w - 1 {
            test(xx);
        }
    }
}

/// [`boundary_at`] at a pixel with all four neighbours in the image: its label `c` and theirs, `nb`.
#[inline(always)]
fn interior_rule(c: u32, nb: [u32; 4], is_region: impl Fn(u32) -> bool, separators: bool) -> bool {
    if is_region(c) {
        nb.iter().any(|&m| is_region(m) && m != c)
    } else if separators {
        let mut it = nb.iter().filter(|&&m| is_region(m));
        it.next().is_some_and(|&first| it.any(|&m| m != first))
    } else {
        false
    }
}

/// The rule of [`boundaries_into`] at pixel `(x, y)`.
#[inline]
fn boundary_at(
    labels: &LabelImage,
    is_region: impl Fn(u32) -> bool,
    separators: bool,
    x: i64,
    y: i64,
) -> bool {
    let at = |x: i64, y: i64| labels.get_signed(x, y).copied().filter(|&l| is_region(l));
    let nb = [at(x - 1, y), at(x + 1, y), at(x, y - 1), at(x, y + 1)];
    match at(x, y) {
        Some(l) => nb.iter().any(|n| n.is_some_and(|m| m != l)),
        None if separators => {
            let mut it = nb.iter().flatten();
            it.next().is_some_and(|&first| it.any(|&m| m != first))
        }
        None => false,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Grid;

    #[test]
    fn borders_are_two_sided_and_separators_join_only_label_boundaries() {
        let labels = Grid::from_rows(vec![vec![10, 10, 11, 11, 0, 12], vec![10, 10, 11, 11, 0, 12]]).unwrap();
        let b = region_borders(&labels, |l| l != 0);
        assert_eq!(b.rows().next().unwrap().to_vec(), vec![false, true, true, false, false, false]);
        // The unlabelled column separates 11 and 12: a segmentation boundary, not a region border.
        let s = label_boundaries(&labels, |l| l != 0);
        assert_eq!(s.rows().next().unwrap().to_vec(), vec![false, true, true, false, true, false]);
        // Which labels are regions is the caller's: with 11 not a region, nothing borders 10.
        let b = region_borders(&labels, |l| l == 10 || l == 12);
        assert!(b.as_slice().iter().all(|&e| !e));
    }
    #[test]
    fn interior_shortcut_matches_the_rule_at_every_pixel() {
        // A fixed pseudo-random sequence (an LCG): label images of few labels with runs, every size from 1×1.
        let mut s = 0x9e37_79b9_7f4a_7c15u64;
        let mut next = move |n: u32| {
            s = s.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            ((s >> 33) % u64::from(n)) as u32
        };
        for k in 0..300 {
            // Wider images from case 150 on, so that chunks are skipped and tested too.
            let (w, h) = (1 + next(if k < 150 { 12 } else { 60 }), 1 + next(12));
            let mut v = Vec::new();
            for i in 0..w * h {
                // Mostly repeats of the previous label, so interior pixels of one label are common; from case 150
                // on, blocks 13 × 5 with scattered other labels.
                let l = if k >= 150 {
                    if next(30) == 0 { next(4) } else { (i % w / 13 + i / w / 5) % 3 }
                } else if !v.is_empty() && next(4) > 0 {
                    *v.last().unwrap()
                } else {
                    next(4)
                };
                v.push(l);
            }
            let labels = Grid::from_vec(w, h, v).unwrap();
            for separators in [false, true] {
                for (j, region) in
                    [|l: u32| l != 0, |l: u32| l == 1 || l == 3, |_| true].into_iter().enumerate()
                {
                    let mut got = EdgeMap::default();
                    boundaries_into(&labels, region, separators, &mut got);
                    let want = Grid::from_fn(w, h, |x, y| {
                        boundary_at(&labels, region, separators, i64::from(x), i64::from(y))
                    });
                    assert_eq!(got, want, "case {k} ({w}×{h}), separators {separators}, region rule {j}");
                }
            }
        }
    }

    #[test]
    fn gaps_are_split_between_the_nearest_regions_up_to_the_limit() {
        let row = |r: &[u32]| r.to_vec();
        // Two regions 4 px apart, a 1-px gap on the right, and an invalid pixel that blocks the way.
        let labels =
            Grid::from_rows(vec![row(&[1, 0, 0, 0, 0, 2, 0, 3]), row(&[1, 0, 0, 0, 0, 2, 0, 3])]).unwrap();
        let mut valid = Grid::new(8, 2, true);
        valid[(3, 1)] = false;
        let (mut out, mut gaps) = (LabelImage::default(), Vec::new());
        split_gaps_into(&labels, &valid, 2, &mut out, &mut gaps);
        assert_eq!(out.rows().next().unwrap().to_vec(), vec![1, 1, 1, 2, 2, 2, 2, 3]);
        // `gaps` ends with the pixels given a label: the 5 of row 0's gaps and the 4 valid ones of row 1's.
        gaps.sort_unstable();
        assert_eq!(gaps, vec![1, 2, 3, 4, 6, 9, 10, 12, 14]);
        // Row 1: the invalid pixel stays unlabelled and the one beyond it is reached from 2 only.
        assert_eq!(out.rows().nth(1).unwrap().to_vec(), vec![1, 1, 1, 0, 2, 2, 2, 3]);
        // The border now runs through the gap: 1 | 2 between x = 2 and 3 on row 0.
        let edges = label_boundaries(&out, |l| l != 0);
        assert_eq!(
            edges.rows().next().unwrap().to_vec(),
            vec![false, false, true, true, false, false, true, true]
        );
        // One step reaches only the pixels next to a region; 0 steps change nothing.
        split_gaps_into(&labels, &valid, 1, &mut out, &mut gaps);
        assert_eq!(out.rows().next().unwrap().to_vec(), vec![1, 1, 0, 0, 2, 2, 2, 3]);
        split_gaps_into(&labels, &valid, 0, &mut out, &mut gaps);
        assert_eq!(out, labels);
    }
}
