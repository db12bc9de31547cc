//! `rangeseg segment`: the whole pipeline on files or directories, in parallel.

use anyhow::{Context, Result};
use indicatif::{ProgressBar, ProgressStyle};
use rangeseg::Config;
use rayon::prelude::*;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Instant;

/// Arguments of `rangeseg segment`.
#[derive(Debug, clap::Args)]
pub(crate) struct Args {
    /// Range files, or directories whose range files are all processed.
    #[arg(required = true)]
    inputs: Vec<PathBuf>,
    /// Output directory (created if missing).
    #[arg(short, long)]
    out: PathBuf,
    /// Configuration file (default: the built-in defaults, as in configs/default.toml).
    #[arg(long)]
    config: Option<PathBuf>,
    #[command(flatten)]
    read: super::info::ReadArgs,
    /// Seed (overrides the configuration's).
    #[arg(long)]
    seed: Option<u64>,
}

/// File extensions `segment` picks up inside a directory.
const RANGE_EXTENSIONS: &[&str] = &["range", "png", "pgm", "tif", "tiff", "pcd"];

/// Runs `rangeseg segment`.
pub(crate) fn run(args: Args) -> Result<ExitCode> {
    let mut config = Config::load_or_default(args.config.as_deref())?;
    if let Some(seed) = args.seed {
        config.seed = seed;
    }
    let inputs = expand_inputs(&args.inputs)?;
    std::fs::create_dir_all(&args.out).with_context(|| format!("{}: cannot create", args.out.display()))?;

    let bar = ProgressBar::new(inputs.len() as u64).with_style(
        ProgressStyle::with_template("{bar:40} {pos}/{len} [{elapsed_precise} < {eta_precise}] {msg}")
            .expect("valid template"),
    );
    let results: Vec<Result<()>> = inputs
        .par_iter()
        .map(|input| {
            let r = segment_one(input, &args.out, &config, &args.read.options());
            bar.inc(1);
            r
        })
        .collect();
    bar.finish_and_clear();

    let mut failed = 0;
    for r in &results {
        if let Err(e) = r {
            eprintln!("error: {e:#}");
            failed += 1;
        }
    }
    if failed > 0 {
        eprintln!("{failed} of {} inputs failed", inputs.len());
        return Ok(ExitCode::FAILURE);
    }
    Ok(ExitCode::SUCCESS)
}

/// Files named directly, plus the range files inside named directories (sorted).
fn expand_inputs(inputs: &[PathBuf]) -> Result<Vec<PathBuf>> {
    let mut out = Vec::new();
    for input in inputs {
        if input.is_dir() {
            let mut found: Vec<PathBuf> = std::fs::read_dir(input)
                .with_context(|| format!("{}: cannot list directory", input.display()))?
                .filter_map(|e| e.ok().map(|e| e.path()))
                .filter(|p| {
                    p.is_file()
                        && p.extension()
                            .and_then(|e| e.to_str())
                            .is_some_and(|e| RANGE_EXTENSIONS.contains(&e.to_ascii_lowercase().as_str()))
                })
                .collect();
            found.sort();
            if found.is_empty() {
                anyhow::bail!("{}: no range files in directory", input.display());
            }
            out.extend(found);
        } else {
            out.push(input.clone());
        }
    }
    Ok(out)
}

/// The output stem: the file name without its last extension (`abw.test.7.range` → `abw.test.7`).
pub(crate) fn stem_of(path: &Path) -> String {
    path.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_else(|| "out".into())
}

fn segment_one(input: &Path, out: &Path, config: &Config, opts: &rangeio::ReadOptions) -> Result<()> {
    let t_total = Instant::now();
    let t = Instant::now();
    let frame = rangeio::read(input, opts)?;
    let t_read = t.elapsed().as_secs_f64() * 1e3;

    let result = rangeseg::segment(&frame.range, &frame.camera, config);

    let t = Instant::now();
    let stem = stem_of(input);
    let summary = rangeseg::write_outputs(out, &stem, &frame, &result)?;
    let t_write = t.elapsed().as_secs_f64() * 1e3;
    let total = t_total.elapsed().as_secs_f64() * 1e3;

    let mut json = summary;
    json["input"] = input.display().to_string().into();
    json["timings_ms"] = serde_json::json!({
        "read": t_read,
        "features": result.timings.features,
        "regiongrow": result.timings.regiongrow,
        "vcanny": result.timings.vcanny,
        "relax": result.timings.relax,
        "write": t_write,
        "total": total,
    });
    let text = serde_json::to_string_pretty(&json).expect("json values serialise");
    rangeio::write_atomic(&out.join(format!("{stem}.json")), text.as_bytes())?;
    Ok(())
}
