//! `rangeseg score`: Hoover region metrics, boundary P/R/F and the paper's precision.

use anyhow::{Context, bail};
use std::path::{Path, PathBuf};
use std::process::ExitCode;

/// Which labels of the segmentation are regions (see `eval::hoover::Convention`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
enum SegConvention {
    /// ABW unless a label in 4..=9 appears, then every non-zero label.
    Auto,
    /// Labels ≥ 10 are regions (ABW).
    Abw,
    /// Every non-zero label is a region.
    Nonzero,
}

impl From<SegConvention> for eval::Convention {
    fn from(c: SegConvention) -> Self {
        match c {
            SegConvention::Auto => eval::Convention::Auto,
            SegConvention::Abw => eval::Convention::Abw,
            SegConvention::Nonzero => eval::Convention::NonZero,
        }
    }
}

/// Arguments of `rangeseg score`.
#[derive(Debug, clap::Args)]
pub(crate) struct Args {
    /// Ground-truth labels (ABW `.gt-seg` Sun rasterfile).
    #[arg(long, value_name = "GT.gt-seg")]
    gt: PathBuf,
    /// Machine segmentation (ABW `.ms-seg` Sun rasterfile).
    #[arg(long, value_name = "SEG.ms-seg")]
    seg: PathBuf,
    /// Edge map PNG to score (else the segmentation's own region boundaries are scored).
    #[arg(long, value_name = "EDGES.png")]
    edges: Option<PathBuf>,
    /// Angles between adjacent GT regions [default: GT.gt-ang beside the GT file, if present].
    #[arg(long, value_name = "FILE")]
    gt_ang: Option<PathBuf>,
    /// Normals of the segmentation's regions [default: SEG.ms-nor beside the segmentation, if present].
    #[arg(long, value_name = "FILE")]
    seg_nor: Option<PathBuf>,
    /// Reference edge PNG for the paper's precision (Eq. 7), e.g. C1; needs --edges.
    #[arg(long, value_name = "REF.png")]
    reference: Option<PathBuf>,
    /// Edge matching tolerance in pixels (Euclidean, inclusive), at most the image diagonal.
    #[arg(long, default_value_t = eval::TOLERANCE_PX)]
    tolerance_px: f64,
    /// Hoover tolerance T, in (0.5, 1].
    #[arg(long, default_value_t = eval::HOOVER_T)]
    hoover_t: f64,
    /// Which labels of the segmentation are regions.
    #[arg(long, value_enum, default_value_t = SegConvention::Auto)]
    seg_convention: SegConvention,
    /// Also compute the Hoover curve for T = 0.51 … 0.95.
    #[arg(long)]
    curve: bool,
    /// Print exactly one JSON object instead of text.
    #[arg(long)]
    json: bool,
}

/// The files a score was computed from, echoed in the JSON output.
#[derive(Debug, serde::Serialize)]
struct Files {
    gt: PathBuf,
    seg: PathBuf,
    edges: Option<PathBuf>,
    reference: Option<PathBuf>,
    gt_ang: Option<PathBuf>,
    seg_nor: Option<PathBuf>,
}

/// The JSON document: the scores plus where they came from.
#[derive(Debug, serde::Serialize)]
struct Report<'a> {
    #[serde(flatten)]
    scores: &'a eval::Scores,
    seg_convention: eval::Convention,
    files: &'a Files,
}

/// `explicit` if given (it must exist), else `default` if that file exists.
fn side_file(explicit: Option<&Path>, default: PathBuf) -> Option<PathBuf> {
    match explicit {
        Some(p) => Some(p.to_path_buf()),
        None => default.is_file().then_some(default),
    }
}

fn check_size<T, U>(
    what: &str,
    path: &Path,
    img: &rangeimage::Grid<T>,
    gt_path: &Path,
    gt: &rangeimage::Grid<U>,
) -> anyhow::Result<()> {
    if !img.same_size(gt) {
        bail!(
            "{}: {what} is {}×{} but the ground truth {} is {}×{}",
            path.display(),
            img.width(),
            img.height(),
            gt_path.display(),
            gt.width(),
            gt.height()
        );
    }
    Ok(())
}

/// Refuses a matching tolerance τ larger than the image diagonal: no two pixels are farther apart, so a
/// larger value means nothing (and the one-to-one matching's candidate lists grow with τ²).
fn check_tolerance<T>(tolerance_px: f64, gt_path: &Path, gt: &rangeimage::Grid<T>) -> anyhow::Result<()> {
    let diagonal = f64::from(gt.width()).hypot(f64::from(gt.height()));
    if tolerance_px > diagonal {
        bail!(
            "--tolerance-px {tolerance_px} is larger than the diagonal of {} ({}×{}: {diagonal:.1} px); \
             use a value up to the diagonal",
            gt_path.display(),
            gt.width(),
            gt.height()
        );
    }
    Ok(())
}

/// Runs `rangeseg score`.
pub(crate) fn run(args: Args) -> anyhow::Result<ExitCode> {
    let (scores, files, convention) = compute(&args)?;
    if args.json {
        let report = Report { scores: &scores, seg_convention: convention, files: &files };
        let text = serde_json::to_string_pretty(&report).context("serialising the scores")?;
        print_out(&text)?;
    } else {
        print_out(&render_text(&scores, &files, convention, args.tolerance_px))?;
    }
    Ok(ExitCode::SUCCESS)
}

/// Reads the inputs and computes the scores, the files used and the resolved MS convention.
fn compute(args: &Args) -> anyhow::Result<(eval::Scores, Files, eval::Convention)> {
    let params = eval::Params {
        tolerance_px: args.tolerance_px,
        hoover_t: args.hoover_t,
        seg_convention: args.seg_convention.into(),
        hoover_curve: args.curve,
    };
    if !(args.tolerance_px.is_finite() && args.tolerance_px >= 0.0) {
        bail!("--tolerance-px must be a finite number ≥ 0, got {}", args.tolerance_px);
    }
    if !(args.hoover_t > 0.5 && args.hoover_t <= 1.0) {
        bail!("--hoover-t must be in (0.5, 1], got {}", args.hoover_t);
    }
    if let Err(e) = params.validate() {
        bail!("invalid option: {e}");
    }
    if args.reference.is_some() && args.edges.is_none() {
        bail!("--reference needs --edges (the paper's precision scores an edge map against a reference)");
    }
    let gt = rangeio::abw::read_labels(&args.gt, true)?;
    check_tolerance(args.tolerance_px, &args.gt, &gt)?;
    let seg = rangeio::abw::read_labels(&args.seg, false)?;
    check_size("segmentation", &args.seg, &seg, &args.gt, &gt)?;
    let edges = match &args.edges {
        Some(p) => {
            let e = rangeio::png::read_edge_png(p)?;
            check_size("edge map", p, &e, &args.gt, &gt)?;
            Some(e)
        }
        None => None,
    };
    let reference = match &args.reference {
        Some(p) => {
            let r = rangeio::png::read_edge_png(p)?;
            check_size("reference edge map", p, &r, &args.gt, &gt)?;
            Some(r)
        }
        None => None,
    };
    let gt_ang = side_file(args.gt_ang.as_deref(), args.gt.with_extension("gt-ang"));
    let seg_nor = side_file(args.seg_nor.as_deref(), args.seg.with_extension("ms-nor"));
    let angles: Option<Vec<(u32, u32, f64)>> = match &gt_ang {
        Some(p) => Some(rangeio::abw::read_angles(p)?.into_iter().map(|a| (a.a, a.b, a.angle_deg)).collect()),
        None => None,
    };
    let normals = match &seg_nor {
        Some(p) => Some(rangeio::abw::read_normals(p)?),
        None => None,
    };
    let inputs = eval::Inputs {
        gt: &gt,
        seg: Some(&seg),
        edges: edges.as_ref(),
        reference: reference.as_ref(),
        gt_angles: angles.as_deref(),
        seg_normals: normals.as_deref(),
    };
    let scores = eval::score(&inputs, &params);
    let files = Files {
        gt: args.gt.clone(),
        seg: args.seg.clone(),
        edges: args.edges.clone(),
        reference: args.reference.clone(),
        gt_ang,
        seg_nor,
    };
    Ok((scores, files, params.seg_convention.resolve(&seg)))
}

/// Writes the report to standard output.
fn print_out(text: &str) -> std::io::Result<()> {
    use std::io::Write;
    let mut out = std::io::stdout().lock();
    writeln!(out, "{text}")?;
    out.flush()
}

fn fmt_prf(p: &eval::Prf) -> String {
    format!(
        "P {:.4}  R {:.4}  F {:.4}  (detected {}/{}, GT {}/{})",
        p.precision, p.recall, p.f, p.n_detected_matched, p.n_detected, p.n_gt_matched, p.n_gt
    )
}

fn fmt_hoover(h: &eval::HooverScore) -> String {
    format!(
        "T {:.2}: GT regions {}, MS regions {}, correct {}, over {}, under {}, missed {}, noise {}",
        h.t, h.gt_regions, h.seg_regions, h.correct, h.over, h.under, h.missed, h.noise
    )
}

/// The human-readable report.
fn render_text(s: &eval::Scores, files: &Files, convention: eval::Convention, tolerance_px: f64) -> String {
    use std::fmt::Write;
    let mut out = String::new();
    let na = |why: &str| format!("n/a ({why})");
    let _ = writeln!(out, "ground truth   {}", files.gt.display());
    let _ = writeln!(out, "segmentation   {} (convention {convention:?})", files.seg.display());
    if let Some(h) = &s.hoover {
        let _ = writeln!(out, "hoover         {}", fmt_hoover(h));
        let angle = match (h.angle_error_deg, h.angle_error_std_deg) {
            (Some(m), Some(sd)) => format!("{m:.2}° ± {sd:.2}° over {} adjacent pairs", h.angle_pairs),
            _ if files.gt_ang.is_none() => na("no .gt-ang"),
            _ if files.seg_nor.is_none() => na("no .ms-nor"),
            _ => na("no correctly detected adjacent pair with normals"),
        };
        let _ = writeln!(out, "angle error    {angle}");
    }
    if let Some(j) = &s.jin {
        let _ = writeln!(
            out,
            "jin et al.     {} of {} GT planes covered ≥ {:.0} % by one region ({:.3})",
            j.detected,
            j.gt_regions,
            100.0 * j.threshold,
            j.rate
        );
    }
    if let Some(curve) = &s.hoover_curve {
        for h in curve {
            let _ = writeln!(out, "  curve        {}", fmt_hoover(h));
        }
    }
    match &s.boundary {
        Some(b) => {
            let source = match b.boundary_source {
                eval::BoundarySource::Edges => "edge map",
                eval::BoundarySource::Segmentation => "segmentation boundaries",
            };
            let _ = writeln!(out, "boundary       τ = {} px, scoring the {source}", b.tolerance_px);
            let _ = writeln!(out, "  matched      {}", fmt_prf(&b.matched));
            let _ = writeln!(out, "  simple       {}", fmt_prf(&b.simple));
        }
        None => {
            let _ = writeln!(out, "boundary       {}", na("nothing to score"));
        }
    }
    let pp = match (s.paper_precision, &files.edges, &files.reference) {
        (Some(p), _, _) => format!("{p:.4} (τ = {tolerance_px} px)"),
        (None, Some(_), Some(_)) => na("the edge map is empty"),
        _ => na("needs --edges and --reference"),
    };
    let _ = write!(out, "paper precision {pp}");
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use rangeimage::Grid;

    fn args(dir: &Path) -> Args {
        Args {
            gt: dir.join("a.gt-seg"),
            seg: dir.join("a.ms-seg"),
            edges: None,
            gt_ang: None,
            seg_nor: None,
            reference: None,
            tolerance_px: eval::TOLERANCE_PX,
            hoover_t: eval::HOOVER_T,
            seg_convention: SegConvention::Auto,
            curve: false,
            json: true,
        }
    }

    /// GT: 10 | 11 over a 24×16 image; MS: the same split one column to the right.
    fn write_case(dir: &Path) {
        std::fs::create_dir_all(dir).unwrap();
        let gt = Grid::from_fn(24, 16, |x, _| if x < 12 { 10 } else { 11 });
        let seg = Grid::from_fn(24, 16, |x, _| if x < 13 { 20 } else { 21 });
        rangeio::abw::write_labels(&dir.join("a.gt-seg"), &gt).unwrap();
        rangeio::abw::write_labels(&dir.join("a.ms-seg"), &seg).unwrap();
        let ang = [rangeio::abw::AdjacentAngle { a: 10, b: 11, angle_deg: 90.0 }];
        rangeio::abw::write_angles(&dir.join("a.gt-ang"), &ang).unwrap();
        rangeio::abw::write_normals(&dir.join("a.ms-nor"), &[(20, [0.0, 0.0, 1.0]), (21, [1.0, 0.0, 1.0])])
            .unwrap();
        rangeio::png::write_edge_png(&dir.join("e.png"), &eval::boundary::gt_boundaries(&gt)).unwrap();
        rangeio::png::write_edge_png(&dir.join("small.png"), &Grid::new(3, 3, false)).unwrap();
    }

    #[test]
    fn scores_files_and_finds_side_files() {
        let dir = std::env::temp_dir().join(format!("rangeseg-score-test-{}", std::process::id()));
        write_case(&dir);
        let (s, files, conv) = compute(&args(&dir)).unwrap();
        assert_eq!(conv, eval::Convention::Abw);
        assert_eq!(files.gt_ang.as_deref(), Some(dir.join("a.gt-ang").as_path()));
        let h = s.hoover.as_ref().unwrap();
        assert_eq!((h.correct, h.angle_pairs), (2, 1));
        approx::assert_relative_eq!(h.angle_error_deg.unwrap(), 45.0, epsilon = 1e-4);
        let b = s.boundary.as_ref().unwrap();
        assert_eq!(b.boundary_source, eval::BoundarySource::Segmentation);
        // The 2-px GT band (32 px) thins to column 11, rows 1..=15; the MS boundary's thinned
        // line (column 12) lies 1 px beside it.
        assert_eq!((b.matched.n_gt, b.matched.n_gt_matched), (15, 15));
        assert_eq!(s.jin.as_ref().map(|j| (j.detected, j.gt_regions)), Some((2, 2)));
        let json = serde_json::to_value(Report { scores: &s, seg_convention: conv, files: &files }).unwrap();
        assert_eq!(json["hoover"]["correct"], 2);
        assert_eq!(json["jin"]["detected"], 2);
        assert!(json["paper_precision"].is_null());
        assert!(render_text(&s, &files, conv, 2.0).contains("n/a (needs --edges and --reference)"));

        let with_edges =
            Args { edges: Some(dir.join("e.png")), reference: Some(dir.join("e.png")), ..args(&dir) };
        let (s, _, _) = compute(&with_edges).unwrap();
        assert_eq!(s.boundary.unwrap().boundary_source, eval::BoundarySource::Edges);
        assert_eq!(s.paper_precision, Some(1.0));

        let bad = Args { edges: Some(dir.join("small.png")), ..args(&dir) };
        let err = format!("{:#}", compute(&bad).unwrap_err());
        assert!(err.contains("small.png") && err.contains("3×3"), "{err}");
        let missing = Args { seg: dir.join("none.ms-seg"), ..args(&dir) };
        assert!(format!("{:#}", compute(&missing).unwrap_err()).contains("none.ms-seg"));
        let huge_tau = Args { tolerance_px: 1e9, ..args(&dir) };
        let err = format!("{:#}", compute(&huge_tau).unwrap_err());
        assert!(err.contains("--tolerance-px 1000000000") && err.contains("a.gt-seg"), "{err}");
        let diagonal = Args { tolerance_px: 24f64.hypot(16.0), ..args(&dir) };
        assert!(compute(&diagonal).is_ok(), "τ = the diagonal is allowed");
        let bad_t = Args { hoover_t: 0.3, ..args(&dir) };
        assert!(format!("{:#}", compute(&bad_t).unwrap_err()).contains("--hoover-t"));
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// Numbers the fuzz draws the numeric options from: ordinary, boundary and absurd values.
    fn numbers() -> impl proptest::strategy::Strategy<Value = f64> {
        use proptest::prelude::*;
        prop_oneof![
            -3.0f64..40.0,
            0.5f64..1.0,
            Just(f64::NAN),
            Just(f64::INFINITY),
            Just(f64::NEG_INFINITY),
            Just(1e9),
            Just(f64::MAX),
            Just(-0.0),
            Just(0.5),
            Just(1.0),
            any::<f64>(),
        ]
    }

    proptest::proptest! {
        #![proptest_config(proptest::test_runner::Config {
            cases: 64,
            rng_seed: proptest::test_runner::RngSeed::Fixed(16),
            failure_persistence: None,
            ..proptest::test_runner::Config::default()
        })]

        /// `score` on mutated input files and absurd numeric options: never a panic, and every error
        /// names the file or the option at fault.
        #[test]
        fn score_fuzz_never_panics_and_names_the_culprit(
            tolerance_px in numbers(),
            hoover_t in numbers(),
            which in 0usize..4,
            edits in proptest::collection::vec((proptest::prelude::any::<proptest::sample::Index>(), proptest::prelude::any::<u8>()), 0..6),
            cut in proptest::option::of(proptest::prelude::any::<proptest::sample::Index>()),
            curve in proptest::prelude::any::<bool>(),
        ) {
            let dir = tempfile::tempdir().unwrap();
            write_case(dir.path());
            let file = ["a.gt-seg", "a.ms-seg", "e.png", "a.gt-ang"][which];
            let path = dir.path().join(file);
            let mut bytes = std::fs::read(&path).unwrap();
            for (i, v) in &edits {
                let i = i.index(bytes.len());
                bytes[i] = *v;
            }
            if let Some(c) = cut {
                bytes.truncate(c.index(bytes.len() + 1));
            }
            std::fs::write(&path, &bytes).unwrap();
            let a = Args {
                edges: Some(dir.path().join("e.png")),
                reference: Some(dir.path().join("e.png")),
                tolerance_px,
                hoover_t,
                curve,
                ..args(dir.path())
            };
            if let Err(e) = compute(&a) {
                let msg = format!("{e:#}");
                let names_option = msg.contains("--tolerance-px") || msg.contains("--hoover-t");
                proptest::prop_assert!(names_option || msg.contains(file), "{}", msg);
            }
        }
    }
}
