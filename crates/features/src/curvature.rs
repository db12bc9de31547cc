//! Curvatures from the quadratic-fit derivatives, and the windowed standard deviation of K.

use rangeimage::Grid;

/// Per-pixel curvatures: `(K, H, [k1, k2], curvedness)`.
pub(crate) struct Curvatures {
    pub(crate) k: Grid<f32>,
    pub(crate) h: Grid<f32>,
    pub(crate) principal: Grid<[f32; 2]>,
    pub(crate) curvedness: Grid<f32>,
}

/// K, H, principal curvatures and curvedness of the graph surface from its derivatives (NaN propagates).
pub(crate) fn curvatures(grad: &Grid<[f32; 2]>, hess: &Grid<[f32; 3]>) -> Curvatures {
    let (w, h) = grad.dimensions();
    let n = grad.len();
    let (mut kv, mut hv, mut pv, mut cv) =
        (Vec::with_capacity(n), Vec::with_capacity(n), Vec::with_capacity(n), Vec::with_capacity(n));
    for (g, s) in grad.as_slice().iter().zip(hess.as_slice()) {
        let (ix, iy) = (f64::from(g[0]), f64::from(g[1]));
        let (ixx, ixy, iyy) = (f64::from(s[0]), f64::from(s[1]), f64::from(s[2]));
        let q = 1.0 + ix * ix + iy * iy;
        let k = (ixx * iyy - ixy * ixy) / (q * q);
        let hm = ((1.0 + iy * iy) * ixx - 2.0 * ix * iy * ixy + (1.0 + ix * ix) * iyy) / (2.0 * q * q.sqrt());
        let disc = (hm * hm - k).max(0.0).sqrt();
        let (k1, k2) = (hm + disc, hm - disc);
        kv.push(k as f32);
        hv.push(hm as f32);
        pv.push([k1 as f32, k2 as f32]);
        cv.push(((k1 * k1 + k2 * k2) / 2.0).sqrt() as f32);
    }
    Curvatures {
        k: Grid::from_vec(w, h, kv).expect("size matches"),
        h: Grid::from_vec(w, h, hv).expect("size matches"),
        principal: Grid::from_vec(w, h, pv).expect("size matches"),
        curvedness: Grid::from_vec(w, h, cv).expect("size matches"),
    }
}

/// Standard deviation of the finite values of `k` over the `window_px × window_px` window of each pixel
/// (clipped at the border); NaN where `k` itself is NaN. Running box sums, O(1) per pixel.
pub(crate) fn window_std(k: &Grid<f32>, window_px: u32) -> Grid<f32> {
    let (w, h) = k.dimensions();
    let (wu, hu) = (w as usize, h as usize);
    let r = (window_px / 2) as usize;
    // Row pass: [count, Σk, Σk²] over x - r ..= x + r via prefix sums.
    let mut rows = vec![[0.0f64; 3]; wu * hu];
    let mut prefix = vec![[0.0f64; 3]; wu + 1];
    for y in 0..hu {
        let src = &k.as_slice()[y * wu..(y + 1) * wu];
        let mut p = [0.0f64; 3];
        for (x, &v) in src.iter().enumerate() {
            if v.is_finite() {
                let v = f64::from(v);
                p = [p[0] + 1.0, p[1] + v, p[2] + v * v];
            }
            prefix[x + 1] = p;
        }
        for x in 0..wu {
            let lo = prefix[x.saturating_sub(r)];
            let hi = prefix[(x + r + 1).min(wu)];
            rows[y * wu + x] = [hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]];
        }
    }
    // Column pass: running sums down each column.
    let mut out = vec![f32::NAN; wu * hu];
    let mut acc = vec![[0.0f64; 3]; wu];
    for y in 0..r.min(hu) {
        for (a, s) in acc.iter_mut().zip(&rows[y * wu..(y + 1) * wu]) {
            *a = [a[0] + s[0], a[1] + s[1], a[2] + s[2]];
        }
    }
    for y in 0..hu {
        if y + r < hu {
            let yy = y + r;
            for (a, s) in acc.iter_mut().zip(&rows[yy * wu..(yy + 1) * wu]) {
                *a = [a[0] + s[0], a[1] + s[1], a[2] + s[2]];
            }
        }
        if y > r {
            let yy = y - r - 1;
            for (a, s) in acc.iter_mut().zip(&rows[yy * wu..(yy + 1) * wu]) {
                *a = [a[0] - s[0], a[1] - s[1], a[2] - s[2]];
            }
        }
        for x in 0..wu {
            if !k.as_slice()[y * wu + x].is_finite() {
                continue;
            }
            let [n, s1, s2] = acc[x];
            let n = n.round();
            let mean = s1 / n;
            out[y * wu + x] = (s2 / n - mean * mean).max(0.0).sqrt() as f32;
        }
    }
    Grid::from_vec(w, h, out).expect("size matches")
}
