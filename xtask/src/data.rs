//! Labelled data sets for `eval` and `tune`: the synthetic benchmark, its artefact families and rooms, real ABW folders,
//! any folder of `STEM.range` (or `.png`, `.pgm`, `.tif`, `.tiff`, `.pcd`) with `STEM.gt-seg`.

use anyhow::{Context, Result, bail};
use rangeimage::{Camera, LabelImage};
use rangeio::abw::{Dataset, Split};
use std::path::{Path, PathBuf};

/// Which images of a folder a command reads.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Role {
    /// `tune`: the training split where the folder has one, otherwise every labelled image.
    Tune,
    /// `eval`: the test split where the folder has one, otherwise every labelled image.
    Eval,
}

/// One data set named on the command line: a folder, and the camera its images need.
#[derive(Debug, Clone, PartialEq)]
pub struct DataSpec {
    /// The folder (`None`: the synthetic benchmark or, with `family`, a family set, generated on first use).
    pub dir: Option<PathBuf>,
    /// With `dir: None`, an artefact family and its strength (`--data synthetic:FAMILY[@STRENGTH]`), generated
    /// into `target/synthetic/FAMILY-sSTRENGTH/` on every use.
    pub family: Option<(scenegen::Family, f64)>,
    /// With `dir: None`, the rooms seen by a Kinect-like camera at this sensor strength (`--data
    /// synthetic:rooms[@STRENGTH]`, [`scenegen::generate_room`]), generated into `target/synthetic/rooms-sSTRENGTH/` on
    /// every use; a test set only.
    pub rooms: Option<f64>,
    /// The camera of every image; `None`: by file name (ABW calibration 0 or 1, or [`rangeio::NYU_GREY`] for
    /// `nyu.K`), and the reader's own for the sensor formats (PNG, PGM, TIFF, PCD).
    pub camera: Option<Camera>,
    /// `ReadOptions::inverted_depth` of every image (set with the camera by `--camera nyu-grey`).
    pub inverted_depth: Option<f64>,
    /// Every depth value is multiplied by this after reading (`--depth-scale M`: the same scenes in other
    /// units, e.g. the NYU frames in metres-like units, to check that results do not depend on units).
    pub depth_scale: Option<f64>,
}

impl DataSpec {
    /// The synthetic ABW-like benchmark.
    pub fn synthetic() -> Self {
        Self { dir: None, family: None, rooms: None, camera: None, inverted_depth: None, depth_scale: None }
    }

    /// A folder of labelled images.
    pub fn folder(dir: impl Into<PathBuf>) -> Self {
        Self { dir: Some(dir.into()), ..Self::synthetic() }
    }

    /// Parses the value of `--data`: `synthetic`, `synthetic:FAMILY[@STRENGTH]` or a folder.
    pub fn parse(v: &str) -> Result<Self> {
        let Some(rest) = v.strip_prefix("synthetic:") else {
            return Ok(if v == "synthetic" { Self::synthetic() } else { Self::folder(v) });
        };
        let (name, strength) = match rest.split_once('@') {
            Some((n, s)) => {
                let strength: f64 =
                    s.parse().ok().filter(|x: &f64| (0.0..=10.0).contains(x)).with_context(|| {
                        format!("--data {v}: the strength after @ must be a number in 0..=10")
                    })?;
                (n, strength)
            }
            None => (rest, 1.0),
        };
        if name == "rooms" {
            // 16-bit PNG in TUM's units: read in metres on the reader's default pinhole camera, the rooms' own.
            return Ok(Self { rooms: Some(strength), ..Self::synthetic() });
        }
        let family = scenegen::Family::from_name(name).with_context(|| {
            let names: Vec<&str> = scenegen::Family::ALL.iter().map(|f| f.name()).collect();
            format!("--data {v}: unknown family `{name}` (families: {}, and rooms)", names.join(", "))
        })?;
        Ok(Self { family: Some((family, strength)), ..Self::synthetic() })
    }

    /// The folder this spec reads, generating the synthetic benchmark or the family set if needed.
    pub fn resolve_dir(&self, root: &Path) -> Result<PathBuf> {
        match (&self.dir, self.family, self.rooms) {
            (Some(d), _, _) => Ok(d.clone()),
            (None, _, Some(strength)) => crate::gen_data::ensure_rooms_data(root, strength),
            (None, None, None) => crate::gen_data::ensure_synthetic_data(root),
            (None, Some((family, strength)), None) => {
                crate::gen_data::ensure_family_data(root, family, strength)
            }
        }
    }

    /// The short name of a synthetic spec (`synthetic`, `synthetic:stripes@1`), `None` for a folder.
    pub fn synthetic_name(&self) -> Option<String> {
        match (&self.dir, self.family, self.rooms) {
            (Some(_), _, _) => None,
            (None, _, Some(s)) => Some(format!("synthetic:rooms@{s}")),
            (None, None, None) => Some("synthetic".into()),
            (None, Some((f, s)), None) => Some(format!("synthetic:{}@{s}", f.name())),
        }
    }
}

/// Parses repeated `--data DIR [--camera CAM] [--depth-scale M]` options (a `--camera` or `--depth-scale` applies to the `--data` before it;
/// `--data synthetic` names the synthetic benchmark, `--data synthetic:FAMILY[@STRENGTH]` a family set). Returns the specs and the arguments left over.
pub fn parse_specs(args: &[String]) -> Result<(Vec<DataSpec>, Vec<String>)> {
    let mut specs: Vec<DataSpec> = Vec::new();
    let mut rest = Vec::new();
    let mut it = args.iter();
    while let Some(a) = it.next() {
        match a.as_str() {
            "--data" => {
                let v = it.next().context("--data needs a folder (or `synthetic`, `synthetic:FAMILY`)")?;
                specs.push(DataSpec::parse(v)?);
            }
            "--camera" => {
                let v = it
                    .next()
                    .context("--camera needs a value (abw0, abw1, grid, nyu-grey, pinhole:fx,fy,cx,cy)")?;
                let (camera, inverted_depth) = if v == "nyu-grey" {
                    (rangeio::NYU_GREY.camera, Some(rangeio::NYU_GREY.inverted_depth))
                } else {
                    (rangeio::parse_camera(v).map_err(|e| anyhow::anyhow!("--camera {v}: {e}"))?, None)
                };
                let last = specs.last_mut().context("--camera must follow the --data it applies to")?;
                if last.camera.is_some() {
                    bail!("--camera given twice for one --data");
                }
                (last.camera, last.inverted_depth) = (Some(camera), inverted_depth);
            }
            "--depth-scale" => {
                let v = it.next().context("--depth-scale needs a positive number")?;
                let m: f64 = v
                    .parse()
                    .ok()
                    .filter(|m: &f64| m.is_finite() && *m > 0.0)
                    .with_context(|| format!("--depth-scale {v}: not a positive number"))?;
                let last = specs.last_mut().context("--depth-scale must follow the --data it applies to")?;
                if last.depth_scale.replace(m).is_some() {
                    bail!("--depth-scale given twice for one --data");
                }
            }
            _ => rest.push(a.clone()),
        }
    }
    Ok((specs, rest))
}

/// One labelled image of a data set, not yet read.
#[derive(Debug, Clone, PartialEq)]
pub struct LabelledImage {
    /// File name without extension, e.g. `abw.test.7` or `nyu.15`.
    pub stem: String,
    /// The range file.
    pub range: PathBuf,
    /// The ground-truth labels.
    pub gt_seg: PathBuf,
    /// Angles between adjacent GT regions, where the data set has them.
    pub gt_ang: Option<PathBuf>,
    /// The camera to read it with (`None`: the format's own, e.g. a 16-bit PNG's default pinhole camera in metres).
    pub camera: Option<Camera>,
    /// `ReadOptions::inverted_depth` to read it with.
    pub inverted_depth: Option<f64>,
    /// Multiplies every depth value after reading ([`DataSpec::depth_scale`]).
    pub depth_scale: Option<f64>,
}

/// A labelled image read into memory.
pub struct LoadedImage {
    /// File name without extension.
    pub stem: String,
    /// The range image (NaN = no data) with its camera and format.
    pub frame: rangeio::Frame,
    /// Ground-truth labels (ABW convention).
    pub gt: LabelImage,
    /// `(a, b, degrees)` for adjacent GT regions; empty where the data set has no `.gt-ang`.
    pub angles: Vec<(u32, u32, f64)>,
}

impl LabelledImage {
    /// Reads the range image, ground truth and angles.
    pub fn load(&self) -> Result<LoadedImage> {
        let frame = rangeio::read(
            &self.range,
            &rangeio::ReadOptions {
                camera: self.camera,
                inverted_depth: self.inverted_depth,
                ..Default::default()
            },
        )?;
        let mut frame = frame;
        if let Some(m) = self.depth_scale {
            frame.range = frame.range.map(|&v| (f64::from(v) * m) as f32);
        }
        let gt = rangeio::abw::read_labels(&self.gt_seg, true)?;
        if !gt.same_size(&frame.range) {
            bail!(
                "{}: ground truth is {:?} but the range image is {:?}",
                self.gt_seg.display(),
                gt.dimensions(),
                frame.range.dimensions()
            );
        }
        let angles = match &self.gt_ang {
            Some(p) => rangeio::abw::read_angles(p)?.iter().map(|a| (a.a, a.b, a.angle_deg)).collect(),
            None => Vec::new(),
        };
        Ok(LoadedImage { stem: self.stem.clone(), frame, gt, angles })
    }
}

/// A data set's images for one role, with a short name for reports.
#[derive(Debug, Clone, PartialEq)]
pub struct DataSet {
    /// Short name: `synthetic` or the folder's name.
    pub name: String,
    /// The folder.
    pub dir: PathBuf,
    /// What the images were chosen as, for reports (e.g. "test split", "every labelled image").
    pub selection: &'static str,
    /// How the camera was chosen, for reports.
    pub camera: String,
    /// The images, in a fixed order.
    pub images: Vec<LabelledImage>,
}

/// Finds the images of `spec` that `role` reads.
///
/// A folder with ABW names (`abw.train.N`, `abw.test.N`) gives its training split to `tune` and its test split to
/// `eval`; where the split is absent (the real ABW test images stand in for training data) or the names are not
/// ABW names, every range file with a `STEM.gt-seg` beside it is read (`.range`, `.png`, `.pgm`, `.tif`, `.tiff`,
/// `.pcd`). `.range` images without ABW (or `nyu.K`) names need `--camera`; the sensor formats are read with the
/// reader's own camera and units.
pub fn discover(root: &Path, spec: &DataSpec, role: Role) -> Result<DataSet> {
    if spec.rooms.is_some() && role == Role::Tune {
        bail!("--data synthetic:rooms is a test set only: nothing is tuned on it");
    }
    let dir = spec.resolve_dir(root)?;
    let name = match &spec.dir {
        None => spec.synthetic_name().unwrap_or_default(),
        Some(d) => d
            .canonicalize()
            .ok()
            .as_deref()
            .and_then(Path::file_name)
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_else(|| d.display().to_string()),
    };
    let abw = Dataset::discover(&dir).ok();
    let split = abw.as_ref().map(|ds| match role {
        Role::Tune => (&ds.train, Split::Train),
        Role::Eval => (&ds.test, Split::Test),
    });
    let mut images = Vec::new();
    let selection = match split {
        Some((imgs, split)) if !imgs.is_empty() => {
            for img in imgs {
                let Some(gt_seg) = img.gt_seg.clone() else {
                    bail!("{}: no ground truth ({}.gt-seg)", dir.display(), img.stem);
                };
                images.push(LabelledImage {
                    stem: img.stem.clone(),
                    range: img.range.clone(),
                    gt_seg,
                    gt_ang: img.gt_ang.clone(),
                    camera: Some(spec.camera.unwrap_or(img.camera)),
                    inverted_depth: spec.inverted_depth,
                    depth_scale: spec.depth_scale,
                });
            }
            if split == Split::Train { "training split" } else { "test split" }
        }
        _ => {
            images = every_labelled(&dir, spec)?;
            "every labelled image"
        }
    };
    if images.is_empty() {
        bail!(
            "{}: no labelled images (STEM.range, .png, .pgm, .tif, .tiff or .pcd with STEM.gt-seg)",
            dir.display()
        );
    }
    let camera = match (spec.camera, spec.inverted_depth) {
        (Some(c), None) => format!("{c:?}"),
        (Some(c), Some(o)) => format!("{c:?}, depth = {o} − stored value"),
        (None, _) => {
            "by file name (ABW calibration 0 or 1; nyu.K: nyu-grey; PNG, PGM, TIFF and PCD: the reader's, \
                      a pinhole camera in metres)"
                .to_string()
        }
    };
    let camera = match spec.depth_scale {
        Some(m) => format!("{camera}; depth × {m}"),
        None => camera,
    };
    Ok(DataSet { name, dir, selection, camera, images })
}

/// `nyu.K` (K a number): the name of the 8-bit NYU frames of Jin et al. (`../shared/data/nyu-planes`).
fn is_nyu_grey_stem(stem: &str) -> bool {
    stem.strip_prefix("nyu.").is_some_and(|k| !k.is_empty() && k.bytes().all(|b| b.is_ascii_digit()))
}

/// The extensions of range files a folder of labelled images may hold, in the order a stem's file is chosen by.
const RANGE_EXTENSIONS: [&str; 6] = ["range", "png", "pgm", "tif", "tiff", "pcd"];

/// Every range file in `dir` (`STEM.range`, else `STEM.png`, `.pgm`, `.tif`, `.tiff` or `.pcd`: the first of
/// [`RANGE_EXTENSIONS`]) with a `STEM.gt-seg` beside it, sorted by stem (numbers in natural order).
fn every_labelled(dir: &Path, spec: &DataSpec) -> Result<Vec<LabelledImage>> {
    let entries = std::fs::read_dir(dir).with_context(|| format!("{}: cannot list", dir.display()))?;
    let mut images = Vec::new();
    for entry in entries {
        let entry = entry.with_context(|| format!("{}: cannot list", dir.display()))?;
        let file_name = entry.file_name();
        let Some((stem, ext)) = file_name.to_str().and_then(|n| n.rsplit_once('.')) else { continue };
        let Some(rank) = RANGE_EXTENSIONS.iter().position(|&e| e == ext) else { continue };
        let gt_seg = dir.join(format!("{stem}.gt-seg"));
        // A stem with files of several extensions is read from the first of them.
        if !gt_seg.is_file()
            || RANGE_EXTENSIONS[..rank].iter().any(|e| dir.join(format!("{stem}.{e}")).is_file())
        {
            continue;
        }
        let (camera, inverted_depth) = match (spec.camera, rangeio::abw::camera_for_path(&entry.path())) {
            (Some(c), _) => (Some(c), spec.inverted_depth),
            (None, Some(c)) => (Some(c), None),
            (None, None) if ext == "range" && is_nyu_grey_stem(stem) => {
                (Some(rangeio::NYU_GREY.camera), Some(rangeio::NYU_GREY.inverted_depth))
            }
            // Sensor formats carry their units, and the reader knows their usual camera.
            (None, None) if ext != "range" => (None, None),
            (None, None) => {
                bail!("{}: no camera for this file name: pass --camera after --data", entry.path().display())
            }
        };
        let gt_ang = Some(dir.join(format!("{stem}.gt-ang"))).filter(|p| p.is_file());
        images.push(LabelledImage {
            stem: stem.to_string(),
            range: entry.path(),
            gt_seg,
            gt_ang,
            camera,
            inverted_depth,
            depth_scale: spec.depth_scale,
        });
    }
    images.sort_by_key(|img| natural_key(&img.stem));
    Ok(images)
}

/// A sort key that orders the digit runs of a name by value (`nyu.2` before `nyu.15`).
fn natural_key(s: &str) -> Vec<(String, u64)> {
    let mut key = Vec::new();
    let mut text = String::new();
    let mut chars = s.chars().peekable();
    while let Some(&c) = chars.peek() {
        if c.is_ascii_digit() {
            let mut n = 0u64;
            while let Some(d) = chars.peek().and_then(|c| c.to_digit(10)) {
                n = n.saturating_mul(10).saturating_add(u64::from(d));
                chars.next();
            }
            key.push((std::mem::take(&mut text), n));
        } else {
            text.push(c);
            chars.next();
        }
    }
    key.push((text, 0));
    key
}

#[cfg(test)]
mod tests {
    use super::*;

    fn args(s: &str) -> Vec<String> {
        s.split_whitespace().map(String::from).collect()
    }

    #[test]
    fn camera_follows_its_data() {
        let (specs, rest) = parse_specs(&args("--data a --data b --camera grid --out o")).unwrap();
        assert_eq!(specs.len(), 2);
        assert_eq!(specs[0], DataSpec::folder("a"));
        assert_eq!(specs[1], DataSpec { camera: Some(Camera::Grid), ..DataSpec::folder("b") });
        let (specs, _) = parse_specs(&args("--data n --camera nyu-grey")).unwrap();
        let nyu = rangeio::NYU_GREY;
        assert_eq!((specs[0].camera, specs[0].inverted_depth), (Some(nyu.camera), Some(nyu.inverted_depth)));
        assert_eq!(rest, args("--out o"));
        assert_eq!(parse_specs(&args("--data synthetic")).unwrap().0, vec![DataSpec::synthetic()]);
        let (specs, _) = parse_specs(&args("--data n --camera nyu-grey --depth-scale 0.001")).unwrap();
        assert_eq!(specs[0].depth_scale, Some(0.001));
        for bad in [
            "--depth-scale 2",
            "--data n --depth-scale 0",
            "--data n --depth-scale x",
            "--data n --depth-scale 1 --depth-scale 2",
        ] {
            assert!(parse_specs(&args(bad)).is_err(), "{bad}");
        }
    }

    #[test]
    fn synthetic_families_parse_with_their_strength() {
        let (specs, _) = parse_specs(&args("--data synthetic:stripes --data synthetic:kinect@0.5")).unwrap();
        assert_eq!(specs[0].family, Some((scenegen::Family::Stripes, 1.0)));
        assert_eq!(specs[1].family, Some((scenegen::Family::Kinect, 0.5)));
        assert_eq!(specs[1].dir, None);
        assert_eq!(specs[1].synthetic_name().as_deref(), Some("synthetic:kinect@0.5"));
        assert_eq!(DataSpec::synthetic().synthetic_name().as_deref(), Some("synthetic"));
        for bad in ["synthetic:nope", "synthetic:stripes@x", "synthetic:stripes@-1", "synthetic:abw@11"] {
            let err = DataSpec::parse(bad).unwrap_err();
            assert!(format!("{err:#}").contains(bad), "{err:#}");
        }
        // A folder that happens to start with `synthetic` but has no colon is a folder.
        assert_eq!(DataSpec::parse("synthetic-abw").unwrap(), DataSpec::folder("synthetic-abw"));
    }

    #[test]
    fn camera_without_data_or_twice_is_an_error() {
        assert!(parse_specs(&args("--camera grid")).is_err());
        assert!(parse_specs(&args("--data a --camera grid --camera grid")).is_err());
        assert!(parse_specs(&args("--data a --camera nonsense")).is_err());
    }

    #[test]
    fn natural_order() {
        let mut v = vec!["nyu.15", "nyu.2", "nyu.1436", "abw.test.10", "abw.test.9"];
        v.sort_by_key(|s| natural_key(s));
        assert_eq!(v, ["abw.test.9", "abw.test.10", "nyu.2", "nyu.15", "nyu.1436"]);
    }

    #[test]
    fn folder_without_abw_names_needs_a_camera() {
        let dir = std::env::temp_dir().join(format!("xtask-data-test-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let range = rangeimage::RangeImage::new(4, 4, 100.0);
        rangeio::abw::write_range(&dir.join("k.7.range"), &range).unwrap();
        rangeio::abw::write_labels(&dir.join("k.7.gt-seg"), &LabelImage::new(4, 4, 10)).unwrap();
        rangeio::abw::write_range(&dir.join("unlabelled.range"), &range).unwrap();
        let spec = DataSpec::folder(&dir);
        let err = discover(Path::new("."), &spec, Role::Eval).unwrap_err();
        assert!(format!("{err:#}").contains("k.7.range: no camera"), "{err:#}");
        let spec = DataSpec { camera: Some(Camera::Grid), ..DataSpec::folder(&dir) };
        let set = discover(Path::new("."), &spec, Role::Eval).unwrap();
        assert_eq!(set.images.len(), 1);
        assert_eq!(set.images[0].stem, "k.7");
        assert_eq!(set.selection, "every labelled image");
        let loaded = set.images[0].load().unwrap();
        assert_eq!(loaded.gt.dimensions(), (4, 4));
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn nyu_names_read_as_the_inverted_grey_rendering() {
        let dir = std::env::temp_dir().join(format!("xtask-data-nyu-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        rangeio::abw::write_range(&dir.join("nyu.15.range"), &rangeimage::RangeImage::new(4, 4, 100.0))
            .unwrap();
        rangeio::abw::write_labels(&dir.join("nyu.15.gt-seg"), &LabelImage::new(4, 4, 10)).unwrap();
        let spec = DataSpec::folder(&dir);
        let set = discover(Path::new("."), &spec, Role::Eval).unwrap();
        let nyu = rangeio::NYU_GREY;
        assert_eq!(
            (set.images[0].camera, set.images[0].inverted_depth),
            (Some(nyu.camera), Some(nyu.inverted_depth))
        );
        assert_eq!(set.images[0].load().unwrap().frame.range[(0, 0)], 270.0);
        // An explicit camera wins, without the inversion.
        let spec = DataSpec { camera: Some(Camera::Grid), ..spec };
        let set = discover(Path::new("."), &spec, Role::Eval).unwrap();
        assert_eq!(set.images[0].load().unwrap().frame.range[(0, 0)], 100.0);
        assert!(!is_nyu_grey_stem("nyu.") && !is_nyu_grey_stem("nyu.1a") && is_nyu_grey_stem("nyu.1436"));
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn sensor_formats_are_labelled_images_read_with_their_own_camera() {
        let dir = std::env::temp_dir().join(format!("xtask-data-png-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        // 16-bit PNG in TUM's units (1/5000 m): 10000 = 2 m.
        let depth = rangeimage::Grid::new(4, 3, 10000u16);
        rangeio::png::write_gray16_png(&dir.join("frame.1.png"), &depth).unwrap();
        rangeio::abw::write_labels(&dir.join("frame.1.gt-seg"), &LabelImage::new(4, 3, 10)).unwrap();
        // A stem with a .range and a .png is read from the .range; a .png without ground truth is skipped.
        rangeio::abw::write_range(&dir.join("frame.2.range"), &rangeimage::RangeImage::new(4, 3, 7.0))
            .unwrap();
        rangeio::png::write_gray16_png(&dir.join("frame.2.png"), &depth).unwrap();
        rangeio::abw::write_labels(&dir.join("frame.2.gt-seg"), &LabelImage::new(4, 3, 10)).unwrap();
        rangeio::png::write_gray16_png(&dir.join("unlabelled.png"), &depth).unwrap();
        let spec = DataSpec { camera: None, ..DataSpec::folder(&dir) };
        // frame.2.range has no camera by its name.
        let err = discover(Path::new("."), &spec, Role::Eval).unwrap_err();
        assert!(format!("{err:#}").contains("frame.2.range: no camera"), "{err:#}");
        std::fs::remove_file(dir.join("frame.2.range")).unwrap();
        let set = discover(Path::new("."), &spec, Role::Eval).unwrap();
        let stems: Vec<&str> = set.images.iter().map(|i| i.stem.as_str()).collect();
        assert_eq!(stems, ["frame.1", "frame.2"]);
        assert_eq!(set.images[0].camera, None);
        let loaded = set.images[0].load().unwrap();
        assert!((loaded.frame.range[(0, 0)] - 2.0).abs() < 1e-6, "{}", loaded.frame.range[(0, 0)]);
        assert_eq!(loaded.frame.camera, rangeio::default_pinhole(4, 3));
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn rooms_are_a_test_set_read_in_metres() {
        let spec = DataSpec::parse("synthetic:rooms@0.5").unwrap();
        assert_eq!(spec.rooms, Some(0.5));
        // No camera given: a 16-bit PNG of the rooms' size is read on the rooms' camera.
        assert_eq!(spec.camera, None);
        assert_eq!(rangeio::default_pinhole(640, 480), scenegen::RoomParams::default().camera());
        assert_eq!(spec.synthetic_name().as_deref(), Some("synthetic:rooms@0.5"));
        assert_eq!(DataSpec::parse("synthetic:rooms").unwrap().rooms, Some(1.0));
        let err = discover(Path::new("."), &spec, Role::Tune).unwrap_err();
        assert!(format!("{err:#}").contains("test set only"), "{err:#}");
        assert!(DataSpec::parse("synthetic:roomz").is_err());
    }
}
