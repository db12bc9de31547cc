//! `rangeseg segment`: the whole pipeline on files or directories, several images at once as memory allows.

use anyhow::{Context, Result, bail};
use indicatif::{ProgressBar, ProgressStyle};
use rangeseg::Config;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Condvar, Mutex};
use std::time::Instant;

/// Arguments of `rangeseg segment`.
#[derive(Debug, clap::Args)]
pub(crate) struct Args {
    /// Range files, or directories whose range files are all processed (our own outputs
    /// `*.c1.png`, `*.c2.png`, `*.edges.png`, `*.regions.png`, `*.labels.png` inside them are skipped).
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
    /// Images processed at once, at most [default: RAYON_NUM_THREADS if set, else the number of CPUs];
    /// fewer run together when their estimated peak memory does not fit (see README, Limits).
    #[arg(short, long, value_name = "N")]
    jobs: Option<usize>,
    /// Memory the images in flight may use together, in MiB [default: 3/4 of MemAvailable, else 4096].
    #[arg(long, value_name = "MIB")]
    memory_mib: Option<u64>,
    /// The files to write besides `NAME.json`, comma-separated: ms-seg (also `.ms-nor` and `.labels.png`),
    /// edges, c1, c2, regions, planes, or all.
    #[arg(long, value_name = "LIST", default_value = "all", value_parser = rangeseg::OutputSet::parse)]
    outputs: rangeseg::OutputSet,
}

/// File extensions `segment` picks up inside a directory.
const RANGE_EXTENSIONS: &[&str] = &["range", "png", "pgm", "tif", "tiff", "pcd"];

/// Name endings of the PNGs `segment` and `regions` write; skipped when listing a directory, so
/// `segment DIR -o DIR` run twice does not read its own outputs as inputs.
const OWN_OUTPUTS: &[&str] = &[".c1.png", ".c2.png", ".edges.png", ".regions.png", ".labels.png"];

/// Peak memory of the pipeline per pixel of the input, in bytes, as `segment` reserves it: the peak
/// resident size of `rangeseg segment -j 1` on one image less that of the process on a tiny one, divided by
/// the pixels. Measured 2026-12-04 on ABW rasterfiles of two tilted planes, 512² to 4096², with and without
/// noise: 152 bytes per pixel, 172 where the depth is a staircase that is dequantised (its five extra
/// per-pixel maps); rounded up to 200 for images with more edges and regions than those. (It was 73–74 when
/// first measured, before the stages kept their working buffers from frame to frame.)
pub(crate) const PEAK_BYTES_PER_PIXEL: u64 = 200;

/// The memory budget when `/proc/meminfo` cannot be read: 4 GiB.
const FALLBACK_BUDGET: u64 = 4 << 30;

/// Runs `rangeseg segment`.
pub(crate) fn run(args: Args) -> Result<ExitCode> {
    let mut config = Config::load_or_default(args.config.as_deref())?;
    if let Some(seed) = args.seed {
        config.seed = seed;
    }
    let inputs = expand_inputs(&args.inputs)?;
    check_distinct_stems(&inputs, &args.out)?;
    super::prepare_out_dir(&args.out)?;

    let jobs = args
        .jobs
        .or_else(env_threads)
        .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, std::num::NonZeroUsize::get));
    if jobs == 0 {
        bail!("--jobs must be at least 1");
    }
    let budget = Budget::new(args.memory_mib.map_or_else(memory_budget, |m| m.saturating_mul(1 << 20)));
    tracing::info!(jobs, budget_bytes = budget.total, "segment: scheduling");

    let bar = ProgressBar::new(inputs.len() as u64).with_style(
        ProgressStyle::with_template("{bar:40} {pos}/{len} [{elapsed_precise} < {eta_precise}] {msg}")
            .expect("valid template"),
    );
    let opts = args.read.options();
    let next = AtomicUsize::new(0);
    let results: Mutex<Vec<Option<Result<()>>>> = Mutex::new((0..inputs.len()).map(|_| None).collect());
    std::thread::scope(|s| {
        for _ in 0..jobs.min(inputs.len()) {
            s.spawn(|| {
                // One segmenter per worker: its images reuse the buffers of its previous image.
                let mut seg = rangeseg::pipeline::Segmenter::new(config.clone());
                loop {
                    let i = next.fetch_add(1, Ordering::Relaxed);
                    let Some(input) = inputs.get(i) else { break };
                    let r = segment_one(input, (&args.out, args.outputs), &mut seg, &opts, &budget);
                    results.lock().unwrap_or_else(std::sync::PoisonError::into_inner)[i] = Some(r);
                    bar.inc(1);
                }
            });
        }
    });
    bar.finish_and_clear();

    let results = results.into_inner().unwrap_or_else(std::sync::PoisonError::into_inner);
    let mut failed = 0;
    for r in results {
        if let Some(Err(e)) = r {
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

/// `RAYON_NUM_THREADS`, which set the number of images at once before `--jobs` existed.
fn env_threads() -> Option<usize> {
    std::env::var("RAYON_NUM_THREADS").ok()?.trim().parse().ok().filter(|&n| n > 0)
}

/// Files named directly, plus the range files inside named directories (sorted, our own outputs skipped).
fn expand_inputs(inputs: &[PathBuf]) -> Result<Vec<PathBuf>> {
    let mut out = Vec::new();
    for input in inputs {
        if input.is_dir() {
            let mut found: Vec<PathBuf> = std::fs::read_dir(input)
                .with_context(|| format!("{}: cannot list directory", input.display()))?
                .filter_map(|e| e.ok().map(|e| e.path()))
                .filter(|p| p.is_file() && is_range_file(p) && !is_own_output(p))
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

fn is_range_file(p: &Path) -> bool {
    p.extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| RANGE_EXTENSIONS.contains(&e.to_ascii_lowercase().as_str()))
}

/// A PNG whose name ends like one `segment` writes (`NAME.c1.png`, …).
fn is_own_output(p: &Path) -> bool {
    let name = p.file_name().map(|n| n.to_string_lossy().to_ascii_lowercase()).unwrap_or_default();
    OWN_OUTPUTS.iter().any(|suffix| name.ends_with(suffix))
}

/// Refuses inputs whose outputs would share names (same stem), naming both, before any work.
fn check_distinct_stems(inputs: &[PathBuf], out: &Path) -> Result<()> {
    let mut seen: BTreeMap<String, &PathBuf> = BTreeMap::new();
    for input in inputs {
        let stem = stem_of(input);
        if let Some(first) = seen.insert(stem.clone(), input) {
            bail!(
                "{} and {} would both write {}: {stem}.* (outputs are named by the file name without its \
                 extension); rename one or segment them into different output folders",
                first.display(),
                input.display(),
                out.join(format!("{stem}.ms-seg")).display(),
            );
        }
    }
    Ok(())
}

/// The output stem: the file name without its last extension (`abw.test.7.range` → `abw.test.7`).
pub(crate) fn stem_of(path: &Path) -> String {
    path.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_else(|| "out".into())
}

/// The memory budget: 3/4 of `MemAvailable` in `/proc/meminfo`, else [`FALLBACK_BUDGET`].
fn memory_budget() -> u64 {
    let available = std::fs::read_to_string("/proc/meminfo").ok().and_then(|text| {
        let line = text.lines().find(|l| l.starts_with("MemAvailable:"))?;
        let kib: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
        Some(kib.saturating_mul(1024))
    });
    available.map_or(FALLBACK_BUDGET, |b| b / 4 * 3)
}

/// Bytes of memory that images in flight may reserve together.
struct Budget {
    total: u64,
    free: Mutex<u64>,
    freed: Condvar,
}

impl Budget {
    fn new(total: u64) -> Self {
        Self { total, free: Mutex::new(total), freed: Condvar::new() }
    }

    /// Waits until `bytes` (at most the whole budget, so one image always runs alone) are free and takes them.
    fn acquire(&self, bytes: u64) -> Reservation<'_> {
        let bytes = bytes.min(self.total);
        let mut free = self.free.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
        while *free < bytes {
            free = self.freed.wait(free).unwrap_or_else(std::sync::PoisonError::into_inner);
        }
        *free -= bytes;
        Reservation { budget: self, bytes }
    }
}

/// Memory taken from a [`Budget`], given back on drop.
struct Reservation<'a> {
    budget: &'a Budget,
    bytes: u64,
}

impl Drop for Reservation<'_> {
    fn drop(&mut self) {
        *self.budget.free.lock().unwrap_or_else(std::sync::PoisonError::into_inner) += self.bytes;
        self.budget.freed.notify_all();
    }
}

fn segment_one(
    input: &Path,
    (out, which): (&Path, rangeseg::OutputSet),
    seg: &mut rangeseg::pipeline::Segmenter,
    opts: &rangeio::ReadOptions,
    budget: &Budget,
) -> Result<()> {
    let t_total = Instant::now();
    let t = Instant::now();
    let frame = rangeio::read(input, opts)?;
    let t_read = t.elapsed().as_secs_f64() * 1e3;

    let need = PEAK_BYTES_PER_PIXEL.saturating_mul(frame.range.len() as u64);
    if need > budget.total {
        tracing::warn!(
            "{}: needs about {} MiB at its peak, more than the memory budget of {} MiB; running it alone",
            input.display(),
            need >> 20,
            budget.total >> 20
        );
    }
    let _reserved = budget.acquire(need);
    let result = seg.segment(&frame.range, &frame.camera);

    let t = Instant::now();
    let stem = stem_of(input);
    // The JSON is the mark of a complete set: remove a previous run's before writing anything.
    let json_path = out.join(format!("{stem}.json"));
    match std::fs::remove_file(&json_path) {
        Err(e) if e.kind() != std::io::ErrorKind::NotFound => {
            return Err(e)
                .with_context(|| format!("{}: cannot remove the previous run's file", json_path.display()));
        }
        _ => {}
    }
    let summary = rangeseg::write_selected_outputs(out, &stem, &frame, result, which)?;
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
    // Written last: its presence means every output of this image is complete.
    rangeio::write_atomic(&json_path, text.as_bytes())?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn budget_runs_an_oversized_image_alone_and_gives_memory_back() {
        let b = Budget::new(100);
        {
            let r = b.acquire(1000);
            assert_eq!(r.bytes, 100, "capped at the whole budget");
            assert_eq!(*b.free.lock().unwrap(), 0);
        }
        assert_eq!(*b.free.lock().unwrap(), 100);
        let (a, c) = (b.acquire(60), b.acquire(40));
        assert_eq!(*b.free.lock().unwrap(), 0);
        drop((a, c));
        assert_eq!(*b.free.lock().unwrap(), 100);
    }

    #[test]
    fn same_stems_are_refused_naming_both_paths() {
        let inputs = [PathBuf::from("in/d1/x.range"), PathBuf::from("y.png"), PathBuf::from("in/d2/x.range")];
        let e = check_distinct_stems(&inputs, Path::new("o")).unwrap_err().to_string();
        assert!(e.contains("in/d1/x.range") && e.contains("in/d2/x.range"), "{e}");
        assert!(check_distinct_stems(&inputs[..2], Path::new("o")).is_ok());
    }

    #[test]
    fn own_outputs_are_recognised() {
        for own in ["a.c1.png", "a.C2.PNG", "x.edges.png", "x.regions.png", "x.labels.png"] {
            assert!(is_own_output(Path::new(own)), "{own}");
        }
        for input in ["a.png", "abw.test.1.range", "edges.png", "c1.png.range"] {
            assert!(!is_own_output(Path::new(input)), "{input}");
        }
    }
}
