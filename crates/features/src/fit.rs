//! The per-row fitting engine: local planes and quadratic derivatives, one output row at a time.
//!
//! **Fast path** (window entirely inside the image and every pixel of it valid). For a full symmetric window the
//! least-squares solutions are fixed linear filters: the plane slope is `a = Σu·z / Σu²`, `b = Σv·z / Σv²` and its
//! mean `Σz / n` (then `c = mean − a·x₀ − b·y₀` with `(x₀, y₀)` the pixel's offset from the image centre); the
//! quadratic's `c1 = Σu·z / Σu²`, `c2 = Σv·z / Σv²`, `c4 = Σuv·z / Σu²v²`, `c3 = Σp(u)·z / Σp(u)²` and
//! `c5 = Σp(v)·z / Σp(v)²` with the centred `p(t) = t² − mean(t²)` (the gains come from the kernels' closed form,
//! [`SgKernels`]). These moments are separable: a row pass per input row (`Σu·z`, `Σp(u)·z`, `Σ(z − z_centre)`)
//! kept in a ring of `w` rows, then a column pass per output row, plus a column-first pass for the `v` kernels
//! (`Σv·z`, `Σp(v)·z`, followed by a row box sum). Every kernel is written as a sum of **differences of nearby
//! depths** (each tap relative to its row's or column's centre pixel), so the f32 arithmetic only rounds quantities
//! of the size of the local depth variation, never the absolute depth (for integer depths the moments are exact);
//! all loops run over structure-of-arrays rows and vectorise, and for windows of 3, 5 and 7 pixels they are fused
//! into three passes per row with the window loop unrolled (same arithmetic in the same order, so bit-identical).
//! The cost per pixel is O(w) with a small constant (separable filters). A window containing no-data (NaN or ±∞)
//! makes some moment non-finite, which sends the pixel to the general path: no-data never enters a fast fit.
//! In the plane-only mode ([`Fit::Plane`], for `fit_planes` and a plane window that differs from the
//! derivative window) the quadratic's moments and solves are skipped.
//!
//! **General path** (windows clipped by the border or holding no-data): the plane and the quadratic are fitted to the
//! window's valid pixels alone (window coordinates, depths relative to the centre pixel, f64). If the window clipped
//! to the image is a rectangle without no-data (the image border), the least-squares kernels of that rectangle are
//! computed once per process (for `w ≤ 7`) and applied (in the top and bottom border rows, where all pixels away
//! from the sides share one rectangle, across the whole row at once). Otherwise the pixel's own normal equations are
//! solved (the quadratic by `LDLᵀ` Cholesky; windows inside the image that hold no-data four at a time, their
//! solves side by side, bit-identical to one at a time); the normal matrix is the full window's minus the missing
//! pixels' terms (of a window clipped by the border, the valid pixels' terms), exact because its entries are
//! integers. A no-data pixel gets NaN without a fit.

use std::sync::OnceLock;

use crate::plane;
use crate::quadratic::{SgKernels, basis, cholesky_solve, cholesky_solve_lanes, mean_t2};

/// One row of the quadratic fit's derivatives, one array per derivative: `[Ix, Iy, Ixx, Ixy, Iyy]` (structure of
/// arrays, so that the fast path's stores and the curvatures' loads vectorise without shuffles).
pub(crate) type DerivRow = [Vec<f32>; 5];

/// A [`DerivRow`] of `wu` zeros.
pub(crate) fn deriv_row(wu: usize) -> DerivRow {
    std::array::from_fn(|_| vec![0.0; wu])
}

/// What a [`RowFitter`] fits.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Fit {
    /// The plane and the quadratic's derivatives.
    Quadratic,
    /// The plane alone: the fast path skips the quadratic's moments and the general path its `LDLᵀ` solve. The
    /// planes are bit-identical to [`Fit::Quadratic`]'s (same arithmetic); the only difference is which windows go
    /// to the general path when a quadratic moment overflows f32 with finite depths (|z| ≳ 1e36).
    Plane,
}

/// Streams the fits of one window size over an image, output row by output row (rows in increasing order).
pub(crate) struct RowFitter<'a> {
    /// The range image, row-major.
    src: &'a [f32],
    /// Image width and height.
    wu: usize,
    hu: usize,
    /// Half window.
    r: usize,
    /// The image centre.
    cx: f64,
    cy: f64,
    /// `x − cx` for every column.
    xoff: Vec<f64>,
    /// Gains of the fast path: `[c1, c2, c3, c4, c5, 1/n]` per moment.
    gains: [f32; 6],
    /// The plane's gains in f64 (`a`, `b`, mean), for `c = mean − a·x₀ − b·y₀`: the moments are exact for integer
    /// depths, and `c` amplifies the slopes' rounding by the distance to the image centre.
    plane_gains: [f64; 3],
    /// `p(k) = k² − mean(t²)` for `k = 0..=r`.
    p: Vec<f32>,
    /// The basis `[1, u, v, u², uv, v²]` of each window tap (row-major taps).
    bas: Vec<[f64; 6]>,
    /// The lower triangle (row-major) of each tap's outer product `b·bᵀ`; integers.
    outer: Vec<[f64; 21]>,
    /// The lower triangle of the full window's normal matrix (sum of `outer`; integers, exact).
    outer_full: [f64; 21],
    /// Row-pass ring (`w` rows of `wu − 2r` values): `Σu·z`, `Σp(u)·z`, `Σ(z − z_centre)`.
    ring_h1: Vec<f32>,
    ring_hp: Vec<f32>,
    ring_r0: Vec<f32>,
    /// Next input row to run the row pass on.
    next_row: usize,
    /// Column-first pass of the current output row (length `wu`): `Σv·z`, `Σp(v)·z`, `Σ(z − z_centre)`.
    v1: Vec<f32>,
    vp: Vec<f32>,
    c0: Vec<f32>,
    /// Moments of the current output row (length `wu − 2r`): `[Σz', Σu·z, Σv·z, Σp(u)·z, Σuv·z, Σp(v)·z]`.
    mom: [Vec<f32>; 6],
    /// Check value of the current output row (sum of the moments; non-finite where the window held no data).
    chk: Vec<f32>,
    /// Which code computes the full windows.
    path: Path,
    /// Whether the derivatives are fitted too.
    fit: Fit,
    /// Scratch of [`Self::shape_row`]: the nine sums per pixel (plane `a, b, c`, quadratic `c0..c5`), and per column
    /// whether the rectangle's rows hold no-data there.
    row_acc: Vec<f64>,
    row_bad: Vec<bool>,
    /// Scratch of [`Self::row`]: the columns of the current row whose full window holds no-data (centre valid).
    holed: Vec<usize>,
}

/// The nine sums of [`plane::solve`] (`[n, Σu, Σv, Σu², Σuv, Σv², Σz, Σuz, Σvz]`) from the general fit's packed
/// normal matrix (lower triangle, row-major) and right-hand sides.
fn plane_sums(packed: &[f64; 21], rhs: &[f64; 6]) -> [f64; 9] {
    [packed[0], packed[1], packed[3], packed[2], packed[4], packed[5], rhs[0], rhs[1], rhs[2]]
}

/// Systems solved side by side by [`RowFitter::full_window_fits`].
const LANES: usize = 4;

/// The largest window (taps) whose sums [`RowFitter::lane_sums`] takes side by side (its no-data mask is a `u64`).
const MAX_LANE_TAPS: usize = 64;

/// The sums of [`RowFitter::lane_sums`]: per lane the count of valid taps, the right-hand sides `Σ b·(z − zc)`
/// and the bit mask of the no-data taps.
struct LaneSums {
    count: [u32; LANES],
    rhs: [[f64; LANES]; 6],
    missing: [u64; LANES],
}

impl LaneSums {
    /// Lane `l`'s `(count, rhs, packed normal matrix)`, as [`RowFitter::normal_sums`] gives them for a full window:
    /// the full window's normal matrix minus the no-data taps' terms, added in tap order.
    #[inline(always)]
    fn lane(&self, l: usize, outer: &[[f64; 21]], full: &[f64; 21]) -> (usize, [f64; 6], [f64; 21]) {
        let mut acc = [0.0f64; 21];
        let mut m = self.missing[l];
        while m != 0 {
            let o = &outer[m.trailing_zeros() as usize];
            for i in 0..21 {
                acc[i] += o[i];
            }
            m &= m - 1;
        }
        let packed = std::array::from_fn(|i| full[i] - acc[i]);
        (self.count[l] as usize, self.rhs.map(|r| r[l]), packed)
    }
}

/// Which code fits the full windows.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Path {
    /// Fused loops specialised for windows of 3, 5 and 7 pixels, the multi-pass loops otherwise.
    Fast,
    /// The multi-pass loops for every window size (bit-identical to `Fast`; the tests compare them).
    #[cfg_attr(not(test), allow(dead_code))]
    Unspecialised,
    /// The general (partial-window) path for every pixel (the tests compare it with the fast paths).
    #[cfg_attr(not(test), allow(dead_code))]
    General,
}

/// The result of one pixel's fit.
struct PixelFit {
    /// `[a, b, c]` of the plane (c at the image centre), or NaN.
    plane: [f32; 3],
    /// `[Ix, Iy]`, or NaN.
    grad: [f32; 2],
    /// `[Ixx, Ixy, Iyy]`, or NaN.
    hess: [f32; 3],
}

const NAN_FIT: PixelFit = PixelFit { plane: [f32::NAN; 3], grad: [f32::NAN; 2], hess: [f32::NAN; 3] };

impl PixelFit {
    /// Stores the fit at column `x` of the rows (the derivatives only for [`Fit::Quadratic`]).
    fn store(self, fit: Fit, x: usize, plane: &mut [[f32; 3]], deriv: &mut DerivRow) {
        plane[x] = self.plane;
        if fit == Fit::Quadratic {
            let [ix, iy, ixx, ixy, iyy] = deriv;
            ([ix[x], iy[x]], [ixx[x], ixy[x], iyy[x]]) = (self.grad, self.hess);
        }
    }
}

impl<'a> RowFitter<'a> {
    /// Prepares the fits of `window_px × window_px` windows over `src` (`wu × hu`, row-major).
    pub(crate) fn new(src: &'a [f32], wu: usize, hu: usize, window_px: u32, path: Path, fit: Fit) -> Self {
        assert_eq!(src.len(), wu * hu, "image size");
        let k = SgKernels::new(window_px);
        let r = window_px as usize / 2;
        let win = 2 * r + 1;
        let idx = |u: usize, v: usize| (v + r) * win + (u + r);
        // Gains of the full-window kernels, read off the pseudo-inverse:
        // kernel of c1 at (1, 0) is 1/Σu²; of c2 at (0, 1) is 1/Σv²; of c4 at (1, 1) is 1/Σu²v²;
        // kernel of c3 is g3·p(u), and p(1) − p(0) = 1, so g3 = K3(1, 0) − K3(0, 0); likewise c5.
        let pv = &k.pinv;
        let gains = [
            pv[idx(1, 0)][1] as f32,
            pv[idx(0, 1)][2] as f32,
            (pv[idx(1, 0)][3] - pv[idx(0, 0)][3]) as f32,
            pv[idx(1, 1)][4] as f32,
            (pv[idx(0, 1)][5] - pv[idx(0, 0)][5]) as f32,
            1.0 / (win * win) as f32,
        ];
        let plane_gains = [pv[idx(1, 0)][1], pv[idx(0, 1)][2], 1.0 / (win * win) as f64];
        let mt2 = mean_t2(r);
        let p = (0..=r).map(|t| ((t * t) as f64 - mt2) as f32).collect();
        let bas: Vec<[f64; 6]> =
            (0..win * win).map(|t| basis((t % win) as f64 - r as f64, (t / win) as f64 - r as f64)).collect();
        let outer: Vec<[f64; 21]> = bas
            .iter()
            .map(|b| {
                let mut o = [0.0; 21];
                let mut t = 0;
                for i in 0..6 {
                    for j in 0..=i {
                        o[t] = b[i] * b[j];
                        t += 1;
                    }
                }
                o
            })
            .collect();
        let mut outer_full = [0.0; 21];
        for o in &outer {
            for i in 0..21 {
                outer_full[i] += o[i];
            }
        }
        let m = wu.saturating_sub(2 * r);
        Self {
            src,
            wu,
            hu,
            r,
            cx: (wu as f64 - 1.0) / 2.0,
            cy: (hu as f64 - 1.0) / 2.0,
            xoff: (0..wu).map(|x| x as f64 - (wu as f64 - 1.0) / 2.0).collect(),
            gains,
            plane_gains,
            p,
            bas,
            outer,
            outer_full,
            ring_h1: vec![0.0; win * m],
            ring_hp: vec![0.0; win * m],
            ring_r0: vec![0.0; win * m],
            next_row: 0,
            v1: vec![0.0; wu],
            vp: vec![0.0; wu],
            c0: vec![0.0; wu],
            mom: std::array::from_fn(|_| vec![0.0; m]),
            chk: vec![0.0; m],
            path,
            fit,
            row_acc: Vec::new(),
            row_bad: Vec::new(),
            holed: Vec::new(),
        }
    }

    /// Runs the row pass of input row `yy` into its ring slot.
    fn row_pass(&mut self, yy: usize) {
        let (wu, r) = (self.wu, self.r);
        let m = wu - 2 * r;
        let slot = (yy % (2 * r + 1)) * m;
        let z = &self.src[yy * wu..(yy + 1) * wu];
        let h1 = &mut self.ring_h1[slot..slot + m];
        let hp = &mut self.ring_hp[slot..slot + m];
        let r0 = &mut self.ring_r0[slot..slot + m];
        h1.fill(0.0);
        hp.fill(0.0);
        r0.fill(0.0);
        let zc = &z[r..r + m];
        for k in 1..=r {
            let (zp, zm) = (&z[r + k..r + k + m], &z[r - k..r - k + m]);
            let (kf, pk) = (k as f32, self.p[k]);
            for i in 0..m {
                let (a, b, c) = (zp[i], zm[i], zc[i]);
                h1[i] += kf * (a - b);
                let e = (a - c) + (b - c);
                hp[i] += pk * e;
                r0[i] += e;
            }
        }
    }

    /// Computes the fast-path moments of output row `y` (`r ≤ y < hu − r`, `wu > 2r`) into `self.mom`.
    fn moments(&mut self, y: usize) {
        let (wu, r) = (self.wu, self.r);
        let win = 2 * r + 1;
        let m = wu - 2 * r;
        let slot = |yy: usize| (yy % win) * m;
        let [m00, m10, m01, m20, m11, m02] = &mut self.mom;
        // Column sums of the row passes.
        let sc = slot(y);
        m10.copy_from_slice(&self.ring_h1[sc..sc + m]);
        m20.copy_from_slice(&self.ring_hp[sc..sc + m]);
        m00.copy_from_slice(&self.ring_r0[sc..sc + m]);
        m11.fill(0.0);
        for k in 1..=r {
            let (sp, sm) = (slot(y + k), slot(y - k));
            let kf = k as f32;
            let (h1p, h1m) = (&self.ring_h1[sp..sp + m], &self.ring_h1[sm..sm + m]);
            let (hpp, hpm) = (&self.ring_hp[sp..sp + m], &self.ring_hp[sm..sm + m]);
            let (r0p, r0m) = (&self.ring_r0[sp..sp + m], &self.ring_r0[sm..sm + m]);
            for i in 0..m {
                m10[i] += h1p[i] + h1m[i];
                m11[i] += kf * (h1p[i] - h1m[i]);
                m20[i] += hpp[i] + hpm[i];
                m00[i] += r0p[i] + r0m[i];
            }
        }
        // Column-first pass for the v kernels, over the whole row.
        let src = self.src;
        let zc = &src[y * wu..(y + 1) * wu];
        let (v1, vp, c0) = (&mut self.v1, &mut self.vp, &mut self.c0);
        v1.fill(0.0);
        vp.fill(0.0);
        c0.fill(0.0);
        for k in 1..=r {
            let zp = &src[(y + k) * wu..(y + k + 1) * wu];
            let zm = &src[(y - k) * wu..(y - k + 1) * wu];
            let (kf, pk) = (k as f32, self.p[k]);
            for i in 0..wu {
                let (a, b, c) = (zp[i], zm[i], zc[i]);
                v1[i] += kf * (a - b);
                let e = (a - c) + (b - c);
                vp[i] += pk * e;
                c0[i] += e;
            }
        }
        // Row box sums of the column-first pass; the centre column's Σ(z − z_centre) counts once per column.
        m01.copy_from_slice(&v1[..m]);
        m02.copy_from_slice(&vp[..m]);
        for j in 1..win {
            let (a, b) = (&v1[j..j + m], &vp[j..j + m]);
            for i in 0..m {
                m01[i] += a[i];
                m02[i] += b[i];
            }
        }
        let wf = win as f32;
        for (o, &c) in m00.iter_mut().zip(&c0[r..r + m]) {
            *o += wf * c;
        }
    }

    /// Fits output row `y` (rows must come in increasing order) into `plane` and `deriv` (length `wu`); `deriv` is
    /// left as it is for [`Fit::Plane`].
    pub(crate) fn row(&mut self, y: usize, plane: &mut [[f32; 3]], deriv: &mut DerivRow) {
        let (wu, hu, r) = (self.wu, self.hu, self.r);
        assert!(plane.len() == wu && deriv.iter().all(|d| d.len() == wu), "row length");
        let fast_row = self.path != Path::General && wu > 2 * r && y >= r && y + r < hu;
        let (mut fast_lo, mut fast_hi) = (0, 0);
        if fast_row {
            (fast_lo, fast_hi) = (r, wu - r);
            let p = &mut plane[r..wu - r];
            let [ix, iy, ixx, ixy, iyy] = deriv.each_mut().map(|d| &mut d[r..wu - r]);
            match (self.path, self.fit, r) {
                (Path::Fast, Fit::Quadratic, 1) => self.fused::<1, 3, true>(y, p, ix, iy, ixx, ixy, iyy),
                (Path::Fast, Fit::Quadratic, 2) => self.fused::<2, 5, true>(y, p, ix, iy, ixx, ixy, iyy),
                (Path::Fast, Fit::Quadratic, 3) => self.fused::<3, 7, true>(y, p, ix, iy, ixx, ixy, iyy),
                (Path::Fast, Fit::Plane, 1) => self.fused::<1, 3, false>(y, p, ix, iy, ixx, ixy, iyy),
                (Path::Fast, Fit::Plane, 2) => self.fused::<2, 5, false>(y, p, ix, iy, ixx, ixy, iyy),
                (Path::Fast, Fit::Plane, 3) => self.fused::<3, 7, false>(y, p, ix, iy, ixx, ixy, iyy),
                _ => {
                    while self.next_row <= y + r {
                        self.row_pass(self.next_row);
                        self.next_row += 1;
                    }
                    self.moments(y);
                    self.fast_row(y, p, [ix, iy, ixx, ixy, iyy]);
                }
            }
        }
        // The top and bottom border rows: every pixel away from the side borders has the same clipped rectangle,
        // so its kernels are applied to the whole row at once.
        let shape_row = !fast_row && self.path != Path::General && wu > 2 * r && r as i64 <= MAX_SHAPE_R;
        if shape_row {
            (fast_lo, fast_hi) = (r, wu - r);
            self.shape_row(y, plane, deriv);
        }
        for x in (0..fast_lo).chain(fast_hi..wu) {
            let f = self.general_fit(x, y);
            f.store(self.fit, x, plane, deriv);
        }
        // Windows with no data (or overflowing sums) left a non-finite check value: refit them.
        let non_finite = |v: &f32| u32::from(v.to_bits() & 0x7f80_0000 == 0x7f80_0000);
        if fast_row && fast_hi > fast_lo {
            let zrow = &self.src[y * wu + fast_lo..y * wu + fast_hi];
            let chk = &self.chk[..fast_hi - fast_lo];
            let fit = self.fit;
            let mut holed = std::mem::take(&mut self.holed);
            holed.clear();
            // In blocks of 16 pixels: a block without a non-finite check value (most) is passed over at once.
            for (x0, (cs, zs)) in (fast_lo..).step_by(16).zip(chk.chunks(16).zip(zrow.chunks(16))) {
                if cs.iter().fold(0, |bad, v| bad | non_finite(v)) == 0 {
                    continue;
                }
                for (x, (c, z)) in (x0..).zip(cs.iter().zip(zs)) {
                    if !c.is_finite() {
                        if z.is_finite() {
                            holed.push(x);
                        } else {
                            // No-data pixels (most of these in frames with large holes) need no fit.
                            NAN_FIT.store(fit, x, plane, deriv);
                        }
                    }
                }
            }
            for xs in holed.chunks(LANES) {
                self.full_window_fits(xs, y, plane, deriv);
            }
            self.holed = holed;
        }
    }

    /// Writes the fast-path fits of output row `y` from the moments (slices of length `wu − 2r`, x = r ..); the
    /// check value `chk` (sum of the moments) is non-finite where the window held no data.
    fn fast_row(&mut self, y: usize, plane: &mut [[f32; 3]], deriv: [&mut [f32]; 5]) {
        let (wu, r) = (self.wu, self.r);
        let m = wu - 2 * r;
        let (g, gd) = (self.gains, self.plane_gains);
        let y0 = y as f64 - self.cy;
        let xoff = &self.xoff[r..r + m];
        let zc = &self.src[y * wu + r..y * wu + r + m];
        let [m00, m10, m01, m20, m11, m02] = &self.mom;
        let (m00, m10, m01, m20, m11, m02) =
            (&m00[..m], &m10[..m], &m01[..m], &m20[..m], &m11[..m], &m02[..m]);
        let chk = &mut self.chk[..m];
        let plane = &mut plane[..m];
        let quad = self.fit == Fit::Quadratic;
        for i in 0..m {
            let (c1, c2) = (g[0] * m10[i], g[1] * m01[i]);
            let c = f64::from(zc[i]) + gd[2] * f64::from(m00[i])
                - gd[0] * f64::from(m10[i]) * xoff[i]
                - gd[1] * f64::from(m01[i]) * y0;
            plane[i] = [c1, c2, c as f32];
            chk[i] = if quad {
                m00[i] + m10[i] + m01[i] + m20[i] + m11[i] + m02[i]
            } else {
                m00[i] + m10[i] + m01[i]
            };
        }
        if quad {
            let [ix, iy, ixx, ixy, iyy] = deriv.map(|d| &mut d[..m]);
            for i in 0..m {
                (ix[i], iy[i]) = (g[0] * m10[i], g[1] * m01[i]);
                let (c3, c4, c5) = (g[2] * m20[i], g[3] * m11[i], g[4] * m02[i]);
                (ixx[i], ixy[i], iyy[i]) = (2.0 * c3, c4, 2.0 * c5);
            }
        }
    }

    /// The fast path of output row `y` for a window of `2R + 1 = W` pixels: the same arithmetic, in the same order,
    /// as `row_pass` + `moments` + `fast_row`, but fused into three loops whose inner loops over the window are
    /// unrolled (bit-identical results, far fewer memory passes). `Q`: fit the quadratic too ([`Fit::Quadratic`]);
    /// without it the quadratic's moments are not computed.
    ///
    /// The five derivative rows are separate arguments, not an array: only then does the compiler know they alias
    /// nothing else, and the last loop vectorises.
    #[inline(never)] // inlined into `row`, its loops stop vectorising
    #[allow(clippy::too_many_arguments)]
    fn fused<const R: usize, const W: usize, const Q: bool>(
        &mut self,
        y: usize,
        plane: &mut [[f32; 3]],
        ix: &mut [f32],
        iy: &mut [f32],
        ixx: &mut [f32],
        ixy: &mut [f32],
        iyy: &mut [f32],
    ) {
        isa::dispatch(
            #[inline(always)]
            || self.fused_kernel::<R, W, Q>(y, plane, ix, iy, ixx, ixy, iyy),
        );
    }

    /// [`Self::fused`]'s body, compiled for each instruction set ([`isa::dispatch`]).
    #[inline(always)]
    #[allow(clippy::too_many_arguments)]
    fn fused_kernel<const R: usize, const W: usize, const Q: bool>(
        &mut self,
        y: usize,
        plane: &mut [[f32; 3]],
        ix: &mut [f32],
        iy: &mut [f32],
        ixx: &mut [f32],
        ixy: &mut [f32],
        iyy: &mut [f32],
    ) {
        let wu = self.wu;
        let m = wu - 2 * R;
        let src = self.src;
        let mut pk = [0.0f32; W];
        pk[..=R].copy_from_slice(&self.p);
        // Row passes of the rows entering the window.
        while self.next_row <= y + R {
            let yy = self.next_row;
            let slot = (yy % W) * m;
            let z = &src[yy * wu..(yy + 1) * wu];
            let h1 = &mut self.ring_h1[slot..slot + m];
            let hp = &mut self.ring_hp[slot..slot + m];
            let r0 = &mut self.ring_r0[slot..slot + m];
            let zs: [&[f32]; W] = std::array::from_fn(|j| &z[j..j + m]);
            for i in 0..m {
                let (a1, ap, a0) = symmetric_taps::<R, W>(&zs, &pk, i);
                (h1[i], r0[i]) = (a1, a0);
                if Q {
                    hp[i] = ap;
                }
            }
            self.next_row += 1;
        }
        // Column-first pass over the whole row.
        let rows: [&[f32]; W] = std::array::from_fn(|j| &src[(y + j - R) * wu..(y + j - R + 1) * wu]);
        let (v1, vp, c0) = (&mut self.v1[..wu], &mut self.vp[..wu], &mut self.c0[..wu]);
        for i in 0..wu {
            let (a1, ap, a0) = symmetric_taps::<R, W>(&rows, &pk, i);
            (v1[i], c0[i]) = (a1, a0);
            if Q {
                vp[i] = ap;
            }
        }
        // Column sums of the row passes, row box sums of the column-first pass, and the fits.
        let slot = |v: usize| ((y + v - R) % W) * m;
        let h1s: [&[f32]; W] = std::array::from_fn(|v| &self.ring_h1[slot(v)..slot(v) + m]);
        let hps: [&[f32]; W] = std::array::from_fn(|v| &self.ring_hp[slot(v)..slot(v) + m]);
        let r0s: [&[f32]; W] = std::array::from_fn(|v| &self.ring_r0[slot(v)..slot(v) + m]);
        let (g, gd) = (self.gains, self.plane_gains);
        let y0 = y as f64 - self.cy;
        let xoff = &self.xoff[R..R + m];
        let zc = &src[y * wu + R..y * wu + R + m];
        let (v1, vp, c0) = (&self.v1[..wu], &self.vp[..wu], &self.c0[..wu]);
        let chk = &mut self.chk[..m];
        let plane = &mut plane[..m];
        let (ix, iy, ixx, ixy, iyy) =
            (&mut ix[..m], &mut iy[..m], &mut ixx[..m], &mut ixy[..m], &mut iyy[..m]);
        let wf = W as f32;
        for i in 0..m {
            let (mut m10, mut m00) = (h1s[R][i], r0s[R][i]);
            let (mut m20, mut m11) = if Q { (hps[R][i], 0.0f32) } else { (0.0, 0.0) };
            for k in 1..=R {
                let (h1p, h1m) = (h1s[R + k][i], h1s[R - k][i]);
                m10 += h1p + h1m;
                if Q {
                    m11 += k as f32 * (h1p - h1m);
                    m20 += hps[R + k][i] + hps[R - k][i];
                }
                m00 += r0s[R + k][i] + r0s[R - k][i];
            }
            let vv1 = &v1[i..i + W];
            let mut m01 = vv1[0];
            for j in 1..W {
                m01 += vv1[j];
            }
            m00 += wf * c0[i + R];
            let (c1, c2) = (g[0] * m10, g[1] * m01);
            let c = f64::from(zc[i]) + gd[2] * f64::from(m00)
                - gd[0] * f64::from(m10) * xoff[i]
                - gd[1] * f64::from(m01) * y0;
            plane[i] = [c1, c2, c as f32];
            if Q {
                let vvp = &vp[i..i + W];
                let mut m02 = vvp[0];
                for j in 1..W {
                    m02 += vvp[j];
                }
                let (c3, c4, c5) = (g[2] * m20, g[3] * m11, g[4] * m02);
                (ix[i], iy[i]) = (c1, c2);
                (ixx[i], ixy[i], iyy[i]) = (2.0 * c3, c4, 2.0 * c5);
                chk[i] = m00 + m10 + m01 + m20 + m11 + m02;
            } else {
                chk[i] = m00 + m10 + m01;
            }
        }
    }

    /// Fits the plane and (for [`Fit::Quadratic`]) the quadratic to the valid pixels of the window around `(x, y)`.
    fn general_fit(&mut self, x: usize, y: usize) -> PixelFit {
        let (wu, hu, r) = (self.wu, self.hu, self.r as i64);
        let zc = self.src[y * wu + x];
        if !zc.is_finite() {
            return NAN_FIT;
        }
        let zc = f64::from(zc);
        let (xi, yi) = (x as i64, y as i64);
        // The window clipped to the image.
        let (ulo, uhi) = ((-xi).max(-r), (wu as i64 - 1 - xi).min(r));
        let (vlo, vhi) = ((-yi).max(-r), (hu as i64 - 1 - yi).min(r));
        if r <= MAX_SHAPE_R
            && let Some(f) = self.shape_fit(x, y, zc, [ulo, uhi, vlo, vhi])
        {
            return f;
        }
        // The plane needs only the first 3 right-hand sides and the first 6 packed entries (the 3×3 block).
        let (count, mut rhs, packed) = match self.fit {
            Fit::Quadratic => self.normal_sums::<6, 21>(x, y, zc, [ulo, uhi, vlo, vhi]),
            Fit::Plane => self.normal_sums::<3, 6>(x, y, zc, [ulo, uhi, vlo, vhi]),
        };
        let mut n = [[0.0f64; 6]; 6];
        let mut t = 0;
        for i in 0..6 {
            for j in 0..=i {
                n[i][j] = packed[t];
                t += 1;
            }
        }
        let plane = plane::solve(&plane_sums(&packed, &rhs));
        let quad =
            (self.fit == Fit::Quadratic && count >= 6 && cholesky_solve(&mut n, &mut rhs)).then_some(rhs);
        self.pixel_fit(x, y, zc, plane, quad)
    }

    /// [`Self::general_fit`] of up to [`LANES`] pixels of row `y` whose windows are inside the image (not clipped)
    /// and whose centres are valid, stored into `plane` and `deriv`: the planes' and the quadratics' solves run side
    /// by side ([`plane::solve_lanes`], [`cholesky_solve_lanes`]; bit-identical to one at a time). A window without
    /// no-data (a fast-path moment overflowed) gets its full-window kernels, as in `general_fit`.
    fn full_window_fits(&mut self, xs: &[usize], y: usize, plane: &mut [[f32; 3]], deriv: &mut DerivRow) {
        if self.fit != Fit::Quadratic {
            for &x in xs {
                let f = self.general_fit(x, y);
                f.store(self.fit, x, plane, deriv);
            }
            return;
        }
        isa::dispatch(
            #[inline(always)]
            || self.full_window_fits_kernel(xs, y, plane, deriv),
        );
    }

    /// [`Self::full_window_fits`] of the quadratic mode, compiled for each instruction set ([`isa::dispatch`]).
    #[inline(always)]
    fn full_window_fits_kernel(
        &mut self,
        xs: &[usize],
        y: usize,
        plane: &mut [[f32; 3]],
        deriv: &mut DerivRow,
    ) {
        let (wu, r) = (self.wu, self.r as i64);
        let full = [-r, r, -r, r];
        // Lanes without a system (past `xs`, or fitted otherwise) hold the identity.
        let mut n = [[[0.0f64; LANES]; 6]; 6];
        for (i, row) in n.iter_mut().enumerate() {
            row[i] = [1.0; LANES];
        }
        let mut rhs = [[0.0f64; LANES]; 6];
        // The plane's nine sums per lane (zeros in lanes without a system, which `solve_lanes` rejects).
        let mut sums = [[0.0f64; LANES]; 9];
        let mut lanes = [None; LANES];
        let n_taps = ((2 * r + 1) * (2 * r + 1)) as usize;
        let side_by_side = (n_taps <= MAX_LANE_TAPS && !xs.is_empty()).then(|| self.lane_sums(xs, y));
        for (l, &x) in xs.iter().enumerate() {
            let zc = f64::from(self.src[y * wu + x]);
            let (count, rl, packed) = match &side_by_side {
                Some(s) => s.lane(l, &self.outer, &self.outer_full),
                None => self.normal_sums::<6, 21>(x, y, zc, full),
            };
            if count == n_taps
                && r <= MAX_SHAPE_R
                && let Some(f) = self.shape_fit(x, y, zc, full)
            {
                f.store(self.fit, x, plane, deriv);
                continue;
            }
            let mut t = 0;
            for i in 0..6 {
                for j in 0..=i {
                    n[i][j][l] = packed[t];
                    t += 1;
                }
                rhs[i][l] = rl[i];
            }
            for (s, v) in sums.iter_mut().zip(plane_sums(&packed, &rl)) {
                s[l] = v;
            }
            lanes[l] = Some((x, zc, count));
        }
        let planes = plane::solve_lanes(&sums);
        let ok = cholesky_solve_lanes(&mut n, &mut rhs);
        for (l, lane) in lanes.into_iter().enumerate() {
            if let Some((x, zc, count)) = lane {
                let quad = (count >= 6 && ok[l]).then(|| std::array::from_fn(|i| rhs[i][l]));
                let f = self.pixel_fit(x, y, zc, planes[l], quad);
                f.store(self.fit, x, plane, deriv);
            }
        }
    }

    /// The right-hand sides and counts of [`Self::normal_sums`] for the full windows (inside the image) of up to
    /// [`LANES`] pixels `xs` of row `y` (lanes past `xs` repeat its first pixel), side by side and without
    /// branches, and per lane the bit mask of its window's no-data taps (`win² ≤` [`MAX_LANE_TAPS`]). Each lane adds
    /// the same products in the same tap order as `normal_sums`; a no-data tap adds `b·0 = ±0`, which leaves the
    /// sum as it is (a sum that starts at +0 is never −0, and `s + (±0) = s` for every other `s`).
    #[inline(always)]
    fn lane_sums(&self, xs: &[usize], y: usize) -> LaneSums {
        let (wu, r) = (self.wu, self.r);
        let win = 2 * r + 1;
        let at = |l: usize| xs[if l < xs.len() { l } else { 0 }];
        let zc: [f64; LANES] = std::array::from_fn(|l| f64::from(self.src[y * wu + at(l)]));
        // Each lane's window, from its top-left tap to its bottom-right tap.
        let span = (win - 1) * wu + win;
        let wins: [&[f32]; LANES] = std::array::from_fn(|l| &self.src[(y - r) * wu + at(l) - r..][..span]);
        let mut rhs = [[0.0f64; LANES]; 6];
        let mut count = [0u32; LANES];
        let mut missing = [0u64; LANES];
        for v in 0..win {
            for u in 0..win {
                let t = v * win + u;
                let b = &self.bas[t];
                let mut z = [0.0f64; LANES];
                for l in 0..LANES {
                    let z32 = wins[l][v * wu + u];
                    let fin = z32.is_finite();
                    z[l] = if fin { f64::from(z32) - zc[l] } else { 0.0 };
                    count[l] += u32::from(fin);
                    missing[l] |= u64::from(!fin) << t;
                }
                for i in 0..6 {
                    for l in 0..LANES {
                        rhs[i][l] += b[i] * z[l];
                    }
                }
            }
        }
        LaneSums { count, rhs, missing }
    }

    /// The sums of the general fit over the valid pixels of the clipped window `[ulo, uhi] × [vlo, vhi]` around
    /// `(x, y)`: their count, the first `NR` right-hand sides `Σ b·(z − zc)` and the first `NP` packed entries of the
    /// normal matrix (the rest stay 0).
    fn normal_sums<const NR: usize, const NP: usize>(
        &self,
        x: usize,
        y: usize,
        zc: f64,
        [ulo, uhi, vlo, vhi]: [i64; 4],
    ) -> (usize, [f64; 6], [f64; 21]) {
        let (wu, r) = (self.wu, self.r);
        let win = 2 * r + 1;
        // Window offsets as indices `0..win` of the window and columns/rows of the image.
        let (u0, u1) = ((ulo + r as i64) as usize, (uhi + r as i64) as usize + 1);
        let (v0, v1) = ((vlo + r as i64) as usize, (vhi + r as i64) as usize + 1);
        let (x0, y0) = (x + u0 - r, y + v0 - r);
        // The normal matrix is exact (integer entries): of a full window, the full window's minus the missing
        // pixels' terms; of a clipped one, the sum of the valid pixels' terms.
        let clipped = u1 - u0 < win || v1 - v0 < win;
        let mut rhs = [0.0f64; 6];
        let mut acc = [0.0f64; 21];
        let mut count = 0;
        for v in v0..v1 {
            let row = &self.src[(y0 + v - v0) * wu + x0..][..u1 - u0];
            let taps = v * win + u0..v * win + u1;
            for ((&z, b), o) in row.iter().zip(&self.bas[taps.clone()]).zip(&self.outer[taps]) {
                if z.is_finite() {
                    count += 1;
                    let z = f64::from(z) - zc;
                    for i in 0..NR {
                        rhs[i] += b[i] * z;
                    }
                    if clipped {
                        for i in 0..NP {
                            acc[i] += o[i];
                        }
                    }
                } else if !clipped {
                    for i in 0..NP {
                        acc[i] += o[i];
                    }
                }
            }
        }
        let mut packed = acc;
        if !clipped {
            let full = &self.outer_full;
            for i in 0..NP {
                packed[i] = full[i] - acc[i];
            }
        }
        (count, rhs, packed)
    }

    /// The outputs of a fit in window coordinates with depths relative to `zc`.
    fn pixel_fit(
        &self,
        x: usize,
        y: usize,
        zc: f64,
        plane: Option<[f64; 3]>,
        quad: Option<[f64; 6]>,
    ) -> PixelFit {
        let mut out = NAN_FIT;
        if let Some([a, b, c]) = plane {
            let (x0, y0) = (x as f64 - self.cx, y as f64 - self.cy);
            out.plane = [a as f32, b as f32, (zc + c - a * x0 - b * y0) as f32];
        }
        if let Some(q) = quad {
            out.grad = [q[1] as f32, q[2] as f32];
            out.hess = [(2.0 * q[3]) as f32, q[4] as f32, (2.0 * q[5]) as f32];
        }
        out
    }

    /// The fit of a pixel whose window, clipped to the image to the rectangle `[ulo, uhi] × [vlo, vhi]` of window
    /// offsets, holds no no-data: the least-squares kernels of that rectangle (computed once per rectangle) applied
    /// to the depths. `None` if the rectangle holds no-data.
    fn shape_fit(&mut self, x: usize, y: usize, zc: f64, [ulo, uhi, vlo, vhi]: [i64; 4]) -> Option<PixelFit> {
        let wu = self.wu;
        let cols = (x as i64 + ulo) as usize..=(x as i64 + uhi) as usize;
        for dv in vlo..=vhi {
            let row = &self.src[(y as i64 + dv) as usize * wu..];
            if row[cols.clone()].iter().any(|z| !z.is_finite()) {
                return None;
            }
        }
        let kernel = shape_kernel(self.r as i64, [ulo, uhi, vlo, vhi]);
        let quad = self.fit == Fit::Quadratic;
        // Each lane of `acc` sums its own weights times the depths in tap order (the plane's lanes 0..3, the
        // quadratic's 3..9); the plane-only mode needs the first 4 lanes (3 used).
        let mut acc = [0.0f64; 12];
        let width = (uhi - ulo + 1) as usize;
        for (dv, ks) in (vlo..=vhi).zip(kernel.taps.chunks_exact(width)) {
            let row = &self.src[(y as i64 + dv) as usize * wu..][cols.clone()];
            if quad {
                for (&z, k) in row.iter().zip(ks) {
                    let z = f64::from(z) - zc;
                    for i in 0..12 {
                        acc[i] += k[i] * z;
                    }
                }
            } else {
                for (&z, k) in row.iter().zip(ks) {
                    let z = f64::from(z) - zc;
                    for i in 0..4 {
                        acc[i] += k[i] * z;
                    }
                }
            }
        }
        let p = [acc[0], acc[1], acc[2]];
        let q = [acc[3], acc[4], acc[5], acc[6], acc[7], acc[8]];
        let (has_plane, has_quad) = (kernel.has_plane, quad && kernel.has_quad);
        Some(self.pixel_fit(x, y, zc, has_plane.then_some(p), has_quad.then_some(q)))
    }

    /// [`Self::shape_fit`] of the pixels `r..wu − r` of a top or bottom border row `y` (`wu > 2r`, `r ≤ 3`), whose
    /// clipped windows are all the same rectangle: each tap's kernel weights applied across the row (the same
    /// arithmetic in the same order per pixel, so bit-identical); pixels whose rectangle holds no-data go to
    /// [`Self::general_fit`].
    #[inline(never)]
    fn shape_row(&mut self, y: usize, plane: &mut [[f32; 3]], deriv: &mut DerivRow) {
        isa::dispatch(
            #[inline(always)]
            || self.shape_row_kernel(y, plane, deriv),
        );
    }

    /// [`Self::shape_row`]'s body, compiled for each instruction set ([`isa::dispatch`]).
    #[inline(always)]
    fn shape_row_kernel(&mut self, y: usize, plane: &mut [[f32; 3]], deriv: &mut DerivRow) {
        let (wu, hu, r) = (self.wu, self.hu, self.r);
        let (ri, yi) = (r as i64, y as i64);
        let (vlo, vhi) = ((-yi).max(-ri), (hu as i64 - 1 - yi).min(ri));
        let kernel = shape_kernel(ri, [-ri, ri, vlo, vhi]);
        let m = wu - 2 * r;
        let quad = self.fit == Fit::Quadratic;
        let mut acc = std::mem::take(&mut self.row_acc);
        let mut bad = std::mem::take(&mut self.row_bad);
        acc.clear();
        acc.resize(9 * m, 0.0);
        bad.clear();
        bad.resize(wu, false);
        let src = self.src;
        let rows = || (vlo..=vhi).map(|dv| &src[(yi + dv) as usize * wu..(yi + dv + 1) as usize * wu]);
        for row in rows() {
            for (b, z) in bad.iter_mut().zip(row) {
                *b |= !z.is_finite();
            }
        }
        let zc = &src[y * wu + r..y * wu + r + m];
        let (pa, qa) = acc.split_at_mut(3 * m);
        let [p0, p1, p2] = pa.get_disjoint_mut([0..m, m..2 * m, 2 * m..3 * m]).expect("disjoint");
        let mut t = 0;
        for row in rows() {
            for du in 0..2 * r + 1 {
                let zs = &row[du..du + m];
                let kp = &kernel.taps[t];
                for i in 0..m {
                    let z = f64::from(zs[i]) - f64::from(zc[i]);
                    p0[i] += kp[0] * z;
                    p1[i] += kp[1] * z;
                    p2[i] += kp[2] * z;
                }
                if quad {
                    let kq = &kp[3..9];
                    for (j, q) in qa.chunks_exact_mut(m).enumerate() {
                        let q = &mut q[..m];
                        for i in 0..m {
                            let z = f64::from(zs[i]) - f64::from(zc[i]);
                            q[i] += kq[j] * z;
                        }
                    }
                }
                t += 1;
            }
        }
        let (has_plane, has_quad) = (kernel.has_plane, quad && kernel.has_quad);
        let mut refit = false;
        for i in 0..m {
            let x = r + i;
            if bad[x - r..=x + r].iter().any(|&b| b) {
                refit = true;
                continue;
            }
            let p = [acc[i], acc[m + i], acc[2 * m + i]];
            let q: [f64; 6] = std::array::from_fn(|j| acc[(3 + j) * m + i]);
            let f = self.pixel_fit(x, y, f64::from(zc[i]), has_plane.then_some(p), has_quad.then_some(q));
            f.store(self.fit, x, plane, deriv);
        }
        if refit {
            for x in r..wu - r {
                if bad[x - r..=x + r].iter().any(|&b| b) {
                    let f = self.general_fit(x, y);
                    f.store(self.fit, x, plane, deriv);
                }
            }
        }
        (self.row_acc, self.row_bad) = (acc, bad);
    }
}

/// Largest half window whose clipped-rectangle kernels are cached ((r + 1)⁴ rectangles).
const MAX_SHAPE_R: i64 = 3;

/// The kernels of the rectangle `[ulo, uhi] × [vlo, vhi]` of window offsets of half window `r ≤ MAX_SHAPE_R`
/// (`−r ≤ ulo ≤ 0 ≤ uhi ≤ r`, likewise v). They depend on the rectangle alone, so each is computed once per process,
/// on first use, and shared read-only.
fn shape_kernel(r: i64, [ulo, uhi, vlo, vhi]: [i64; 4]) -> &'static ShapeKernel {
    const N: usize = ((MAX_SHAPE_R + 1) as usize).pow(4);
    static KERNELS: [[OnceLock<ShapeKernel>; N]; MAX_SHAPE_R as usize + 1] =
        [const { [const { OnceLock::new() }; N] }; MAX_SHAPE_R as usize + 1];
    let s = (r + 1) as usize;
    let key = (((ulo + r) as usize * s + uhi as usize) * s + (vlo + r) as usize) * s + vhi as usize;
    KERNELS[r as usize][key].get_or_init(|| ShapeKernel::new([ulo, uhi, vlo, vhi]))
}

/// The least-squares kernels of one rectangle of window offsets (taps in row-major order).
#[derive(Debug, Clone)]
struct ShapeKernel {
    /// Per tap, the weights of the plane's `[a, b, c]` (window coordinates, depths relative to the centre), then
    /// of the quadratic's `c0..c5`, then zeros (padding to whole vector registers).
    taps: Vec<[f64; 12]>,
    /// Whether the rectangle determines a plane / a quadratic (same criteria as the general path).
    has_plane: bool,
    has_quad: bool,
}

impl ShapeKernel {
    /// The kernels of the rectangle `[ulo, uhi] × [vlo, vhi]`: the general path's solvers applied to unit depths.
    fn new([ulo, uhi, vlo, vhi]: [i64; 4]) -> Self {
        let taps: Vec<[f64; 6]> =
            (vlo..=vhi).flat_map(|v| (ulo..=uhi).map(move |u| basis(u as f64, v as f64))).collect();
        let mut n = [[0.0f64; 6]; 6];
        for b in &taps {
            for i in 0..6 {
                for j in 0..=i {
                    n[i][j] += b[i] * b[j];
                }
            }
        }
        let sums = |b: &[f64; 6]| [n[0][0], n[1][0], n[2][0], n[1][1], n[2][1], n[2][2], b[0], b[1], b[2]];
        // The plane's solution is linear in (Σz, Σuz, Σvz): the kernel of a tap is the solution for a unit depth there.
        let plane: Vec<Option<[f64; 3]>> = taps.iter().map(|b| plane::solve(&sums(b))).collect();
        let quad: Vec<Option<[f64; 6]>> = taps
            .iter()
            .map(|b| {
                let (mut n, mut rhs) = (n, *b);
                (taps.len() >= 6 && cholesky_solve(&mut n, &mut rhs)).then_some(rhs)
            })
            .collect();
        let has_plane = plane.iter().all(Option::is_some);
        let has_quad = quad.iter().all(Option::is_some);
        Self {
            taps: plane
                .into_iter()
                .zip(quad)
                .map(|(p, q)| {
                    let (p, q) = (p.unwrap_or([0.0; 3]), q.unwrap_or([0.0; 6]));
                    let mut t = [0.0; 12];
                    t[..3].copy_from_slice(&p);
                    t[3..9].copy_from_slice(&q);
                    t
                })
                .collect(),
            has_plane,
            has_quad,
        }
    }
}

/// The three symmetric window sums at position `i` of `W = 2R + 1` shifted slices (`s[R]` is the centre):
/// `Σ k·(z₊ₖ − z₋ₖ)`, `Σ p(k)·((z₊ₖ − z₀) + (z₋ₖ − z₀))` and `Σ ((z₊ₖ − z₀) + (z₋ₖ − z₀))` over `k = 1..=R`,
/// in that order of operations (the fused fast path's row and column-first passes share it).
#[inline(always)]
fn symmetric_taps<const R: usize, const W: usize>(
    s: &[&[f32]; W],
    pk: &[f32; W],
    i: usize,
) -> (f32, f32, f32) {
    let c = s[R][i];
    let (mut a1, mut ap, mut a0) = (0.0f32, 0.0f32, 0.0f32);
    for k in 1..=R {
        let (a, b) = (s[R + k][i], s[R - k][i]);
        a1 += k as f32 * (a - b);
        let e = (a - c) + (b - c);
        ap += pk[k] * e;
        a0 += e;
    }
    (a1, ap, a0)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{RngExt, SeedableRng, rngs::Xoshiro256PlusPlus};

    #[test]
    fn lane_sums_equal_normal_sums_bit_for_bit() {
        // Random depths (integers, fractions, −0, ±∞ and NaN holes) and every window the lanes take: each lane's
        // count, right-hand sides and normal matrix equal `normal_sums` of its pixel alone, whatever the others.
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(18);
        for trial in 0..60 {
            let (wu, hu) = (rng.random_range(7..40), rng.random_range(7..30));
            let holes = [0.02, 0.2, 0.6][trial % 3];
            let src: Vec<f32> = (0..wu * hu)
                .map(|_| {
                    if rng.random_bool(holes) {
                        [f32::NAN, f32::INFINITY, f32::NEG_INFINITY][rng.random_range(0..3)]
                    } else if rng.random_bool(0.05) {
                        -0.0
                    } else if trial % 2 == 0 {
                        rng.random_range(-50..50) as f32
                    } else {
                        rng.random_range(-3.0..3.0f32) * 10f32.powi(rng.random_range(-3..4))
                    }
                })
                .collect();
            for window in [3u32, 5, 7] {
                let r = window as usize / 2;
                if wu <= 2 * r || hu <= 2 * r {
                    continue;
                }
                let f = RowFitter::new(&src, wu, hu, window, Path::Fast, Fit::Quadratic);
                let ri = r as i64;
                for y in r..hu - r {
                    let xs: Vec<usize> = (r..wu - r).filter(|_| rng.random_bool(0.5)).collect();
                    for group in xs.chunks(rng.random_range(1..=LANES)) {
                        let s = f.lane_sums(group, y);
                        for (l, &x) in group.iter().enumerate() {
                            let zc = f64::from(src[y * wu + x]);
                            let (count, rhs, packed) = s.lane(l, &f.outer, &f.outer_full);
                            let (c0, r0, p0) = f.normal_sums::<6, 21>(x, y, zc, [-ri, ri, -ri, ri]);
                            let at = format!("trial {trial}, window {window}, ({x}, {y})");
                            assert_eq!(count, c0, "{at}");
                            assert_eq!(rhs.map(f64::to_bits), r0.map(f64::to_bits), "{at}");
                            assert_eq!(packed.map(f64::to_bits), p0.map(f64::to_bits), "{at}");
                        }
                    }
                }
            }
        }
    }
}
