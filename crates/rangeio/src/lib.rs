//! Reading and writing range images: ABW Sun rasterfiles, sensor depth formats, PNG outputs.
//!
//! - [`abw`]: the ABW benchmark files (docs/method.md §2.1): `.range`, `.gt-seg`, `.ms-seg` Sun rasterfiles,
//!   `.gt-ang` and `.ms-nor` text files, and [`abw::Dataset::discover`].
//! - [`read`]: any supported depth input (Sun rasterfile, PGM, PNG, TIFF, organized PCD), detected
//!   from its magic bytes, as a [`Frame`] with a range image, a camera and a record of the format.
//! - [`png`]: viewable outputs (depth, labels, edges) and edge maps read back.
//! - [`write_atomic`]: every writer goes through it, so an output is never half-written.
//!
//! # Units and defaults of [`read`]
//! | input | range values | default camera |
//! |---|---|---|
//! | Sun rasterfile | raw 8-bit ABW value `v` (0 → NaN) | ABW calibration by name (`abw.test.N`), else calibration 0 |
//! | 16-bit PNG | metres: value / 5000 (TUM convention) | pinhole fx=fy=525, cx=(w−1)/2, cy=(h−1)/2 |
//! | 16-bit TIFF | metres: value / 1000 (OpenNI millimetres) | same pinhole |
//! | 8-bit PNG/TIFF, any PGM | raw sample value | grid |
//! | PCD (organized) | the `z` field in metres | pinhole fitted to the points by least squares |
//!
//! `ReadOptions::depth_scale` replaces the scale (then the values are metres and the default
//! camera is the pinhole), `ReadOptions::camera` replaces the camera. Stored 0 is always no data
//! (NaN). NYU Depth v2 raw frames (PGM, little-endian 11-bit disparity) are read with
//! `pgm_little_endian` and `nyu_disparity_to_depth`, which gives `depth_m = 351.3 / (1092.5 − raw)`
//! with raw 2047 (and any raw ≥ 1092) as no data. Images that render depth nearer-is-brighter (the 8-bit NYU
//! frames of Jin et al., see [`NYU_GREY`]) are read with `inverted_depth`: `depth = offset − stored value`.

pub mod abw;
mod error;
pub mod lzf;
pub mod pcd;
pub mod pgm;
pub mod png;
mod raster;

pub use error::{ReadError, WriteError};

use rangeimage::{Camera, Grid, RangeImage};
use std::fmt;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

/// The largest width or height any reader accepts; larger headers are refused before allocating.
pub const MAX_SIDE: u32 = 32768;

/// The default pixel cap of [`ReadOptions::max_pixels`] (and of the readers that take no options):
/// 100 megapixels. The pipeline needs about 100 bytes per pixel at its peak, so this bounds one image
/// to roughly 10 GB; raise it with `ReadOptions::max_pixels` (the CLI's `--max-pixels`).
pub const DEFAULT_MAX_PIXELS: u64 = 100_000_000;

/// How [`read`] interprets an input file.
#[derive(Debug, Clone, PartialEq)]
pub struct ReadOptions {
    /// Metres per stored unit for PGM, PNG and TIFF samples; `None` uses the format's default
    /// (16-bit PNG 1/5000, 16-bit TIFF 1/1000, otherwise raw values).
    pub depth_scale: Option<f64>,
    /// Camera to report instead of the default one.
    pub camera: Option<Camera>,
    /// 16-bit PGM samples are little-endian (the NYU Depth v2 toolbox writes them so).
    pub pgm_little_endian: bool,
    /// Treat 16-bit samples as raw NYU/Kinect disparity: `depth_m = 351.3 / (1092.5 − raw)`,
    /// raw 2047 (or any raw ≥ 1092) = no data. Overrides `depth_scale`.
    pub nyu_disparity_to_depth: bool,
    /// The stored values render depth inverted, nearer = brighter: the range value becomes `this − stored`
    /// (in stored units; no data stays no data, and so does a result ≤ 0), applied after any scaling, to every format.
    pub inverted_depth: Option<f64>,
    /// The largest width × height accepted, checked from the header before any pixel is decoded
    /// (default [`DEFAULT_MAX_PIXELS`]).
    pub max_pixels: u64,
}

impl ReadOptions {
    /// These options for the 8-bit NYU frames of Jin et al.: [`NYU_GREY`]'s camera and inverted depth.
    pub fn nyu_grey(self) -> Self {
        Self { camera: Some(NYU_GREY.camera), inverted_depth: Some(NYU_GREY.inverted_depth), ..self }
    }
}

impl Default for ReadOptions {
    fn default() -> Self {
        Self {
            depth_scale: None,
            camera: None,
            pgm_little_endian: false,
            nyu_disparity_to_depth: false,
            inverted_depth: None,
            max_pixels: DEFAULT_MAX_PIXELS,
        }
    }
}

/// The file format a [`Frame`] was read from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[non_exhaustive]
pub enum Format {
    /// Sun rasterfile, 8-bit (ABW `.range`).
    SunRaster,
    /// Binary PGM (P5), 8 or 16 bits per sample.
    Pgm,
    /// PNG, 8 or 16-bit gray.
    Png,
    /// TIFF, 8 or 16-bit gray.
    Tiff,
    /// PCD with `DATA ascii`.
    PcdAscii,
    /// PCD with `DATA binary`.
    PcdBinary,
    /// PCD with `DATA binary_compressed` (LZF).
    PcdBinaryCompressed,
}

impl fmt::Display for Format {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Format::SunRaster => "sun rasterfile",
            Format::Pgm => "pgm",
            Format::Png => "png",
            Format::Tiff => "tiff",
            Format::PcdAscii => "pcd ascii",
            Format::PcdBinary => "pcd binary",
            Format::PcdBinaryCompressed => "pcd binary_compressed",
        })
    }
}

/// What the values of [`Frame::range`] mean.
#[derive(Debug, Clone, Copy, PartialEq)]
#[non_exhaustive]
pub enum Units {
    /// The raw 8-bit ABW range value (larger = farther).
    AbwRaw,
    /// Depth in metres, converted from stored samples by `stored · metres_per_unit`.
    Metres {
        /// The scale that was applied (1.0 if the file already stores metres).
        metres_per_unit: f64,
    },
    /// Depth in metres from raw NYU/Kinect disparity, `351.3 / (1092.5 − raw)`.
    NyuDisparity,
    /// The stored sample value, unscaled (units unknown: disparity, raw depth …).
    Raw,
    /// `offset − stored value`: depth in stored units from an inverted rendering (see `inverted_depth`).
    Inverted {
        /// The stored value of depth 0.
        offset: f64,
    },
}

impl fmt::Display for Units {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Units::AbwRaw => f.write_str("raw 8-bit abw value"),
            Units::Metres { metres_per_unit } if *metres_per_unit == 1.0 => f.write_str("m"),
            Units::Metres { metres_per_unit } => write!(f, "m (stored value × {metres_per_unit})"),
            Units::NyuDisparity => f.write_str("m (from nyu disparity: 351.3 / (1092.5 − raw))"),
            Units::Raw => f.write_str("raw sample value"),
            Units::Inverted { offset } => write!(f, "{offset} − stored value (inverted rendering of depth)"),
        }
    }
}

/// A range image read by [`read`], with its camera and where it came from.
#[derive(Debug, Clone, PartialEq)]
#[non_exhaustive]
pub struct Frame {
    /// The range values; NaN = no data.
    pub range: RangeImage,
    /// The camera that maps `(x, y, range)` to 3D points.
    pub camera: Camera,
    /// The file format.
    pub format: Format,
    /// What the range values mean.
    pub units: Units,
    /// Bits per stored sample (8, 16, 32 or 64).
    pub bits_per_sample: u8,
}

impl Frame {
    /// Fraction of pixels with data, in `0..=1`.
    pub fn valid_fraction(&self) -> f64 {
        let n = self.range.len();
        if n == 0 {
            0.0
        } else {
            self.range.as_slice().iter().filter(|v| !v.is_nan()).count() as f64 / n as f64
        }
    }

    /// Smallest and largest valid range value; `None` if no pixel has data.
    pub fn value_range(&self) -> Option<(f32, f32)> {
        value_range(&self.range)
    }
}

/// Smallest and largest non-NaN value of `range`; `None` if every pixel is NaN.
pub fn value_range(range: &RangeImage) -> Option<(f32, f32)> {
    range.as_slice().iter().filter(|v| !v.is_nan()).fold(None, |acc, &v| match acc {
        None => Some((v, v)),
        Some((lo, hi)) => Some((lo.min(v), hi.max(v))),
    })
}

/// Reads any supported depth file (see the crate docs for formats, units and default cameras).
///
/// The format is detected from the magic bytes; the extension only helps when they are ambiguous.
pub fn read(path: &Path, opts: &ReadOptions) -> Result<Frame, ReadError> {
    let bytes = read_file(path)?;
    read_bytes(&bytes, path, opts)
}

/// Like [`read`], for bytes already in memory; `path` names the file in errors and, for ABW
/// files, chooses the calibration.
pub fn read_bytes(bytes: &[u8], path: &Path, opts: &ReadOptions) -> Result<Frame, ReadError> {
    let ext = path.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase).unwrap_or_default();
    let head = &bytes[..bytes.len().min(16)];
    let is_sun = head.len() >= 4 && (head[..4] == abw::SUN_MAGIC_BE || head[..4] == abw::SUN_MAGIC_LE);
    let is_pgm = head.starts_with(b"P5") || head.starts_with(b"P2");
    let is_png = head.starts_with(b"\x89PNG\r\n\x1a\n");
    let is_tiff = head.starts_with(b"II*\0") || head.starts_with(b"MM\0*");
    let is_pcd = pcd::looks_like_pcd(bytes);
    let mut frame = if is_sun || (head.len() < 4 && matches!(ext.as_str(), "range" | "ras")) {
        let raw = abw::raster_from_bytes_limited(bytes, path, opts.max_pixels)?;
        let camera = abw::camera_for_path(path).unwrap_or(Camera::ABW0);
        Frame {
            range: abw::raw_to_range(&raw),
            camera,
            format: Format::SunRaster,
            units: Units::AbwRaw,
            bits_per_sample: 8,
        }
    } else if is_pgm || (!is_png && !is_tiff && !is_pcd && matches!(ext.as_str(), "pgm" | "pnm")) {
        let img = pgm::pgm_from_bytes_limited(bytes, path, opts.pgm_little_endian, opts.max_pixels)?;
        let (range, units) = scale_samples(&img.samples, opts, None);
        sensor_frame(range, Format::Pgm, units, img.bits)
    } else if is_png || is_tiff || (!is_pcd && matches!(ext.as_str(), "png" | "tif" | "tiff")) {
        let format = if is_png || (!is_tiff && ext == "png") { Format::Png } else { Format::Tiff };
        let (samples, bits) = raster::decode_gray(bytes, path, format, opts.max_pixels)?;
        let default = match (format, bits) {
            (Format::Png, 16) => Some(1.0 / 5000.0),
            (Format::Tiff, 16) => Some(1.0 / 1000.0),
            _ => None,
        };
        let (range, units) = scale_samples(&samples, opts, default);
        sensor_frame(range, format, units, bits)
    } else if is_pcd || ext == "pcd" {
        let cloud = pcd::pcd_from_bytes_limited(bytes, path, opts.max_pixels)?;
        let camera = pcd::estimate_camera(&cloud);
        Frame {
            range: cloud.z,
            camera,
            format: cloud.format,
            units: Units::Metres { metres_per_unit: 1.0 },
            bits_per_sample: cloud.z_bits,
        }
    } else {
        return Err(ReadError::UnknownFormat { path: path.to_path_buf() });
    };
    if let Some(offset) = opts.inverted_depth {
        // A value at or beyond the offset would put the point at or behind the camera: no data.
        frame.range = frame.range.map(|&v| {
            let d = offset - f64::from(v);
            if v.is_finite() && d > 0.0 { d as f32 } else { f32::NAN }
        });
        frame.units = Units::Inverted { offset };
    }
    if let Some(camera) = opts.camera {
        frame.camera = camera;
    }
    Ok(frame)
}

/// A frame from a sensor image: pinhole default camera for metric values, grid otherwise.
fn sensor_frame(range: RangeImage, format: Format, units: Units, bits: u8) -> Frame {
    let camera = match units {
        Units::Metres { .. } | Units::NyuDisparity => default_pinhole(range.width(), range.height()),
        Units::AbwRaw | Units::Raw | Units::Inverted { .. } => Camera::Grid,
    };
    Frame { range, camera, format, units, bits_per_sample: bits }
}

/// The default camera of a metric sensor frame: fx = fy = 525, principal point at the centre.
pub fn default_pinhole(width: u32, height: u32) -> Camera {
    Camera::Pinhole {
        fx: 525.0,
        fy: 525.0,
        cx: (f64::from(width) - 1.0) / 2.0,
        cy: (f64::from(height) - 1.0) / 2.0,
        depth_scale: 1.0,
    }
}

/// Converts stored samples (0 = no data) to range values according to the options.
fn scale_samples(samples: &Grid<u16>, opts: &ReadOptions, default: Option<f64>) -> (RangeImage, Units) {
    if opts.nyu_disparity_to_depth {
        let range = samples.map(|&raw| nyu_disparity_to_depth(raw));
        return (range, Units::NyuDisparity);
    }
    match opts.depth_scale.or(default) {
        Some(s) => (
            samples.map(|&v| if v == 0 { f32::NAN } else { (f64::from(v) * s) as f32 }),
            Units::Metres { metres_per_unit: s },
        ),
        None => (samples.map(|&v| if v == 0 { f32::NAN } else { f32::from(v) }), Units::Raw),
    }
}

/// Depth in metres of a raw NYU/Kinect disparity sample; NaN for 0, 2047 and raw ≥ 1092.
pub fn nyu_disparity_to_depth(raw: u16) -> f32 {
    if raw == 0 || raw >= 1092 { f32::NAN } else { (351.3 / (1092.5 - f64::from(raw))) as f32 }
}

/// How to read the 8-bit NYU Depth v2 frames that Jin et al. (2017) published with per-plane ground truth
/// (`rawDepth_K.bmp`, 564 × 427): the grey value renders depth nearer-is-brighter, close to linear in depth
/// (a plane's depth is the inverse of an affine function of the pixel, and `offset − grey` is that depth up to
/// scale: robust plane fits over the 151 GT planes of 20 frames leave a median 3.9 grey levels for offsets 350–500,
/// against 4.7 for the grey value itself and up to 10 on receding floors and ceilings; within that flat range the
/// segmentation does best at 355–385, so 370: docs/method.md §2.3), seen through the Kinect's
/// colour-camera intrinsics (fx 518.86, fy 519.47, principal point 325.58, 253.74 in the 640 × 480 frame) shifted
/// by the crop (38 columns, 44 rows). The scale of depth is unknown and does not matter to a plane.
pub const NYU_GREY: NyuGrey = NyuGrey {
    camera: Camera::Pinhole { fx: 518.86, fy: 519.47, cx: 287.58, cy: 209.74, depth_scale: 1.0 },
    inverted_depth: 370.0,
};

/// A camera together with the inverted-depth offset its images need (see [`NYU_GREY`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NyuGrey {
    /// The camera of the frames.
    pub camera: Camera,
    /// [`ReadOptions::inverted_depth`] for the frames.
    pub inverted_depth: f64,
}

/// Parses a camera spec: `abw0`, `abw1`, `pinhole:fx,fy,cx,cy[,depth_scale]` or `grid`.
pub fn parse_camera(s: &str) -> Result<Camera, String> {
    let s = s.trim();
    match s.to_ascii_lowercase().as_str() {
        "abw0" | "abw" => return Ok(Camera::ABW0),
        "abw1" => return Ok(Camera::ABW1),
        "grid" => return Ok(Camera::Grid),
        _ => {}
    }
    let Some(rest) = s.strip_prefix("pinhole:") else {
        return Err(format!(
            "unknown camera `{s}`: expected abw0, abw1, grid or pinhole:fx,fy,cx,cy[,depth_scale]"
        ));
    };
    let nums = rest
        .split(',')
        .map(|t| t.trim().parse::<f64>().map_err(|_| format!("camera `{s}`: `{}` is not a number", t.trim())))
        .collect::<Result<Vec<_>, _>>()?;
    if !(4..=5).contains(&nums.len()) {
        return Err(format!("camera `{s}`: pinhole needs 4 or 5 numbers (fx,fy,cx,cy[,depth_scale])"));
    }
    if nums.iter().any(|v| !v.is_finite()) {
        return Err(format!("camera `{s}`: numbers must be finite"));
    }
    let (fx, fy) = (nums[0], nums[1]);
    let depth_scale = nums.get(4).copied().unwrap_or(1.0);
    if fx <= 0.0 || fy <= 0.0 || depth_scale <= 0.0 {
        return Err(format!("camera `{s}`: fx, fy and depth_scale must be positive"));
    }
    Ok(Camera::Pinhole { fx, fy, cx: nums[2], cy: nums[3], depth_scale })
}

/// Reads a whole file, mapping errors to [`ReadError::Io`].
pub(crate) fn read_file(path: &Path) -> Result<Vec<u8>, ReadError> {
    std::fs::read(path).map_err(|error| ReadError::Io { path: path.to_path_buf(), error })
}

/// Checks header dimensions against [`MAX_SIDE`] and `max_pixels` and returns them as `usize`.
pub(crate) fn check_dims(
    path: &Path,
    width: u64,
    height: u64,
    max_pixels: u64,
) -> Result<(usize, usize), ReadError> {
    let max = u64::from(MAX_SIDE);
    if width == 0 || height == 0 || width > max || height > max {
        return Err(ReadError::Dimensions { path: path.to_path_buf(), width, height });
    }
    if width * height > max_pixels {
        return Err(ReadError::TooManyPixels { path: path.to_path_buf(), width, height, max_pixels });
    }
    Ok((width as usize, height as usize))
}

/// Temporary files of [`write_atomic`] now being written, and whether [`abort_writes`] was called.
struct InFlight {
    tmps: Vec<PathBuf>,
    aborted: bool,
}

static IN_FLIGHT: std::sync::Mutex<InFlight> =
    std::sync::Mutex::new(InFlight { tmps: Vec::new(), aborted: false });

fn in_flight() -> std::sync::MutexGuard<'static, InFlight> {
    IN_FLIGHT.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
}

/// Writes `bytes` to `path` atomically: a temporary file in the same directory, then a rename.
///
/// Readers see either the old file or the complete new one, never a partial write. The temporary
/// file (`.NAME.tmp.PID.N`) is registered while it exists, so [`abort_writes`] can remove it.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), WriteError> {
    static COUNTER: AtomicU64 = AtomicU64::new(0);
    let io = |error| WriteError::Io { path: path.to_path_buf(), error };
    let name = path.file_name().ok_or_else(|| WriteError::Invalid {
        path: path.to_path_buf(),
        what: "to a path without a file name".into(),
    })?;
    let dir = match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    };
    let tmp = dir.join(format!(
        ".{}.tmp.{}.{}",
        name.to_string_lossy(),
        std::process::id(),
        COUNTER.fetch_add(1, Ordering::Relaxed)
    ));
    // Registered and created under the lock: `abort_writes` either sees the file or stops it being made.
    let file = {
        let mut g = in_flight();
        if g.aborted {
            return Err(WriteError::Invalid {
                path: path.to_path_buf(),
                what: "after the process was interrupted".into(),
            });
        }
        let file = std::fs::File::create(&tmp).map_err(io)?;
        g.tmps.push(tmp.clone());
        file
    };
    let result = (|| {
        let mut f = file;
        f.write_all(bytes)?;
        f.sync_all()?;
        drop(f);
        std::fs::rename(&tmp, path)
    })();
    if result.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    let mut g = in_flight();
    g.tmps.retain(|t| t != &tmp);
    drop(g);
    result.map_err(io)
}

/// Removes the temporary file of every [`write_atomic`] in flight and makes later writes fail;
/// returns how many were removed. For a binary about to exit on a signal (SIGINT, SIGTERM): the
/// caller should exit while the writes are still blocked, so no temporary file is left behind.
pub fn abort_writes() -> usize {
    let mut g = in_flight();
    g.aborted = true;
    let n = g.tmps.iter().filter(|t| std::fs::remove_file(t).is_ok()).count();
    g.tmps.clear();
    n
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parse_camera_accepts_every_form() {
        assert_eq!(parse_camera("abw0"), Ok(Camera::ABW0));
        assert_eq!(parse_camera("ABW1"), Ok(Camera::ABW1));
        assert_eq!(parse_camera("grid"), Ok(Camera::Grid));
        assert_eq!(
            parse_camera("pinhole:525,525,319.5,239.5"),
            Ok(Camera::Pinhole { fx: 525.0, fy: 525.0, cx: 319.5, cy: 239.5, depth_scale: 1.0 })
        );
        assert_eq!(
            parse_camera("pinhole: 500, 501, 320, 240, 0.001"),
            Ok(Camera::Pinhole { fx: 500.0, fy: 501.0, cx: 320.0, cy: 240.0, depth_scale: 0.001 })
        );
    }

    #[test]
    fn inverted_depth_maps_every_format_and_keeps_no_data() {
        // An 8-bit PGM: 0 is no data, 100 and 250 become 270 and 120.
        let pgm = b"P5\n3 1\n255\n\x00\x64\xfa";
        let path = Path::new("x.pgm");
        let f = read_bytes(pgm, path, &ReadOptions::default().nyu_grey()).unwrap();
        assert!(f.range[(0, 0)].is_nan());
        assert_eq!((f.range[(1, 0)], f.range[(2, 0)]), (270.0, 120.0));
        assert_eq!(f.units, Units::Inverted { offset: 370.0 });
        assert_eq!(f.camera, NYU_GREY.camera);
        let plain = read_bytes(pgm, path, &ReadOptions::default()).unwrap();
        assert_eq!((plain.range[(1, 0)], plain.camera), (100.0, Camera::Grid));
        // Values at or beyond the offset (16-bit samples) would lie at or behind the camera: no data.
        let wide = b"P5\n3 1\n65535\n\x01\x72\x01\x73\x00\x64";
        let f = read_bytes(wide, path, &ReadOptions::default().nyu_grey()).unwrap();
        assert!(f.range[(0, 0)].is_nan() && f.range[(1, 0)].is_nan(), "370 and 371 → no data");
        assert_eq!(f.range[(2, 0)], 270.0);
    }

    #[test]
    fn parse_camera_rejects_bad_specs() {
        for bad in ["abw2", "pinhole:1,2,3", "pinhole:1,2,3,x", "pinhole:0,1,2,3", "pinhole:1,1,1,1,1,1", ""]
        {
            let e = parse_camera(bad).unwrap_err();
            assert!(e.contains("camera"), "{bad}: {e}");
        }
    }

    #[test]
    fn write_atomic_replaces_and_leaves_no_temp() {
        let dir = std::env::temp_dir().join(format!("rangeio-atomic-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join("out.bin");
        write_atomic(&p, b"first").unwrap();
        write_atomic(&p, b"second").unwrap();
        assert_eq!(std::fs::read(&p).unwrap(), b"second");
        let names: Vec<_> = std::fs::read_dir(&dir).unwrap().map(|e| e.unwrap().file_name()).collect();
        assert_eq!(names.len(), 1, "{names:?}");
        let missing = dir.join("no/such/dir/out.bin");
        let e = write_atomic(&missing, b"x").unwrap_err().to_string();
        assert!(e.starts_with(&format!("{}: ", missing.display())), "{e}");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// CRC-32 (ISO-HDLC) as PNG chunks use it.
    fn crc32(data: &[u8]) -> u32 {
        let mut c = !0u32;
        for &b in data {
            c ^= u32::from(b);
            for _ in 0..8 {
                c = if c & 1 != 0 { 0xedb8_8320 ^ (c >> 1) } else { c >> 1 };
            }
        }
        !c
    }

    /// A small 16-bit gray PNG whose header is patched to claim `width`×`height` (valid CRC).
    fn png_claiming(width: u32, height: u32) -> Vec<u8> {
        let mut png = Vec::new();
        image::ImageBuffer::<image::Luma<u16>, _>::from_raw(4, 3, vec![7u16; 12])
            .unwrap()
            .write_to(&mut std::io::Cursor::new(&mut png), image::ImageFormat::Png)
            .unwrap();
        png[16..20].copy_from_slice(&width.to_be_bytes());
        png[20..24].copy_from_slice(&height.to_be_bytes());
        let crc = crc32(&png[12..29]);
        png[29..33].copy_from_slice(&crc.to_be_bytes());
        png
    }

    #[test]
    fn pixel_cap_is_checked_from_the_header_before_decoding() {
        // 20000×20000 = 400 megapixels: refused by the default cap without decoding a pixel.
        let e = read_bytes(&png_claiming(20000, 20000), Path::new("huge.png"), &ReadOptions::default())
            .unwrap_err();
        assert!(matches!(e, ReadError::TooManyPixels { width: 20000, height: 20000, .. }), "{e}");
        let msg = e.to_string();
        assert!(msg.starts_with("huge.png: ") && msg.contains("--max-pixels"), "{msg}");
        // Every format obeys a lower cap.
        let small = ReadOptions { max_pixels: 11, ..ReadOptions::default() };
        let s16 = Grid::from_fn(4, 3, |x, y| (x * 1000 + y * 3 + 1) as u16);
        let z = Grid::from_fn(4, 3, |x, y| 1.0 + 0.1 * x as f32 + 0.01 * y as f32);
        let mut tiff = Vec::new();
        image::ImageBuffer::<image::Luma<u16>, _>::from_raw(4, 3, s16.as_slice().to_vec())
            .unwrap()
            .write_to(&mut std::io::Cursor::new(&mut tiff), image::ImageFormat::Tiff)
            .unwrap();
        let files = [
            (abw::raster_to_bytes(&Grid::new(4, 3, 9u8)), "a.range"),
            (pgm::pgm_to_bytes(&s16), "a.pgm"),
            (png_claiming(4, 3), "a.png"),
            (tiff, "a.tiff"),
            (pcd::pcd_to_bytes(&z, &z, &z, Format::PcdBinary), "a.pcd"),
        ];
        for (bytes, name) in &files {
            assert!(read_bytes(bytes, Path::new(name), &ReadOptions::default()).is_ok(), "{name}");
            let e = read_bytes(bytes, Path::new(name), &small).unwrap_err();
            assert!(matches!(e, ReadError::TooManyPixels { width: 4, height: 3, max_pixels: 11, .. }), "{e}");
        }
        let twelve = ReadOptions { max_pixels: 12, ..ReadOptions::default() };
        assert!(read_bytes(&files[0].0, Path::new("a.range"), &twelve).is_ok(), "the cap is inclusive");
    }

    #[test]
    fn nyu_conversion_matches_toolbox() {
        approx::assert_relative_eq!(nyu_disparity_to_depth(839), (351.3 / 253.5) as f32);
        assert!(nyu_disparity_to_depth(2047).is_nan());
        assert!(nyu_disparity_to_depth(0).is_nan());
    }

    #[test]
    fn unknown_format_is_an_error() {
        let e = read_bytes(b"hello world, not an image", Path::new("x.dat"), &ReadOptions::default())
            .unwrap_err();
        assert!(matches!(e, ReadError::UnknownFormat { .. }));
        assert_eq!(
            e.to_string(),
            "x.dat: unrecognised file format (expected sun rasterfile, pgm, png, tiff or pcd)"
        );
    }
}
