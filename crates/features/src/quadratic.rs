//! Least-squares quadratic derivatives (2D Savitzky–Golay) over valid pixels.
//!
//! The fit is `z = c0 + c1·u + c2·v + c3·u² + c4·u·v + c5·v²` in window coordinates `(u, v)` centred on the pixel.
//! For a window whose pixels are all valid, the coefficients are `c = (AᵀA)⁻¹ Aᵀ z` with the fixed design matrix
//! `A`; `(AᵀA)⁻¹ = A⁺ A⁺ᵀ` comes from faer's QR pseudo-inverse, computed once, and the six moments `Aᵀz` are separable
//! filters (row pass `Σ uᵏ z`, column pass `Σ vˡ ·`). A window with missing pixels (no data, or the image border) is
//! fitted from its valid pixels alone by solving its own 6×6 normal equations (Cholesky); if they are singular
//! (fewer than 6 valid pixels in general position) the pixel gets NaN. No-data pixels never enter a fit.

use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::qr::no_pivoting::{factor, solve};
use faer::{Mat, Par};
use rangeimage::{Grid, RangeImage};

/// The fixed part of the quadratic fit for one window size.
#[derive(Debug, Clone)]
pub(crate) struct SgKernels {
    /// Half window.
    r: usize,
    /// `(AᵀA)⁻¹`, for the moments in basis order `[1, u, v, u², uv, v²]`.
    m: [[f64; 6]; 6],
    /// The pseudo-inverse `A⁺` (6 × w²), window pixels in row-major order; row `j` is the kernel of `c_j`
    /// (kept for the tests that check it against the closed-form Savitzky–Golay kernels).
    #[cfg_attr(not(test), allow(dead_code))]
    pub(crate) pinv: Vec<[f64; 6]>,
}

/// The basis `[1, u, v, u², uv, v²]` at window offset `(u, v)`.
#[inline]
fn basis(u: f64, v: f64) -> [f64; 6] {
    [1.0, u, v, u * u, u * v, v * v]
}

impl SgKernels {
    /// Computes the kernels of a `window_px × window_px` window (odd, ≥ 3) with faer's QR (sequential).
    pub(crate) fn new(window_px: u32) -> Self {
        assert!(
            window_px >= 3 && !window_px.is_multiple_of(2),
            "quadratic window must be odd and ≥ 3, got {window_px}"
        );
        let w = window_px as usize;
        let r = w / 2;
        let n = w * w;
        let off = |i: usize| ((i % w) as f64 - r as f64, (i / w) as f64 - r as f64);
        let mut a = Mat::<f64>::from_fn(n, 6, |i, j| {
            let (u, v) = off(i);
            basis(u, v)[j]
        });
        let bs = factor::recommended_block_size::<f64>(n, 6);
        let mut q = Mat::<f64>::zeros(bs, 6);
        let req = factor::qr_in_place_scratch::<f64>(n, 6, bs, Par::Seq, Default::default())
            .or(solve::solve_lstsq_in_place_scratch::<f64>(n, 6, bs, n, Par::Seq));
        let mut mem = MemBuffer::new(req);
        let stack = MemStack::new(&mut mem);
        factor::qr_in_place(a.as_mut(), q.as_mut(), Par::Seq, stack, Default::default());
        let mut rhs = Mat::<f64>::identity(n, n);
        solve::solve_lstsq_in_place(a.as_ref(), q.as_ref(), a.as_ref(), rhs.as_mut(), Par::Seq, stack);
        // The first 6 rows of the solution are A⁺.
        let pinv: Vec<[f64; 6]> = (0..n).map(|i| std::array::from_fn(|j| rhs[(j, i)])).collect();
        let mut m = [[0.0; 6]; 6];
        for (j, mj) in m.iter_mut().enumerate() {
            for (k, mjk) in mj.iter_mut().enumerate() {
                *mjk = pinv.iter().map(|p| p[j] * p[k]).sum();
            }
        }
        Self { r, m, pinv }
    }
}

/// First and second derivatives `([Ix, Iy], [Ixx, Ixy, Iyy])` of every pixel; NaN at no-data pixels and where the
/// valid pixels of the window do not determine a quadratic.
pub(crate) fn derivatives(range: &RangeImage, k: &SgKernels) -> (Grid<[f32; 2]>, Grid<[f32; 3]>) {
    let (w, h) = range.dimensions();
    let (wu, hu) = (w as usize, h as usize);
    let mut grad = Grid::new(w, h, [f32::NAN; 2]);
    let mut hess = Grid::new(w, h, [f32::NAN; 3]);
    if wu == 0 || hu == 0 {
        return (grad, hess);
    }
    let r = k.r;
    let win = 2 * r + 1;
    let full = (win * win) as f64;
    let src = range.as_slice();
    // Subtract a reference depth so the moments stay small; it cancels in c1..c5.
    let zref = src.iter().find(|v| v.is_finite()).map_or(0.0, |&v| f64::from(v));
    let z0: Vec<f64> = src.iter().map(|&v| if v.is_finite() { f64::from(v) - zref } else { 0.0 }).collect();
    let m0: Vec<f64> = src.iter().map(|&v| if v.is_finite() { 1.0 } else { 0.0 }).collect();

    // Ring of row passes: [count, Σz, Σuz, Σu²z] per row, indexed by row mod win.
    let mut ring = vec![[0.0f64; 4]; win * wu];
    let row_pass = |yy: usize, dst: &mut [[f64; 4]]| {
        let zr = &z0[yy * wu..(yy + 1) * wu];
        let mr = &m0[yy * wu..(yy + 1) * wu];
        for x in 0..wu {
            let mut s = [0.0f64; 4];
            let lo = x.saturating_sub(r);
            let hi = (x + r).min(wu - 1);
            for xx in lo..=hi {
                let u = xx as f64 - x as f64;
                let z = zr[xx];
                s[0] += mr[xx];
                s[1] += z;
                s[2] += u * z;
                s[3] += u * u * z;
            }
            dst[x] = s;
        }
    };
    let mut mom = vec![[0.0f64; 7]; wu];
    let kk = &k.m;
    let (gs, hs) = (grad.as_mut_slice(), hess.as_mut_slice());
    for yy in 0..hu + r {
        let slot = (yy % win) * wu;
        if yy < hu {
            row_pass(yy, &mut ring[slot..slot + wu]);
        } else {
            ring[slot..slot + wu].fill([0.0; 4]);
        }
        if yy < r {
            continue;
        }
        let y = yy - r;
        // Column pass: rows y - r ..= y + r (rows outside the image are zero slots).
        mom.fill([0.0; 7]);
        for dv in 0..win {
            let row = y as isize + dv as isize - r as isize;
            if row < 0 {
                continue;
            }
            let v = dv as f64 - r as f64;
            let s = (row as usize % win) * wu;
            for (m, h) in mom.iter_mut().zip(&ring[s..s + wu]) {
                m[0] += h[0];
                m[1] += h[1];
                m[2] += h[2];
                m[3] += v * h[1];
                m[4] += h[3];
                m[5] += v * h[2];
                m[6] += v * v * h[1];
            }
        }
        let row = &src[y * wu..(y + 1) * wu];
        for x in 0..wu {
            if !row[x].is_finite() {
                continue;
            }
            let c = if mom[x][0] == full {
                let mm = &mom[x][1..];
                let mut c = [0.0f64; 6];
                for j in 1..6 {
                    c[j] = (0..6).map(|q| kk[j][q] * mm[q]).sum();
                }
                Some(c)
            } else {
                fit_partial(src, wu, hu, x, y, r)
            };
            let i = y * wu + x;
            if let Some(c) = c {
                gs[i] = [c[1] as f32, c[2] as f32];
                hs[i] = [(2.0 * c[3]) as f32, c[4] as f32, (2.0 * c[5]) as f32];
            }
        }
    }
    (grad, hess)
}

/// Fits the quadratic to the valid pixels of the window around `(x, y)` by its own normal equations.
fn fit_partial(src: &[f32], wu: usize, hu: usize, x: usize, y: usize, r: usize) -> Option<[f64; 6]> {
    let mut n = [[0.0f64; 6]; 6];
    let mut rhs = [0.0f64; 6];
    let zc = f64::from(src[y * wu + x]);
    let mut count = 0;
    for yy in y.saturating_sub(r)..=(y + r).min(hu - 1) {
        for xx in x.saturating_sub(r)..=(x + r).min(wu - 1) {
            let z = src[yy * wu + xx];
            if !z.is_finite() {
                continue;
            }
            count += 1;
            let b = basis(xx as f64 - x as f64, yy as f64 - y as f64);
            let z = f64::from(z) - zc;
            for i in 0..6 {
                rhs[i] += b[i] * z;
                for j in 0..=i {
                    n[i][j] += b[i] * b[j];
                }
            }
        }
    }
    if count < 6 {
        return None;
    }
    cholesky_solve(&mut n, &mut rhs).then_some(rhs)
}

/// Solves `N c = rhs` in place for symmetric positive definite `N` (lower triangle used); false if (near) singular.
fn cholesky_solve(n: &mut [[f64; 6]; 6], rhs: &mut [f64; 6]) -> bool {
    for j in 0..6 {
        let diag0 = n[j][j];
        let mut d = diag0;
        for k in 0..j {
            d -= n[j][k] * n[j][k];
        }
        if d.partial_cmp(&(1e-9 * diag0.max(1e-300))) != Some(std::cmp::Ordering::Greater) {
            return false;
        }
        let d = d.sqrt();
        n[j][j] = d;
        for i in j + 1..6 {
            let mut s = n[i][j];
            for k in 0..j {
                s -= n[i][k] * n[j][k];
            }
            n[i][j] = s / d;
        }
    }
    for i in 0..6 {
        let mut s = rhs[i];
        for k in 0..i {
            s -= n[i][k] * rhs[k];
        }
        rhs[i] = s / n[i][i];
    }
    for i in (0..6).rev() {
        let mut s = rhs[i];
        for k in i + 1..6 {
            s -= n[k][i] * rhs[k];
        }
        rhs[i] = s / n[i][i];
    }
    true
}
