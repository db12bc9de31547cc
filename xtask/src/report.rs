//! The evaluation report: Markdown, self-contained HTML, CSV and JSON from the per-image results.

use anyhow::{Context, Result};
use base64::Engine as _;
use rangeimage::{EdgeMap, Grid, LabelImage, RangeImage};
use rangeseg::evaluate::{CURVE_TS, EdgeScores, ImageScores};
use rangeseg::pipeline::{Output, StageTimings};
use serde::Serialize;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// Published Hoover et al. (1996) correct detections on the real ABW test set, T = 0.8, of 15.2 GT regions.
const PUBLISHED_HOOVER: &[(&str, f64)] = &[("UE", 13.4), ("UB", 12.8), ("USF", 12.7), ("WSU", 9.7)];
/// The paper's Table I means (precision against C1, real ABW).
const PAPER_TABLE1: (&str, &str) = ("0.6236 ± 0.1050", "0.9422 ± 0.0209");

/// One test image's results.
#[derive(Debug, Clone, Serialize)]
pub(crate) struct ImageRow {
    pub(crate) stem: String,
    pub(crate) scores: ImageScores,
    pub(crate) timings: StageTimings,
    pub(crate) read_ms: f64,
    pub(crate) write_ms: f64,
    pub(crate) total_ms: f64,
    pub(crate) relax_energy_before: f64,
    pub(crate) relax_energy_after: f64,
    /// Robust depth noise σ of the range image around local planes, quantisation included
    /// (`planefit::noise::estimate`), in its depth units.
    pub(crate) noise_sigma: f64,
    /// The image's depth quantisation step, if any.
    pub(crate) noise_step: Option<f64>,
    /// The step, if the pipeline dequantised the image as a staircase (`rangeseg::dequantise`).
    pub(crate) dequantised: Option<f64>,
    #[serde(skip)]
    pub(crate) figure: PathBuf,
}

/// Everything the report shows.
#[derive(Debug, Clone, Serialize)]
pub(crate) struct Report {
    /// Short name of the data set (`synthetic`, or the folder's name).
    pub(crate) data_name: String,
    pub(crate) data_dir: String,
    /// Which of the folder's images were read (e.g. "test split").
    pub(crate) selection: String,
    /// How the camera was chosen.
    pub(crate) camera: String,
    pub(crate) config_path: String,
    pub(crate) config_toml: String,
    pub(crate) rows: Vec<ImageRow>,
    pub(crate) wall_s: f64,
    pub(crate) threads: usize,
}

/// Mean and sample standard deviation, in input order (deterministic).
pub(crate) fn mean_std(xs: impl IntoIterator<Item = f64>) -> (f64, f64) {
    let v: Vec<f64> = xs.into_iter().filter(|x| x.is_finite()).collect();
    if v.is_empty() {
        return (f64::NAN, f64::NAN);
    }
    let n = v.len() as f64;
    let mean = v.iter().sum::<f64>() / n;
    let var = if v.len() > 1 { v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1.0) } else { 0.0 };
    (mean, var.sqrt())
}

fn ms(xs: impl IntoIterator<Item = f64>, digits: usize) -> String {
    let (m, s) = mean_std(xs);
    if m.is_nan() { "—".into() } else { format!("{m:.digits$} ± {s:.digits$}") }
}

fn opt(x: Option<f64>) -> f64 {
    x.unwrap_or(f64::NAN)
}

/// A Markdown table from a header and rows.
fn md_table(header: &[&str], rows: &[Vec<String>]) -> String {
    let mut s = format!("| {} |\n|{}\n", header.join(" | "), "---|".repeat(header.len()));
    for r in rows {
        let _ = writeln!(s, "| {} |", r.join(" | "));
    }
    s
}

/// An HTML table from a header and rows.
fn html_table(header: &[&str], rows: &[Vec<String>]) -> String {
    let mut s = String::from("<table><thead><tr>");
    for h in header {
        let _ = write!(s, "<th>{}</th>", esc(h));
    }
    s.push_str("</tr></thead><tbody>");
    for r in rows {
        s.push_str("<tr>");
        for c in r {
            let _ = write!(s, "<td>{}</td>", esc(c));
        }
        s.push_str("</tr>");
    }
    s.push_str("</tbody></table>\n");
    s
}

fn esc(s: &str) -> String {
    s.replace('&', "&amp;").replace('<', "&lt;").replace('>', "&gt;")
}

/// The report's tables as (title, note, header, rows).
type Table = (&'static str, String, Vec<&'static str>, Vec<Vec<String>>);

fn tables(r: &Report) -> Vec<Table> {
    vec![
        edge_table(&r.rows),
        relaxation_table(&r.rows),
        hoover_table(&r.rows),
        per_image_table(&r.rows),
        timings_table(r),
    ]
}

/// Table I: the edge maps against C1 and ground truth.
fn edge_table(rows: &[ImageRow]) -> Table {
    let edge_row = |name: &str, pick: &dyn Fn(&ImageScores) -> &EdgeScores| -> Vec<String> {
        let e = |f: &dyn Fn(&EdgeScores) -> f64| ms(rows.iter().map(|x| f(pick(&x.scores))), 4);
        vec![
            name.to_string(),
            e(&|s| opt(s.paper_precision_c1)),
            e(&|s| opt(s.paper_precision_gt)),
            e(&|s| s.matched.precision),
            e(&|s| s.matched.recall),
            e(&|s| s.matched.f),
            e(&|s| s.simple.f),
            ms(rows.iter().map(|x| pick(&x.scores).n_edges as f64), 0),
        ]
    };
    let edge_header = vec![
        "edge map",
        "paper precision vs C1",
        "paper precision vs GT",
        "P (1:1)",
        "R (1:1)",
        "F (1:1)",
        "F (simple)",
        "edge px",
    ];
    let table1 = vec![
        edge_row("Canny on raw depth", &|s| &s.raw_canny),
        edge_row("Canny on plane parameters (C2)", &|s| &s.c2),
        edge_row("region borders (C1)", &|s| &s.c1),
        edge_row("final edge map (C)", &|s| &s.relaxed),
        vec![
            "paper, real ABW (raw / plane), precision vs C1".into(),
            format!("{} / {}", PAPER_TABLE1.0, PAPER_TABLE1.1),
            "—".into(),
            "—".into(),
            "—".into(),
            "—".into(),
            "—".into(),
            "—".into(),
        ],
    ];
    (
        "Edge maps: Table I (Canny on raw depth vs on plane parameters), C1 and the final map",
        format!(
            "Tolerance {} px. Paper precision (Eq. 7) against C1 is the paper's protocol; against ground truth and the boundary P/R/F are the honest versions (one-to-one: both maps thinned to one pixel, as BSDS). The paper's row was measured elsewhere (the 30 real ABW test images).",
            rangeseg::evaluate::TOLERANCE_PX
        ),
        edge_header,
        table1,
    )
}

/// Table II: C2 before and the final edge map after relaxation, per image.
fn relaxation_table(rows: &[ImageRow]) -> Table {
    let mut table2: Vec<Vec<String>> = rows
        .iter()
        .map(|x| {
            let s = &x.scores;
            let (a, b) = (opt(s.c2.paper_precision_c1), opt(s.relaxed.paper_precision_c1));
            vec![
                x.stem.clone(),
                format!("{a:.4}"),
                format!("{b:.4}"),
                format!("{:+.2}%", 100.0 * (b - a)),
                format!("{:.4}", s.c2.matched.f),
                format!("{:.4}", s.relaxed.matched.f),
                format!("{:+.4}", s.relaxed.matched.f - s.c2.matched.f),
            ]
        })
        .collect();
    let d = |f: &dyn Fn(&ImageScores) -> f64| ms(rows.iter().map(|x| f(&x.scores)), 4);
    table2.push(vec![
        "mean ± std".into(),
        d(&|s| opt(s.c2.paper_precision_c1)),
        d(&|s| opt(s.relaxed.paper_precision_c1)),
        format!(
            "{:+.2}%",
            100.0
                * mean_std(rows.iter().map(|x| {
                    opt(x.scores.relaxed.paper_precision_c1) - opt(x.scores.c2.paper_precision_c1)
                }))
                .0
        ),
        d(&|s| s.c2.matched.f),
        d(&|s| s.relaxed.matched.f),
        format!(
            "{:+.4}",
            mean_std(rows.iter().map(|x| x.scores.relaxed.matched.f - x.scores.c2.matched.f)).0
        ),
    ]);
    (
        "Table II: before (C2) vs after relaxation (final C), per image",
        "Paper precision against the initial C1 (the paper's protocol; it reports +3.20% on average on real ABW) and one-to-one boundary F against ground truth.".into(),
        vec!["image", "precision C2", "precision relaxed", "Δ precision", "F C2", "F relaxed", "Δ F"],
        table2,
    )
}

/// Hoover et al.'s region metrics and Jin et al.'s rate, with published rows for scale.
fn hoover_table(rows: &[ImageRow]) -> Table {
    let hoover_row = |name: &str,
                      pick: &dyn Fn(&ImageScores) -> &eval::hoover::HooverScore,
                      jin: &dyn Fn(&ImageScores) -> &eval::JinScore|
     -> Vec<String> {
        let h =
            |f: &dyn Fn(&eval::hoover::HooverScore) -> f64| ms(rows.iter().map(|x| f(pick(&x.scores))), 2);
        let total = |f: &dyn Fn(&eval::hoover::HooverScore) -> u32| -> f64 {
            rows.iter().map(|x| f64::from(f(pick(&x.scores)))).sum()
        };
        vec![
            name.into(),
            h(&|s| f64::from(s.gt_regions)),
            h(&|s| f64::from(s.correct)),
            format!("{:.1} %", 100.0 * total(&|s| s.correct) / total(&|s| s.gt_regions).max(1.0)),
            h(&|s| opt(s.angle_error_deg)),
            h(&|s| f64::from(s.over)),
            h(&|s| f64::from(s.under)),
            h(&|s| f64::from(s.missed)),
            h(&|s| f64::from(s.noise)),
            format!(
                "{:.1} %",
                100.0 * rows.iter().map(|x| f64::from(jin(&x.scores).detected)).sum::<f64>()
                    / rows.iter().map(|x| f64::from(jin(&x.scores).gt_regions)).sum::<f64>().max(1.0)
            ),
        ]
    };
    let mut hoover = vec![
        hoover_row("region growing alone (ours)", &|s| &s.hoover_regiongrow, &|s| &s.jin_regiongrow),
        hoover_row("final segmentation (ours)", &|s| &s.hoover_final, &|s| &s.jin_final),
    ];
    hoover.extend(published_rows(rows));
    (
        "Hoover et al. region metrics at T = 0.8 (mean ± std per image)",
        "Rows marked 'measured elsewhere' are published figures on other images or by other rules, for scale only. Jin et al.'s rate: a GT plane counts as detected when one machine region covers 80 % of it (their calculateROC.m, one-sided), Σ detected ÷ Σ GT planes.".into(),
        vec![
            "segmenter",
            "GT regions",
            "correct",
            "correct % (Σ correct ÷ Σ GT)",
            "angle error (°)",
            "over",
            "under",
            "missed",
            "noise",
            "Jin et al. rate",
        ],
        hoover,
    )
}

/// Per image: region growing alone, the final segmentation and the three edge maps.
fn per_image_table(rows: &[ImageRow]) -> Table {
    let per_image: Vec<Vec<String>> = rows
        .iter()
        .map(|x| {
            let s = &x.scores;
            vec![
                x.stem.clone(),
                s.hoover_final.gt_regions.to_string(),
                s.hoover_regiongrow.correct.to_string(),
                s.hoover_final.correct.to_string(),
                format!("{} / {}", s.hoover_final.over, s.hoover_final.under),
                s.hoover_final.noise.to_string(),
                format!("{:.3}", s.c1.matched.f),
                format!("{:.3}", s.c2.matched.f),
                format!("{:.3}", s.relaxed.matched.f),
                noise_cell(x),
            ]
        })
        .collect();
    (
        "Per image: region growing alone, final segmentation and the three edge maps",
        "Hoover correct detections at T = 0.8, the final segmentation's over-/under-segmentations and noise regions, one-to-one boundary F of C1, C2 and the final edge map C; the range image's own depth noise σ (robust scale of 5 × 5 plane-fit residuals, quantisation included) and quantisation step, in its depth units.".into(),
        vec![
            "image",
            "GT regions",
            "correct (RG)",
            "correct (final)",
            "over / under",
            "noise",
            "F C1",
            "F C2",
            "F C",
            "depth σ / step",
        ],
        per_image,
    )
}

/// `σ / step` of an image's depth noise estimate (`—` where there is no step or too little data), and whether
/// the pipeline dequantised it.
fn noise_cell(x: &ImageRow) -> String {
    let sigma = if x.noise_sigma.is_nan() { "—".to_string() } else { format!("{:.2}", x.noise_sigma) };
    let step = x.noise_step.map_or_else(|| "—".to_string(), |q| format!("{q:.3}"));
    let stairs = if x.dequantised.is_some() { ", dequantised" } else { "" };
    format!("{sigma} / {step}{stairs}")
}

/// The range of the images' noise estimates, e.g. `depth σ 0.55–0.81, step 1.000`.
fn noise_range(rows: &[ImageRow]) -> String {
    let sig: Vec<f64> = rows.iter().map(|x| x.noise_sigma).filter(|s| s.is_finite()).collect();
    let lo = sig.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = sig.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    let mut steps: Vec<String> =
        rows.iter().map(|x| x.noise_step.map_or_else(|| "none".to_string(), |q| format!("{q:.3}"))).collect();
    steps.sort();
    steps.dedup();
    let stairs = match rows.iter().filter(|x| x.dequantised.is_some()).count() {
        0 => String::new(),
        n => format!(", {n} of {} dequantised (staircases)", rows.len()),
    };
    if sig.is_empty() {
        format!("depth σ —, step {}{stairs}", steps.join("/"))
    } else {
        format!("depth σ {lo:.2}–{hi:.2}, step {}{stairs}", steps.join("/"))
    }
}

/// Per-stage timings.
fn timings_table(r: &Report) -> Table {
    let rows = &r.rows;
    let t = |f: &dyn Fn(&ImageRow) -> f64| ms(rows.iter().map(f), 1);
    let timings = vec![vec![
        t(&|x| x.read_ms),
        t(&|x| x.timings.features),
        t(&|x| x.timings.regiongrow),
        t(&|x| x.timings.vcanny),
        t(&|x| x.timings.relax),
        t(&|x| x.write_ms),
        t(&|x| x.total_ms),
    ]];
    (
        "Per-stage timings (ms per image, mean ± std)",
        format!(
            "{} images on {} thread{}; whole evaluation {:.1} s wall time.",
            rows.len(),
            r.threads,
            if r.threads == 1 { "" } else { "s" },
            r.wall_s
        ),
        vec!["read", "features", "regiongrow", "vcanny", "relax + final", "write", "total"],
        timings,
    )
}

/// Published figures for scale, chosen by the data set's file names: Hoover et al. (1996) for ABW names, Jin et
/// al. (2017) for the NYU Kinect frames. None of them was measured on these exact images.
fn published_rows(rows: &[ImageRow]) -> Vec<Vec<String>> {
    // Columns: name, GT regions, correct, correct %, angle, over, under, missed, noise, Jin rate; "—" where unknown.
    let row = |name: String, known: &[(usize, String)]| -> Vec<String> {
        let mut r = vec!["—".to_string(); 10];
        r[0] = name;
        for (i, v) in known {
            r[*i] = v.clone();
        }
        r
    };
    if rows.iter().all(|x| x.stem.starts_with("abw.")) {
        PUBLISHED_HOOVER
            .iter()
            .map(|(name, correct)| {
                row(
                    format!("{name}, Hoover et al. 1996: 30 real ABW test images (measured elsewhere)"),
                    &[
                        (1, "15.2".into()),
                        (2, format!("{correct:.1}")),
                        (3, format!("{:.1} %", 100.0 * correct / 15.2)),
                    ],
                )
            })
            .collect()
    } else if rows.iter().all(|x| x.stem.starts_with("nyu.")) {
        vec![row(
            "Jin et al. 2017, their method: 66 NYU frames (measured elsewhere)".into(),
            &[(9, "80.7 %".into())],
        )]
    } else {
        Vec::new()
    }
}

/// Mean correct detections over T for both segmentations.
fn curve(r: &Report) -> Vec<(f64, f64, f64)> {
    CURVE_TS
        .iter()
        .enumerate()
        .map(|(i, &t)| {
            let m = |pick: &dyn Fn(&ImageScores) -> &Vec<u32>| {
                mean_std(r.rows.iter().map(|x| f64::from(pick(&x.scores)[i]))).0
            };
            (t, m(&|s| &s.curve_correct_regiongrow), m(&|s| &s.curve_correct))
        })
        .collect()
}

/// An SVG line plot of mean correct detections against the Hoover tolerance T.
fn curve_svg(points: &[(f64, f64, f64)], gt_mean: f64) -> String {
    let (w, h, pad) = (560.0, 320.0, 48.0);
    let ymax = (gt_mean.max(1.0) * 1.1).ceil();
    let px = |t: f64| pad + (t - 0.5) / 0.45 * (w - 2.0 * pad);
    let py = |c: f64| h - pad - c / ymax * (h - 2.0 * pad);
    let line = |sel: &dyn Fn(&(f64, f64, f64)) -> f64| {
        points.iter().map(|p| format!("{:.1},{:.1}", px(p.0), py(sel(p)))).collect::<Vec<_>>().join(" ")
    };
    let mut s = format!(
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="{w}" height="{h}" font-family="sans-serif" font-size="12">"#
    );
    let _ = write!(
        s,
        r#"<line x1="{pad}" y1="{b}" x2="{r}" y2="{b}" stroke="black"/><line x1="{pad}" y1="{pad}" x2="{pad}" y2="{b}" stroke="black"/>"#,
        b = h - pad,
        r = w - pad
    );
    for i in 0..=9 {
        let t = 0.5 + 0.05 * f64::from(i);
        let _ =
            write!(s, r#"<text x="{:.1}" y="{}" text-anchor="middle">{t:.2}</text>"#, px(t), h - pad + 16.0);
    }
    for i in 0..=4 {
        let c = ymax * f64::from(i) / 4.0;
        let _ =
            write!(s, r#"<text x="{}" y="{:.1}" text-anchor="end">{c:.0}</text>"#, pad - 6.0, py(c) + 4.0);
    }
    let _ = write!(
        s,
        r#"<line x1="{pad}" y1="{y:.1}" x2="{r}" y2="{y:.1}" stroke="gray" stroke-dasharray="4 3"/><text x="{r}" y="{ty:.1}" text-anchor="end" fill="gray">GT regions {gt_mean:.1}</text>"#,
        y = py(gt_mean),
        ty = py(gt_mean) - 4.0,
        r = w - pad
    );
    let _ = write!(
        s,
        r##"<polyline fill="none" stroke="#1f77b4" stroke-width="2" points="{}"/>"##,
        line(&|p| p.2)
    );
    let _ = write!(
        s,
        r##"<polyline fill="none" stroke="#ff7f0e" stroke-width="2" stroke-dasharray="5 3" points="{}"/>"##,
        line(&|p| p.1)
    );
    let _ = write!(
        s,
        r##"<text x="{x}" y="{y1}" fill="#1f77b4">final segmentation</text><text x="{x}" y="{y2}" fill="#ff7f0e">region growing alone</text><text x="{cx}" y="{by}" text-anchor="middle">Hoover tolerance T</text><text x="14" y="{cy}" transform="rotate(-90 14 {cy})" text-anchor="middle">correct detections per image</text></svg>"##,
        x = pad + 10.0,
        y1 = pad + 4.0,
        y2 = pad + 20.0,
        cx = w / 2.0,
        by = h - 8.0,
        cy = h / 2.0
    );
    s
}

/// A short plain-text summary for the terminal.
pub(crate) fn summary(r: &Report) -> String {
    let rows = &r.rows;
    let m = |f: &dyn Fn(&ImageScores) -> f64| mean_std(rows.iter().map(|x| f(&x.scores))).0;
    let gt = m(&|s| f64::from(s.hoover_final.gt_regions));
    format!(
        "{}: Hoover T=0.8 correct {:.2} of {:.2} ({:.1} %; region growing alone {:.2}), over {:.2}, under {:.2}, Jin rate {:.1} % | F(1:1) raw {:.3}, C2 {:.3}, C1 {:.3}, final {:.3} | precision vs C1 C2 {:.4} -> final {:.4} | {}",
        r.data_name,
        m(&|s| f64::from(s.hoover_final.correct)),
        gt,
        100.0 * m(&|s| f64::from(s.hoover_final.correct)) / gt.max(f64::MIN_POSITIVE),
        m(&|s| f64::from(s.hoover_regiongrow.correct)),
        m(&|s| f64::from(s.hoover_final.over)),
        m(&|s| f64::from(s.hoover_final.under)),
        100.0 * m(&|s| f64::from(s.jin_final.detected))
            / m(&|s| f64::from(s.jin_final.gt_regions)).max(f64::MIN_POSITIVE),
        m(&|s| s.raw_canny.matched.f),
        m(&|s| s.c2.matched.f),
        m(&|s| s.c1.matched.f),
        m(&|s| s.relaxed.matched.f),
        m(&|s| opt(s.c2.paper_precision_c1)),
        m(&|s| opt(s.relaxed.paper_precision_c1)),
        noise_range(rows),
    )
}

/// One CSV line per image with the main figures.
fn csv(r: &Report) -> String {
    let mut s = String::from(
        "image,raw_f,raw_pp_c1,c2_f,c2_pp_c1,c1_f,relaxed_f,relaxed_pp_c1,gt_regions,rg_correct,rg_over,rg_under,rg_missed,rg_noise,correct,over,under,missed,noise,angle_error_deg,rg_jin_detected,jin_detected,features_ms,regiongrow_ms,vcanny_ms,relax_ms,total_ms,noise_sigma,noise_step,dequantised_step\n",
    );
    for x in &r.rows {
        let s_ = &x.scores;
        let (h, g) = (&s_.hoover_final, &s_.hoover_regiongrow);
        let _ = writeln!(
            s,
            "{},{:.5},{:.5},{:.5},{:.5},{:.5},{:.5},{:.5},{},{},{},{},{},{},{},{},{},{},{},{:.3},{},{},{:.2},{:.2},{:.2},{:.2},{:.2},{:.4},{},{}",
            x.stem,
            s_.raw_canny.matched.f,
            opt(s_.raw_canny.paper_precision_c1),
            s_.c2.matched.f,
            opt(s_.c2.paper_precision_c1),
            s_.c1.matched.f,
            s_.relaxed.matched.f,
            opt(s_.relaxed.paper_precision_c1),
            h.gt_regions,
            g.correct,
            g.over,
            g.under,
            g.missed,
            g.noise,
            h.correct,
            h.over,
            h.under,
            h.missed,
            h.noise,
            opt(h.angle_error_deg),
            s_.jin_regiongrow.detected,
            s_.jin_final.detected,
            x.timings.features,
            x.timings.regiongrow,
            x.timings.vcanny,
            x.timings.relax,
            x.total_ms,
            x.noise_sigma,
            x.noise_step.map_or_else(String::new, |q| format!("{q:.4}")),
            x.dequantised.map_or_else(String::new, |q| format!("{q:.4}"))
        );
    }
    s
}

/// Writes report.md, report.html, results.csv and results.json into `dir`, each atomically.
pub(crate) fn write_all(r: &Report, dir: &Path) -> Result<()> {
    let tables = tables(r);
    let points = curve(r);
    let gt_mean = mean_std(r.rows.iter().map(|x| f64::from(x.scores.hoover_final.gt_regions))).0;
    let intro = format!(
        "Data: {} — `{}` ({} images: {}; camera: {}). Config: `{}`.\nFigures per image: shaded range, GT edges, C2 / region map, C1, final edges (as the paper's Fig. 2).",
        r.data_name,
        r.data_dir,
        r.rows.len(),
        r.selection,
        r.camera,
        r.config_path
    );

    let mut md = format!("# rangeseg evaluation: {}\n\n{intro}\n\n", r.data_name);
    for (title, note, header, rows) in &tables {
        let _ = write!(md, "## {title}\n\n{note}\n\n{}\n", md_table(header, rows));
    }
    md.push_str("## Correct detections over T\n\n| T | region growing | final |\n|---|---|---|\n");
    for (t, a, b) in &points {
        let _ = writeln!(md, "| {t:.2} | {a:.2} | {b:.2} |");
    }
    let _ = write!(md, "\n## Configuration\n\n```toml\n{}```\n\n## Figures\n\n", r.config_toml);
    for x in &r.rows {
        let _ = writeln!(md, "![{}](figures/{}.png)", x.stem, x.stem);
    }

    let mut html = String::from(
        "<!doctype html><html><head><meta charset=\"utf-8\"><title>rangeseg evaluation</title><style>body{font-family:sans-serif;max-width:1200px;margin:2em auto;padding:0 1em;color:#222}table{border-collapse:collapse;margin:1em 0;font-size:13px}td,th{border:1px solid #ccc;padding:3px 8px;text-align:right}td:first-child,th:first-child{text-align:left}th{background:#f3f3f3}figure{margin:1.5em 0}figure img{max-width:100%;border:1px solid #ddd}pre{background:#f7f7f7;padding:1em;overflow:auto}</style></head><body><h1>rangeseg evaluation</h1>",
    );
    let _ = write!(html, "<p>{}</p>", esc(&intro).replace('\n', "<br>"));
    for (title, note, header, rows) in &tables {
        let _ = write!(html, "<h2>{}</h2><p>{}</p>{}", esc(title), esc(note), html_table(header, rows));
    }
    let _ = write!(html, "<h2>Correct detections over T</h2>{}", curve_svg(&points, gt_mean));
    let _ = write!(html, "<h2>Configuration</h2><pre>{}</pre><h2>Figures</h2>", esc(&r.config_toml));
    for x in &r.rows {
        let bytes = std::fs::read(&x.figure)
            .with_context(|| format!("{}: cannot read figure", x.figure.display()))?;
        let b64 = base64::engine::general_purpose::STANDARD.encode(bytes);
        let _ = write!(
            html,
            "<figure><img alt=\"{s}\" src=\"data:image/png;base64,{b64}\"><figcaption>{s}: shaded range · GT edges · C2 / region map · C1 · final edges</figcaption></figure>",
            s = esc(&x.stem)
        );
    }
    html.push_str("</body></html>\n");

    let json = serde_json::to_string_pretty(&r.rows).context("serialising results")?;
    for (name, text) in
        [("report.md", md), ("report.html", html), ("results.csv", csv(r)), ("results.json", json)]
    {
        rangeio::write_atomic(&dir.join(name), text.as_bytes())?;
    }
    Ok(())
}

/// A gray RGB pixel.
fn gray(v: u8) -> [u8; 3] {
    [v, v, v]
}

/// Panel of an edge map: black edges on white; downsampled by `f` with "any edge" pooling.
fn edge_panel(e: &EdgeMap, f: u32) -> Grid<[u8; 3]> {
    Grid::from_fn(e.width() / f, e.height() / f, |x, y| {
        let any = (0..f).any(|dy| (0..f).any(|dx| e[(x * f + dx, y * f + dy)]));
        gray(if any { 0 } else { 255 })
    })
}

/// The paper's Fig. 2 for one image: shaded range, GT edges, C2 / region map, C1, final edges (2 × 3 panels).
pub(crate) fn figure(range: &RangeImage, gt: &LabelImage, out: &Output) -> Grid<[u8; 3]> {
    let f = if range.width() > 320 { 2 } else { 1 };
    let shade = rangeseg::features::shade(range);
    let shaded = Grid::from_fn(range.width() / f, range.height() / f, |x, y| {
        let mut s = 0u32;
        for dy in 0..f {
            for dx in 0..f {
                s += u32::from(shade[(x * f + dx, y * f + dy)]);
            }
        }
        gray((s / (f * f)) as u8)
    });
    let regions = Grid::from_fn(range.width() / f, range.height() / f, |x, y| {
        rangeio::png::label_color(out.fin.labels[(x * f, y * f)])
    });
    let panels = [
        shaded,
        edge_panel(&eval::boundary::gt_boundaries(gt), f),
        edge_panel(&out.canny.edges, f),
        regions,
        edge_panel(&out.regions.c1, f),
        edge_panel(out.fin.edges(), f),
    ];
    let (pw, ph, gap) = (panels[0].width(), panels[0].height(), 4);
    let (cols, rows) = (3, 2);
    let mut fig = Grid::new(cols * pw + (cols - 1) * gap, rows * ph + (rows - 1) * gap, [255u8; 3]);
    for (i, p) in panels.iter().enumerate() {
        let (ox, oy) = ((i as u32 % cols) * (pw + gap), (i as u32 / cols) * (ph + gap));
        for (x, y, v) in p.enumerate() {
            fig[(ox + x, oy + y)] = *v;
        }
    }
    fig
}
