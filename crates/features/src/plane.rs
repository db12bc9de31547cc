//! Local plane fits `z = a·x + b·y + c` over the valid pixels of a window.
//!
//! Each pixel's fit uses the valid pixels of the `w × w` window centred on it (the window is clipped at the image
//! border). x and y are measured from the image centre, so `c` is the same for every pixel of a true plane. The fits
//! come from the row engine ([`crate::fit`], its plane-only mode): full windows by separable filters (O(w) per pixel with tiny constants),
//! the others from the nine sums `Σ1, Σu, Σv, Σu², Σuv, Σv², Σz, Σuz, Σvz` of their valid pixels ([`solve`]). The
//! coordinate sums are exact (integers), so collinearity is detected exactly.

use crate::fit::{Fit, Path, RowFitter};
use rangeimage::{PlaneMap, RangeImage};

/// Fits the local plane of every pixel; `[NAN; 3]` at no-data pixels and where the valid pixels of the window are
/// fewer than 3 or collinear.
pub(crate) fn fit(range: &RangeImage, window_px: u32) -> PlaneMap {
    let (w, h) = range.dimensions();
    let (wu, hu) = (w as usize, h as usize);
    let mut fitter = RowFitter::new(range.as_slice(), wu, hu, window_px, Path::Fast, Fit::Plane);
    // Zeroed memory is not filled first (the allocator's zeroed pages); the fitter writes every value of each row.
    let mut plane = vec![[0.0f32; 3]; wu * hu];
    // The plane-only engine does not write these.
    let mut deriv = crate::fit::deriv_row(wu);
    for (y, row) in plane.chunks_exact_mut(wu.max(1)).enumerate() {
        fitter.row(y, row, &mut deriv);
    }
    PlaneMap::from_vec(w, h, plane).expect("size matches")
}

/// Solves the 3-parameter normal equations from the nine sums `[n, Σx, Σy, Σx², Σxy, Σy², Σz, Σxz, Σyz]`;
/// `None` when fewer than 3 points or (near) collinear. One system of [`solve_lanes`].
#[inline]
pub(crate) fn solve(s: &[f64; 9]) -> Option<[f64; 3]> {
    let [r] = solve_lanes(&s.map(|v| [v]));
    r
}

/// [`solve`] of `L` independent systems at once, one per lane (`s[sum][lane]`): each lane's arithmetic is the
/// single system's, in the same order, so its result is bit-identical to solving it alone; the lanes run side by
/// side (their divisions overlap). Inlined, so it is compiled for each instruction set where a dispatched loop calls
/// it.
#[inline(always)]
pub(crate) fn solve_lanes<const L: usize>(s: &[[f64; L]; 9]) -> [Option<[f64; 3]>; L] {
    let mut out = [None; L];
    for l in 0..L {
        let n = s[0][l];
        let (sx, sy) = (s[1][l], s[2][l]);
        let cxx = s[3][l] - sx * sx / n;
        let cxy = s[4][l] - sx * sy / n;
        let cyy = s[5][l] - sy * sy / n;
        let det = cxx * cyy - cxy * cxy;
        // NaN-safe: a NaN determinant fails `det > …` and is rejected.
        let reject = n < 2.5
            || det.partial_cmp(&(1e-9 * cxx * cyy)) != Some(std::cmp::Ordering::Greater)
            || cxx <= 0.0
            || cyy <= 0.0;
        let mz = s[6][l] / n;
        let cxz = s[7][l] - sx * mz;
        let cyz = s[8][l] - sy * mz;
        let a = (cyy * cxz - cxy * cyz) / det;
        let b = (cxx * cyz - cxy * cxz) / det;
        let c = mz - a * sx / n - b * sy / n;
        out[l] = (!reject).then_some([a, b, c]);
    }
    out
}
