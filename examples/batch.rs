//! Batch throughput of the whole method in memory on a folder of range images, one `Segmenter` per rayon worker
//! thread for the whole run.
//!
//! `cargo run --release --example batch -- [DIR] [ROUNDS]` (default `data/synthetic-abw`, 3 rounds): reads every
//! `*.range` of DIR, runs one untimed round on each pool (1 and 2 threads), then alternates rounds on 1 thread and
//! on 2 threads and prints each round's images per second and the best 2-thread / 1-thread ratio.
#![allow(clippy::print_stdout)]

use rayon::prelude::*;
use std::time::Instant;

fn main() -> anyhow::Result<()> {
    let mut args = std::env::args().skip(1);
    let dir = args.next().unwrap_or_else(|| "data/synthetic-abw".into());
    let rounds: usize = args.next().map(|s| s.parse()).transpose()?.unwrap_or(3);
    let mut paths: Vec<_> = std::fs::read_dir(&dir)?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|e| e == "range"))
        .collect();
    paths.sort();
    let frames =
        paths.iter().map(|p| rangeio::read(p, &Default::default())).collect::<Result<Vec<_>, _>>()?;
    let config = rangeseg::Config::default();
    // One pool per thread count and one `Segmenter` per worker thread, kept for every round: a frame reuses the
    // buffers of its thread's previous frame, as in a long batch.
    let pools = [1, 2].map(|threads| -> anyhow::Result<_> {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build()?;
        let segs = rangeseg::pipeline::Segmenters::new(&config, threads);
        Ok((pool, segs))
    });
    let [p1, p2] = pools;
    let (p1, p2) = (p1?, p2?);
    let run = |(pool, segs): &(rayon::ThreadPool, rangeseg::pipeline::Segmenters)| -> f64 {
        let t = Instant::now();
        let regions: usize = pool.install(|| {
            frames
                .par_iter()
                .map(|f| segs.with(|seg| seg.segment(&f.range, &f.camera).fin.final_regions.len()))
                .sum()
        });
        std::hint::black_box(regions);
        frames.len() as f64 / t.elapsed().as_secs_f64()
    };
    // A first, untimed round on each pool allocates every worker's buffers.
    std::hint::black_box((run(&p1), run(&p2)));
    println!("{} images of {dir}, images per second:", frames.len());
    let (mut best1, mut best2) = (0.0f64, 0.0f64);
    for r in 0..rounds {
        let (one, two) = (run(&p1), run(&p2));
        println!("round {r}: 1 thread {one:.1}, 2 threads {two:.1} ({:.2}×)", two / one);
        (best1, best2) = (best1.max(one), best2.max(two));
    }
    println!("best: 1 thread {best1:.1}, 2 threads {best2:.1} ({:.2}×)", best2 / best1);
    Ok(())
}
