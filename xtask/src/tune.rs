//! `cargo xtask tune`: a parameter grid over one or more data sets (by default the synthetic training split), with
//! stage outputs cached.

use crate::data::{DataSet, DataSpec, Role};
use anyhow::{Context, Result, bail};
use indicatif::{ProgressBar, ProgressStyle};
use rangeimage::{Camera, LabelImage, RangeImage, SurfaceFeatures};
use rangeseg::Config;
use rayon::prelude::*;
use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::Path;
use std::sync::{Arc, Mutex, OnceLock};

/// Objectives a grid can maximise, with what each measures on a data set; over several sets, the mean of the sets'.
const OBJECTIVES: &[(&str, &str)] = &[
    (
        "hoover_correct",
        "mean Hoover correct detections at T = 0.8 minus half the over- and under-segmentations, as a fraction of the GT regions",
    ),
    ("boundary_f", "mean one-to-one boundary F (τ = 2 px) of the final edge map"),
    ("paper_precision", "mean paper precision of the final edge map against C1 (the paper's protocol)"),
    ("c2_paper_precision", "mean paper precision of C2 against C1 (the paper's Table I protocol)"),
];

/// The tuning file: a base config, an objective and a grid of dotted keys.
#[derive(Debug, serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct TuneFile {
    /// Base configuration, relative to the tuning file.
    base: String,
    /// Objective name (see `OBJECTIVES`).
    objective: String,
    /// Dotted key → values.
    grid: BTreeMap<String, Vec<toml::Value>>,
}

/// One tuning image, read once, and the index of its data set.
struct Image {
    set: usize,
    stem: String,
    range: RangeImage,
    camera: Camera,
    gt: LabelImage,
    angles: Vec<(u32, u32, f64)>,
}

/// A value computed once per key, shared between the grid's combinations.
struct Cache<V> {
    map: Mutex<BTreeMap<String, Arc<OnceLock<Arc<V>>>>>,
}

impl<V> Cache<V> {
    fn new() -> Self {
        Self { map: Mutex::new(BTreeMap::new()) }
    }

    fn get(&self, key: String, compute: impl FnOnce() -> V) -> Arc<V> {
        let cell = self.map.lock().expect("cache lock").entry(key).or_default().clone();
        cell.get_or_init(|| Arc::new(compute())).clone()
    }
}

/// The per-image numbers the objectives are computed from.
#[derive(Debug, Clone, Copy, Default)]
struct Sample {
    correct: f64,
    over: f64,
    under: f64,
    gt_regions: f64,
    rg_correct: f64,
    f: f64,
    c2_f: f64,
    c2_pp: f64,
    pp: f64,
}

fn objective(name: &str, s: &Sample) -> f64 {
    match name {
        // Normalised so that data sets with more regions per image do not outweigh the others.
        "hoover_correct" => (s.correct - 0.5 * (s.over + s.under)) / s.gt_regions.max(1.0),
        "boundary_f" => s.f,
        "paper_precision" => s.pp,
        "c2_paper_precision" => s.c2_pp,
        _ => unreachable!("objective names are checked when the grid is read"),
    }
}

/// Runs `cargo xtask tune`.
pub fn run(root: &Path, args: &[String]) -> Result<()> {
    let Options { grid_path, objective_name, write, specs } = options(root, args)?;
    let text = std::fs::read_to_string(&grid_path)
        .with_context(|| format!("{}: cannot read", grid_path.display()))?;
    let tune: TuneFile =
        toml::from_str(&text).with_context(|| format!("{}: invalid tuning file", grid_path.display()))?;
    let objective_name = objective_name.unwrap_or(tune.objective.clone());
    if !OBJECTIVES.iter().any(|(n, _)| *n == objective_name) {
        let names: Vec<_> = OBJECTIVES.iter().map(|(n, _)| *n).collect();
        bail!("{}: unknown objective {objective_name:?} (known: {})", grid_path.display(), names.join(", "));
    }
    let base_path = grid_path.parent().unwrap_or(Path::new(".")).join(&tune.base);
    let base_text = std::fs::read_to_string(&base_path)
        .with_context(|| format!("{}: cannot read", base_path.display()))?;
    let base: toml::Table =
        toml::from_str(&base_text).with_context(|| format!("{}: invalid TOML", base_path.display()))?;
    let combos = expand_grid(&base, &tune.grid, &grid_path)?;

    // A folder with a training split gives only that split: the synthetic test split is never touched here.
    let sets: Vec<DataSet> =
        specs.iter().map(|spec| crate::data::discover(root, spec, Role::Tune)).collect::<Result<_>>()?;
    let images = read_images(&sets)?;
    eprintln!(
        "tuning {} combinations × {} images ({}), objective {objective_name}",
        combos.len(),
        images.len(),
        sets.iter()
            .map(|s| format!("{} {}: {}", s.name, s.selection, s.images.len()))
            .collect::<Vec<_>>()
            .join("; ")
    );

    let caches = Caches::default();

    let bar = ProgressBar::new((combos.len() * images.len()) as u64).with_style(
        ProgressStyle::with_template("{bar:40} {pos}/{len} [{elapsed_precise} < {eta_precise}] {msg}")
            .expect("template"),
    );
    let jobs: Vec<(usize, usize)> =
        (0..combos.len()).flat_map(|c| (0..images.len()).map(move |i| (c, i))).collect();
    let samples: Vec<Sample> = jobs
        .par_iter()
        .map(|&(c, i)| {
            let sample = evaluate(&images[i], &combos[c].1, &caches);
            bar.inc(1);
            sample
        })
        .collect();
    bar.finish_and_clear();

    let ranking = rank(&samples, combos.len(), &images, sets.len(), &objective_name);
    let best = ranking.best;

    let out = root.join("target/tune");
    std::fs::create_dir_all(&out).with_context(|| format!("{}: cannot create", out.display()))?;
    let keys: Vec<&String> = tune.grid.keys().collect();
    let csv = results_csv(&keys, &combos, &sets, &ranking.per_set, &ranking.means, &objective_name);
    let best_config = &combos[best].1;
    let best_toml = best_config.to_toml();
    let report = report_md(
        &crate::shown(root, &grid_path),
        &objective_name,
        &keys,
        &combos,
        images.len(),
        &sets,
        &ranking,
    );
    for (name, text) in
        [("results.csv", csv), ("best.toml", best_toml.clone()), ("report.md", report.clone())]
    {
        rangeio::write_atomic(&out.join(name), text.as_bytes())?;
    }
    eprintln!("{report}");
    eprintln!("wrote {}", out.display());
    if write {
        let best_toml = best_config.to_commented_toml();
        let path = root.join("configs/default.toml");
        let text = format!(
            "# The default configuration: our best, tuned on the training split by `cargo xtask tune --write`\n# (objective {objective_name}). It must equal Config::default() (a test checks it): after --write,\n# copy the changed values into the stages' Params::default().\n\n{best_toml}"
        );
        rangeio::write_atomic(&path, text.as_bytes())?;
        eprintln!("updated {}", path.display());
    }
    Ok(())
}

/// The command line of `cargo xtask tune`.
struct Options {
    grid_path: std::path::PathBuf,
    objective_name: Option<String>,
    write: bool,
    specs: Vec<DataSpec>,
}

/// Parses the command line of `cargo xtask tune` (no data set given: the synthetic one).
fn options(root: &Path, args: &[String]) -> Result<Options> {
    let mut grid_path = root.join("configs/tune.toml");
    let mut objective_name: Option<String> = None;
    let mut write = false;
    let (mut specs, rest) = crate::data::parse_specs(args)?;
    if specs.is_empty() {
        specs.push(DataSpec::synthetic());
    }
    let mut it = rest.iter();
    while let Some(a) = it.next() {
        match a.as_str() {
            "--grid" => grid_path = it.next().context("--grid needs a file")?.into(),
            "--objective" => objective_name = Some(it.next().context("--objective needs a name")?.clone()),
            "--write" => write = true,
            other => bail!(
                "unknown option {other}\nusage: cargo xtask tune [--grid configs/tune.toml] [--objective NAME] [--data DIR|synthetic [--camera CAM]]... [--write]"
            ),
        }
    }
    Ok(Options { grid_path, objective_name, write, specs })
}

/// The stage outputs shared between grid combinations: features by their parameters, region
/// growing and Canny with their own scores (which do not depend on the later stages).
struct Caches {
    features: Cache<SurfaceFeatures>,
    regions: Cache<(regiongrow::Segmentation, f64)>,
    canny: Cache<(vcanny::Edges, f64)>,
}

impl Default for Caches {
    fn default() -> Self {
        Self { features: Cache::new(), regions: Cache::new(), canny: Cache::new() }
    }
}

/// The scores of one configuration on one image (stage outputs from `caches` where present).
fn evaluate(img: &Image, config: &Config, caches: &Caches) -> Sample {
    let fkey = format!("{}|{}|{}", img.set, img.stem, toml_of(&config.features));
    let features = caches.features.get(fkey.clone(), || features::compute(&img.range, &config.features));
    let rkey = format!("{fkey}|{}|{}", toml_of(&config.regiongrow), config.seed);
    let regions = caches.regions.get(rkey, || {
        let (seg, _) = regiongrow::grow(&img.range, &features, &img.camera, &config.regiongrow, config.seed);
        let h = rangeseg::evaluate::hoover(&img.gt, &seg.labels, &seg.regions, &img.angles);
        (seg, f64::from(h.correct))
    });
    let ckey = format!("{fkey}|{}", toml_of(&config.vcanny));
    let canny = caches.canny.get(ckey, || {
        let e = vcanny::detect_planes(&features.plane, &rangeimage::valid_mask(&img.range), &config.vcanny);
        let f = eval::boundary::matched(&e.edges, &img.gt, rangeseg::evaluate::TOLERANCE_PX).f;
        (e, f)
    });
    let fin = rangeseg::pipeline::finish(&img.range, &img.camera, config, &features, &regions.0, &canny.0);
    let h = rangeseg::evaluate::hoover(&img.gt, &fin.labels, &fin.final_regions, &img.angles);
    let f = eval::boundary::matched(fin.edges(), &img.gt, rangeseg::evaluate::TOLERANCE_PX).f;
    let pp =
        eval::paper_precision(fin.edges(), &regions.0.c1, rangeseg::evaluate::TOLERANCE_PX).unwrap_or(0.0);
    Sample {
        correct: f64::from(h.correct),
        over: f64::from(h.over),
        under: f64::from(h.under),
        gt_regions: f64::from(h.gt_regions),
        rg_correct: regions.1,
        f,
        c2_f: canny.1,
        c2_pp: eval::paper_precision(&canny.0.edges, &regions.0.c1, rangeseg::evaluate::TOLERANCE_PX)
            .unwrap_or(0.0),
        pp,
    }
}

/// Per combination: the mean sample of each data set, the mean over the sets with the objective,
/// and the best combination.
struct Ranking {
    per_set: Vec<Vec<Sample>>,
    means: Vec<(Sample, f64)>,
    best: usize,
}

/// Ranks the combinations by `objective_name` (`samples` combination-major over `images`).
fn rank(
    samples: &[Sample],
    n_combos: usize,
    images: &[Image],
    n_sets: usize,
    objective_name: &str,
) -> Ranking {
    // Average per combination and data set in a fixed order (rayon's float reductions depend on scheduling); the
    // objective of a combination is the mean of its sets' objectives, so each set weighs the same.
    let per_set: Vec<Vec<Sample>> = (0..n_combos)
        .map(|c| {
            let rows = &samples[c * images.len()..(c + 1) * images.len()];
            (0..n_sets)
                .map(|k| {
                    let set_rows: Vec<&Sample> =
                        rows.iter().zip(images).filter(|(_, img)| img.set == k).map(|(s, _)| s).collect();
                    mean_sample(&set_rows)
                })
                .collect()
        })
        .collect();
    let n_sets_f = n_sets as f64;
    let means: Vec<(Sample, f64)> = per_set
        .iter()
        .map(|set_means| {
            let score = set_means.iter().map(|m| objective(objective_name, m)).sum::<f64>() / n_sets_f;
            let refs: Vec<&Sample> = set_means.iter().collect();
            (mean_sample(&refs), score)
        })
        .collect();
    // Best: highest score; ties (frequent: Hoover counts on 10 images saturate) go to the better region growing
    // alone, then to the higher boundary F of the final edges, then to the earlier combination (grid order), so
    // the choice is deterministic.
    // Scores are means of counts: round away the last bits that the summation order leaves.
    let tie = |v: f64| (v * 1e6).round();
    let key = |c: usize| (tie(means[c].1), tie(means[c].0.rg_correct), means[c].0.f);
    let best = (0..means.len())
        .fold(0, |b, c| if key(c).partial_cmp(&key(b)) == Some(std::cmp::Ordering::Greater) { c } else { b });
    Ranking { per_set, means, best }
}

/// `target/tune/results.csv`: one row per combination, its values, objective and mean scores.
fn results_csv(
    keys: &[&String],
    combos: &[(Vec<toml::Value>, Config)],
    sets: &[DataSet],
    per_set: &[Vec<Sample>],
    means: &[(Sample, f64)],
    objective_name: &str,
) -> String {
    let mut csv = keys.iter().map(|k| k.as_str()).collect::<Vec<_>>().join(",");
    csv.push_str(",objective,correct,over,under,gt_regions,rg_correct,f,c2_f,paper_precision");
    for set in sets {
        let _ = write!(csv, ",objective_{}", set.name);
    }
    csv.push('\n');
    for (c, (m, score)) in means.iter().enumerate() {
        let vals: Vec<String> = combos[c].0.iter().map(|v| v.to_string()).collect();
        let set_scores: String =
            per_set[c].iter().map(|m| format!(",{:.5}", objective(objective_name, m))).collect();
        let _ = writeln!(
            csv,
            "{},{score:.5},{:.3},{:.3},{:.3},{:.3},{:.3},{:.5},{:.5},{:.5}{set_scores}",
            vals.join(","),
            m.correct,
            m.over,
            m.under,
            m.gt_regions,
            m.rg_correct,
            m.f,
            m.c2_f,
            m.pp
        );
    }
    csv
}

/// `target/tune/report.md`: the grid, the best combination and its scores per data set.
fn report_md(
    shown_grid: &str,
    objective_name: &str,
    keys: &[&String],
    combos: &[(Vec<toml::Value>, Config)],
    n_images: usize,
    sets: &[DataSet],
    ranking: &Ranking,
) -> String {
    let best = ranking.best;
    let (bm, bs) = &ranking.means[best];
    let mut report = format!(
        "# rangeseg tuning\n\nGrid `{}` ({} combinations) over {} images of {} data set{} ({}); objective `{objective_name}`: {}{}.\n\n",
        shown_grid,
        combos.len(),
        n_images,
        sets.len(),
        if sets.len() == 1 { "" } else { "s" },
        sets.iter()
            .map(|s| format!("{}, {}, {} images", s.name, s.selection, s.images.len()))
            .collect::<Vec<_>>()
            .join("; "),
        OBJECTIVES.iter().find(|(n, _)| *n == objective_name).map(|(_, d)| *d).unwrap_or(""),
        if sets.len() > 1 { "; the mean over the data sets" } else { "" }
    );
    let _ = writeln!(report, "## Best combination (objective {bs:.4})\n");
    for (k, v) in keys.iter().zip(&combos[best].0) {
        let _ = writeln!(report, "- `{k}` = {v}");
    }
    let _ = writeln!(
        report,
        "\n| data set | objective | correct | GT regions | region growing alone | over | under | boundary F | C2 alone F | paper precision vs C1 |\n|---|---|---|---|---|---|---|---|---|---|"
    );
    for (set, m) in sets.iter().zip(&ranking.per_set[best]) {
        let _ = writeln!(
            report,
            "| {} | {:.4} | {:.2} | {:.2} | {:.2} | {:.2} | {:.2} | {:.4} | {:.4} | {:.4} |",
            set.name,
            objective(objective_name, m),
            m.correct,
            m.gt_regions,
            m.rg_correct,
            m.over,
            m.under,
            m.f,
            m.c2_f,
            m.pp
        );
    }
    let _ = writeln!(
        report,
        "\nMeans over the data sets: correct {:.2} of {:.2} GT regions (region growing alone {:.2}), over {:.2}, under {:.2}, boundary F {:.4} (C2 alone {:.4}), paper precision vs C1 {:.4}.",
        bm.correct, bm.gt_regions, bm.rg_correct, bm.over, bm.under, bm.f, bm.c2_f, bm.pp
    );
    report
}

/// A stage's parameters as canonical TOML text, the cache key of what it computes.
fn toml_of<T: serde::Serialize>(v: &T) -> String {
    toml::to_string(v).expect("params serialise")
}

/// Every combination of the grid as (values in key order, validated config).
fn expand_grid(
    base: &toml::Table,
    grid: &BTreeMap<String, Vec<toml::Value>>,
    grid_path: &Path,
) -> Result<Vec<(Vec<toml::Value>, Config)>> {
    let mut combos: Vec<Vec<toml::Value>> = vec![Vec::new()];
    for (key, values) in grid {
        if values.is_empty() {
            bail!("{}: grid key {key} has no values", grid_path.display());
        }
        combos = combos
            .into_iter()
            .flat_map(|c| values.iter().map(move |v| [c.clone(), vec![v.clone()]].concat()))
            .collect();
    }
    combos
        .into_iter()
        .map(|values| {
            let mut table = base.clone();
            for (key, value) in grid.keys().zip(&values) {
                set_dotted(&mut table, key, value.clone())
                    .with_context(|| format!("{}: grid key {key}", grid_path.display()))?;
            }
            let config = Config::from_table(table, grid_path)?;
            Ok((values, config))
        })
        .collect()
}

/// Sets `a.b.c = value` in a TOML table, creating intermediate tables.
fn set_dotted(table: &mut toml::Table, key: &str, value: toml::Value) -> Result<()> {
    let mut parts: Vec<&str> = key.split('.').collect();
    let last = parts.pop().context("empty key")?;
    let mut t = table;
    for p in parts {
        t = t
            .entry(p)
            .or_insert_with(|| toml::Value::Table(toml::Table::new()))
            .as_table_mut()
            .with_context(|| format!("{p} is not a table"))?;
    }
    t.insert(last.to_string(), value);
    Ok(())
}

/// Reads every data set's images with their ground truth.
fn read_images(sets: &[DataSet]) -> Result<Vec<Image>> {
    let mut images = Vec::new();
    for (k, set) in sets.iter().enumerate() {
        for img in &set.images {
            let loaded = img.load()?;
            // In the working units the pipeline runs it in (`normalize_units` is not tuned).
            let (range, units) = rangeseg::units::in_working_units(
                &loaded.frame.range,
                &loaded.frame.camera,
                &rangeseg::Config::default(),
            );
            images.push(Image {
                set: k,
                stem: loaded.stem,
                range: range.into_owned(),
                camera: units.camera,
                gt: loaded.gt,
                angles: loaded.angles,
            });
        }
    }
    Ok(images)
}

/// The mean of per-image samples, summed in order.
fn mean_sample(rows: &[&Sample]) -> Sample {
    let n = rows.len().max(1) as f64;
    let mut m = Sample::default();
    for s in rows {
        m.correct += s.correct / n;
        m.over += s.over / n;
        m.under += s.under / n;
        m.gt_regions += s.gt_regions / n;
        m.rg_correct += s.rg_correct / n;
        m.f += s.f / n;
        m.c2_f += s.c2_f / n;
        m.c2_pp += s.c2_pp / n;
        m.pp += s.pp / n;
    }
    m
}
