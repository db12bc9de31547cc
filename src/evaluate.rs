//! Scoring one image of a benchmark: the numbers behind Tables I and II and the Hoover table.

use crate::pipeline::Output;
use eval::boundary::Prf;
use eval::hoover::HooverScore;
use eval::jin::JinScore;
use rangeimage::{EdgeMap, LabelImage, Region};
use serde::Serialize;

pub use eval::hoover::CURVE_TS;
pub use eval::{HOOVER_T, TOLERANCE_PX};

/// The label convention of the segmentations this module scores: the pipeline numbers its regions from 1 and
/// leaves 0 unlabelled (`Convention::Auto` would read a segmentation of at most three regions, labels 1–3, as
/// ABW's unlabelled levels and score every region of it missed).
pub const SEGMENTATION: eval::Convention = eval::Convention::NonZero;

/// Scores of one edge map.
#[derive(Debug, Clone, Serialize)]
pub struct EdgeScores {
    /// Edge pixels detected.
    pub n_edges: usize,
    /// Paper precision (Eq. 7) against the initial region borders C1.
    pub paper_precision_c1: Option<f64>,
    /// Paper precision against the ground-truth boundaries.
    pub paper_precision_gt: Option<f64>,
    /// Boundary P/R/F against ground truth, one-to-one matching.
    pub matched: Prf,
    /// Boundary P/R/F against ground truth, simple distance rule.
    pub simple: Prf,
}

/// Every number the evaluation reports for one image.
#[derive(Debug, Clone, Serialize)]
pub struct ImageScores {
    /// Table I: Canny on raw depth.
    pub raw_canny: EdgeScores,
    /// Table I and II: Canny on plane parameters, C2 before relaxation.
    pub c2: EdgeScores,
    /// Region borders C1 before relaxation.
    pub c1: EdgeScores,
    /// Table II: the final edge map after relaxation.
    pub relaxed: EdgeScores,
    /// Hoover at T = 0.8 for region growing alone.
    pub hoover_regiongrow: HooverScore,
    /// Hoover at T = 0.8 for the final segmentation.
    pub hoover_final: HooverScore,
    /// Jin et al.'s one-sided detection rule (≥ 80 % of a GT plane in one region), region growing alone.
    pub jin_regiongrow: JinScore,
    /// Jin et al.'s one-sided detection rule for the final segmentation.
    pub jin_final: JinScore,
    /// Correct detections of the final segmentation over [`CURVE_TS`].
    pub curve_correct: Vec<u32>,
    /// Correct detections of region growing alone over [`CURVE_TS`].
    pub curve_correct_regiongrow: Vec<u32>,
}

/// Scores an edge map against C1 and the ground truth.
pub fn score_edges(edges: &EdgeMap, c1: &EdgeMap, gt: &LabelImage) -> EdgeScores {
    let gt_edges = eval::boundary::gt_boundaries(gt);
    EdgeScores {
        n_edges: edges.as_slice().iter().filter(|&&b| b).count(),
        paper_precision_c1: eval::paper_precision(edges, c1, TOLERANCE_PX),
        paper_precision_gt: eval::paper_precision(edges, &gt_edges, TOLERANCE_PX),
        matched: eval::boundary::matched(edges, gt, TOLERANCE_PX),
        simple: eval::boundary::simple(edges, gt, TOLERANCE_PX),
    }
}

/// Region normals as `(label, normal)` pairs for the Hoover angle error.
pub fn normals_of(regions: &[Region]) -> Vec<(u32, [f32; 3])> {
    regions.iter().map(|r| (r.label, r.normal)).collect()
}

/// Scores the pipeline's output for one image against its ground truth.
pub fn score_image(
    out: &Output,
    raw_canny: &EdgeMap,
    gt: &LabelImage,
    gt_angles: &[(u32, u32, f64)],
) -> ImageScores {
    let _s = tracing::info_span!("score_image").entered();
    let c1 = &out.regions.c1;
    let correct = |labels| {
        eval::hoover::curve_with(gt, labels, &CURVE_TS, SEGMENTATION).iter().map(|s| s.correct).collect()
    };
    ImageScores {
        raw_canny: score_edges(raw_canny, c1, gt),
        c2: score_edges(&out.canny.edges, c1, gt),
        c1: score_edges(c1, c1, gt),
        relaxed: score_edges(out.fin.edges(), c1, gt),
        hoover_regiongrow: hoover(gt, &out.regions.labels, &out.regions.regions, gt_angles),
        hoover_final: hoover(gt, &out.fin.labels, &out.fin.final_regions, gt_angles),
        jin_regiongrow: jin(gt, &out.regions.labels),
        jin_final: jin(gt, &out.fin.labels),
        curve_correct: correct(&out.fin.labels),
        curve_correct_regiongrow: correct(&out.regions.labels),
    }
}

/// Hoover metrics at T = 0.8 of a segmentation (labels from 1, [`SEGMENTATION`]) with its region normals.
pub fn hoover(
    gt: &LabelImage,
    labels: &LabelImage,
    regions: &[Region],
    gt_angles: &[(u32, u32, f64)],
) -> HooverScore {
    eval::hoover::compare_with(
        gt,
        labels,
        HOOVER_T,
        Some(gt_angles),
        Some(&normals_of(regions)),
        SEGMENTATION,
    )
}

/// Jin et al.'s one-sided detection counts of a segmentation (labels from 1) at their threshold (0.8).
pub fn jin(gt: &LabelImage, labels: &LabelImage) -> JinScore {
    eval::jin::score(gt, labels, SEGMENTATION, eval::jin::THRESHOLD)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rangeimage::Grid;

    /// Two GT regions (10, 11: left and right halves) and a segmentation of `n` vertical bands numbered from 1.
    fn halves_and_bands(n: u32) -> (LabelImage, LabelImage) {
        let gt = Grid::from_fn(40, 20, |x, _| if x < 20 { 10 } else { 11 });
        let seg = Grid::from_fn(40, 20, |x, _| 1 + x * n / 40);
        (gt, seg)
    }

    #[test]
    fn segmentations_of_three_regions_or_fewer_are_scored_as_numbered_from_1() {
        // Labels 1–3 alone once read as ABW's unlabelled levels: a perfect segmentation scored nothing.
        let (gt, seg) = halves_and_bands(2);
        let h = hoover(&gt, &seg, &[], &[]);
        assert_eq!((h.correct, h.missed, h.noise), (2, 0, 0), "{h:?}");
        assert_eq!(jin(&gt, &seg).detected, 2);
        let curve = eval::hoover::curve_with(&gt, &seg, &CURVE_TS, SEGMENTATION);
        assert!(curve.iter().all(|s| s.correct == 2), "{curve:?}");
        // Four bands: each half split in two, scored the same with or without labels in 4..=9.
        let (gt, seg) = halves_and_bands(4);
        assert_eq!(hoover(&gt, &seg, &[], &[]).over, 2);
        assert_eq!(
            hoover(&gt, &seg, &[], &[]),
            eval::hoover::compare(&gt, &seg, HOOVER_T, Some(&[]), Some(&[]))
        );
    }
}
