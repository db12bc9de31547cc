//! The ABW benchmark files (docs/method.md §2.1): Sun rasterfiles, `.gt-ang`/`.ms-nor` text, directory discovery.

use crate::{ReadError, WriteError, check_dims, read_file, write_atomic};
use rangeimage::{Camera, Grid, LabelImage, RangeImage};
use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// The Sun rasterfile magic number as stored big-endian (the standard byte order).
pub const SUN_MAGIC_BE: [u8; 4] = [0x59, 0xa6, 0x6a, 0x95];
/// The Sun rasterfile magic number as stored by a little-endian writer.
pub const SUN_MAGIC_LE: [u8; 4] = [0x95, 0x6a, 0xa6, 0x59];
const HEADER_LEN: usize = 32;

/// Decodes an 8-bit Sun rasterfile (docs/method.md §2.1) into its raw byte values; `path` names the file in errors.
///
/// Accepts both byte orders of the header, skips `maplength` bytes of colour map and drops the pad
/// byte that ends each row of odd width. Types 0 (old), 1 (standard) and 3 (RGB, same layout at
/// 8 bits) are read; type 2 (run-length encoded) and any depth other than 8 are refused.
pub fn raster_from_bytes(bytes: &[u8], path: &Path) -> Result<Grid<u8>, ReadError> {
    raster_from_bytes_limited(bytes, path, crate::DEFAULT_MAX_PIXELS)
}

/// [`raster_from_bytes`] refusing headers of more than `max_pixels` pixels.
pub(crate) fn raster_from_bytes_limited(
    bytes: &[u8],
    path: &Path,
    max_pixels: u64,
) -> Result<Grid<u8>, ReadError> {
    let p = || path.to_path_buf();
    if bytes.len() < 4 {
        return Err(ReadError::Truncated {
            path: p(),
            what: "sun rasterfile header",
            expected: HEADER_LEN as u64,
            found: bytes.len() as u64,
        });
    }
    let big = match [bytes[0], bytes[1], bytes[2], bytes[3]] {
        SUN_MAGIC_BE => true,
        SUN_MAGIC_LE => false,
        _ => {
            return Err(ReadError::BadMagic {
                path: p(),
                expected: "sun rasterfile",
                found: format!("{:02x}{:02x}{:02x}{:02x}", bytes[0], bytes[1], bytes[2], bytes[3]),
            });
        }
    };
    if bytes.len() < HEADER_LEN {
        return Err(ReadError::Truncated {
            path: p(),
            what: "sun rasterfile header",
            expected: HEADER_LEN as u64,
            found: bytes.len() as u64,
        });
    }
    let word = |i: usize| {
        let b = [bytes[4 * i], bytes[4 * i + 1], bytes[4 * i + 2], bytes[4 * i + 3]];
        if big { u32::from_be_bytes(b) } else { u32::from_le_bytes(b) }
    };
    let (width, height, depth, length, kind, maptype, maplength) =
        (word(1), word(2), word(3), word(4), word(5), word(6), word(7));
    let (w, h) = check_dims(path, width.into(), height.into(), max_pixels)?;
    if depth != 8 {
        return Err(ReadError::Unsupported {
            path: p(),
            what: format!("sun rasterfile depth {depth} (only 8-bit rasters are read)"),
        });
    }
    match kind {
        0 | 1 | 3 => {}
        2 => {
            return Err(ReadError::Unsupported {
                path: p(),
                what: "sun rasterfile type 2 (run-length encoded)".into(),
            });
        }
        t => return Err(ReadError::Invalid { path: p(), what: format!("sun rasterfile type {t}") }),
    }
    if maptype > 2 {
        return Err(ReadError::Invalid { path: p(), what: format!("sun rasterfile maptype {maptype}") });
    }
    if maplength != 0 {
        tracing::debug!(path = %path.display(), maplength, "skipping sun rasterfile colour map");
    }
    let data_start = HEADER_LEN as u64 + u64::from(maplength);
    let padded_row = w + (w & 1);
    let padded = (padded_row * h) as u64;
    let unpadded = (w * h) as u64;
    let available = (bytes.len() as u64).saturating_sub(data_start);
    // Standard files pad odd rows to 16 bits; accept an unpadded file only when its header says so.
    let row_stride = if available >= padded {
        padded_row
    } else if w % 2 == 1 && u64::from(length) == unpadded && available >= unpadded {
        w
    } else {
        return Err(ReadError::Truncated {
            path: p(),
            what: "sun rasterfile pixel data",
            expected: data_start + padded,
            found: bytes.len() as u64,
        });
    };
    let data = &bytes[data_start as usize..];
    let mut out = Vec::with_capacity(w * h);
    for y in 0..h {
        out.extend_from_slice(&data[y * row_stride..y * row_stride + w]);
    }
    Ok(Grid::from_vec(width, height, out).expect("length matches"))
}

/// Encodes 8-bit values as a standard big-endian Sun rasterfile (odd rows padded to 16 bits).
pub fn raster_to_bytes(img: &Grid<u8>) -> Vec<u8> {
    let (w, h) = (img.width() as usize, img.height() as usize);
    let padded_row = w + (w & 1);
    let mut out = Vec::with_capacity(HEADER_LEN + padded_row * h);
    out.extend_from_slice(&SUN_MAGIC_BE);
    for v in [img.width(), img.height(), 8, (padded_row * h) as u32, 1, 0, 0] {
        out.extend_from_slice(&v.to_be_bytes());
    }
    for row in img.rows() {
        out.extend_from_slice(row);
        if w % 2 == 1 {
            out.push(0);
        }
    }
    out
}

fn write_raster(path: &Path, img: &Grid<u8>) -> Result<(), WriteError> {
    if img.is_empty() {
        return Err(WriteError::Invalid { path: path.to_path_buf(), what: "an empty image".into() });
    }
    write_atomic(path, &raster_to_bytes(img))
}

/// Raw 8-bit values to a range image: 0 → NaN, else `v as f32`.
pub fn raw_to_range(raw: &Grid<u8>) -> RangeImage {
    raw.map(|&v| if v == 0 { f32::NAN } else { f32::from(v) })
}

/// Range image to raw 8-bit values: NaN → 0, else rounded and clamped to `1..=255`.
pub fn range_to_raw(range: &RangeImage) -> Grid<u8> {
    range.map(|&v| if v.is_nan() { 0 } else { v.round().clamp(1.0, 255.0) as u8 })
}

/// Reads an ABW `.range` file: 8-bit `v`, 0 → NaN, otherwise `v as f32`.
pub fn read_range(path: &Path) -> Result<RangeImage, ReadError> {
    Ok(raw_to_range(&raster_from_bytes(&read_file(path)?, path)?))
}

/// Writes an ABW `.range` file: NaN → 0, otherwise rounded and clamped to `1..=255`.
pub fn write_range(path: &Path, range: &RangeImage) -> Result<(), WriteError> {
    write_raster(path, &range_to_raw(range))
}

/// Reads an ABW label file (`.gt-seg`, `.ms-seg`).
///
/// Values 0..=3 (no data, noise, too small) become 0 = unlabelled; larger values are kept.
/// With `check`, labels 4..=9 are an error, and so are region labels that are not consecutive from 10.
pub fn read_labels(path: &Path, check: bool) -> Result<LabelImage, ReadError> {
    labels_from_bytes(&read_file(path)?, path, check)
}

/// [`read_labels`] on bytes in memory; `path` names the file in errors.
pub fn labels_from_bytes(bytes: &[u8], path: &Path, check: bool) -> Result<LabelImage, ReadError> {
    let raw = raster_from_bytes(bytes, path)?;
    if check {
        check_labels(&raw, path)?;
    }
    Ok(raw.map(|&v| if v <= 3 { 0 } else { u32::from(v) }))
}

fn check_labels(raw: &Grid<u8>, path: &Path) -> Result<(), ReadError> {
    let mut seen = [false; 256];
    for (x, y, &v) in raw.enumerate() {
        if (4..=9).contains(&v) {
            return Err(ReadError::Label {
                path: path.to_path_buf(),
                problem: format!(
                    "illegal label {v} at pixel (x {x}, y {y}): labels 4..9 are reserved (0..3 unlabelled, regions from 10)"
                ),
            });
        }
        seen[usize::from(v)] = true;
    }
    if let Some(max) = (10..256).rev().find(|&l| seen[l])
        && let Some(gap) = (10..max).find(|&l| !seen[l])
    {
        return Err(ReadError::Label {
            path: path.to_path_buf(),
            problem: format!("region labels are not consecutive from 10: {gap} is missing but {max} is used"),
        });
    }
    Ok(())
}

/// The most regions an 8-bit label file holds (labels 10..=255).
pub const MAX_REGIONS: usize = 246;

/// Writes a label image as an 8-bit ABW label file and returns the `(old, new)` label pairs kept.
///
/// 0 stays 0. If every label is 0 or in `10..=255`, labels are written unchanged (the pairs map each
/// label present to itself, ascending). Otherwise the 246 largest regions (ties: earlier first
/// appearance) are renumbered from 10 in raster order of first appearance and the rest set to 0;
/// the pairs are sorted by new label (a debug event says how many regions were dropped; callers report it).
pub fn write_labels(path: &Path, labels: &LabelImage) -> Result<Vec<(u32, u8)>, WriteError> {
    let stats = label_stats(labels);
    let (raw, pairs) = raw_from_stats(labels, &stats);
    if pairs.len() < stats.len() {
        tracing::debug!(
            path = %path.display(),
            dropped = stats.len() - pairs.len(),
            kept = pairs.len(),
            "8-bit label file holds at most 246 regions: the smallest were set to 0"
        );
    }
    write_raster(path, &raw)?;
    Ok(pairs)
}

/// Calls `f(label, start, length)` for each run of equal values of `labels`, in order (runs go on across rows).
/// A segmentation's labels come in long runs, so per-label tables are updated once a run, not once a pixel.
pub fn for_each_run(labels: &[u32], mut f: impl FnMut(u32, usize, usize)) {
    let mut start = 0;
    while let Some(&l) = labels.get(start) {
        let len = labels[start..].iter().position(|&v| v != l).unwrap_or(labels.len() - start);
        f(l, start, len);
        start += len;
    }
}

/// `(label, pixel count, first pixel index)` of every non-zero label, by increasing label: in per-label tables
/// when the largest label is at most the pixel count (a segmentation's labels 1..n), else in a map.
fn label_stats(labels: &LabelImage) -> Vec<(u32, u64, usize)> {
    let max = labels.as_slice().iter().copied().max().unwrap_or(0) as usize;
    if max <= labels.len() {
        let mut t = vec![(0u64, 0usize); max + 1];
        for_each_run(labels.as_slice(), |l, start, len| {
            let e = &mut t[l as usize];
            if e.0 == 0 {
                e.1 = start;
            }
            e.0 += len as u64;
        });
        return (1..=max).filter(|&l| t[l].0 > 0).map(|l| (l as u32, t[l].0, t[l].1)).collect();
    }
    // label -> (size, first appearance)
    let mut stats: BTreeMap<u32, (u64, usize)> = BTreeMap::new();
    for_each_run(labels.as_slice(), |l, start, len| {
        if l != 0 {
            stats.entry(l).or_insert((0, start)).0 += len as u64;
        }
    });
    stats.iter().map(|(&l, &(n, first))| (l, n, first)).collect()
}

/// The 8-bit encoding of [`write_labels`] without the file: values and `(old, new)` pairs.
pub fn labels_to_raw(labels: &LabelImage) -> (Grid<u8>, Vec<(u32, u8)>) {
    raw_from_stats(labels, &label_stats(labels))
}

/// [`labels_to_raw`] given the [`label_stats`] of `labels`.
fn raw_from_stats(labels: &LabelImage, stats: &[(u32, u64, usize)]) -> (Grid<u8>, Vec<(u32, u8)>) {
    // Every label 0 or in 10..=255: written unchanged.
    if stats.iter().all(|&(l, _, _)| (10..=255).contains(&l)) {
        let pairs = stats.iter().map(|&(l, _, _)| (l, l as u8)).collect();
        return (labels.map(|&l| l as u8), pairs);
    }
    let mut by_size = stats.to_vec();
    by_size.sort_by(|a, b| b.1.cmp(&a.1).then(a.2.cmp(&b.2)));
    by_size.truncate(MAX_REGIONS);
    by_size.sort_by_key(|&(_, _, first)| first);
    let pairs: Vec<(u32, u8)> =
        by_size.iter().enumerate().map(|(i, &(l, _, _))| (l, (10 + i) as u8)).collect();
    // The largest label (the stats are by increasing label), as `label_stats` read it.
    let max = stats.last().map_or(0, |&(l, _, _)| l as usize);
    let raw = if max <= labels.len() {
        let mut table = vec![0u8; max + 1];
        for &(l, new) in &pairs {
            table[l as usize] = new;
        }
        labels.map(|&l| table[l as usize])
    } else {
        let map: BTreeMap<u32, u8> = pairs.iter().copied().collect();
        labels.map(|l| map.get(l).copied().unwrap_or(0))
    };
    (raw, pairs)
}

/// One line of a `.gt-ang` file: the angle between two adjacent ground-truth planes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AdjacentAngle {
    /// First region label.
    pub a: u32,
    /// Second region label.
    pub b: u32,
    /// Angle between the two planes, in degrees.
    pub angle_deg: f64,
}

/// Splits a count-prefixed text file into its `n` data lines as `(line number, fields)`.
fn counted_lines<'a>(
    text: &'a str,
    path: &Path,
    fields: usize,
) -> Result<Vec<(usize, Vec<&'a str>)>, ReadError> {
    let parse_err =
        |line: usize, problem: String| ReadError::Parse { path: path.to_path_buf(), line, problem };
    let mut lines = text.lines().enumerate().map(|(i, l)| (i + 1, l.trim())).filter(|(_, l)| !l.is_empty());
    let Some((first_no, first)) = lines.next() else {
        return Err(parse_err(1, "empty file: expected the number of entries".into()));
    };
    let n: usize = first
        .parse()
        .map_err(|_| parse_err(first_no, format!("expected the number of entries, found `{first}`")))?;
    let rows: Vec<_> = lines.map(|(no, l)| (no, l.split_whitespace().collect::<Vec<_>>())).collect();
    if rows.len() != n {
        let line = rows.last().map_or(first_no, |r| r.0);
        return Err(parse_err(line, format!("header says {n} entries but the file has {}", rows.len())));
    }
    for (no, f) in &rows {
        if f.len() != fields {
            return Err(parse_err(*no, format!("expected {fields} fields, found {}", f.len())));
        }
    }
    Ok(rows)
}

fn parse_field<T: std::str::FromStr>(
    path: &Path,
    line: usize,
    tok: &str,
    what: &str,
) -> Result<T, ReadError> {
    tok.parse().map_err(|_| ReadError::Parse {
        path: path.to_path_buf(),
        line,
        problem: format!("expected {what}, found `{tok}`"),
    })
}

fn read_text(path: &Path) -> Result<String, ReadError> {
    String::from_utf8(read_file(path)?)
        .map_err(|_| ReadError::Invalid { path: path.to_path_buf(), what: "text: not utf-8".into() })
}

/// Reads a `.gt-ang` file: a count `N`, then `N` lines `labelA labelB angle_deg`.
pub fn read_angles(path: &Path) -> Result<Vec<AdjacentAngle>, ReadError> {
    angles_from_str(&read_text(path)?, path)
}

/// [`read_angles`] on text in memory; `path` names the file in errors.
pub fn angles_from_str(text: &str, path: &Path) -> Result<Vec<AdjacentAngle>, ReadError> {
    counted_lines(text, path, 3)?
        .into_iter()
        .map(|(no, f)| {
            let angle_deg: f64 = parse_field(path, no, f[2], "an angle in degrees")?;
            if !angle_deg.is_finite() {
                return Err(ReadError::Parse {
                    path: path.to_path_buf(),
                    line: no,
                    problem: "angle is not finite".into(),
                });
            }
            Ok(AdjacentAngle {
                a: parse_field(path, no, f[0], "a label")?,
                b: parse_field(path, no, f[1], "a label")?,
                angle_deg,
            })
        })
        .collect()
}

/// Writes a `.gt-ang` file.
pub fn write_angles(path: &Path, angles: &[AdjacentAngle]) -> Result<(), WriteError> {
    let mut s = format!("{}\n", angles.len());
    for a in angles {
        let _ = writeln!(s, "{} {} {}", a.a, a.b, a.angle_deg);
    }
    write_atomic(path, s.as_bytes())
}

/// Reads a `.ms-nor` file: a count `N`, then `N` lines `label nx ny nz`.
pub fn read_normals(path: &Path) -> Result<Vec<(u32, [f32; 3])>, ReadError> {
    normals_from_str(&read_text(path)?, path)
}

/// [`read_normals`] on text in memory; `path` names the file in errors.
pub fn normals_from_str(text: &str, path: &Path) -> Result<Vec<(u32, [f32; 3])>, ReadError> {
    counted_lines(text, path, 4)?
        .into_iter()
        .map(|(no, f)| {
            let label = parse_field(path, no, f[0], "a label")?;
            let mut n = [0f32; 3];
            for k in 0..3 {
                n[k] = parse_field(path, no, f[k + 1], "a normal component")?;
            }
            Ok((label, n))
        })
        .collect()
}

/// Writes a `.ms-nor` file.
pub fn write_normals(path: &Path, normals: &[(u32, [f32; 3])]) -> Result<(), WriteError> {
    let mut s = format!("{}\n", normals.len());
    for (l, n) in normals {
        let _ = writeln!(s, "{l} {} {} {}", n[0], n[1], n[2]);
    }
    write_atomic(path, s.as_bytes())
}

/// Which half of the ABW benchmark an image belongs to.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Split {
    /// `abw.train.N`.
    Train,
    /// `abw.test.N`.
    Test,
}

/// One image of an ABW-layout directory.
#[derive(Debug, Clone, PartialEq)]
pub struct AbwImage {
    /// The name without extension, e.g. `"abw.test.7"`.
    pub stem: String,
    /// Train or test.
    pub split: Split,
    /// `N` in the name.
    pub index: u32,
    /// The `.range` file.
    pub range: PathBuf,
    /// The `.gt-seg` file, if present.
    pub gt_seg: Option<PathBuf>,
    /// The `.gt-ang` file, if present.
    pub gt_ang: Option<PathBuf>,
    /// The calibration of this image (docs/method.md §2.1).
    pub camera: Camera,
}

/// The images of a directory laid out like the original ABW set.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Dataset {
    /// `abw.train.N`, sorted by `N`.
    pub train: Vec<AbwImage>,
    /// `abw.test.N`, sorted by `N`.
    pub test: Vec<AbwImage>,
}

/// Parses `abw.{train,test}.N` (with or without extension) into split and index.
pub fn parse_stem(name: &str) -> Option<(Split, u32)> {
    let rest = name.strip_prefix("abw.")?;
    let (split, rest) = if let Some(r) = rest.strip_prefix("train.") {
        (Split::Train, r)
    } else {
        (Split::Test, rest.strip_prefix("test.")?)
    };
    let digits = rest.split('.').next()?;
    if digits.is_empty() || !digits.bytes().all(|b| b.is_ascii_digit()) {
        return None;
    }
    Some((split, digits.parse().ok()?))
}

/// The ABW camera chosen by a file name like `abw.test.19.range`; `None` for other names.
pub fn camera_for_path(path: &Path) -> Option<Camera> {
    let (split, index) = parse_stem(path.file_name()?.to_str()?)?;
    Some(Camera::abw_for(split == Split::Test, index))
}

impl Dataset {
    /// Finds `abw.train.N.range` and `abw.test.N.range` (with optional `.gt-seg`, `.gt-ang`) in `dir`.
    pub fn discover(dir: &Path) -> Result<Dataset, ReadError> {
        let entries =
            std::fs::read_dir(dir).map_err(|error| ReadError::Io { path: dir.to_path_buf(), error })?;
        let mut ds = Dataset::default();
        for entry in entries {
            let entry = entry.map_err(|error| ReadError::Io { path: dir.to_path_buf(), error })?;
            let name = entry.file_name();
            let Some(name) = name.to_str() else { continue };
            let Some(stem) = name.strip_suffix(".range") else { continue };
            let Some((split, index)) = parse_stem(stem) else { continue };
            if format!("abw.{}.{index}", if split == Split::Test { "test" } else { "train" }) != stem {
                continue;
            }
            let sibling = |ext: &str| Some(dir.join(format!("{stem}.{ext}"))).filter(|p| p.is_file());
            let img = AbwImage {
                stem: stem.to_string(),
                split,
                index,
                range: entry.path(),
                gt_seg: sibling("gt-seg"),
                gt_ang: sibling("gt-ang"),
                camera: Camera::abw_for(split == Split::Test, index),
            };
            match split {
                Split::Train => ds.train.push(img),
                Split::Test => ds.test.push(img),
            }
        }
        if ds.train.is_empty() && ds.test.is_empty() {
            return Err(ReadError::NoAbwFiles { path: dir.to_path_buf() });
        }
        ds.train.sort_by_key(|i| i.index);
        ds.test.sort_by_key(|i| i.index);
        Ok(ds)
    }
}
