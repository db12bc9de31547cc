//! Exact Euclidean distance transform (Felzenszwalb–Huttenlocher, separable, O(pixels)).
//!
//! The transform finds, per column, the distance to the nearest set pixel (two scans), then
//! runs the 1D lower-envelope-of-parabolas pass along every row. Squared distances are integers, computed in `f64`, so they are exact
//! for any image that fits in memory; "within τ" tests in this crate compare squared
//! distances with `τ²` and never take a square root.

use rangeimage::Grid;

/// Squared Euclidean distance from every pixel to the nearest `true` pixel of `mask`.
///
/// `0.0` on `true` pixels; `f64::INFINITY` everywhere if `mask` has no `true` pixel.
/// Distances are measured between pixel centres, so a 4-neighbour is at 1 and a diagonal
/// neighbour at 2 (squared). Exact, not an approximation (chamfer, 3×3 passes, …).
pub fn edt_squared(mask: &Grid<bool>) -> Grid<f64> {
    let (w, h) = (mask.width() as usize, mask.height() as usize);
    let m = mask.as_slice();
    // Column pass: for a binary mask the 1D transform is the squared distance to the nearest
    // `true` pixel in the same column, found by a downward and an upward scan. Scanning row by
    // row keeps memory access sequential.
    let mut out = vec![f64::INFINITY; w * h];
    for y in 0..h {
        for x in 0..w {
            let i = y * w + x;
            out[i] = if m[i] {
                0.0
            } else if y > 0 {
                out[i - w] + 1.0
            } else {
                f64::INFINITY
            };
        }
    }
    for y in (0..h.saturating_sub(1)).rev() {
        for x in 0..w {
            let i = y * w + x;
            out[i] = out[i].min(out[i + w] + 1.0);
        }
    }
    for v in &mut out {
        *v *= *v;
    }
    // Row pass: lower envelope of parabolas (Felzenszwalb–Huttenlocher).
    let mut scratch = Scratch { f: vec![0.0; w], d: vec![0.0; w], v: vec![0; w], z: vec![0.0; w + 1] };
    for y in 0..h {
        scratch.f.copy_from_slice(&out[y * w..(y + 1) * w]);
        scratch.run(w);
        out[y * w..(y + 1) * w].copy_from_slice(&scratch.d);
    }
    Grid::from_vec(mask.width(), mask.height(), out).expect("same size as the mask")
}

/// Euclidean distance in pixels from every pixel to the nearest `true` pixel of `mask`.
///
/// `0.0` on `true` pixels; `f32::INFINITY` everywhere if `mask` has no `true` pixel.
/// This is the square root of [`edt_squared`], rounded to `f32`.
pub fn edt(mask: &Grid<bool>) -> Grid<f32> {
    edt_squared(mask).map(|&d2| d2.sqrt() as f32)
}

/// `true` where the pixel lies within `tolerance_px` (Euclidean, inclusive) of a `true` pixel of `mask`.
///
/// # Panics
/// If `tolerance_px` is negative or not finite.
pub fn dilate(mask: &Grid<bool>, tolerance_px: f64) -> Grid<bool> {
    let r2 = radius_squared(tolerance_px);
    edt_squared(mask).map(|&d2| d2 <= r2)
}

/// `τ²`, after checking `τ` is a usable tolerance.
pub(crate) fn radius_squared(tolerance_px: f64) -> f64 {
    assert!(
        tolerance_px.is_finite() && tolerance_px >= 0.0,
        "tolerance_px must be finite and ≥ 0, got {tolerance_px}"
    );
    tolerance_px * tolerance_px
}

/// Buffers of the 1D transform, reused across rows and columns.
struct Scratch {
    /// Input: squared vertical distance per sample (∞ if the column has no set pixel).
    f: Vec<f64>,
    /// Output: lower envelope of the parabolas at every sample.
    d: Vec<f64>,
    /// Sample positions of the parabolas in the envelope.
    v: Vec<usize>,
    /// Boundaries between consecutive envelope parabolas.
    z: Vec<f64>,
}

impl Scratch {
    /// 1D squared distance transform of `f[..n]` into `d[..n]`; only finite samples are sites.
    fn run(&mut self, n: usize) {
        let Scratch { f, d, v, z } = self;
        let mut k: Option<usize> = None;
        for q in 0..n {
            let fq = f[q];
            if !fq.is_finite() {
                continue;
            }
            let qf = q as f64;
            match k {
                None => {
                    v[0] = q;
                    z[0] = f64::NEG_INFINITY;
                    z[1] = f64::INFINITY;
                    k = Some(0);
                }
                Some(mut kk) => {
                    // z[0] = −∞ and `s` is finite, so the loop stops at kk = 0 at the latest.
                    let s = loop {
                        let p = v[kk];
                        let pf = p as f64;
                        let s = ((fq + qf * qf) - (f[p] + pf * pf)) / (2.0 * qf - 2.0 * pf);
                        if s <= z[kk] {
                            kk -= 1;
                        } else {
                            break s;
                        }
                    };
                    kk += 1;
                    v[kk] = q;
                    z[kk] = s;
                    z[kk + 1] = f64::INFINITY;
                    k = Some(kk);
                }
            }
        }
        if k.is_none() {
            d[..n].fill(f64::INFINITY);
            return;
        }
        let mut kk = 0;
        for q in 0..n {
            let qf = q as f64;
            while z[kk + 1] < qf {
                kk += 1;
            }
            let p = v[kk];
            let dq = qf - p as f64;
            d[q] = dq * dq + f[p];
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Brute-force squared distance to the nearest `true` pixel.
    fn brute(mask: &Grid<bool>) -> Grid<f64> {
        let pts: Vec<(i64, i64)> =
            mask.enumerate().filter(|(_, _, m)| **m).map(|(x, y, _)| (i64::from(x), i64::from(y))).collect();
        Grid::from_fn(mask.width(), mask.height(), |x, y| {
            pts.iter()
                .map(|&(px, py)| {
                    let (dx, dy) = (px - i64::from(x), py - i64::from(y));
                    (dx * dx + dy * dy) as f64
                })
                .fold(f64::INFINITY, f64::min)
        })
    }

    #[test]
    fn single_point() {
        let mut m = Grid::new(5, 4, false);
        m[(1, 2)] = true;
        let d = edt(&m);
        assert_eq!(d[(1, 2)], 0.0);
        assert_eq!(d[(2, 2)], 1.0);
        approx::assert_relative_eq!(d[(2, 3)], 2f32.sqrt());
        approx::assert_relative_eq!(d[(4, 0)], 13f32.sqrt());
    }

    #[test]
    fn empty_mask_is_infinite() {
        let d = edt(&Grid::new(3, 3, false));
        assert!(d.as_slice().iter().all(|v| v.is_infinite()));
        let d = edt(&Grid::new(3, 3, true));
        assert!(d.as_slice().iter().all(|&v| v == 0.0));
    }

    #[test]
    fn dilate_is_inclusive() {
        let mut m = Grid::new(7, 7, false);
        m[(3, 3)] = true;
        let d = dilate(&m, 2.0);
        assert!(d[(5, 3)] && d[(3, 1)] && !d[(5, 4)] && d[(4, 4)]);
        assert_eq!(d.as_slice().iter().filter(|&&b| b).count(), 13);
    }

    mod proptests {
        use super::*;
        use proptest::prelude::*;

        proptest! {
            #[test]
            fn proptest_edt_matches_brute_force(
                (w, h, bits) in (1u32..24, 1u32..24).prop_flat_map(|(w, h)| {
                    (Just(w), Just(h), proptest::collection::vec(prop_oneof![6 => Just(false), 1 => Just(true)], (w * h) as usize))
                })
            ) {
                let m = Grid::from_vec(w, h, bits).unwrap();
                let fast = edt_squared(&m);
                let slow = brute(&m);
                prop_assert_eq!(fast.as_slice(), slow.as_slice());
            }
        }
    }
}
