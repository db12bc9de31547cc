//! `rangeseg info`: format, size, camera, valid fraction and value range of range files.

use rangeimage::Camera;
use rangeio::{Frame, ReadOptions};
use std::io::Write;
use std::path::PathBuf;
use std::process::ExitCode;

/// How input files are interpreted; shared by the subcommands that read one.
#[derive(Debug, Clone, clap::Args)]
pub(crate) struct ReadArgs {
    /// Camera instead of the format's default: abw0, abw1, grid or pinhole:fx,fy,cx,cy[,depth_scale].
    #[arg(long, value_name = "SPEC", value_parser = rangeio::parse_camera)]
    pub(crate) camera: Option<Camera>,
    /// Metres per stored unit of PGM, PNG and TIFF samples
    /// [default: 16-bit PNG 1/5000 (TUM), 16-bit TIFF 1/1000 (mm), otherwise raw values].
    #[arg(long, value_name = "M", value_parser = parse_scale)]
    pub(crate) depth_scale: Option<f64>,
    /// 16-bit PGM samples are little-endian (as the NYU Depth v2 toolbox writes them).
    #[arg(long)]
    pub(crate) pgm_little_endian: bool,
    /// Samples are raw NYU/Kinect disparity: depth_m = 351.3 / (1092.5 − raw), 2047 = no data.
    #[arg(long)]
    pub(crate) nyu_disparity: bool,
    /// Inputs are the 8-bit NYU frames of Jin et al. (grey renders depth, nearer = brighter): depth = 370 − grey,
    /// Kinect intrinsics of their 564 × 427 crop (see docs/method.md §2.3). `--camera` still overrides the camera.
    #[arg(long, conflicts_with_all = ["nyu_disparity", "depth_scale"])]
    pub(crate) nyu_grey: bool,
    /// Refuse images of more pixels than this (width × height, read from the header before decoding).
    #[arg(long, value_name = "N", default_value_t = rangeio::DEFAULT_MAX_PIXELS)]
    pub(crate) max_pixels: u64,
}

impl ReadArgs {
    /// The reader options these flags select.
    pub(crate) fn options(&self) -> ReadOptions {
        let opts = ReadOptions {
            depth_scale: self.depth_scale,
            camera: self.camera,
            pgm_little_endian: self.pgm_little_endian,
            nyu_disparity_to_depth: self.nyu_disparity,
            inverted_depth: None,
            max_pixels: self.max_pixels,
        };
        if !self.nyu_grey {
            return opts;
        }
        let nyu = opts.nyu_grey();
        ReadOptions { camera: self.camera.or(nyu.camera), ..nyu }
    }
}

fn parse_scale(s: &str) -> Result<f64, String> {
    match s.parse::<f64>() {
        Ok(v) if v.is_finite() && v > 0.0 => Ok(v),
        _ => Err(format!("`{s}` is not a positive number")),
    }
}

/// Arguments of `rangeseg info`.
#[derive(Debug, clap::Args)]
pub(crate) struct Args {
    /// Range files: ABW Sun rasterfile, PGM, PNG, TIFF or organized PCD.
    #[arg(required = true, value_name = "FILE")]
    files: Vec<PathBuf>,
    #[command(flatten)]
    read: ReadArgs,
}

/// One-line description of a camera.
pub(crate) fn describe_camera(camera: &Camera) -> String {
    match *camera {
        c if c == Camera::ABW0 => "abw calibration 0".into(),
        c if c == Camera::ABW1 => "abw calibration 1".into(),
        Camera::Abw(cal) => {
            format!("abw offset={} scal={} f={} c={}", cal.offset, cal.scal, cal.f, cal.c)
        }
        Camera::Pinhole { fx, fy, cx, cy, depth_scale } => {
            let mut s = format!("pinhole fx={fx:.2} fy={fy:.2} cx={cx:.2} cy={cy:.2}");
            if depth_scale != 1.0 {
                s += &format!(" depth_scale={depth_scale}");
            }
            s
        }
        Camera::Grid => "grid (no calibration)".into(),
    }
}

fn describe(path: &std::path::Path, f: &Frame, little_endian: bool) -> String {
    let n = f.range.len();
    let valid = (f.valid_fraction() * n as f64).round() as usize;
    let range = match f.value_range() {
        Some((lo, hi)) => format!("{lo:.4} .. {hi:.4}"),
        None => "none (no valid pixel)".into(),
    };
    let est = planefit::noise::estimate(&f.range);
    let noise = if est.sigma.is_finite() {
        let step = est.step.map_or_else(|| "continuous".to_string(), |q| format!("step {q:.4}"));
        // What `segment` does with it (the default configuration: `pipeline.dequantise` on).
        let prepared = rangeseg::dequantise::for_config(
            &f.range,
            &f.camera,
            &rangeseg::Config::default(),
            &mut Vec::new(),
            &mut rangeseg::dequantise::Scratch::default(),
        );
        // A pinhole frame that is no staircase of its depth may be one of its inverse depth (a disparity's steps).
        let (stairs, disparity) = match prepared.dequantised {
            Some(_) => (!prepared.inverse_depth, prepared.inverse_depth),
            None => (false, false),
        };
        let stairs = if stairs {
            "; a staircase (noise below the step's rounding): dequantised by segment"
        } else if disparity {
            "; a staircase of its inverse depth (a disparity in uniform steps, noise below their rounding): \
             dequantised by segment"
        } else {
            ""
        };
        format!("σ {:.4} around 5×5 planes, {step}{stairs}", est.sigma)
    } else {
        "unknown (fewer than 20 full 5×5 windows)".into()
    };
    format!(
        "{}\n  format  {}, {}-bit\n  size    {}x{}\n  units   {}\n  camera  {}\n  valid   {:.2}% ({valid} of {n} pixels)\n  range   {range}\n  noise   {noise}\n{}",
        path.display(),
        f.format,
        f.bits_per_sample,
        f.range.width(),
        f.range.height(),
        f.units,
        describe_camera(&f.camera),
        100.0 * f.valid_fraction(),
        byte_order_hint(f, est.sigma, little_endian),
    )
}

/// A line for 16-bit PGM samples read raw that are far smoother in the other byte order (σ around 5 × 5 planes under
/// a sixteenth): the NYU Depth v2 toolbox writes little-endian PGM, which the format's own big-endian order reads as
/// noise of hundreds of units. Empty otherwise.
fn byte_order_hint(f: &Frame, sigma: f64, little_endian: bool) -> String {
    let raw =
        matches!(f.units, rangeio::Units::Raw) && f.format == rangeio::Format::Pgm && f.bits_per_sample == 16;
    if !raw || !sigma.is_finite() {
        return String::new();
    }
    // Whole samples of 0..=65535 as read; swapped, they stay whole and in range.
    let swapped = f.range.map(|&v| if v.is_finite() { f32::from((v as u16).swap_bytes()) } else { v });
    let other = planefit::noise::estimate(&swapped).sigma;
    if other.is_finite() && other * 16.0 < sigma {
        let how = if little_endian {
            "without --pgm-little-endian they are read so"
        } else {
            "--pgm-little-endian reads them so (NYU Depth v2's raw frames)"
        };
        let smoother = if other > 0.0 { format!("{:.0} times", sigma / other) } else { "far".to_string() };
        format!(
            "  hint    in the other byte order the samples are {smoother} smoother (σ {other:.4}): {how}\n"
        )
    } else {
        String::new()
    }
}

/// Runs `rangeseg info`: every file is described; the exit code is 0 only if all were read.
pub(crate) fn run(args: Args) -> anyhow::Result<ExitCode> {
    let opts = args.read.options();
    let mut failed = 0;
    for path in &args.files {
        match rangeio::read(path, &opts) {
            Ok(frame) => {
                let mut out = std::io::stdout().lock();
                out.write_all(describe(path, &frame, opts.pgm_little_endian).as_bytes())?;
                out.flush()?;
            }
            Err(e) => {
                failed += 1;
                eprintln!("error: {e}");
            }
        }
    }
    Ok(if failed == 0 { ExitCode::SUCCESS } else { ExitCode::FAILURE })
}
