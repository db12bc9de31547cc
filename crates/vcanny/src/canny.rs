//! Non-maximum suppression, threshold selection and hysteresis.

use crate::{ThresholdMode, Thresholds};

/// Keeps the pixels whose magnitude is a maximum along the gradient direction (see
/// [`crate::gradient::nms_row`]); pixels that are not `ok` are never kept and count as magnitude 0 for their
/// neighbours, as does the outside of the image. (The detector runs `nms_row` inside its row pipeline; this
/// whole-image form serves the tests.)
#[cfg(test)]
pub(crate) fn non_max_suppression(
    mag: &[f32],
    dir: &[[f32; 2]],
    ok: &[bool],
    w: usize,
    h: usize,
) -> Vec<bool> {
    // Magnitudes padded with a zero border, 0 where not ok.
    let wp = w + 2;
    let mut padded = vec![0.0f32; wp * (h + 2)];
    for y in 0..h {
        for x in 0..w {
            let i = y * w + x;
            padded[(y + 1) * wp + x + 1] = if ok[i] { mag[i] } else { 0.0 };
        }
    }
    let mut keep = vec![0u8; w * h];
    for y in 0..h {
        let row = |yy: usize| &padded[yy * wp..(yy + 1) * wp];
        let dx: Vec<f32> = dir[y * w..(y + 1) * w].iter().map(|d| d[0]).collect();
        let dy: Vec<f32> = dir[y * w..(y + 1) * w].iter().map(|d| d[1]).collect();
        crate::gradient::nms_row([row(y), row(y + 1), row(y + 2)], &dx, &dy, &mut keep[y * w..(y + 1) * w]);
    }
    keep.into_iter().map(|k| k == 1).collect()
}

/// The `(low, high)` absolute thresholds for `mag` over the `ok` pixels.
#[cfg(test)]
pub(crate) fn absolute_thresholds(t: &Thresholds, mag: &[f32], ok: &[bool]) -> (f32, f32) {
    thresholds(t, mag, ok, None)
}

/// The `(low, high)` absolute thresholds for `mag` over the `ok` pixels, given their [`Histogram`] if already made.
#[inline(always)] // into `isa::dispatch` in `run`: compiled for each instruction set
pub(crate) fn thresholds(
    t: &Thresholds,
    mag: &[f32],
    ok: &[bool],
    hist: Option<&mut Histogram>,
) -> (f32, f32) {
    match t.mode {
        ThresholdMode::Absolute => (t.low, t.high),
        ThresholdMode::Quantile => {
            let v = quantiles_of(hist, mag, ok, &[t.low, t.high]);
            (v[0], v[1])
        }
        ThresholdMode::NoiseRelative => {
            let noise = quantiles_of(hist, mag, ok, &[0.5])[0].max(t.noise_floor);
            (t.low * noise, t.high * noise)
        }
    }
}

/// The `qs`-quantiles of `mag` over the `ok` pixels from `hist`, or from a new [`Histogram`] of them.
#[inline(always)] // into `isa::dispatch` in `run`: compiled for each instruction set
fn quantiles_of(hist: Option<&mut Histogram>, mag: &[f32], ok: &[bool], qs: &[f32]) -> Vec<f32> {
    match hist {
        Some(hs) => hs.quantiles(mag, ok, qs),
        None => {
            let mut hs = Histogram::new();
            hs.add_row(mag, ok);
            hs.quantiles(mag, ok, qs)
        }
    }
}

/// The rank of the `q`-quantile (nearest rank) among `n > 0` values.
fn quantile_rank(n: usize, q: f32) -> usize {
    ((q.clamp(0.0, 1.0) * (n - 1) as f32).round() as usize).min(n - 1)
}

/// The `q`-quantile (nearest rank) of `v`; `+inf` for an empty slice so nothing passes.
#[cfg(test)]
pub(crate) fn quantile(v: &mut [f32], q: f32) -> f32 {
    if v.is_empty() {
        return f32::INFINITY;
    }
    let k = quantile_rank(v.len(), q);
    let (_, x, _) = v.select_nth_unstable_by(k, f32::total_cmp);
    *x
}

/// A `u32` whose unsigned order is [`f32::total_cmp`]'s order.
#[inline(always)]
fn order_key(v: f32) -> u32 {
    let b = v.to_bits();
    // Negative: all bits flipped; positive: the sign bit set (branch-free, so loops over it vectorise).
    b ^ ((((b as i32) >> 31) as u32) | 0x8000_0000)
}

/// The inverse of [`order_key`].
fn from_order_key(k: u32) -> f32 {
    f32::from_bits(if k >> 31 == 1 { k & 0x7fff_ffff } else { !k })
}

/// The `qs`-quantiles (nearest rank, as [`quantile`]) of `mag` over the `ok` pixels, `+inf` if there are none.
#[cfg(test)]
pub(crate) fn masked_quantiles(mag: &[f32], ok: &[bool], qs: &[f32]) -> Vec<f32> {
    let mut hs = Histogram::new();
    hs.add_row(mag, ok);
    hs.quantiles(mag, ok, qs)
}

/// Counts of values by the top 16 bits of their [`order_key`], for a radix select of quantiles.
pub(crate) struct Histogram {
    counts: Vec<u32>,
    n: usize,
    /// The second-level counts of [`Histogram::quantiles`], kept to be reused.
    low: Vec<u32>,
}

impl Histogram {
    /// An empty histogram.
    pub(crate) fn new() -> Self {
        Self { counts: vec![0; 1 << 16], n: 0, low: Vec::new() }
    }

    /// Empties the histogram, keeping its memory.
    pub(crate) fn reset(&mut self) {
        self.counts.fill(0);
        self.n = 0;
    }

    /// Counts the values of `mag` where `ok` (a row while it is in cache, or the whole image).
    #[inline(always)] // into `gradient`, compiled for each instruction set
    pub(crate) fn add_row(&mut self, mag: &[f32], ok: &[bool]) {
        for (&m, &o) in mag.iter().zip(ok) {
            self.counts[(order_key(m) >> 16) as usize] += u32::from(o);
            self.n += usize::from(o);
        }
    }

    /// The `qs`-quantiles (nearest rank, as [`quantile`]) of `mag` over the `ok` pixels, the values this
    /// histogram counted; `+inf` if there are none. Radix select: the bucket of the top 16 key bits holding the
    /// rank, then the low 16 bits by counting the keys of that bucket.
    #[inline(always)] // into `isa::dispatch` in `run`: compiled for each instruction set
    pub(crate) fn quantiles(&mut self, mag: &[f32], ok: &[bool], qs: &[f32]) -> Vec<f32> {
        if self.n == 0 {
            return vec![f32::INFINITY; qs.len()];
        }
        let mut low = std::mem::take(&mut self.low);
        low.resize(1 << 16, 0);
        // A plain loop, not an iterator chain, so that all of it is inlined into the dispatched code.
        let mut out = Vec::with_capacity(qs.len());
        for &q in qs {
            let mut k = quantile_rank(self.n, q);
            let bucket = skip_ranks(&self.counts, &mut k) as u32;
            // The rank among the low 16 bits of the keys in that bucket, by a second histogram of those keys alone.
            count_low_bits(mag, ok, bucket, &mut low);
            let lo = skip_ranks(&low, &mut k) as u32;
            out.push(from_order_key(bucket << 16 | lo));
        }
        self.low = low;
        out
    }
}

/// Counts into `low` (emptied first) the low 16 bits of the [`order_key`]s of the `ok` values of `mag` whose
/// top 16 bits are `bucket`. The bucket holds a small share of the pixels: a vectorised test skips the blocks
/// without one, and in the others the branch is well predicted (measured faster than a branch-free compaction,
/// whose cursor chains every pixel to the previous one).
#[inline(always)]
fn count_low_bits(mag: &[f32], ok: &[bool], bucket: u32, low: &mut [u32]) {
    const BLOCK: usize = 32;
    low.fill(0);
    let in_bucket = |m: f32, o: bool| o & (order_key(m) >> 16 == bucket);
    for (ms, os) in mag.chunks(BLOCK).zip(ok.chunks(BLOCK)) {
        if ms.len() == BLOCK && !ms.iter().zip(os).fold(false, |a, (&m, &o)| a | in_bucket(m, o)) {
            continue;
        }
        for (&m, &o) in ms.iter().zip(os) {
            if in_bucket(m, o) {
                low[(order_key(m) & 0xffff) as usize] += 1;
            }
        }
    }
}

/// The bin of `counts` holding rank `k` (< the sum of `counts`), counting from the first bin; `k` becomes the
/// rank within that bin. Whole blocks of bins are skipped by their (vectorised) sum.
#[inline(always)]
fn skip_ranks(counts: &[u32], k: &mut usize) -> usize {
    const BLOCK: usize = 64;
    let mut bin = 0;
    for block in counts.chunks_exact(BLOCK) {
        let sum: usize = block.iter().map(|&c| c as usize).sum();
        if *k < sum {
            break;
        }
        *k -= sum;
        bin += BLOCK;
    }
    while *k >= counts[bin] as usize {
        *k -= counts[bin] as usize;
        bin += 1;
    }
    bin
}

/// Hysteresis: the candidates with magnitude ≥ `low` that are 8-connected through such candidates to one with
/// magnitude ≥ `high`. A flood fill from the strong pixels, so the result does not depend on the scan order.
#[cfg(test)]
pub(crate) fn hysteresis(mag: &[f32], cand: &[bool], w: usize, h: usize, low: f32, high: f32) -> Vec<bool> {
    let mut state: Vec<u8> = cand.iter().map(|&c| u8::from(c)).collect();
    let mut out = Vec::new();
    hysteresis_in_place(mag, &mut state, w, h, (low, high), (&mut out, &mut Vec::new()));
    out
}

/// [`hysteresis`] on candidates given as `state` (0 or 1 per pixel), used as the flood's scratch, into `out`.
#[inline(always)] // into `isa::dispatch` in `run`: compiled for each instruction set
pub(crate) fn hysteresis_in_place(
    mag: &[f32],
    state: &mut [u8],
    w: usize,
    h: usize,
    (low, high): (f32, f32),
    (out, stack): (&mut Vec<bool>, &mut Vec<(u32, u32)>),
) {
    // Bit 0 = weak (candidate ≥ low), bit 1 = also strong (≥ high); 4 = edge (visited).
    for (s, &m) in state.iter_mut().zip(mag) {
        let weak = *s & u8::from(m >= low);
        *s = weak | (weak & u8::from(m >= high)) << 1;
    }
    const STRONG: u64 = u64::from_le_bytes([2; 8]);
    // The flood's stack: each pixel enters it at most once; room for all of them up front (reserved memory is
    // touched only as far as used), so a later frame with larger edge chains does not reallocate it.
    stack.clear();
    stack.reserve(w * h);
    let mut i = 0;
    while i < w * h {
        // Skip 8 pixels at a time while none is strong.
        if i + 8 <= w * h && u64::from_le_bytes(state[i..i + 8].try_into().expect("8 bytes")) & STRONG == 0 {
            i += 8;
            continue;
        }
        if state[i] & 2 != 0 {
            state[i] = 4;
            stack.push(((i % w) as u32, (i / w) as u32));
            while let Some((x, y)) = stack.pop() {
                let (x, y) = (x as usize, y as usize);
                for yy in y.saturating_sub(1)..(y + 2).min(h) {
                    for xx in x.saturating_sub(1)..(x + 2).min(w) {
                        let k = yy * w + xx;
                        if state[k] & 3 != 0 {
                            state[k] = 4;
                            stack.push((xx as u32, yy as u32));
                        }
                    }
                }
            }
        }
        i += 1;
    }
    out.clear();
    out.extend(state.iter().map(|&s| s == 4));
}
