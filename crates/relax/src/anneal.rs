//! The annealing state: point lists, compact occupancy grids and the incremental energy.
//!
//! Moves hit random places of the image, so the state is laid out for few cache misses: one
//! byte of flags per cell (valid, C2 occupied), one [`Cell`] (`u8`, or `u16` for caps over 15.8 px) per cell that is both the C1
//! occupancy and the cached nearest-C2 squared distance of the C1 point there, and one `f32`
//! array per strength. [`State::sweep`] draws its moves a few steps ahead and prefetches the cells
//! they will need ([`isa::prefetch`]), so the cache misses of consecutive moves overlap.
//!
//! A C2 move from a to b can change the cached distance only of C1 points within the cap of a
//! or b. Per direction, a window of `2·⌊cap⌋ + 2` rows by a multiple of 16 columns covers both
//! disks, with precomputed squared distances to a and to b; each window row is first tested
//! branch-free (vectorised) for a cell that may change ([`affected`]), and only the rare rows
//! that have one are examined cell by cell. A C1 move searches the nearest C2 point around b,
//! starting from the lower bound `(d(a) − |b − a|)²` implied by the cached distance at a.

use rand::RngExt;
use rand::rngs::Xoshiro256PlusPlus;
use rangeimage::{EdgeMap, Grid};

/// "No C2 point within the cap" (as a squared distance).
pub(crate) const NONE: u32 = u32::MAX;
const VALID: u8 = 1;
const OCC2: u8 = 2;

/// The type of a `c1d2` cell (and of the window tables compared with it): `u8` when `⌊cap²⌋ ≤ 252` (the
/// default cap of 10 px gives 100), else `u16`. A byte per cell halves the memory the window scans read and
/// doubles the cells per vector; the decisions and sums are the same.
pub(crate) trait Cell: Copy + PartialEq + PartialOrd + 'static {
    /// `c1d2` value of a cell without a C1 point.
    const EMPTY: Self;
    /// `c1d2` value of a C1 point with no C2 point within the cap.
    const FAR: Self;
    /// `Window::da` value beyond the cap (never equal to a `c1d2` value).
    const FAR_A: Self;
    /// The largest `⌊cap²⌋` the type holds below `FAR_A`.
    const MAX_CAP2: u32;
    /// The cell of squared distance `d2 ≤ MAX_CAP2`.
    fn of(d2: u32) -> Self;
    /// The value as a `u32`.
    fn get(self) -> u32;
    /// This type's `c1d2` vector in `b`.
    fn buf(b: &mut Buffers) -> &mut Vec<Self>;
}

impl Cell for u16 {
    const EMPTY: Self = u16::MAX;
    const FAR: Self = u16::MAX - 1;
    const FAR_A: Self = u16::MAX - 3;
    const MAX_CAP2: u32 = u16::MAX as u32 - 4;
    #[inline(always)]
    fn of(d2: u32) -> Self {
        d2 as u16
    }
    #[inline(always)]
    fn get(self) -> u32 {
        u32::from(self)
    }
    fn buf(b: &mut Buffers) -> &mut Vec<Self> {
        &mut b.c1d2
    }
}

impl Cell for u8 {
    const EMPTY: Self = u8::MAX;
    const FAR: Self = u8::MAX - 1;
    const FAR_A: Self = u8::MAX - 2;
    const MAX_CAP2: u32 = u8::MAX as u32 - 3;
    #[inline(always)]
    fn of(d2: u32) -> Self {
        d2 as u8
    }
    #[inline(always)]
    fn get(self) -> u32 {
        u32::from(self)
    }
    fn buf(b: &mut Buffers) -> &mut Vec<Self> {
        &mut b.c1d8
    }
}

/// Capped distance term shared by the incremental state and [`crate::energy`].
#[derive(Debug, Clone)]
pub(crate) struct DistanceTerm {
    /// The cap in pixels: a C1 point with no C2 point within `cap` contributes `cap`.
    pub(crate) cap: f64,
    /// Largest integer squared distance that counts as "within the cap" (`⌊cap²⌋`).
    pub(crate) cap2: u32,
    /// `lut[d²] = √d²` for `d² ≤ cap2`.
    lut: Vec<f64>,
}

impl DistanceTerm {
    /// The term for distance cap `cap` (pixels, finite, 0 ≤ cap ≤ 65).
    pub(crate) fn new(cap: f64) -> Self {
        let cap2 = (cap * cap).floor() as u32;
        assert!(cap2 <= <u16 as Cell>::MAX_CAP2, "distance cap {cap} too large");
        let lut = (0..=cap2).map(|d2| f64::from(d2).sqrt()).collect();
        Self { cap, cap2, lut }
    }

    /// Contribution of a C1 point whose nearest C2 point is at squared distance `d2`
    /// (`NONE` or anything above `cap2` means "not within the cap").
    #[inline]
    pub(crate) fn value(&self, d2: u32) -> f64 {
        if d2 <= self.cap2 { self.lut[d2 as usize] } else { self.cap }
    }

    /// [`DistanceTerm::value`] of a `c1d2` cell value (its `FAR` is above every `cap2` it holds).
    #[inline]
    fn value_of<C: Cell>(&self, d2: C) -> f64 {
        self.value(d2.get())
    }
}

/// Per move direction: the `win_h × win_w` window (row-major) that covers the disks of radius
/// `cap` around both the source a and the target b of a C2 move, as squared distances to a
/// and to b (`C::FAR_A` / `C::FAR` outside the respective disk), so the cells whose cached
/// distance may change are found by branch-free, vectorisable row scans. Where b is as far as a, `da` holds
/// `C::FAR_A` too: a cell there cannot change when the point moves from a to b, which [`affected`] then reads from
/// `old == da` alone (one compare per cell fewer).
struct Window<C> {
    /// Linear offset of the window's top-left cell relative to a.
    origin: isize,
    /// Squared distance to a, or `C::FAR_A` beyond the cap or where it equals the squared distance to b.
    da: Vec<C>,
    /// Squared distance to b, or `C::FAR` beyond the cap.
    db: Vec<C>,
}

impl<C> Default for Window<C> {
    fn default() -> Self {
        Self { origin: 0, da: Vec::new(), db: Vec::new() }
    }
}
/// Window width granularity (cells per vector chunk).
const LANES: usize = 16;
/// How many moves ahead [`State::sweep`] draws and prefetches.
const LOOK: usize = 16;

/// Whether a C1 cell with cached squared distance `old` may change when the C2 point at squared
/// distance `da` moves to squared distance `db`: b is strictly closer, or the moved point was
/// at the cached distance (and b is not at the same distance). `da` comes from a [`Window`], whose `da` is
/// `C::FAR_A` (never a cached value) where b is at a's distance, so `old == da` already implies `db != old`.
#[inline(always)]
fn affected<C: Cell>(old: C, da: C, db: C) -> bool {
    (old != C::EMPTY) & (db < old) | (old == da)
}

/// Whether any cell of a window row is [`affected`] (branch-free over 16-cell chunks).
#[inline(always)]
fn row_hit<C: Cell>(old: &[C], da: &[C], db: &[C]) -> bool {
    let mut acc = [false; LANES];
    for ((o, a), b) in old.chunks_exact(LANES).zip(da.chunks_exact(LANES)).zip(db.chunks_exact(LANES)) {
        for j in 0..LANES {
            acc[j] |= affected(o[j], a[j], b[j]);
        }
    }
    acc.iter().fold(false, |x, &y| x | y)
}

/// Whether any cell of a `W`-cell window row is [`affected`] (one branch-free vector test).
#[inline(always)]
fn row_any<C: Cell, const W: usize>(old: &[C; W], da: &[C; W], db: &[C; W]) -> bool {
    let mut acc = [0u8; W];
    for j in 0..W {
        acc[j] = u8::from(affected(old[j], da[j], db[j]));
    }
    acc.iter().fold(0, |x, &y| x | y) != 0
}

/// Whether any cell of two `W`-cell window rows is [`affected`] (one branch-free vector test of both).
#[inline(always)]
fn row_pair_any<C: Cell, const W: usize>(
    old0: &[C; W],
    old1: &[C; W],
    da: &[[C; W]; 2],
    db: &[[C; W]; 2],
) -> bool {
    let mut acc = [0u8; W];
    for j in 0..W {
        acc[j] = u8::from(affected(old0[j], da[0][j], db[0][j]) | affected(old1[j], da[1][j], db[1][j]));
    }
    acc.iter().fold(0, |x, &y| x | y) != 0
}

/// Bit `j` set when cell `j` of a `W`-cell window row is [`affected`] (`W` a multiple of 8, at most 32): the
/// flags side by side as bytes 0 or 1, gathered eight per multiplication (byte `i` of a word lands in bit `56 + i`
/// of the product and no two partial products overlap).
#[inline(always)]
fn row_bits<C: Cell, const W: usize>(old: &[C; W], da: &[C; W], db: &[C; W]) -> u32 {
    debug_assert!(W.is_multiple_of(8) && W <= 32);
    let mut acc = [0u8; W];
    for j in 0..W {
        acc[j] = u8::from(affected(old[j], da[j], db[j]));
    }
    let mut bits = 0u32;
    for (g, c) in acc.as_chunks::<8>().0.iter().enumerate() {
        bits |= ((u64::from_le_bytes(*c).wrapping_mul(0x0102_0408_1020_4080) >> 56) as u32) << (8 * g);
    }
    bits
}

/// Squared distance from padded cell `p` to the nearest C2 point (`OCC2` in `flags`) within the
/// cap, or `C::FAR`, when none is known to be closer than squared distance `from`. The disk entries are read
/// eight at a time and the first occupied one of a group taken (the first in the disk's order, as one by one).
#[inline]
fn nearest_in<C: Cell>(flags: &[u8], disk: &[(isize, C)], start: &[u32], p: usize, from: usize) -> C {
    let mut chunks = disk[start[from] as usize..].chunks_exact(8);
    for ch in &mut chunks {
        let hits: [bool; 8] = std::array::from_fn(|k| flags[(p as isize + ch[k].0) as usize] & OCC2 != 0);
        if let Some(k) = hits.iter().position(|&h| h) {
            return ch[k].1;
        }
    }
    for &(off, d2) in chunks.remainder() {
        if flags[(p as isize + off) as usize] & OCC2 != 0 {
            return d2;
        }
    }
    C::FAR
}

/// `u < exp(−x)` for `x ≥ 0` and `u` a multiple of 2⁻⁵³ in [0, 1) (as `rand` samples f64): for
/// `x > 37`, `exp(−x) < 2⁻⁵³`, so only `u = 0` can pass and `exp` is evaluated only then.
#[inline]
fn metropolis(u: f64, x: f64) -> bool {
    if x > 37.0 { u == 0.0 && (-x).exp() > 0.0 } else { u < (-x).exp() }
}

/// The offsets within the cap (`r = ⌊cap⌋`, `cap2 = ⌊cap²⌋`) on a padded grid of width `pw`, sorted by
/// squared distance, and the index of the first one at each squared distance: [`State`]'s `disk` and `start`.
fn disk_tables<C: Cell>(r: i32, cap2: u32, pw: usize) -> (Vec<(isize, C)>, Vec<u32>) {
    let mut disk = Vec::new();
    for dy in -r..=r {
        for dx in -r..=r {
            let d2 = dx * dx + dy * dy;
            if d2 <= cap2 as i32 {
                disk.push((d2, dy, dx));
            }
        }
    }
    disk.sort_unstable();
    let start = (0..=cap2 + 1)
        .map(|d| disk.iter().position(|e| e.0 as u32 >= d).unwrap_or(disk.len()) as u32)
        .collect();
    let disk = disk
        .iter()
        .map(|&(d2, dy, dx)| (dy as isize * pw as isize + dx as isize, C::of(d2 as u32)))
        .collect();
    (disk, start)
}

/// Per move direction (the 8 neighbours in raster order): [`State`]'s `nbr`, `lower` and `win`.
fn move_tables<C: Cell>(
    r: i32,
    cap2: u32,
    pw: usize,
    win_size: (usize, usize),
) -> ([isize; 8], [Vec<u16>; 8], [Window<C>; 8]) {
    let cap2 = cap2 as i32;
    let mut nbr = [0; 8];
    let mut lower: [Vec<u16>; 8] = Default::default();
    let mut win: [Window<C>; 8] = Default::default();
    let mut k = 0;
    for my in -1i32..=1 {
        for mx in -1i32..=1 {
            if mx == 0 && my == 0 {
                continue;
            }
            nbr[k] = my as isize * pw as isize + mx as isize;
            let step = f64::from(mx * mx + my * my).sqrt();
            lower[k] = (0..=cap2 + 1)
                .map(|d2| {
                    let d = f64::from(d2).sqrt() - step;
                    if d <= 0.0 { 0 } else { (d * d - 1e-9).ceil().max(0.0) as u16 }
                })
                .collect();
            win[k] = Window::new((mx, my), r, cap2, pw, win_size);
            k += 1;
        }
    }
    (nbr, lower, win)
}

impl<C: Cell> Window<C> {
    /// The window of the move by `(mx, my)`, for `r = ⌊cap⌋` and `cap2 = ⌊cap²⌋` on a padded grid of width `pw`.
    fn new((mx, my): (i32, i32), r: i32, cap2: i32, pw: usize, (win_w, win_h): (usize, usize)) -> Self {
        let (x0, y0) = (-r + mx.min(0), -r + my.min(0));
        let mut win = Window { origin: y0 as isize * pw as isize + x0 as isize, ..Window::default() };
        for wy in 0..win_h as i32 {
            for wx in 0..win_w as i32 {
                let (dx, dy) = (x0 + wx, y0 + wy);
                let da2 = dx * dx + dy * dy;
                let db2 = (dx - mx) * (dx - mx) + (dy - my) * (dy - my);
                win.da.push(if da2 <= cap2 && da2 != db2 { C::of(da2 as u32) } else { C::FAR_A });
                win.db.push(if db2 <= cap2 { C::of(db2 as u32) } else { C::FAR });
            }
        }
        win
    }
}

/// Sets the pad cells of a padded grid (image `w × h` at column and row `pad`, padded width `pw`) to 0.
fn zero_pad(v: &mut [f32], (w, h): (usize, usize), pad: usize, pw: usize) {
    v[..pad * pw].fill(0.0);
    v[(pad + h) * pw..].fill(0.0);
    for row in v[pad * pw..(pad + h) * pw].chunks_exact_mut(pw) {
        row[..pad].fill(0.0);
        row[pad + w..].fill(0.0);
    }
}

/// The per-cell arrays of a [`State`], kept between frames (see [`crate::Scratch`]).
#[derive(Default)]
pub(crate) struct Buffers {
    flags: Vec<u8>,
    /// `c1d2` of a state with `u16` cells, and of one with `u8` cells.
    c1d2: Vec<u16>,
    c1d8: Vec<u8>,
    vals: [Vec<f32>; 2],
    pos: Vec<u32>,
    /// The C2 occupancy of [`State::recompute_at`].
    occ2: Vec<bool>,
}

/// The mutable annealing state on a padded grid (pad cells are invalid, so a move can never
/// leave the image and window scans need no bounds checks).
pub(crate) struct State<C: Cell> {
    w: usize,
    h: usize,
    /// Left and top padding (cells); the right padding is wider so whole window rows fit.
    pad: usize,
    pw: usize,
    /// `VALID | OCC2` bits per padded cell.
    flags: Vec<u8>,
    /// Per padded cell: `C::EMPTY`, or the capped squared distance from the C1 point there to the
    /// nearest C2 point (`C::FAR` beyond the cap).
    c1d2: Vec<C>,
    /// `[s1, |∇|]`: one array per strength over the padded cells (C1 moves read the first,
    /// C2 moves the second).
    vals: [Vec<f32>; 2],
    /// Padded linear positions: `[0, n1)` are C1 points, `[n1, len)` C2 points.
    pub(crate) pos: Vec<u32>,
    n1: usize,
    /// Offsets within the cap, sorted by squared distance: (linear delta, d²).
    disk: Vec<(isize, C)>,
    /// `start[d]` = index of the first `disk` entry with squared distance ≥ d (d ≤ cap2 + 1).
    start: Vec<u32>,
    /// Linear offset of each of the 8 move directions.
    nbr: [isize; 8],
    /// Per move direction: lower bound on the squared distance from b to C2 given the cached
    /// one at a (`lower[dir][d²]`, index `cap2 + 1` for `C::FAR`), from `|b − a| ≤ √2`.
    lower: [Vec<u16>; 8],
    /// Per move direction: the C2-move window.
    win: [Window<C>; 8],
    /// Window width (a multiple of `LANES`) and height.
    win_w: usize,
    win_h: usize,
    term: DistanceTerm,
    lambda: f64,
    /// Running Σ over C1 of the distance term.
    pub(crate) e_int: f64,
    /// Running Σ s1 over C1 + Σ |∇| over C2.
    ext_sum: f64,
    /// A + B (initial external sums).
    ab: f64,
    /// Pending (padded cell, new d²) updates of the last C2 proposal.
    scratch: Vec<(u32, C)>,
    /// The C2 occupancy of [`State::recompute_at`], kept for its next call.
    occ2: Vec<bool>,
    /// New d² of the C1 point of the last C1 proposal.
    pending: C,
    /// The vectors of the buffers this state does not use (the other cell type's `c1d2`).
    rest: Buffers,
}

impl<C: Cell> State<C> {
    /// Builds the state from (already pruned) edge maps and sanitised, scaled s1 / magnitude,
    /// with A + B = `ab` (tests: the building blocks of [`crate::relax`] one by one).
    #[cfg(test)]
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn new(
        c1: &EdgeMap,
        c2: &EdgeMap,
        s1: &Grid<f32>,
        mag: &Grid<f32>,
        valid: &Grid<bool>,
        term: DistanceTerm,
        lambda: f64,
        ab: f64,
    ) -> Self {
        let mut st = Self::scaled(c1, c2, [s1, mag], false, valid, term, lambda, Buffers::default());
        st.ab = ab;
        st.ext_sum = ab;
        st
    }

    /// Builds the state from (already pruned) edge maps and the raw strengths `[s1, |∇|]`:
    /// non-finite values count as 0, and with `normalize` each strength is divided in f64 by its mean over its
    /// points (C1 for s1, C2 for |∇|; `crate::divisor`: summed in raster order, 1 unless positive and finite) and
    /// rounded to f32 (without, the values are kept). A + B is the sum of the stored
    /// strengths over the initial points, C1 in raster order then C2 in raster order.
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn scaled(
        c1: &EdgeMap,
        c2: &EdgeMap,
        strengths: [&Grid<f32>; 2],
        normalize: bool,
        valid: &Grid<bool>,
        term: DistanceTerm,
        lambda: f64,
        mut bufs: Buffers,
    ) -> Self {
        assert!(term.cap2 <= C::MAX_CAP2, "distance cap {} too large for the cell type", term.cap);
        let mut c1d2 = std::mem::take(C::buf(&mut bufs));
        let mut flags = std::mem::take(&mut bufs.flags);
        let [mut v0, mut v1] = std::mem::take(&mut bufs.vals);
        let mut pos = std::mem::take(&mut bufs.pos);
        let occ2 = std::mem::take(&mut bufs.occ2);
        let (w, h) = (c1.width() as usize, c1.height() as usize);
        let r = term.cap.floor() as usize;
        let pad = r + 1;
        let win_w = (2 * r + 2).div_ceil(LANES) * LANES;
        let win_h = 2 * r + 2;
        // A window starts at most r + 1 left of a and spans win_w cells.
        let pad_right = (win_w - r).max(pad);
        let pw = w + pad + pad_right;
        let ph = h + 2 * pad;
        // Memory of the previous frame, refilled (fresh vectors on the first).
        flags.clear();
        flags.resize(pw * ph, 0);
        c1d2.clear();
        c1d2.resize(pw * ph, C::EMPTY);
        for v in [&mut v0, &mut v1] {
            if v.len() == pw * ph {
                // The previous frame's memory: `load_strengths` rewrites every image cell, so only the pad cells are
                // set (to the 0 a fresh vector holds).
                zero_pad(v, (w, h), pad, pw);
            } else {
                v.clear();
                v.resize(pw * ph, 0.0);
            }
        }
        // Room for every point a frame of this size can have (C1 and C2 each at most one per pixel), so a later
        // frame with more edge points reuses the memory (reserved memory is touched only as far as used).
        pos.clear();
        pos.reserve(2 * w * h);
        let (disk, start) = disk_tables(r as i32, term.cap2, pw);
        let (nbr, lower, win) = move_tables(r as i32, term.cap2, pw, (win_w, win_h));
        let mut st = Self {
            w,
            h,
            pad,
            pw,
            flags,
            c1d2,
            vals: [v0, v1],
            pos,
            occ2,
            n1: 0,
            disk,
            start,
            nbr,
            lower,
            win,
            win_w,
            win_h,
            term,
            lambda,
            e_int: 0.0,
            ext_sum: 0.0,
            ab: 0.0,
            scratch: Vec::new(),
            pending: C::EMPTY,
            rest: bufs,
        };
        // The point list first: the means of the strengths over the points are summed while it is listed (the
        // divisors `crate::divisor` computes, without another scan of the edge maps).
        let sums = st.load_points(c1, c2, strengths);
        let divisor = sums.map(|(sum, n)| {
            let mean = if normalize && n > 0 { sum / n as f64 } else { 0.0 };
            if mean > 0.0 && mean.is_finite() { mean } else { 1.0 }
        });
        // Compiled for the best instruction set of this CPU (the divisions run several at a time; the same quotients).
        isa::dispatch(
            #[inline(always)]
            || st.load_strengths(valid, strengths, divisor),
        );
        for &p in &st.pos[st.n1..] {
            st.flags[p as usize] |= OCC2;
        }
        st.init_energies();
        st
    }

    /// Fills the flags with the valid cells and `vals` with the strengths (see [`State::scaled`]). Inlined, for its
    /// caller's `isa::dispatch`.
    #[inline(always)]
    fn load_strengths(&mut self, valid: &Grid<bool>, [s1, mag]: [&Grid<f32>; 2], divisor: [f64; 2]) {
        let w = self.w;
        for (y, ((vrow, srow), mrow)) in valid
            .as_slice()
            .chunks_exact(w.max(1))
            .zip(s1.as_slice().chunks_exact(w.max(1)))
            .zip(mag.as_slice().chunks_exact(w.max(1)))
            .enumerate()
        {
            let p0 = self.padded(0, y);
            for (f, &v) in self.flags[p0..p0 + w].iter_mut().zip(vrow) {
                *f = if v { VALID } else { 0 };
            }
            for (k, src) in [srow, mrow].into_iter().enumerate() {
                let div = divisor[k];
                for (d, &v) in self.vals[k][p0..p0 + w].iter_mut().zip(src) {
                    *d = (f64::from(if v.is_finite() { v } else { 0.0 }) / div) as f32;
                }
            }
        }
    }

    /// The point list: C1 in raster order, then C2 in raster order (the caller marks C2 `OCC2` in the flags).
    /// Returns per strength the sum of its raw values (non-finite as 0) over its points in that order, and their
    /// number (s1 over C1, |∇| over C2).
    fn load_points(&mut self, c1: &EdgeMap, c2: &EdgeMap, strengths: [&Grid<f32>; 2]) -> [(f64, u64); 2] {
        let w = self.w;
        let mut sums = [(0.0, 0); 2];
        for (k, map) in [c1, c2].into_iter().enumerate() {
            let v = strengths[k].as_slice();
            let (sum, n) = &mut sums[k];
            for (y, row) in map.as_slice().chunks_exact(w.max(1)).enumerate() {
                let p0 = self.padded(0, y);
                crate::for_each_set(row, |x| {
                    self.pos.push((p0 + x) as u32);
                    let value = v[y * w + x];
                    *sum += f64::from(if value.is_finite() { value } else { 0.0 });
                    *n += 1;
                });
            }
            if k == 0 {
                self.n1 = self.pos.len();
            }
        }
        sums
    }

    /// The cached distances of the C1 points, the internal energy and A + B from the loaded points.
    fn init_energies(&mut self) {
        let mut e_int = 0.0;
        for k in 0..self.n1 {
            let p = self.pos[k] as usize;
            let d = self.nearest(p);
            self.c1d2[p] = d;
            e_int += self.term.value_of(d);
        }
        self.e_int = e_int;
        let mut ab = 0.0;
        for (k, &p) in self.pos.iter().enumerate() {
            ab += f64::from(self.vals[usize::from(k >= self.n1)][p as usize]);
        }
        self.ab = ab;
        self.ext_sum = ab;
    }

    #[inline]
    fn padded(&self, x: usize, y: usize) -> usize {
        (y + self.pad) * self.pw + x + self.pad
    }

    /// Number of points in C1 ∪ C2.
    pub(crate) fn len(&self) -> usize {
        self.pos.len()
    }

    /// Current total energy from the running sums.
    pub(crate) fn energy(&self) -> f64 {
        self.e_int + self.lambda * (self.ab - self.ext_sum)
    }

    /// Squared distance from padded cell `p` to the nearest C2 point within the cap, or `C::FAR`.
    #[inline]
    fn nearest(&self, p: usize) -> C {
        self.nearest_from(p, 0)
    }

    /// [`State::nearest`] when no C2 point is known to be closer than squared distance `from`
    /// (`from ≤ cap2`): the search skips the disk entries below it.
    #[inline]
    fn nearest_from(&self, p: usize, from: usize) -> C {
        nearest_in(&self.flags, &self.disk, &self.start, p, from)
    }

    /// Full recomputation of (Eⁱ, Eᵉ) for the points at padded positions `pos` (same point
    /// order as `self.pos`), from scratch: a fresh C2 occupancy grid and a fresh nearest search.
    pub(crate) fn recompute_at(&mut self, pos: &[u32]) -> (f64, f64) {
        let mut occ2 = std::mem::take(&mut self.occ2);
        occ2.clear();
        occ2.resize(self.flags.len(), false);
        for &p in &pos[self.n1..] {
            occ2[p as usize] = true;
        }
        let nearest = |p: usize| {
            self.disk.iter().find(|&&(off, _)| occ2[(p as isize + off) as usize]).map_or(NONE, |d| d.1.get())
        };
        let e_int: f64 = pos[..self.n1].iter().map(|&p| self.term.value(nearest(p as usize))).sum();
        let mut ext = 0.0;
        for (k, &p) in pos.iter().enumerate() {
            ext += f64::from(self.vals[usize::from(k >= self.n1)][p as usize]);
        }
        self.occ2 = occ2;
        (e_int, self.ab - ext)
    }

    /// The per-cell arrays, for the next frame's state.
    pub(crate) fn into_buffers(self) -> Buffers {
        let mut b =
            Buffers { flags: self.flags, vals: self.vals, pos: self.pos, occ2: self.occ2, ..self.rest };
        *C::buf(&mut b) = self.c1d2;
        b
    }

    /// (ΔEⁱ, change of the external sum) of moving point `i` by neighbour `dir`, or `None` if the
    /// move is not allowed; ΔE = ΔEⁱ − λ·Δsum. For a C2 point the occupancy is left moved and
    /// `scratch` holds the pending updates; the caller must then [`State::commit`] or
    /// [`State::revert`].
    #[inline(always)]
    fn propose(&mut self, i: usize, dir: usize) -> Option<(f64, f64)> {
        let a = self.pos[i] as usize;
        let b = (a as isize + self.nbr[dir]) as usize;
        let fb = self.flags[b];
        if fb & VALID == 0 {
            return None;
        }
        let set = usize::from(i >= self.n1);
        // Read the strengths first: they are likely cache misses, which then overlap the scan.
        let d_ext = f64::from(self.vals[set][b]) - f64::from(self.vals[set][a]);
        if set == 0 {
            if self.c1d2[b] != C::EMPTY {
                return None;
            }
            let old = self.c1d2[a];
            // Cached values are ≤ cap2 or C::FAR (which `lower` holds at index cap2 + 1).
            let li = if old == C::FAR { self.term.cap2 as usize + 1 } else { old.get() as usize };
            let from = usize::from(self.lower[dir][li]);
            let new = nearest_in(&self.flags, &self.disk, &self.start, b, from);
            self.pending = new;
            let d_int = self.term.value_of(new) - self.term.value_of(old);
            Some((d_int, d_ext))
        } else {
            if fb & OCC2 != 0 {
                return None;
            }
            self.flags[a] &= !OCC2;
            self.flags[b] |= OCC2;
            self.scratch.clear();
            let d_int = match self.win_w {
                16 => self.scan_fixed::<16>(a, dir),
                32 => self.scan_fixed::<32>(a, dir),
                _ => self.scan_rows(a, dir),
            };
            Some((d_int, d_ext))
        }
    }

    /// The cell at padded position `p` of a C2 move's window with cached squared distance `o`, squared distances
    /// `da` / `db` to the move's source and target: if it is [`affected`], its new cached value, pushed to
    /// `scratch` with the change of the internal energy added to `d_int` when it differs.
    #[inline(always)]
    fn update_cell(&mut self, p: usize, (o, da, db): (C, C, C), d_int: &mut f64) {
        if !affected(o, da, db) {
            return;
        }
        let new = if db < o {
            // b is closer than the old nearest: nothing else can be closer.
            db
        } else {
            // The moved point was a nearest one; every other C2 point is at squared
            // distance ≥ old, so search from there.
            nearest_in(&self.flags, &self.disk, &self.start, p, o.get() as usize)
        };
        if new != o {
            self.scratch.push((p as u32, new));
            *d_int += self.term.value_of(new) - self.term.value_of(o);
        }
    }

    /// The window scan of a C2 move of the point at `a` by `dir` (the occupancy already moved): pushes the cells
    /// whose cached distance changes to `scratch` (window rows top to bottom, cells left to right) and returns
    /// ΔEⁱ, their changes summed in that order. Any window width (the reference for [`State::scan_fixed`]).
    #[inline(always)]
    fn scan_rows(&mut self, a: usize, dir: usize) -> f64 {
        let (ww, pw) = (self.win_w, self.pw);
        let base = (a as isize + self.win[dir].origin) as usize;
        let mut d_int = 0.0;
        for k in 0..self.win_h {
            let row = base + k * pw;
            let win = &self.win[dir];
            let (da, db) = (&win.da[k * ww..(k + 1) * ww], &win.db[k * ww..(k + 1) * ww]);
            if !row_hit(&self.c1d2[row..row + ww], da, db) {
                continue;
            }
            for j in 0..ww {
                let win = &self.win[dir];
                let cell = (self.c1d2[row + j], win.da[k * ww + j], win.db[k * ww + j]);
                self.update_cell(row + j, cell, &mut d_int);
            }
        }
        d_int
    }

    /// [`State::scan_rows`] for windows `W` cells wide (so at most `W` rows high): first a bit mask of the rows
    /// holding an affected cell, two rows at a time one branch-free vector test (then each row of a pair that has
    /// one), then the cells of those rows in the same order as [`State::scan_rows`] (the same pushes and the same
    /// sum).
    #[inline(always)]
    fn scan_fixed<const W: usize>(&mut self, a: usize, dir: usize) -> f64 {
        debug_assert!(self.win_w == W && self.win_h <= W && W <= 32);
        let (h, pw) = (self.win_h, self.pw);
        let base = (a as isize + self.win[dir].origin) as usize;
        let mut rows = 0u32;
        {
            // The tables zipped with the row index (no index checks on them; the same rows in the same order).
            let win = &self.win[dir];
            let (da, db) = (&win.da.as_chunks::<W>().0[..h], &win.db.as_chunks::<W>().0[..h]);
            let region = &self.c1d2[base..base + (h - 1) * pw + W];
            // Rows in pairs: one vector test of both (most pairs have no affected cell), then each row of a pair
            // that has one.
            let (da2, da1) = da.as_chunks::<2>();
            let (db2, db1) = db.as_chunks::<2>();
            for (q, (a, b)) in da2.iter().zip(db2).enumerate() {
                let k = 2 * q;
                let old0: &[C; W] = region[k * pw..].first_chunk::<W>().expect("W cells");
                let old1: &[C; W] = region[(k + 1) * pw..].first_chunk::<W>().expect("W cells");
                if row_pair_any(old0, old1, a, b) {
                    rows |= u32::from(row_any(old0, &a[0], &b[0])) << k;
                    rows |= u32::from(row_any(old1, &a[1], &b[1])) << (k + 1);
                }
            }
            if let (Some(a), Some(b)) = (da1.first(), db1.first()) {
                let k = 2 * da2.len();
                let old: &[C; W] = region[k * pw..].first_chunk::<W>().expect("W cells");
                rows |= u32::from(row_any(old, a, b)) << k;
            }
        }
        let mut d_int = 0.0;
        while rows != 0 {
            let k = rows.trailing_zeros() as usize;
            rows &= rows - 1;
            let row = base + k * pw;
            let mut cells = {
                let win = &self.win[dir];
                let old: &[C; W] = self.c1d2[row..row + W].try_into().expect("W cells");
                row_bits(old, &win.da.as_chunks::<W>().0[k], &win.db.as_chunks::<W>().0[k])
            };
            while cells != 0 {
                let j = cells.trailing_zeros() as usize;
                cells &= cells - 1;
                let win = &self.win[dir];
                let cell = (self.c1d2[row + j], win.da[k * W + j], win.db[k * W + j]);
                self.update_cell(row + j, cell, &mut d_int);
            }
        }
        d_int
    }

    /// Applies the pending proposal of point `i` by `dir`.
    #[inline(always)]
    fn commit(&mut self, i: usize, dir: usize, d_int: f64, d_ext: f64) {
        let a = self.pos[i] as usize;
        let b = (a as isize + self.nbr[dir]) as usize;
        if i < self.n1 {
            self.c1d2[a] = C::EMPTY;
            self.c1d2[b] = self.pending;
        } else {
            for &(p, new) in &self.scratch {
                self.c1d2[p as usize] = new;
            }
        }
        self.pos[i] = b as u32;
        self.e_int += d_int;
        self.ext_sum += d_ext;
    }

    /// Undoes the occupancy change of a rejected C2 proposal.
    #[inline(always)]
    fn revert(&mut self, i: usize, dir: usize) {
        if i >= self.n1 {
            let a = self.pos[i] as usize;
            let b = (a as isize + self.nbr[dir]) as usize;
            self.flags[b] &= !OCC2;
            self.flags[a] |= OCC2;
        }
    }

    /// One sweep of `n` random moves at temperature `t`; returns the number accepted. Moves
    /// (point, direction) come from `moves`, the Metropolis coins from `coins`. The moves are
    /// drawn `LOOK` steps ahead and the memory they will touch is read early, so the cache
    /// misses of several moves overlap (the `LOOK` moves still pending at the end of the sweep
    /// are dropped, so the stream is a fixed function of the seeds and the sweep lengths). Inlined, for
    /// its caller's `isa::dispatch`.
    #[inline(always)]
    pub(crate) fn sweep(
        &mut self,
        moves: &mut Xoshiro256PlusPlus,
        coins: &mut Xoshiro256PlusPlus,
        t: f64,
        n: usize,
    ) -> u64 {
        let len = self.pos.len() as u32;
        if len == 0 {
            return 0;
        }
        let mut draw = || (moves.random_range(0..len) as usize, moves.random_range(0..8u32) as usize);
        let mut ring = [(0usize, 0usize); LOOK];
        for r in &mut ring {
            *r = draw();
        }
        for &(i, _) in &ring {
            isa::prefetch(&self.pos, i);
        }
        let mut accepted = 0;
        for k in 0..n {
            let (i, dir) = ring[k % LOOK];
            let next = draw();
            ring[k % LOOK] = next;
            // Two stages: the position of a move LOOK steps ahead, then (its line arrived) the cells of the move
            // LOOK / 2 steps ahead.
            isa::prefetch(&self.pos, next.0);
            let (i2, dir2) = ring[(k + LOOK / 2) % LOOK];
            self.touch(i2, dir2);
            accepted += u64::from(self.attempt(i, dir, coins, t));
        }
        accepted
    }

    /// Prefetches the cells a future move of point `i` by `dir` will read (hints only: nothing is read into the
    /// program, so a cache miss here does not hold up the current move).
    #[inline(always)]
    fn touch(&self, i: usize, dir: usize) {
        let a = self.pos[i] as usize;
        let b = (a as isize + self.nbr[dir]) as usize;
        let vals = &self.vals[usize::from(i >= self.n1)];
        isa::prefetch(vals, b);
        isa::prefetch(vals, a);
        isa::prefetch(&self.flags, b);
        isa::prefetch(&self.c1d2, b);
    }

    /// Tries one random move at temperature `t`; returns whether it was accepted (tests: the
    /// single-stream form of [`State::sweep`]).
    #[cfg(test)]
    pub(crate) fn step(&mut self, rng: &mut Xoshiro256PlusPlus, t: f64) -> bool {
        let i = rng.random_range(0..self.pos.len() as u32) as usize;
        let dir = rng.random_range(0..8u32) as usize;
        let mut coins = rng.clone();
        let accept = self.attempt(i, dir, &mut coins, t);
        *rng = coins;
        accept
    }

    /// Tries moving point `i` by `dir` at temperature `t` (coin from `coins` if uphill).
    #[inline(always)]
    fn attempt(&mut self, i: usize, dir: usize, rng: &mut Xoshiro256PlusPlus, t: f64) -> bool {
        let Some((d_int, d_ext)) = self.propose(i, dir) else {
            return false;
        };
        let de = d_int - self.lambda * d_ext;
        let accept = de < 0.0 || metropolis(rng.random::<f64>(), de / t);
        if accept {
            self.commit(i, dir, d_int, d_ext);
        } else {
            self.revert(i, dir);
        }
        accept
    }

    /// Mean positive ΔE over `n` random trial moves that are evaluated but never applied.
    pub(crate) fn mean_uphill(&mut self, rng: &mut Xoshiro256PlusPlus, n: usize) -> Option<f64> {
        let (mut sum, mut count) = (0.0, 0u32);
        for _ in 0..n {
            let i = rng.random_range(0..self.pos.len() as u32) as usize;
            let dir = rng.random_range(0..8u32) as usize;
            if let Some((d_int, d_ext)) = self.propose(i, dir) {
                self.revert(i, dir);
                let de = d_int - self.lambda * d_ext;
                if de > 0.0 {
                    sum += de;
                    count += 1;
                }
            }
        }
        (count > 0).then(|| sum / f64::from(count))
    }

    /// Edge maps (C1, C2) of the points at padded positions `pos`.
    #[cfg(test)]
    pub(crate) fn maps(&self, pos: &[u32]) -> (EdgeMap, EdgeMap) {
        let (mut c1, mut c2) = (EdgeMap::default(), EdgeMap::default());
        self.maps_into(pos, &mut c1, &mut c2);
        (c1, c2)
    }

    /// [`State::maps`] into `c1` and `c2`, whose memory is reused.
    pub(crate) fn maps_into(&self, pos: &[u32], c1: &mut EdgeMap, c2: &mut EdgeMap) {
        let (w, h) = (self.w as u32, self.h as u32);
        c1.reset(w, h, false);
        c2.reset(w, h, false);
        for (k, &p) in pos.iter().enumerate() {
            let (py, px) = (p as usize / self.pw, p as usize % self.pw);
            let (x, y) = ((px - self.pad) as u32, (py - self.pad) as u32);
            if k < self.n1 {
                c1[(x, y)] = true;
            } else {
                c2[(x, y)] = true;
            }
        }
    }

    /// Checks every cached d² against a fresh search (tests only).
    #[cfg(test)]
    pub(crate) fn cache_consistent(&self) -> bool {
        let occupied = self.c1d2.iter().filter(|&&d| d != C::EMPTY).count();
        occupied == self.n1
            && self.pos[..self.n1].iter().all(|&p| self.c1d2[p as usize] == self.nearest(p as usize))
    }

    /// The stored `[s1, |∇|]` of every padded cell and A + B (tests only).
    #[cfg(test)]
    pub(crate) fn strengths(&self) -> (&[Vec<f32>; 2], f64) {
        (&self.vals, self.ab)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    /// `zero_pad` sets exactly the pad cells of a reused grid (the cells a fresh, zeroed grid has and
    /// `load_strengths` does not write).
    #[test]
    fn zero_pad_sets_exactly_the_pad_cells() {
        for (w, h, pad, extra) in
            [(1usize, 1usize, 1usize, 0usize), (5, 3, 2, 7), (7, 4, 11, 21), (3, 9, 1, 1)]
        {
            let pw = w + 2 * pad + extra;
            let ph = h + 2 * pad;
            let mut v = vec![1.0f32; pw * ph];
            zero_pad(&mut v, (w, h), pad, pw);
            for (i, &x) in v.iter().enumerate() {
                let (c, r) = (i % pw, i / pw);
                let image = (pad..pad + w).contains(&c) && (pad..pad + h).contains(&r);
                assert_eq!(x, if image { 1.0 } else { 0.0 }, "w {w} h {h} pad {pad} at ({c}, {r})");
            }
        }
    }

    /// Random C2 moves of a state with cells `C` and cap `cap`: [`State::scan_fixed`] pushes the same cells and
    /// returns the same ΔEⁱ bits as [`State::scan_rows`]; half of the moves are applied, so the states vary.
    fn check_fixed_scan<C: Cell>(case: &crate::tests::Case, cap: f64, seed: u64) {
        let term = DistanceTerm::new(cap);
        let mut st = State::<C>::new(&case.c1, &case.c2, &case.s1, &case.mag, &case.valid, term, 0.3, 0.0);
        assert!(st.len() > st.n1 + 10, "the case has C2 points");
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed);
        let mut moves = 0;
        for _ in 0..4000 {
            let i = rng.random_range(st.n1..st.len());
            let dir = rng.random_range(0..8usize);
            let a = st.pos[i] as usize;
            let b = (a as isize + st.nbr[dir]) as usize;
            if st.flags[b] & VALID == 0 || st.flags[b] & OCC2 != 0 {
                continue;
            }
            st.flags[a] &= !OCC2;
            st.flags[b] |= OCC2;
            st.scratch.clear();
            let got = match st.win_w {
                16 => st.scan_fixed::<16>(a, dir),
                32 => st.scan_fixed::<32>(a, dir),
                w => panic!("window width {w}"),
            };
            let got_cells = std::mem::take(&mut st.scratch);
            let want = st.scan_rows(a, dir);
            assert_eq!(got.to_bits(), want.to_bits(), "cap {cap}, seed {seed}");
            let cells = |v: &[(u32, C)]| v.iter().map(|&(p, d)| (p, d.get())).collect::<Vec<_>>();
            assert_eq!(cells(&got_cells), cells(&st.scratch), "cap {cap}, seed {seed}");
            moves += 1;
            if rng.random_bool(0.5) { st.commit(i, dir, got, 0.0) } else { st.revert(i, dir) }
        }
        assert!(moves > 1000 && st.cache_consistent());
    }

    /// The fixed-width window scans (16 and 32 cells wide, byte and `u16` cells, every instruction set) match
    /// the any-width row scan on random states and moves.
    #[test]
    fn fixed_width_scans_match_the_row_scan() {
        for (seed, cap) in [(1, 10.0), (2, 7.5), (3, 15.5), (4, 3.0), (5, 1.0), (6, 12.3)] {
            let case = crate::tests::random_case(90, 70, seed);
            for isa in isa::Isa::available() {
                isa::with_isa(isa, || {
                    isa::dispatch(
                        #[inline(always)]
                        || {
                            check_fixed_scan::<u8>(&case, cap, seed);
                            check_fixed_scan::<u16>(&case, cap, seed);
                        },
                    )
                });
            }
        }
    }

    /// `nearest_in` (disk entries eight at a time) finds the first occupied entry in the disk's order from
    /// `start[from]`, as the entry-by-entry search, on random occupancies of every density and every `from`.
    #[test]
    fn grouped_nearest_search_matches_one_by_one() {
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(21);
        for (r, cap2) in [(10, 100u32), (3, 12), (1, 1), (15, 252)] {
            let pw = 2 * r as usize + 41;
            let (disk, start) = disk_tables::<u8>(r, cap2, pw);
            for density in [0.0, 0.002, 0.02, 0.2, 0.9] {
                let flags: Vec<u8> = (0..pw * pw)
                    .map(|_| if rng.random_bool(density) { OCC2 | VALID } else { VALID })
                    .collect();
                for _ in 0..200 {
                    let p = (r as usize + rng.random_range(0..41usize)) * pw
                        + r as usize
                        + rng.random_range(0..41usize);
                    for from in 0..=cap2 as usize + 1 {
                        let want = disk[start[from] as usize..]
                            .iter()
                            .find(|&&(off, _)| flags[(p as isize + off) as usize] & OCC2 != 0)
                            .map_or(<u8 as Cell>::FAR, |e| e.1);
                        assert_eq!(nearest_in(&flags, &disk, &start, p, from), want, "r {r}, from {from}");
                    }
                }
            }
        }
    }

    #[test]
    fn metropolis_shortcut_matches_exp() {
        // rand samples f64 in [0, 1) as multiples of 2⁻⁵³, which the shortcut relies on.
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(3);
        let unit = 2f64.powi(-53);
        for _ in 0..10_000 {
            let u: f64 = rng.random();
            assert_eq!((u / unit).fract(), 0.0, "{u} is not a multiple of 2^-53");
        }
        let mut us: Vec<f64> = (0..4).map(|k| f64::from(k) * unit).collect();
        us.extend((0..200).map(|_| rng.random::<f64>()));
        let mut xs: Vec<f64> = (0..400).map(|k| f64::from(k) * 0.25).collect();
        xs.extend([36.0, 36.7, 36.9, 37.0, 37.0 + 1e-12, 37.5, 745.0, 1e300, f64::INFINITY]);
        for &x in &xs {
            for &u in &us {
                assert_eq!(metropolis(u, x), u < (-x).exp(), "u {u}, x {x}");
            }
        }
    }

    /// The window tables' `da` (`C::FAR_A` where b is as far as a) with the short [`affected`] give the decision of
    /// the full rule on the raw squared distance to a, for every window cell of every direction and cap and every
    /// cached value.
    #[test]
    fn window_tables_keep_the_affected_rule() {
        fn check<C: Cell>(cap: f64) {
            let term = DistanceTerm::new(cap);
            let r = cap.floor() as i32;
            let cap2 = term.cap2 as i32;
            let win_w = (2 * r as usize + 2).div_ceil(LANES) * LANES;
            let win_h = 2 * r as usize + 2;
            let pw = 300;
            let (_, _, wins) = move_tables::<C>(r, term.cap2, pw, (win_w, win_h));
            let mut olds: Vec<C> = (0..=term.cap2).map(C::of).collect();
            olds.extend([C::FAR, C::EMPTY]);
            let mut k = 0;
            for my in -1i32..=1 {
                for mx in -1i32..=1 {
                    if mx == 0 && my == 0 {
                        continue;
                    }
                    let win = &wins[k];
                    k += 1;
                    let (x0, y0) = (-r + mx.min(0), -r + my.min(0));
                    for wy in 0..win_h as i32 {
                        for wx in 0..win_w as i32 {
                            let (dx, dy) = (x0 + wx, y0 + wy);
                            let da2 = dx * dx + dy * dy;
                            let raw_da = if da2 <= cap2 { C::of(da2 as u32) } else { C::FAR_A };
                            let cell = wy as usize * win_w + wx as usize;
                            let (da, db) = (win.da[cell], win.db[cell]);
                            for &old in &olds {
                                let full = (old != C::EMPTY) & (db < old) | (old == raw_da) & (db != old);
                                assert_eq!(
                                    affected(old, da, db),
                                    full,
                                    "cap {cap}, move ({mx}, {my}), cell ({dx}, {dy})"
                                );
                            }
                        }
                    }
                }
            }
        }
        for cap in [1.0, 2.5, 3.0, 7.3, 10.0, 15.8] {
            check::<u8>(cap);
            check::<u16>(cap);
        }
        check::<u16>(20.0);
    }
}
