//! Run-time choice of the instruction set the kernels run with.
//!
//! The kernels are written once, generic over a [`Level`], with every function on the path from
//! a query's entry to a lane operation `#[inline(always)]`. A query's entry (the `dispatch!`
//! macro in `bvh/traverse.rs`, and the few walks that were `#[inline(never)]` boundaries) calls
//! [`Level::call`], which for [`Avx2`] is a function compiled with
//! `#[target_feature(enable = "avx2,fma,…")]`: everything inlined into it — the whole walk — is
//! compiled for AVX2 and FMA, whatever the crate was built for. The choice is made once per
//! process from the CPU's features ([`Isa::best`]), can be forced with the environment variable
//! `STRAHL_ISA` (`avx2`, `baseline`) or [`set_isa`], and is visible as [`isa`] (and in
//! `BuildStats`).
//!
//! This module and `lanes.rs` hold the only ISA-specific code of the kernels.

use core::sync::atomic::{AtomicU8, Ordering};

/// An instruction-set level strahl's kernels are compiled for, chosen at run time.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[non_exhaustive]
pub enum Isa {
    /// What the crate itself is compiled for: SSE2 on a default x86-64 build (no FMA; packets of
    /// 16 run as four 4-lane operations), NEON on aarch64.
    Baseline,
    /// x86-64-v3: AVX2, FMA, BMI1/2, LZCNT (Intel Haswell, AMD Excavator and later): 8-lane
    /// operations, fused multiply-adds.
    Avx2,
}

impl Isa {
    /// Every level, from the baseline up.
    pub const ALL: [Isa; 2] = [Isa::Baseline, Isa::Avx2];

    /// The level's name, as `STRAHL_ISA` spells it.
    pub fn name(self) -> &'static str {
        match self {
            Isa::Baseline => "baseline",
            Isa::Avx2 => "avx2",
        }
    }

    /// The level named `s` (`baseline` or `avx2`, any case), if there is one.
    pub fn from_name(s: &str) -> Option<Isa> {
        Isa::ALL.into_iter().find(|i| i.name().eq_ignore_ascii_case(s.trim()))
    }

    /// Whether this processor can run the level.
    pub fn supported(self) -> bool {
        match self {
            Isa::Baseline => true,
            Isa::Avx2 => avx2_detected(),
        }
    }

    /// The fastest level this processor runs.
    pub fn best() -> Isa {
        if Isa::Avx2.supported() { Isa::Avx2 } else { Isa::Baseline }
    }

    /// Whether the level's multiply-adds are fused (one rounding): the one way results differ
    /// between levels (by float rounding only).
    pub fn fused_multiply_add(self) -> bool {
        match self {
            Isa::Baseline => Base::FMA,
            Isa::Avx2 => Avx2::FMA,
        }
    }
}

impl core::fmt::Display for Isa {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(self.name())
    }
}

#[cfg(target_arch = "x86_64")]
fn avx2_detected() -> bool {
    std::arch::is_x86_feature_detected!("avx2")
        && std::arch::is_x86_feature_detected!("fma")
        && std::arch::is_x86_feature_detected!("bmi1")
        && std::arch::is_x86_feature_detected!("bmi2")
        && std::arch::is_x86_feature_detected!("lzcnt")
        && std::arch::is_x86_feature_detected!("popcnt")
}

#[cfg(not(target_arch = "x86_64"))]
fn avx2_detected() -> bool {
    false
}

/// The active level: 0 until first asked, else `1 + index in Isa::ALL`.
static ACTIVE: AtomicU8 = AtomicU8::new(0);

fn encode(isa: Isa) -> u8 {
    match isa {
        Isa::Baseline => 1,
        Isa::Avx2 => 2,
    }
}

/// The level the kernels run with: [`Isa::best`] unless `STRAHL_ISA` or [`set_isa`] chose
/// another. A `STRAHL_ISA` naming an unknown level or one this processor cannot run is ignored
/// with a message on standard error, never a crash.
#[inline]
pub fn isa() -> Isa {
    match ACTIVE.load(Ordering::Relaxed) {
        1 => Isa::Baseline,
        2 => Isa::Avx2,
        _ => init(),
    }
}

#[cold]
fn init() -> Isa {
    let chosen = match std::env::var("STRAHL_ISA") {
        Ok(name) if !name.trim().is_empty() => match Isa::from_name(&name) {
            Some(i) if i.supported() => i,
            Some(i) => {
                eprintln!("strahl: STRAHL_ISA={name}: this processor cannot run {i}; using {}", Isa::best());
                Isa::best()
            }
            None => {
                eprintln!("strahl: STRAHL_ISA={name} names no level (baseline, avx2); using {}", Isa::best());
                Isa::best()
            }
        },
        _ => Isa::best(),
    };
    // A concurrent first call may have stored its own (equal) choice, or `set_isa` a forced one:
    // keep whichever came first.
    match ACTIVE.compare_exchange(0, encode(chosen), Ordering::Relaxed, Ordering::Relaxed) {
        Ok(_) => chosen,
        Err(_) => isa(),
    }
}

/// Forces the kernels' level for the rest of the process (for tests and benchmarks). Queries
/// already running finish with the level they started with.
pub fn set_isa(isa: Isa) -> crate::Result<()> {
    if !isa.supported() {
        return Err(crate::Error::UnsupportedIsa(isa.name()));
    }
    ACTIVE.store(encode(isa), Ordering::Relaxed);
    Ok(())
}

/// A multiply-add that may be fused: `f32` and the float lane types.
pub(crate) trait Fusable:
    Copy + core::ops::Mul<Output = Self> + core::ops::Add<Output = Self> + core::ops::Sub<Output = Self>
{
    /// `self·b + c` with one rounding; only called where the enclosing code runs with FMA.
    fn fused(self, b: Self, c: Self) -> Self;
    /// `-c`.
    fn negated(self) -> Self;
}

impl Fusable for f32 {
    #[inline(always)]
    fn fused(self, b: Self, c: Self) -> Self {
        self.mul_add(b, c)
    }
    #[inline(always)]
    fn negated(self) -> Self {
        -self
    }
}

macro_rules! fusable {
    ($($t:ty),*) => {$(
        impl Fusable for $t {
            #[inline(always)]
            fn fused(self, b: Self, c: Self) -> Self {
                self.fused_mul_add(b, c)
            }
            #[inline(always)]
            fn negated(self) -> Self {
                -self
            }
        }
    )*};
}
fusable!(super::f32x4, super::f32x8, super::f32x16);

/// An instruction-set level as a type: what the kernels are generic over. Implemented by
/// [`Base`] and [`Avx2`] only; code generic over `L` runs with `L`'s features because every
/// entry into it goes through [`Level::call`].
pub(crate) trait Level: Copy + 'static {
    /// Whether [`madd`](Self::madd) fuses.
    const FMA: bool;

    /// `a·b + c`: fused (one rounding) on a level with FMA, a multiply then an add elsewhere
    /// (Embree's `madd`).
    #[inline(always)]
    fn madd<T: Fusable>(a: T, b: T, c: T) -> T {
        if Self::FMA { a.fused(b, c) } else { a * b + c }
    }

    /// `a·b − c` (Embree's `msub`).
    #[inline(always)]
    fn msub<T: Fusable>(a: T, b: T, c: T) -> T {
        if Self::FMA { a.fused(b, c.negated()) } else { a * b - c }
    }

    /// Runs `f` in a function of its own compiled for this level; `f` (a closure over a walk
    /// whose functions are all `#[inline(always)]`) is inlined into it. Never inlined into a
    /// caller compiled for less, so this is also the walk's `#[inline(never)]` boundary.
    fn call<R>(f: impl FnOnce() -> R) -> R;
}

/// The baseline level (see [`Isa::Baseline`]).
#[derive(Clone, Copy, Debug)]
pub(crate) enum Base {}

impl Level for Base {
    /// Fused only where the crate is compiled with FMA (a native build, or aarch64, whose
    /// baseline has it); else `mul_add` would be a slow library call.
    const FMA: bool = cfg!(any(target_feature = "fma", target_arch = "aarch64"));

    #[inline(always)]
    fn call<R>(f: impl FnOnce() -> R) -> R {
        run_base(f)
    }
}

#[inline(never)]
fn run_base<R>(f: impl FnOnce() -> R) -> R {
    f()
}

/// The AVX2 + FMA level (see [`Isa::Avx2`]).
#[derive(Clone, Copy, Debug)]
pub(crate) enum Avx2 {}

impl Level for Avx2 {
    const FMA: bool = true;

    #[inline(always)]
    fn call<R>(f: impl FnOnce() -> R) -> R {
        #[cfg(target_arch = "x86_64")]
        {
            debug_assert!(avx2_detected());
            // SAFETY: `run_avx2` needs AVX2, FMA, BMI1, BMI2, LZCNT and POPCNT. Code generic over
            // a `Level` is instantiated with `Avx2` only in `with_level!`'s `Isa::Avx2` arm, which
            // runs only when `isa()` returned `Isa::Avx2`, and `isa()` returns it only after
            // `avx2_detected()` found all six features (`init` and `set_isa` check
            // `supported()`). `Avx2` has no values and `Level` is crate-private, so no other code
            // can reach this with the level chosen otherwise.
            unsafe { run_avx2(f) }
        }
        #[cfg(not(target_arch = "x86_64"))]
        {
            f()
        }
    }
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma,bmi1,bmi2,lzcnt,popcnt")]
#[inline]
fn run_avx2<R>(f: impl FnOnce() -> R) -> R {
    f()
}

/// Evaluates `$body` with `$l` bound to the [`Level`] type of the active [`Isa`], inside
/// [`Level::call`] (so compiled for that level).
macro_rules! with_level {
    (|$l:ident| $body:expr) => {
        match $crate::simd::isa() {
            $crate::simd::Isa::Avx2 => {
                type $l = $crate::simd::Avx2;
                <$l as $crate::simd::Level>::call(|| $body)
            }
            _ => {
                type $l = $crate::simd::Base;
                <$l as $crate::simd::Level>::call(|| $body)
            }
        }
    };
}
pub(crate) use with_level;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_round_trip_and_the_best_level_is_supported() {
        for i in Isa::ALL {
            assert_eq!(Isa::from_name(i.name()), Some(i));
            assert_eq!(Isa::from_name(&i.name().to_uppercase()), Some(i));
        }
        assert_eq!(Isa::from_name("avx9000"), None);
        assert!(Isa::best().supported());
        assert!(Isa::Baseline.supported());
        assert!(isa().supported());
    }

    #[test]
    fn multiply_add_fuses_only_where_the_level_says() {
        // 1 + 2⁻²³ squared is 1 + 2⁻²² + 2⁻⁴⁶: the last term survives only in a fused result.
        let a = 1.0 + f32::EPSILON;
        let c = -(1.0 + 2.0 * f32::EPSILON);
        let fused = Avx2::madd(a, a, c);
        let base = Base::madd(a, a, c);
        if Base::FMA {
            assert_eq!(base, fused);
        } else {
            assert_eq!(base, 0.0, "a·a rounds to 1 + 2⁻²², which c cancels");
        }
        if Isa::Avx2.supported() {
            assert_eq!(<Avx2 as Level>::call(|| Avx2::madd(a, a, c)), 2f32.powi(-46));
        }
    }
}
