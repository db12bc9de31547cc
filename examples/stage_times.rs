//! Per-stage times of the pipeline on a stream of frames, as the eval report sees them, in wall-clock time and in
//! time on the CPU (which leaves out the time other processes of a busy machine take the core).
//!
//! `cargo run --release --example stage_times -- FILE [N] [oneshot] [CONFIG.toml]`: segments FILE N times (default
//! 30) on one thread with the default configuration (or CONFIG.toml, e.g. `configs/fast.toml`), by default with one
//! `Segmenter` for all frames (`oneshot`: `rangeseg::segment` per frame), and prints the
//! fastest and median wall-clock time of each stage (`rangeseg::pipeline::StageTimings`), of the whole frame
//! (depth → labels + planes) and the frame's time on the CPU (Linux: `/proc/thread-self/schedstat`).
#![allow(clippy::print_stdout)]

use anyhow::Context;
use std::time::Instant;

/// Nanoseconds this thread has run on a CPU (Linux), or `None`.
fn cpu_ns() -> Option<f64> {
    let s = std::fs::read_to_string("/proc/thread-self/schedstat").ok()?;
    s.split_whitespace().next()?.parse::<f64>().ok()
}

fn main() -> anyhow::Result<()> {
    let mut args = std::env::args().skip(1);
    let path = args.next().context("usage: stage_times FILE [N] [oneshot] [CONFIG.toml]")?;
    let n: usize = args.next().map(|s| s.parse()).transpose()?.unwrap_or(30);
    let rest: Vec<String> = args.collect();
    let oneshot = rest.iter().any(|a| a == "oneshot");
    let frame = rangeio::read(std::path::Path::new(&path), &Default::default())?;
    let config = match rest.iter().find(|a| a.ends_with(".toml")) {
        Some(c) => rangeseg::Config::load(std::path::Path::new(c))?,
        None => rangeseg::Config::default(),
    };
    let mut seg = rangeseg::pipeline::Segmenter::new(config.clone());
    let mut rows: Vec<[f64; 6]> = Vec::with_capacity(n);
    for _ in 0..n {
        let (t, c) = (Instant::now(), cpu_ns());
        let s = if oneshot {
            let out = rangeseg::segment(&frame.range, &frame.camera, &config);
            std::hint::black_box(rangeseg::planes(&frame.range, &out.fin.labels, &frame.camera));
            out.timings
        } else {
            let out = seg.segment(&frame.range, &frame.camera);
            std::hint::black_box(rangeseg::planes(&frame.range, &out.fin.labels, &frame.camera));
            out.timings
        };
        let total = t.elapsed().as_secs_f64() * 1e3;
        let cpu = match (c, cpu_ns()) {
            (Some(a), Some(b)) => (b - a) / 1e6,
            _ => f64::NAN,
        };
        rows.push([s.features, s.regiongrow, s.vcanny, s.relax, total, cpu]);
    }
    let mode = if oneshot { "segment() per frame" } else { "one Segmenter" };
    println!("{path}: {n} frames, {mode}, ms (fastest / median)");
    let names = ["features", "regiongrow", "vcanny", "relax+final", "total", "total on CPU"];
    for (i, name) in names.iter().enumerate() {
        let mut v: Vec<f64> = rows.iter().map(|r| r[i]).collect();
        v.sort_by(f64::total_cmp);
        println!("{name:>12}: {:6.2} / {:6.2}", v[0], v[v.len() / 2]);
    }
    Ok(())
}
