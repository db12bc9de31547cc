//! Valid-normalised Gaussian smoothing, Sobel per channel, the Di Zenzo structure tensor and non-maximum
//! suppression, streamed over the rows of the image.
//!
//! The rows flow through small ring buffers (a few rows per stage, cache-resident) instead of full-image
//! temporaries: horizontal smoothing of row `t + r`, vertical smoothing of row `t`, Sobel + tensor + eigenvector
//! of row `t − 1`, non-maximum suppression of row `t − 2`. The inner loops run over whole rows of equal-length
//! slices without per-pixel branches (selects only), so the compiler vectorises them. Sobel splits each row into
//! runs whose 3×3 neighbourhoods are all valid (values used as they are) and the rest (each missing neighbour
//! replaced by the centre); the first and last column use explicit bounds checks. Rows without no-data share one
//! smoothed mask and, away from the top and bottom, one normaliser.
//!
//! Every pixel's arithmetic is the same sequence of `f32` operations as the straightforward per-pixel
//! formulation kept as the test oracle in `reference.rs`, so magnitudes and edges are bit-identical to it. The one
//! change from the detector before this streamed form: the eigenvector handed to non-maximum suppression is no
//! longer normalised (it only uses the ratio and signs of its components), which can move an edge only where the
//! rounding of that ratio flips a near-tie.

use rangeimage::Grid;

/// The channels of [`crate::detect`] or [`crate::detect_planes`], read row by row without copying the image.
pub(crate) enum Input<'a> {
    /// One grid per channel.
    Stack(&'a [&'a Grid<f32>]),
    /// The three plane parameters of each pixel as channels.
    Planes(&'a [[f32; 3]]),
}

impl Input<'_> {
    /// Number of channels.
    pub(crate) fn len(&self) -> usize {
        match self {
            Input::Stack(c) => c.len(),
            Input::Planes(_) => 3,
        }
    }

    /// Loads row `y`: `ok[x]` = `valid` (true if `None`) and every channel finite; `pads` holds one row of
    /// `w + 2r` per channel, whose middle `r..r + w` gets the channel's values, 0 where not ok.
    #[inline(always)] // into `gradient`, compiled for each instruction set
    fn load_row(&self, y: usize, valid: Option<&[bool]>, ok: &mut [bool], pads: &mut [f32], r: usize) {
        let w = ok.len();
        let pw = w + 2 * r;
        match valid {
            Some(v) => ok.copy_from_slice(&v[y * w..(y + 1) * w]),
            None => ok.fill(true),
        }
        match self {
            Input::Stack(channels) => {
                for ch in channels.iter() {
                    for (o, v) in ok.iter_mut().zip(&ch.as_slice()[y * w..(y + 1) * w]) {
                        *o &= v.is_finite();
                    }
                }
                for (c, ch) in channels.iter().enumerate() {
                    let dst = &mut pads[c * pw + r..c * pw + r + w];
                    for ((d, &v), &o) in dst.iter_mut().zip(&ch.as_slice()[y * w..(y + 1) * w]).zip(&*ok) {
                        *d = if o { v } else { 0.0 };
                    }
                }
            }
            Input::Planes(p) => {
                let (p0, rest) = pads.split_at_mut(pw);
                let (p1, p2) = rest.split_at_mut(pw);
                let (d0, d1, d2) = (&mut p0[r..r + w], &mut p1[r..r + w], &mut p2[r..r + w]);
                let src = &p[y * w..(y + 1) * w];
                for x in 0..w {
                    let v = src[x];
                    let o = ok[x] & v[0].is_finite() & v[1].is_finite() & v[2].is_finite();
                    ok[x] = o;
                    d0[x] = if o { v[0] } else { 0.0 };
                    d1[x] = if o { v[1] } else { 0.0 };
                    d2[x] = if o { v[2] } else { 0.0 };
                }
            }
        }
    }
}

/// The normalised 1D Gaussian of `kernel_px` taps.
pub(crate) fn gaussian(sigma_px: f32, kernel_px: u32) -> Vec<f32> {
    let r = (kernel_px / 2) as i32;
    let g: Vec<f32> = (-r..=r).map(|i| (-(i * i) as f32 / (2.0 * sigma_px * sigma_px)).exp()).collect();
    let s: f32 = g.iter().sum();
    g.into_iter().map(|v| v / s).collect()
}

/// Magnitude and non-maximum-suppression candidates of the whole image.
#[derive(Debug, Clone, Default)]
pub(crate) struct Gradient {
    /// The pixels that take part: valid and every channel finite.
    pub(crate) ok: Vec<bool>,
    /// `sqrt(λmax)` of the weighted structure tensor; 0 where `ok` is false.
    pub(crate) magnitude: Vec<f32>,
    /// 1 at the pixels whose magnitude is a maximum along the gradient direction (see [`nms_row`]), else 0.
    pub(crate) candidates: Vec<u8>,
}

/// `out[x] = Σ_k g[k] · rows[k][x]`, accumulated from 0 in tap order (one pass for the common 3 and 5 taps).
fn weighted_sum(rows: &[&[f32]], g: &[f32], out: &mut [f32]) {
    // Called from a closure of `gradient` that is not inlined: dispatched on its own.
    isa::dispatch(
        #[inline(always)]
        || weighted_sum_kernel(rows, g, out),
    );
}

/// [`weighted_sum`]'s body, compiled for each instruction set ([`isa::dispatch`]).
#[inline(always)]
fn weighted_sum_kernel(rows: &[&[f32]], g: &[f32], out: &mut [f32]) {
    let w = out.len();
    match (rows, g) {
        ([r0, r1, r2, r3, r4], &[g0, g1, g2, g3, g4]) => {
            let (r0, r1, r2, r3, r4) = (&r0[..w], &r1[..w], &r2[..w], &r3[..w], &r4[..w]);
            for x in 0..w {
                out[x] = 0.0 + g0 * r0[x] + g1 * r1[x] + g2 * r2[x] + g3 * r3[x] + g4 * r4[x];
            }
        }
        ([r0, r1, r2], &[g0, g1, g2]) => {
            let (r0, r1, r2) = (&r0[..w], &r1[..w], &r2[..w]);
            for x in 0..w {
                out[x] = 0.0 + g0 * r0[x] + g1 * r1[x] + g2 * r2[x];
            }
        }
        _ => {
            out.fill(0.0);
            for (r, &gk) in rows.iter().zip(g) {
                for (d, &p) in out.iter_mut().zip(&r[..w]) {
                    *d += gk * p;
                }
            }
        }
    }
}

/// Horizontal correlation of `pad[r..r + w]` (zeros on both sides) with `g` into `dst`, accumulating from 0 in
/// tap order.
#[inline(always)] // into `gradient`, compiled for each instruction set
fn horizontal(pad: &[f32], g: &[f32], dst: &mut [f32]) {
    let w = dst.len();
    let mut rows = [&pad[..0]; crate::MAX_KERNEL_PX];
    for (k, row) in rows.iter_mut().enumerate().take(g.len()) {
        *row = &pad[k..k + w];
    }
    weighted_sum(&rows[..g.len()], g, dst);
}

/// Smooths each weighted channel over the `ok` pixels (Gaussian normalised by the smoothed mask), takes Sobel
/// derivatives, combines them with the Di Zenzo tensor into magnitude and direction, and suppresses
/// non-maxima. Channels of weight 0 are skipped. The magnitudes of the ok pixels are counted into `hist`.
/// The result reuses the memory of `bufs`.
#[allow(clippy::too_many_arguments)]
#[inline(always)] // into `isa::dispatch` in `run`: compiled for each instruction set
pub(crate) fn gradient(
    input: &Input<'_>,
    weights: &[f32],
    valid: Option<&[bool]>,
    w: usize,
    h: usize,
    g: &[f32],
    mut hist: Option<&mut crate::canny::Histogram>,
    bufs: Gradient,
) -> Gradient {
    let n = w * h;
    let Gradient { mut ok, mut magnitude, mut candidates } = bufs;
    ok.clear();
    ok.resize(n, false);
    magnitude.clear();
    magnitude.resize(n, 0.0);
    candidates.clear();
    candidates.resize(n, 0);
    if n == 0 {
        return Gradient { ok, magnitude, candidates };
    }
    let r = g.len() / 2;
    let ring = g.len();
    let active: Vec<(usize, f32)> =
        weights.iter().copied().enumerate().filter(|&(_, wt)| wt != 0.0).collect();
    let na = active.len();

    // Horizontal ring: slot 0 = the mask, 1.. = the active channels; `ring` rows each.
    let mut hbuf = vec![0.0f32; (1 + na) * ring * w];
    // Padded input rows (zeros on both sides): the mask, then every channel.
    let pw = w + 2 * r;
    let mut pad = vec![0.0f32; pw];
    let mut pads = vec![0.0f32; input.len() * pw];
    // Smoothed channels, 3 rows each (rows t − 2, t − 1, t).
    let mut sbuf = vec![0.0f32; na * 3 * w];
    let mut inv = vec![0.0f32; w];
    let mut vrow = vec![0.0f32; w];
    let none = vec![false; w];
    let (mut col, mut full, mut runs) = (Vec::with_capacity(w), Vec::with_capacity(w), Vec::new());
    // Tensor of one row.
    let (mut jxx, mut jxy, mut jyy) = (vec![0.0f32; w], vec![0.0f32; w], vec![0.0f32; w]);
    // Magnitudes padded with a zero column on each side, 3 rows; a zero row for outside the image.
    let mut mbuf = vec![0.0f32; 3 * (w + 2)];
    let zero = vec![0.0f32; w + 2];
    // Directions, 2 rows.
    let (mut dxs, mut dys) = (vec![0.0f32; 2 * w], vec![0.0f32; 2 * w]);

    let rows = |y: usize| y * w..(y + 1) * w;
    // The smoothed mask of a row without no-data, the normaliser of a band of such rows, and the last row
    // loaded that has no-data.
    let (mut full_h, mut full_inv): (Option<Vec<f32>>, Option<Vec<f32>>) = (None, None);
    let mut last_partial: Option<usize> = None;
    let mut next_h = 0;
    for t in 0..h + 2 {
        if t < h {
            // Horizontal smoothing of every row the vertical pass of row t needs.
            while next_h < h && next_h <= t + r {
                let y = next_h;
                let slot = y % ring;
                input.load_row(y, valid, &mut ok[rows(y)], &mut pads, r);
                let mask_h = &mut hbuf[slot * w..(slot + 1) * w];
                if ok[rows(y)].iter().fold(true, |a, &o| a & o) {
                    // Every row without no-data smooths its mask to the same row: computed once.
                    match &full_h {
                        Some(fh) => mask_h.copy_from_slice(fh),
                        None => {
                            pad[r..r + w].fill(1.0);
                            horizontal(&pad, g, mask_h);
                            full_h = Some(mask_h.to_vec());
                        }
                    }
                } else {
                    last_partial = Some(y);
                    for (p, &o) in pad[r..r + w].iter_mut().zip(&ok[rows(y)]) {
                        *p = if o { 1.0 } else { 0.0 };
                    }
                    horizontal(&pad, g, mask_h);
                }
                for (a, &(c, _)) in active.iter().enumerate() {
                    let base = ((1 + a) * ring + slot) * w;
                    horizontal(&pads[c * pw..(c + 1) * pw], g, &mut hbuf[base..base + w]);
                }
                next_h += 1;
            }
            // Vertical smoothing of row t: the mask gives the normaliser, then each channel.
            // Rows outside the image contribute nothing (zero padding): their taps are skipped.
            let k0 = r.saturating_sub(t);
            let k1 = g.len().min(h + r - t);
            let vertical = |plane: usize, out: &mut [f32]| {
                let mut rows = [&hbuf[..0]; crate::MAX_KERNEL_PX];
                for k in k0..k1 {
                    let base = (plane * ring + (t + k - r) % ring) * w;
                    rows[k - k0] = &hbuf[base..base + w];
                }
                weighted_sum(&rows[..k1 - k0], &g[k0..k1], out);
            };
            // Away from the top and bottom, a band of rows without no-data has the same normaliser every time.
            let full_band = t >= r && t + r < h && last_partial.is_none_or(|b| b + r < t);
            match (&full_inv, full_band) {
                (Some(fi), true) => inv.copy_from_slice(fi),
                _ => {
                    vertical(0, &mut vrow);
                    for ((iv, &s), &o) in inv.iter_mut().zip(&vrow).zip(&ok[rows(t)]) {
                        *iv = if o && s > 0.0 { 1.0 / s } else { 0.0 };
                    }
                    if full_band {
                        full_inv = Some(inv.clone());
                    }
                }
            }
            for a in 0..na {
                let base = (a * 3 + t % 3) * w;
                let out = &mut sbuf[base..base + w];
                vertical(1 + a, out);
                for (s, &iv) in out.iter_mut().zip(&inv) {
                    *s *= iv;
                }
            }
        }
        if (1..=h).contains(&t) {
            // Sobel, tensor and eigenvector of row y.
            let y = t - 1;
            jxx.fill(0.0);
            jxy.fill(0.0);
            jyy.fill(0.0);
            for (a, &(_, wt)) in active.iter().enumerate() {
                let row = |yy: usize| &sbuf[(a * 3 + yy % 3) * w..(a * 3 + yy % 3 + 1) * w];
                let (sc, oc) = (row(y), &ok[rows(y)]);
                // Outside the image: any row with no valid pixel (every neighbour there takes the centre value).
                let (su, ou) = if y > 0 { (row(y - 1), &ok[rows(y - 1)]) } else { (sc, &none[..]) };
                let (sd, od) = if y + 1 < h { (row(y + 1), &ok[rows(y + 1)]) } else { (sc, &none[..]) };
                let rows = SobelRows { su, sc, sd, ou, oc, od };
                if a == 0 {
                    interior_runs(&rows, &mut col, &mut full, &mut runs);
                }
                sobel_row(&rows, &runs, wt, &mut jxx, &mut jxy, &mut jyy);
            }
            let slot = y % 3;
            let (mrow, drow) = (&mut mbuf[slot * (w + 2)..(slot + 1) * (w + 2)], (y % 2) * w);
            eigen_row(
                &jxx,
                &jxy,
                &jyy,
                &ok[rows(y)],
                &mut mrow[1..w + 1],
                &mut dxs[drow..drow + w],
                &mut dys[drow..drow + w],
            );
            magnitude[y * w..(y + 1) * w].copy_from_slice(&mrow[1..w + 1]);
            if let Some(hs) = hist.as_deref_mut() {
                hs.add_row(&mrow[1..w + 1], &ok[rows(y)]);
            }
        }
        if t >= 2 {
            // Non-maximum suppression of row y.
            let y = t - 2;
            let mrow = |yy: usize| &mbuf[(yy % 3) * (w + 2)..(yy % 3 + 1) * (w + 2)];
            let up = if y > 0 { mrow(y - 1) } else { &zero[..] };
            let down = if y + 1 < h { mrow(y + 1) } else { &zero[..] };
            let drow = (y % 2) * w;
            nms_row(
                [up, mrow(y), down],
                &dxs[drow..drow + w],
                &dys[drow..drow + w],
                &mut candidates[y * w..(y + 1) * w],
            );
        }
    }
    Gradient { ok, magnitude, candidates }
}

/// The smoothed values and `ok` flags of three consecutive rows (up, centre, down), all of the row's length.
struct SobelRows<'a> {
    su: &'a [f32],
    sc: &'a [f32],
    sd: &'a [f32],
    ou: &'a [bool],
    oc: &'a [bool],
    od: &'a [bool],
}

/// The Sobel derivatives (scaled to per-pixel units) from the 3×3 neighbourhood `a b c / d · f / g h i`.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn sobel(a: f32, b: f32, c: f32, d: f32, f: f32, g: f32, h: f32, i: f32) -> (f32, f32) {
    let gx = (c + 2.0 * f + i) - (a + 2.0 * d + g);
    let gy = (g + 2.0 * h + i) - (a + 2.0 * b + c);
    (gx * 0.125, gy * 0.125)
}

/// Adds `wt · [gx², gx·gy, gy²]` of the Sobel derivatives of one row to the tensor row. A neighbour that is not
/// `ok` (or outside the image) takes the centre pixel's value, so missing data adds no gradient and real steps
/// between valid pixels are kept. Values at centres that are not `ok` are meaningless (masked later).
#[inline(always)] // into `gradient`, compiled for each instruction set
fn sobel_row(
    s: &SobelRows<'_>,
    runs: &[(usize, usize, bool)],
    wt: f32,
    jxx: &mut [f32],
    jxy: &mut [f32],
    jyy: &mut [f32],
) {
    let w = s.sc.len();
    let mut add = |x: usize, (gx, gy): (f32, f32)| {
        jxx[x] += wt * gx * gx;
        jxy[x] += wt * gx * gy;
        jyy[x] += wt * gy * gy;
    };
    // Border columns: explicit bounds.
    let border = |x: usize| {
        let c = s.sc[x];
        let at = |vals: &[f32], oks: &[bool], dx: isize| {
            let xx = x as isize + dx;
            if xx < 0 || xx >= w as isize {
                return c;
            }
            let xx = xx as usize;
            if oks[xx] { vals[xx] } else { c }
        };
        sobel(
            at(s.su, s.ou, -1),
            at(s.su, s.ou, 0),
            at(s.su, s.ou, 1),
            at(s.sc, s.oc, -1),
            at(s.sc, s.oc, 1),
            at(s.sd, s.od, -1),
            at(s.sd, s.od, 0),
            at(s.sd, s.od, 1),
        )
    };
    add(0, border(0));
    if w < 3 {
        if w == 2 {
            add(1, border(1));
        }
        return;
    }
    add(w - 1, border(w - 1));
    // Interior columns 1..w − 1, in runs: where the whole 3×3 neighbourhood is ok the values are used as they
    // are; elsewhere each neighbour is picked (selects only). Both give the same numbers where both apply.
    for &(x0, x1, full) in runs {
        let m = x1 - x0;
        let (u0, u1, u2) = (&s.su[x0 - 1..x1 - 1], &s.su[x0..x1], &s.su[x0 + 1..x1 + 1]);
        let (c0, c1, c2) = (&s.sc[x0 - 1..x1 - 1], &s.sc[x0..x1], &s.sc[x0 + 1..x1 + 1]);
        let (d0, d1, d2) = (&s.sd[x0 - 1..x1 - 1], &s.sd[x0..x1], &s.sd[x0 + 1..x1 + 1]);
        let (jxx, jxy, jyy) = (&mut jxx[x0..x1], &mut jxy[x0..x1], &mut jyy[x0..x1]);
        if full {
            for i in 0..m {
                let (gx, gy) = sobel(u0[i], u1[i], u2[i], c0[i], c2[i], d0[i], d1[i], d2[i]);
                jxx[i] += wt * gx * gx;
                jxy[i] += wt * gx * gy;
                jyy[i] += wt * gy * gy;
            }
            continue;
        }
        let (ou0, ou1, ou2) = (&s.ou[x0 - 1..x1 - 1], &s.ou[x0..x1], &s.ou[x0 + 1..x1 + 1]);
        let (oc0, oc2) = (&s.oc[x0 - 1..x1 - 1], &s.oc[x0 + 1..x1 + 1]);
        let (od0, od1, od2) = (&s.od[x0 - 1..x1 - 1], &s.od[x0..x1], &s.od[x0 + 1..x1 + 1]);
        for i in 0..m {
            let c = c1[i];
            let pick = |o: bool, v: f32| if o { v } else { c };
            let (gx, gy) = sobel(
                pick(ou0[i], u0[i]),
                pick(ou1[i], u1[i]),
                pick(ou2[i], u2[i]),
                pick(oc0[i], c0[i]),
                pick(oc2[i], c2[i]),
                pick(od0[i], d0[i]),
                pick(od1[i], d1[i]),
                pick(od2[i], d2[i]),
            );
            jxx[i] += wt * gx * gx;
            jxy[i] += wt * gx * gy;
            jyy[i] += wt * gy * gy;
        }
    }
}

/// Splits the interior columns `1..w − 1` of a row into runs `(x0, x1, full)`: `full` if every pixel of the 3×3
/// neighbourhood of every column in the run is ok. `col` and `full` are scratch.
#[inline(always)] // into `gradient`, compiled for each instruction set
fn interior_runs(
    s: &SobelRows<'_>,
    col: &mut Vec<u8>,
    full: &mut Vec<u8>,
    runs: &mut Vec<(usize, usize, bool)>,
) {
    let w = s.sc.len();
    runs.clear();
    if w < 3 {
        return;
    }
    col.clear();
    col.extend(s.ou.iter().zip(s.oc).zip(s.od).map(|((&a, &b), &c)| u8::from(a & b & c)));
    // full[i] is column i + 1.
    full.clear();
    full.extend(col.iter().zip(&col[1..]).zip(&col[2..]).map(|((&a, &b), &c)| a & b & c));
    let mut i0 = 0;
    while i0 < full.len() {
        let f = full[i0];
        let pattern = if f == 1 { u64::from_le_bytes([1; 8]) } else { 0 };
        let mut i1 = i0 + 1;
        while i1 + 8 <= full.len()
            && u64::from_le_bytes(full[i1..i1 + 8].try_into().expect("8 bytes")) == pattern
        {
            i1 += 8;
        }
        while i1 < full.len() && full[i1] == f {
            i1 += 1;
        }
        runs.push((i0 + 1, i1 + 1, f == 1));
        i0 = i1;
    }
}

/// Magnitude `sqrt(λmax)` (0 where not `ok`) and an eigenvector of `λmax` (not normalised), canonically
/// oriented (`dx > 0`, or `dx = 0` and `dy ≥ 0`; `(1, 0)` where undefined), of one row of the tensor.
#[allow(clippy::too_many_arguments)]
#[inline(always)] // into `gradient`, compiled for each instruction set
fn eigen_row(
    jxx: &[f32],
    jxy: &[f32],
    jyy: &[f32],
    ok: &[bool],
    mag: &mut [f32],
    dxs: &mut [f32],
    dys: &mut [f32],
) {
    let w = mag.len();
    let (jxx, jxy, jyy, ok, dxs, dys) =
        (&jxx[..w], &jxy[..w], &jyy[..w], &ok[..w], &mut dxs[..w], &mut dys[..w]);
    for i in 0..w {
        let (p, q, s) = (jxx[i], jxy[i], jyy[i]);
        let half = 0.5 * (p - s);
        let root = (half * half + q * q).sqrt();
        // p, s ≥ +0 and root ≥ 0, so λ is never −0: this is `max(0)` (NaN → 0).
        let l = 0.5 * (p + s) + root;
        let lmax = if l > 0.0 { l } else { 0.0 };
        // Eigenvector of λmax: (q, λ − p) or (λ − s, q), whichever is better conditioned.
        let (v1x, v1y, v2x) = (q, lmax - p, lmax - s);
        let (n1, n2) = (v1x * v1x + v1y * v1y, v2x * v2x + q * q);
        let first = n1 >= n2;
        let (vx, vy, nn) = if first { (v1x, v1y, n1) } else { (v2x, q, n2) };
        // Left unnormalised: non-maximum suppression only uses the ratio and signs of its components.
        let def = nn > 0.0 && nn.is_finite();
        let flip = vx < 0.0 || (vx == 0.0 && vy < 0.0);
        let (dx, dy) = if flip { (-vx, -vy) } else { (vx, vy) };
        let o = ok[i];
        mag[i] = if o { lmax.sqrt() } else { 0.0 };
        dxs[i] = if o & def { dx } else { 1.0 };
        dys[i] = if o & def { dy } else { 0.0 };
    }
}

/// Non-maximum suppression of one row: keeps the pixels whose magnitude is positive and a maximum along the
/// direction `(dx, dy)` (any length), interpolating the two neighbours on the 3×3 ring linearly (the ring
/// sampled at ±d scaled so that `max(|dx|, |dy|) = 1`). Ties keep the pixel on the negative side of the
/// direction, so a symmetric two-pixel ridge gives a one-pixel edge. `keep` gets 1 or 0. `m = [up, centre,
/// down]` are magnitude rows padded with one column on each side (0 outside the image and at no-data pixels);
/// `dx`, `dy` and `keep` have the row's length.
#[inline(always)] // into `gradient`, compiled for each instruction set
pub(crate) fn nms_row(m: [&[f32]; 3], dx: &[f32], dy: &[f32], keep: &mut [u8]) {
    let w = keep.len();
    let (dx, dy) = (&dx[..w], &dy[..w]);
    let (ul, u, ur) = (&m[0][..w], &m[0][1..w + 1], &m[0][2..w + 2]);
    let (l, c, r) = (&m[1][..w], &m[1][1..w + 1], &m[1][2..w + 2]);
    let (dl, d, dr) = (&m[2][..w], &m[2][1..w + 1], &m[2][2..w + 2]);
    for i in 0..w {
        let (ex, ey) = (dx[i], dy[i]);
        let xdom = ex.abs() >= ey.abs();
        // Main axis: x if |dx| ≥ |dy|; `pos`: the forward sample is on its positive side. `side_f`, `side_b`:
        // the forward / backward sample leans to the positive side of the other axis (t = ±q ≥ 0).
        let (num, den) = if xdom { (ey, ex.abs()) } else { (ex, ey.abs()) };
        let q = num / den;
        let f = q.abs();
        let pos = if xdom { ex >= 0.0 } else { ey >= 0.0 };
        let (side_f, side_b) = (q >= 0.0, -q >= 0.0);
        // Every neighbour is loaded, then picked by selects (no conditional loads, so the loop vectorises).
        let (nul, nu, nur, nl, nr, ndl, nd, ndr) = (ul[i], u[i], ur[i], l[i], r[i], dl[i], d[i], dr[i]);
        // The main neighbours on the positive / negative side of the main axis.
        let (pa, na) = if xdom { (nr, nl) } else { (nd, nu) };
        let (fa, ba) = if pos { (pa, na) } else { (na, pa) };
        // The interpolation partner: the corner on the main side (positive: right column if x-dominant, bottom row
        // if y-dominant) and the lean side (positive: down if x-dominant, right if y-dominant). The corners
        // (+, +) = down-right and (−, −) = up-left are the same for both axes; the mixed ones swap.
        let (pn, np) = if xdom { (nur, ndl) } else { (ndl, nur) };
        let fb = if pos {
            if side_f { ndr } else { pn }
        } else if side_f {
            np
        } else {
            nul
        };
        // Backward: the main side is the opposite one.
        let bb = if pos {
            if side_b { np } else { nul }
        } else if side_b {
            ndr
        } else {
            pn
        };
        let fwd = (1.0 - f) * fa + f * fb;
        let bwd = (1.0 - f) * ba + f * bb;
        let v = c[i];
        keep[i] = u8::from((v > 0.0) & (v >= fwd) & (v > bwd));
    }
}
