//! Run-time choice of the instruction set for the stages' per-pixel loops.
//!
//! The default build targets baseline x86-64, so one binary or wheel runs on any x86-64 CPU. A stage wraps a
//! hot loop in [`dispatch`]: the loop is compiled a second time with the x86-64-v3 features (AVX, AVX2, FMA,
//! BMI1/2, LZCNT; pulp's `V3`) and that copy runs when the CPU has them. Only code inlined into pulp's
//! target-feature function is compiled for those features: the closure itself must be `#[inline(always)]`
//! (`isa::dispatch(#[inline(always)] || kernel(..))`, allowed in argument position), and so must `kernel` and
//! what it calls in the hot loop; a function left out of line runs its baseline code (a profile shows it by
//! name next to `pulp::x86::v3::V3::vectorize::imp`).
//!
//! Every path gives the same bits: Rust never contracts `a * b + c` into an FMA, never reorders a float
//! reduction, and `mul_add`, `sqrt` and the libm calls are correctly rounded or the same call on every path.
//! Each stage has a test that runs its kernels on every path of [`Isa::available`] with [`with_isa`] and
//! compares the outputs bit for bit.

use std::cell::Cell;
use std::sync::atomic::{AtomicU8, Ordering};

/// An instruction set the dispatched loops are compiled for.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Isa {
    /// The features the whole build targets (baseline x86-64: SSE2), the only path on other architectures.
    Baseline,
    /// x86-64-v3 (AVX, AVX2, FMA, BMI1/2, LZCNT), on x86-64 CPUs that have it (Intel since 2013, AMD since 2015).
    V3,
}

impl Isa {
    /// Every instruction set, fastest last.
    pub const ALL: [Isa; 2] = [Isa::Baseline, Isa::V3];

    /// Whether this CPU can run `self`'s path.
    pub fn is_available(self) -> bool {
        match self {
            Isa::Baseline => true,
            Isa::V3 => v3_available(),
        }
    }

    /// The instruction sets this CPU can run, fastest last.
    pub fn available() -> Vec<Isa> {
        Isa::ALL.into_iter().filter(|i| i.is_available()).collect()
    }

    /// The lowercase name: `baseline`, `v3`.
    pub fn name(self) -> &'static str {
        match self {
            Isa::Baseline => "baseline",
            Isa::V3 => "v3",
        }
    }

    /// Parses [`Isa::name`].
    pub fn from_name(name: &str) -> Option<Isa> {
        Isa::ALL.into_iter().find(|i| i.name() == name)
    }
}

#[cfg(target_arch = "x86_64")]
fn v3_available() -> bool {
    pulp::x86::V3::try_new().is_some()
}

#[cfg(not(target_arch = "x86_64"))]
fn v3_available() -> bool {
    false
}

/// The process-wide ceiling ([`set_limit`]), as `Isa as u8`.
static LIMIT: AtomicU8 = AtomicU8::new(Isa::V3 as u8);

thread_local! {
    /// The instruction set [`with_isa`] imposes on this thread.
    static FORCED: Cell<Option<Isa>> = const { Cell::new(None) };
}

/// Caps the instruction set of every later [`dispatch`] in the process (e.g. from the `RANGESEG_ISA`
/// environment variable, read by the binaries): `Isa::Baseline` runs the baseline code everywhere.
pub fn set_limit(isa: Isa) {
    LIMIT.store(isa as u8, Ordering::Relaxed);
}

/// Applies the `RANGESEG_ISA` environment variable (`baseline` or `v3`), if set, with [`set_limit`] and returns
/// it; the binaries call this first. An unknown value is an error naming it.
pub fn limit_from_env() -> Result<Option<Isa>, String> {
    let Some(value) = std::env::var_os("RANGESEG_ISA") else {
        return Ok(None);
    };
    let value = value.to_string_lossy();
    let isa = Isa::from_name(value.trim())
        .ok_or_else(|| format!("RANGESEG_ISA={value}: expected one of baseline, v3"))?;
    set_limit(isa);
    Ok(Some(isa))
}

/// The instruction set [`dispatch`] uses on this thread now: the one [`with_isa`] imposes, else the fastest
/// available one within [`set_limit`]'s ceiling.
pub fn selected() -> Isa {
    if let Some(isa) = FORCED.get() {
        return isa;
    }
    let limit = LIMIT.load(Ordering::Relaxed);
    Isa::ALL.into_iter().rev().find(|i| *i as u8 <= limit && i.is_available()).unwrap_or(Isa::Baseline)
}

/// Runs `f` with every [`dispatch`] on this thread using `isa`'s path; `None` if this CPU cannot run it.
/// For tests and benchmarks that compare the paths.
pub fn with_isa<R>(isa: Isa, f: impl FnOnce() -> R) -> Option<R> {
    /// Restores the previous choice when `f` returns or unwinds.
    struct Restore(Option<Isa>);
    impl Drop for Restore {
        fn drop(&mut self) {
            FORCED.set(self.0);
        }
    }
    if !isa.is_available() {
        return None;
    }
    let _restore = Restore(FORCED.replace(Some(isa)));
    Some(f())
}

/// Runs `kernel` compiled for the [`selected`] instruction set. Pass an `#[inline(always)]` closure and mark the
/// functions of the loop `#[inline(always)]`: only what is inlined is compiled for it (see the crate docs).
#[inline(always)]
pub fn dispatch<R>(kernel: impl FnOnce() -> R) -> R {
    #[cfg(target_arch = "x86_64")]
    if selected() == Isa::V3
        && let Some(simd) = pulp::x86::V3::try_new()
    {
        return simd.vectorize(kernel);
    }
    kernel()
}

/// Asks the CPU to start loading the cache line of `slice[i]` into its caches (x86-64 `prefetcht0`; nothing on
/// other architectures). A hint: it reads nothing into the program and changes no result, and an index out of
/// bounds is allowed (no fault, no effect on results). Unlike a plain load it does not hold up the instructions
/// after it while the line arrives.
#[inline(always)]
pub fn prefetch<T>(slice: &[T], i: usize) {
    #[cfg(target_arch = "x86_64")]
    if let Some(sse) = pulp::core_arch::x86::Sse::try_new() {
        sse._mm_prefetch::<{ core::arch::x86_64::_MM_HINT_T0 }>(slice.as_ptr().wrapping_add(i).cast());
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = (slice, i);
}

#[cfg(test)]
mod tests {
    use super::*;

    #[inline(always)]
    fn dot(a: &[f32], b: &[f32]) -> f32 {
        a.iter().zip(b).map(|(x, y)| x * y).sum()
    }

    #[test]
    fn with_isa_selects_and_restores() {
        let before = selected();
        for isa in Isa::available() {
            assert_eq!(with_isa(isa, selected), Some(isa));
            assert_eq!(selected(), before);
        }
        assert_eq!(with_isa(Isa::Baseline, || with_isa(Isa::Baseline, selected)), Some(Some(Isa::Baseline)));
        assert!(Isa::available().contains(&Isa::Baseline));
    }

    #[test]
    fn every_path_gives_the_same_bits() {
        let a: Vec<f32> = (0..1000).map(|i| (i as f32 * 0.37).sin()).collect();
        let b: Vec<f32> = (0..1000).map(|i| (i as f32 * 0.11).cos() * 3.0).collect();
        let sums: Vec<u32> = Isa::available()
            .into_iter()
            .map(|isa| {
                with_isa(isa, || {
                    dispatch(
                        #[inline(always)]
                        || dot(&a, &b),
                    )
                })
                .expect("available")
                .to_bits()
            })
            .collect();
        assert!(sums.windows(2).all(|w| w[0] == w[1]), "{sums:?}");
    }

    #[test]
    fn names_round_trip() {
        for isa in Isa::ALL {
            assert_eq!(Isa::from_name(isa.name()), Some(isa));
        }
        assert_eq!(Isa::from_name("avx512"), None);
    }
}
