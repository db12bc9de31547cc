//! Measures the relax stage on the synthetic training split (docs/method.md §3.4, the paper's Table II).
//!
//! For each training image (`scenegen::benchmark_image(false, i)`, the scenes `cargo xtask
//! gen-data` writes as `abw.train.i`): features → regiongrow (C1, s1) and vcanny (C2, |∇|) →
//! relax → final segmentation, all with default parameters except the relax ones given here.
//! Reports boundary P/R/F (one-to-one matching, τ = 2) for C1, C2 and the relaxed C = C1 ∪ C2,
//! the paper's precision against C1 (τ = 2) before and after relaxation, and Hoover correct
//! detections at T = 0.8 for region growing alone vs the final segmentation, and Hoover
//! correct / over / under for region growing and the final segmentation in both modes.
//!
//! ```text
//! cargo run --release --example relax_eval -- [--s1 curvedness|k] [--t-d 3] [--lambda 1] [--delta 0.7] [--sweeps 7] [--gap 2] [--min-region 50]
//!     [--mode regions|components] [--no-unlabelled-core] [--support 0.3] [--merge-angle 10] [--merge-residual 2] [--support-px 2] [--no-merge-within] [--rms-ratio 1.5] [--seg-supported] [--tune]
//! ```
//! `ONLY=i` in the environment restricts the run to `abw.train.i`. `--seg-supported` gives the final
//! segmentation the support-tested edge map instead of the full relaxed sets (which the pipeline gives it).
//! `--tune` sweeps `t_d_px × lambda` on the training split and prints one summary line per pair.
#![allow(clippy::print_stdout)] // an example reports on stdout

use anyhow::{Context, Result, bail};
use rangeimage::{Camera, EdgeMap, Grid, LabelImage, RangeImage, valid_mask};
use rayon::prelude::*;

struct Prepared {
    stem: String,
    range: RangeImage,
    gt: LabelImage,
    camera: Camera,
    valid: Grid<bool>,
    rg_labels: LabelImage,
    c1: EdgeMap,
    s1: Grid<f32>,
    c2: EdgeMap,
    magnitude: Grid<f32>,
}

struct Row {
    f_c1: f64,
    f_c2: f64,
    f_final: f64,
    pp_c2: f64,
    pp_c2_relaxed: f64,
    pp_final: f64,
    /// (correct, over, under) at T = 0.8 for region growing, Components mode, Regions mode.
    hoover: [[u32; 3]; 3],
    hoover_rg: u32,
    hoover_final: u32,
    gt_regions: u32,
    rg_regions: u32,
    final_regions: u32,
    info: relax::Info,
}

fn prepare(index: u32, use_k: bool) -> Prepared {
    let (sp, seed) = scenegen::benchmark_image(false, index);
    let scene = scenegen::generate(&sp, seed);
    let range = rangeio::abw::raw_to_range(&scene.range);
    let camera = Camera::abw_for(false, index);
    let valid = valid_mask(&range);
    let feats = features::compute(&range, &features::Params::default());
    let (seg, _) = regiongrow::grow(&range, &feats, &camera, &regiongrow::Params::default(), 0);
    let canny = vcanny::detect_planes(&feats.plane, &valid, &vcanny::Params::default());
    let s1 = if use_k { feats.k.map(|v| v.abs()) } else { feats.curvedness.clone() };
    Prepared {
        stem: format!("abw.train.{index}"),
        range,
        gt: scene.labels,
        camera,
        valid,
        rg_labels: seg.labels,
        c1: seg.c1,
        s1,
        c2: canny.edges,
        magnitude: canny.magnitude,
    }
}

fn evaluate(p: &Prepared, params: &relax::Params, sp: &finalseg::Params, seg_supported: bool) -> Row {
    let (r, info) = relax::relax(
        &relax::Input { c1: &p.c1, s1: &p.s1, c2: &p.c2, magnitude: &p.magnitude, valid: &p.valid },
        params,
        0,
    );
    let seg_edges = if seg_supported { r.edges.clone() } else { r.union() };
    let (labels, regions) = finalseg::segment(&p.range, &p.camera, &seg_edges, Some(&p.rg_labels), sp);
    let other_mode = match sp.mode {
        finalseg::Mode::Regions => finalseg::Mode::Components,
        finalseg::Mode::Components => finalseg::Mode::Regions,
    };
    let sp_other = finalseg::Params { mode: other_mode, ..sp.clone() };
    let (labels_other, _) = finalseg::segment(&p.range, &p.camera, &seg_edges, Some(&p.rg_labels), &sp_other);
    let f = |e: &EdgeMap| eval::boundary::matched(e, &p.gt, 2.0).f;
    let pp = |e: &EdgeMap| eval::paper_precision(e, &p.c1, 2.0).unwrap_or(f64::NAN);
    let nz = eval::Convention::NonZero;
    let h_rg = eval::hoover::compare_with(&p.gt, &p.rg_labels, 0.8, None, None, nz);
    let h_final = eval::hoover::compare_with(&p.gt, &labels, 0.8, None, None, nz);
    let h_other = eval::hoover::compare_with(&p.gt, &labels_other, 0.8, None, None, nz);
    let (h_comp, h_reg) =
        if sp.mode == finalseg::Mode::Regions { (&h_other, &h_final) } else { (&h_final, &h_other) };
    let cou = |h: &eval::hoover::HooverScore| [h.correct, h.over, h.under];
    Row {
        f_c1: f(&p.c1),
        f_c2: f(&p.c2),
        f_final: f(&r.edges),
        pp_c2: pp(&p.c2),
        pp_c2_relaxed: pp(&r.c2),
        pp_final: pp(&r.edges),
        hoover: [cou(&h_rg), cou(h_comp), cou(h_reg)],
        hoover_rg: h_rg.correct,
        hoover_final: h_final.correct,
        gt_regions: h_rg.gt_regions,
        rg_regions: h_rg.seg_regions,
        final_regions: regions.len() as u32,
        info,
    }
}

fn mean(v: impl Iterator<Item = f64>) -> f64 {
    let v: Vec<f64> = v.collect();
    v.iter().sum::<f64>() / v.len().max(1) as f64
}

impl Row {
    /// The figures the summaries average: F of C1, C2 and C; the paper's precision of C2, relaxed C2 and C;
    /// Hoover correct detections of region growing and of the final segmentation; GT regions.
    fn figures(&self) -> [f64; 9] {
        [
            self.f_c1,
            self.f_c2,
            self.f_final,
            self.pp_c2,
            self.pp_c2_relaxed,
            self.pp_final,
            f64::from(self.hoover_rg),
            f64::from(self.hoover_final),
            f64::from(self.gt_regions),
        ]
    }
}

/// The mean over images of each of [`Row::figures`].
fn means(rows: &[Row]) -> [f64; 9] {
    std::array::from_fn(|k| mean(rows.iter().map(|r| r.figures()[k])))
}

/// The command line: relax and final-segmentation parameters, and the options.
struct Args {
    params: relax::Params,
    sp: finalseg::Params,
    tune: bool,
    use_k: bool,
    seg_supported: bool,
}

fn parse_args() -> Result<Args> {
    let mut params = relax::Params::default();
    let mut sp = finalseg::Params::default();
    let (mut tune, mut use_k, mut seg_supported) = (false, false, false);
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        let mut value = |name: &str| args.next().with_context(|| format!("{name} needs a value"));
        match a.as_str() {
            "--tune" => tune = true,
            "--s1" => use_k = value("--s1")? == "k",
            "--t-d" => params.t_d_px = value("--t-d")?.parse()?,
            "--lambda" => params.lambda = value("--lambda")?.parse()?,
            "--delta" => params.cooling_delta = value("--delta")?.parse()?,
            "--sweeps" => params.max_sweeps = value("--sweeps")?.parse()?,
            "--gap" => sp.gap_close_px = value("--gap")?.parse()?,
            "--min-region" => sp.min_region_px = value("--min-region")?.parse()?,
            "--mode" => {
                sp.mode = match value("--mode")?.as_str() {
                    "components" => finalseg::Mode::Components,
                    "regions" => finalseg::Mode::Regions,
                    m => bail!("unknown mode {m}"),
                }
            }
            "--no-unlabelled-core" => sp.unlabelled_core = false,
            "--support-px" => params.support_px = value("--support-px")?.parse()?,
            "--no-merge-within" => sp.merge_within_region = false,
            "--rms-ratio" => sp.within_max_rms_ratio = value("--rms-ratio")?.parse()?,
            "--seg-supported" => seg_supported = true,
            "--support" => sp.min_border_support = value("--support")?.parse()?,
            "--merge-angle" => sp.merge_max_angle_deg = value("--merge-angle")?.parse()?,
            "--merge-residual" => sp.merge_max_residual = value("--merge-residual")?.parse()?,
            _ => bail!("unknown argument {a}"),
        }
    }
    params.validate()?;
    sp.validate()?;
    Ok(Args { params, sp, tune, use_k, seg_supported })
}

/// `--tune`: one summary line per `t_d_px × lambda`.
fn tune(images: &[Prepared], args: &Args) {
    println!("t_d  lambda | F(C2)  F(C)   | pp(C2) pp(C2') pp(C) | Hoover RG  final (of GT)");
    for t_d in [1.5, 2.0, 3.0, 4.0] {
        for lambda in [0.0, 0.3, 1.0, 3.0] {
            let p = relax::Params { t_d_px: t_d, lambda, ..args.params.clone() };
            let rows: Vec<Row> =
                images.par_iter().map(|im| evaluate(im, &p, &args.sp, args.seg_supported)).collect();
            let [_, f_c2, f_final, pp_c2, pp_c2_relaxed, pp_final, rg, fin, gt] = means(&rows);
            println!(
                "{t_d:<4} {lambda:<6} | {f_c2:.4} {f_final:.4} | {pp_c2:.4} {pp_c2_relaxed:.4}  {pp_final:.4} | {rg:.2}  {fin:.2}  ({gt:.2})"
            );
        }
    }
}

/// One line per image, the means, and the Hoover counts of both final-segmentation modes.
fn report(images: &[Prepared], rows: &[Row]) {
    println!(
        "image         | F(C1)  F(C2)  F(C)   | pp(C2) pp(C2') pp(C) | Hoover RG final /GT | #RG #fin | rm C1 rm C2 sweeps E0 -> E1"
    );
    for (im, r) in images.iter().zip(rows) {
        println!(
            "{:<13} | {:.4} {:.4} {:.4} | {:.4} {:.4}  {:.4} | {:>3} {:>3} /{:<3} | {:>3} {:>3} | {:>5} {:>5} {:>3} {:.0} -> {:.0}",
            im.stem,
            r.f_c1,
            r.f_c2,
            r.f_final,
            r.pp_c2,
            r.pp_c2_relaxed,
            r.pp_final,
            r.hoover_rg,
            r.hoover_final,
            r.gt_regions,
            r.rg_regions,
            r.final_regions,
            r.info.removed_c1,
            r.info.removed_c2,
            r.info.sweeps,
            r.info.energy_before,
            r.info.energy_after,
        );
    }
    let [f_c1, f_c2, f_final, pp_c2, pp_c2_relaxed, pp_final, rg, fin, _] = means(rows);
    println!(
        "mean          | {f_c1:.4} {f_c2:.4} {f_final:.4} | {pp_c2:.4} {pp_c2_relaxed:.4}  {pp_final:.4} | {rg:.2} {fin:.2}"
    );
    let h = |m: usize, k: usize| mean(rows.iter().map(|r| f64::from(r.hoover[m][k])));
    println!("Hoover T = 0.8, mean per image (correct / over / under):");
    for (m, name) in ["region growing", "final, components", "final, regions"].iter().enumerate() {
        println!("  {name:<18} {:.2} / {:.2} / {:.2}", h(m, 0), h(m, 1), h(m, 2));
    }
}

fn main() -> Result<()> {
    let args = parse_args()?;
    let only: Option<u32> = match std::env::var("ONLY") {
        Ok(v) => Some(v.parse().with_context(|| format!("ONLY={v:?}: not an image index"))?),
        Err(_) => None,
    };
    let images: Vec<Prepared> = (0..10u32)
        .filter(|i| only.is_none_or(|o| o == *i))
        .collect::<Vec<_>>()
        .into_par_iter()
        .map(|i| prepare(i, args.use_k))
        .collect();
    println!("s1 = {}", if args.use_k { "|K|" } else { "curvedness" });
    if args.tune {
        tune(&images, &args);
        return Ok(());
    }
    let (params, sp) = (&args.params, &args.sp);
    println!("relax params: {params:?}\nsegment params: {sp:?}");
    let rows: Vec<Row> = images.par_iter().map(|im| evaluate(im, params, sp, args.seg_supported)).collect();
    report(&images, &rows);
    Ok(())
}
