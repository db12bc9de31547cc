//! Curvatures from the quadratic-fit derivatives, and the windowed standard deviation of K, one row at a time.

/// K, H and the half-difference `d = (k1 − k2)/2` of the principal curvatures at one pixel from its derivatives
/// (NaN propagates).
///
/// With `E = 1 + Ix²`, `F = Ix·Iy`, `G = 1 + Iy²`, `q = 1 + Ix² + Iy²` and `(L, M, N) = (Ixx, Ixy, Iyy)`:
/// `K = (LN − M²)/q²`, `H = (EN − 2FM + GL)/(2q^{3/2})`, and `d = sqrt(H² − K) = sqrt((EN − GL)² + 4(EM − FL)(GM −
/// FN)) / (2q^{3/2})`. The last form has no cancellation at umbilics (where `H² ≈ K`), so f32 keeps `k1,2 = H ± d`
/// accurate there. Curvedness `sqrt((k1² + k2²)/2) = sqrt(H² + d²)`.
#[inline(always)]
fn khd(ix: f32, iy: f32, l: f32, m: f32, nn: f32) -> (f32, f32, f32) {
    let (e, f, g) = (1.0 + ix * ix, ix * iy, 1.0 + iy * iy);
    let inv_q = 1.0 / (1.0 + ix * ix + iy * iy);
    let s = inv_q * inv_q.sqrt();
    let k = (l * nn - m * m) * (inv_q * inv_q);
    let h = 0.5 * (e * nn - 2.0 * f * m + g * l) * s;
    let (a, b) = (e * nn - g * l, 4.0 * (e * m - f * l) * (g * m - f * nn));
    let d = 0.5 * (a * a + b).max(0.0).sqrt() * s;
    (k, h, d)
}

/// K, H and curvedness of one row from its derivatives `[Ix, Iy, Ixx, Ixy, Iyy]` (see [`khd`]); all slices have
/// the row's length.
pub(crate) fn curvature_row(
    deriv: &[Vec<f32>; 5],
    k_out: &mut [f32],
    h_out: &mut [f32],
    curvedness: &mut [f32],
) {
    isa::dispatch(
        #[inline(always)]
        || curvature_row_kernel(deriv, k_out, h_out, curvedness),
    );
}

/// [`curvature_row`]'s body, compiled for each instruction set ([`isa::dispatch`]).
#[inline(always)]
fn curvature_row_kernel(deriv: &[Vec<f32>; 5], k_out: &mut [f32], h_out: &mut [f32], curvedness: &mut [f32]) {
    let n = k_out.len();
    let [ix, iy, l, m, nn] = deriv.each_ref().map(|d| &d[..n]);
    let (h_out, curvedness) = (&mut h_out[..n], &mut curvedness[..n]);
    for i in 0..n {
        let (k, h, d) = khd(ix[i], iy[i], l[i], m[i], nn[i]);
        k_out[i] = k;
        h_out[i] = h;
        curvedness[i] = (h * h + d * d).sqrt();
    }
}

/// The principal curvatures `[k1, k2] = [H + d, H − d]` (k1 ≥ k2) of every pixel from its derivatives (see [`khd`]).
pub(crate) fn principal(grad: &[[f32; 2]], hess: &[[f32; 3]]) -> Vec<[f32; 2]> {
    grad.iter()
        .zip(hess)
        .map(|(&[ix, iy], &[l, m, nn])| {
            let (_, h, d) = khd(ix, iy, l, m, nn);
            [h + d, h - d]
        })
        .collect()
}

/// Streaming standard deviation of the finite values of K over a `w × w` window (clipped at the border).
///
/// Feed the rows of K in order with [`WindowStd::push_row`]; row `y` of the result is available once rows up to
/// `y + r` are in ([`WindowStd::out_row`], called for `y = 0, 1, …` in order). Per row: horizontal box sums
/// `[count, Σk, Σk²]` (the count in f32, exact; the sums in f64; straight from the row for windows up to 7, over a
/// padded copy beyond), kept in a ring of `w + 1` rows; vertically a running sum (add the row entering the window,
/// subtract the row leaving), so the cost per pixel does not depend on the window height.
pub(crate) struct WindowStd {
    /// Row length, half window and image height.
    wu: usize,
    r: usize,
    hu: usize,
    /// Ring of horizontal sums, `w + 1` rows of `wu` each: the count (small integers, exact in f32), Σk and Σk².
    ring_n: Vec<f32>,
    ring: [Vec<f64>; 2],
    /// Vertical running sums of the current output row (count, Σk, Σk²).
    acc_n: Vec<f32>,
    acc: [Vec<f64>; 2],
    /// Next row to add to `acc`.
    next_add: usize,
    /// Padded row scratch (`wu + 2r`) of windows wider than 7: count, k, k².
    pad_n: Vec<f32>,
    pad: [Vec<f64>; 2],
}

impl WindowStd {
    /// A window of `window_px` (odd) over an image of `wu × hu`.
    pub(crate) fn new(wu: usize, hu: usize, window_px: u32) -> Self {
        let r = window_px as usize / 2;
        let slots = 2 * r + 2;
        Self {
            wu,
            r,
            hu,
            ring_n: vec![0.0; slots * wu],
            ring: std::array::from_fn(|_| vec![0.0; slots * wu]),
            acc_n: vec![0.0; wu],
            acc: std::array::from_fn(|_| vec![0.0; wu]),
            next_add: 0,
            pad_n: vec![0.0; wu + 2 * r],
            pad: std::array::from_fn(|_| vec![0.0; wu + 2 * r]),
        }
    }

    /// Adds row `y` of K (rows in order).
    pub(crate) fn push_row(&mut self, y: usize, k: &[f32]) {
        isa::dispatch(
            #[inline(always)]
            || self.push_row_kernel(y, k),
        );
    }

    /// [`Self::push_row`]'s body, compiled for each instruction set ([`isa::dispatch`]).
    #[inline(always)]
    fn push_row_kernel(&mut self, y: usize, k: &[f32]) {
        let (wu, r) = (self.wu, self.r);
        let slot = (y % (2 * r + 2)) * wu;
        if r <= 3 {
            let [r1, r2] = &mut self.ring;
            let c = &mut self.ring_n[slot..slot + wu];
            let (s1, s2) = (&mut r1[slot..slot + wu], &mut r2[slot..slot + wu]);
            match r {
                0 => box_k::<0, 1>(&k[..wu], c, s1, s2),
                1 => box_k::<1, 3>(&k[..wu], c, s1, s2),
                2 => box_k::<2, 5>(&k[..wu], c, s1, s2),
                _ => box_k::<3, 7>(&k[..wu], c, s1, s2),
            }
            return;
        }
        let [p1, p2] = &mut self.pad;
        let (pc, p1, p2) = (&mut self.pad_n[r..r + wu], &mut p1[r..r + wu], &mut p2[r..r + wu]);
        for (i, &v) in k[..wu].iter().enumerate() {
            (pc[i], p1[i], p2[i]) = terms(v);
        }
        let [r1, r2] = &mut self.ring;
        let c = &mut self.ring_n[slot..slot + wu];
        let (s1, s2) = (&mut r1[slot..slot + wu], &mut r2[slot..slot + wu]);
        let ([p1, p2], pc) = (&self.pad, &self.pad_n);
        c.copy_from_slice(&pc[..wu]);
        s1.copy_from_slice(&p1[..wu]);
        s2.copy_from_slice(&p2[..wu]);
        for j in 1..=2 * r {
            let (a, b, d) = (&pc[j..j + wu], &p1[j..j + wu], &p2[j..j + wu]);
            for i in 0..wu {
                c[i] += a[i];
                s1[i] += b[i];
                s2[i] += d[i];
            }
        }
    }

    /// Adds ring row `add` to the running sums and removes ring row `sub` (either may be absent).
    #[inline(always)] // inlined into the dispatched kernels (isa::dispatch)
    fn update(&mut self, add: Option<usize>, sub: Option<usize>) {
        let (wu, slots) = (self.wu, 2 * self.r + 2);
        running_update(&mut self.acc_n, &self.ring_n, wu, slots, add, sub);
        for (acc, ring) in self.acc.iter_mut().zip(&self.ring) {
            running_update(acc, ring, wu, slots, add, sub);
        }
    }

    /// Writes row `y` of the standard deviation (NaN where `k_row`, row `y` of K, is not finite); rows
    /// `y − r ..= min(y + r, hu − 1)` must have been pushed, and rows `0..y` written before.
    pub(crate) fn out_row(&mut self, y: usize, k_row: &[f32], out: &mut [f32]) {
        isa::dispatch(
            #[inline(always)]
            || self.out_row_kernel(y, k_row, out),
        );
    }

    /// [`Self::out_row`]'s body, compiled for each instruction set ([`isa::dispatch`]).
    #[inline(always)]
    fn out_row_kernel(&mut self, y: usize, k_row: &[f32], out: &mut [f32]) {
        let (wu, r) = (self.wu, self.r);
        while self.next_add < (y + r).min(self.hu - 1) {
            self.update(Some(self.next_add), None);
            self.next_add += 1;
        }
        let add = (self.next_add <= (y + r).min(self.hu - 1)).then_some(self.next_add);
        self.next_add += usize::from(add.is_some());
        let sub = (y > r).then(|| y - r - 1);
        let (k_row, out) = (&k_row[..wu], &mut out[..wu]);
        if let (Some(a), Some(s)) = (add, sub) {
            // The usual row: the running-sum update (as in `update`) and the output in one loop.
            let slots = 2 * r + 2;
            let row = |ring, yy| ring_row(ring, yy, slots, wu);
            let [r1, r2] = &self.ring;
            let (ac, sc) = (ring_row(&self.ring_n, a, slots, wu), ring_row(&self.ring_n, s, slots, wu));
            let (a1, s1r, a2, s2r) = (row(r1, a), row(r1, s), row(r2, a), row(r2, s));
            let [s1, s2] = &mut self.acc;
            let (n, s1, s2) = (&mut self.acc_n[..wu], &mut s1[..wu], &mut s2[..wu]);
            for i in 0..wu {
                n[i] += ac[i] - sc[i];
                s1[i] += a1[i] - s1r[i];
                s2[i] += a2[i] - s2r[i];
                out[i] = std_of(n[i], s1[i], s2[i], k_row[i]);
            }
            return;
        }
        self.update(add, sub);
        let ([s1, s2], n) = (&self.acc, &self.acc_n);
        for i in 0..wu {
            out[i] = std_of(n[i], s1[i], s2[i], k_row[i]);
        }
    }
}

/// The standard deviation from the window's count `n`, `Σk` and `Σk²`, NaN where the pixel's own `k` is not finite:
/// var = (n·Σk² − (Σk)²) / n², the numerator in f64, the division and the square root in f32.
#[inline(always)]
fn std_of(n: f32, s1: f64, s2: f64, k: f32) -> f32 {
    let num = (f64::from(n) * s2 - s1 * s1).max(0.0) as f32;
    let sd = num.sqrt() / n;
    if k.is_finite() { sd } else { f32::NAN }
}

/// Row `yy` of a ring of `slots` rows of `wu`.
fn ring_row<T>(ring: &[T], yy: usize, slots: usize, wu: usize) -> &[T] {
    let o = (yy % slots) * wu;
    &ring[o..o + wu]
}

/// Adds ring row `add` to the running sums `acc` and removes ring row `sub` (either may be absent).
#[inline(always)] // inlined into the dispatched kernels (isa::dispatch)
fn running_update<T>(
    acc: &mut [T],
    ring: &[T],
    wu: usize,
    slots: usize,
    add: Option<usize>,
    sub: Option<usize>,
) where
    T: Copy + std::ops::AddAssign + std::ops::SubAssign + std::ops::Sub<Output = T>,
{
    let row = |yy| ring_row(ring, yy, slots, wu);
    match (add, sub) {
        (Some(a), Some(s)) => {
            for ((acc, &a), &s) in acc.iter_mut().zip(row(a)).zip(row(s)) {
                *acc += a - s;
            }
        }
        (Some(a), None) => acc.iter_mut().zip(row(a)).for_each(|(acc, &a)| *acc += a),
        (None, Some(s)) => acc.iter_mut().zip(row(s)).for_each(|(acc, &s)| *acc -= s),
        (None, None) => {}
    }
}

/// `[1, k, k²]` of a finite K value (the count in f32, exact), `[0, 0, 0]` otherwise (also the padding beyond the
/// row ends).
#[inline(always)]
fn terms(v: f32) -> (f32, f64, f64) {
    let ok = v.is_finite();
    let x = if ok { f64::from(v) } else { 0.0 };
    (if ok { 1.0 } else { 0.0 }, x, x * x)
}

/// Horizontal box sums over `W = 2R + 1` pixels (count, Σk, Σk²) of the row `k` into `c`, `s1`, `s2`, straight from
/// K: the sum of each pixel runs over its window left to right, the padding beyond the row ends adding zeros (the
/// window loop unrolled; the interior vectorises across pixels).
#[inline(always)] // inlined into the dispatched kernels (isa::dispatch)
fn box_k<const R: usize, const W: usize>(k: &[f32], c: &mut [f32], s1: &mut [f64], s2: &mut [f64]) {
    let wu = k.len();
    let (c, s1, s2) = (&mut c[..wu], &mut s1[..wu], &mut s2[..wu]);
    let at = |i: usize, j: usize| {
        let t = (i + j).wrapping_sub(R);
        if t < wu { terms(k[t]) } else { (0.0, 0.0, 0.0) }
    };
    let mut edge = |i: usize| {
        let (mut a, mut b, mut d) = at(i, 0);
        for j in 1..W {
            let (x, y, z) = at(i, j);
            a += x;
            b += y;
            d += z;
        }
        (c[i], s1[i], s2[i]) = (a, b, d);
    };
    if wu <= 2 * R {
        (0..wu).for_each(&mut edge);
        return;
    }
    (0..R).chain(wu - R..wu).for_each(&mut edge);
    let m = wu - 2 * R;
    let ks: [&[f32]; W] = std::array::from_fn(|j| &k[j..j + m]);
    let (c, s1, s2) = (&mut c[R..R + m], &mut s1[R..R + m], &mut s2[R..R + m]);
    for i in 0..m {
        let (mut a, mut b, mut d) = terms(ks[0][i]);
        for j in 1..W {
            let (x, y, z) = terms(ks[j][i]);
            a += x;
            b += y;
            d += z;
        }
        (c[i], s1[i], s2[i]) = (a, b, d);
    }
}
