//! nalgebra's symmetric eigen-solver (`SymmetricEigen::new` and `symmetric_eigenvalues`, nalgebra 0.35)
//! specialised to 3 × 3 `f64` matrices: the same floating-point operations in the same order (scaling by the
//! largest entry, one Householder tridiagonalisation step, implicit QR with Wilkinson shifts and Givens
//! rotations, the 2 × 2 end case), so the same bits, without the generic views, dynamic sub-ranges and their
//! bounds checks. A test compares both with nalgebra bit for bit on random matrices.
//!
//! Derived from nalgebra (Apache-2.0, © Sébastien Crozet and the nalgebra contributors): the changes are the
//! specialisation to 3 × 3 `f64` and the removal of the generic views. The comments name the nalgebra function
//! each step copies. Sums start from `0.0` where nalgebra's do (its
//! dot product on dynamically sized views), which matters only for the sign of a zero.

/// `f64::EPSILON`, nalgebra's `default_epsilon`.
const EPS: f64 = f64::EPSILON;

/// simba's `to_exp` for a real: `(|x|, ±1)`, with `+1` for `x ≥ 0` (and `-1` for NaN).
#[inline(always)]
fn to_exp(x: f64) -> (f64, f64) {
    if x >= 0.0 { (x, 1.0) } else { (-x, -1.0) }
}

/// The eigenvalues (in the solver's order) and, if `vectors`, the eigenvectors as the columns of the returned
/// row-major matrix (`q[r][k]`: row `r` of the eigenvector of `values[k]`; the identity when `!vectors`).
/// `c` is symmetric, row-major; only its lower triangle and diagonal are read after the scaling, as in nalgebra.
#[must_use]
pub fn symmetric_eigen3(c: [[f64; 3]; 3], vectors: bool) -> ([f64; 3], [[f64; 3]; 3]) {
    // `camax`: the largest modulus (a fold of `max`, whose result does not depend on the order).
    let amax = c.iter().flatten().fold(c[0][0].abs(), |a, &b| a.max(b.abs()));
    let mut m = c;
    if amax != 0.0 {
        m = m.map(|row| row.map(|v| v / amax));
    }
    let signs = tridiagonalise(&mut m);
    let mut diag = [m[0][0], m[1][1], m[2][2]];
    let mut off = [signs[0].abs(), signs[1].abs()];
    let mut q =
        if vectors { assemble_q(&m, signs) } else { [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]] };
    implicit_qr(&mut diag, &mut off, vectors.then_some(&mut q));
    (diag.map(|d| d * amax), q)
}

/// `householder::reflection_axis_mut` on `x` (length 1 or 2): the normalised axis in place, the signed norm,
/// and whether the reflection is not the identity.
#[inline(always)]
fn reflection_axis(x: &mut [f64]) -> (f64, bool) {
    let mut dot = 0.0;
    for &v in x.iter() {
        dot += v * v;
    }
    let sq = 0.0 + dot;
    let norm = sq.sqrt();
    let (modulus, sign) = to_exp(x[0]);
    let signed_norm = sign * norm;
    let factor = (sq + modulus * norm) * 2.0;
    x[0] += signed_norm;
    if factor != 0.0 {
        let f = factor.sqrt();
        x.iter_mut().for_each(|v| *v /= f);
        let mut dot = 0.0;
        for &v in x.iter() {
            dot += v * v;
        }
        let n = (0.0 + dot).sqrt();
        x.iter_mut().for_each(|v| *v /= n);
        (-signed_norm, true)
    } else {
        (signed_norm, false)
    }
}

/// `SymmetricTridiagonal::new` on the 3 × 3 `m` (lower triangle updated, the Householder axes stored below the
/// diagonal of columns 0 and 1); returns the signed off-diagonal.
#[inline(always)]
#[allow(clippy::neg_multiply, clippy::assign_op_pattern)] // nalgebra's operations, operand order included
fn tridiagonalise(m: &mut [[f64; 3]; 3]) -> [f64; 2] {
    let mut off = [0.0; 2];
    // i = 0: axis = m[1..3][0], sub-matrix m[1..3][1..3].
    let mut axis = [m[1][0], m[2][0]];
    let (norm, not_zero) = reflection_axis(&mut axis);
    (m[1][0], m[2][0]) = (axis[0], axis[1]);
    off[0] = norm;
    if not_zero {
        let mut s = [[m[1][1], m[1][2]], [m[2][1], m[2][2]]];
        let p = hegemv2(&s, axis);
        let dot = 0.0 + axis[0] * p[0] + axis[1] * p[1];
        hegerc2(&mut s, -1.0, p, axis);
        hegerc2(&mut s, -1.0, axis, p);
        hegerc2(&mut s, dot * 2.0, axis, axis);
        (m[1][1], m[2][1], m[2][2]) = (s[0][0], s[1][0], s[1][1]);
    }
    // i = 1: axis = m[2][1], sub-matrix m[2][2].
    let mut axis = [m[2][1]];
    let (norm, not_zero) = reflection_axis(&mut axis);
    m[2][1] = axis[0];
    off[1] = norm;
    if not_zero {
        // `hegemv` with a 1 × 1 matrix: the product, then `+= alpha · (empty dot)`.
        let mut p = 2.0 * axis[0] * m[2][2];
        p += 2.0 * 0.0;
        let dot = 0.0 + axis[0] * p;
        let mut s = m[2][2];
        s += -1.0 * axis[0] * p;
        s = (-1.0 * p) * axis[0] + s;
        s = (dot * 2.0 * axis[0]) * axis[0] + s;
        m[2][2] = s;
    }
    off
}

/// `p.hegemv(2.0, s, x, 0.0)` for a 2 × 2 `s` (lower triangle read).
#[inline(always)]
fn hegemv2(s: &[[f64; 2]; 2], x: [f64; 2]) -> [f64; 2] {
    let alpha = 2.0;
    // axpy(alpha · x0, column 0, beta = 0): y = (alpha · x0) · col · 1.
    let a0 = alpha * x[0];
    let mut y = [a0 * s[0][0] * 1.0, a0 * s[1][0] * 1.0];
    y[0] += alpha * (0.0 + s[1][0] * x[1]);
    // j = 1: the dot of column 1's rows 1.. with x's rows 1..; the axpy on rows 2.. is empty.
    y[1] += alpha * (0.0 + s[1][1] * x[1]);
    y
}

/// `s.hegerc(alpha, x, y, 1.0)` for a 2 × 2 `s` (lower triangle and diagonal written).
#[inline(always)]
fn hegerc2(s: &mut [[f64; 2]; 2], alpha: f64, x: [f64; 2], y: [f64; 2]) {
    let a = alpha * y[0];
    s[0][0] = a * x[0] * 1.0 + 1.0 * s[0][0];
    s[1][0] = a * x[1] * 1.0 + 1.0 * s[1][0];
    let a = alpha * y[1];
    s[1][1] = a * x[1] * 1.0 + 1.0 * s[1][1];
}

/// `householder::assemble_q` for 3 × 3: the identity reflected by the axis of column 1, then of column 0.
#[inline(always)]
fn assemble_q(m: &[[f64; 3]; 3], signs: [f64; 2]) -> [[f64; 3]; 3] {
    let mut q = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
    // i = 1: rows 2.., columns 1.. of q; axis m[2][1].
    let sign = signs[1].signum();
    let axis = m[2][1];
    for col in 1..3 {
        let m_two = sign * -2.0;
        let factor = ((0.0 + axis * q[2][col]) - 0.0) * m_two;
        q[2][col] = factor * axis * 1.0 + sign * q[2][col];
    }
    // i = 0: rows 1.., columns 0.. of q; axis m[1..3][0].
    let sign = signs[0].signum();
    let axis = [m[1][0], m[2][0]];
    for col in 0..3 {
        let m_two = sign * -2.0;
        let factor = ((0.0 + axis[0] * q[1][col] + axis[1] * q[2][col]) - 0.0) * m_two;
        q[1][col] = factor * axis[0] * 1.0 + sign * q[1][col];
        q[2][col] = factor * axis[1] * 1.0 + sign * q[2][col];
    }
    q
}

/// nalgebra's `wilkinson_shift`.
#[inline(always)]
fn wilkinson_shift(tmm: f64, tnn: f64, tmn: f64) -> f64 {
    let sq_tmn = tmn * tmn;
    if sq_tmn != 0.0 {
        let d = (tmm - tnn) * 0.5;
        tnn - sq_tmn / (d + d.signum() * (d * d + sq_tmn).sqrt())
    } else {
        tnn
    }
}

/// `SymmetricEigen::delimit_subproblem`.
#[inline(always)]
fn delimit_subproblem(diag: &[f64; 3], off: &mut [f64; 2], end: usize) -> (usize, usize) {
    let mut n = end;
    while n > 0 {
        let m = n - 1;
        if off[m].abs() > EPS * (diag[n].abs() + diag[m].abs()) {
            break;
        }
        n -= 1;
    }
    if n == 0 {
        return (0, 0);
    }
    let mut new_start = n - 1;
    while new_start > 0 {
        let m = new_start - 1;
        if off[m] == 0.0 || off[m].abs() <= EPS * (diag[new_start].abs() + diag[m].abs()) {
            off[m] = 0.0;
            break;
        }
        new_start -= 1;
    }
    (new_start, n)
}

/// `q`'s columns `i` and `i + 1` rotated by `(c, s)` (`GivensRotation::rotate_rows`).
#[inline(always)]
fn rotate_rows(q: &mut [[f64; 3]; 3], i: usize, c: f64, s: f64) {
    for row in q.iter_mut() {
        let (a, b) = (row[i], row[i + 1]);
        row[i] = a * c + s * b;
        row[i + 1] = -s * a + b * c;
    }
}

/// The implicit QR iterations of `SymmetricEigen::do_decompose` (no iteration limit, as `new` and
/// `symmetric_eigenvalues` call it).
#[inline(always)]
fn implicit_qr(diag: &mut [f64; 3], off: &mut [f64; 2], mut q: Option<&mut [[f64; 3]; 3]>) {
    let (mut start, mut end) = delimit_subproblem(diag, off, 2);
    while end != start {
        let subdim = end - start + 1;
        if subdim > 2 {
            qr_step(diag, off, start, end, q.as_deref_mut());
            let m = end - 1;
            if off[m].abs() <= EPS * (diag[m].abs() + diag[end].abs()) {
                end -= 1;
            }
        } else if subdim == 2 {
            end_2x2(diag, off, start, q.as_deref_mut());
            end -= 1;
        }
        (start, end) = delimit_subproblem(diag, off, end);
    }
}

/// One implicit QR sweep with a Wilkinson shift over `start..=end` (of `do_decompose`'s `subdim > 2` branch).
#[inline(always)]
fn qr_step(
    diag: &mut [f64; 3],
    off: &mut [f64; 2],
    start: usize,
    end: usize,
    mut q: Option<&mut [[f64; 3]; 3]>,
) {
    let (m, n) = (end - 1, end);
    let mut vec = [diag[start] - wilkinson_shift(diag[m], diag[n], off[m]), off[start]];
    for i in start..n {
        let j = i + 1;
        // `GivensRotation::cancel_y`.
        if vec[1] == 0.0 {
            break;
        }
        let (mod0, sign0) = to_exp(vec[0]);
        let denom = (mod0 * mod0 + vec[1] * vec[1]).sqrt();
        let c = mod0 / denom;
        let s = -vec[1] / (sign0 * denom);
        let norm = sign0 * denom;
        if i > start {
            off[i - 1] = norm;
        }
        let (mii, mjj, mij) = (diag[i], diag[j], off[i]);
        let (cc, ss, cs) = (c * c, s * s, c * s);
        let b = cs * 2.0 * mij;
        diag[i] = (cc * mii + ss * mjj) - b;
        diag[j] = (ss * mii + cc * mjj) + b;
        off[i] = cs * (mii - mjj) + mij * (cc - ss);
        if i != n - 1 {
            vec[0] = off[i];
            vec[1] = -s * off[i + 1];
            off[i + 1] *= c;
        }
        if let Some(q) = q.as_deref_mut() {
            // `rot.inverse().rotate_rows(..)`.
            rotate_rows(q, i, c, -s);
        }
    }
}

/// The 2 × 2 end case of `do_decompose` on `start, start + 1` (`Matrix2::eigenvalues` and the basis rotation).
#[inline(always)]
fn end_2x2(diag: &mut [f64; 3], off: &[f64; 2], start: usize, q: Option<&mut [[f64; 3]; 3]>) {
    let (h00, h11, h01) = (diag[start], diag[start + 1], off[start]);
    // `compute_2x2_eigvals`; nalgebra unwraps its `None` (a NaN discriminant).
    let val = (h00 - h11) * 0.5;
    let discr = h01 * h01 + val * val;
    assert!(discr >= 0.0, "symmetric 2x2 eigenvalues: NaN discriminant");
    let sqrt_discr = discr.sqrt();
    let half_tra = (h00 + h11) * 0.5;
    let (e0, e1) = (half_tra + sqrt_discr, half_tra - sqrt_discr);
    let basis = if (e0 - h11).abs() > (e0 - h00).abs() { [e0 - h11, h01] } else { [h01, e0 - h00] };
    diag[start] = e0;
    diag[start + 1] = e1;
    if let Some(q) = q {
        // `GivensRotation::try_new(x, y, eps)`.
        let (mod0, sign0) = to_exp(basis[0]);
        let denom = (mod0 * mod0 + basis[1] * basis[1]).sqrt();
        if denom > EPS {
            let norm = sign0 * denom;
            rotate_rows(q, start, mod0 / denom, basis[1] / norm);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Matrix3, SymmetricEigen};
    use rand::{RngExt, SeedableRng, rngs::Xoshiro256PlusPlus};

    fn check(c: [[f64; 3]; 3], k: usize) {
        let mat = Matrix3::from_fn(|r, col| c[r][col]);
        let eig = SymmetricEigen::new(mat);
        let (values, q) = symmetric_eigen3(c, true);
        for i in 0..3 {
            assert_eq!(values[i].to_bits(), eig.eigenvalues[i].to_bits(), "case {k}: value {i} of {c:?}");
            for r in 0..3 {
                assert_eq!(
                    q[r][i].to_bits(),
                    eig.eigenvectors[(r, i)].to_bits(),
                    "case {k}: vector {i} of {c:?}"
                );
            }
        }
        let (only, _) = symmetric_eigen3(c, false);
        let ev = mat.symmetric_eigenvalues();
        for i in 0..3 {
            assert_eq!(only[i].to_bits(), ev[i].to_bits(), "case {k}: eigenvalues-only {i} of {c:?}");
        }
    }

    /// The same bits as nalgebra on covariances of random point sets (near planes, lines, single points, at
    /// several scales and offsets) and on random symmetric matrices with zeros, signs and ties.
    #[test]
    fn matches_nalgebra_bit_for_bit() {
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(5);
        for k in 0..60000 {
            let c = if k % 3 == 0 {
                // Random symmetric entries, some exactly zero or repeated.
                let mut e = [0.0f64; 6];
                for v in &mut e {
                    *v = match rng.random_range(0..6) {
                        0 => 0.0,
                        1 => 1.0,
                        2 => -0.5,
                        _ => rng.random_range(-1.0..1.0) * 10f64.powi(rng.random_range(-6..6)),
                    };
                }
                [[e[0], e[1], e[2]], [e[1], e[3], e[4]], [e[2], e[4], e[5]]]
            } else {
                let scale = 10f64.powi(rng.random_range(-3..4));
                let off = [0, 1, 2]
                    .map(|_| rng.random_range(-1.0..1.0) * scale * 10f64.powi(rng.random_range(0..4)));
                let noise = [0.0, 1e-9, 1e-4, 1e-2, 0.3, 1.0][k % 6];
                let line = k % 7 == 1;
                let n = rng.random_range(1..40);
                let mut m = crate::Moments::default();
                for _ in 0..n {
                    let (u, v) =
                        (rng.random_range(-1.0..1.0), if line { 0.0 } else { rng.random_range(-1.0..1.0) });
                    let w = noise * rng.random_range(-1.0..1.0);
                    let p = [
                        off[0] + scale * (u + 0.3 * v),
                        off[1] + scale * (v - 0.2 * w),
                        off[2] + scale * (w + 0.5 * u),
                    ];
                    m.add(p.map(|c| f64::from(c as f32)));
                }
                let cov = m.covariance();
                [0, 1, 2].map(|r| [0, 1, 2].map(|col| cov[(r, col)]))
            };
            check(c, k);
        }
        // Diagonal, zero and axis-aligned cases.
        check([[0.0; 3]; 3], 0);
        check([[1.0, 0.0, 0.0], [0.0, 2.0, 0.0], [0.0, 0.0, 3.0]], 1);
        check([[2.0, 0.0, 0.0], [0.0, 2.0, 0.0], [0.0, 0.0, 2.0]], 2);
        check([[1.0, 0.0, 0.0], [0.0, 1.0, 1e-300], [0.0, 1e-300, 1.0]], 3);
        check([[0.0, 0.0, 1.0], [0.0, 0.0, 0.0], [1.0, 0.0, 0.0]], 4);
    }
}
