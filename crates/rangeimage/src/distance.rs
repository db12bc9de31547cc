//! Exact Euclidean distance transforms of binary masks, and "within τ" tests.
//!
//! Shared by the relaxation (pruning, support tests, energies) and the evaluation (tolerances τ), so that every
//! "within τ pixels" in the workspace is the same test: Euclidean distance between pixel centres ≤ τ, inclusive.

use crate::Grid;

/// For every pixel, the squared Euclidean distance (in pixels², between pixel centres) to the nearest `true` pixel
/// of `mask`: `0.0` on `true` pixels, `f64::INFINITY` everywhere if the mask is empty. Finite values are exact
/// integers (a 4-neighbour is at 1, a diagonal neighbour at 2), not an approximation (chamfer, 3×3 passes, …).
///
/// Separable: an exact 1D distance along each column (two linear sweeps, binary input), then the
/// lower envelope of parabolas along each row. O(width · height).
#[must_use]
pub fn edt_squared(mask: &Grid<bool>) -> Grid<f64> {
    let (w, h) = (mask.width() as usize, mask.height() as usize);
    let m = mask.as_slice();
    // Pass 1: per column, vertical distance to the nearest feature, by a downward and an upward
    // sweep over whole rows (cache-friendly), then squared.
    let big = (w + h + 1) as u32;
    let mut vd = vec![big; w * h];
    for y in 0..h {
        let (prev, cur) = vd.split_at_mut(y * w);
        let cur = &mut cur[..w];
        let prev = if y > 0 { &prev[(y - 1) * w..] } else { &[][..] };
        for x in 0..w {
            cur[x] = if m[y * w + x] {
                0
            } else if y > 0 {
                (prev[x] + 1).min(big)
            } else {
                big
            };
        }
    }
    for y in (0..h.saturating_sub(1)).rev() {
        let (cur, next) = vd.split_at_mut((y + 1) * w);
        let cur = &mut cur[y * w..];
        for x in 0..w {
            cur[x] = cur[x].min(next[x] + 1);
        }
    }
    let g: Vec<f64> =
        vd.iter().map(|&d| if d >= big { f64::INFINITY } else { f64::from(d) * f64::from(d) }).collect();
    // Pass 2: per row, lower envelope of the parabolas (q − i)² + g(q).
    let mut out = vec![f64::INFINITY; w * h];
    let mut v = vec![0usize; w];
    let mut z = vec![0.0f64; w + 1];
    for y in 0..h {
        let f = &g[y * w..(y + 1) * w];
        let o = &mut out[y * w..(y + 1) * w];
        // Only feature-reachable columns (finite g) take part; if none, the row stays infinite.
        let mut k: usize = 0;
        let mut started = false;
        for q in 0..w {
            if f[q] == f64::INFINITY {
                continue;
            }
            if !started {
                v[0] = q;
                z[0] = f64::NEG_INFINITY;
                z[1] = f64::INFINITY;
                started = true;
                continue;
            }
            let qf = q as f64;
            loop {
                let p = v[k] as f64;
                let s = ((f[q] + qf * qf) - (f[v[k]] + p * p)) / (2.0 * qf - 2.0 * p);
                if s <= z[k] && k > 0 {
                    k -= 1;
                } else {
                    k += 1;
                    v[k] = q;
                    z[k] = s;
                    z[k + 1] = f64::INFINITY;
                    break;
                }
            }
        }
        if !started {
            continue;
        }
        let mut k = 0;
        for q in 0..w {
            let qf = q as f64;
            while z[k + 1] < qf {
                k += 1;
            }
            let p = v[k] as f64;
            o[q] = (qf - p) * (qf - p) + f[v[k]];
        }
    }
    Grid::from_vec(mask.width(), mask.height(), out).expect("size matches")
}

/// `reach[dy]` for `dy = 0..=⌊t⌋`: the largest `dx ≥ 0` with `dx² + dy² ≤ t²` (compared in f64,
/// exact for these integers), so a pixel is within `t` of one `dy` rows away iff that one is at
/// most `reach[dy]` columns away.
#[must_use]
pub fn reach(t: f64) -> Vec<usize> {
    let t2 = t * t;
    (0..=t.floor() as usize)
        .map(|dy| {
            let dy2 = (dy * dy) as f64;
            let mut dx = (t2 - dy2).max(0.0).sqrt().floor() as usize;
            while ((dx + 1) * (dx + 1)) as f64 + dy2 <= t2 {
                dx += 1;
            }
            while dx > 0 && (dx * dx) as f64 + dy2 > t2 {
                dx -= 1;
            }
            dx
        })
        .collect()
}

/// For every pixel, whether some `true` pixel of `mask` is within Euclidean distance `t` (inclusive;
/// `0 ≤ t < 65535`, as row distances are kept in `u16`): the same as `edt_squared(mask) ≤ t²`, in O(pixels · t)
/// cheap vectorisable steps (for large `t`, threshold [`edt_squared`] instead: O(pixels) whatever `t`). Per row, the horizontal distance to the nearest mask pixel (capped at ⌊t⌋ + 1) by two
/// sweeps; then a pixel is near if a row `dy` away has that distance ≤ `reach[dy]`.
#[must_use]
pub fn within(mask: &Grid<bool>, t: f64) -> Grid<bool> {
    assert!(t.is_finite() && (0.0..65535.0).contains(&t), "distance::within: distance {t} out of range");
    let (w, h) = (mask.width() as usize, mask.height() as usize);
    let rx = reach(t);
    let r = rx.len() - 1;
    let cap = (r + 1) as u16;
    let mut hd = vec![cap; w * h];
    for (row, mrow) in hd.chunks_exact_mut(w.max(1)).zip(mask.as_slice().chunks_exact(w.max(1))) {
        let mut d = cap;
        for (o, &m) in row.iter_mut().zip(mrow) {
            d = if m { 0 } else { (d + 1).min(cap) };
            *o = d;
        }
        let mut d = cap;
        for (o, &m) in row.iter_mut().zip(mrow).rev() {
            d = if m { 0 } else { (d + 1).min(cap) };
            *o = (*o).min(d);
        }
    }
    let mut out = vec![false; w * h];
    for (y, orow) in out.chunks_exact_mut(w.max(1)).enumerate() {
        for yy in y.saturating_sub(r)..(y + r + 1).min(h) {
            let lim = rx[yy.abs_diff(y)] as u16;
            for (o, &d) in orow.iter_mut().zip(&hd[yy * w..(yy + 1) * w]) {
                *o |= d <= lim;
            }
        }
    }
    Grid::from_vec(mask.width(), mask.height(), out).expect("size matches")
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Brute-force squared distance to the nearest `true` pixel.
    fn brute(mask: &Grid<bool>) -> Grid<f64> {
        let pts: Vec<(i64, i64)> =
            mask.enumerate().filter(|&(_, _, &b)| b).map(|(x, y, _)| (i64::from(x), i64::from(y))).collect();
        Grid::from_fn(mask.width(), mask.height(), |x, y| {
            pts.iter()
                .map(|&(px, py)| ((px - i64::from(x)).pow(2) + (py - i64::from(y)).pow(2)) as f64)
                .fold(f64::INFINITY, f64::min)
        })
    }

    /// A deterministic pseudo-random mask (64-bit LCG; no RNG crate in this crate).
    fn mask(w: u32, h: u32, p_per_mille: u64, seed: u64) -> Grid<bool> {
        let mut s = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        Grid::from_fn(w, h, |_, _| {
            s = s.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (s >> 33) % 1000 < p_per_mille
        })
    }

    #[test]
    fn matches_brute_force_on_random_masks() {
        for case in 0..80u64 {
            let (w, h) = (1 + (case * 7 % 41) as u32, 1 + (case * 13 % 37) as u32);
            let p = [0, 2, 20, 200, 900][(case % 5) as usize];
            let m = mask(w, h, p, case);
            assert_eq!(edt_squared(&m), brute(&m), "case {case} ({w}×{h}, p = {p}‰)");
        }
    }

    #[test]
    fn empty_and_full_masks() {
        assert!(edt_squared(&Grid::new(3, 3, false)).as_slice().iter().all(|v| *v == f64::INFINITY));
        assert!(edt_squared(&Grid::new(3, 3, true)).as_slice().iter().all(|&v| v == 0.0));
        assert!(within(&Grid::new(4, 2, false), 3.0).as_slice().iter().all(|&b| !b));
    }

    #[test]
    fn single_point_distances() {
        let mut m = Grid::new(5, 4, false);
        m[(1, 2)] = true;
        let d = edt_squared(&m);
        assert_eq!((d[(1, 2)], d[(2, 2)], d[(0, 3)], d[(4, 0)]), (0.0, 1.0, 2.0, 13.0));
    }

    #[test]
    fn within_is_inclusive_and_matches_thresholded_edt() {
        let mut m = Grid::new(7, 7, false);
        m[(3, 3)] = true;
        let d = within(&m, 2.0);
        assert!(d[(5, 3)] && d[(3, 1)] && !d[(5, 4)] && d[(4, 4)]);
        assert_eq!(d.as_slice().iter().filter(|&&b| b).count(), 13);
        for case in 0..40u64 {
            let (w, h) = (1 + (case * 11 % 90) as u32, 1 + (case * 5 % 40) as u32);
            let p = [0, 2, 20, 200, 900][(case % 5) as usize];
            let m = mask(w, h, p, 100 + case);
            let d = edt_squared(&m);
            for t in [0.0, 1.0, 1.5, 2.0, 2.9, 5.0, 64.0] {
                let want: Vec<bool> = d.as_slice().iter().map(|&v| v <= t * t).collect();
                assert_eq!(within(&m, t).as_slice(), &want[..], "case {case} ({w}×{h}, p = {p}‰, t = {t})");
            }
        }
    }

    #[test]
    fn reach_is_the_largest_offset_inside_the_disk() {
        for t in [0.0, 0.5, 1.0, 2.5, 7.3, 64.0] {
            for (dy, &dx) in reach(t).iter().enumerate() {
                assert!((dx * dx + dy * dy) as f64 <= t * t, "t {t}, dy {dy}");
                assert!((((dx + 1) * (dx + 1) + dy * dy) as f64) > t * t, "t {t}, dy {dy}");
            }
        }
    }
}
