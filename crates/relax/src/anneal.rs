//! The annealing state: point lists, compact occupancy grids and the incremental energy.
//!
//! Moves hit random places of the image, so the state is laid out for few cache misses: one
//! byte of flags per cell (valid, C2 occupied), one `u16` per cell that is both the C1
//! occupancy and the cached nearest-C2 squared distance of the C1 point there, and the two
//! strengths interleaved as `[f32; 2]`.

use rand::RngExt;
use rand::rngs::Xoshiro256PlusPlus;
use rangeimage::{EdgeMap, Grid};

/// "No C2 point within the cap" (as a squared distance).
pub(crate) const NONE: u32 = u32::MAX;
/// `c1d2` value of a cell without a C1 point.
const EMPTY: u16 = u16::MAX;
/// `c1d2` value of a C1 point with no C2 point within the cap.
const FAR16: u16 = u16::MAX - 1;
const VALID: u8 = 1;
const OCC2: u8 = 2;

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
        assert!(cap2 < u32::from(FAR16), "distance cap {cap} too large");
        let lut = (0..=cap2).map(|d2| f64::from(d2).sqrt()).collect();
        Self { cap, cap2, lut }
    }

    /// Contribution of a C1 point whose nearest C2 point is at squared distance `d2`
    /// (`NONE` or anything above `cap2` means "not within the cap").
    #[inline]
    pub(crate) fn value(&self, d2: u32) -> f64 {
        if d2 <= self.cap2 { self.lut[d2 as usize] } else { self.cap }
    }

    #[inline]
    fn value16(&self, d2: u16) -> f64 {
        self.value(u32::from(d2))
    }
}

/// The mutable annealing state on a padded grid (pad cells are invalid, so a move can never
/// leave the image and window scans need no bounds checks).
pub(crate) struct State {
    w: usize,
    h: usize,
    pad: usize,
    pw: usize,
    /// `VALID | OCC2` bits per padded cell.
    flags: Vec<u8>,
    /// Per padded cell: `EMPTY`, or the capped squared distance from the C1 point there to the
    /// nearest C2 point (`FAR16` beyond the cap).
    c1d2: Vec<u16>,
    /// `[s1, |∇|]` per padded cell (values exactly representable in f32).
    vals: Vec<[f32; 2]>,
    /// Padded linear positions: `[0, n1)` are C1 points, `[n1, len)` C2 points.
    pub(crate) pos: Vec<u32>,
    n1: usize,
    /// Offsets within the cap, sorted by squared distance: (linear delta, d², dx, dy).
    disk: Vec<(isize, u16, i32, i32)>,
    /// `start[d]` = index of the first `disk` entry with squared distance ≥ d (d ≤ cap2 + 1).
    start: Vec<u32>,
    nbr: [(isize, i32, i32); 8],
    /// Per move direction: the offsets (relative to the target b) of the disk around b that
    /// are outside the disk around the source a, with their squared distance to b.
    fresh: [Vec<(isize, u16)>; 8],
    term: DistanceTerm,
    lambda: f64,
    /// Running Σ over C1 of the distance term.
    pub(crate) e_int: f64,
    /// Running Σ s1 over C1 + Σ |∇| over C2.
    ext_sum: f64,
    /// A + B (initial external sums).
    ab: f64,
    /// Pending (padded cell, new d²) updates of the last C2 proposal.
    scratch: Vec<(u32, u16)>,
}

impl State {
    /// Builds the state from (already pruned) edge maps and sanitised, scaled s1 / magnitude
    /// (values must be exactly representable in f32).
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn new(
        c1: &EdgeMap,
        c2: &EdgeMap,
        s1: &Grid<f64>,
        mag: &Grid<f64>,
        valid: &Grid<bool>,
        term: DistanceTerm,
        lambda: f64,
        ab: f64,
    ) -> Self {
        let (w, h) = (c1.width() as usize, c1.height() as usize);
        let r = term.cap.floor() as usize;
        let pad = r + 1;
        let pw = w + 2 * pad;
        let ph = h + 2 * pad;
        let mut st = Self {
            w,
            h,
            pad,
            pw,
            flags: vec![0; pw * ph],
            c1d2: vec![EMPTY; pw * ph],
            vals: vec![[0.0; 2]; pw * ph],
            pos: Vec::new(),
            n1: 0,
            disk: Vec::new(),
            start: Vec::new(),
            nbr: [(0, 0, 0); 8],
            fresh: Default::default(),
            term,
            lambda,
            e_int: 0.0,
            ext_sum: ab,
            ab,
            scratch: Vec::new(),
        };
        let ri = r as i32;
        for dy in -ri..=ri {
            for dx in -ri..=ri {
                let d2 = (dx * dx + dy * dy) as u32;
                if d2 <= st.term.cap2 {
                    st.disk.push((dy as isize * pw as isize + dx as isize, d2 as u16, dx, dy));
                }
            }
        }
        st.disk.sort_by_key(|&(_, d2, dx, dy)| (d2, dy, dx));
        st.start = (0..=st.term.cap2 + 1)
            .map(|d| st.disk.iter().position(|e| u32::from(e.1) >= d).unwrap_or(st.disk.len()) as u32)
            .collect();
        let mut k = 0;
        for dy in -1i32..=1 {
            for dx in -1i32..=1 {
                if dx != 0 || dy != 0 {
                    st.nbr[k] = (dy as isize * pw as isize + dx as isize, dx, dy);
                    k += 1;
                }
            }
        }
        for dir in 0..8 {
            let (_, mx, my) = st.nbr[dir];
            let cap2 = st.term.cap2 as i32;
            st.fresh[dir] = st
                .disk
                .iter()
                .filter(|&&(_, _, dx, dy)| (dx + mx) * (dx + mx) + (dy + my) * (dy + my) > cap2)
                .map(|&(o, d2, _, _)| (o, d2))
                .collect();
        }
        for y in 0..h {
            for x in 0..w {
                let i = y * w + x;
                let p = st.padded(x, y);
                st.flags[p] = if valid.as_slice()[i] { VALID } else { 0 };
                st.vals[p] = [s1.as_slice()[i] as f32, mag.as_slice()[i] as f32];
                debug_assert_eq!(f64::from(st.vals[p][0]), s1.as_slice()[i]);
                if c1.as_slice()[i] {
                    st.pos.push(p as u32);
                }
            }
        }
        st.n1 = st.pos.len();
        for y in 0..h {
            for x in 0..w {
                if c2.as_slice()[y * w + x] {
                    let p = st.padded(x, y);
                    st.flags[p] |= OCC2;
                    st.pos.push(p as u32);
                }
            }
        }
        let mut e_int = 0.0;
        for k in 0..st.n1 {
            let p = st.pos[k] as usize;
            let d = st.nearest(p);
            st.c1d2[p] = d;
            e_int += st.term.value16(d);
        }
        st.e_int = e_int;
        st
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

    /// Squared distance from padded cell `p` to the nearest C2 point within the cap, or `FAR16`.
    #[inline]
    fn nearest(&self, p: usize) -> u16 {
        self.nearest_from(p, 0)
    }

    /// [`State::nearest`] when no C2 point is known to be closer than squared distance `from`
    /// (`from ≤ cap2`): the search skips the disk entries below it.
    #[inline]
    fn nearest_from(&self, p: usize, from: u16) -> u16 {
        for &(off, d2, _, _) in &self.disk[self.start[usize::from(from)] as usize..] {
            if self.flags[(p as isize + off) as usize] & OCC2 != 0 {
                return d2;
            }
        }
        FAR16
    }

    /// Full recomputation of (Eⁱ, Eᵉ) for the points at padded positions `pos` (same point
    /// order as `self.pos`), from scratch: a fresh C2 occupancy grid and a fresh nearest search.
    pub(crate) fn recompute_at(&self, pos: &[u32]) -> (f64, f64) {
        let mut occ2 = vec![false; self.flags.len()];
        for &p in &pos[self.n1..] {
            occ2[p as usize] = true;
        }
        let nearest = |p: usize| {
            self.disk
                .iter()
                .find(|&&(off, _, _, _)| occ2[(p as isize + off) as usize])
                .map_or(NONE, |d| u32::from(d.1))
        };
        let e_int: f64 = pos[..self.n1].iter().map(|&p| self.term.value(nearest(p as usize))).sum();
        let mut ext = 0.0;
        for (k, &p) in pos.iter().enumerate() {
            ext += f64::from(self.vals[p as usize][usize::from(k >= self.n1)]);
        }
        (e_int, self.ab - ext)
    }

    /// (ΔEⁱ, change of the external sum) of moving point `i` by neighbour `dir`, or `None` if the
    /// move is not allowed; ΔE = ΔEⁱ − λ·Δsum. For a C2 point the occupancy is left moved and
    /// `scratch` holds the pending updates; the caller must then [`State::commit`] or
    /// [`State::revert`].
    #[inline]
    fn propose(&mut self, i: usize, dir: usize) -> Option<(f64, f64)> {
        let a = self.pos[i] as usize;
        let (off, mx, my) = self.nbr[dir];
        let b = (a as isize + off) as usize;
        let fb = self.flags[b];
        if fb & VALID == 0 {
            return None;
        }
        self.scratch.clear();
        if i < self.n1 {
            if self.c1d2[b] != EMPTY {
                return None;
            }
            let old = self.c1d2[a];
            let new = self.nearest(b);
            let d_int = self.term.value16(new) - self.term.value16(old);
            Some((d_int, f64::from(self.vals[b][0]) - f64::from(self.vals[a][0])))
        } else {
            if fb & OCC2 != 0 {
                return None;
            }
            self.flags[a] &= !OCC2;
            self.flags[b] |= OCC2;
            let cap2 = self.term.cap2 as i32;
            let mut d_int = 0.0;
            for j in 0..self.disk.len() {
                let (o, da2, dx, dy) = self.disk[j];
                let p = (a as isize + o) as usize;
                let old = self.c1d2[p];
                if old == EMPTY {
                    continue;
                }
                let db2 = (dx - mx) * (dx - mx) + (dy - my) * (dy - my);
                let new = if db2 <= cap2 && (db2 as u16) <= old {
                    // b is at least as close as the old nearest: nothing else can be closer.
                    db2 as u16
                } else if old == da2 {
                    // The moved point may have been the (only) nearest; every other C2 point is
                    // at squared distance ≥ old, so search from there.
                    self.nearest_from(p, old)
                } else {
                    old
                };
                if new != old {
                    self.scratch.push((p as u32, new));
                    d_int += self.term.value16(new) - self.term.value16(old);
                }
            }
            // C1 points newly within the cap of b (those near a were handled above).
            for j in 0..self.fresh[dir].len() {
                let (o, db2) = self.fresh[dir][j];
                let p = (b as isize + o) as usize;
                let old = self.c1d2[p];
                if old == EMPTY || db2 >= old {
                    continue;
                }
                self.scratch.push((p as u32, db2));
                d_int += self.term.value16(db2) - self.term.value16(old);
            }
            Some((d_int, f64::from(self.vals[b][1]) - f64::from(self.vals[a][1])))
        }
    }

    /// Applies the pending proposal of point `i` by `dir`.
    #[inline]
    fn commit(&mut self, i: usize, dir: usize, d_int: f64, d_ext: f64) {
        let a = self.pos[i] as usize;
        let b = (a as isize + self.nbr[dir].0) as usize;
        if i < self.n1 {
            self.c1d2[a] = EMPTY;
            self.c1d2[b] = self.nearest(b);
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
    #[inline]
    fn revert(&mut self, i: usize, dir: usize) {
        if i >= self.n1 {
            let a = self.pos[i] as usize;
            let b = (a as isize + self.nbr[dir].0) as usize;
            self.flags[b] &= !OCC2;
            self.flags[a] |= OCC2;
        }
    }

    /// Tries one random move at temperature `t`; returns whether it was accepted.
    #[inline]
    pub(crate) fn step(&mut self, rng: &mut Xoshiro256PlusPlus, t: f64) -> bool {
        let i = rng.random_range(0..self.pos.len() as u32) as usize;
        let dir = rng.random_range(0..8u32) as usize;
        let Some((d_int, d_ext)) = self.propose(i, dir) else {
            return false;
        };
        let de = d_int - self.lambda * d_ext;
        let accept = de < 0.0 || rng.random::<f64>() < (-de / t).exp();
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
    pub(crate) fn maps(&self, pos: &[u32]) -> (EdgeMap, EdgeMap) {
        let (w, h) = (self.w as u32, self.h as u32);
        let mut c1 = Grid::new(w, h, false);
        let mut c2 = Grid::new(w, h, false);
        for (k, &p) in pos.iter().enumerate() {
            let (py, px) = (p as usize / self.pw, p as usize % self.pw);
            let (x, y) = ((px - self.pad) as u32, (py - self.pad) as u32);
            if k < self.n1 {
                c1[(x, y)] = true;
            } else {
                c2[(x, y)] = true;
            }
        }
        (c1, c2)
    }

    /// Checks every cached d² against a fresh search (tests only).
    #[cfg(test)]
    pub(crate) fn cache_consistent(&self) -> bool {
        let occupied = self.c1d2.iter().filter(|&&d| d != EMPTY).count();
        occupied == self.n1
            && self.pos[..self.n1].iter().all(|&p| self.c1d2[p as usize] == self.nearest(p as usize))
    }
}
