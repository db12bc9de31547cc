//! The straightforward per-pixel implementation the streamed one replaced, kept as a test oracle: with the
//! direction left unnormalised (as the streamed one does) its results are bit-identical; with unit directions it
//! is the detector as it was before.

use crate::{Edges, ThresholdMode, Thresholds};
use rangeimage::Grid;

/// Reference `detect`: the same rules as [`crate::detect`], written pixel by pixel.
pub(crate) fn detect(
    channels: &[&Grid<f32>],
    weights: &[f32],
    valid: &Grid<bool>,
    params: &crate::Params,
) -> Edges {
    detect_with(channels, weights, valid, params, false)
}

/// The detector as it was before the fast path: the same, except that the direction handed to non-maximum
/// suppression was normalised to a unit vector (same ratio of components, up to rounding).
pub(crate) fn detect_unit_direction(
    channels: &[&Grid<f32>],
    weights: &[f32],
    valid: &Grid<bool>,
    params: &crate::Params,
) -> Edges {
    detect_with(channels, weights, valid, params, true)
}

fn detect_with(
    channels: &[&Grid<f32>],
    weights: &[f32],
    valid: &Grid<bool>,
    params: &crate::Params,
    normalise: bool,
) -> Edges {
    let (w, h) = (valid.width() as usize, valid.height() as usize);
    let ok: Vec<bool> = (0..w * h)
        .map(|i| valid.as_slice()[i] && channels.iter().all(|c| c.as_slice()[i].is_finite()))
        .collect();
    let g = gaussian(params.sigma_px, params.kernel_px);
    let grad = gradient(channels, weights, &ok, w, h, &g, normalise);
    let nms = non_max_suppression(&grad.magnitude, &grad.direction, &ok, w, h);
    let (low, high) = absolute_thresholds(&params.thresholds, &grad.magnitude, &ok);
    let edges = hysteresis(&grad.magnitude, &nms, w, h, low, high);
    let (wu, hu) = (valid.width(), valid.height());
    Edges {
        edges: Grid::from_vec(wu, hu, edges).expect("size matches"),
        magnitude: Grid::from_vec(wu, hu, grad.magnitude).expect("size matches"),
    }
}

/// Magnitude and unit direction of the multi-channel gradient.
pub(crate) struct Gradient {
    /// `sqrt(λmax)` of the weighted structure tensor; 0 where `ok` is false.
    pub(crate) magnitude: Vec<f32>,
    /// Eigenvector of `λmax` (unit if normalised), canonically oriented (`dx > 0`, or `dx = 0` and `dy ≥ 0`).
    pub(crate) direction: Vec<[f32; 2]>,
}

/// The normalised 1D Gaussian of `kernel_px` taps.
pub(crate) fn gaussian(sigma_px: f32, kernel_px: u32) -> Vec<f32> {
    let r = (kernel_px / 2) as i32;
    let g: Vec<f32> = (-r..=r).map(|i| (-(i * i) as f32 / (2.0 * sigma_px * sigma_px)).exp()).collect();
    let s: f32 = g.iter().sum();
    g.into_iter().map(|v| v / s).collect()
}

/// Separable correlation with `g`, pixels outside the image counted as 0.
fn separable(src: &[f32], w: usize, h: usize, g: &[f32], tmp: &mut Vec<f32>, out: &mut Vec<f32>) {
    let r = g.len() / 2;
    tmp.clear();
    tmp.resize(w * h, 0.0);
    out.clear();
    out.resize(w * h, 0.0);
    let mut pad = vec![0.0f32; w + 2 * r];
    for y in 0..h {
        pad[r..r + w].copy_from_slice(&src[y * w..(y + 1) * w]);
        let dst = &mut tmp[y * w..(y + 1) * w];
        for (k, &gk) in g.iter().enumerate() {
            for (d, &p) in dst.iter_mut().zip(&pad[k..k + w]) {
                *d += gk * p;
            }
        }
    }
    for y in 0..h {
        let dst = &mut out[y * w..(y + 1) * w];
        for (k, &gk) in g.iter().enumerate() {
            let yy = y as isize + k as isize - r as isize;
            if yy < 0 || yy >= h as isize {
                continue;
            }
            let yy = yy as usize;
            for (d, &p) in dst.iter_mut().zip(&tmp[yy * w..(yy + 1) * w]) {
                *d += gk * p;
            }
        }
    }
}

/// Smooths each channel over the `ok` pixels, takes Sobel derivatives and combines them with the Di Zenzo tensor;
/// the direction is the eigenvector of λmax, a unit vector if `normalise`.
fn gradient(
    channels: &[&Grid<f32>],
    weights: &[f32],
    ok: &[bool],
    w: usize,
    h: usize,
    g: &[f32],
    normalise: bool,
) -> Gradient {
    let n = w * h;
    let mut tmp = Vec::new();
    let mask: Vec<f32> = ok.iter().map(|&o| if o { 1.0 } else { 0.0 }).collect();
    let mut norm = Vec::new();
    separable(&mask, w, h, g, &mut tmp, &mut norm);
    let inv: Vec<f32> =
        norm.iter().zip(ok).map(|(&s, &o)| if o && s > 0.0 { 1.0 / s } else { 0.0 }).collect();

    // Structure tensor [Jxx, Jxy, Jyy].
    let mut jxx = vec![0.0f32; n];
    let mut jxy = vec![0.0f32; n];
    let mut jyy = vec![0.0f32; n];
    let mut masked = vec![0.0f32; n];
    let mut sm = Vec::new();
    for (ch, &wt) in channels.iter().zip(weights) {
        if wt == 0.0 {
            continue;
        }
        for ((m, &v), &o) in masked.iter_mut().zip(ch.as_slice()).zip(ok) {
            *m = if o { v } else { 0.0 };
        }
        separable(&masked, w, h, g, &mut tmp, &mut sm);
        for (s, &iv) in sm.iter_mut().zip(&inv) {
            *s *= iv;
        }
        sobel_accumulate(&sm, ok, w, h, wt, &mut jxx, &mut jxy, &mut jyy);
    }

    let mut magnitude = vec![0.0f32; n];
    let mut direction = vec![[1.0f32, 0.0]; n];
    for i in 0..n {
        if !ok[i] {
            continue;
        }
        let (p, q, s) = (jxx[i], jxy[i], jyy[i]);
        let half = 0.5 * (p - s);
        let root = (half * half + q * q).sqrt();
        let lmax = (0.5 * (p + s) + root).max(0.0);
        magnitude[i] = lmax.sqrt();
        // Eigenvector of λmax: (q, λ − p) or (λ − s, q), whichever is better conditioned.
        let (v1, v2) = ([q, lmax - p], [lmax - s, q]);
        let (n1, n2) = (v1[0] * v1[0] + v1[1] * v1[1], v2[0] * v2[0] + v2[1] * v2[1]);
        let (v, nn) = if n1 >= n2 { (v1, n1) } else { (v2, n2) };
        if nn > 0.0 && nn.is_finite() {
            let l = if normalise { nn.sqrt() } else { 1.0 };
            let (mut dx, mut dy) = if normalise { (v[0] / l, v[1] / l) } else { (v[0], v[1]) };
            if dx < 0.0 || (dx == 0.0 && dy < 0.0) {
                dx = -dx;
                dy = -dy;
            }
            direction[i] = [dx, dy];
        }
    }
    Gradient { magnitude, direction }
}

/// Adds `wt · [gx², gx·gy, gy²]` of the Sobel derivatives (scaled to per-pixel units) of `s` to the tensor.
/// A neighbour that is not `ok` (or outside the image) takes the centre pixel's value, so missing data adds no
/// gradient and real steps between valid pixels are kept.
#[allow(clippy::too_many_arguments)]
fn sobel_accumulate(
    s: &[f32],
    ok: &[bool],
    w: usize,
    h: usize,
    wt: f32,
    jxx: &mut [f32],
    jxy: &mut [f32],
    jyy: &mut [f32],
) {
    for y in 0..h {
        let interior_row = y > 0 && y + 1 < h;
        for x in 0..w {
            let i = y * w + x;
            if !ok[i] {
                continue;
            }
            let c = s[i];
            let (gx, gy) = if interior_row
                && x > 0
                && x + 1 < w
                && ok[i - w - 1]
                && ok[i - w]
                && ok[i - w + 1]
                && ok[i - 1]
                && ok[i + 1]
                && ok[i + w - 1]
                && ok[i + w]
                && ok[i + w + 1]
            {
                let (a, b, cc) = (s[i - w - 1], s[i - w], s[i - w + 1]);
                let (d, f) = (s[i - 1], s[i + 1]);
                let (gg, hh, ii) = (s[i + w - 1], s[i + w], s[i + w + 1]);
                ((cc + 2.0 * f + ii) - (a + 2.0 * d + gg), (gg + 2.0 * hh + ii) - (a + 2.0 * b + cc))
            } else {
                let at = |dx: isize, dy: isize| {
                    let (xx, yy) = (x as isize + dx, y as isize + dy);
                    if xx < 0 || yy < 0 || xx >= w as isize || yy >= h as isize {
                        return c;
                    }
                    let j = yy as usize * w + xx as usize;
                    if ok[j] { s[j] } else { c }
                };
                let gx = (at(1, -1) + 2.0 * at(1, 0) + at(1, 1)) - (at(-1, -1) + 2.0 * at(-1, 0) + at(-1, 1));
                let gy = (at(-1, 1) + 2.0 * at(0, 1) + at(1, 1)) - (at(-1, -1) + 2.0 * at(0, -1) + at(1, -1));
                (gx, gy)
            };
            let (gx, gy) = (gx * 0.125, gy * 0.125);
            jxx[i] += wt * gx * gx;
            jxy[i] += wt * gx * gy;
            jyy[i] += wt * gy * gy;
        }
    }
}

/// Keeps the pixels whose magnitude is a maximum along the gradient direction, interpolating the two neighbours
/// on the 3×3 ring linearly. Ties keep the pixel on the negative side of the (canonically oriented) direction, so
/// a symmetric two-pixel ridge gives a one-pixel edge.
pub(crate) fn non_max_suppression(
    mag: &[f32],
    dir: &[[f32; 2]],
    ok: &[bool],
    w: usize,
    h: usize,
) -> Vec<bool> {
    let at = |x: isize, y: isize| -> f32 {
        if x < 0 || y < 0 || x >= w as isize || y >= h as isize {
            return 0.0;
        }
        let j = y as usize * w + x as usize;
        if ok[j] { mag[j] } else { 0.0 }
    };
    let mut keep = vec![false; w * h];
    for y in 0..h {
        for x in 0..w {
            let i = y * w + x;
            let m = mag[i];
            if !ok[i] || m <= 0.0 {
                continue;
            }
            let [dx, dy] = dir[i];
            let (xi, yi) = (x as isize, y as isize);
            // Sample the ring at ±d scaled so that max(|dx|, |dy|) = 1.
            let sample = |s: isize| -> f32 {
                if dx.abs() >= dy.abs() {
                    let sx = if dx >= 0.0 { s } else { -s };
                    let t = dy / dx.abs() * s as f32;
                    let sy = if t >= 0.0 { 1 } else { -1 };
                    let f = t.abs();
                    (1.0 - f) * at(xi + sx, yi) + f * at(xi + sx, yi + sy)
                } else {
                    let sy = if dy >= 0.0 { s } else { -s };
                    let t = dx / dy.abs() * s as f32;
                    let sx = if t >= 0.0 { 1 } else { -1 };
                    let f = t.abs();
                    (1.0 - f) * at(xi, yi + sy) + f * at(xi + sx, yi + sy)
                }
            };
            let (fwd, bwd) = (sample(1), sample(-1));
            keep[i] = m >= fwd && m > bwd;
        }
    }
    keep
}

/// The `(low, high)` absolute thresholds for `mag` over the `ok` pixels.
pub(crate) fn absolute_thresholds(t: &Thresholds, mag: &[f32], ok: &[bool]) -> (f32, f32) {
    match t.mode {
        ThresholdMode::Absolute => (t.low, t.high),
        ThresholdMode::Quantile => {
            let mut v: Vec<f32> = mag.iter().zip(ok).filter(|&(_, &o)| o).map(|(&m, _)| m).collect();
            (quantile(&mut v, t.low), quantile(&mut v, t.high))
        }
        ThresholdMode::NoiseRelative => {
            let mut v: Vec<f32> = mag.iter().zip(ok).filter(|&(_, &o)| o).map(|(&m, _)| m).collect();
            let noise = quantile(&mut v, 0.5).max(t.noise_floor);
            (t.low * noise, t.high * noise)
        }
    }
}

/// The `q`-quantile (nearest rank) of `v`; `+inf` for an empty slice so nothing passes.
pub(crate) fn quantile(v: &mut [f32], q: f32) -> f32 {
    if v.is_empty() {
        return f32::INFINITY;
    }
    let k = ((q.clamp(0.0, 1.0) * (v.len() - 1) as f32).round() as usize).min(v.len() - 1);
    let (_, x, _) = v.select_nth_unstable_by(k, f32::total_cmp);
    *x
}

/// Hysteresis: the candidates with magnitude ≥ `low` that are 8-connected through such candidates to one with
/// magnitude ≥ `high`. A flood fill from the strong pixels, so the result does not depend on the scan order.
pub(crate) fn hysteresis(mag: &[f32], cand: &[bool], w: usize, h: usize, low: f32, high: f32) -> Vec<bool> {
    let weak = |i: usize| cand[i] && mag[i] >= low;
    let mut out = vec![false; w * h];
    let mut stack = Vec::new();
    for i in 0..w * h {
        if cand[i] && mag[i] >= high && mag[i] >= low && !out[i] {
            out[i] = true;
            stack.push(i);
            while let Some(j) = stack.pop() {
                let (x, y) = ((j % w) as isize, (j / w) as isize);
                for dy in -1..=1isize {
                    for dx in -1..=1isize {
                        let (xx, yy) = (x + dx, y + dy);
                        if xx < 0 || yy < 0 || xx >= w as isize || yy >= h as isize {
                            continue;
                        }
                        let k = yy as usize * w + xx as usize;
                        if !out[k] && weak(k) {
                            out[k] = true;
                            stack.push(k);
                        }
                    }
                }
            }
        }
    }
    out
}
