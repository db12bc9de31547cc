//! Jin et al. (2017)'s one-sided plane detection rule, as their evaluation code computes it.
//!
//! Source: `calculateROC.m` of the public DPD-Project repository by Jin et al. (the code behind
//! their 2017 depth-image plane detection paper, whose NYU figures are per-plane "correct
//! detection rates" under this rule). A GT plane counts as detected when one machine region covers
//! at least a fraction `threshold` (0.8 in their scripts) of it; nothing is asked of the machine
//! region's own size, so unlike [`crate::hoover`] an under-segmentation can still "detect" its
//! largest GT plane. The rule, step by step:
//!
//! - GT planes are visited one by one (their script lists them by hand; we take the GT regions,
//!   labels ≥ 10, by increasing label). Machine pixels that are not regions (label 0 in their
//!   images; here the non-region labels of the [`Convention`]) are holes and never count.
//! - For plane `n` (area `|n|`, all its pixels), the machine regions inside it are ranked by how
//!   many of its pixels they hold, most first (ties: lower label first, as MATLAB's stable sort
//!   after `unique`).
//! - If the first has not been *claimed* by an earlier plane, it is claimed; `n` is detected when
//!   its overlap is `≥ threshold · |n|`.
//! - Otherwise, only if **more than two** machine regions lie in `n` (`length(...) > 2` in the
//!   code: with exactly two, the second is never tried), the second is tried, then the third:
//!   it is taken if its overlap with `n` is `> 10` px and more than half of its pixels still in
//!   the machine map; `n` is detected when that overlap is `≥ threshold · |n|`. The second or
//!   third region is not claimed (a quirk of the code, kept).
//! - Whenever a region was taken for `n`, the machine pixels of `n` are removed from the machine
//!   map, which shrinks "its pixels still in the machine map" for later planes.
//! - `rate` = detected ÷ GT planes (0 when there is none).
//!
//! Differences, all where the MATLAB code has no defined behaviour for our data: a plane with no
//! machine region in it is simply not detected (the code would fail on an empty index); their
//! GT images mark edges with 255, whose machine pixels the code also removes, while in ours
//! unlabelled GT is 0..=9 and 255 is an ordinary region label, so nothing else is removed.

use crate::hoover::Convention;
use rangeimage::LabelImage;
use std::collections::HashMap;

/// The coverage threshold of Jin et al.'s scripts (`check_threshold = 0.8`).
pub const THRESHOLD: f64 = 0.8;

/// Jin et al.'s one-sided detection counts of one segmentation.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct JinScore {
    /// Fraction of a GT plane one machine region must cover.
    pub threshold: f64,
    /// GT planes (regions, labels ≥ 10).
    pub gt_regions: u32,
    /// GT planes detected under the rule.
    pub detected: u32,
    /// `detected / gt_regions`, 0 without GT planes.
    pub rate: f64,
}

/// Scores `seg` against `gt` under Jin et al.'s rule (see the module documentation).
///
/// # Panics
/// If the images differ in size or `threshold` is not in `(0, 1]`.
pub fn score(gt: &LabelImage, seg: &LabelImage, seg_convention: Convention, threshold: f64) -> JinScore {
    let _s = tracing::info_span!("eval::jin").entered();
    assert!(
        gt.same_size(seg),
        "GT {:?} and segmentation {:?} must have the same size",
        gt.dimensions(),
        seg.dimensions()
    );
    assert!(threshold > 0.0 && threshold <= 1.0, "threshold must be in (0, 1], got {threshold}");
    let conv = seg_convention.resolve(seg);
    let (g, s) = (gt.as_slice(), seg.as_slice());
    // Pixels of every GT plane, by increasing label; pixels still in the machine map per label.
    let mut planes: HashMap<u32, Vec<usize>> = HashMap::new();
    let mut remaining: HashMap<u32, u64> = HashMap::new();
    for (i, (&gl, &sl)) in g.iter().zip(s).enumerate() {
        if gl >= crate::boundary::FIRST_REGION_LABEL {
            planes.entry(gl).or_default().push(i);
        }
        if conv.is_region(sl) {
            *remaining.entry(sl).or_default() += 1;
        }
    }
    let mut labels: Vec<u32> = planes.keys().copied().collect();
    labels.sort_unstable();
    let mut claimed: Vec<u32> = Vec::new();
    let mut detected = 0u32;
    for label in &labels {
        let pixels = &planes[label];
        let area = pixels.len() as f64;
        let mut inside: HashMap<u32, u64> = HashMap::new();
        for &i in pixels {
            if conv.is_region(s[i]) {
                *inside.entry(s[i]).or_default() += 1;
            }
        }
        let mut ranked: Vec<(u32, u64)> = inside.into_iter().collect();
        // Most pixels first; ties by increasing label (MATLAB: `unique`, then a stable sort).
        ranked.sort_unstable_by(|a, b| b.1.cmp(&a.1).then(a.0.cmp(&b.0)));
        let Some(&(first, first_overlap)) = ranked.first() else { continue };
        let taken = if !claimed.contains(&first) {
            claimed.push(first);
            Some(first_overlap)
        } else if ranked.len() > 2 {
            let mostly_here = |(l, o): (u32, u64)| o > 10 && o as f64 / remaining[&l] as f64 > 0.5;
            [ranked[1], ranked[2]].into_iter().find(|&r| mostly_here(r)).map(|r| r.1)
        } else {
            None
        };
        let Some(overlap) = taken else { continue };
        if overlap as f64 >= threshold * area {
            detected += 1;
        }
        for &i in pixels {
            if conv.is_region(s[i]) {
                *remaining.get_mut(&s[i]).expect("counted above") -= 1;
            }
        }
    }
    let gt_regions = labels.len() as u32;
    let rate = if gt_regions == 0 { 0.0 } else { f64::from(detected) / f64::from(gt_regions) };
    let score = JinScore { threshold, gt_regions, detected, rate };
    tracing::debug!(?score, "jin score");
    score
}

#[cfg(test)]
mod tests {
    use super::*;
    use rangeimage::Grid;

    /// One row: `(label, run length)` pairs laid end to end.
    fn runs(r: &[(u32, usize)]) -> LabelImage {
        let row: Vec<u32> = r.iter().flat_map(|&(l, n)| std::iter::repeat_n(l, n)).collect();
        Grid::from_rows(vec![row]).unwrap()
    }

    fn detected(gt: &LabelImage, seg: &LabelImage) -> u32 {
        score(gt, seg, Convention::Auto, THRESHOLD).detected
    }

    #[test]
    fn coverage_threshold_is_inclusive_and_one_sided() {
        // GT 10 (100 px): MS 20 covers 80 → detected; 79 → not.
        let gt = runs(&[(10, 100)]);
        assert_eq!(detected(&gt, &runs(&[(20, 80), (21, 20)])), 1);
        assert_eq!(detected(&gt, &runs(&[(20, 79), (21, 21)])), 0);
        // One-sided: MS 20 also spills over all of GT 11 and unlabelled GT; 10 is still detected
        // (Hoover would call it an under-segmentation, or nothing).
        let gt = runs(&[(10, 100), (11, 30), (0, 50)]);
        let s = score(&gt, &runs(&[(20, 180)]), Convention::Auto, THRESHOLD);
        assert_eq!((s.gt_regions, s.detected), (2, 1));
        assert_eq!(s.rate, 0.5);
        // Holes (MS labels 0..=9 here) never count, but the plane's area includes them.
        assert_eq!(detected(&runs(&[(10, 10)]), &runs(&[(20, 7), (0, 3)])), 0);
        assert_eq!(detected(&runs(&[(10, 10)]), &runs(&[(20, 8), (0, 2)])), 1);
    }

    #[test]
    fn a_claimed_region_makes_the_next_plane_try_its_second_and_third() {
        // GT 10 (50 px) and GT 11 (100 px). MS 20 covers all of 10 and 60 px of 11 (claimed by
        // 10, so 11 cannot use it). In 11: 20 (60), 21 (25), 22 (15).
        let gt = runs(&[(10, 50), (11, 100)]);
        let seg = runs(&[(20, 110), (21, 25), (22, 15)]);
        // 21: 25 > 10 px and 25/25 of it left → taken, 25 < 80: 11 not detected.
        let s = score(&gt, &seg, Convention::Auto, THRESHOLD);
        assert_eq!((s.detected, s.gt_regions), (1, 2));
        // With a lower threshold 0.25, 21's 25 px detect 11.
        assert_eq!(score(&gt, &seg, Convention::Auto, 0.25).detected, 2);
        // Exactly two regions in 11 (20 and 21): the code never tries the second one.
        let seg = runs(&[(20, 110), (21, 40)]);
        assert_eq!(score(&gt, &seg, Convention::Auto, 0.25).detected, 1);
    }

    #[test]
    fn second_must_be_mostly_inside_else_third() {
        // GT 10 (50 px), GT 11 (100 px), GT 12 (40 px). MS 20 = all of 10 + 60 px of 11;
        // MS 21 = 25 px of 11 + 40 px of 12 (only 25/65 of it in 11: not taken);
        // MS 22 = 15 px of 11 (> 10 px, all of it) → taken as the third.
        let gt = runs(&[(10, 50), (11, 100), (12, 40)]);
        let seg = runs(&[(20, 110), (22, 15), (21, 65)]);
        let s = score(&gt, &seg, Convention::Auto, 0.15);
        // 10: 20 claimed, 50/50 → detected. 11: 22's 15 px ≥ 0.15·100 → detected.
        // 12: its only region, 21, is unclaimed → claimed, 40/40 → detected.
        assert_eq!((s.detected, s.gt_regions), (3, 3));
        // A third region of 10 px or fewer is not taken.
        let seg = runs(&[(20, 110), (22, 10), (23, 5), (21, 65)]);
        let gt = runs(&[(10, 50), (11, 100), (12, 40)]);
        assert_eq!(score(&gt, &seg, Convention::Auto, 0.05).detected, 2);
    }

    #[test]
    fn a_second_region_taken_is_not_claimed() {
        // GT 10 (40), 11 (40), 12 (12). MS 20 = all of 10 + 20 px of 11; MS 21 = 15 px of 11 +
        // 11 px of 12; MS 22 = 5 px of 11; MS 24 = 1 px of 12.
        let gt = runs(&[(10, 40), (11, 40), (12, 12)]);
        let seg = runs(&[(20, 60), (21, 15), (22, 5), (21, 11), (24, 1)]);
        // 10 claims 20 (40/40, detected). In 11, 20 is claimed: the second, 21 (15 px > 10, 15 of
        // its 26 px > half) is taken but not claimed; 15 < 0.8·40. In 12, 21 comes first and is
        // still free: claimed, 11 ≥ 0.8·12 → detected. Had 11 claimed it, 12 (two regions) would
        // have had nothing left to try.
        assert_eq!(detected(&gt, &seg), 2);
        assert_eq!(score(&gt, &seg, Convention::Auto, 0.25).detected, 3);
    }

    #[test]
    fn removing_a_planes_pixels_shrinks_what_is_left_of_a_region() {
        // GT 10 (40), 11 (40). MS 20 = 20 px of 10 + 20 px of 11; MS 21 = 20 px of 10 + 15 px of
        // 11; MS 22 = 5 px of 11. In 10, 20 and 21 tie at 20 px: the lower label, 20, is claimed
        // (20 ≥ 0.3·40: detected) and 10's pixels leave the map. In 11, 20 is claimed; the second,
        // 21, has 15 of its 15 remaining px there (15/35 before the removal) → taken, detected.
        let gt = runs(&[(10, 40), (11, 40)]);
        let seg = runs(&[(20, 20), (21, 20), (20, 20), (21, 15), (22, 5)]);
        assert_eq!(score(&gt, &seg, Convention::Auto, 0.3).detected, 2);
    }

    #[test]
    fn no_plane_no_rate() {
        let s = score(&runs(&[(0, 5)]), &runs(&[(20, 5)]), Convention::Auto, THRESHOLD);
        assert_eq!((s.gt_regions, s.detected, s.rate), (0, 0, 0.0));
        // A plane entirely under holes is not detected.
        let s = score(&runs(&[(10, 5)]), &runs(&[(0, 5)]), Convention::Auto, THRESHOLD);
        assert_eq!((s.gt_regions, s.detected), (1, 0));
    }
}
