//! Edge and region metrics: paper precision, boundary P/R/F, Hoover et al. region metrics.
//!
//! Everything here is pure computation on in-memory images (no I/O). The metrics (docs/method.md §3.5):
//! - [`paper_precision`]: the paper's Eq. 7, detected edge pixels within τ of a reference set.
//! - [`boundary`]: boundary precision/recall/F against ground-truth region boundaries, simple
//!   distance and one-to-one (BSDS-style) matching of the thinned maps ([`thin`]), with a
//!   don't-care zone around unlabelled GT.
//! - [`hoover`]: Hoover et al. (1996) correct / over / under / missed / noise counts at a
//!   tolerance T, the curve over T, and the normal-angle error of correctly detected pairs.
//! - [`jin`]: Jin et al. (2017)'s one-sided plane detection rule (one machine region covering
//!   ≥ 80 % of a GT plane), as their evaluation code computes it.
//! - [`score`]: everything the given inputs allow, as one serialisable [`Scores`].
//!
//! Label conventions: GT images follow ABW (regions ≥ 10, 0..=9 unlabelled); machine
//! segmentations follow a [`hoover::Convention`] (auto-detected by default).

pub mod boundary;
pub mod distance;
pub mod hoover;
pub mod jin;
#[cfg(test)]
mod testing;
pub mod thin;

pub use boundary::Prf;
pub use hoover::{Convention, HooverScore};
pub use jin::JinScore;

use rangeimage::ParamError;
use rangeimage::{EdgeMap, LabelImage};

/// The edge tolerance τ of the boundary and paper-precision metrics, in pixels (docs/method.md §3.5).
pub const TOLERANCE_PX: f64 = 2.0;
/// The Hoover tolerance T of the main table (docs/method.md §3.5).
pub const HOOVER_T: f64 = 0.8;

/// The paper's precision (Eq. 7): detected edge pixels within `tolerance_px` of a `reference`
/// edge pixel ÷ detected edge pixels.
///
/// "Within" is Euclidean distance between pixel centres ≤ `tolerance_px` (inclusive), computed
/// exactly with [`distance::edt_squared`]. No don't-care zone. `None` if nothing is detected;
/// `Some(0.0)` if something is detected and `reference` is empty.
///
/// # Panics
/// If the sizes differ or `tolerance_px` is negative or not finite.
#[must_use]
pub fn paper_precision(detected: &EdgeMap, reference: &EdgeMap, tolerance_px: f64) -> Option<f64> {
    let _s = tracing::info_span!("eval::paper_precision").entered();
    assert!(
        detected.same_size(reference),
        "detected {:?} and reference {:?} must have the same size",
        detected.dimensions(),
        reference.dimensions()
    );
    let r2 = distance::radius_squared(tolerance_px);
    let dist = distance::edt_squared(reference);
    let mut n = 0u64;
    let mut hit = 0u64;
    for (&d, &d2) in detected.as_slice().iter().zip(dist.as_slice()) {
        if d {
            n += 1;
            hit += u64::from(d2 <= r2);
        }
    }
    tracing::debug!(n, hit, "paper precision");
    (n > 0).then(|| hit as f64 / n as f64)
}

/// The `[eval]` table: tolerances and conventions of [`score`].
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Params {
    /// Edge matching tolerance τ in pixels (boundary P/R/F and paper precision). Default 2.
    pub tolerance_px: f64,
    /// Hoover tolerance T, in (0.5, 1]. Default 0.8.
    pub hoover_t: f64,
    /// Which labels of the machine segmentation are regions. Default auto.
    pub seg_convention: Convention,
    /// Also compute the Hoover curve over [`hoover::CURVE_TS`]. Default false.
    pub hoover_curve: bool,
}

impl Default for Params {
    fn default() -> Self {
        Self {
            tolerance_px: TOLERANCE_PX,
            hoover_t: HOOVER_T,
            seg_convention: Convention::Auto,
            hoover_curve: false,
        }
    }
}

impl Params {
    /// Checks the values; the message names the bad field.
    pub fn validate(&self) -> Result<(), ParamError> {
        if !(self.tolerance_px.is_finite() && self.tolerance_px >= 0.0) {
            return Err(ParamError::new(
                "eval.tolerance_px",
                format!("must be finite and ≥ 0, got {}", self.tolerance_px),
            ));
        }
        if !(self.hoover_t > 0.5 && self.hoover_t <= 1.0) {
            return Err(ParamError::new(
                "eval.hoover_t",
                format!("must be in (0.5, 1], got {}", self.hoover_t),
            ));
        }
        Ok(())
    }
}

/// What [`score`] has to work with; every field but `gt` is optional.
#[derive(Debug, Clone, Copy)]
pub struct Inputs<'a> {
    /// Ground-truth labels (ABW convention).
    pub gt: &'a LabelImage,
    /// Machine segmentation.
    pub seg: Option<&'a LabelImage>,
    /// Detected edge map.
    pub edges: Option<&'a EdgeMap>,
    /// Reference edge set for the paper's precision (e.g. C1, or GT boundaries).
    pub reference: Option<&'a EdgeMap>,
    /// Angles between adjacent GT regions `(a, b, degrees)` (`.gt-ang`).
    pub gt_angles: Option<&'a [(u32, u32, f64)]>,
    /// Normals of the segmentation's regions (`.ms-nor`).
    pub seg_normals: Option<&'a [(u32, [f32; 3])]>,
}

impl<'a> Inputs<'a> {
    /// Inputs with only the ground truth set.
    pub fn new(gt: &'a LabelImage) -> Self {
        Self { gt, seg: None, edges: None, reference: None, gt_angles: None, seg_normals: None }
    }
}

/// Which edge set the boundary scores measure.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum BoundarySource {
    /// The edge map given as input.
    Edges,
    /// The segmentation's own region boundaries ([`rangeimage::boundary::label_boundaries`]).
    Segmentation,
}

/// Boundary P/R/F of one edge set at one tolerance.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct BoundaryScores {
    /// Matching tolerance τ in pixels.
    pub tolerance_px: f64,
    /// Where the detected boundary pixels come from.
    pub boundary_source: BoundarySource,
    /// One-to-one matching ([`boundary::matched`]).
    pub matched: Prf,
    /// Simple distance ([`boundary::simple`]).
    pub simple: Prf,
}

/// Every metric the inputs allow; `None` (JSON `null`) for the others.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Scores {
    /// Hoover scores at `Params::hoover_t` (needs a segmentation).
    pub hoover: Option<HooverScore>,
    /// Hoover scores over [`hoover::CURVE_TS`] (needs a segmentation and `Params::hoover_curve`).
    pub hoover_curve: Option<Vec<HooverScore>>,
    /// Jin et al.'s one-sided detection rule at [`jin::THRESHOLD`] (needs a segmentation).
    pub jin: Option<JinScore>,
    /// Boundary P/R/F (needs an edge map or a segmentation).
    pub boundary: Option<BoundaryScores>,
    /// The paper's precision (needs an edge map and a reference; `None` if nothing is detected).
    pub paper_precision: Option<f64>,
}

/// Computes every metric the inputs allow.
///
/// Boundary scores use `inputs.edges` if given, else the boundaries of `inputs.seg` under
/// `params.seg_convention`. The angle error needs both `gt_angles` and `seg_normals`.
///
/// # Panics
/// If the images differ in size; in debug builds also if `params` is invalid ([`Params::validate`]:
/// callers validate once, at the edge).
#[must_use]
pub fn score(inputs: &Inputs<'_>, params: &Params) -> Scores {
    let _s = tracing::info_span!("eval").entered();
    debug_assert_eq!(params.validate(), Ok(()), "invalid eval parameters");
    let gt = inputs.gt;
    let (hoover, hoover_curve) = match inputs.seg {
        Some(seg) => {
            let overlap = hoover::Overlap::new(gt, seg, params.seg_convention);
            let main = overlap.score(params.hoover_t, inputs.gt_angles, inputs.seg_normals);
            let curve = params.hoover_curve.then(|| {
                hoover::CURVE_TS
                    .iter()
                    .map(|&t| overlap.score(t, inputs.gt_angles, inputs.seg_normals))
                    .collect()
            });
            (Some(main), curve)
        }
        None => (None, None),
    };
    let jin = inputs.seg.map(|seg| jin::score(gt, seg, params.seg_convention, jin::THRESHOLD));
    let detected = match (inputs.edges, inputs.seg) {
        (Some(e), _) => Some((e.clone(), BoundarySource::Edges)),
        (None, Some(seg)) => {
            let conv = params.seg_convention.resolve(seg);
            Some((
                rangeimage::boundary::label_boundaries(seg, |l| conv.is_region(l)),
                BoundarySource::Segmentation,
            ))
        }
        (None, None) => None,
    };
    let boundary = detected.map(|(det, source)| {
        let gt_b = boundary::gt_boundaries(gt);
        let dc = boundary::dont_care(gt, params.tolerance_px);
        BoundaryScores {
            tolerance_px: params.tolerance_px,
            boundary_source: source,
            matched: boundary::matched_masked(&det, &gt_b, &dc, params.tolerance_px),
            simple: boundary::simple_masked(&det, &gt_b, &dc, params.tolerance_px),
        }
    });
    let paper_precision = match (inputs.edges, inputs.reference) {
        (Some(e), Some(r)) => paper_precision(e, r, params.tolerance_px),
        _ => None,
    };
    Scores { hoover, hoover_curve, jin, boundary, paper_precision }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;
    use rangeimage::Grid;

    #[test]
    fn paper_precision_by_hand() {
        let reference = Grid::from_fn(10, 6, |x, _| x == 3);
        let detected = Grid::from_fn(10, 6, |x, y| (x == 5 && y < 3) || (x == 6 && y >= 3));
        // Column 5 is 2 px from the reference, column 6 is 3 px away.
        assert_relative_eq!(paper_precision(&detected, &reference, 2.0).unwrap(), 0.5);
        assert_relative_eq!(paper_precision(&detected, &reference, 3.0).unwrap(), 1.0);
        assert_relative_eq!(paper_precision(&detected, &reference, 1.0).unwrap(), 0.0);
        assert_eq!(paper_precision(&Grid::new(10, 6, false), &reference, 2.0), None);
        assert_eq!(paper_precision(&detected, &Grid::new(10, 6, false), 2.0), Some(0.0));
    }

    #[test]
    fn params_validate() {
        assert!(Params::default().validate().is_ok());
        assert!(Params { hoover_t: 0.5, ..Params::default() }.validate().is_err());
        assert!(Params { tolerance_px: -1.0, ..Params::default() }.validate().is_err());
        let p: Params = serde_json::from_str(r#"{"hoover_t": 0.9, "seg_convention": "nonzero"}"#).unwrap();
        assert_eq!((p.hoover_t, p.seg_convention, p.tolerance_px), (0.9, Convention::NonZero, 2.0));
        assert!(serde_json::from_str::<Params>(r#"{"hover_t": 0.9}"#).is_err());
    }

    #[test]
    fn score_fills_what_inputs_allow() {
        let gt: LabelImage = Grid::from_fn(16, 8, |x, _| if x < 8 { 10 } else { 11 });
        let only_gt = score(&Inputs::new(&gt), &Params::default());
        assert_eq!(
            (only_gt.hoover.is_none(), only_gt.boundary.is_none(), only_gt.paper_precision),
            (true, true, None)
        );
        let s = score(
            &Inputs { seg: Some(&gt), ..Inputs::new(&gt) },
            &Params { hoover_curve: true, ..Params::default() },
        );
        let h = s.hoover.as_ref().unwrap();
        assert_eq!((h.correct, h.gt_regions), (2, 2));
        assert_eq!(s.jin.as_ref().map(|j| (j.detected, j.gt_regions)), Some((2, 2)));
        assert_eq!(s.hoover_curve.as_ref().unwrap().len(), hoover::CURVE_TS.len());
        let b = s.boundary.as_ref().unwrap();
        assert_eq!(b.boundary_source, BoundarySource::Segmentation);
        assert_eq!((b.matched.f, b.simple.f), (1.0, 1.0));
        let json = serde_json::to_value(&s).unwrap();
        assert_eq!(json["hoover"]["correct"], 2);
        assert_eq!(json["jin"]["rate"], 1.0);
        assert_eq!(json["boundary"]["boundary_source"], "segmentation");
        assert_eq!(json["boundary"]["matched"]["precision"], 1.0);
        assert!(json["paper_precision"].is_null());
        let edges = boundary::gt_boundaries(&gt);
        let s = score(
            &Inputs { edges: Some(&edges), reference: Some(&edges), ..Inputs::new(&gt) },
            &Params::default(),
        );
        assert_eq!(s.boundary.unwrap().boundary_source, BoundarySource::Edges);
        assert_eq!(s.paper_precision, Some(1.0));
        assert!(s.hoover.is_none());
    }

    mod proptests {
        use super::*;
        use crate::testing::{abw_labels, relabel};
        use proptest::prelude::*;

        proptest! {
            #[test]
            fn proptest_gt_against_itself_is_perfect(gt in abw_labels(2..24, 2..24, 6)) {
                let s = score(&Inputs { seg: Some(&gt), ..Inputs::new(&gt) }, &Params::default());
                let h = s.hoover.unwrap();
                prop_assert_eq!((h.correct, h.seg_regions, h.missed, h.noise), (h.gt_regions, h.gt_regions, 0, 0));
                let b = s.boundary.unwrap();
                // The segmentation's boundaries also hold its unlabelled separator pixels, which
                // can move the thinned line near unlabelled GT: matched is exact only without them.
                let no_unlabelled = gt.as_slice().iter().all(|&l| l >= 10);
                let given_edges = boundary::gt_boundaries(&gt);
                let e = score(&Inputs { edges: Some(&given_edges), ..Inputs::new(&gt) }, &Params::default());
                let e = e.boundary.unwrap();
                let mut exact = vec![b.simple, e.matched, e.simple];
                if no_unlabelled {
                    exact.push(b.matched);
                }
                for prf in exact {
                    prop_assert_eq!((prf.n_detected_matched, prf.n_gt_matched), (prf.n_detected, prf.n_gt));
                    if prf.n_gt > 0 {
                        prop_assert_eq!((prf.precision, prf.recall, prf.f), (1.0, 1.0, 1.0));
                    }
                }
            }

            #[test]
            fn proptest_relabelling_changes_no_score(
                gt in abw_labels(2..20, 2..20, 5),
                seg in abw_labels(2..20, 2..20, 5),
                seed in any::<u64>(),
            ) {
                // Crop both to a common size.
                let (w, h) = (gt.width().min(seg.width()), gt.height().min(seg.height()));
                let gt = Grid::from_fn(w, h, |x, y| gt[(x, y)]);
                let seg = Grid::from_fn(w, h, |x, y| seg[(x, y)]);
                let (seg2, _) = relabel(&seg, seed, |l| l >= 10, 10);
                let params = Params { hoover_curve: true, ..Params::default() };
                let a = score(&Inputs { seg: Some(&seg), ..Inputs::new(&gt) }, &params);
                let b = score(&Inputs { seg: Some(&seg2), ..Inputs::new(&gt) }, &params);
                // Except Jin et al.'s rule, which breaks ties between machine regions by label.
                prop_assert_eq!(Scores { jin: None, ..a }, Scores { jin: None, ..b });
            }
        }
    }
}
