//! The noise and quantisation of a range image, measured on the image itself.
//!
//! [`estimate`] fits a plane `z = a·x + b·y + c` (pixel coordinates, depth in the image's own
//! units) to every 5 × 5 window whose 25 pixels hold data, and takes the residual RMS of each
//! window (22 degrees of freedom). Windows across a jump or a crease have large RMS; most windows of
//! a scene of planes do not, so the median of the window RMS, divided by the median of
//! `√(χ²₂₂ / 22)`, is the noise scale σ of a Gaussian that gives the planar windows' RMS. The window
//! RMS spreads little (about ±15 % of σ), so edges move σ little: +1 % when 6 % of the windows
//! straddle one, about +5 % at 25 %.
//!
//! σ is the noise a local plane fit sees: noise correlated over more than a few pixels (scanner
//! stripes) is partly absorbed by the 5 × 5 planes and counts only in part.
//! The quantisation step is the smallest nonzero difference between 4-neighbours that is common
//! and of which nearly every nonzero difference is a whole multiple, or the highest riser of nearly
//! uniform steps (terraces whose risers differ by a storage unit; [`near_uniform_step`]); `None`
//! for continuous depth.
//!
//! σ includes the quantisation's share (the rounding error, `q²/12` in variance when the noise is
//! not much smaller than a step); [`NoiseEstimate::sigma_noise`] removes it.

/// Side of the square window of the local plane fits.
const WINDOW: usize = 5;
/// Degrees of freedom of a window's residuals: 25 pixels, 3 plane parameters.
const DOF: f64 = 22.0;
/// The quantile of the windows' residual RMS that σ is read from (the median: a lower quantile
/// would resist more edges but reads 0 on coarsely quantised images, where most windows lie
/// within one step).
const QUANTILE: f64 = 0.5;
/// Fewest full windows for an estimate.
const MIN_WINDOWS: usize = 20;
/// A difference value is a quantisation step candidate when at least this fraction of the
/// nonzero differences equal it.
const STEP_MIN_SHARE: f64 = 0.02;
/// Fraction of the nonzero differences that must be whole multiples of the step.
const STEP_MULTIPLE_SHARE: f64 = 0.9;
/// Relative tolerance of "equal" and "whole multiple" (depths stored as scaled integers in `f32`).
const STEP_REL_TOL: f64 = 1e-3;
/// Nearly uniform steps ([`near_uniform_step`]): at least this fraction of the finite neighbour differences are
/// exactly 0 (the terraces of a staircase; continuous depth has next to none).
const NEAR_STEP_MIN_ZERO_SHARE: f64 = 0.25;
/// Nearly uniform steps: at least this fraction of the nonzero differences lie within one step, from the
/// smallest nonzero difference `d` up to (not including) `2d`.
const NEAR_STEP_MIN_SHARE: f64 = 0.5;

/// What [`estimate`] measured on one image.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NoiseEstimate {
    /// Robust scale of the depth residuals around local planes, in the image's depth units,
    /// quantisation included (NaN when fewer than 20 full 5 × 5 windows hold data).
    pub sigma: f64,
    /// The quantisation step of depth (smallest common nonzero neighbour difference of which the
    /// others are multiples, else the highest riser of nearly uniform steps: [`near_uniform_step`]), `None` if
    /// depths look continuous.
    pub step: Option<f64>,
    /// Number of full 5 × 5 windows σ comes from.
    pub windows: usize,
}

impl NoiseEstimate {
    /// σ without the quantisation's share: `√(σ² − q²/12)`, at least 0; `sigma` when there is no step.
    ///
    /// Only meaningful when the noise is not much below half a step (below it, rounding is not
    /// an independent uniform error and this underestimates).
    #[must_use]
    pub fn sigma_noise(&self) -> f64 {
        match self.step {
            Some(q) => (self.sigma * self.sigma - q * q / 12.0).max(0.0).sqrt(),
            None => self.sigma,
        }
    }
}

/// Estimates the depth noise σ and the quantisation step of a range image (NaN = no data).
///
/// Pure and deterministic (sequential sums in raster order); logs the result at `debug` level.
#[must_use]
pub fn estimate(range: &rangeimage::RangeImage) -> NoiseEstimate {
    let _s = tracing::debug_span!("noise_estimate").entered();
    let (sigma, windows) = sigma_of_windows(range, 1, &mut Vec::new());
    let step = quantisation_step(range)
        .or_else(|| smallest_difference(range, 1).and_then(|d| near_uniform_step(range, 1, d)));
    tracing::debug!(sigma, ?step, windows, "noise estimate");
    NoiseEstimate { sigma, step, windows }
}

/// Calls `f` with the absolute difference of every pair of horizontal or vertical neighbours on every `stride`-th
/// row (and between it and the row below), in raster order; NaN where either holds no data.
fn for_each_difference(range: &rangeimage::RangeImage, stride: usize, mut f: impl FnMut(f64)) {
    let (w, h) = (range.width() as usize, range.height() as usize);
    let data = range.as_slice();
    for y in (0..h).step_by(stride) {
        let row = &data[y * w..(y + 1) * w];
        for pair in row.windows(2) {
            f((f64::from(pair[0]) - f64::from(pair[1])).abs());
        }
        if y + 1 < h {
            for (&a, &b) in row.iter().zip(&data[(y + 1) * w..(y + 2) * w]) {
                f((f64::from(a) - f64::from(b)).abs());
            }
        }
    }
}

/// The smallest nonzero difference between neighbours on every `stride`-th row (see [`smallest_step`]), taken in
/// `f32`; `None` if there is none. One pass over `1 / stride` of the image.
///
/// # Panics
/// If `stride` is 0.
#[must_use]
pub fn smallest_difference(range: &rangeimage::RangeImage, stride: usize) -> Option<f64> {
    assert!(stride > 0, "stride must be positive");
    let (w, h) = (range.width() as usize, range.height() as usize);
    let data = range.as_slice();
    // In f32, branch-free, so that the loops vectorise: a NaN difference (no data) or 0 counts as +∞.
    let min_of = |a: &[f32], b: &[f32]| {
        a.iter().zip(b).fold(f32::INFINITY, |m, (&x, &y)| {
            let d = (x - y).abs();
            m.min(if d > 0.0 { d } else { f32::INFINITY })
        })
    };
    let mut min = f32::INFINITY;
    for y in (0..h).step_by(stride) {
        let row = &data[y * w..(y + 1) * w];
        min = min.min(min_of(&row[..w.saturating_sub(1)], &row[1.min(w)..]));
        if y + 1 < h {
            min = min.min(min_of(row, &data[(y + 1) * w..(y + 2) * w]));
        }
    }
    min.is_finite().then_some(f64::from(min))
}

/// Whether `step` is the quantisation step of the neighbour differences on every `stride`-th row: at least 2 %
/// of the nonzero differences equal it and 90 % are whole multiples of it (within 0.1 %; at least 100 nonzero
/// differences). One pass over `1 / stride` of the image.
///
/// # Panics
/// If `stride` is 0.
#[must_use]
pub fn is_step(range: &rangeimage::RangeImage, stride: usize, step: f64) -> bool {
    assert!(stride > 0, "stride must be positive");
    let (mut nonzero, mut at_step, mut multiples) = (0usize, 0usize, 0usize);
    for_each_difference(range, stride, |d| {
        if d > 0.0 && d.is_finite() {
            nonzero += 1;
            at_step += usize::from(d <= step * (1.0 + STEP_REL_TOL));
            multiples += usize::from(is_multiple(d, step));
        }
    });
    nonzero >= 100
        && at_step as f64 >= STEP_MIN_SHARE * nonzero as f64
        && multiples as f64 >= STEP_MULTIPLE_SHARE * nonzero as f64
}

/// Whether the difference `d` is a whole multiple of `step` (within [`STEP_REL_TOL`] of the multiple).
fn is_multiple(d: f64, step: f64) -> bool {
    let m = d / step;
    (m - m.round()).abs() <= STEP_REL_TOL * m.round().max(1.0) + STEP_REL_TOL
}

/// The quantisation step of depth as [`estimate`] finds it, but read only from every `stride`-th row (and the
/// row below it) and only tried at the smallest nonzero difference between neighbours: that difference if
/// [`is_step`], else `None` (continuous depth, too few differences, or a step that is not the smallest
/// difference). Two passes over `1 / stride` of the image, no allocation.
///
/// # Panics
/// If `stride` is 0.
#[must_use]
pub fn smallest_step(range: &rangeimage::RangeImage, stride: usize) -> Option<f64> {
    smallest_difference(range, stride).filter(|&d| is_step(range, stride, d))
}

/// The step of depth rounded to steps that are nearly but not exactly uniform, read from every `stride`-th row
/// (and the row below it), given `smallest`, the smallest nonzero difference between neighbours there: the largest
/// of the nonzero differences in `[smallest, 2 · smallest)` (the highest riser) when at least a quarter of all finite differences are
/// exactly 0 (terraces) and at least half of the nonzero ones lie in that range (one step); `None` otherwise.
///
/// A step that is not a whole number of the storage unit gives two neighbouring differences (3.99 grey levels
/// stored in whole grey levels: 4 and, where the rounding drifts, 3), and 4 is not a whole multiple of the
/// smallest difference, as [`is_step`] asks.
/// Continuous depth has next to no zero differences. One pass over `1 / stride` of the image; callers try
/// [`is_step`] first.
///
/// # Panics
/// If `stride` is 0.
#[must_use]
pub fn near_uniform_step(range: &rangeimage::RangeImage, stride: usize, smallest: f64) -> Option<f64> {
    assert!(stride > 0, "stride must be positive");
    let (mut finite, mut zero, mut nonzero, mut in_step, mut largest) =
        (0usize, 0usize, 0usize, 0usize, 0.0f64);
    for_each_difference(range, stride, |d| {
        if d.is_finite() {
            finite += 1;
            if d == 0.0 {
                zero += 1;
            } else {
                nonzero += 1;
                if d >= smallest && d < 2.0 * smallest {
                    in_step += 1;
                    largest = largest.max(d);
                }
            }
        }
    });
    (smallest > 0.0
        && nonzero >= 100
        && zero as f64 >= NEAR_STEP_MIN_ZERO_SHARE * finite as f64
        && in_step as f64 >= NEAR_STEP_MIN_SHARE * nonzero as f64)
        .then_some(largest)
}

/// The depth step of every `stride`-th row given `smallest`, the smallest nonzero difference between neighbours there
/// ([`smallest_difference`]): `smallest` if [`is_step`], else [`near_uniform_step`]; `None` for continuous depth.
/// One or two passes over `1 / stride` of the image, no allocation.
///
/// # Panics
/// If `stride` is 0.
#[must_use]
pub fn step_from_smallest(range: &rangeimage::RangeImage, stride: usize, smallest: f64) -> Option<f64> {
    if is_step(range, stride, smallest) { Some(smallest) } else { near_uniform_step(range, stride, smallest) }
}

/// The 3D length of a depth step of `step` units and the 3D distance between horizontally neighbouring pixels (the
/// pitch), at the image centre and the image's mean depth value (over every 16th pixel of every 16th row); `None`
/// without data, or where the camera gives no point there, a length that is not finite or a pitch of 0.
#[must_use]
pub fn step_geometry(
    range: &rangeimage::RangeImage,
    camera: &rangeimage::Camera,
    step: f64,
) -> Option<(f64, f64)> {
    let (w, h) = (range.width() as usize, range.height() as usize);
    let (mut sum, mut n) = (0.0, 0u32);
    for row in range.as_slice().chunks_exact(w.max(1)).step_by(16) {
        for &v in row.iter().step_by(16).filter(|v| v.is_finite()) {
            sum += f64::from(v);
            n += 1;
        }
    }
    if n == 0 {
        return None;
    }
    let (x, y, v) = ((w / 2) as f64, (h / 2) as f64, sum / f64::from(n));
    let (p0, right, deeper) =
        (camera.point(x, y, v)?, camera.point(x + 1.0, y, v)?, camera.point(x, y, v + step)?);
    let dist =
        |a: [f64; 3]| ((a[0] - p0[0]).powi(2) + (a[1] - p0[1]).powi(2) + (a[2] - p0[2]).powi(2)).sqrt();
    let (step_3d, pitch) = (dist(deeper), dist(right));
    (step_3d.is_finite() && pitch > 0.0 && pitch.is_finite()).then_some((step_3d, pitch))
}

/// σ as [`estimate`] reads it, from the full 5 × 5 windows whose top-left corner lies on every `stride`-th
/// row and column (`stride` = 1: every window, as [`estimate`]); NaN when fewer than 20 windows hold data.
///
/// A stride of 4 reads 1/16 of the windows: the same σ within a few percent on images of more than a few
/// thousand windows, at 1/16 of the cost (the pipeline's choice of working units needs only its order of
/// magnitude).
///
/// # Panics
/// If `stride` is 0.
#[must_use]
pub fn sigma_sampled(range: &rangeimage::RangeImage, stride: usize) -> f64 {
    sigma_sampled_with(range, stride, &mut Vec::new())
}

/// [`sigma_sampled`] with the windows' RMS in `scratch` (cleared first), so a stream of frames reuses it.
///
/// # Panics
/// If `stride` is 0.
pub fn sigma_sampled_with(range: &rangeimage::RangeImage, stride: usize, scratch: &mut Vec<f64>) -> f64 {
    assert!(stride > 0, "stride must be positive");
    sigma_of_windows(range, stride, scratch).0
}

/// σ (NaN when fewer than [`MIN_WINDOWS`]) and the number of windows it comes from; `rms` is scratch.
fn sigma_of_windows(range: &rangeimage::RangeImage, stride: usize, rms: &mut Vec<f64>) -> (f64, usize) {
    window_rms(range, stride, rms);
    let windows = rms.len();
    let sigma = if windows < MIN_WINDOWS {
        f64::NAN
    } else {
        let k = ((windows - 1) as f64 * QUANTILE).round() as usize;
        let (_, v, _) = rms.select_nth_unstable_by(k, f64::total_cmp);
        *v / chi_rms_quantile(DOF, QUANTILE)
    };
    (sigma, windows)
}

/// Window offsets relative to the corner, centred coordinates: (dx, dy, index offset) for `dx, dy` in −2..=2,
/// row by row.
fn window_offsets(w: usize) -> [(f64, f64, usize); WINDOW * WINDOW] {
    let r = WINDOW / 2;
    std::array::from_fn(|k| {
        let (dx, dy) = (k % WINDOW, k / WINDOW);
        (dx as f64 - r as f64, dy as f64 - r as f64, dy * w + dx)
    })
}

/// Windows computed side by side by [`window_rms`].
const LANES: usize = 4;

/// Residual RMS (√(SSR / 22)) of the least-squares plane of every full 5 × 5 window whose top-left corner
/// lies on every `stride`-th row and column, in raster order.
///
/// `LANES` windows of a row side by side, each with exactly the operations of one window alone (in the same
/// order, so the same bits: [`window_rms_one_by_one`] in the tests), so their dependency chains (the
/// sequential sums) overlap.
fn window_rms(range: &rangeimage::RangeImage, stride: usize, out: &mut Vec<f64>) {
    // Compiled for the best instruction set of this CPU (the same operations in the same order: the same bits).
    isa::dispatch(
        #[inline(always)]
        || window_rms_kernel(range, stride, out),
    );
}

/// [`window_rms`]'s loops.
#[inline(always)] // into `isa::dispatch` in `window_rms`: compiled for each instruction set
fn window_rms_kernel(range: &rangeimage::RangeImage, stride: usize, out: &mut Vec<f64>) {
    let (w, h) = (range.width() as usize, range.height() as usize);
    out.clear();
    if w < WINDOW || h < WINDOW {
        return;
    }
    let data = range.as_slice();
    let r = WINDOW / 2;
    let offsets = window_offsets(w);
    // Σx² = Σy² = 5 · (4 + 1 + 0 + 1 + 4) over the centred window.
    let sxx = 50.0;
    // The corners' columns are k · stride for k < nx, taken `LANES` at a time (a last, shorter group fills its
    // unused lanes with its first column).
    let nx = (w - WINDOW) / stride + 1;
    let lane_dx: [usize; LANES] = std::array::from_fn(|l| l * stride);
    for y0 in (0..=h - WINDOW).step_by(stride) {
        for k0 in (0..nx).step_by(LANES) {
            let (group, first) = (LANES.min(nx - k0), y0 * w + k0 * stride);
            let corner: [usize; LANES] =
                std::array::from_fn(|l| first + if l < group { lane_dx[l] } else { 0 });
            let centre: [f64; LANES] = corner.map(|c| f64::from(data[c + r * w + r]));
            let full: [bool; LANES] = std::array::from_fn(|l| {
                l < group
                    && centre[l].is_finite()
                    && offsets.iter().all(|&(_, _, o)| data[corner[l] + o].is_finite())
            });
            if !full.contains(&true) {
                continue;
            }
            let mut z = [[0.0f64; LANES]; WINDOW * WINDOW];
            let (mut s, mut sx, mut sy) = ([0.0; LANES], [0.0; LANES], [0.0; LANES]);
            for (zk, &(dx, dy, o)) in z.iter_mut().zip(&offsets) {
                for l in 0..LANES {
                    // Relative to the centre, so large depths lose no precision.
                    let d = f64::from(data[corner[l] + o]) - centre[l];
                    zk[l] = d;
                    s[l] += d;
                    sx[l] += dx * d;
                    sy[l] += dy * d;
                }
            }
            let abc: [(f64, f64, f64); LANES] =
                std::array::from_fn(|l| (sx[l] / sxx, sy[l] / sxx, s[l] / (WINDOW * WINDOW) as f64));
            // The sum of the squares from −0, as `Iterator::sum` (the same bits: every square is ≥ +0).
            let mut ssr = [-0.0f64; LANES];
            for (zk, &(dx, dy, _)) in z.iter().zip(&offsets) {
                for l in 0..LANES {
                    let (a, b, c) = abc[l];
                    let e = zk[l] - (a * dx + b * dy + c);
                    ssr[l] += e * e;
                }
            }
            for l in 0..LANES {
                if full[l] {
                    out.push((ssr[l] / DOF).sqrt());
                }
            }
        }
    }
}

/// [`window_rms`] one window at a time (the reference of the tests).
#[cfg(test)]
fn window_rms_one_by_one(range: &rangeimage::RangeImage, stride: usize, out: &mut Vec<f64>) {
    let (w, h) = (range.width() as usize, range.height() as usize);
    out.clear();
    if w < WINDOW || h < WINDOW {
        return;
    }
    let data = range.as_slice();
    let r = WINDOW / 2;
    // Centred window offsets: -2..=2 in x and y.
    let offsets: Vec<(f64, f64, usize)> = (0..WINDOW * WINDOW)
        .map(|k| {
            let (dx, dy) = (k % WINDOW, k / WINDOW);
            (dx as f64 - r as f64, dy as f64 - r as f64, dy * w + dx)
        })
        .collect();
    // Σx² = Σy² = 5 · (4 + 1 + 0 + 1 + 4) over the centred window.
    let sxx = 50.0;
    let mut z = [0.0f64; WINDOW * WINDOW];
    for y0 in (0..=h - WINDOW).step_by(stride) {
        for x0 in (0..=w - WINDOW).step_by(stride) {
            let corner = y0 * w + x0;
            let centre = f64::from(data[corner + r * w + r]);
            if !centre.is_finite() || offsets.iter().any(|&(_, _, o)| !data[corner + o].is_finite()) {
                continue;
            }
            let (mut s, mut sx, mut sy) = (0.0, 0.0, 0.0);
            for (zk, &(dx, dy, o)) in z.iter_mut().zip(&offsets) {
                // Relative to the centre, so large depths lose no precision.
                let d = f64::from(data[corner + o]) - centre;
                *zk = d;
                s += d;
                sx += dx * d;
                sy += dy * d;
            }
            let (a, b, c) = (sx / sxx, sy / sxx, s / (WINDOW * WINDOW) as f64);
            let ssr: f64 = z
                .iter()
                .zip(&offsets)
                .map(|(&zk, &(dx, dy, _))| {
                    let e = zk - (a * dx + b * dy + c);
                    e * e
                })
                .sum();
            out.push((ssr / DOF).sqrt());
        }
    }
}

/// The `p` quantile of `√(χ²_k / k)` (Wilson–Hilferty; within 0.1 % for k = 22).
fn chi_rms_quantile(k: f64, p: f64) -> f64 {
    let z = normal_quantile(p);
    let t = 2.0 / (9.0 * k);
    (1.0 - t + z * t.sqrt()).powi(3).sqrt()
}

/// The standard normal quantile (Acklam's rational approximation, relative error < 1.2e-9).
fn normal_quantile(p: f64) -> f64 {
    const A: [f64; 6] = [
        -3.969_683_028_665_376e1,
        2.209_460_984_245_205e2,
        -2.759_285_104_469_687e2,
        1.383_577_518_672_69e2,
        -3.066_479_806_614_716e1,
        2.506_628_277_459_239,
    ];
    const B: [f64; 5] = [
        -5.447_609_879_822_406e1,
        1.615_858_368_580_409e2,
        -1.556_989_798_598_866e2,
        6.680_131_188_771_972e1,
        -1.328_068_155_288_572e1,
    ];
    const C: [f64; 6] = [
        -7.784_894_002_430_293e-3,
        -3.223_964_580_411_365e-1,
        -2.400_758_277_161_838,
        -2.549_732_539_343_734,
        4.374_664_141_464_968,
        2.938_163_982_698_783,
    ];
    const D: [f64; 4] =
        [7.784_695_709_041_462e-3, 3.224_671_290_700_398e-1, 2.445_134_137_142_996, 3.754_408_661_907_416];
    let tail = |q: f64| {
        (((((C[0] * q + C[1]) * q + C[2]) * q + C[3]) * q + C[4]) * q + C[5])
            / ((((D[0] * q + D[1]) * q + D[2]) * q + D[3]) * q + 1.0)
    };
    if p < 0.02425 {
        tail((-2.0 * p.ln()).sqrt())
    } else if p > 1.0 - 0.02425 {
        -tail((-2.0 * (1.0 - p).ln()).sqrt())
    } else {
        let q = p - 0.5;
        let r = q * q;
        (((((A[0] * r + A[1]) * r + A[2]) * r + A[3]) * r + A[4]) * r + A[5]) * q
            / (((((B[0] * r + B[1]) * r + B[2]) * r + B[3]) * r + B[4]) * r + 1.0)
    }
}

/// The quantisation step of depth: the smallest nonzero absolute difference between 4-neighbours
/// shared by at least 2 % of the nonzero differences, provided 90 % of them are whole multiples of
/// it (within 0.1 %); `None` otherwise (continuous depth, or too few differences).
fn quantisation_step(range: &rangeimage::RangeImage) -> Option<f64> {
    let (w, h) = (range.width() as usize, range.height() as usize);
    let data = range.as_slice();
    let mut diffs = Vec::new();
    for y in 0..h {
        for x in 0..w {
            let v = data[y * w + x];
            for (nx, ny) in [(x + 1, y), (x, y + 1)] {
                if nx < w && ny < h {
                    let d = (f64::from(data[ny * w + nx]) - f64::from(v)).abs();
                    if d.is_finite() && d > 0.0 {
                        diffs.push(d);
                    }
                }
            }
        }
    }
    if diffs.len() < 100 {
        return None;
    }
    diffs.sort_unstable_by(f64::total_cmp);
    let min_count = (diffs.len() as f64 * STEP_MIN_SHARE).ceil() as usize;
    // Runs of equal values (within the relative tolerance of the run's first value), smallest first.
    let mut i = 0;
    let step = loop {
        if i >= diffs.len() {
            return None;
        }
        let first = diffs[i];
        let end = i + diffs[i..].partition_point(|&d| d <= first * (1.0 + STEP_REL_TOL));
        if end - i >= min_count {
            break diffs[i..end].iter().sum::<f64>() / (end - i) as f64;
        }
        i = end;
    };
    let multiples = diffs.iter().filter(|&&d| is_multiple(d, step)).count();
    (multiples as f64 >= STEP_MULTIPLE_SHARE * diffs.len() as f64).then_some(step)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::rngs::Xoshiro256PlusPlus;
    use rand::{RngExt, SeedableRng};
    use rangeimage::{Grid, RangeImage};

    #[test]
    fn step_geometry_measures_a_step_in_3d_at_the_image_centre() {
        // The grid camera's points are (x, y, value): a step of 2 values is 2 units long, the pitch 1.
        let img = Grid::new(40, 30, 100.0f32);
        assert_eq!(step_geometry(&img, &rangeimage::Camera::Grid, 2.0), Some((2.0, 1.0)));
        // On the ABW camera a step of one stored value is 1.26–1.29 units of Z, the pixels about 0.5 apart.
        let (step, pitch) =
            step_geometry(&Grid::new(64, 64, 120.0f32), &rangeimage::Camera::ABW0, 1.0).expect("data");
        assert!((1.2..1.35).contains(&step) && (0.3..0.8).contains(&pitch), "{step} {pitch}");
        assert_eq!(
            step_geometry(&Grid::new(40, 30, f32::NAN), &rangeimage::Camera::Grid, 2.0),
            None,
            "no data"
        );
    }

    #[test]
    fn smallest_step_reads_the_step_of_quantised_depth_only() {
        // A ramp of steps 0.5 down the rows and 2 across, with a no-data pixel (its differences never count).
        let mut img: RangeImage =
            Grid::from_fn(40, 30, |x, y| (10.0 + 2.0 * x as f64 + 0.5 * y as f64) as f32);
        img[(3, 3)] = f32::NAN;
        assert_eq!(smallest_step(&img, 1), Some(0.5));
        assert_eq!(smallest_step(&img, 3), Some(0.5), "every 3rd row and the row below it");
        for s in [0.1, 0.5] {
            let mut rng = Xoshiro256PlusPlus::seed_from_u64(9);
            let noisy = scene(s, Some(0.25), 3);
            assert_eq!(smallest_step(&noisy, 4), Some(0.25), "σ {s}, step 0.25");
            assert_eq!(smallest_step(&scene(s, None, 3), 4), None, "σ {s}, continuous");
            // A steep continuous plane with little noise: its smallest difference is no step.
            let steep: RangeImage = Grid::from_fn(40, 30, |x, y| {
                (3.0 * x as f64 + 0.7 * y as f64 + 0.01 * s * gauss(&mut rng)) as f32
            });
            assert_eq!(smallest_step(&steep, 1), None, "σ {s}, steep plane");
        }
        assert_eq!(smallest_step(&Grid::new(40, 30, 4.0f32), 1), None, "constant depth");
        assert_eq!(smallest_step(&Grid::new(40, 30, f32::NAN), 1), None, "no data");
    }

    #[test]
    fn nearly_uniform_steps_give_their_highest_riser() {
        // Rounded to 3.8 and stored in whole units: risers of 4 and, every fifth, 3.
        let stored = |sigma: f64, seed: u64| -> RangeImage {
            let img = scene(sigma, Some(3.8), seed);
            Grid::from_fn(img.width(), img.height(), |x, y| img[(x, y)].round())
        };
        for (sigma, seed) in [(0.0, 12), (0.25, 13)] {
            let img = stored(sigma, seed);
            let smallest = smallest_difference(&img, 4).expect("differences");
            assert_eq!(smallest, 3.0, "σ {sigma}");
            assert_eq!(smallest_step(&img, 4), None, "σ {sigma}: 4 is no multiple of 3");
            assert_eq!(near_uniform_step(&img, 4, smallest), Some(4.0), "σ {sigma}");
            assert_eq!(estimate(&img).step, Some(4.0), "σ {sigma}");
        }
        // Continuous depth, noisy or steep and smooth: next to no zero differences, no step.
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(14);
        let steep: RangeImage =
            Grid::from_fn(40, 30, |x, y| (3.0 * x as f64 + 0.7 * y as f64 + 0.001 * gauss(&mut rng)) as f32);
        for (name, img) in
            [("σ 0.1", scene(0.1, None, 15)), ("σ 0.5", scene(0.5, None, 16)), ("steep", steep)]
        {
            let smallest = smallest_difference(&img, 1).expect("differences");
            assert_eq!(near_uniform_step(&img, 1, smallest), None, "{name}");
            assert_eq!(estimate(&img).step, None, "{name}");
        }
        // A frontal plane whose few nonzero differences are jumps of many sizes: terraces, but no common riser.
        let blocks: RangeImage =
            Grid::from_fn(60, 40, |x, y| (10 + 7 * (x / 10) * (x / 10) + 3 * (y / 20)) as f32);
        let smallest = smallest_difference(&blocks, 1).expect("differences");
        assert_eq!(near_uniform_step(&blocks, 1, smallest), None);
    }

    /// Unit-variance Gaussian (Irwin–Hall sum of 12 uniforms).
    fn gauss(rng: &mut Xoshiro256PlusPlus) -> f64 {
        (0..12).map(|_| rng.random::<f64>()).sum::<f64>() - 6.0
    }

    /// A 160 × 120 scene of four tilted planes meeting at jumps and creases (6 % of the full 5 × 5
    /// windows straddle an edge), plus Gaussian noise `sigma`, rounded to `step` if given, with a
    /// block of missing data.
    fn scene(sigma: f64, step: Option<f64>, seed: u64) -> RangeImage {
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed);
        Grid::from_fn(160, 120, |x, y| {
            let (x, y) = (f64::from(x), f64::from(y));
            let clean = match (x < 80.0, y < 60.0) {
                (true, true) => 100.0 + 0.31 * x + 0.17 * y,
                (false, true) => 140.0 - 0.23 * x + 0.05 * y,
                (true, false) => 90.0 + 0.43 * y - 0.07 * x,
                (false, false) => 60.0 + 0.9 * y - 0.2 * x,
            };
            let v = clean + sigma * gauss(&mut rng);
            let v = step.map_or(v, |q| (v / q).round() * q);
            if (20.0..30.0).contains(&x) && (70.0..90.0).contains(&y) { f32::NAN } else { v as f32 }
        })
    }

    #[test]
    fn sigma_of_continuous_noise_within_5_percent() {
        for (sigma, seed) in [(0.2, 1), (0.6, 2), (1.0, 3), (3.0, 4)] {
            let e = estimate(&scene(sigma, None, seed));
            assert!((e.sigma / sigma - 1.0).abs() < 0.05, "σ {sigma}: estimated {}", e.sigma);
            assert_eq!(e.step, None, "σ {sigma}: continuous depth has no step");
            assert_eq!(e.sigma_noise(), e.sigma);
            assert!(e.windows > 15_000, "{}", e.windows);
        }
    }

    #[test]
    fn quantised_noise_gives_its_step_and_sigma() {
        for (sigma, q, seed) in [(0.6, 1.0, 5), (1.0, 1.0, 6), (2.0, 1.0, 7), (1.5, 2.0, 8), (0.5, 0.25, 9)] {
            let e = estimate(&scene(sigma, Some(q), seed));
            let step = e.step.expect("quantised depth has a step");
            assert!((step / q - 1.0).abs() < 1e-3, "σ {sigma}, q {q}: step {step}");
            // σ sees the rounding error too; sigma_noise removes it.
            let total = (sigma * sigma + q * q / 12.0).sqrt();
            assert!((e.sigma / total - 1.0).abs() < 0.07, "σ {sigma}, q {q}: total {} vs {total}", e.sigma);
            assert!((e.sigma_noise() / sigma - 1.0).abs() < 0.10, "σ {sigma}, q {q}: {}", e.sigma_noise());
        }
    }

    #[test]
    fn noise_free_staircase_has_a_step_and_little_sigma() {
        let e = estimate(&scene(0.0, Some(0.5), 10));
        assert_eq!(e.step, Some(0.5));
        // Rounding of tilted planes: about q / √12 ≈ 0.14, far from any noise.
        assert!(e.sigma < 0.2, "{}", e.sigma);
    }

    #[test]
    fn edges_do_not_move_sigma_but_a_naive_scale_does() {
        // The naive estimator (RMS of every window) would be far off on the same image.
        let img = scene(0.6, None, 11);
        let mut rms = Vec::new();
        window_rms(&img, 1, &mut rms);
        let naive = (rms.iter().map(|r| r * r).sum::<f64>() / rms.len() as f64).sqrt();
        assert!(naive > 1.5 * 0.6, "the scene's edges matter: naive RMS {naive}");
        let e = estimate(&img);
        assert!((e.sigma / 0.6 - 1.0).abs() < 0.05, "{}", e.sigma);
    }

    /// The windows side by side give the RMS of the windows one by one, bit for bit, on random images with
    /// missing data, every stride up to 5 and widths that leave partial groups, on every instruction-set path.
    #[test]
    fn windows_side_by_side_match_one_by_one() {
        use rand::{RngExt, SeedableRng};
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(11);
        for (w, h) in [(5u32, 5u32), (6, 9), (17, 12), (40, 31), (64, 7)] {
            for missing in [0.0, 0.02, 0.3] {
                let mut img = RangeImage::new(w, h, 0.0);
                for v in img.as_mut_slice() {
                    *v = if rng.random_bool(missing) {
                        [f32::NAN, f32::INFINITY][rng.random_range(0..2usize)]
                    } else {
                        rng.random_range(100.0..2000.0f32)
                    };
                }
                for stride in 1..=5 {
                    let mut b = Vec::new();
                    window_rms_one_by_one(&img, stride, &mut b);
                    let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
                    for path in isa::Isa::available() {
                        let mut a = Vec::new();
                        isa::with_isa(path, || window_rms(&img, stride, &mut a)).expect("available");
                        assert_eq!(
                            bits(&a),
                            bits(&b),
                            "{w}x{h}, missing {missing}, stride {stride}, {path:?}"
                        );
                    }
                }
            }
        }
    }

    #[test]
    fn sampled_sigma_is_close_to_the_full_estimate() {
        for (sigma, seed) in [(0.2, 21), (1.0, 22), (3.0, 23)] {
            let img = scene(sigma, None, seed);
            assert_eq!(sigma_sampled(&img, 1), estimate(&img).sigma, "stride 1 is the full estimate");
            let s4 = sigma_sampled(&img, 4);
            assert!((s4 / sigma - 1.0).abs() < 0.1, "σ {sigma}: stride 4 estimated {s4}");
        }
        assert!(sigma_sampled(&Grid::new(20, 20, 1.0f32), 4).is_nan(), "16 windows are too few");
    }

    #[test]
    fn too_little_data_gives_nan_not_a_panic() {
        let e = estimate(&Grid::new(4, 4, 1.0f32));
        assert!(e.sigma.is_nan() && e.windows == 0 && e.step.is_none());
        let e = estimate(&Grid::new(64, 64, f32::NAN));
        assert!(e.sigma.is_nan() && e.windows == 0 && e.step.is_none());
        // A constant image: σ 0, no nonzero difference, so no step.
        let e = estimate(&Grid::new(64, 64, 7.0f32));
        assert_eq!((e.sigma, e.step), (0.0, None));
    }

    #[test]
    fn quantiles() {
        assert!(normal_quantile(0.5).abs() < 1e-9);
        assert!((normal_quantile(0.25) + 0.674_489_750).abs() < 1e-8);
        assert!((normal_quantile(0.01) + 2.326_347_874).abs() < 1e-8);
        // √(χ²₂₂/22) quantiles: 0.25 → √(17.240 / 22), 0.5 → √(21.337 / 22).
        assert!((chi_rms_quantile(22.0, 0.25) - (17.2396f64 / 22.0).sqrt()).abs() < 1e-3);
        assert!((chi_rms_quantile(22.0, 0.5) - (21.3370f64 / 22.0).sqrt()).abs() < 1e-3);
    }
}
