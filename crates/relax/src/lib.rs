//! Cooperative relaxation of two edge sets by simulated annealing.
//!
//! docs/method.md §3.4. [`relax`] takes the region borders C1 (with a per-pixel strength s1, e.g. |K| or
//! curvedness) and the Canny edges C2 (with the gradient magnitude), removes the points of each
//! set that the other does not support ([`prune`]), then minimises
//! `E = Eⁱ + λ·Eᵉ` by simulated annealing over one-pixel moves of single points:
//!
//! - `Eⁱ = Σ_{p∈C1} min(d(p, C2), cap)` with `cap = t_d_px + 1` pixels (see below);
//! - `Eᵉ = A + B − Σ_{p∈C1} s1(p) − Σ_{q∈C2} |∇q|`, with A, B the same sums over the pruned
//!   initial sets, so `Eᵉ = 0` at the start.
//!
//! **Distance cap.** After pruning every C1 point lies within `t_d_px` of C2, but annealing can
//! move points apart. The nearest-C2 distance of a C1 point is searched only within the disk of
//! radius `cap = t_d_px + 1`; a C1 point with no C2 point at squared distance `≤ ⌊cap²⌋`
//! contributes exactly `cap`. [`energy`] (full recomputation) uses the same definition, so the
//! incremental bookkeeping and a full recomputation agree up to float rounding.
//!
//! **Scaling** (the paper is silent): with `normalize = true` (default), s1 and |∇| are divided
//! by their means over the pruned initial C1 and C2 respectively, so λ is unitless and the same
//! value works for |K|, curvedness, or any gradient unit. Non-finite s1/|∇| values count as 0.
//!
//! **Annealing.** A move picks a uniformly random point of C1 ∪ C2 and a uniformly random
//! 8-neighbour; it is rejected (counted as tried, not accepted) if the target is outside the
//! image, invalid, or occupied by a point of the same set. Metropolis acceptance: `ΔE < 0` or
//! `u < exp(−ΔE/T)` (so ΔE = 0 moves are always accepted). Moves and the Metropolis coins `u`
//! come from two Xoshiro256++ streams, both seeded from `seed`, so the moves can be drawn (and
//! their memory fetched) a few steps ahead. `T ← (1 − δ)·T` after every sweep of
//! `|C1 ∪ C2|` attempts. If `t0 = 0` the initial temperature is automatic: the mean positive ΔE
//! of `min(|C1 ∪ C2|, 1000)` trial moves (evaluated, never applied) divided by
//! `ln(1 / auto_t0_acceptance)`, so an average uphill move is accepted with probability
//! `auto_t0_acceptance` at the start (default 1%: the relaxation is a local refinement of two
//! nearly aligned sets, and hotter starts measured worse energies). Stop after a sweep whose
//! acceptance rate is below `min_acceptance`, or after `max_sweeps` sweeps.
//!
//! **Final support test** (ours; the paper stops after annealing). Eⁱ sums distances from C1
//! points only, so a C2 point that is nobody's nearest neighbour feels no pull toward C1, and
//! one-pixel moves within the schedule's few sweeps cannot carry a point several pixels anyway:
//! after annealing, C2 points between `support_px` and `t_d_px` from C1 are still where Canny put
//! them, mostly responses inside a face that C1 does not corroborate. So the relaxed edge map
//! ([`Relaxed::edges`], the paper's final edge map) keeps only the relaxed C2 points within `support_px` of C1 (`support_px = 0` keeps all of them, as
//! the paper). The reference is the pruned C1 as region growing placed it, not the relaxed C1,
//! whose points annealing has jittered by a pixel or two (measured on the training split: higher
//! boundary F and precision against C1 on every image than testing against the relaxed C1).
//! [`Relaxed::c2`] and the energies are those of the annealed state, before this test; the final
//! segmentation uses [`Relaxed::union`], since a border between two faces that region growing
//! merged has only C2 to show it.
//!
//! **Returned state.** The lowest-energy state among the initial (pruned) state and the states
//! at the end of each sweep; its energy is then recomputed from scratch and, should rounding
//! make it exceed the initial energy, the initial state is returned. So `energy_after ≤
//! energy_before` always.

mod anneal;

use anneal::{Cell, DistanceTerm, NONE, State};
use rand::SeedableRng;
use rangeimage::{EdgeMap, Grid, ParamError, distance};

/// The `[relax]` table: pruning distance, energy weight and annealing schedule.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Params {
    /// T_d: points of one set farther than this from the other set are removed (pixels).
    pub t_d_px: f64,
    /// λ, the weight of the external (edge strength) energy against the distance energy.
    pub lambda: f64,
    /// Initial temperature; 0 = automatic (see `auto_t0_acceptance`).
    pub t0: f64,
    /// With `t0 = 0`: T0 is set so that a move with the mean uphill ΔE of a trial batch is
    /// accepted with this probability, `T0 = mean⁺ / ln(1 / p)`. In (0, 1).
    pub auto_t0_acceptance: f64,
    /// δ in the geometric cooling `T ← (1 − δ)·T` per sweep, in (0, 1).
    pub cooling_delta: f64,
    /// Stop after a sweep whose fraction of accepted moves is below this.
    pub min_acceptance: f64,
    /// Upper bound on the number of sweeps (0 = prune only).
    pub max_sweeps: u32,
    /// Divide s1 and |∇| by their means over the initial sets (λ becomes unitless).
    pub normalize: bool,
    /// Final support test (not in the paper): relaxed C2 points farther than this from the
    /// pruned initial C1 are left out of the final edge map C (pixels; 0 = no test). See the
    /// crate docs.
    pub support_px: f64,
}

/// Defaults: `t_d_px` and `lambda` were picked by `cargo xtask tune` on the synthetic training split
/// (objective `hoover_correct` of the whole pipeline, see `configs/tune.toml`); the schedule (7 sweeps,
/// δ = 0.7, starting temperature from the acceptance target) was chosen on the 512×512 bench case as
/// the lowest energy reached within the 50 ms budget.
impl Default for Params {
    fn default() -> Self {
        Self {
            t_d_px: 9.0,
            lambda: 0.3,
            t0: 0.0,
            auto_t0_acceptance: 0.01,
            cooling_delta: 0.7,
            min_acceptance: 0.05,
            max_sweeps: 7,
            normalize: true,
            support_px: 2.0,
        }
    }
}

impl Params {
    /// Checks the values; the error names the offending field.
    pub fn validate(&self) -> Result<(), ParamError> {
        ParamError::in_range("relax.t_d_px", self.t_d_px, 0.0, 64.0)?;
        ParamError::at_least("relax.lambda", self.lambda, 0.0)?;
        if !(self.t0.is_finite() && self.t0 >= 0.0) {
            return Err(ParamError::new(
                "relax.t0",
                format!("must be finite and ≥ 0 (0 = automatic), got {}", self.t0),
            ));
        }
        if !(self.auto_t0_acceptance > 0.0 && self.auto_t0_acceptance < 1.0) {
            return Err(ParamError::new(
                "relax.auto_t0_acceptance",
                format!("must be in (0, 1), got {}", self.auto_t0_acceptance),
            ));
        }
        if !(self.cooling_delta > 0.0 && self.cooling_delta < 1.0) {
            return Err(ParamError::new(
                "relax.cooling_delta",
                format!("must be in (0, 1), got {}", self.cooling_delta),
            ));
        }
        ParamError::in_range("relax.min_acceptance", self.min_acceptance, 0.0, 1.0)?;
        if !(self.support_px.is_finite() && (0.0..=64.0).contains(&self.support_px)) {
            return Err(ParamError::new(
                "relax.support_px",
                format!("must be in 0..=64 (0 = no test), got {}", self.support_px),
            ));
        }
        Ok(())
    }

    /// The distance cap of the internal energy, `t_d_px + 1` pixels (see the crate docs).
    pub fn distance_cap_px(&self) -> f64 {
        self.t_d_px + 1.0
    }
}

/// The relaxed edge sets.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct Relaxed {
    /// Pruned and relaxed region borders.
    pub c1: EdgeMap,
    /// Pruned and relaxed Canny edges (the annealed state, before the final support test).
    pub c2: EdgeMap,
    /// The relaxed edge map C = C1 ∪ (the points of C2 within `support_px` of the pruned initial
    /// C1; all of C2 if `support_px = 0`): the paper's final edge map (the pipeline's with
    /// `pipeline.final_edges = "relaxed"`).
    pub edges: EdgeMap,
}

impl Relaxed {
    /// C1 ∪ C2 of the annealed state, before the support test: the edges the final
    /// segmentation sees (it needs only one cue per border, see `finalseg::segment`).
    pub fn union(&self) -> EdgeMap {
        union(&self.c1, &self.c2)
    }
}

/// The union `a ∪ b` of two edge maps of one size.
///
/// # Panics
/// If the sizes differ.
#[must_use]
pub fn union(a: &EdgeMap, b: &EdgeMap) -> EdgeMap {
    let mut u = EdgeMap::default();
    union_into(a, b, &mut u);
    u
}

/// [`union`] into `out`, whose memory is reused.
///
/// # Panics
/// If the sizes differ.
pub fn union_into(a: &EdgeMap, b: &EdgeMap, out: &mut EdgeMap) {
    assert!(a.same_size(b), "edge maps differ in size");
    out.copy_from(a);
    for (e, &v) in out.as_mut_slice().iter_mut().zip(b.as_slice()) {
        *e |= v;
    }
}

/// Diagnostics of one [`relax`] run. Energies are in the (normalised) units of the crate docs.
#[derive(Debug, Clone, Default, PartialEq, serde::Serialize)]
pub struct Info {
    /// C1 points removed by pruning.
    pub removed_c1: u32,
    /// C2 points removed by pruning.
    pub removed_c2: u32,
    /// Relaxed C2 points left out of the final edge map by the support test.
    pub unsupported_c2: u32,
    /// E of the pruned initial state.
    pub energy_before: f64,
    /// E of the returned state (≤ `energy_before`).
    pub energy_after: f64,
    /// Eⁱ of the pruned initial state.
    pub e_internal_before: f64,
    /// Eⁱ of the returned state.
    pub e_internal_after: f64,
    /// Eᵉ of the pruned initial state (0 by construction).
    pub e_external_before: f64,
    /// Eᵉ of the returned state.
    pub e_external_after: f64,
    /// Initial temperature used.
    pub t0: f64,
    /// Sweeps run.
    pub sweeps: u32,
    /// Move attempts, including those rejected as invalid or occupied.
    pub moves_tried: u64,
    /// Accepted moves.
    pub moves_accepted: u64,
    /// `moves_accepted / moves_tried` (0 if nothing was tried).
    pub acceptance_rate: f64,
}

/// The energy of a configuration, split into its terms.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Energy {
    /// Eⁱ, the capped distance sum.
    pub internal: f64,
    /// Eᵉ = A + B − Σ s1 − Σ |∇|.
    pub external: f64,
    /// E = Eⁱ + λ·Eᵉ.
    pub total: f64,
}

/// Removes unsupported edges (docs/method.md §3.4 step 1): every C2 point farther than `t_d_px` from C1,
/// then every C1 point farther than `t_d_px` from the pruned C2. Exact Euclidean distances.
///
/// # Panics
/// If the maps differ in size, or `t_d_px` is not in 0..=64 (the range `Params::validate` allows).
#[must_use]
pub fn prune(c1: &EdgeMap, c2: &EdgeMap, t_d_px: f64) -> (EdgeMap, EdgeMap) {
    let (mut p1, mut p2) = (EdgeMap::default(), EdgeMap::default());
    prune_into(c1, c2, t_d_px, &mut Near::default(), &mut p1, &mut p2);
    (p1, p2)
}

/// [`prune`] into `p1` and `p2`, whose memory is reused, with the working rows `near`.
fn prune_into(c1: &EdgeMap, c2: &EdgeMap, t_d_px: f64, near: &mut Near, p1: &mut EdgeMap, p2: &mut EdgeMap) {
    assert!(c1.same_size(c2), "relax::prune: C1 and C2 differ in size");
    within_into(c2, c1, t_d_px, near, p2);
    within_into(c1, p2, t_d_px, near, p1);
}

/// Chunk width of [`within_into`]'s window test (cells compared side by side).
const NEAR_LANES: usize = 32;

/// The working rows of [`within_into`], kept between calls (in [`Scratch`]).
#[derive(Default)]
struct Near {
    /// Per pixel, the distance in rows to the nearest mask pixel at or below it in its column (capped).
    up: Vec<u8>,
    /// The same from above, for the current row.
    down: Vec<u8>,
    /// The current row's vertical distances (the smaller of the two) from column `−r`, capped cells either side.
    row: Vec<u8>,
    /// Per column offset `dx + r`: 1 + the largest row distance within `t` at that offset (0 past `2r`).
    lim: Vec<u8>,
}

/// Writes into `out` the points of `query` at Euclidean distance ≤ `t_px` (0 ≤ `t_px` ≤ 64) from a point of `mask`
/// (exact: the same decision as thresholding the squared EDT of `mask`). Per column, the distance in rows to the
/// nearest mask pixel (capped at `r + 1`, `r = ⌊t⌋`) is kept by a sweep up the image (stored) and one down (the
/// current row); a query pixel (x, y) is kept if some column `x + dx` (`|dx| ≤ r`) has that distance at row y within
/// `ry(|dx|)`, the largest integer with `dx² + ry² ≤ t²`: a mask pixel at that offset and at most that many rows away
/// exists exactly when one is within `t`. Vectorised sweeps and one side-by-side test of `2r + 1` cells per query pixel.
fn within_into(query: &EdgeMap, mask: &EdgeMap, t_px: f64, near: &mut Near, out: &mut EdgeMap) {
    // Compiled for the best instruction set of this CPU (wider sweeps and window tests; the same decisions).
    isa::dispatch(
        #[inline(always)]
        || within_body(query, mask, t_px, near, out),
    );
}

/// [`within_into`]'s work, inlined into its `isa::dispatch`.
#[inline(always)]
fn within_body(query: &EdgeMap, mask: &EdgeMap, t_px: f64, near: &mut Near, out: &mut EdgeMap) {
    assert!(t_px.is_finite() && (0.0..=64.0).contains(&t_px), "relax::within: distance {t_px} out of range");
    let (w, h) = (mask.width() as usize, mask.height() as usize);
    out.copy_from(query);
    if w == 0 || h == 0 {
        return;
    }
    let rx = distance::reach(t_px);
    let r = rx.len() - 1;
    let cap = (r + 1) as u8;
    let span = (2 * r + 1).div_ceil(NEAR_LANES) * NEAR_LANES;
    let Near { up, down, row, lim } = near;
    lim.clear();
    lim.resize(span, 0);
    for (j, l) in lim[..=2 * r].iter_mut().enumerate() {
        // `rx` does not increase, so the rows within reach of column offset dx are a prefix 0..=ry.
        *l = rx.iter().take_while(|&&x| x >= j.abs_diff(r)).count() as u8;
    }
    let step = |d: u8, m: bool| if m { 0 } else { d.min(cap - 1) + 1 };
    if up.len() != w * h {
        up.clear();
        up.resize(w * h, 0);
    }
    down.clear();
    down.resize(w, cap);
    for (urow, mrow) in up.chunks_exact_mut(w).zip(mask.as_slice().chunks_exact(w)).rev() {
        for ((u, d), &m) in urow.iter_mut().zip(down.iter_mut()).zip(mrow) {
            *d = step(*d, m);
            *u = *d;
        }
    }
    down.fill(cap);
    row.clear();
    row.resize(r + w + span, cap);
    let o = out.as_mut_slice();
    for ((qrow, orow), (urow, mrow)) in query
        .as_slice()
        .chunks_exact(w)
        .zip(o.chunks_exact_mut(w))
        .zip(up.chunks_exact(w).zip(mask.as_slice().chunks_exact(w)))
    {
        for (((v, d), &u), &m) in row[r..r + w].iter_mut().zip(down.iter_mut()).zip(urow).zip(mrow) {
            *d = step(*d, m);
            *v = (*d).min(u);
        }
        for_each_set(qrow, |x| {
            orow[x] = row[x..x + span]
                .chunks_exact(NEAR_LANES)
                .zip(lim.chunks_exact(NEAR_LANES))
                .any(|(v, l)| v.iter().zip(l).fold(false, |a, (&v, &l)| a | (v < l)));
        });
    }
}

/// Calls `f(i)` for every `i` with `mask[i]`, in increasing order. Each 32-wide block is read as four 8-byte words
/// (flags are bytes 0 or 1): an all-false block is skipped after one test (edge maps are sparse); otherwise its flags
/// are gathered into a bit mask, eight per multiplication (byte `i` of a word lands in bit `56 + i` of the product and
/// no two partial products overlap), whose set bits are visited lowest first.
#[inline]
pub(crate) fn for_each_set(mask: &[bool], mut f: impl FnMut(usize)) {
    let word = |g: &[bool]| u64::from_le_bytes(std::array::from_fn(|k| u8::from(g[k])));
    let mut chunks = mask.chunks_exact(32);
    let mut base = 0;
    for c in &mut chunks {
        let words = [word(&c[..8]), word(&c[8..16]), word(&c[16..24]), word(&c[24..])];
        if words.iter().fold(0, |a, &x| a | x) != 0 {
            let mut bits = words.iter().enumerate().fold(0u32, |acc, (g, &x)| {
                acc | ((x.wrapping_mul(0x0102_0408_1020_4080) >> 56) as u32) << (8 * g)
            });
            while bits != 0 {
                f(base + bits.trailing_zeros() as usize);
                bits &= bits - 1;
            }
        }
        base += 32;
    }
    for (k, &b) in chunks.remainder().iter().enumerate() {
        if b {
            f(base + k);
        }
    }
}

/// `values` with non-finite values set to 0, divided by their mean over `set` if `normalize`
/// and that mean (computed in f64) is positive; the quotients are rounded to f32, so the
/// annealing state stores exactly these values.
fn scaled(values: &Grid<f32>, set: &EdgeMap, normalize: bool) -> Grid<f32> {
    let div = divisor(values, set, normalize);
    values.map(|&v| (f64::from(if v.is_finite() { v } else { 0.0 }) / div) as f32)
}

/// The divisor [`scaled`] applies: the mean of the (finite, else 0) values over `set` if
/// `normalize` and that mean is positive and finite, else 1 (which keeps the values exactly).
fn divisor(values: &Grid<f32>, set: &EdgeMap, normalize: bool) -> f64 {
    let clean = |v: f32| if v.is_finite() { v } else { 0.0 };
    let mean = if normalize {
        let (mut sum, mut n) = (0.0f64, 0u64);
        let v = values.as_slice();
        for_each_set(set.as_slice(), |i| {
            sum += f64::from(clean(v[i]));
            n += 1;
        });
        if n > 0 { sum / n as f64 } else { 0.0 }
    } else {
        0.0
    };
    if mean > 0.0 && mean.is_finite() { mean } else { 1.0 }
}

/// Σ s1 over `c1` then Σ |∇| over `c2`, raster order, one accumulator.
fn external_sum(c1: &EdgeMap, s1: &Grid<f32>, c2: &EdgeMap, mag: &Grid<f32>) -> f64 {
    let mut sum = 0.0;
    for (&e, &v) in c1.as_slice().iter().zip(s1.as_slice()) {
        if e {
            sum += f64::from(v);
        }
    }
    for (&e, &v) in c2.as_slice().iter().zip(mag.as_slice()) {
        if e {
            sum += f64::from(v);
        }
    }
    sum
}

/// Full recomputation of E for the configuration (`c1`, `c2`) relative to the initial sets
/// (`c1_initial`, `c2_initial`, which define A, B and the normalisation), with exactly the
/// definitions [`relax`] uses (distance cap, scaling). For tests and diagnostics: O(pixels).
///
/// # Panics
/// If the grids differ in size.
#[must_use]
pub fn energy(
    c1: &EdgeMap,
    s1: &Grid<f32>,
    c2: &EdgeMap,
    magnitude: &Grid<f32>,
    c1_initial: &EdgeMap,
    c2_initial: &EdgeMap,
    params: &Params,
) -> Energy {
    for (name, ok) in [
        ("s1", c1.same_size(s1)),
        ("c2", c1.same_size(c2)),
        ("magnitude", c1.same_size(magnitude)),
        ("c1_initial", c1.same_size(c1_initial)),
        ("c2_initial", c1.same_size(c2_initial)),
    ] {
        assert!(ok, "relax::energy: {name} differs in size from c1");
    }
    let s1n = scaled(s1, c1_initial, params.normalize);
    let magn = scaled(magnitude, c2_initial, params.normalize);
    let ab = external_sum(c1_initial, &s1n, c2_initial, &magn);
    let term = DistanceTerm::new(params.distance_cap_px());
    let d = distance::edt_squared(c2);
    let mut internal = 0.0;
    for (&e, &d2) in c1.as_slice().iter().zip(d.as_slice()) {
        if e {
            internal += term.value(if d2 <= f64::from(term.cap2) { d2 as u32 } else { NONE });
        }
    }
    let external = ab - external_sum(c1, &s1n, c2, &magn);
    Energy { internal, external, total: internal + params.lambda * external }
}

/// What [`relax`] reconciles: the two edge sets of one image with their strengths, and the valid
/// pixels (no point moves onto an invalid one). All grids have one size.
#[derive(Debug, Clone, Copy)]
pub struct Input<'a> {
    /// C1, the region borders.
    pub c1: &'a EdgeMap,
    /// s1, the strength of each C1 point (|K| or curvedness; non-finite counts as 0).
    pub s1: &'a Grid<f32>,
    /// C2, the Canny edges.
    pub c2: &'a EdgeMap,
    /// |∇|, the strength of each C2 point (non-finite counts as 0).
    pub magnitude: &'a Grid<f32>,
    /// The valid pixels.
    pub valid: &'a Grid<bool>,
}

/// Prunes and relaxes C1 (region borders, strength `s1`) and C2 (Canny edges, strength
/// `magnitude`) by simulated annealing (docs/method.md §3.4 steps 1–3; details in the crate docs).
/// Deterministic for a given `seed`; single-threaded.
///
/// # Panics
/// If the grids differ in size; in debug builds also if `params` is invalid ([`Params::validate`]).
#[must_use]
pub fn relax(input: &Input<'_>, params: &Params, seed: u64) -> (Relaxed, Info) {
    let mut out = Relaxed::default();
    let info = relax_into(input, params, seed, &mut Scratch::default(), &mut out);
    (out, info)
}

/// The working buffers of [`relax_into`] (the pruned maps, the annealing state's per-cell arrays, the
/// point lists), kept between frames so a stream of same-sized images allocates them once.
#[derive(Default)]
pub struct Scratch {
    p1: EdgeMap,
    p2: EdgeMap,
    supported: EdgeMap,
    near: Near,
    state: anneal::Buffers,
    initial: Vec<u32>,
    best: Vec<u32>,
}

impl std::fmt::Debug for Scratch {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("relax::Scratch").finish_non_exhaustive()
    }
}

/// [`relax`] into `out` (its maps reused) with the buffers of `scratch`; the same result, bit for bit.
///
/// # Panics
/// As [`relax`].
pub fn relax_into(
    input: &Input<'_>,
    params: &Params,
    seed: u64,
    scratch: &mut Scratch,
    out: &mut Relaxed,
) -> Info {
    let Input { c1, s1, c2, magnitude, valid } = *input;
    let _s = tracing::info_span!("relax", w = c1.width(), h = c1.height()).entered();
    for (name, ok) in [
        ("s1", c1.same_size(s1)),
        ("c2", c1.same_size(c2)),
        ("magnitude", c1.same_size(magnitude)),
        ("valid", c1.same_size(valid)),
    ] {
        assert!(ok, "relax::relax: {name} differs in size from c1");
    }
    debug_assert_eq!(params.validate(), Ok(()), "relax::relax: invalid params");
    let count = |m: &EdgeMap| m.as_slice().iter().filter(|&&b| b).count() as u32;
    let Scratch { p1, p2, supported, near, state, initial, best } = scratch;
    prune_into(c1, c2, params.t_d_px, near, p1, p2);
    let (p1, p2) = (&*p1, &*p2);
    let mut info =
        Info { removed_c1: count(c1) - count(p1), removed_c2: count(c2) - count(p2), ..Info::default() };
    tracing::debug!(removed_c1 = info.removed_c1, removed_c2 = info.removed_c2, "pruned");
    let term = DistanceTerm::new(params.distance_cap_px());
    // Scaling fused into the state (the same values and A + B as `scaled` / `external_sum`).
    let bufs = std::mem::take(state);
    let strengths = [s1, magnitude];
    *state = if term.cap2 <= <u8 as Cell>::MAX_CAP2 {
        let st = State::<u8>::scaled(p1, p2, strengths, params.normalize, valid, term, params.lambda, bufs);
        anneal(st, params, seed, (initial, best), &mut info, out)
    } else {
        let st = State::<u16>::scaled(p1, p2, strengths, params.normalize, valid, term, params.lambda, bufs);
        anneal(st, params, seed, (initial, best), &mut info, out)
    };
    if params.support_px > 0.0 {
        within_into(&out.c2, p1, params.support_px, near, supported);
    } else {
        supported.copy_from(&out.c2);
    }
    info.unsupported_c2 = count(&out.c2) - count(supported);
    union_into(&out.c1, supported, &mut out.edges);
    info
}

/// The annealing of [`relax_into`] from the built state `st`: its statistics into `info`, the best positions
/// (`best`; `initial` holds the starting ones) into `out.c1` and `out.c2`; returns the state's buffers.
fn anneal<C: Cell>(
    mut st: State<C>,
    params: &Params,
    seed: u64,
    (initial, best): (&mut Vec<u32>, &mut Vec<u32>),
    info: &mut Info,
    out: &mut Relaxed,
) -> anneal::Buffers {
    initial.clear();
    initial.reserve(st.pos.capacity());
    initial.extend_from_slice(&st.pos);
    // The state's initial sums are a full computation already: Eⁱ summed over C1 in the same
    // order as `State::recompute_at`, and Eᵉ = A + B − (the same sums in the same order) = 0.
    let (ei0, ee0) = (st.e_int, 0.0);
    let e0 = ei0 + params.lambda * ee0;
    info.energy_before = e0;
    info.e_internal_before = ei0;
    info.e_external_before = ee0;

    let n = st.len();
    best.clear();
    best.reserve(st.pos.capacity());
    best.extend_from_slice(initial);
    if n > 0 && params.max_sweeps > 0 {
        let mut rng = rand::rngs::Xoshiro256PlusPlus::seed_from_u64(seed);
        let mut coins = rand::rngs::Xoshiro256PlusPlus::seed_from_u64(seed ^ 0x9E37_79B9_7F4A_7C15);
        let t0 = if params.t0 > 0.0 {
            params.t0
        } else {
            st.mean_uphill(&mut rng, n.min(1000)).map_or(1e-9, |m| m / (1.0 / params.auto_t0_acceptance).ln())
        };
        info.t0 = t0;
        let mut t = t0;
        let mut best_e = st.energy();
        for _ in 0..params.max_sweeps {
            // Compiled for the best instruction set of this CPU (the window scans several cells at a time; the
            // same decisions and sums on every one).
            let acc = isa::dispatch(
                #[inline(always)]
                || st.sweep(&mut rng, &mut coins, t, n),
            );
            info.sweeps += 1;
            info.moves_tried += n as u64;
            info.moves_accepted += acc;
            let e = st.energy();
            tracing::trace!(sweep = info.sweeps, t, e, acceptance = acc as f64 / n as f64, "sweep");
            if e < best_e {
                best_e = e;
                best.clone_from(&st.pos);
            }
            t *= 1.0 - params.cooling_delta;
            if (acc as f64) < params.min_acceptance * n as f64 {
                break;
            }
        }
    }
    let (mut ei1, mut ee1) = st.recompute_at(best);
    if ei1 + params.lambda * ee1 > e0 {
        std::mem::swap(best, initial);
        (ei1, ee1) = (ei0, ee0);
    }
    info.energy_after = ei1 + params.lambda * ee1;
    info.e_internal_after = ei1;
    info.e_external_after = ee1;
    info.acceptance_rate =
        if info.moves_tried > 0 { info.moves_accepted as f64 / info.moves_tried as f64 } else { 0.0 };
    tracing::debug!(?info, "relaxed");
    st.maps_into(best, &mut out.c1, &mut out.c2);
    st.into_buffers()
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;
    use rand::{RngExt, rngs::Xoshiro256PlusPlus};

    /// The previous support test (one bitset per mask row, rows tried nearest first per query pixel): the reference
    /// of [`within_into`]. It writes into `out` the points of `query` at Euclidean distance ≤ `t_px` from a point of `mask` (exact: the
    /// same decision as thresholding the squared EDT of `mask`, but only O(pixels / 64 + |query|·t)).
    /// The mask is packed into one bitset per row; a query pixel (x, y) is kept if for some
    /// `|dy| ≤ t` row `y + dy` has a mask bit within `x ± rx(dy)`, `rx(dy)` the largest integer with
    /// `rx² + dy² ≤ t²`. Rows are tried nearest first, so most queries stop after one or two.
    fn within_sparse(query: &EdgeMap, mask: &EdgeMap, t_px: f64, out: &mut EdgeMap) {
        let (w, h) = (mask.width() as usize, mask.height() as usize);
        let words = w.div_ceil(64);
        let mut bits = vec![0u64; words * h];
        for (brow, mrow) in bits.chunks_exact_mut(words.max(1)).zip(mask.as_slice().chunks_exact(w.max(1))) {
            pack_bits(mrow, brow);
        }
        let rx = distance::reach(t_px);
        let r = rx.len() - 1;
        // Whether row `y` of `bits` has a set bit in columns lo..=hi.
        let any = |y: usize, lo: usize, hi: usize| {
            let row = &bits[y * words..(y + 1) * words];
            let (wl, wh) = (lo / 64, hi / 64);
            let lo_mask = u64::MAX << (lo % 64);
            let hi_mask = u64::MAX >> (63 - hi % 64);
            if wl == wh {
                return row[wl] & lo_mask & hi_mask != 0;
            }
            row[wl] & lo_mask != 0 || row[wl + 1..wh].iter().any(|&v| v != 0) || row[wh] & hi_mask != 0
        };
        out.copy_from(query);
        let o = out.as_mut_slice();
        // Row by row, so a point's row and column come without a division.
        for (y, (qrow, orow)) in
            query.as_slice().chunks_exact(w.max(1)).zip(o.chunks_exact_mut(w.max(1))).enumerate()
        {
            for_each_set(qrow, |x| {
                orow[x] = (0..=r).any(|dy| {
                    let (lo, hi) = (x.saturating_sub(rx[dy]), (x + rx[dy]).min(w - 1));
                    (dy <= y && any(y - dy, lo, hi)) || (dy > 0 && y + dy < h && any(y + dy, lo, hi))
                });
            });
        }
    }

    /// Packs `row` into `words`, bit `j` of word `k` = `row[64k + j]`; eight flags at a time (as one 8-byte word whose
    /// bytes are 0 or 1, gathered into a byte by one multiplication: byte `i` lands in bit `56 + i` of the product and no
    /// two partial products overlap).
    fn pack_bits(row: &[bool], words: &mut [u64]) {
        let byte = |c: &[bool]| {
            let x = u64::from_le_bytes(std::array::from_fn(|k| u8::from(c[k])));
            x.wrapping_mul(0x0102_0408_1020_4080) >> 56
        };
        for (word, chunk) in words.iter_mut().zip(row.chunks(64)) {
            *word = if chunk.len() == 64 {
                chunk.chunks_exact(8).enumerate().fold(0u64, |acc, (g, c)| acc | (byte(c) << (8 * g)))
            } else {
                chunk.iter().enumerate().fold(0u64, |acc, (j, &b)| acc | (u64::from(b) << j))
            };
        }
    }

    /// The column sweeps of [`within_into`] keep exactly the query pixels the sparse row test keeps, on random
    /// masks and queries of every density, narrow and wide images, and distances 0–64 (the one `Near` reused).
    #[test]
    fn column_sweeps_match_the_sparse_support_test() {
        use rand::SeedableRng;
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(17);
        let mut near = Near::default();
        let (mut got, mut want) = (EdgeMap::default(), EdgeMap::default());
        for case in 0..120u32 {
            let (w, h) = ([1, 2, 7, 31, 32, 33, 64, 97, 150][case as usize % 9], 1 + (case * 7) % 45);
            let (pq, pm) =
                ([0.0, 0.02, 0.3, 1.0][case as usize % 4], [0.0, 0.005, 0.05, 0.5, 1.0][case as usize % 5]);
            let query = Grid::from_fn(w, h, |_, _| rng.random_bool(pq));
            let mask = Grid::from_fn(w, h, |_, _| rng.random_bool(pm));
            for t in [0.0, 0.5, 1.0, 1.5, 2.0, 2.9, 5.0, 9.0, 9.5, 15.9, 16.0, 31.7, 64.0] {
                within_into(&query, &mask, t, &mut near, &mut got);
                within_sparse(&query, &mask, t, &mut want);
                assert_eq!(got, want, "case {case} ({w}×{h}), t {t}");
            }
        }
        // A lone mask pixel: the kept query pixels form the digital disk.
        let mask = Grid::from_fn(41, 41, |x, y| (x, y) == (20, 20));
        let query = Grid::new(41, 41, true);
        within_into(&query, &mask, 9.0, &mut near, &mut got);
        let want = Grid::from_fn(41, 41, |x, y| (x as i32 - 20).pow(2) + (y as i32 - 20).pow(2) <= 81);
        assert_eq!(got, want);
    }

    /// `for_each_set` visits exactly the set flags, in increasing order, on random masks of every length up to 300.
    #[test]
    fn for_each_set_visits_the_set_flags_in_order() {
        use rand::SeedableRng;
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(9);
        for len in 0..=300usize {
            for density in [0.0, 0.01, 0.2, 0.7, 1.0] {
                let mask: Vec<bool> = (0..len).map(|_| rng.random_bool(density)).collect();
                let mut got = Vec::new();
                for_each_set(&mask, |i| got.push(i));
                let want: Vec<usize> = (0..len).filter(|&i| mask[i]).collect();
                assert_eq!(got, want, "length {len}, density {density}");
            }
        }
    }

    /// `pack_bits` equals one shift per flag on random rows of every length up to 200.
    #[test]
    fn pack_bits_matches_the_bitwise_packing() {
        use rand::SeedableRng;
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(5);
        for len in 1..=200usize {
            for density in [0.05, 0.5, 0.95] {
                let row: Vec<bool> = (0..len).map(|_| rng.random_bool(density)).collect();
                let mut got = vec![0u64; len.div_ceil(64)];
                pack_bits(&row, &mut got);
                let want: Vec<u64> = row
                    .chunks(64)
                    .map(|c| c.iter().enumerate().fold(0u64, |acc, (j, &b)| acc | (u64::from(b) << j)))
                    .collect();
                assert_eq!(got, want, "length {len}");
            }
        }
    }

    /// A random test case: C1 = a few thick random segments, C2 = a jittered, gappy copy plus
    /// clutter, about 5% invalid pixels, random strengths.
    pub(crate) struct Case {
        pub(crate) c1: EdgeMap,
        pub(crate) s1: Grid<f32>,
        pub(crate) c2: EdgeMap,
        pub(crate) mag: Grid<f32>,
        pub(crate) valid: Grid<bool>,
    }

    impl Case {
        /// The case as the input of [`relax`].
        pub(crate) fn input(&self) -> Input<'_> {
            Input { c1: &self.c1, s1: &self.s1, c2: &self.c2, magnitude: &self.mag, valid: &self.valid }
        }
    }

    pub(crate) fn random_case(w: u32, h: u32, seed: u64) -> Case {
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed);
        let mut c1 = Grid::new(w, h, false);
        let mut c2 = Grid::new(w, h, false);
        for _ in 0..(w + h) / 16 + 1 {
            let (x0, y0) = (rng.random_range(0..w) as f64, rng.random_range(0..h) as f64);
            let (x1, y1) = (rng.random_range(0..w) as f64, rng.random_range(0..h) as f64);
            let (ox, oy) = (rng.random_range(-2..=2i32) as f64, rng.random_range(-2..=2i32) as f64);
            let steps = ((x1 - x0).abs().max((y1 - y0).abs()) as usize).max(1);
            for s in 0..=steps {
                let t = s as f64 / steps as f64;
                let (x, y) = (x0 + t * (x1 - x0), y0 + t * (y1 - y0));
                for (dx, dy) in [(0.0, 0.0), (1.0, 0.0)] {
                    let (px, py) = ((x + dx).round() as i64, (y + dy).round() as i64);
                    if c1.in_bounds(px, py) {
                        c1[(px as u32, py as u32)] = true;
                    }
                }
                let (qx, qy) = ((x + ox).round() as i64, (y + oy).round() as i64);
                if c2.in_bounds(qx, qy) && rng.random_bool(0.85) {
                    c2[(qx as u32, qy as u32)] = true;
                }
            }
        }
        for v in c2.as_mut_slice() {
            if rng.random_bool(0.01) {
                *v = true;
            }
        }
        let s1 =
            Grid::from_fn(w, h, |_, _| if rng.random_bool(0.02) { f32::NAN } else { rng.random::<f32>() });
        let mag = Grid::from_fn(w, h, |_, _| 5.0 * rng.random::<f32>());
        let valid = Grid::from_fn(w, h, |_, _| !rng.random_bool(0.05));
        Case { c1, s1, c2, mag, valid }
    }

    fn count(m: &EdgeMap) -> usize {
        m.as_slice().iter().filter(|&&b| b).count()
    }

    /// The incrementally kept energies of `st` equal a recomputation at its current positions.
    fn assert_energy_is_recomputed<C: Cell>(st: &mut State<C>, lambda: f64) {
        let pos = st.pos.clone();
        let (ei, ee) = st.recompute_at(&pos);
        assert_relative_eq!(st.e_int, ei, epsilon = 1e-9, max_relative = 1e-6);
        assert_relative_eq!(st.energy(), ei + lambda * ee, epsilon = 1e-9, max_relative = 1e-6);
    }

    #[test]
    fn incremental_energy_matches_full_recomputation() {
        for seed in 0..4u64 {
            let c = random_case(70, 50, seed);
            let params =
                Params { t_d_px: [2.0, 3.0, 4.5, 1.0][seed as usize], lambda: 0.7, ..Params::default() };
            let (p1, p2) = prune(&c.c1, &c.c2, params.t_d_px);
            let s1n = scaled(&c.s1, &p1, true);
            let magn = scaled(&c.mag, &p2, true);
            let ab = external_sum(&p1, &s1n, &p2, &magn);
            let term = DistanceTerm::new(params.distance_cap_px());
            let mut st = State::<u8>::new(&p1, &p2, &s1n, &magn, &c.valid, term, params.lambda, ab);
            assert!(st.len() > 50, "seed {seed}: too few points ({})", st.len());
            let mut rng = Xoshiro256PlusPlus::seed_from_u64(seed);
            let mut accepted = 0;
            for m in 0..6000 {
                let t = if m < 3000 { 2.0 } else { 0.05 };
                if st.step(&mut rng, t) {
                    accepted += 1;
                    assert_energy_is_recomputed(&mut st, params.lambda);
                    if accepted % 97 == 0 {
                        assert!(st.cache_consistent(), "seed {seed}, move {m}: stale nearest-distance cache");
                    }
                }
            }
            assert!(accepted > 500, "seed {seed}: only {accepted} accepted moves");
            assert!(st.cache_consistent());
            // The public full recomputation (EDT-based, raster order) agrees as well.
            let (r1, r2) = st.maps(&st.pos);
            let e = energy(&r1, &c.s1, &r2, &c.mag, &p1, &p2, &params);
            assert_relative_eq!(e.total, st.energy(), epsilon = 1e-9, max_relative = 1e-6);
            assert_relative_eq!(e.internal, st.e_int, epsilon = 1e-9, max_relative = 1e-6);
        }
    }

    #[test]
    fn prune_matches_brute_force() {
        for seed in 0..20u64 {
            let c = random_case(40, 30, 100 + seed);
            let t_d = [0.0, 1.0, 1.5, 2.0, 3.2][seed as usize % 5];
            let (p1, p2) = prune(&c.c1, &c.c2, t_d);
            let pts = |m: &EdgeMap| {
                m.enumerate()
                    .filter(|(_, _, b)| **b)
                    .map(|(x, y, _)| (x as f64, y as f64))
                    .collect::<Vec<_>>()
            };
            let near = |p: (f64, f64), set: &[(f64, f64)]| {
                set.iter().any(|q| (p.0 - q.0).hypot(p.1 - q.1) <= t_d + 1e-12)
            };
            let all1 = pts(&c.c1);
            let want2 = Grid::from_fn(40, 30, |x, y| c.c2[(x, y)] && near((x as f64, y as f64), &all1));
            let kept2 = pts(&want2);
            let want1 = Grid::from_fn(40, 30, |x, y| c.c1[(x, y)] && near((x as f64, y as f64), &kept2));
            assert_eq!(p2, want2, "seed {seed}, t_d {t_d}");
            assert_eq!(p1, want1, "seed {seed}, t_d {t_d}");
        }
    }

    #[test]
    fn sweeps_keep_the_incremental_energy_exact() {
        for seed in 0..4u64 {
            let c = random_case(90, 60, 40 + seed);
            let params =
                Params { t_d_px: [2.0, 3.0, 6.0, 1.5][seed as usize], lambda: 0.8, ..Params::default() };
            let (p1, p2) = prune(&c.c1, &c.c2, params.t_d_px);
            let term = DistanceTerm::new(params.distance_cap_px());
            let mut st = State::<u16>::scaled(
                &p1,
                &p2,
                [&c.s1, &c.mag],
                true,
                &c.valid,
                term,
                params.lambda,
                Default::default(),
            );
            let n = st.len();
            assert!(n > 50, "seed {seed}: too few points ({n})");
            let mut moves = Xoshiro256PlusPlus::seed_from_u64(seed);
            let mut coins = Xoshiro256PlusPlus::seed_from_u64(seed + 100);
            let mut accepted = 0;
            for t in [3.0, 1.0, 0.3, 0.1, 0.01, 0.0] {
                accepted += st.sweep(&mut moves, &mut coins, t, n);
                assert_energy_is_recomputed(&mut st, params.lambda);
                assert!(st.cache_consistent(), "seed {seed}, t {t}: stale nearest-distance cache");
            }
            assert!(accepted > 100, "seed {seed}: only {accepted} accepted moves");
            let (r1, r2) = st.maps(&st.pos);
            let e = energy(&r1, &c.s1, &r2, &c.mag, &p1, &p2, &params);
            assert_relative_eq!(e.total, st.energy(), epsilon = 1e-9, max_relative = 1e-6);
        }
    }

    #[test]
    fn byte_cells_anneal_as_u16_cells() {
        // The `u8` cells (caps up to √252 px) against the general `u16` ones: the same moves, decisions and sums.
        for seed in 0..6u64 {
            let c = random_case(80, 60, 300 + seed);
            let t_d = [1.0, 2.5, 4.0, 9.0, 12.9, 14.87][seed as usize];
            let params = Params { t_d_px: t_d, lambda: 0.6, ..Params::default() };
            let (p1, p2) = prune(&c.c1, &c.c2, params.t_d_px);
            let term = DistanceTerm::new(params.distance_cap_px());
            assert!(term.cap2 <= <u8 as Cell>::MAX_CAP2, "seed {seed}: cap {} too large for bytes", term.cap);
            let strengths = [&c.s1, &c.mag];
            let mut a = State::<u8>::scaled(
                &p1,
                &p2,
                strengths,
                true,
                &c.valid,
                term.clone(),
                0.6,
                Default::default(),
            );
            let mut b =
                State::<u16>::scaled(&p1, &p2, strengths, true, &c.valid, term, 0.6, Default::default());
            let n = a.len();
            assert!(n > 50, "seed {seed}: too few points ({n})");
            let rngs =
                || (Xoshiro256PlusPlus::seed_from_u64(seed), Xoshiro256PlusPlus::seed_from_u64(seed + 9));
            let ((mut ma, mut ca), (mut mb, mut cb)) = (rngs(), rngs());
            assert_eq!(
                a.mean_uphill(&mut ma, 500).map(f64::to_bits),
                b.mean_uphill(&mut mb, 500).map(f64::to_bits)
            );
            for t in [5.0, 2.0, 1.0, 0.3, 0.1, 0.01, 0.0] {
                let acc = a.sweep(&mut ma, &mut ca, t, n);
                assert_eq!(acc, b.sweep(&mut mb, &mut cb, t, n), "seed {seed}, t {t}");
                assert_eq!(a.pos, b.pos, "seed {seed}, t {t}");
                assert_eq!(a.e_int.to_bits(), b.e_int.to_bits(), "seed {seed}, t {t}");
                assert_eq!(a.energy().to_bits(), b.energy().to_bits(), "seed {seed}, t {t}");
                assert!(a.cache_consistent(), "seed {seed}, t {t}: stale byte cache");
            }
            let pos = a.pos.clone();
            assert_eq!(a.recompute_at(&pos), b.recompute_at(&pos));
        }
    }

    #[test]
    fn every_instruction_set_gives_the_same_relaxation() {
        // Byte cells (the default cap) and u16 cells (a cap over √252 px).
        for (seed, t_d) in [(0u64, 9.0), (1, 3.0), (2, 16.0)] {
            let c = random_case(90, 60, 500 + seed);
            let params = Params { t_d_px: t_d, ..Params::default() };
            let run = || relax(&c.input(), &params, seed);
            let want = isa::with_isa(isa::Isa::Baseline, run).expect("baseline");
            assert!(want.1.moves_accepted > 0, "seed {seed}: nothing moved");
            for other in isa::Isa::available() {
                let got = isa::with_isa(other, run).expect("available");
                assert_eq!(got.0, want.0, "seed {seed}, {other:?}");
                assert_eq!(format!("{:?}", got.1), format!("{:?}", want.1), "seed {seed}, {other:?}");
            }
        }
    }

    #[test]
    fn fused_scaling_matches_scaled_grids() {
        for (seed, normalize) in [(1u64, true), (2, false), (3, true)] {
            let mut c = random_case(50, 40, seed);
            c.mag[(3, 4)] = f32::INFINITY;
            let (p1, p2) = prune(&c.c1, &c.c2, 3.0);
            let (s1n, magn) = (scaled(&c.s1, &p1, normalize), scaled(&c.mag, &p2, normalize));
            let ab = external_sum(&p1, &s1n, &p2, &magn);
            let term = || DistanceTerm::new(4.0);
            let a = State::<u8>::new(&p1, &p2, &s1n, &magn, &c.valid, term(), 1.0, ab);
            let b = State::<u8>::scaled(
                &p1,
                &p2,
                [&c.s1, &c.mag],
                normalize,
                &c.valid,
                term(),
                1.0,
                Default::default(),
            );
            assert_eq!(a.strengths(), b.strengths(), "seed {seed}");
            assert_eq!(a.pos, b.pos);
            assert_eq!(a.e_int, b.e_int);
            assert_eq!(b.energy(), a.e_int);
        }
    }

    #[test]
    fn prune_matches_edt_thresholding_on_wide_images() {
        for seed in 0..3 {
            let c = random_case(200, 23, 70 + seed);
            for t_d in [0.0, 1.0, 9.5, 20.0, 63.2, 64.0] {
                let (p1, p2) = prune(&c.c1, &c.c2, t_d);
                let d1 = distance::edt_squared(&c.c1);
                let want2 = Grid::from_fn(c.c2.width(), c.c2.height(), |x, y| {
                    c.c2[(x, y)] && d1[(x, y)] <= t_d * t_d
                });
                let d2 = distance::edt_squared(&want2);
                let want1 = Grid::from_fn(c.c1.width(), c.c1.height(), |x, y| {
                    c.c1[(x, y)] && d2[(x, y)] <= t_d * t_d
                });
                assert_eq!(p2, want2, "seed {seed}, t_d {t_d}");
                assert_eq!(p1, want1, "seed {seed}, t_d {t_d}");
            }
        }
    }

    #[test]
    fn prune_with_empty_c1_removes_everything() {
        let c = random_case(20, 20, 3);
        let (p1, p2) = prune(&Grid::new(20, 20, false), &c.c2, 3.0);
        assert_eq!(count(&p1) + count(&p2), 0);
    }

    #[test]
    fn prune_matches_edt_thresholding() {
        for seed in 0..6 {
            let c = random_case(37 + seed as u32, 29, seed);
            for t_d in [0.0, 1.0, 1.5, 2.9, 4.0, 7.3] {
                let (p1, p2) = prune(&c.c1, &c.c2, t_d);
                let t2 = t_d * t_d;
                let d1 = distance::edt_squared(&c.c1);
                let want2 =
                    Grid::from_fn(c.c2.width(), c.c2.height(), |x, y| c.c2[(x, y)] && d1[(x, y)] <= t2);
                let d2 = distance::edt_squared(&want2);
                let want1 =
                    Grid::from_fn(c.c1.width(), c.c1.height(), |x, y| c.c1[(x, y)] && d2[(x, y)] <= t2);
                assert_eq!(p2, want2, "seed {seed}, t_d {t_d}");
                assert_eq!(p1, want1, "seed {seed}, t_d {t_d}");
            }
        }
        let empty = Grid::new(9, 7, false);
        let full = Grid::new(9, 7, true);
        assert_eq!(prune(&full, &empty, 3.0), (empty.clone(), empty.clone()));
    }

    #[test]
    fn relax_reports_consistent_energies_and_keeps_point_counts() {
        let c = random_case(80, 60, 11);
        let params = Params::default();
        let (r, info) = relax(&c.input(), &params, 5);
        let (p1, p2) = prune(&c.c1, &c.c2, params.t_d_px);
        assert_eq!(count(&r.c1), count(&p1));
        assert_eq!(count(&r.c2), count(&p2));
        assert_eq!(info.removed_c1 as usize, count(&c.c1) - count(&p1));
        assert_eq!(info.removed_c2 as usize, count(&c.c2) - count(&p2));
        assert!(info.removed_c2 > 0, "clutter should be pruned");
        assert_eq!(info.e_external_before, 0.0);
        assert!(info.energy_after <= info.energy_before);
        assert!(info.energy_after < info.energy_before, "annealing should find a better state: {info:?}");
        assert!(info.sweeps >= 1 && info.moves_accepted > 0 && info.moves_tried >= info.moves_accepted);
        let e = energy(&r.c1, &c.s1, &r.c2, &c.mag, &p1, &p2, &params);
        assert_relative_eq!(e.total, info.energy_after, epsilon = 1e-9, max_relative = 1e-9);
        assert_relative_eq!(e.internal, info.e_internal_after, epsilon = 1e-9, max_relative = 1e-9);
        let e0 = energy(&p1, &c.s1, &p2, &c.mag, &p1, &p2, &params);
        assert_relative_eq!(e0.total, info.energy_before, epsilon = 1e-9, max_relative = 1e-9);
        let d1 = distance::edt_squared(&p1);
        let s2 = params.support_px * params.support_px;
        assert!(params.support_px > 0.0);
        let mut unsupported = 0;
        for (x, y, &b) in r.edges.enumerate() {
            let supported = r.c2[(x, y)] && d1[(x, y)] <= s2;
            unsupported += u32::from(r.c2[(x, y)] && !supported);
            assert_eq!(b, r.c1[(x, y)] || supported, "({x}, {y})");
            // Points only move onto valid pixels; the ones that never moved may sit anywhere.
            if (r.c1[(x, y)] && !p1[(x, y)]) || (r.c2[(x, y)] && !p2[(x, y)]) {
                assert!(c.valid[(x, y)], "a point moved onto invalid pixel ({x}, {y})");
            }
        }
        assert_eq!(info.unsupported_c2, unsupported);
        assert!(unsupported > 0, "the jittered copy should leave some C2 points unsupported");
    }

    #[test]
    fn relax_pulls_shifted_copies_together() {
        // C1: a vertical line pair at x = 20, 21; C2: a line at x = 23. Uniform strengths, so
        // only the distance term matters and relaxation must reduce it.
        let (w, h) = (40, 40);
        let c1 = Grid::from_fn(w, h, |x, _| x == 20 || x == 21);
        let c2 = Grid::from_fn(w, h, |x, _| x == 23);
        let ones = Grid::new(w, h, 1.0f32);
        let valid = Grid::new(w, h, true);
        let params = Params { lambda: 0.0, max_sweeps: 200, min_acceptance: 0.0, ..Params::default() };
        let (_, info) =
            relax(&Input { c1: &c1, s1: &ones, c2: &c2, magnitude: &ones, valid: &valid }, &params, 1);
        assert_relative_eq!(info.e_internal_before, 40.0 * (2.0 + 3.0));
        assert!(info.e_internal_after < 0.5 * info.e_internal_before, "{info:?}");
    }

    #[test]
    fn same_seed_same_output_at_any_thread_count() {
        let c = random_case(64, 64, 21);
        let params = Params::default();
        let run = |seed| relax(&c.input(), &params, seed);
        let (r0, i0) = run(9);
        for threads in [1, 2, 3] {
            let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().expect("pool");
            let (r, i) = pool.install(|| run(9));
            assert_eq!(r, r0, "{threads} threads");
            assert_eq!(i, i0, "{threads} threads");
        }
        let (r2, _) = run(10);
        assert_ne!(r2, r0, "different seeds should give different relaxations");
    }

    #[test]
    fn support_test_drops_only_far_c2_points() {
        // C1: a line at x = 10; C2: lines at x = 11 (1 px away) and x = 14 (4 px away, within
        // T_d = 5). No annealing, so the support test alone decides.
        let (w, h) = (30, 20);
        let c1 = Grid::from_fn(w, h, |x, _| x == 10);
        let c2 = Grid::from_fn(w, h, |x, _| x == 11 || x == 14);
        let ones = Grid::new(w, h, 1.0f32);
        let valid = Grid::new(w, h, true);
        let base = Params { t_d_px: 5.0, max_sweeps: 0, ..Params::default() };
        for (support, want_x) in [(2.0, vec![10, 11]), (4.0, vec![10, 11, 14]), (0.0, vec![10, 11, 14])] {
            let (r, info) = relax(
                &Input { c1: &c1, s1: &ones, c2: &c2, magnitude: &ones, valid: &valid },
                &Params { support_px: support, ..base.clone() },
                0,
            );
            assert_eq!(r.c2, c2, "support {support}: the annealed C2 keeps every point");
            let want = Grid::from_fn(w, h, |x, _| want_x.contains(&x));
            assert_eq!(r.edges, want, "support {support}");
            assert_eq!(info.unsupported_c2, (3 - want_x.len() as u32) * h, "support {support}");
        }
    }

    #[test]
    fn zero_sweeps_only_prunes() {
        let c = random_case(50, 50, 4);
        let params = Params { max_sweeps: 0, ..Params::default() };
        let (r, info) = relax(&c.input(), &params, 0);
        let (p1, p2) = prune(&c.c1, &c.c2, params.t_d_px);
        assert_eq!((r.c1, r.c2), (p1, p2));
        assert_eq!(info.energy_after, info.energy_before);
        assert_eq!(info.moves_tried, 0);
    }

    #[test]
    fn empty_input_is_fine() {
        let e = Grid::new(8, 6, false);
        let z = Grid::new(8, 6, 0.0f32);
        let (r, info) = relax(
            &Input { c1: &e, s1: &z, c2: &e, magnitude: &z, valid: &Grid::new(8, 6, true) },
            &Params::default(),
            0,
        );
        assert_eq!(count(&r.edges), 0);
        assert_eq!(info.energy_after, 0.0);
    }

    #[test]
    fn params_default_validates_and_round_trips() {
        let p = Params::default();
        assert_eq!(p.validate(), Ok(()));
        let back: Params = serde_json::from_str(&serde_json::to_string(&p).unwrap()).unwrap();
        assert_eq!(back, p);
        assert!(Params { cooling_delta: 1.0, ..p.clone() }.validate().is_err());
        assert!(Params { lambda: f64::NAN, ..p.clone() }.validate().is_err());
        assert!(Params { support_px: -1.0, ..p.clone() }.validate().is_err());
        assert!(serde_json::from_str::<Params>(r#"{"t_d": 2}"#).is_err());
        assert_eq!(serde_json::from_str::<Params>(r#"{"lambda": 2.0}"#).unwrap().t_d_px, p.t_d_px);
    }

    mod proptests {
        use super::*;
        use proptest::prelude::*;

        proptest! {
            #![proptest_config(ProptestConfig::with_cases(24))]
            #[test]
            fn proptest_energy_never_increases(
                w in 8u32..60, h in 8u32..60, seed in 0u64..1000, lambda in 0.0f64..3.0,
                t_d in 0.0f64..5.0, t0 in prop_oneof![Just(0.0), 0.01f64..10.0], normalize in any::<bool>(),
            ) {
                let c = random_case(w, h, seed);
                let params = Params { t_d_px: t_d, lambda, t0, normalize, max_sweeps: 15, ..Params::default() };
                let (r, info) = relax(&c.input(), &params, seed);
                prop_assert!(info.energy_after <= info.energy_before, "{:?}", info);
                let (p1, p2) = prune(&c.c1, &c.c2, t_d);
                let e = energy(&r.c1, &c.s1, &r.c2, &c.mag, &p1, &p2, &params);
                let e0 = energy(&p1, &c.s1, &p2, &c.mag, &p1, &p2, &params);
                prop_assert!(e.total <= e0.total + 1e-9 * e0.total.abs().max(1.0), "{} > {}", e.total, e0.total);
            }
        }
    }
}
