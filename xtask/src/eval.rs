//! `cargo xtask eval`: the paper's protocol on the test split, and a report people read.

use crate::data::{self, DataSpec, LabelledImage, LoadedImage, Role};
use crate::report::{self, ImageRow, Report};
use anyhow::{Context, Result, bail};
use indicatif::{ProgressBar, ProgressStyle};
use rangeseg::Config;
use rayon::prelude::*;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Options of `cargo xtask eval`.
struct Options {
    config: PathBuf,
    data: DataSpec,
    out: PathBuf,
    /// Runs with the seeds `seed … seed + seeds − 1` (see [`crate::seeds`]).
    seeds: u32,
}

const EVAL_USAGE: &str = "usage: cargo xtask eval [--config C.toml] [--data DIR|synthetic|synthetic:FAMILY[@S] [--camera CAM] [--depth-scale M]] [--out DIR] [--seeds N]";

fn parse(root: &Path, args: &[String]) -> Result<Options> {
    let (mut specs, rest) = data::parse_specs(args)?;
    if specs.len() > 1 {
        bail!("eval reads one data set; run it once per --data\n{EVAL_USAGE}");
    }
    let data = specs.pop().unwrap_or_else(DataSpec::synthetic);
    let mut o =
        Options { config: root.join("configs/default.toml"), data, out: root.join("target/eval"), seeds: 1 };
    let mut it = rest.iter();
    while let Some(a) = it.next() {
        let mut value = || it.next().cloned().with_context(|| format!("{a} needs a value"));
        match a.as_str() {
            "--config" => o.config = value()?.into(),
            "--out" => o.out = value()?.into(),
            "--seeds" => {
                let v = value()?;
                o.seeds = v.parse().ok().filter(|&n| (1..=100).contains(&n)).with_context(|| {
                    format!("--seeds {v}: expected a number of runs from 1 to 100\n{EVAL_USAGE}")
                })?;
            }
            other => bail!("unknown option {other}\n{EVAL_USAGE}"),
        }
    }
    Ok(o)
}

/// Runs `cargo xtask eval`.
pub fn run(root: &Path, args: &[String]) -> Result<()> {
    let started = Instant::now();
    let o = parse(root, args)?;
    let config = Config::load(&o.config)?;
    let set = data::discover(root, &o.data, Role::Eval)?;
    let out_dir = o.out.join("out");
    let fig_dir = o.out.join("figures");
    for d in [&out_dir, &fig_dir] {
        std::fs::create_dir_all(d).with_context(|| format!("{}: cannot create", d.display()))?;
    }
    eprintln!(
        "evaluating {} images ({}) of {} from {} with {}",
        set.images.len(),
        set.selection,
        set.name,
        set.dir.display(),
        o.config.display()
    );
    let bar = ProgressBar::new(set.images.len() as u64).with_style(
        ProgressStyle::with_template("{bar:40} {pos}/{len} [{elapsed_precise} < {eta_precise}]")
            .expect("template"),
    );
    // One segmenter per worker thread for the whole run: its images reuse the buffers of its previous image.
    let segs = rangeseg::pipeline::Segmenters::for_current_pool(&config);
    let rows: Vec<ImageRow> = set
        .images
        .par_iter()
        .map(|img| {
            let r = segs.with(|seg| evaluate_one(img, seg, &out_dir, &fig_dir));
            bar.inc(1);
            r
        })
        .collect::<Result<_>>()?;
    bar.finish_and_clear();

    let report = Report {
        data_name: set.name.clone(),
        data_dir: crate::shown(root, &set.dir),
        selection: set.selection.to_string(),
        camera: set.camera.clone(),
        config_path: crate::shown(root, &o.config),
        config_toml: config.to_toml(),
        rows,
        wall_s: started.elapsed().as_secs_f64(),
        threads: rayon::current_num_threads(),
    };
    report::write_all(&report, &o.out)?;
    eprintln!("{}", report::summary(&report));
    if o.seeds > 1 {
        let mut first = crate::seeds::Totals { seed: config.seed, ..Default::default() };
        for r in &report.rows {
            let s = &r.scores;
            first.add(&s.hoover_final, &s.hoover_regiongrow, &s.jin_final, s.relaxed.matched.f);
        }
        let mut runs = vec![first];
        runs.extend(crate::seeds::other_seeds(&set, &config, o.seeds)?);
        eprintln!("{}", crate::seeds::report(&set.name, &runs, &o.out)?);
    }
    eprintln!("wrote {}", o.out.join("report.html").display());
    Ok(())
}

/// Runs the pipeline on one test image, writes its outputs and figure, and scores it.
fn evaluate_one(
    img: &LabelledImage,
    seg: &mut rangeseg::pipeline::Segmenter,
    out_dir: &Path,
    fig_dir: &Path,
) -> Result<ImageRow> {
    let t = Instant::now();
    let LoadedImage { frame, gt, angles, .. } = img.load()?;
    let read_ms = t.elapsed().as_secs_f64() * 1e3;
    // The image's own noise and quantisation, for the report (not an input of the pipeline).
    let noise = planefit::noise::estimate(&frame.range);

    let t_total = Instant::now();
    let out = seg.segment(&frame.range, &frame.camera);
    let t = Instant::now();
    rangeseg::write_outputs(out_dir, &img.stem, &frame, out)?;
    let write_ms = t.elapsed().as_secs_f64() * 1e3;
    let total_ms = t_total.elapsed().as_secs_f64() * 1e3 + read_ms;

    // The raw-depth baseline of Table I is not part of the pipeline, so it is outside the timings.
    let raw = vcanny::detect_raw(&frame.range, &seg.config().raw_canny.detector());

    let out = seg.output();
    let scores = rangeseg::evaluate::score_image(out, &raw.edges, &gt, &angles);
    let figure = report::figure(&frame.range, &gt, out);
    let fig_path = fig_dir.join(format!("{}.png", img.stem));
    rangeio::png::write_rgb_png(&fig_path, &figure)?;
    Ok(ImageRow {
        stem: img.stem.clone(),
        scores,
        timings: out.timings,
        read_ms,
        write_ms,
        total_ms,
        relax_energy_before: out.fin.relax_info.energy_before,
        relax_energy_after: out.fin.relax_info.energy_after,
        noise_sigma: noise.sigma,
        noise_step: noise.step,
        dequantised: out.dequantised,
        figure: fig_path,
    })
}
