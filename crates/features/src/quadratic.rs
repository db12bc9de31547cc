//! The quadratic (2D Savitzky–Golay) fit's fixed kernels, and the small solver of its partial-window fits.
//!
//! The fit is `z = c0 + c1·u + c2·v + c3·u² + c4·u·v + c5·v²` in window coordinates `(u, v)` centred on the pixel.
//! For a window whose pixels are all valid the coefficients are `c = A⁺ z` with the pseudo-inverse `A⁺` of the fixed
//! design matrix `A`, in closed form ([`SgKernels::new`]); the row engine ([`crate::fit`]) applies these kernels as
//! separable filters. A window with missing pixels (no data, or the image border) is fitted from its valid pixels
//! alone by solving its own 6×6 normal equations ([`cholesky_solve`], square-root-free `LDLᵀ`); if they are singular (fewer than 6 valid
//! pixels in general position) the pixel gets NaN. No-data pixels never enter a fit.

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

/// The mean of `t²` over the offsets `t = −r..=r` of a window's row: `r(r + 1)/3`, the constant that centres `u²`
/// and `v²` (one rounding).
pub(crate) fn mean_t2(r: usize) -> f64 {
    (r * (r + 1)) as f64 / 3.0
}

impl SgKernels {
    /// Computes the kernels of a `window_px × window_px` window (odd, ≥ 3) in closed form.
    ///
    /// On a square window centred on the pixel the basis is orthogonal once `u²` and `v²` are centred: with
    /// `m = mean(t²)` over `t = −r..=r`, `p(u) = u² − m` and `q(v) = v² − m`, the columns `1, u, v, p(u), uv, q(v)`
    /// are pairwise orthogonal (every cross sum factors into a sum of an odd power, or of `p`, over one axis). Each
    /// coefficient is then its column's projection: `c1 = Σu·z / Σu²`, `c2 = Σv·z / Σv²`, `c4 = Σuv·z / Σu²v²`,
    /// `c3 = Σp(u)·z / Σp(u)²`, `c5 = Σq(v)·z / Σq(v)²`, and `c0 = mean(z) − m·(c3 + c5)` (the constant of `p` and
    /// `q` given back). `Σt²` is exact; `m` ([`mean_t2`]) and `Σ(t² − m)²` are rounded. The f32 gains the row engine
    /// reads ([`crate::fit`]) are bit for bit those of the QR pseudo-inverse (faer) this replaced, for every window of
    /// 3–21 pixels; faer's two f64 plane gains differed from these in the last few bits (and between the axes).
    pub(crate) fn new(window_px: u32) -> Self {
        assert!(
            window_px >= 3 && !window_px.is_multiple_of(2),
            "quadratic window must be odd and ≥ 3, got {window_px}"
        );
        let w = window_px as usize;
        let r = (w / 2) as i64;
        let n = (w * w) as f64;
        let ts = || -r..=r;
        // Per axis: Σt², the mean of t², and Σ(t² − m)²; over the window each sum is w times that of one axis.
        let st2 = ts().map(|t| (t * t) as f64).sum::<f64>();
        let m = mean_t2(w / 2);
        let sp2 = ts().map(|t| ((t * t) as f64 - m).powi(2)).sum::<f64>();
        let (s_u2, s_p2, s_u2v2) = (w as f64 * st2, w as f64 * sp2, st2 * st2);
        let pinv = (0..w * w)
            .map(|i| {
                let (u, v) = ((i % w) as f64 - r as f64, (i / w) as f64 - r as f64);
                let (k3, k5) = ((u * u - m) / s_p2, (v * v - m) / s_p2);
                [1.0 / n - m * (k3 + k5), u / s_u2, v / s_u2, k3, u * v / s_u2v2, k5]
            })
            .collect();
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
