//! `cargo xtask eval --seeds N`: how much the region counts move with region growing's random seed order.
//!
//! Region growing draws its seeds in a random order (`seed` of the configuration). On the NYU frames one seed's mean
//! correct count lies anywhere in 3.35–3.75 of 7.80, so a change that moves a data set by 0.1 can be noise. With
//! `--seeds N` the evaluation runs again with the seeds `seed + 1 … seed + N − 1` (Hoover at T = 0.8, Jin et al.'s
//! rate and the final edge map's F; no files but `seeds.csv`) and reports the mean and range over all `N`.

use crate::data::DataSet;
use anyhow::{Context, Result};
use eval::{HooverScore, JinScore};
use rangeseg::Config;
use rayon::prelude::*;
use std::fmt::Write as _;
use std::path::Path;

/// The counts of one run, summed over its images.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub(crate) struct Totals {
    /// The seed of the run.
    pub seed: u64,
    /// Images.
    pub images: u32,
    /// GT regions.
    pub gt: u32,
    /// Correct detections of the final segmentation.
    pub correct: u32,
    /// Correct detections of region growing alone.
    pub correct_regiongrow: u32,
    /// Over-segmented GT regions of the final segmentation.
    pub over: u32,
    /// Under-segmenting regions of the final segmentation.
    pub under: u32,
    /// GT planes detected by Jin et al.'s rule (final segmentation).
    pub jin_detected: u32,
    /// Sum over the images of the final edge map's one-to-one F.
    pub f_final: f64,
}

impl Totals {
    /// Adds one image's scores: Hoover of the final segmentation and of region growing alone, Jin of the final one,
    /// the final edge map's F.
    pub(crate) fn add(&mut self, fin: &HooverScore, regiongrow: &HooverScore, jin: &JinScore, f_final: f64) {
        self.images += 1;
        self.gt += fin.gt_regions;
        self.correct += fin.correct;
        self.correct_regiongrow += regiongrow.correct;
        self.over += fin.over;
        self.under += fin.under;
        self.jin_detected += jin.detected;
        self.f_final += f_final;
    }

    /// Per-image means of (correct, region growing alone, over, under), the Jin rate in %, and the mean F.
    fn means(&self) -> [f64; 6] {
        let n = f64::from(self.images.max(1));
        [
            f64::from(self.correct) / n,
            f64::from(self.correct_regiongrow) / n,
            f64::from(self.over) / n,
            f64::from(self.under) / n,
            100.0 * f64::from(self.jin_detected) / f64::from(self.gt.max(1)),
            self.f_final / n,
        ]
    }
}

/// Runs the images of `set` with the seeds `config.seed + 1 … + (n − 1)`, and returns those runs' totals.
pub(crate) fn other_seeds(set: &DataSet, config: &Config, n: u32) -> Result<Vec<Totals>> {
    (1..u64::from(n))
        .map(|k| {
            let mut cfg = config.clone();
            cfg.seed = config.seed.wrapping_add(k);
            let segs = rangeseg::pipeline::Segmenters::for_current_pool(&cfg);
            // Each image is read again for each seed, as the first run reads it: one image in memory per thread.
            let scores: Vec<(HooverScore, HooverScore, JinScore, f64)> = set
                .images
                .par_iter()
                .map(|img| {
                    let img = img.load()?;
                    Ok(segs.with(|seg| {
                        let out = seg.segment(&img.frame.range, &img.frame.camera);
                        let hoover = |l, r| rangeseg::evaluate::hoover(&img.gt, l, r, &img.angles);
                        (
                            hoover(&out.fin.labels, &out.fin.final_regions),
                            hoover(&out.regions.labels, &out.regions.regions),
                            rangeseg::evaluate::jin(&img.gt, &out.fin.labels),
                            rangeseg::evaluate::score_edges(out.fin.edges(), &out.regions.c1, &img.gt)
                                .matched
                                .f,
                        )
                    }))
                })
                .collect::<Result<_>>()?;
            let mut t = Totals { seed: cfg.seed, ..Totals::default() };
            for (fin, rg, jin, f) in &scores {
                t.add(fin, rg, jin, *f);
            }
            Ok(t)
        })
        .collect()
}

/// Writes `seeds.csv` (one row per seed: per-image means) into `out` and returns the terminal line: the mean and
/// the range over the runs of each count.
pub(crate) fn report(name: &str, runs: &[Totals], out: &Path) -> Result<String> {
    let mut csv = String::from("seed,images,correct,correct_regiongrow,over,under,jin_rate_pct,f_final\n");
    for t in runs {
        let [c, rg, o, u, j, f] = t.means();
        writeln!(csv, "{},{},{c:.4},{rg:.4},{o:.4},{u:.4},{j:.2},{f:.4}", t.seed, t.images).expect("string");
    }
    let path = out.join("seeds.csv");
    rangeio::write_atomic(&path, csv.as_bytes())
        .with_context(|| format!("{}: cannot write", path.display()))?;
    let stat = |i: usize| {
        let xs: Vec<f64> = runs.iter().map(|t| t.means()[i]).collect();
        let mean = xs.iter().sum::<f64>() / xs.len().max(1) as f64;
        let (lo, hi) = xs.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &x| (a.min(x), b.max(x)));
        (mean, lo, hi)
    };
    let gt = runs.first().map_or(0.0, |t| f64::from(t.gt) / f64::from(t.images.max(1)));
    let f = |(m, lo, hi): (f64, f64, f64), p: usize| format!("{m:.p$} ({lo:.p$}–{hi:.p$})");
    Ok(format!(
        "{name}, {} seeds ({}–{}): Hoover T=0.8 correct {} of {gt:.2}, region growing alone {}, over {}, under {}, Jin rate {} %, final F {}",
        runs.len(),
        runs.iter().map(|t| t.seed).min().unwrap_or(0),
        runs.iter().map(|t| t.seed).max().unwrap_or(0),
        f(stat(0), 2),
        f(stat(1), 2),
        f(stat(2), 2),
        f(stat(3), 2),
        f(stat(4), 1),
        f(stat(5), 3),
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn hoover(gt: u32, correct: u32, over: u32, under: u32) -> HooverScore {
        HooverScore {
            t: 0.8,
            gt_regions: gt,
            seg_regions: 0,
            correct,
            over,
            under,
            missed: 0,
            noise: 0,
            over_seg_regions: 0,
            under_gt_regions: 0,
            angle_error_deg: None,
            angle_error_std_deg: None,
            angle_pairs: 0,
        }
    }

    fn jin(gt: u32, detected: u32) -> JinScore {
        JinScore { threshold: 0.8, gt_regions: gt, detected, rate: f64::from(detected) / f64::from(gt) }
    }

    #[test]
    fn the_line_gives_each_count_s_mean_and_range_over_the_seeds() {
        // Two images per run; seed 7: 3 + 5 correct of 10 + 10, seed 8: 4 + 6.
        let mut a = Totals { seed: 7, ..Totals::default() };
        a.add(&hoover(10, 3, 1, 0), &hoover(10, 2, 0, 0), &jin(10, 4), 0.5);
        a.add(&hoover(10, 5, 0, 1), &hoover(10, 5, 0, 0), &jin(10, 6), 0.7);
        let mut b = Totals { seed: 8, ..Totals::default() };
        b.add(&hoover(10, 4, 0, 0), &hoover(10, 4, 0, 0), &jin(10, 8), 0.8);
        b.add(&hoover(10, 6, 2, 0), &hoover(10, 3, 0, 0), &jin(10, 8), 0.9);
        let dir = std::env::temp_dir().join(format!("xtask-seeds-test-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let line = report("set", &[a, b], &dir).unwrap();
        assert_eq!(
            line,
            "set, 2 seeds (7–8): Hoover T=0.8 correct 4.50 (4.00–5.00) of 10.00, region growing alone 3.50 \
             (3.50–3.50), over 0.75 (0.50–1.00), under 0.25 (0.00–0.50), Jin rate 65.0 (50.0–80.0) %, final F 0.725 \
             (0.600–0.850)"
        );
        let csv = std::fs::read_to_string(dir.join("seeds.csv")).unwrap();
        std::fs::remove_dir_all(&dir).unwrap();
        assert_eq!(
            csv,
            "seed,images,correct,correct_regiongrow,over,under,jin_rate_pct,f_final\n\
             7,2,4.0000,3.5000,0.5000,0.5000,50.00,0.6000\n\
             8,2,5.0000,3.5000,1.0000,0.0000,80.00,0.8500\n"
        );
    }
}
