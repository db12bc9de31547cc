//! The quadratic (2D Savitzky–Golay) fit's fixed kernels, and the small solver of its partial-window fits.
//!
//! The fit is `z = c0 + c1·u + c2·v + c3·u² + c4·u·v + c5·v²` in window coordinates `(u, v)` centred on the pixel.
//! For a window whose pixels are all valid the coefficients are `c = A⁺ z` with the pseudo-inverse `A⁺` of the fixed
//! design matrix `A`, computed once with faer's QR; the row engine ([`crate::fit`]) applies these kernels as
//! separable filters. A window with missing pixels (no data, or the image border) is fitted from its valid pixels
//! alone by solving its own 6×6 normal equations ([`cholesky_solve`], square-root-free `LDLᵀ`); if they are singular (fewer than 6 valid
//! pixels in general position) the pixel gets NaN. No-data pixels never enter a fit.

use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::qr::no_pivoting::{factor, solve};
use faer::{Mat, Par};

/// The fixed part of the quadratic fit for one window size.
#[derive(Debug, Clone)]
pub(crate) struct SgKernels {
    /// The pseudo-inverse `A⁺` (w² × 6), window pixels in row-major order; column `j` is the kernel of `c_j`.
    pub(crate) pinv: Vec<[f64; 6]>,
}

/// The basis `[1, u, v, u², uv, v²]` at window offset `(u, v)`.
#[inline]
pub(crate) fn basis(u: f64, v: f64) -> [f64; 6] {
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
        Self { pinv }
    }
}

/// Solves `N c = rhs` in place for symmetric positive definite `N` (lower triangle used) by an `LDLᵀ`
/// factorisation (no square roots, one division per column); false if (near) singular: a pivot `D_j` not above
/// `1e-9 · N_jj`. One system of [`cholesky_solve_lanes`].
pub(crate) fn cholesky_solve(n: &mut [[f64; 6]; 6], rhs: &mut [f64; 6]) -> bool {
    let mut nl = n.map(|row| row.map(|v| [v]));
    let mut rl = rhs.map(|v| [v]);
    let [ok] = cholesky_solve_lanes(&mut nl, &mut rl);
    *n = nl.map(|row| row.map(|[v]| v));
    *rhs = rl.map(|[v]| v);
    ok
}

/// [`cholesky_solve`] of `L` independent systems at once, one per lane (`n[i][j][lane]`, `rhs[i][lane]`): each
/// lane's arithmetic is the single system's, in the same order, so its result is bit-identical to solving it alone;
/// the lanes run side by side (vector instructions, and the division chains of different systems overlap). A lane
/// whose system is singular gets `false` and a meaningless solution, without effect on the other lanes. Inlined, so
/// it is compiled for each instruction set where a dispatched loop calls it.
#[inline(always)]
pub(crate) fn cholesky_solve_lanes<const L: usize>(
    n: &mut [[[f64; L]; 6]; 6],
    rhs: &mut [[f64; L]; 6],
) -> [bool; L] {
    // After the loop, n[j][j] holds 1/D_j and n[i][j] (i > j) holds L_ij.
    let mut ok = [true; L];
    let mut d = [[0.0f64; L]; 6];
    for j in 0..6 {
        let diag0 = n[j][j];
        let mut dj = diag0;
        for k in 0..j {
            for l in 0..L {
                dj[l] -= n[j][k][l] * n[j][k][l] * d[k][l];
            }
        }
        let mut inv = [0.0f64; L];
        for l in 0..L {
            ok[l] &= dj[l].partial_cmp(&(1e-9 * diag0[l].max(1e-300))) == Some(std::cmp::Ordering::Greater);
            inv[l] = 1.0 / dj[l];
        }
        d[j] = dj;
        for i in j + 1..6 {
            let mut s = n[i][j];
            for k in 0..j {
                for l in 0..L {
                    s[l] -= n[i][k][l] * n[j][k][l] * d[k][l];
                }
            }
            for l in 0..L {
                n[i][j][l] = s[l] * inv[l];
            }
        }
        n[j][j] = inv;
    }
    for i in 0..6 {
        let mut s = rhs[i];
        for k in 0..i {
            for l in 0..L {
                s[l] -= n[i][k][l] * rhs[k][l];
            }
        }
        rhs[i] = s;
    }
    for i in 0..6 {
        for l in 0..L {
            rhs[i][l] *= n[i][i][l];
        }
    }
    for i in (0..6).rev() {
        let mut s = rhs[i];
        for k in i + 1..6 {
            for l in 0..L {
                s[l] -= n[k][i][l] * rhs[k][l];
            }
        }
        rhs[i] = s;
    }
    ok
}
