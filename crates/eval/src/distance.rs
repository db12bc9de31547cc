//! Distances for the metrics: the workspace's one exact Euclidean distance transform
//! ([`rangeimage::distance::edt_squared`], re-exported here), its square root, and dilation by a tolerance.
//!
//! Squared distances are exact integers in `f64`; "within τ" tests in this crate compare squared distances with
//! `τ²` and never take a square root, so they agree with [`rangeimage::distance::within`].

use rangeimage::Grid;

pub use rangeimage::distance::edt_squared;

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

#[cfg(test)]
mod tests {
    use super::*;

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
    fn dilate_is_the_shared_within_test() {
        let mut m = Grid::new(9, 6, false);
        m[(3, 3)] = true;
        m[(8, 0)] = true;
        for t in [0.0, 1.0, 2.0, 2.5] {
            assert_eq!(dilate(&m, t), rangeimage::distance::within(&m, t), "t = {t}");
        }
    }
}
