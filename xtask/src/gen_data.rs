//! `cargo xtask gen-data`: the synthetic ABW-like benchmark in ABW file formats, with checksums.
//!
//! Writes `abw.{train,test}.N.{range,gt-seg,gt-ang}` (10 train, 30 test; scenes from
//! [`scenegen::benchmark_image`]) and `MANIFEST.sha256`, the committed checksum of every file.
//! The data files themselves are not committed: [`ensure_synthetic_data`] regenerates them on
//! first use and checks them against the manifest, so a change to the generator (or to the ABW
//! writers) is caught unless the manifest is updated deliberately with `cargo xtask gen-data`.
//!
//! `--family NAME [--strength S]` writes an artefact family set instead ([`scenegen::family_image`]:
//! 10 train + 20 test images, same names), by default into `target/synthetic/NAME-sS/`, where
//! `--data synthetic:NAME@S` regenerates it on every use ([`ensure_family_data`]); its manifest is
//! written but not committed.

// A command-line tool: printing its results is its job.
#![allow(clippy::print_stdout)]

use crate::report::mean_std;
use anyhow::{Context, Result, bail};
use rangeio::abw::{AdjacentAngle, raw_to_range, write_angles, write_labels, write_range};
use rayon::prelude::*;
use scenegen::Scene;
use sha2::{Digest, Sha256};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// The benchmark directory, relative to the project root.
pub const DATA_DIR: &str = "data/synthetic-abw";
/// The checksum file inside [`DATA_DIR`].
pub const MANIFEST: &str = "MANIFEST.sha256";
/// The file extensions written per image.
const EXTENSIONS: [&str; 3] = ["range", "gt-seg", "gt-ang"];

/// One benchmark image: its stem (`abw.test.7`), split and index.
#[derive(Debug, Clone)]
struct ImageId {
    stem: String,
    test: bool,
    index: u32,
}

/// `(file name, sha256 hex)` of every benchmark file, in manifest order.
type Hashes = Vec<(String, String)>;

/// Which images a set holds and how each is generated: the benchmark, or an artefact family at a strength.
#[derive(Debug, Clone, Copy, PartialEq)]
enum SetKind {
    Benchmark,
    Family(scenegen::Family, f64),
}

impl SetKind {
    fn counts(self) -> (u32, u32) {
        match self {
            SetKind::Benchmark => (scenegen::TRAIN_IMAGES, scenegen::TEST_IMAGES),
            SetKind::Family(..) => (scenegen::FAMILY_TRAIN_IMAGES, scenegen::FAMILY_TEST_IMAGES),
        }
    }

    fn image(self, id: &ImageId) -> (scenegen::Params, u64) {
        match self {
            SetKind::Benchmark => scenegen::benchmark_image(id.test, id.index),
            SetKind::Family(f, s) => scenegen::family_image(f, s, id.test, id.index),
        }
    }
}

fn set_ids(kind: SetKind) -> Vec<ImageId> {
    let split = |test: bool, n: u32| {
        (0..n).map(move |index| ImageId {
            stem: format!("abw.{}.{index}", if test { "test" } else { "train" }),
            test,
            index,
        })
    };
    let (train, test) = kind.counts();
    split(false, train).chain(split(true, test)).collect()
}

/// Generates every scene of a set, in parallel; the result is in [`set_ids`] order and does
/// not depend on the thread count (each scene is generated on one thread from its own seed).
fn generate_set(kind: SetKind) -> Result<Vec<(ImageId, Scene)>> {
    set_ids(kind)
        .into_par_iter()
        .map(|id| {
            let (params, seed) = kind.image(&id);
            params.validate().map_err(|e| anyhow::anyhow!("{}: {e}", id.stem))?;
            let scene = scenegen::generate(&params, seed);
            Ok((id, scene))
        })
        .collect()
}

fn write_scene(dir: &Path, stem: &str, scene: &Scene) -> Result<()> {
    write_range(&dir.join(format!("{stem}.range")), &raw_to_range(&scene.range))?;
    write_gt_seg(dir, stem, &scene.labels)?;
    let angles: Vec<AdjacentAngle> =
        scene.angles.iter().map(|&(a, b, angle_deg)| AdjacentAngle { a, b, angle_deg }).collect();
    write_angles(&dir.join(format!("{stem}.gt-ang")), &angles)?;
    Ok(())
}

/// Writes `dir/STEM.gt-seg`; an error if the 8-bit writer had to renumber the labels (they must stay as generated).
fn write_gt_seg(dir: &Path, stem: &str, labels: &rangeimage::LabelImage) -> Result<()> {
    let pairs = write_labels(&dir.join(format!("{stem}.gt-seg")), labels)?;
    let identity = pairs.iter().all(|&(old, new)| old == u32::from(new));
    anyhow::ensure!(identity, "{stem}: ground-truth labels were renumbered by the 8-bit writer");
    Ok(())
}

/// Every data file name of the benchmark, sorted bytewise (the manifest order).
#[cfg(test)]
fn file_names() -> Vec<String> {
    set_file_names(SetKind::Benchmark)
}

/// Every data file name of a set, sorted bytewise (the manifest order).
fn set_file_names(kind: SetKind) -> Vec<String> {
    let mut names: Vec<String> = set_ids(kind)
        .iter()
        .flat_map(|id| EXTENSIONS.iter().map(move |e| format!("{}.{e}", id.stem)))
        .collect();
    names.sort();
    names
}

fn sha256_hex(bytes: &[u8]) -> String {
    Sha256::digest(bytes).iter().fold(String::with_capacity(64), |mut s, b| {
        let _ = write!(s, "{b:02x}");
        s
    })
}

/// `(name, sha256)` of every benchmark file in `dir`; a missing file has the hash `"missing"`.
fn hash_files(dir: &Path) -> Hashes {
    hash_set_files(dir, SetKind::Benchmark)
}

/// `(name, sha256)` of every file of a set in `dir`; a missing file has the hash `"missing"`.
fn hash_set_files(dir: &Path, kind: SetKind) -> Hashes {
    hash_named(dir, set_file_names(kind))
}

/// `(name, sha256)` of the files `names` (in that order) in `dir`; a missing file has the hash `"missing"`.
fn hash_named(dir: &Path, names: Vec<String>) -> Hashes {
    names
        .into_par_iter()
        .map(|name| {
            let hash =
                std::fs::read(dir.join(&name)).map_or_else(|_| "missing".to_string(), |b| sha256_hex(&b));
            (name, hash)
        })
        .collect()
}

fn manifest_text(hashes: &[(String, String)]) -> String {
    hashes.iter().map(|(name, hash)| format!("{hash}  {name}\n")).collect()
}

fn parse_manifest(path: &Path) -> Result<Hashes> {
    let text = std::fs::read_to_string(path)
        .with_context(|| format!("{}: cannot read the manifest", path.display()))?;
    text.lines()
        .enumerate()
        .filter(|(_, l)| !l.trim().is_empty())
        .map(|(i, l)| {
            let (hash, name) = l
                .split_once("  ")
                .with_context(|| format!("{}:{}: expected `sha256  name`", path.display(), i + 1))?;
            Ok((name.to_string(), hash.to_string()))
        })
        .collect()
}

/// Names whose hashes differ between two manifests (including files only in one of them).
fn differences(expected: &[(String, String)], actual: &[(String, String)]) -> Vec<String> {
    let exp: std::collections::BTreeMap<_, _> = expected.iter().cloned().collect();
    let act: std::collections::BTreeMap<_, _> = actual.iter().cloned().collect();
    let names: std::collections::BTreeSet<&String> = exp.keys().chain(act.keys()).collect();
    names
        .into_iter()
        .filter(|n| exp.get(*n) != act.get(*n))
        .map(|n| {
            format!(
                "{n}: manifest {} / generated {}",
                exp.get(n).map_or("absent", String::as_str),
                act.get(n).map_or("absent", String::as_str)
            )
        })
        .collect()
}

/// Generates the benchmark into `dir` and returns the scenes and the hashes of the written files.
fn generate_into(dir: &Path) -> Result<(Vec<(ImageId, Scene)>, Hashes)> {
    generate_set_into(dir, SetKind::Benchmark)
}

/// Generates a set into `dir` and returns the scenes and the hashes of the written files.
fn generate_set_into(dir: &Path, kind: SetKind) -> Result<(Vec<(ImageId, Scene)>, Hashes)> {
    std::fs::create_dir_all(dir)
        .with_context(|| format!("{}: cannot create the directory", dir.display()))?;
    let scenes = generate_set(kind)?;
    scenes.par_iter().try_for_each(|(id, scene)| write_scene(dir, &id.stem, scene))?;
    Ok((scenes, hash_set_files(dir, kind)))
}

/// The default folder of a family set: `target/synthetic/NAME-sSTRENGTH`.
pub fn family_dir(root: &Path, family: scenegen::Family, strength: f64) -> PathBuf {
    root.join("target/synthetic").join(format!("{}-s{strength}", family.name()))
}

/// Generates the set of `family` at `strength` into [`family_dir`] (every time: it takes seconds and
/// can never be stale) and returns the directory.
pub fn ensure_family_data(root: &Path, family: scenegen::Family, strength: f64) -> Result<PathBuf> {
    let dir = family_dir(root, family, strength);
    let (_, hashes) = generate_set_into(&dir, SetKind::Family(family, strength))?;
    rangeio::write_atomic(&dir.join(MANIFEST), manifest_text(&hashes).as_bytes())?;
    Ok(dir)
}

/// The folder of a rooms set: `target/synthetic/rooms-sSTRENGTH`.
pub fn rooms_dir(root: &Path, strength: f64) -> PathBuf {
    root.join("target/synthetic").join(format!("rooms-s{strength}"))
}

/// Generates the rooms set at `strength` ([`scenegen::generate_room`]: `room.test.N.png`, depth in TUM's 16-bit units,
/// and `room.test.N.gt-seg`, N < [`scenegen::ROOM_TEST_IMAGES`]) into [`rooms_dir`], every time, with a manifest, and
/// returns the directory.
pub fn ensure_rooms_data(root: &Path, strength: f64) -> Result<PathBuf> {
    let dir = rooms_dir(root, strength);
    std::fs::create_dir_all(&dir)
        .with_context(|| format!("{}: cannot create the directory", dir.display()))?;
    let names: Vec<String> = (0..scenegen::ROOM_TEST_IMAGES)
        .into_par_iter()
        .map(|index| {
            let (params, seed) = scenegen::room_image(index, strength);
            let stem = format!("room.test.{index}");
            params.validate().map_err(|e| anyhow::anyhow!("{stem}: {e}"))?;
            let scene = scenegen::generate_room(&params, seed);
            rangeio::png::write_gray16_png(&dir.join(format!("{stem}.png")), &scene.depth)?;
            write_gt_seg(&dir, &stem, &scene.labels)?;
            Ok(stem)
        })
        .collect::<Result<_>>()?;
    let mut files: Vec<String> =
        names.iter().flat_map(|stem| [format!("{stem}.gt-seg"), format!("{stem}.png")]).collect();
    files.sort();
    let hashes = hash_named(&dir, files);
    if let Some((name, _)) = hashes.iter().find(|(_, h)| h == "missing") {
        bail!("{}: cannot read the file just written", dir.join(name).display());
    }
    rangeio::write_atomic(&dir.join(MANIFEST), manifest_text(&hashes).as_bytes())?;
    Ok(dir)
}

/// Makes sure `root/data/synthetic-abw` holds the benchmark exactly as the committed manifest
/// says, generating it if files are missing or differ; returns the directory.
///
/// Fails if the generator's output does not match the manifest (the generator or the ABW writers
/// changed: run `cargo xtask gen-data` to regenerate and commit the new manifest deliberately).
pub fn ensure_synthetic_data(root: &Path) -> Result<PathBuf> {
    let dir = root.join(DATA_DIR);
    let manifest_path = dir.join(MANIFEST);
    let expected = parse_manifest(&manifest_path)?;
    if differences(&expected, &hash_files(&dir)).is_empty() {
        return Ok(dir);
    }
    println!("generating the synthetic ABW-like benchmark into {}", dir.display());
    let (_, actual) = generate_into(&dir)?;
    let diff = differences(&expected, &actual);
    if !diff.is_empty() {
        bail!(
            "{}: the generated benchmark differs from the committed manifest in {} file(s) \
             (run `cargo xtask gen-data` to update it deliberately):\n  {}",
            manifest_path.display(),
            diff.len(),
            diff.join("\n  ")
        );
    }
    Ok(dir)
}

fn print_stats(scenes: &[(ImageId, Scene)]) {
    for test in [false, true] {
        let split: Vec<&Scene> = scenes.iter().filter(|(id, _)| id.test == test).map(|(_, s)| s).collect();
        let regions: Vec<f64> = split
            .iter()
            .map(|s| f64::from(s.labels.as_slice().iter().copied().max().unwrap_or(0).saturating_sub(9)))
            .collect();
        let valid: Vec<f64> = split
            .iter()
            .map(|s| s.range.as_slice().iter().filter(|&&v| v != 0).count() as f64 / s.range.len() as f64)
            .collect();
        let labelled: Vec<f64> = split
            .iter()
            .map(|s| s.labels.as_slice().iter().filter(|&&l| l != 0).count() as f64 / s.labels.len() as f64)
            .collect();
        let (rm, rs) = mean_std(regions.iter().copied());
        let (vm, vs) = mean_std(valid.iter().copied());
        let (lm, _) = mean_std(labelled.iter().copied());
        let lo = regions.iter().copied().fold(f64::INFINITY, f64::min);
        let hi = regions.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        println!(
            "{:5}: {} images, GT regions {rm:.1} ± {rs:.1} (min {lo}, max {hi}), valid {vm:.3} ± {vs:.3}, labelled {lm:.3}",
            if test { "test" } else { "train" },
            split.len()
        );
    }
}

fn render_figures(root: &Path, scenes: &[(ImageId, Scene)]) -> Result<()> {
    let (_, scene) =
        scenes.iter().find(|(id, _)| !id.test && id.index == 0).context("abw.train.0 is missing")?;
    let dir = root.join("docs/img");
    std::fs::create_dir_all(&dir)
        .with_context(|| format!("{}: cannot create the directory", dir.display()))?;
    rangeio::png::write_depth_png(&dir.join("synthetic-example-range.png"), &raw_to_range(&scene.range))?;
    rangeio::png::write_label_png(&dir.join("synthetic-example-gt.png"), &scene.labels)?;
    println!("wrote {}/synthetic-example-{{range,gt}}.png (abw.train.0)", dir.display());
    Ok(())
}

/// `cargo xtask gen-data [--out DIR] [--check] [--figures] [--family NAME [--strength S]]`.
pub fn run(args: &[String]) -> Result<()> {
    let root = crate::project_root();
    let mut out = None;
    let (mut check, mut figures) = (false, false);
    let (mut family, mut strength) = (None, 1.0);
    let mut it = args.iter();
    while let Some(a) = it.next() {
        match a.as_str() {
            "--out" => out = Some(PathBuf::from(it.next().context("--out needs a directory")?)),
            "--check" => check = true,
            "--figures" => figures = true,
            "--family" => {
                let name = it.next().context("--family needs a name")?;
                family = Some(
                    crate::data::DataSpec::parse(&format!("synthetic:{name}"))?.family.context("family")?.0,
                );
            }
            "--strength" => {
                let v = it.next().context("--strength needs a number")?;
                strength = v
                    .parse()
                    .ok()
                    .filter(|x: &f64| (0.0..=10.0).contains(x))
                    .with_context(|| format!("--strength {v}: must be a number in 0..=10"))?;
            }
            other => bail!("gen-data: unknown argument `{other}`\n\n{}", crate::USAGE),
        }
    }
    if family.is_none() && args.iter().any(|a| a == "--strength") {
        bail!("gen-data: --strength needs --family");
    }
    if let Some(family) = family {
        if check || figures {
            bail!("gen-data: --check and --figures are for the benchmark, not with --family");
        }
        let out = out.unwrap_or_else(|| family_dir(&root, family, strength));
        let start = Instant::now();
        let (scenes, hashes) = generate_set_into(&out, SetKind::Family(family, strength))?;
        rangeio::write_atomic(&out.join(MANIFEST), manifest_text(&hashes).as_bytes())?;
        print_stats(&scenes);
        println!(
            "wrote {} files of family {} at strength {strength} to {} in {:.2?}",
            hashes.len(),
            family.name(),
            out.display(),
            start.elapsed()
        );
        return Ok(());
    }
    let out = out.unwrap_or_else(|| root.join(DATA_DIR));
    let committed = root.join(DATA_DIR).join(MANIFEST);
    let start = Instant::now();
    if check {
        // Generate into a scratch directory so the files hashed are exactly what gen-data writes.
        let scratch = root.join("target/tmp/gen-data-check");
        let _ = std::fs::remove_dir_all(&scratch);
        let (scenes, actual) = generate_into(&scratch)?;
        let elapsed = start.elapsed();
        let _ = std::fs::remove_dir_all(&scratch);
        print_stats(&scenes);
        let diff = differences(&parse_manifest(&committed)?, &actual);
        if !diff.is_empty() {
            bail!(
                "{}: the generator's output differs from the committed manifest in {} file(s):\n  {}",
                committed.display(),
                diff.len(),
                diff.join("\n  ")
            );
        }
        println!(
            "gen-data --check: all {} files match {} ({elapsed:.2?})",
            actual.len(),
            committed.display()
        );
        return Ok(());
    }
    let (scenes, hashes) = generate_into(&out)?;
    let elapsed = start.elapsed();
    rangeio::write_atomic(&out.join(MANIFEST), manifest_text(&hashes).as_bytes())?;
    print_stats(&scenes);
    println!("wrote {} files and {MANIFEST} to {} in {elapsed:.2?}", hashes.len(), out.display());
    if figures {
        render_figures(&root, &scenes)?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn committed_manifest_matches_the_generator() {
        let root = crate::project_root();
        let expected = parse_manifest(&root.join(DATA_DIR).join(MANIFEST)).expect("committed manifest");
        assert_eq!(expected.len(), 120);
        let scratch = root.join("target/tmp/gen-data-test");
        let _ = std::fs::remove_dir_all(&scratch);
        let (_, actual) = generate_into(&scratch).expect("generate");
        // The files read back through the ABW readers with the strict label check.
        let ds = rangeio::abw::Dataset::discover(&scratch).expect("discover");
        assert_eq!((ds.train.len(), ds.test.len()), (10, 30));
        for img in ds.train.iter().chain(&ds.test) {
            let gt = img.gt_seg.as_ref().expect("gt-seg");
            rangeio::abw::read_labels(gt, true).expect("ABW label rules");
            assert!(
                !rangeio::abw::read_angles(img.gt_ang.as_ref().expect("gt-ang")).expect("angles").is_empty()
            );
        }
        let _ = std::fs::remove_dir_all(&scratch);
        let diff = differences(&expected, &actual);
        assert!(diff.is_empty(), "generator differs from the manifest:\n{}", diff.join("\n"));
    }

    #[test]
    fn family_sets_have_both_splits_and_differ_from_the_benchmark() {
        let root = crate::project_root();
        let family = scenegen::Family::Staircase;
        let dir = ensure_family_data(&root, family, 1.0).expect("family set");
        assert_eq!(dir, family_dir(&root, family, 1.0));
        let spec = crate::data::DataSpec::parse("synthetic:staircase@1").expect("spec");
        let test = crate::data::discover(&root, &spec, crate::data::Role::Eval).expect("test split");
        let train = crate::data::discover(&root, &spec, crate::data::Role::Tune).expect("train split");
        assert_eq!((test.images.len(), train.images.len()), (20, 10));
        assert_eq!(test.name, "synthetic:staircase@1");
        assert_eq!(test.selection, "test split");
        // Written as the manifest says, and not the benchmark's files.
        let manifest = parse_manifest(&dir.join(MANIFEST)).expect("manifest");
        assert_eq!(manifest, hash_set_files(&dir, SetKind::Family(family, 1.0)));
        assert_eq!(manifest.len(), 90);
        let benchmark = parse_manifest(&root.join(DATA_DIR).join(MANIFEST)).expect("committed manifest");
        let same = manifest.iter().filter(|m| benchmark.contains(m)).count();
        assert_eq!(same, 0, "family files equal to benchmark files");
    }

    #[test]
    fn manifest_round_trips_and_reports_differences() {
        let a = vec![("x.range".to_string(), "00".to_string()), ("y.range".to_string(), "11".to_string())];
        let dir = crate::project_root().join("target/tmp/gen-data-manifest-test");
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join(MANIFEST);
        std::fs::write(&path, manifest_text(&a)).unwrap();
        assert_eq!(parse_manifest(&path).unwrap(), a);
        let mut b = a.clone();
        b[1].1 = "22".into();
        let d = differences(&a, &b);
        assert_eq!(d.len(), 1);
        assert!(d[0].starts_with("y.range"));
        assert_eq!(sha256_hex(b"abc"), "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad");
        assert_eq!(file_names().len(), 120);
    }
}
