//! Per-stage wall-clock times of the pipeline on a stream of frames, as the eval report sees them.
//!
//! `cargo run --release --example stage_times -- FILE [N]`: segments FILE N times (default 30) on one thread and
//! prints the fastest and median time of each stage (`rangeseg::pipeline::StageTimings`) and of the whole frame.
#![allow(clippy::print_stdout)]

use anyhow::Context;
use std::time::Instant;

fn main() -> anyhow::Result<()> {
    let mut args = std::env::args().skip(1);
    let path = args.next().context("usage: stage_times FILE [N]")?;
    let n: usize = args.next().map(|s| s.parse()).transpose()?.unwrap_or(30);
    let frame = rangeio::read(std::path::Path::new(&path), &Default::default())?;
    let config = rangeseg::Config::default();
    let mut rows: Vec<[f64; 5]> = Vec::with_capacity(n);
    for _ in 0..n {
        let t = Instant::now();
        let out = rangeseg::segment(&frame.range, &frame.camera, &config);
        let planes = rangeseg::planes(&frame.range, &out.fin.labels, &frame.camera);
        let total = t.elapsed().as_secs_f64() * 1e3;
        std::hint::black_box(&planes);
        let s = out.timings;
        rows.push([s.features, s.regiongrow, s.vcanny, s.relax, total]);
    }
    println!("{path}: {n} frames, ms (fastest / median)");
    for (i, name) in ["features", "regiongrow", "vcanny", "relax+final", "total"].iter().enumerate() {
        let mut v: Vec<f64> = rows.iter().map(|r| r[i]).collect();
        v.sort_by(f64::total_cmp);
        println!("{name:>12}: {:6.2} / {:6.2}", v[0], v[v.len() / 2]);
    }
    Ok(())
}
