//! Region boundaries of a label image, the one rule the final edge map and the evaluation share.

use crate::{EdgeMap, LabelImage};

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
}
