//! Canny edge detection on vector fields (plane parameters) with the Di Zenzo tensor (docs/method.md §3.3).
//!
//! [`detect`] runs on any stack of channels: each channel is smoothed with a Gaussian normalised over the valid
//! pixels, differentiated with Sobel, and the channels are combined with the weighted Di Zenzo structure tensor
//! (magnitude = `sqrt(λmax)`, direction = its eigenvector). Then non-maximum suppression along the direction
//! (interpolated) and 8-connected hysteresis from the strong pixels. [`detect_planes`] runs it on the plane
//! parameters `a, b, c` of the `features` stage; [`detect_raw`] on the range image itself (the baseline).
//!
//! No-data pixels are never edges, contribute nothing to smoothing, and a missing Sobel neighbour takes the centre
//! pixel's value, so no-data adds no gradient of its own while real steps between valid pixels next to no data
//! (occlusion boundaries) are still found. Magnitudes are finite everywhere (0 at no-data pixels).

mod canny;
mod gradient;

use rangeimage::ParamError;
use rangeimage::{EdgeMap, Grid, PlaneMap, RangeImage};

/// Largest Gaussian kernel side `kernel_px` accepted (the smoothing passes keep this many row slices on the stack).
const MAX_KERNEL_PX: usize = 31;

/// How [`Thresholds::low`] and [`Thresholds::high`] are read.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ThresholdMode {
    /// Magnitudes in the channels' (weighted) units per pixel.
    Absolute,
    /// Quantiles in `[0, 1]` of the magnitude over the valid pixels.
    Quantile,
    /// Multiples of a robust noise estimate: the median magnitude over the valid pixels (at least `noise_floor`).
    /// On scenes made mostly of planes the median is the level of quantisation and sensor noise, so the same
    /// factors work on 8- and 16-bit data.
    NoiseRelative,
}

/// Hysteresis thresholds.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Thresholds {
    /// How `low` and `high` are read.
    pub mode: ThresholdMode,
    /// Weak threshold: edge pixels connected to a strong one need at least this.
    pub low: f32,
    /// Strong threshold: edges start at pixels with at least this.
    pub high: f32,
    /// Lower bound of the noise estimate in `noise_relative` mode, in magnitude units (noise-free images).
    pub noise_floor: f32,
}

/// Defaults tuned on the 10 training images of the synthetic ABW benchmark (mean one-to-one boundary F at τ = 2 px,
/// `cargo run --release --example table1 -- --tune`): noise-relative, low 1.5 and high 4 × the median magnitude.
impl Default for Thresholds {
    fn default() -> Self {
        Self { mode: ThresholdMode::NoiseRelative, low: 1.5, high: 4.0, noise_floor: 1e-3 }
    }
}

/// The `[vcanny]` table of a config file.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Params {
    /// Standard deviation of the Gaussian smoothing, in pixels.
    pub sigma_px: f32,
    /// Side of the Gaussian mask (odd).
    pub kernel_px: u32,
    /// Weights of the plane channels `[a, b, c]` in the structure tensor ([`detect_planes`]). The slopes `a, b`
    /// are dimensionless (range units per pixel); `c` is in range units, and, being the intercept at the image
    /// centre, it carries the slope noise times the distance from the centre, hence its small weight.
    pub weights: [f32; 3],
    /// Hysteresis thresholds.
    pub thresholds: Thresholds,
}

impl Default for Params {
    fn default() -> Self {
        Self { sigma_px: 1.6, kernel_px: 5, weights: [1.0, 1.0, 0.0], thresholds: Thresholds::default() }
    }
}

impl Params {
    /// Checks the values; the message names the offending field.
    pub fn validate(&self) -> Result<(), ParamError> {
        if !(self.sigma_px.is_finite() && self.sigma_px > 0.0) {
            return Err(ParamError::new(
                "vcanny.sigma_px",
                format!("must be positive, got {}", self.sigma_px),
            ));
        }
        if self.kernel_px == 0 || self.kernel_px.is_multiple_of(2) || self.kernel_px as usize > MAX_KERNEL_PX
        {
            return Err(ParamError::new(
                "vcanny.kernel_px",
                format!("must be odd and in 1..={MAX_KERNEL_PX}, got {}", self.kernel_px),
            ));
        }
        if self.weights.iter().any(|w| !(w.is_finite() && *w >= 0.0))
            || self.weights.iter().all(|&w| w == 0.0)
        {
            return Err(ParamError::new(
                "vcanny.weights",
                format!("must be finite, ≥ 0 and not all 0, got {:?}", self.weights),
            ));
        }
        let t = &self.thresholds;
        if !(t.low.is_finite() && t.high.is_finite() && t.low >= 0.0 && t.low <= t.high) {
            return Err(ParamError::new(
                "vcanny.thresholds",
                format!("need 0 ≤ low ≤ high, got low {} high {}", t.low, t.high),
            ));
        }
        if t.mode == ThresholdMode::Quantile && t.high > 1.0 {
            return Err(ParamError::new(
                "vcanny.thresholds",
                format!("quantiles must be in [0, 1], got high {}", t.high),
            ));
        }
        if !(t.noise_floor.is_finite() && t.noise_floor > 0.0) {
            return Err(ParamError::new(
                "vcanny.thresholds.noise_floor",
                format!("must be positive, got {}", t.noise_floor),
            ));
        }
        Ok(())
    }
}

/// Detected edges and the gradient magnitude.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Edges {
    /// The edge set (C2): `true` = edge pixel; never at no-data pixels.
    pub edges: EdgeMap,
    /// `sqrt(λmax)` of the weighted Di Zenzo tensor, in channel units per pixel; 0 at no-data pixels, never NaN.
    pub magnitude: Grid<f32>,
}

/// Canny on a stack of channels combined by the Di Zenzo tensor with per-channel `weights`.
///
/// A pixel takes part if `valid` is true and every channel is finite there.
///
/// # Panics
/// If the grids differ in size, `channels` is empty or its length differs from `weights`; in debug builds also if `params` is invalid.
#[must_use]
pub fn detect(channels: &[&Grid<f32>], weights: &[f32], valid: &Grid<bool>, params: &Params) -> Edges {
    let _s = tracing::info_span!("vcanny", w = valid.width(), h = valid.height(), channels = channels.len())
        .entered();
    assert!(!channels.is_empty(), "vcanny::detect needs at least one channel");
    assert!(channels.iter().all(|c| c.same_size(valid)), "channels and mask differ in size");
    let mut out = Edges::default();
    let input = gradient::Input::Stack(channels);
    run(&input, weights, Some(valid), valid.dimensions(), params, &mut Scratch::default(), &mut out);
    out
}

/// The working buffers of [`detect_planes_into`] (the per-pixel flags, candidates and threshold histogram),
/// kept between frames so a stream of same-sized images allocates them once.
#[derive(Default)]
pub struct Scratch {
    grad: gradient::Gradient,
    hist: Option<canny::Histogram>,
    stack: Vec<(u32, u32)>,
}

impl std::fmt::Debug for Scratch {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("vcanny::Scratch").finish_non_exhaustive()
    }
}

/// Canny on the plane parameters `[a, b, c]` with the weights of `params`.
///
/// # Panics
/// If `plane` and `valid` differ in size; in debug builds also if `params` is invalid.
#[must_use]
pub fn detect_planes(plane: &PlaneMap, valid: &Grid<bool>, params: &Params) -> Edges {
    let mut out = Edges::default();
    detect_planes_into(plane, valid, params, &mut Scratch::default(), &mut out);
    out
}

/// [`detect_planes`] into `out` (its grids reused) with the buffers of `scratch`; the same result, bit for bit.
///
/// # Panics
/// As [`detect_planes`].
pub fn detect_planes_into(
    plane: &PlaneMap,
    valid: &Grid<bool>,
    params: &Params,
    scratch: &mut Scratch,
    out: &mut Edges,
) {
    let _s = tracing::info_span!("vcanny", w = valid.width(), h = valid.height(), channels = 3).entered();
    assert!(plane.same_size(valid), "plane map and mask differ in size");
    let input = gradient::Input::Planes(plane.as_slice());
    run(&input, &params.weights, Some(valid), valid.dimensions(), params, scratch, out);
}

/// Canny on the raw range image (the baseline of the paper's Table I); `params.weights` is not used.
///
/// # Panics
/// In debug builds, if `params` is invalid ([`Params::validate`]).
#[must_use]
pub fn detect_raw(range: &RangeImage, params: &Params) -> Edges {
    let _s = tracing::info_span!("vcanny", w = range.width(), h = range.height(), channels = 1).entered();
    let mut out = Edges::default();
    run(
        &gradient::Input::Stack(&[range]),
        &[1.0],
        None,
        range.dimensions(),
        params,
        &mut Scratch::default(),
        &mut out,
    );
    out
}

/// The detector on `input` into `out`; `valid = None` means every pixel (where the channels are finite).
fn run(
    input: &gradient::Input<'_>,
    weights: &[f32],
    valid: Option<&Grid<bool>>,
    (wu, hu): (u32, u32),
    params: &Params,
    scratch: &mut Scratch,
    out: &mut Edges,
) {
    debug_assert_eq!(params.validate(), Ok(()), "invalid vcanny params");
    assert_eq!(input.len(), weights.len(), "one weight per channel");
    assert!(
        weights.iter().all(|w| w.is_finite() && *w >= 0.0),
        "weights must be finite and ≥ 0: {weights:?}"
    );
    let (w, h) = (wu as usize, hu as usize);
    let g = gradient::gaussian(params.sigma_px, params.kernel_px);
    // Quantile thresholds count the magnitudes while each row is in cache.
    let hist = if params.thresholds.mode == ThresholdMode::Absolute {
        None
    } else {
        let hs = scratch.hist.get_or_insert_with(canny::Histogram::new);
        hs.reset();
        Some(hs)
    };
    let mut bufs = std::mem::take(&mut scratch.grad);
    // The magnitude is written into the output grid's memory.
    bufs.magnitude = std::mem::take(&mut out.magnitude).into_vec();
    let valid = valid.map(|v| v.as_slice());
    let mut hist = hist;
    let mut edges = std::mem::take(&mut out.edges).into_vec();
    // The per-pixel passes, thresholds and hysteresis, compiled for the best instruction set of this CPU
    // (bit-identical on every one).
    let (mut grad, low, high) = isa::dispatch(
        #[inline(always)]
        || {
            let mut grad = gradient::gradient(input, weights, valid, w, h, &g, hist.as_deref_mut(), bufs);
            let (low, high) = canny::thresholds(&params.thresholds, &grad.magnitude, &grad.ok, hist);
            let bufs = (&mut edges, &mut scratch.stack);
            canny::hysteresis_in_place(&grad.magnitude, &mut grad.candidates, w, h, (low, high), bufs);
            (grad, low, high)
        },
    );
    tracing::debug!(low, high, n_edges = edges.iter().filter(|&&e| e).count(), "vcanny done");
    out.edges = Grid::from_vec(wu, hu, edges).expect("size matches");
    out.magnitude = Grid::from_vec(wu, hu, std::mem::take(&mut grad.magnitude)).expect("size matches");
    scratch.grad = grad;
}

#[cfg(test)]
mod reference;
#[cfg(test)]
mod tests;
