//! Local plane fits `z = a·x + b·y + c` by running box sums over valid pixels.
//!
//! Each pixel's fit uses the valid pixels of the `w × w` window centred on it (the window is clipped at the image
//! border). x and y are measured from the image centre, so `c` is the same for every pixel of a true plane. The
//! nine sums `Σ1, Σx, Σy, Σx², Σxy, Σy², Σz, Σxz, Σyz` are kept as running sums in `f64`: horizontally with prefix
//! sums per row, vertically with a running accumulator over a ring of row sums, so the cost per pixel does not
//! depend on `w`. The moment sums of the coordinates are exact (half-integers and their products), so collinearity
//! is detected exactly.

use rangeimage::{Grid, PlaneMap, RangeImage};

/// Number of per-row horizontal sums: `Σ1, Σx, Σx², Σz, Σxz`.
const NH: usize = 5;

/// Fits the local plane of every pixel; `[NAN; 3]` at no-data pixels and where the valid pixels of the window are
/// fewer than 3 or collinear.
pub(crate) fn fit(range: &RangeImage, window_px: u32) -> PlaneMap {
    let (w, h) = range.dimensions();
    let (wu, hu) = (w as usize, h as usize);
    let mut out = Grid::new(w, h, [f32::NAN; 3]);
    if wu == 0 || hu == 0 {
        return out;
    }
    let r = (window_px / 2) as usize;
    let cx = (f64::from(w) - 1.0) / 2.0;
    let cy = (f64::from(h) - 1.0) / 2.0;
    let src = range.as_slice();

    // Ring of horizontal window sums, one slot per row of the window plus the row that is leaving.
    let slots = 2 * r + 2;
    let mut ring = vec![[0.0f64; NH]; slots * wu];
    let mut prefix = vec![[0.0f64; NH]; wu + 1];
    // Vertical running sums: n, sx, sy, sxx, sxy, syy, sz, sxz, syz.
    let mut acc = vec![[0.0f64; 9]; wu];

    let row_sums = |yy: usize, prefix: &mut [[f64; NH]], dst: &mut [[f64; NH]]| {
        let row = &src[yy * wu..(yy + 1) * wu];
        let mut p = [0.0f64; NH];
        prefix[0] = p;
        for (x, &z) in row.iter().enumerate() {
            if z.is_finite() {
                let xf = x as f64 - cx;
                let zf = f64::from(z);
                p[0] += 1.0;
                p[1] += xf;
                p[2] += xf * xf;
                p[3] += zf;
                p[4] += xf * zf;
            }
            prefix[x + 1] = p;
        }
        for x in 0..wu {
            let lo = &prefix[x.saturating_sub(r)];
            let hi = &prefix[(x + r + 1).min(wu)];
            dst[x] = [hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2], hi[3] - lo[3], hi[4] - lo[4]];
        }
    };
    let apply = |acc: &mut [[f64; 9]], s: &[[f64; NH]], yy: usize, sign: f64| {
        let yf = yy as f64 - cy;
        let (y1, y2) = (sign * yf, sign * yf * yf);
        for (a, s) in acc.iter_mut().zip(s) {
            a[0] += sign * s[0];
            a[1] += sign * s[1];
            a[2] += y1 * s[0];
            a[3] += sign * s[2];
            a[4] += y1 * s[1];
            a[5] += y2 * s[0];
            a[6] += sign * s[3];
            a[7] += sign * s[4];
            a[8] += y1 * s[3];
        }
    };

    // Rows entering the window of output row y: y + r; leaving: y - r - 1.
    for yy in 0..r.min(hu) {
        let slot = &mut ring[(yy % slots) * wu..(yy % slots + 1) * wu];
        row_sums(yy, &mut prefix, slot);
        apply(&mut acc, &ring[(yy % slots) * wu..(yy % slots + 1) * wu], yy, 1.0);
    }
    let out_slice = out.as_mut_slice();
    for y in 0..hu {
        let yin = y + r;
        if yin < hu {
            let s = (yin % slots) * wu;
            row_sums(yin, &mut prefix, &mut ring[s..s + wu]);
            apply(&mut acc, &ring[s..s + wu], yin, 1.0);
        }
        if y > r {
            let yout = y - r - 1;
            let s = (yout % slots) * wu;
            apply(&mut acc, &ring[s..s + wu], yout, -1.0);
        }
        let row = &src[y * wu..(y + 1) * wu];
        let dst = &mut out_slice[y * wu..(y + 1) * wu];
        for x in 0..wu {
            if row[x].is_finite() {
                dst[x] = solve(&acc[x]);
            }
        }
    }
    out
}

/// Solves the 3-parameter normal equations from the nine sums; NaN when singular.
#[inline]
fn solve(s: &[f64; 9]) -> [f32; 3] {
    let n = s[0];
    if n < 2.5 {
        return [f32::NAN; 3];
    }
    let (sx, sy) = (s[1], s[2]);
    let cxx = s[3] - sx * sx / n;
    let cxy = s[4] - sx * sy / n;
    let cyy = s[5] - sy * sy / n;
    let det = cxx * cyy - cxy * cxy;
    // NaN-safe: a NaN determinant fails `det > …` and is rejected.
    if det.partial_cmp(&(1e-9 * cxx * cyy)) != Some(std::cmp::Ordering::Greater) || cxx <= 0.0 || cyy <= 0.0 {
        return [f32::NAN; 3];
    }
    let mz = s[6] / n;
    let cxz = s[7] - sx * mz;
    let cyz = s[8] - sy * mz;
    let a = (cyy * cxz - cxy * cyz) / det;
    let b = (cxx * cyz - cxy * cxz) / det;
    let c = mz - a * sx / n - b * sy / n;
    [a as f32, b as f32, c as f32]
}
