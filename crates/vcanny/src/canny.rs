//! Non-maximum suppression, threshold selection and hysteresis.

use crate::{ThresholdMode, Thresholds};

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
