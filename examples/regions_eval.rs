//! Hoover scores (T = 0.8) of `regiongrow` on the synthetic ABW-like benchmark, with an optional
//! small parameter grid tuned on the training split.
//!
//! `cargo run --release --example regions_eval -- --split train|test [--mode paper|default] [--tune]
//! [--data DIR] [--seed N]`. `--tune` sweeps the grid on the training split only, then scores the
//! chosen parameters on `--split`.

use anyhow::{Context, bail};
use rangeimage::{Camera, LabelImage, RangeImage, SurfaceFeatures};
use rayon::prelude::*;
use regiongrow::{Mode, Params};
use std::io::Write;
use std::path::PathBuf;

/// One image with its features and ground truth.
struct Item {
    stem: String,
    range: RangeImage,
    features: SurfaceFeatures,
    camera: Camera,
    gt: LabelImage,
}

/// Mean Hoover counts per image.
#[derive(Debug, Default, Clone, Copy)]
struct Mean {
    gt: f64,
    correct: f64,
    over: f64,
    under: f64,
    missed: f64,
    noise: f64,
    ms: f64,
}

impl Mean {
    /// Objective for tuning: correct detections minus over/under-segmentations and noise.
    fn objective(&self) -> f64 {
        self.correct - 0.5 * (self.over + self.under) - 0.25 * self.noise
    }
}

fn load(dir: &std::path::Path, test: bool) -> anyhow::Result<Vec<Item>> {
    let ds = rangeio::abw::Dataset::discover(dir)?;
    let imgs = if test { ds.test } else { ds.train };
    if imgs.is_empty() {
        bail!(
            "{}: no {} images (run `cargo xtask gen-data`)",
            dir.display(),
            if test { "test" } else { "train" }
        );
    }
    let fp = features::Params::default();
    imgs.par_iter()
        .map(|im| {
            let range = rangeio::abw::read_range(&im.range)?;
            let gt_path = im.gt_seg.as_ref().with_context(|| format!("{}: no .gt-seg", im.stem))?;
            let gt = rangeio::abw::read_labels(gt_path, false)?;
            let features = features::compute(&range, &fp);
            Ok(Item { stem: im.stem.clone(), range, features, camera: im.camera, gt })
        })
        .collect()
}

fn score(items: &[Item], params: &Params, seed: u64) -> (Mean, Vec<eval::HooverScore>) {
    let scores: Vec<eval::HooverScore> = items
        .par_iter()
        .map(|it| {
            let (seg, _) = regiongrow::grow(&it.range, &it.features, &it.camera, params, seed);
            eval::hoover::compare_with(
                &it.gt,
                &seg.labels,
                0.8,
                None,
                None,
                eval::hoover::Convention::NonZero,
            )
        })
        .collect();
    let n = scores.len() as f64;
    let mut m = Mean::default();
    for s in &scores {
        m.gt += f64::from(s.gt_regions) / n;
        m.ms += f64::from(s.seg_regions) / n;
        m.correct += f64::from(s.correct) / n;
        m.over += f64::from(s.over) / n;
        m.under += f64::from(s.under) / n;
        m.missed += f64::from(s.missed) / n;
        m.noise += f64::from(s.noise) / n;
    }
    (m, scores)
}

/// The small tuning grid of each mode, applied on top of the mode's base parameters.
fn grid(mode: Mode) -> Vec<Params> {
    let mut out = Vec::new();
    match mode {
        Mode::Default => {
            for max_angle_deg in [10.0, 15.0, 20.0] {
                for max_residual in [2.0, 3.0, 4.5] {
                    for min_region_px in [50, 100, 200] {
                        for max_curvedness in [0.3, 1.0] {
                            out.push(Params {
                                max_angle_deg,
                                max_residual,
                                fill_max_residual: max_residual,
                                min_region_px,
                                max_curvedness,
                                ..Params::default()
                            });
                        }
                    }
                }
            }
        }
        Mode::Paper => {
            for max_k_diff in [0.001, 0.003, 0.01, 0.03] {
                for t_m in [0.003, 0.02] {
                    for t_sigma in [0.005, 0.02] {
                        for min_region_px in [50, 200] {
                            out.push(Params { max_k_diff, t_m, t_sigma, min_region_px, ..Params::paper() });
                        }
                    }
                }
            }
        }
    }
    out
}

/// Training split only: every GT region with its best-overlapping MS region and the overlap
/// fractions (of the GT region, of the MS region), flagged when under T = 0.8.
fn missed_report(out: &mut impl Write, it: &Item, seg: &LabelImage) -> anyhow::Result<()> {
    use std::collections::BTreeMap;
    let mut gt_size: BTreeMap<u32, u64> = BTreeMap::new();
    let mut ms_size: BTreeMap<u32, u64> = BTreeMap::new();
    let mut pair: BTreeMap<(u32, u32), u64> = BTreeMap::new();
    for (&g, &m) in it.gt.as_slice().iter().zip(seg.as_slice()) {
        *ms_size.entry(m).or_default() += 1;
        if g == 0 {
            continue;
        }
        *gt_size.entry(g).or_default() += 1;
        *pair.entry((g, m)).or_default() += 1;
    }
    for (&g, &gs) in &gt_size {
        let (m, o) = pair
            .range((g, 0)..=(g, u32::MAX))
            .filter(|((_, m), _)| *m != 0)
            .max_by_key(|(_, o)| **o)
            .map(|((_, m), o)| (*m, *o))
            .unwrap_or((0, 0));
        let unl = pair.get(&(g, 0)).copied().unwrap_or(0);
        let ms = ms_size.get(&m).copied().unwrap_or(0).max(1);
        let (fg, fm) = (o as f64 / gs as f64, o as f64 / ms as f64);
        if fg < 0.8 || fm < 0.8 {
            writeln!(
                out,
                "  {} gt {g:>3} size {gs:>6} best ms {m:>3} size {ms:>6} overlap/gt {fg:.2} overlap/ms {fm:.2} unlabelled/gt {:.2}",
                it.stem,
                unl as f64 / gs as f64
            )?;
        }
    }
    Ok(())
}

/// The command line.
struct Args {
    split: String,
    test: bool,
    mode: Mode,
    tune: bool,
    seed: u64,
    data: PathBuf,
}

fn parse_args() -> anyhow::Result<Args> {
    let mut split = String::from("train");
    let mut mode = Mode::Default;
    let mut tune = false;
    let mut seed = 0u64;
    let mut data = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("data/synthetic-abw");
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        match a.as_str() {
            "--split" => split = args.next().context("--split needs train|test")?,
            "--mode" => {
                mode = match args.next().as_deref() {
                    Some("paper") => Mode::Paper,
                    Some("default") => Mode::Default,
                    other => bail!("--mode paper|default, got {other:?}"),
                }
            }
            "--tune" => tune = true,
            "--seed" => seed = args.next().context("--seed N")?.parse()?,
            "--data" => data = args.next().context("--data DIR")?.into(),
            _ => bail!(
                "usage: regions_eval --split train|test [--mode paper|default] [--tune] [--data DIR] [--seed N]"
            ),
        }
    }
    let test = match split.as_str() {
        "train" => false,
        "test" => true,
        _ => bail!("--split train|test"),
    };
    Ok(Args { split, test, mode, tune, seed, data })
}

/// The parameters to score: tuned on the training split (`--tune`), the mode's base parameters with the
/// overrides of `REGIONS_EVAL_PARAMS`, or the base parameters.
fn choose_params(out: &mut impl Write, args: &Args) -> anyhow::Result<Params> {
    let base = if args.mode == Mode::Paper { Params::paper() } else { Params::default() };
    if args.tune {
        let train = load(&args.data, false)?;
        let mut best: Option<(f64, Params, Mean)> = None;
        for p in grid(args.mode) {
            let (m, _) = score(&train, &p, args.seed);
            let better = best.as_ref().is_none_or(|b| m.objective() > b.0);
            if better {
                writeln!(
                    out,
                    "train: objective {:.3} correct {:.2} over {:.2} under {:.2} noise {:.2} with {p:?}",
                    m.objective(),
                    m.correct,
                    m.over,
                    m.under,
                    m.noise
                )?;
                best = Some((m.objective(), p, m));
            }
        }
        let (_, p, _) = best.context("empty grid")?;
        writeln!(out, "chosen on train:\n{}", toml::to_string(&p)?)?;
        Ok(p)
    } else if let Some(extra) = std::env::var_os("REGIONS_EVAL_PARAMS") {
        // Overrides as a TOML table body, e.g. "seed_radius_px = 1" (exploration on train).
        let mut t: toml::Table = toml::from_str(&toml::to_string(&base)?)?;
        t.extend(toml::from_str::<toml::Table>(&extra.to_string_lossy())?);
        let p: Params = t.try_into()?;
        writeln!(out, "params: {p:?}")?;
        Ok(p)
    } else {
        Ok(base)
    }
}

/// Times `grow` on each image, one thread (measurement only); with `diag`, prints each image's `Info`.
fn time_grow(
    out: &mut impl Write,
    items: &[Item],
    params: &Params,
    seed: u64,
    diag: bool,
) -> anyhow::Result<()> {
    let mut fastest = std::time::Duration::MAX;
    let mut total = std::time::Duration::ZERO;
    for it in items {
        let t0 = std::time::Instant::now();
        let (_, info) = regiongrow::grow(&it.range, &it.features, &it.camera, params, seed);
        let dt = t0.elapsed();
        fastest = fastest.min(dt);
        total += dt;
        if diag {
            writeln!(out, "{} {info:?} {dt:.2?}", it.stem)?;
        }
    }
    writeln!(
        out,
        "grow, one thread: mean {:.2?}, fastest {fastest:.2?} per image",
        total / items.len() as u32
    )?;
    Ok(())
}

fn main() -> anyhow::Result<()> {
    let args = parse_args()?;
    let (test, mode, seed) = (args.test, args.mode, args.seed);
    let mut out = std::io::stdout().lock();
    let diag = std::env::var_os("REGIONS_EVAL_DIAG").is_some();
    let params = choose_params(&mut out, &args)?;
    let items = load(&args.data, test)?;
    time_grow(&mut out, &items, &params, seed, diag)?;
    if diag && !test {
        for it in &items {
            let (seg, _) = regiongrow::grow(&it.range, &it.features, &it.camera, &params, seed);
            missed_report(&mut out, it, &seg.labels)?;
        }
    }
    let t0 = std::time::Instant::now();
    let (m, scores) = score(&items, &params, seed);
    let dt = t0.elapsed();
    for (it, s) in items.iter().zip(&scores) {
        writeln!(
            out,
            "{:<14} gt {:>3} ms {:>3} correct {:>3} over {:>2} under {:>2} missed {:>3} noise {:>3}",
            it.stem, s.gt_regions, s.seg_regions, s.correct, s.over, s.under, s.missed, s.noise
        )?;
    }
    writeln!(
        out,
        "\n{} split, mode {mode:?}, {} images, T = 0.8, seed {seed} (grow+score {dt:.2?})",
        args.split,
        items.len()
    )?;
    writeln!(
        out,
        "| mean per image | GT regions | MS regions | correct | over | under | missed | noise | correct/GT |"
    )?;
    writeln!(out, "|---|---|---|---|---|---|---|---|---|")?;
    writeln!(
        out,
        "| {mode:?} | {:.2} | {:.2} | {:.2} | {:.2} | {:.2} | {:.2} | {:.2} | {:.1}% |",
        m.gt,
        m.ms,
        m.correct,
        m.over,
        m.under,
        m.missed,
        m.noise,
        100.0 * m.correct / m.gt.max(1e-9)
    )?;
    Ok(())
}
