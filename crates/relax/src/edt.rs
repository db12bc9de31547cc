//! Exact squared Euclidean distance transform of a binary mask (Felzenszwalb & Huttenlocher, 2012).

use rangeimage::Grid;

/// Squared distance assigned to pixels when the mask has no feature pixel at all.
pub(crate) const FAR: f64 = 1e20;

/// For every pixel, the squared Euclidean distance (in pixels²) to the nearest `true` pixel of
/// `mask`, or [`FAR`] if the mask is empty. Finite values are exact integers.
///
/// Separable: an exact 1D distance along each column (two linear sweeps, binary input), then the
/// lower envelope of parabolas along each row. O(width · height).
pub(crate) fn squared_edt(mask: &Grid<bool>) -> Grid<f64> {
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
    let g: Vec<f64> = vd.iter().map(|&d| if d >= big { FAR } else { f64::from(d) * f64::from(d) }).collect();
    // Pass 2: per row, lower envelope of the parabolas (q − i)² + g(q).
    let mut out = vec![FAR; w * h];
    let mut v = vec![0usize; w];
    let mut z = vec![0.0f64; w + 1];
    for y in 0..h {
        let f = &g[y * w..(y + 1) * w];
        let o = &mut out[y * w..(y + 1) * w];
        // Only feature-reachable columns (finite g) take part; if none, the row stays FAR.
        let mut k: usize = 0;
        let mut started = false;
        for q in 0..w {
            if f[q] >= FAR {
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
pub(crate) fn reach(t: f64) -> Vec<usize> {
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

/// For every pixel, whether some `true` pixel of `mask` is within Euclidean distance `t`
/// (`0 ≤ t < 65535`, as row distances are kept in `u16`): the same as `squared_edt(mask) ≤ t²`, in O(pixels · t) cheap vectorisable
/// steps. Per row, the horizontal distance to the nearest mask pixel (capped at ⌊t⌋ + 1) by two
/// sweeps; then a pixel is near if a row `dy` away has that distance ≤ `reach[dy]`.
pub(crate) fn near(mask: &Grid<bool>, t: f64) -> Vec<bool> {
    assert!(t.is_finite() && (0.0..65535.0).contains(&t), "edt::near: distance {t} out of range");
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
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{RngExt, SeedableRng};

    fn brute(mask: &Grid<bool>) -> Grid<f64> {
        let pts: Vec<(i64, i64)> =
            mask.enumerate().filter(|&(_, _, &b)| b).map(|(x, y, _)| (x as i64, y as i64)).collect();
        Grid::from_fn(mask.width(), mask.height(), |x, y| {
            pts.iter()
                .map(|&(px, py)| ((px - x as i64).pow(2) + (py - y as i64).pow(2)) as f64)
                .fold(FAR, f64::min)
        })
    }

    #[test]
    fn matches_brute_force_on_random_masks() {
        let mut rng = rand::rngs::Xoshiro256PlusPlus::seed_from_u64(7);
        for case in 0..60u32 {
            let w = 1 + rng.random_range(0..40u32);
            let h = 1 + rng.random_range(0..40u32);
            let p = [0.0, 0.002, 0.02, 0.2, 0.9][(case % 5) as usize];
            let mask = Grid::from_fn(w, h, |_, _| rng.random_bool(p));
            assert_eq!(squared_edt(&mask), brute(&mask), "case {case} ({w}×{h}, p = {p})");
        }
    }

    #[test]
    fn near_matches_thresholded_edt() {
        let mut rng = rand::rngs::Xoshiro256PlusPlus::seed_from_u64(8);
        for case in 0..40u32 {
            let w = 1 + rng.random_range(0..90u32);
            let h = 1 + rng.random_range(0..40u32);
            let p = [0.0, 0.002, 0.02, 0.2, 0.9][(case % 5) as usize];
            let mask = Grid::from_fn(w, h, |_, _| rng.random_bool(p));
            let d = squared_edt(&mask);
            for t in [0.0, 1.0, 1.5, 2.0, 2.9, 5.0, 64.0] {
                let want: Vec<bool> = d.as_slice().iter().map(|&v| v <= t * t).collect();
                assert_eq!(near(&mask, t), want, "case {case} ({w}×{h}, p = {p}, t = {t})");
            }
        }
        for t in [0.0, 0.5, 1.0, 2.5, 7.3, 64.0] {
            for (dy, &dx) in reach(t).iter().enumerate() {
                assert!((dx * dx + dy * dy) as f64 <= t * t, "t {t}, dy {dy}");
                assert!((((dx + 1) * (dx + 1) + dy * dy) as f64) > t * t, "t {t}, dy {dy}");
            }
        }
    }

    #[test]
    fn single_point_distances() {
        let mut mask = Grid::new(5, 4, false);
        mask[(1, 2)] = true;
        let d = squared_edt(&mask);
        assert_eq!(d[(1, 2)], 0.0);
        assert_eq!(d[(4, 0)], 13.0);
        assert_eq!(d[(0, 3)], 2.0);
    }
}
