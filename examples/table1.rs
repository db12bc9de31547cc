//! Table I analogue: Canny on raw depth vs Canny on plane parameters, boundary P/R/F against ground truth.
//!
//! `cargo run --release --example table1 -- [--split train|test] [--tune] [--dir data/synthetic-abw]`
//!
//! With `--tune`, thresholds (and the plane channel weights) are chosen by a small grid search maximising the mean
//! one-to-one F on the training split only, then applied to the requested split. Without it, the plane detector
//! and the raw detector use `configs/default.toml`'s `[vcanny]` and `[raw_canny]` (`rangeseg::Config::default()`).
#![allow(clippy::print_stdout)]

use anyhow::Context;
use rangeimage::{EdgeMap, LabelImage, PlaneMap, RangeImage};
use rayon::prelude::*;
use std::path::PathBuf;
use vcanny::{Params, ThresholdMode, Thresholds};

const TAU_PX: f64 = 2.0;

struct Image {
    stem: String,
    range: RangeImage,
    plane: PlaneMap,
    valid: rangeimage::Grid<bool>,
    gt: LabelImage,
}

fn load(list: &[rangeio::abw::AbwImage]) -> anyhow::Result<Vec<Image>> {
    list.par_iter()
        .map(|a| {
            let range = rangeio::abw::read_range(&a.range)?;
            let gt_path = a.gt_seg.as_ref().with_context(|| format!("{}: no .gt-seg", a.stem))?;
            let gt = rangeio::abw::read_labels(gt_path, false)?;
            let plane = features::fit_planes(&range, 5);
            let valid = rangeimage::valid_mask(&range);
            Ok(Image { stem: a.stem.clone(), range, plane, valid, gt })
        })
        .collect()
}

fn detect(img: &Image, p: &Params, raw: bool) -> EdgeMap {
    if raw {
        vcanny::detect_raw(&img.range, p).edges
    } else {
        vcanny::detect_planes(&img.plane, &img.valid, p).edges
    }
}

/// (one-to-one, simple) P/R/F per image.
fn score(imgs: &[Image], p: &Params, raw: bool) -> Vec<(eval::boundary::Prf, eval::boundary::Prf)> {
    imgs.par_iter()
        .map(|img| {
            let e = detect(img, p, raw);
            (eval::boundary::matched(&e, &img.gt, TAU_PX), eval::boundary::simple(&e, &img.gt, TAU_PX))
        })
        .collect()
}

fn mean_f(s: &[(eval::boundary::Prf, eval::boundary::Prf)]) -> f64 {
    s.iter().map(|(m, _)| m.f).sum::<f64>() / s.len().max(1) as f64
}

fn with(base: &Params, mode: ThresholdMode, low: f32, high: f32, weights: [f32; 3]) -> Params {
    Params { weights, thresholds: Thresholds { mode, low, high, ..base.thresholds.clone() }, ..base.clone() }
}

fn tune(train: &[Image], raw: bool) -> Params {
    let base = Params::default();
    let mut grid = Vec::new();
    if raw {
        for (lo, hi) in [(0.8, 0.95), (0.9, 0.97), (0.95, 0.99), (0.97, 0.995)] {
            grid.push(with(&base, ThresholdMode::Quantile, lo, hi, [1.0; 3]));
        }
        for (lo, hi) in [(1.0, 2.0), (1.5, 3.0), (2.0, 4.0), (3.0, 6.0), (5.0, 10.0)] {
            grid.push(with(&base, ThresholdMode::Absolute, lo, hi, [1.0; 3]));
        }
        for (lo, hi) in [(2.0, 4.0), (3.0, 6.0), (4.0, 8.0), (6.0, 12.0)] {
            grid.push(with(&base, ThresholdMode::NoiseRelative, lo, hi, [1.0; 3]));
        }
    } else {
        for c in [0.0, 1e-3] {
            for (lo, hi) in [
                (1.0, 2.0),
                (1.0, 3.0),
                (1.5, 3.0),
                (1.5, 4.0),
                (2.0, 3.0),
                (2.0, 4.0),
                (2.0, 6.0),
                (3.0, 6.0),
            ] {
                grid.push(with(&base, ThresholdMode::NoiseRelative, lo, hi, [1.0, 1.0, c]));
            }
        }
    }
    let mut best = (f64::NEG_INFINITY, base);
    for p in grid {
        let f = mean_f(&score(train, &p, raw));
        if f > best.0 {
            best = (f, p);
        }
    }
    println!(
        "tuned {} on train: mean F (one-to-one) {:.4} with {:?}",
        if raw { "raw" } else { "plane" },
        best.0,
        best.1
    );
    best.1
}

fn main() -> anyhow::Result<()> {
    let mut split = "test".to_string();
    let mut do_tune = false;
    let mut dir = PathBuf::from("data/synthetic-abw");
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        match a.as_str() {
            "--split" => split = args.next().context("--split needs a value")?,
            "--tune" => do_tune = true,
            "--dir" => dir = args.next().context("--dir needs a value")?.into(),
            other => anyhow::bail!(
                "unknown argument {other}; usage: table1 [--split train|test] [--tune] [--dir D]"
            ),
        }
    }
    let ds = rangeio::abw::Dataset::discover(&dir)?;
    let train = load(&ds.train)?;
    let (raw_p, plane_p) = if do_tune {
        (tune(&train, true), tune(&train, false))
    } else {
        {
            let c = rangeseg::Config::default();
            (c.raw_canny.detector(), c.vcanny)
        }
    };
    let imgs = match split.as_str() {
        "train" => train,
        "test" => load(&ds.test)?,
        s => anyhow::bail!("--split must be train or test, got {s}"),
    };

    // Timing of the plane path (one thread, after warm-up) on the first image.
    if let Some(img) = imgs.first() {
        let t = std::time::Instant::now();
        let n = 5;
        for _ in 0..n {
            let pl = features::fit_planes(&img.range, 5);
            std::hint::black_box(vcanny::detect_planes(&pl, &img.valid, &plane_p));
        }
        let t_all = t.elapsed() / n;
        let t = std::time::Instant::now();
        for _ in 0..n {
            std::hint::black_box(vcanny::detect_planes(&img.plane, &img.valid, &plane_p));
        }
        println!(
            "timing on {}: fit_planes + detect_planes {:?}, detect_planes {:?}",
            img.stem,
            t_all,
            t.elapsed() / n
        );
    }

    let raw = score(&imgs, &raw_p, true);
    let plane = score(&imgs, &plane_p, false);
    println!(
        "\n| image | raw P | raw R | raw F | plane P | plane R | plane F | raw F (simple) | plane F (simple) |"
    );
    println!("|---|---|---|---|---|---|---|---|---|");
    for (i, img) in imgs.iter().enumerate() {
        let (r, rs) = raw[i];
        let (p, ps) = plane[i];
        println!(
            "| {} | {:.3} | {:.3} | {:.3} | {:.3} | {:.3} | {:.3} | {:.3} | {:.3} |",
            img.stem, r.precision, r.recall, r.f, p.precision, p.recall, p.f, rs.f, ps.f
        );
    }
    let stats = |v: &[(eval::boundary::Prf, eval::boundary::Prf)], simple: bool| {
        let n = v.len().max(1) as f64;
        let pick = |i: usize| {
            let xs: Vec<f64> = v
                .iter()
                .map(|(m, s)| {
                    let q = if simple { s } else { m };
                    [q.precision, q.recall, q.f][i]
                })
                .collect();
            let mean = xs.iter().sum::<f64>() / n;
            let sd = (xs.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / n).sqrt();
            format!("{mean:.4} ± {sd:.4}")
        };
        format!("P {} | R {} | F {}", pick(0), pick(1), pick(2))
    };
    println!("\nsplit {split}, {} images, τ = {TAU_PX} px", imgs.len());
    println!("raw   (one-to-one): {}", stats(&raw, false));
    println!("plane (one-to-one): {}", stats(&plane, false));
    println!("raw   (simple):     {}", stats(&raw, true));
    println!("plane (simple):     {}", stats(&plane, true));
    println!("raw params:   {raw_p:?}\nplane params: {plane_p:?}");
    Ok(())
}
