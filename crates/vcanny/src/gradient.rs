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
#[inline(always)] // into `gradient`, compiled for each instruction set
fn weighted_sum(rows: &[&[f32]], g: &[f32], out: &mut [f32]) {
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
///
/// Step `t` of the pipeline smooths row `t` (horizontally first every row up to `t + r` it needs), then takes
/// the tensor of row `t − 1` and suppresses the non-maxima of row `t − 2`.
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
    // Every row of the three is written below, so stale values of a reused buffer need no clearing.
    ok.resize(n, false);
    magnitude.resize(n, 0.0);
    candidates.resize(n, 0);
    if n == 0 {
        return Gradient { ok, magnitude, candidates };
    }
    let rows = |y: usize| y * w..(y + 1) * w;
    let mut smooth = Smoother::new(input, weights, valid, w, h, g);
    let mut tensor = Tensor::new(w);
    for t in 0..h + 2 {
        if t < h {
            smooth.horizontal_to(t, &mut ok);
            smooth.vertical(t, &ok[rows(t)]);
        }
        if (1..=h).contains(&t) {
            let y = t - 1;
            let mrow = tensor.row(&smooth, y, &ok);
            magnitude[rows(y)].copy_from_slice(mrow);
            if let Some(hs) = hist.as_deref_mut() {
                hs.add_row(mrow, &ok[rows(y)]);
            }
        }
        if t >= 2 {
            tensor.suppress(t - 2, h, &mut candidates[rows(t - 2)]);
        }
    }
    Gradient { ok, magnitude, candidates }
}

/// The smoothing stages of [`gradient`]: the horizontal pass into a ring of `g.len()` rows, the vertical pass
/// and normalisation into a ring of the 3 rows Sobel needs.
struct Smoother<'a> {
    input: &'a Input<'a>,
    valid: Option<&'a [bool]>,
    w: usize,
    h: usize,
    g: &'a [f32],
    /// `(channel, weight)` of the channels of weight ≠ 0.
    active: Vec<(usize, f32)>,
    /// Horizontal ring: slot 0 = the mask, 1.. = the active channels; `g.len()` rows each.
    hbuf: Vec<f32>,
    /// The padded mask row (zeros on both sides) and the padded rows of every channel.
    pad: Vec<f32>,
    pads: Vec<f32>,
    /// Smoothed active channels, 3 rows each (row `y` in slot `y % 3`).
    sbuf: Vec<f32>,
    /// The normaliser of the current row and the vertically smoothed mask it comes from.
    inv: Vec<f32>,
    vrow: Vec<f32>,
    /// The smoothed mask of a row without no-data (all such rows have the same).
    full_h: Option<Vec<f32>>,
    /// The normaliser of a row in a band of rows without no-data, away from the top and bottom.
    full_inv: Option<Vec<f32>>,
    /// The last row loaded that has no-data.
    last_partial: Option<usize>,
    /// The next row to smooth horizontally.
    next_h: usize,
}

impl<'a> Smoother<'a> {
    /// Empty rings for an image of `w × h` pixels.
    #[inline(always)]
    fn new(
        input: &'a Input<'a>,
        weights: &[f32],
        valid: Option<&'a [bool]>,
        w: usize,
        h: usize,
        g: &'a [f32],
    ) -> Self {
        let active: Vec<(usize, f32)> =
            weights.iter().copied().enumerate().filter(|&(_, wt)| wt != 0.0).collect();
        let (na, pw) = (active.len(), w + g.len() - 1);
        Self {
            input,
            valid,
            w,
            h,
            g,
            hbuf: vec![0.0; (1 + na) * g.len() * w],
            pad: vec![0.0; pw],
            pads: vec![0.0; input.len() * pw],
            sbuf: vec![0.0; na * 3 * w],
            inv: vec![0.0; w],
            vrow: vec![0.0; w],
            active,
            full_h: None,
            full_inv: None,
            last_partial: None,
            next_h: 0,
        }
    }

    /// Loads and smooths horizontally every row up to `t + r` not done yet (the rows the vertical pass of row
    /// `t` needs), setting their `ok` flags.
    #[inline(always)]
    fn horizontal_to(&mut self, t: usize, ok: &mut [bool]) {
        let (w, g) = (self.w, self.g);
        let (r, ring) = (g.len() / 2, g.len());
        let pw = w + 2 * r;
        while self.next_h < self.h && self.next_h <= t + r {
            let y = self.next_h;
            let slot = y % ring;
            let ok = &mut ok[y * w..(y + 1) * w];
            self.input.load_row(y, self.valid, ok, &mut self.pads, r);
            let mask_h = &mut self.hbuf[slot * w..(slot + 1) * w];
            if ok.iter().fold(true, |a, &o| a & o) {
                // Every row without no-data smooths its mask to the same row: computed once.
                match &self.full_h {
                    Some(fh) => mask_h.copy_from_slice(fh),
                    None => {
                        self.pad[r..r + w].fill(1.0);
                        horizontal(&self.pad, g, mask_h);
                        self.full_h = Some(mask_h.to_vec());
                    }
                }
            } else {
                self.last_partial = Some(y);
                for (p, &o) in self.pad[r..r + w].iter_mut().zip(&*ok) {
                    *p = if o { 1.0 } else { 0.0 };
                }
                horizontal(&self.pad, g, mask_h);
            }
            for (a, &(c, _)) in self.active.iter().enumerate() {
                let base = ((1 + a) * ring + slot) * w;
                horizontal(&self.pads[c * pw..(c + 1) * pw], g, &mut self.hbuf[base..base + w]);
            }
            self.next_h += 1;
        }
    }

    /// Smooths row `t` vertically: the mask gives the normaliser (0 where not `ok`), then each active channel,
    /// normalised, into its slot of the 3-row ring.
    #[inline(always)]
    fn vertical(&mut self, t: usize, ok: &[bool]) {
        let (w, h, r) = (self.w, self.h, self.g.len() / 2);
        // Away from the top and bottom, a band of rows without no-data has the same normaliser every time.
        let full_band = t >= r && t + r < h && self.last_partial.is_none_or(|b| b + r < t);
        match (&self.full_inv, full_band) {
            (Some(fi), true) => self.inv.copy_from_slice(fi),
            _ => {
                self.vertical_sum(0, t, Out::Mask);
                for ((iv, &s), &o) in self.inv.iter_mut().zip(&self.vrow).zip(ok) {
                    *iv = if o && s > 0.0 { 1.0 / s } else { 0.0 };
                }
                if full_band {
                    self.full_inv = Some(self.inv.clone());
                }
            }
        }
        for a in 0..self.active.len() {
            self.vertical_sum(1 + a, t, Out::Channel(a));
            let base = (a * 3 + t % 3) * w;
            for (s, &iv) in self.sbuf[base..base + w].iter_mut().zip(&self.inv) {
                *s *= iv;
            }
        }
    }

    /// The vertical Gaussian of ring `plane` (0 = the mask) at row `t` into `out`. Rows outside the image
    /// contribute nothing (zero padding): their taps are skipped.
    #[inline(always)]
    fn vertical_sum(&mut self, plane: usize, t: usize, out: Out) {
        let (w, h, g) = (self.w, self.h, self.g);
        let (r, ring) = (g.len() / 2, g.len());
        let (k0, k1) = (r.saturating_sub(t), g.len().min(h + r - t));
        let mut rows = [&self.hbuf[..0]; crate::MAX_KERNEL_PX];
        for k in k0..k1 {
            let base = (plane * ring + (t + k - r) % ring) * w;
            rows[k - k0] = &self.hbuf[base..base + w];
        }
        let out = match out {
            Out::Mask => &mut self.vrow[..],
            Out::Channel(a) => &mut self.sbuf[(a * 3 + t % 3) * w..(a * 3 + t % 3 + 1) * w],
        };
        weighted_sum(&rows[..k1 - k0], &g[k0..k1], out);
    }

    /// Row `y` of active channel `a`, smoothed (one of the last 3 rows done).
    #[inline(always)]
    fn smoothed(&self, a: usize, y: usize) -> &[f32] {
        let base = (a * 3 + y % 3) * self.w;
        &self.sbuf[base..base + self.w]
    }
}

/// Where [`Smoother::vertical_sum`] writes: the smoothed mask row or active channel `a`'s row.
#[derive(Clone, Copy)]
enum Out {
    Mask,
    Channel(usize),
}

/// The tensor stage of [`gradient`]: Sobel, the Di Zenzo tensor and its eigenvector of one row, and the
/// rings of magnitudes (3 rows) and directions (2 rows) that non-maximum suppression reads.
struct Tensor {
    w: usize,
    /// A row of `ok` flags all false (the row outside the image).
    none: Vec<bool>,
    /// Scratch of [`interior_runs`] and the runs of the current row.
    col: Vec<u8>,
    full: Vec<u8>,
    runs: Vec<(usize, usize, bool)>,
    /// The tensor of one row.
    jxx: Vec<f32>,
    jxy: Vec<f32>,
    jyy: Vec<f32>,
    /// Magnitudes padded with a zero column on each side, 3 rows; a zero row for outside the image.
    mbuf: Vec<f32>,
    zero: Vec<f32>,
    /// Directions, 2 rows.
    dxs: Vec<f32>,
    dys: Vec<f32>,
}

impl Tensor {
    /// Empty rings for rows of `w` pixels.
    #[inline(always)]
    fn new(w: usize) -> Self {
        Self {
            w,
            none: vec![false; w],
            col: Vec::with_capacity(w),
            full: Vec::with_capacity(w),
            runs: Vec::new(),
            jxx: vec![0.0; w],
            jxy: vec![0.0; w],
            jyy: vec![0.0; w],
            mbuf: vec![0.0; 3 * (w + 2)],
            zero: vec![0.0; w + 2],
            dxs: vec![0.0; 2 * w],
            dys: vec![0.0; 2 * w],
        }
    }

    /// Sobel, tensor and eigenvector of row `y` from the smoothed rows `y − 1 ..= y + 1` of `s`; returns the
    /// row's magnitudes. `ok` holds the flags of the whole image.
    #[inline(always)]
    fn row(&mut self, s: &Smoother<'_>, y: usize, ok: &[bool]) -> &[f32] {
        let (w, h) = (self.w, s.h);
        let rows = |y: usize| y * w..(y + 1) * w;
        self.jxx.fill(0.0);
        self.jxy.fill(0.0);
        self.jyy.fill(0.0);
        for (a, &(_, wt)) in s.active.iter().enumerate() {
            let (sc, oc) = (s.smoothed(a, y), &ok[rows(y)]);
            // Outside the image: any row with no valid pixel (every neighbour there takes the centre value).
            let (su, ou) =
                if y > 0 { (s.smoothed(a, y - 1), &ok[rows(y - 1)]) } else { (sc, &self.none[..]) };
            let (sd, od) =
                if y + 1 < h { (s.smoothed(a, y + 1), &ok[rows(y + 1)]) } else { (sc, &self.none[..]) };
            let rows = SobelRows { su, sc, sd, ou, oc, od };
            if a == 0 {
                interior_runs(&rows, &mut self.col, &mut self.full, &mut self.runs);
            }
            sobel_row(&rows, &self.runs, wt, &mut self.jxx, &mut self.jxy, &mut self.jyy);
        }
        let (m, d) = ((y % 3) * (w + 2), (y % 2) * w);
        let mrow = &mut self.mbuf[m + 1..m + w + 1];
        let (dxs, dys) = (&mut self.dxs[d..d + w], &mut self.dys[d..d + w]);
        eigen_row(&self.jxx, &self.jxy, &self.jyy, &ok[rows(y)], mrow, dxs, dys);
        mrow
    }

    /// Non-maximum suppression of row `y` (of `h`) into `keep`; rows `y − 1 ..= y + 1` are done.
    #[inline(always)]
    fn suppress(&self, y: usize, h: usize, keep: &mut [u8]) {
        let w = self.w;
        let mrow = |yy: usize| &self.mbuf[(yy % 3) * (w + 2)..(yy % 3 + 1) * (w + 2)];
        let up = if y > 0 { mrow(y - 1) } else { &self.zero[..] };
        let down = if y + 1 < h { mrow(y + 1) } else { &self.zero[..] };
        let d = (y % 2) * w;
        nms_row([up, mrow(y), down], &self.dxs[d..d + w], &self.dys[d..d + w], keep);
    }
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
