//! Batch throughput of the whole method in memory on a folder of range images, one `Segmenter` per rayon worker.
//!
//! `cargo run --release --example batch -- [DIR] [ROUNDS]` (default `data/synthetic-abw`, 3 rounds): reads every
//! `*.range` of DIR, then alternates rounds on 1 thread and on 2 threads and prints each round's images per
//! second and the best 2-thread / 1-thread ratio.
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
    let run = |threads: usize| -> anyhow::Result<f64> {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build()?;
        let t = Instant::now();
        let regions: usize = pool.install(|| {
            frames
                .par_iter()
                .map_init(
                    || rangeseg::pipeline::Segmenter::new(config.clone()),
                    |seg, f| seg.segment(&f.range, &f.camera).fin.final_regions.len(),
                )
                .sum()
        });
        std::hint::black_box(regions);
        Ok(frames.len() as f64 / t.elapsed().as_secs_f64())
    };
    println!("{} images of {dir}, images per second:", frames.len());
    let (mut best1, mut best2) = (0.0f64, 0.0f64);
    for r in 0..rounds {
        let one = run(1)?;
        let two = run(2)?;
        println!("round {r}: 1 thread {one:.1}, 2 threads {two:.1} ({:.2}×)", two / one);
        (best1, best2) = (best1.max(one), best2.max(two));
    }
    println!("best: 1 thread {best1:.1}, 2 threads {best2:.1} ({:.2}×)", best2 / best1);
    Ok(())
}
