//! Working units: the depth scale the pipeline runs an image in, chosen from the image's own noise.
//!
//! The distance parameters of region growing and of the final segmentation (`max_residual`,
//! `merge_max_residual`, `fill_max_residual`, …) and the curvature thresholds were tuned on images whose
//! depth noise around local planes, σ from [`planefit::noise::sigma_sampled`], is 0.3–0.7 of their units
//! (ABW in its calibration's units, the NYU grey frames, the synthetic benchmark). A Kinect frame in metres
//! has σ = 0.001–0.02: read as it is, those parameters would let every plane of a room merge into one (a
//! TUM frame gave 3 regions, the largest with an RMS of 34 cm).
//!
//! So a pinhole image is scaled so that its σ is [`PINHOLE_SIGMA`]: a uniform scale of a pinhole image is a
//! similarity of its 3D points (planes, angles and labels keep their meaning, only distances scale), and the
//! result no longer depends on the depth unit (metres and centimetres give the same labels up to rounding).
//! A grid image (pixel coordinates and raw depth values) is scaled only when its σ lies outside
//! [`GRID_SIGMA_BAND`], to the band's nearest end: its depth unit is also the unit of its slopes, so a
//! scale changes its angles. So it is scaled up (or, noise-free, scaled at all) only until its steep slopes reach
//! [`GRID_STEEP_SLOPE`]: steeper, planes' normals crowd together. ABW images keep their calibrated units (the ABW
//! camera is not linear in the stored value). σ is at least the rounding error of the image's depth step q, `q / √12`
//! ([`planefit::noise::step_from_smallest`]; the step test runs only when σ
//! is below that): noise-free quantised depth (rendered, or a sensor that smooths before it rounds) reads
//! σ ≈ 0 where most windows lie within one step, and scaled by that, every step became a jump. docs/method.md §2.5 has the measurements.
//! A staircase the pipeline dequantised ([`crate::dequantise`]) has no step left to read: its σ is floored at a
//! share of its step's rounding error instead ([`crate::dequantise::SIGMA_FLOOR_SHARE`]).
//! Depth with neither noise nor a step (a renderer's floats) reads σ = 0 or float rounding: a pinhole image's σ is at
//! least [`PINHOLE_PITCH_SHARE`] of its pixel pitch.
//! A pinhole or ABW image whose σ exceeds [`MAX_NOISE_PITCHES`] pixel pitches is also stretched across (its camera's
//! focal length divided): an affine map of its 3D points under which 5 × 5 windows span more than the noise.

use rangeimage::{Camera, RangeImage};

/// The noise σ a pinhole image is scaled to: the low end of the tuning images' 0.31–0.69 (the NYU frames do
/// best there: docs/method.md §2.5).
pub const PINHOLE_SIGMA: f64 = 0.25;
/// Grid images whose σ lies within this range run in their own units; others are scaled to its nearest end.
pub const GRID_SIGMA_BAND: (f64, f64) = (0.25, 1.0);
/// A pinhole image without a depth step (neither rounded nor dequantised) has a σ of at least this share of its pixel
/// pitch (the 3D distance between horizontally neighbouring pixels at the image centre and the image's mean depth):
/// rendered depth without noise or rounding reads σ = 0 where most windows see walls head-on, and would run in its own
/// units, metres, where a room merges into one.
/// The real sensor frames we have (Kinect, stereo, structured light) read 0.3–2 pitches, so the floor leaves them alone.
pub const PINHOLE_PITCH_SHARE: f64 = 0.1;
/// A pinhole or ABW image whose σ exceeds this many pixel pitches is stretched across: seen through a camera of focal
/// length divided by σ / (this × pitch), its rows and columns spread against its depth ([`WorkingUnits::stretch`]).
/// Its 5 × 5 windows then span more than its noise, so their normals mean something; the stretch is an affine map of
/// its 3D points, so planes stay planes (their normals tilt, and are tilted back: [`WorkingUnits::input_normal`]).
/// Kinect-like depth (σ ∝ depth², several pitches on far walls) needs it; the NYU frames read at most 1.36 pitches,
/// the synthetic benchmark 1.53, the real ABW images 1.03.
pub const MAX_NOISE_PITCHES: f64 = 2.0;
/// A grid image scaled up (σ below [`GRID_SIGMA_BAND`], or 0) is scaled at most as much as brings its steep slopes,
/// the [`GRID_SLOPE_QUANTILE`] of its gradients, to this many depth units a pixel (and never down): on the grid camera
/// a scale also steepens every slope, and planes whose slopes all exceed a few units a pixel have normals a few degrees
/// apart, which region growing joins. A noise-free grid image (σ = 0) is scaled that much.
pub const GRID_STEEP_SLOPE: f64 = 2.0;
/// The share of an image's nonzero gradients (central differences, on every 4th pixel of every 4th row) below its
/// steep slope ([`GRID_STEEP_SLOPE`]): above the noise of a flat wall, below the few jumps.
pub const GRID_SLOPE_QUANTILE: f64 = 0.9;
/// Stride of the 5 × 5 windows σ is read from (1/16 of them).
pub(crate) const SAMPLE_STRIDE: usize = 4;

/// How one image is run: its depth values times `factor`, seen through `camera`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WorkingUnits {
    /// What every depth value is multiplied by (1 = the image as it is).
    pub factor: f64,
    /// The camera of the scaled image (a pinhole's `depth_scale` folded into `factor`, its focal lengths divided by
    /// `stretch`).
    pub camera: Camera,
    /// How much farther apart `camera` sees neighbouring pixels than depth × `factor` alone would (1 = a similarity
    /// of the input's 3D points; see [`MAX_NOISE_PITCHES`]).
    pub stretch: f64,
}

impl WorkingUnits {
    /// The image as it is.
    #[must_use]
    pub fn identity(camera: &Camera) -> Self {
        Self { factor: 1.0, camera: *camera, stretch: 1.0 }
    }

    /// The unit normal, in the input's 3D geometry, of a plane whose normal in the working geometry is `n` (the same
    /// orientation toward the sensor): the stretch multiplies x and y by `stretch`, so the normal's x and y are.
    #[must_use]
    pub fn input_normal(&self, n: [f32; 3]) -> [f32; 3] {
        if self.stretch == 1.0 {
            return n;
        }
        let s = self.stretch;
        let v = [s * f64::from(n[0]), s * f64::from(n[1]), f64::from(n[2])];
        let len = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
        if len > 0.0 { [(v[0] / len) as f32, (v[1] / len) as f32, (v[2] / len) as f32] } else { n }
    }

    /// Tilts the normals of `regions`, found in these working units, back to the input's geometry
    /// ([`WorkingUnits::input_normal`]).
    pub fn input_normals(&self, regions: &mut [rangeimage::Region]) {
        for r in regions {
            r.normal = self.input_normal(r.normal);
        }
    }

    /// Whether the depth values run as they are (the camera may still be stretched across: `stretch`).
    #[must_use]
    pub fn is_identity(&self) -> bool {
        self.factor == 1.0
    }

    /// Writes `range` in working units into `out` (resized as needed).
    pub fn scale_into(&self, range: &RangeImage, out: &mut RangeImage) {
        let f = self.factor;
        out.map_from(range, |v| (f64::from(*v) * f) as f32);
    }
}

/// The working units of `range` seen through `camera` (see the module docs).
///
/// A pinhole camera's `depth_scale` is folded into the factor, so the features (computed on depth values)
/// and the 3D points (depth values times `depth_scale`) share one unit. Without a noise estimate (fewer
/// than 20 full windows) the image runs in its 3D units.
#[must_use]
pub fn working_units(range: &RangeImage, camera: &Camera) -> WorkingUnits {
    working_units_with(range, camera, &mut Vec::new())
}

/// [`working_units`] with the noise estimate's scratch memory in `scratch` (for a stream of frames).
pub fn working_units_with(range: &RangeImage, camera: &Camera, scratch: &mut Vec<f64>) -> WorkingUnits {
    working_units_given(range, camera, None, 0.0, scratch)
}

/// [`working_units_with`], given `sigma`, the σ of `range` (`planefit::noise::sigma_sampled` at this module's
/// stride, in the image's own units) if the caller read it already, and `floor`, a σ the image has at least in
/// its own units (0: none; a dequantised staircase's, `dequantise::Prepared::sigma_floor`).
pub fn working_units_given(
    range: &RangeImage,
    camera: &Camera,
    sigma: Option<f64>,
    floor: f64,
    scratch: &mut Vec<f64>,
) -> WorkingUnits {
    let (depth_scale, (lo, hi)) = match *camera {
        // ABW images keep their calibrated units; only a noisy one is stretched across.
        Camera::Abw(cal) => {
            let sigma =
                sigma.unwrap_or_else(|| planefit::noise::sigma_sampled_with(range, SAMPLE_STRIDE, scratch));
            let stretch = stretch_for(sigma, range, camera);
            tracing::debug!(sigma, stretch, "working units");
            let camera = Camera::Abw(rangeimage::AbwCalibration { f: cal.f / stretch, ..cal });
            return WorkingUnits { factor: 1.0, camera, stretch };
        }
        Camera::Pinhole { depth_scale, .. } => (depth_scale, (PINHOLE_SIGMA, PINHOLE_SIGMA)),
        Camera::Grid => (1.0, GRID_SIGMA_BAND),
    };
    let sigma = sigma.unwrap_or_else(|| planefit::noise::sigma_sampled_with(range, SAMPLE_STRIDE, scratch))
        * depth_scale;
    // Depth rounded to steps without noise reads σ ≈ 0 (most windows lie within one step; a float fit of a flat
    // window leaves ~1e-11): its rounding error is still that of its step, q / √12.
    // The step test runs only when it matters: σ below the rounding error of the smallest difference.
    let rounding = match planefit::noise::smallest_difference(range, SAMPLE_STRIDE) {
        Some(q) if sigma < q * depth_scale / 12f64.sqrt() => {
            let step = planefit::noise::step_from_smallest(range, SAMPLE_STRIDE, q);
            step.map_or(0.0, |q| q * depth_scale / 12f64.sqrt())
        }
        _ => 0.0,
    };
    // Noise-free depth without a step has neither: the pixel pitch gives a pinhole image its floor (a grid image's
    // scale is also its slopes' unit, so it has none; a stepped or dequantised image has its step's).
    let pitch = match *camera {
        Camera::Pinhole { .. } => planefit::noise::step_geometry(range, camera, 0.0).map(|(_, pitch)| pitch),
        _ => None,
    };
    let stepped = rounding > 0.0 || floor > 0.0;
    let pitch_floor = pitch.filter(|_| !stepped).map_or(0.0, |p| PINHOLE_PITCH_SHARE * p);
    let sigma =
        if sigma.is_nan() { sigma } else { sigma.max(rounding).max(floor * depth_scale).max(pitch_floor) };
    let stretch = pitch.map_or(1.0, |p| stretch_of(sigma, p));
    let mut k = if sigma.is_finite() && sigma > 0.0 { sigma.clamp(lo, hi) / sigma } else { 1.0 };
    // A grid image scaled up (or noise-free) only until its steep slopes reach GRID_STEEP_SLOPE.
    if matches!(camera, Camera::Grid)
        && sigma < lo
        && let Some(steep) = steep_slope(range, scratch)
    {
        let cap = (GRID_STEEP_SLOPE / steep).max(1.0);
        k = if sigma > 0.0 { k.min(cap) } else { cap };
    }
    let camera = match *camera {
        Camera::Pinhole { fx, fy, cx, cy, .. } => {
            Camera::Pinhole { fx: fx / stretch, fy: fy / stretch, cx, cy, depth_scale: 1.0 }
        }
        other => other,
    };
    tracing::debug!(sigma, rounding, ?pitch, factor = k * depth_scale, stretch, "working units");
    WorkingUnits { factor: k * depth_scale, camera, stretch }
}

/// How far an image of noise `sigma` and pixel pitch `pitch` (3D units) is stretched across ([`MAX_NOISE_PITCHES`]):
/// at least 1 (NaN σ: 1).
fn stretch_of(sigma: f64, pitch: f64) -> f64 {
    let stretch = (sigma / (MAX_NOISE_PITCHES * pitch)).max(1.0);
    if stretch.is_finite() { stretch } else { 1.0 }
}

/// [`stretch_of`] an ABW image of noise `sigma` (in stored values, turned into 3D units by the 3D length of one
/// value's step) seen through `camera` (1 without a pitch).
fn stretch_for(sigma: f64, range: &RangeImage, camera: &Camera) -> f64 {
    planefit::noise::step_geometry(range, camera, 1.0)
        .map_or(1.0, |(step, pitch)| stretch_of(sigma * step, pitch))
}

/// The [`GRID_SLOPE_QUANTILE`] of the nonzero gradient magnitudes of `range` (central differences, on every
/// [`SAMPLE_STRIDE`]-th pixel of every [`SAMPLE_STRIDE`]-th row), in depth units a pixel; `None` with fewer than 20.
/// `scratch` holds the gradients (cleared first).
fn steep_slope(range: &RangeImage, scratch: &mut Vec<f64>) -> Option<f64> {
    let (w, h) = (range.width() as usize, range.height() as usize);
    let v = range.as_slice();
    scratch.clear();
    for y in (1..h.saturating_sub(1)).step_by(SAMPLE_STRIDE) {
        for x in (1..w.saturating_sub(1)).step_by(SAMPLE_STRIDE) {
            let i = y * w + x;
            let gx = 0.5 * (f64::from(v[i + 1]) - f64::from(v[i - 1]));
            let gy = 0.5 * (f64::from(v[i + w]) - f64::from(v[i - w]));
            let g = gx.hypot(gy);
            // (No data around the pixel gives NaN; a flat window of a noise-free image gives 0.)
            if g > 0.0 && g.is_finite() {
                scratch.push(g);
            }
        }
    }
    if scratch.len() < 20 {
        return None;
    }
    let k = ((scratch.len() - 1) as f64 * GRID_SLOPE_QUANTILE).round() as usize;
    let (_, g, _) = scratch.select_nth_unstable_by(k, f64::total_cmp);
    Some(*g)
}

/// The working units `config` asks for: [`working_units_with`] when `pipeline.normalize_units` is on, else the
/// image's own.
pub fn for_config(
    range: &RangeImage,
    camera: &Camera,
    config: &crate::Config,
    scratch: &mut Vec<f64>,
) -> WorkingUnits {
    for_config_given(range, camera, config, None, 0.0, scratch)
}

/// [`for_config`], given the σ of `range` if the caller read it already and a floor under it (see
/// [`working_units_given`]).
pub fn for_config_given(
    range: &RangeImage,
    camera: &Camera,
    config: &crate::Config,
    sigma: Option<f64>,
    floor: f64,
    scratch: &mut Vec<f64>,
) -> WorkingUnits {
    if config.pipeline.normalize_units {
        working_units_given(range, camera, sigma, floor, scratch)
    } else {
        WorkingUnits::identity(camera)
    }
}

/// `range` in the working units `config` asks for (borrowed when they are the image's own), and dequantised first
/// if it is a staircase ([`crate::dequantise`]), with those units (their `camera` is the one to run it through):
/// what [`crate::pipeline::Segmenter`] runs the stages on, for callers that run single stages (the regions' normals
/// they get are the working geometry's: [`WorkingUnits::input_normal`] tilts them back).
#[must_use]
pub fn in_working_units<'a>(
    range: &'a RangeImage,
    camera: &Camera,
    config: &crate::Config,
) -> (std::borrow::Cow<'a, RangeImage>, WorkingUnits) {
    let mut noise = Vec::new();
    let prepared = crate::dequantise::for_config(range, camera, config, &mut noise, &mut Default::default());
    let floor = prepared.sigma_floor();
    let dequantised = prepared.dequantised.map(|(_, image)| image);
    let input = dequantised.as_ref().unwrap_or(range);
    let units = for_config_given(input, camera, config, prepared.sigma, floor, &mut noise);
    if units.is_identity() {
        let out = dequantised.map_or(std::borrow::Cow::Borrowed(range), std::borrow::Cow::Owned);
        return (out, units);
    }
    let mut out = RangeImage::default();
    units.scale_into(input, &mut out);
    (std::borrow::Cow::Owned(out), units)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rangeimage::Grid;

    /// A tilted plane with a deterministic ±`amp` pattern (σ ≈ 1.06 `amp` around local planes).
    fn plane(amp: f32) -> RangeImage {
        Grid::from_fn(64, 48, |x, y| {
            let wiggle = if (x * 7 + y * 13) % 5 < 2 { amp } else { -amp };
            1.0 + 0.01 * x as f32 + 0.02 * y as f32 + wiggle
        })
    }

    const PIN: Camera = Camera::Pinhole { fx: 500.0, fy: 500.0, cx: 32.0, cy: 24.0, depth_scale: 1.0 };

    #[test]
    fn grid_images_in_the_tuned_units_run_as_they_are_and_abw_images_always() {
        for amp in [0.3, 0.5, 0.9] {
            let u = working_units(&plane(amp), &Camera::Grid);
            assert!(u.is_identity(), "amp {amp}: {u:?}");
            assert_eq!(u.camera, Camera::Grid);
        }
        assert!(working_units(&plane(0.001), &Camera::ABW0).is_identity(), "ABW keeps its calibration");
    }

    /// σ of `img` in the working units `u`, and the working image.
    fn working_sigma(img: &RangeImage, u: &WorkingUnits) -> (f64, RangeImage) {
        let mut scaled = RangeImage::default();
        u.scale_into(img, &mut scaled);
        (planefit::noise::sigma_sampled(&scaled, SAMPLE_STRIDE), scaled)
    }

    #[test]
    fn pinhole_images_get_one_noise_level_whatever_their_units() {
        for amp in [0.0005f32, 0.002, 0.01, 0.5, 40.0] {
            let img = plane(amp);
            let (s, scaled) = working_sigma(&img, &working_units(&img, &PIN));
            assert!((s / PINHOLE_SIGMA - 1.0).abs() < 1e-4, "amp {amp}: working σ {s}");
            // The same scene in units 10 times smaller gives the same working image, up to rounding.
            let small = img.map(|&v| v * 10.0);
            let (_, scaled_small) = working_sigma(&small, &working_units(&small, &PIN));
            let worst = scaled
                .as_slice()
                .iter()
                .zip(scaled_small.as_slice())
                .map(|(a, b)| (a - b).abs() / a.abs())
                .fold(0.0, f32::max);
            assert!(worst < 1e-5, "amp {amp}: the two units differ by {worst} (relative)");
        }
    }

    #[test]
    fn grid_images_outside_the_band_go_to_its_nearest_end() {
        // (A slope of 0.001 and 0.002 a pixel, so that slopes do not limit the scale up: below.)
        let img: RangeImage = Grid::from_fn(64, 48, |x, y| {
            let wiggle = if (x * 7 + y * 13) % 5 < 2 { 0.002 } else { -0.002 };
            1.0 + 0.001 * x as f32 + 0.002 * y as f32 + wiggle
        });
        for (img, end) in [(img, GRID_SIGMA_BAND.0), (plane(40.0), GRID_SIGMA_BAND.1)] {
            let (s, _) = working_sigma(&img, &working_units(&img, &Camera::Grid));
            assert!((s / end - 1.0).abs() < 1e-4, "working σ {s}, expected {end}");
        }
    }

    #[test]
    fn grid_images_are_scaled_up_only_until_their_steep_slopes_reach_the_limit() {
        // Slopes of 0.01 and 0.02 a pixel (steep slope 0.023 with the noise's) and σ = 0.0021: the band's 0.25 would
        // scale it 118 times, to steep slopes of 2.8 a pixel; the limit, 85 times.
        let img = plane(0.002);
        let u = working_units(&img, &Camera::Grid);
        let mut scaled = RangeImage::default();
        u.scale_into(&img, &mut scaled);
        let steep = steep_slope(&scaled, &mut Vec::new()).expect("slopes");
        assert!((steep / GRID_STEEP_SLOPE - 1.0).abs() < 1e-3, "{u:?}: steep slope {steep}");
        assert!(working_sigma(&img, &u).0 < GRID_SIGMA_BAND.0, "{u:?}");
        // (Noise-free grid depth, σ = 0, is scaled as far: tests/pipeline.rs, `noise_free_float_disparity_…`.)
        // Slopes already steeper than the limit: never scaled down below the image's own units.
        let steep: RangeImage = Grid::from_fn(64, 48, |x, y| 1.0 + 5.0 * x as f32 + 0.02 * y as f32);
        assert!(working_units(&steep, &Camera::Grid).is_identity());
        // And the pinhole camera has no such limit.
        assert!(
            (working_units(&img, &PIN).factor
                - PINHOLE_SIGMA / planefit::noise::sigma_sampled(&img, SAMPLE_STRIDE))
            .abs()
                < 1e-9
        );
    }

    #[test]
    fn pinhole_images_noisier_than_the_limit_are_stretched_across() {
        // Depth about 1.5 seen at 500 px: a pitch of 0.0031, against σ = 0.00053 (no stretch) or 0.053 (9.8).
        for (amp, stretched) in [(0.0005f32, false), (0.05, true)] {
            let img = plane(amp);
            let u = working_units(&img, &PIN);
            let s = planefit::noise::sigma_sampled(&img, SAMPLE_STRIDE);
            let (_, pitch) = planefit::noise::step_geometry(&img, &PIN, 0.0).expect("a pitch");
            let expected = if stretched { s / (MAX_NOISE_PITCHES * pitch) } else { 1.0 };
            assert!((u.stretch / expected - 1.0).abs() < 1e-9, "amp {amp}: {u:?}, expected {expected}");
            assert!(!stretched || u.stretch > 4.0, "amp {amp}: {u:?}");
            let f = 500.0 / u.stretch;
            assert_eq!(u.camera, Camera::Pinhole { fx: f, fy: f, cx: 32.0, cy: 24.0, depth_scale: 1.0 });
        }
        // An ABW image keeps its units, but a noisy one is stretched too: its focal length divided.
        let u = working_units(&plane(5.0), &Camera::ABW0);
        assert!(u.factor == 1.0 && u.stretch > 2.0, "{u:?}");
        let cal = rangeimage::AbwCalibration::CAL0;
        assert_eq!(u.camera, Camera::Abw(rangeimage::AbwCalibration { f: cal.f / u.stretch, ..cal }));
        // A plane's normal in the stretched geometry, tilted back: x and y times the stretch, renormalised.
        let u = WorkingUnits { factor: 1.0, camera: PIN, stretch: 2.0 };
        let n = u.input_normal([0.6, 0.0, -0.8]);
        let len = 1.2f64.hypot(0.8);
        for (got, want) in n.iter().zip([1.2 / len, 0.0, -0.8 / len]) {
            assert!((f64::from(*got) - want).abs() < 1e-6, "{n:?}");
        }
        assert_eq!(u.input_normal([0.0, 0.0, -1.0]), [0.0, 0.0, -1.0]);
        assert_eq!(WorkingUnits::identity(&PIN).input_normal([0.6, 0.0, -0.8]), [0.6, 0.0, -0.8]);
    }

    #[test]
    fn a_pinhole_depth_scale_is_folded_into_the_factor() {
        let img = plane(0.4);
        let cam = Camera::Pinhole { fx: 500.0, fy: 500.0, cx: 32.0, cy: 24.0, depth_scale: 0.25 };
        let u = working_units(&img, &cam);
        let s = planefit::noise::sigma_sampled(&img, SAMPLE_STRIDE);
        assert!((u.factor - PINHOLE_SIGMA / s).abs() < 1e-12, "{u:?}");
        // (Noise of 0.1 m at 0.3 m, far more than the pitch: stretched across, below.)
        let f = 500.0 / u.stretch;
        assert_eq!(u.camera, Camera::Pinhole { fx: f, fy: f, cx: 32.0, cy: 24.0, depth_scale: 1.0 });
        // Noise-free depth (σ = 0): σ is a share of the pixel pitch, 0.5 m / 500 px at the depth of 2 × 0.25 m.
        let flat = Grid::new(64, 48, 2.0f32);
        let expected = 0.25 * PINHOLE_SIGMA / (PINHOLE_PITCH_SHARE * 0.5 / 500.0);
        assert!((working_units(&flat, &cam).factor / expected - 1.0).abs() < 1e-9);
        // No noise estimate (too few windows): the 3D units.
        assert!(working_units(&Grid::new(3, 3, 2.0f32), &PIN).is_identity());
    }

    #[test]
    fn noise_free_steps_count_their_rounding_error_even_when_uneven() {
        // A gentle slope rounded to 3.8 and stored in whole units: wide terraces (σ of the windows ≈ 0), risers
        // of 4 and 3. σ is at least the highest riser's rounding error, 4 / √12 ≈ 1.15, above the grid band.
        let img: RangeImage = Grid::from_fn(200, 150, |x, y| {
            let v = 60.0 + 0.05 * f64::from(x) + 0.1 * f64::from(y);
            ((v / 3.8).round() * 3.8).round() as f32
        });
        assert!(planefit::noise::sigma_sampled(&img, SAMPLE_STRIDE) < 0.1);
        assert_eq!(planefit::noise::smallest_step(&img, SAMPLE_STRIDE), None, "no uniform step");
        let u = working_units(&img, &Camera::Grid);
        assert!((u.factor - GRID_SIGMA_BAND.1 / (4.0 / 12f64.sqrt())).abs() < 1e-12, "{u:?}");
    }

    #[test]
    fn single_stages_run_on_the_dequantised_staircase_as_the_pipeline_does() {
        let img: RangeImage = Grid::from_fn(160, 120, |x, y| {
            let v = 100.0 + 0.31 * f64::from(x) + 0.17 * f64::from(y);
            ((v / 3.0).round() * 3.0) as f32
        });
        let config = crate::Config::default();
        let (range, units) = in_working_units(&img, &Camera::ABW0, &config);
        let camera = units.camera;
        let expected = crate::dequantise::dequantise(&img, 3.0, &mut Default::default());
        assert!(matches!(range, std::borrow::Cow::Owned(_)) && *range == expected && *range != img);
        assert_eq!(camera, Camera::ABW0);
        let off = crate::Config {
            pipeline: crate::PipelineParams { dequantise: false, ..config.pipeline },
            ..config
        };
        assert!(matches!(in_working_units(&img, &Camera::ABW0, &off).0, std::borrow::Cow::Borrowed(_)));
    }
}
