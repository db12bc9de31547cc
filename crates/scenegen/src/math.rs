//! Small vector helpers and platform-independent transcendental functions.
//!
//! `f64::sin`, `cos`, `ln` and `atan2` call the platform's libm, whose last bits differ between
//! systems. The generator's checksums must be identical everywhere, so every function here uses
//! only `+ − × ÷` and `sqrt`, which IEEE 754 rounds exactly.

use std::f64::consts::{FRAC_PI_2, FRAC_PI_4, PI, TAU};

/// A 3-vector.
pub(crate) type V3 = [f64; 3];

pub(crate) fn add(a: V3, b: V3) -> V3 {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}

pub(crate) fn sub(a: V3, b: V3) -> V3 {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

pub(crate) fn scale(a: V3, s: f64) -> V3 {
    [a[0] * s, a[1] * s, a[2] * s]
}

pub(crate) fn dot(a: V3, b: V3) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

pub(crate) fn cross(a: V3, b: V3) -> V3 {
    [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
}

pub(crate) fn norm(a: V3) -> f64 {
    dot(a, a).sqrt()
}

pub(crate) fn normalize(a: V3) -> V3 {
    let n = norm(a);
    assert!(n > 0.0, "normalize: zero vector");
    scale(a, 1.0 / n)
}

/// `(sin x, cos x)` with a fixed polynomial, identical on every platform.
pub(crate) fn sin_cos(x: f64) -> (f64, f64) {
    let r = x - (x / TAU).round() * TAU;
    let q = (r / FRAC_PI_2).round();
    let y = r - q * FRAC_PI_2;
    let y2 = y * y;
    // Taylor series to y^17 / y^16: |y| ≤ π/4 gives an error below 1e-16.
    let mut s = 0.0;
    let mut c = 0.0;
    let mut ts = y;
    let mut tc = 1.0;
    for k in 0..9 {
        s += ts;
        c += tc;
        let k = f64::from(k);
        ts *= -y2 / ((2.0 * k + 2.0) * (2.0 * k + 3.0));
        tc *= -y2 / ((2.0 * k + 1.0) * (2.0 * k + 2.0));
    }
    match (q as i64).rem_euclid(4) {
        0 => (s, c),
        1 => (c, -s),
        2 => (-s, -c),
        _ => (-c, s),
    }
}

/// `atan x` for any finite `x`, identical on every platform.
fn atan(x: f64) -> f64 {
    if x < 0.0 {
        return -atan(-x);
    }
    if x > 1.0 {
        return FRAC_PI_2 - atan(1.0 / x);
    }
    // Two half-angle reductions bring x below tan(π/16) ≈ 0.2, then the series converges fast.
    let mut y = x;
    for _ in 0..2 {
        y /= 1.0 + (1.0 + y * y).sqrt();
    }
    let y2 = y * y;
    let mut sum = 0.0;
    let mut term = y;
    for k in 0..20 {
        sum += term / f64::from(2 * k + 1);
        term *= -y2;
    }
    let r = 4.0 * sum;
    debug_assert!(r <= FRAC_PI_4 + 1e-12);
    r
}

/// The angle between two vectors, in degrees in `[0, 180]`, identical on every platform.
pub(crate) fn angle_deg(a: V3, b: V3) -> f64 {
    let s = norm(cross(a, b));
    let c = dot(a, b);
    let rad = if c > 0.0 {
        atan(s / c)
    } else if c < 0.0 {
        PI - atan(s / -c)
    } else {
        FRAC_PI_2
    };
    rad * (180.0 / PI)
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    #[test]
    fn sin_cos_matches_std() {
        for i in -200..200 {
            let x = f64::from(i) * 0.0731;
            let (s, c) = sin_cos(x);
            assert_relative_eq!(s, x.sin(), epsilon = 1e-14);
            assert_relative_eq!(c, x.cos(), epsilon = 1e-14);
        }
    }

    #[test]
    fn angle_matches_std() {
        for i in 0..100 {
            let t = f64::from(i) * PI / 99.0;
            let (s, c) = sin_cos(t);
            assert_relative_eq!(angle_deg([1.0, 0.0, 0.0], [c, s, 0.0]), t.to_degrees(), epsilon = 1e-10);
        }
        assert_relative_eq!(angle_deg([0.0, 0.0, 2.0], [0.0, 3.0, 0.0]), 90.0, epsilon = 1e-12);
    }
}
