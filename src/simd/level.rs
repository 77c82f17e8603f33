//! Run-time choice of the instruction set the kernels run with (issue 32).
//!
//! The triangle and box kernels are written once, generic over a [`Level`]: its lane types
//! (four, eight and sixteen floats) and its [`Level::call`], the function every walk is entered
//! through. Three levels exist:
//! - [`Native`]: `wide`'s types, compiled for what the crate itself is compiled for. With the
//!   repository's `-C target-cpu=native` that is the machine's best; in a default build (a crate
//!   that depends on strahl) it is SSE2 on x86-64.
//! - [`Avx2`] and [`Avx512`] (x86-64): lanes on `core::arch` vectors, entered through functions
//!   compiled with `#[target_feature]`, so that everything inlined into them runs with AVX2 and
//!   FMA, or AVX-512, whatever the crate was compiled for.
//!
//! [`isa`] picks once per process the level that runs widest on this processor, preferring
//! [`Native`] when the crate was already compiled for at least that width (its code is then
//! `wide`'s own, unchanged). The environment variable `STRAHL_ISA` (`compiled`, `avx2`,
//! `avx512`) or [`set_isa`] forces one, for tests and benchmarks.

use core::sync::atomic::{AtomicU8, Ordering};

use super::{BitOrder, Four, Packet, SimdF};

/// An instruction-set level strahl's kernels run with.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[non_exhaustive]
pub enum Isa {
    /// `wide`'s lanes as the crate was compiled: see [`Isa::compiled_features`].
    Compiled,
    /// AVX2 and FMA (x86-64-v3: Intel Haswell, AMD Zen and later), chosen at run time: 8-lane
    /// node tests, packets of 16 as two 8-lane halves, fused multiply-adds.
    Avx2,
    /// AVX-512 F/VL/DQ/BW with AVX2 and FMA (x86-64-v4: Intel Skylake-SP, AMD Zen 4 and later),
    /// chosen at run time: packets of 16 in one register.
    Avx512,
}

impl Isa {
    /// Every level.
    pub const ALL: [Isa; 3] = [Isa::Compiled, Isa::Avx2, Isa::Avx512];

    /// The level's name, as `STRAHL_ISA` spells it.
    pub fn name(self) -> &'static str {
        match self {
            Isa::Compiled => "compiled",
            Isa::Avx2 => "avx2",
            Isa::Avx512 => "avx512",
        }
    }

    /// The level named `s` (any case), if there is one.
    pub fn from_name(s: &str) -> Option<Isa> {
        Isa::ALL.into_iter().find(|i| i.name().eq_ignore_ascii_case(s.trim()))
    }

    /// What the crate itself was compiled for, as the compiled level's lanes use it: `avx512`,
    /// `avx2+fma`, `avx`, `sse2` or `neon` (or `scalar`).
    pub fn compiled_features() -> &'static str {
        if cfg!(target_feature = "avx512f") {
            "avx512"
        } else if cfg!(all(target_feature = "avx2", target_feature = "fma")) {
            "avx2+fma"
        } else if cfg!(target_feature = "avx") {
            "avx"
        } else if cfg!(target_feature = "sse2") {
            "sse2"
        } else if cfg!(target_feature = "neon") {
            "neon"
        } else {
            "scalar"
        }
    }

    /// Lanes per vector operation at this level (on this build): 16, 8 or 4.
    pub fn width(self) -> usize {
        match self {
            Isa::Compiled => {
                if cfg!(target_feature = "avx512f") {
                    16
                } else if cfg!(target_feature = "avx") {
                    8
                } else {
                    4
                }
            }
            Isa::Avx2 => 8,
            Isa::Avx512 => 16,
        }
    }

    /// Whether this processor can run the level.
    pub fn supported(self) -> bool {
        match self {
            Isa::Compiled => true,
            Isa::Avx2 => avx2_detected(),
            Isa::Avx512 => avx512_detected(),
        }
    }

    /// The level that runs widest here: the compiled one unless the processor runs a wider
    /// level than the crate was compiled for.
    pub fn best() -> Isa {
        let compiled = Isa::Compiled.width();
        if Isa::Avx512.supported() && compiled < 16 {
            Isa::Avx512
        } else if Isa::Avx2.supported() && compiled < 8 {
            Isa::Avx2
        } else {
            Isa::Compiled
        }
    }

    /// Whether the level's multiply-adds are fused (one rounding): the one way results differ
    /// between levels (by float rounding only).
    pub fn fused_multiply_add(self) -> bool {
        match self {
            Isa::Compiled => Native::FMA,
            Isa::Avx2 | Isa::Avx512 => true,
        }
    }
}

impl core::fmt::Display for Isa {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Isa::Compiled => write!(f, "compiled ({})", Isa::compiled_features()),
            other => f.write_str(other.name()),
        }
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

#[cfg(target_arch = "x86_64")]
fn avx512_detected() -> bool {
    avx2_detected()
        && std::arch::is_x86_feature_detected!("avx512f")
        && std::arch::is_x86_feature_detected!("avx512vl")
        && std::arch::is_x86_feature_detected!("avx512dq")
        && std::arch::is_x86_feature_detected!("avx512bw")
}

#[cfg(not(target_arch = "x86_64"))]
fn avx2_detected() -> bool {
    false
}

#[cfg(not(target_arch = "x86_64"))]
fn avx512_detected() -> bool {
    false
}

/// The active level: 0 until first asked, else `1 +` its index in [`Isa::ALL`].
static ACTIVE: AtomicU8 = AtomicU8::new(0);

fn encode(isa: Isa) -> u8 {
    match isa {
        Isa::Compiled => 1,
        Isa::Avx2 => 2,
        Isa::Avx512 => 3,
    }
}

/// The level the kernels run with: [`Isa::best`] unless `STRAHL_ISA` or [`set_isa`] chose
/// another. A `STRAHL_ISA` naming an unknown level or one this processor cannot run is ignored
/// with a message on standard error, never a crash.
#[inline]
pub fn isa() -> Isa {
    match ACTIVE.load(Ordering::Relaxed) {
        1 => Isa::Compiled,
        2 => Isa::Avx2,
        3 => Isa::Avx512,
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
                eprintln!("strahl: STRAHL_ISA={name} names no level (compiled, avx2, avx512); using {}", Isa::best());
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

/// An instruction-set level as a type: what the kernels are generic over. Code generic over `L`
/// runs with `L`'s features because every entry into it goes through [`Level::call`].
pub(crate) trait Level: Copy + Send + Sync + 'static {
    /// Four lanes: one ray against a block of four triangles.
    type F4: Four;
    /// One lane per child of a BVH node.
    type Nf: SimdF<Arr = [f32; 8]> + BitOrder;
    /// One lane per ray of a packet.
    type Pf: Packet;
    /// Whether multiply-adds fuse.
    const FMA: bool;

    /// Runs `f` compiled for this level: `f` (a closure over a walk whose functions are all
    /// `#[inline(always)]`) is inlined into a function compiled with the level's target
    /// features. Functions generic over a level that are not inlined (`#[inline(never)]`
    /// boundaries of a walk) wrap their bodies in it.
    fn call<R>(f: impl FnOnce() -> R) -> R;
}

/// The compiled level (see [`Isa::Compiled`]).
#[derive(Clone, Copy, Debug)]
pub(crate) enum Native {}

impl Level for Native {
    type F4 = wide::f32x4;
    type Nf = wide::f32x8;
    type Pf = wide::f32x16;
    const FMA: bool = cfg!(any(target_feature = "fma", target_arch = "aarch64"));

    #[inline(always)]
    fn call<R>(f: impl FnOnce() -> R) -> R {
        f()
    }
}

/// The AVX2 + FMA level (see [`Isa::Avx2`]).
#[cfg(target_arch = "x86_64")]
#[derive(Clone, Copy, Debug)]
pub(crate) enum Avx2 {}

#[cfg(target_arch = "x86_64")]
impl Level for Avx2 {
    type F4 = super::x86::V4;
    type Nf = super::x86::V8;
    type Pf = super::x86::W16;
    const FMA: bool = true;

    #[inline(always)]
    fn call<R>(f: impl FnOnce() -> R) -> R {
        debug_assert!(avx2_detected());
        // SAFETY: `run_avx2` needs AVX2, FMA, BMI1, BMI2, LZCNT and POPCNT. Code generic over a
        // level is instantiated with `Avx2` only in `with_level!`'s `Isa::Avx2` arm, which runs
        // only when `isa()` returned `Isa::Avx2`; `isa()` returns it only after
        // `avx2_detected()` found all six features (`init` and `set_isa` check `supported()`).
        // `Avx2` has no values and `Level` is crate-private, so no other code reaches this.
        unsafe { run_avx2(f) }
    }
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma,bmi1,bmi2,lzcnt,popcnt")]
#[inline]
fn run_avx2<R>(f: impl FnOnce() -> R) -> R {
    f()
}

/// The AVX-512 level (see [`Isa::Avx512`]).
#[cfg(target_arch = "x86_64")]
#[derive(Clone, Copy, Debug)]
pub(crate) enum Avx512 {}

#[cfg(target_arch = "x86_64")]
impl Level for Avx512 {
    type F4 = super::x86::V4;
    type Nf = super::x86::V8;
    type Pf = super::x86::V16;
    const FMA: bool = true;

    #[inline(always)]
    fn call<R>(f: impl FnOnce() -> R) -> R {
        debug_assert!(avx512_detected());
        // SAFETY: as for `Avx2::call`, with `avx512_detected()` (which includes all of
        // `avx2_detected()`) checked before `isa()` returns `Isa::Avx512`.
        unsafe { run_avx512(f) }
    }
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,avx512vl,avx512dq,avx512bw,avx2,fma,bmi1,bmi2,lzcnt,popcnt")]
#[inline]
fn run_avx512<R>(f: impl FnOnce() -> R) -> R {
    f()
}

/// Evaluates `$body` with `$l` bound to the [`Level`] type of the active [`Isa`]. The body's
/// non-inlined functions enter the level through [`Level::call`].
macro_rules! with_level {
    (|$l:ident| $body:expr) => {
        match $crate::simd::isa() {
            #[cfg(target_arch = "x86_64")]
            $crate::simd::Isa::Avx512 => {
                type $l = $crate::simd::Avx512;
                $body
            }
            #[cfg(target_arch = "x86_64")]
            $crate::simd::Isa::Avx2 => {
                type $l = $crate::simd::Avx2;
                $body
            }
            _ => {
                type $l = $crate::simd::Native;
                $body
            }
        }
    };
}
pub(crate) use with_level;

#[cfg(test)]
mod tests {
    use super::*;

    /// Awkward inputs: signed zeros, infinities, NaN, denormal-sized and huge values.
    const VALUES: [f32; 16] = [
        0.0,
        -0.0,
        1.0,
        -1.5,
        3.25,
        f32::INFINITY,
        f32::NEG_INFINITY,
        f32::NAN,
        1e-30,
        -1e30,
        7.0,
        0.5,
        -2.0,
        2.0,
        1e20,
        -0.25,
    ];

    /// Every lane operation of level `L` on rotations of [`VALUES`], as result bits (NaNs
    /// collapsed to one pattern: the operations may differ in NaN payloads).
    fn bits(x: f32) -> u32 {
        if x.is_nan() { 0x7fc0_0000 } else { x.to_bits() }
    }

    fn put<V: SimdF>(out: &mut Vec<u32>, v: V) {
        out.extend(v.to_array().as_ref().iter().map(|&x| bits(x)));
    }

    fn lane_results<L: Level>() -> Vec<u32> {
        let mut out = Vec::new();
        for shift in 0..16 {
            let a: [f32; 16] = core::array::from_fn(|i| VALUES[(i + shift) % 16]);
            let b: [f32; 16] = core::array::from_fn(|i| VALUES[(i * 7 + shift + 3) % 16]);
            let c: [f32; 16] = core::array::from_fn(|i| VALUES[(i * 5 + shift + 1) % 16]);
            let (x, y, z) = (L::Pf::new(a), L::Pf::new(b), L::Pf::new(c));
            put(&mut out, x + y);
            put(&mut out, x - y);
            put(&mut out, x * y);
            put(&mut out, x / y);
            put(&mut out, -x);
            put(&mut out, x.abs());
            put(&mut out, x.sqrt());
            put(&mut out, x.copysign(y));
            put(&mut out, x.fast_min(y));
            put(&mut out, x.fast_max(y));
            for m in [x.simd_lt(y), x.simd_le(y), x.simd_gt(y), x.simd_ge(y), x.simd_eq(y), x.simd_ne(y)] {
                put(&mut out, m);
                put(&mut out, m.select(x, y));
                put(&mut out, !m & x);
                put(&mut out, m | (x ^ y));
                out.push(m.to_bitmask());
            }
            if L::FMA && Native::FMA {
                put(&mut out, x.mul_add(y, z));
                put(&mut out, x.mul_sub(y, z));
            }
            put(&mut out, x.max_bits(y));
            put(&mut out, x.min_bits(y));
            put(&mut out, x.le_mask(y));
            out.push(x.le_bits(y));
            put(&mut out, L::Pf::lane_mask(0xa5c3 >> (shift % 4)));
            let finite = x.simd_lt(L::Pf::splat(f32::INFINITY)) & x.simd_gt(L::Pf::splat(f32::NEG_INFINITY));
            let finite = finite & x.simd_eq(x);
            out.push(bits(finite.select(x, L::Pf::splat(1.0)).hmin()));
            out.push(bits(finite.select(x, L::Pf::splat(1.0)).hmax()));
            let (n8, m8) = (L::Nf::new(a[..8].try_into().unwrap()), L::Nf::new(b[8..].try_into().unwrap()));
            out.extend((n8.mul_sub(m8, n8) * m8).to_array().map(bits).iter().take(if L::FMA && Native::FMA {
                8
            } else {
                0
            }));
            out.extend(n8.max_bits(m8).to_array().map(bits));
            out.extend(n8.min_bits(m8).to_array().map(bits));
            out.push(n8.le_bits(m8));
            out.push(n8.simd_le(m8).to_bitmask());
            let f4 = L::F4::new(a[..4].try_into().unwrap());
            let finite4 = f4.simd_lt(L::F4::splat(f32::INFINITY)) & f4.simd_eq(f4);
            let f4 = finite4.select(f4, L::F4::splat(9.0));
            out.extend(f4.abs().sqrt().to_array().map(bits));
            out.extend(n8.abs().sqrt().to_array().map(bits));
            out.push(bits(f4.min4()));
            out.extend((0..4).map(|l| bits(f4.lane4(l))));
        }
        out
    }

    #[test]
    fn every_level_computes_what_wide_computes() {
        let native = lane_results::<Native>();
        #[cfg(target_arch = "x86_64")]
        {
            if Isa::Avx2.supported() {
                assert_eq!(Avx2::call(lane_results::<Avx2>), native, "avx2");
            }
            if Isa::Avx512.supported() {
                assert_eq!(Avx512::call(lane_results::<Avx512>), native, "avx512");
            }
        }
        assert!(native.len() > 1000);
    }

    #[test]
    fn names_round_trip_and_the_best_level_is_supported() {
        for i in Isa::ALL {
            assert_eq!(Isa::from_name(i.name()), Some(i));
            assert_eq!(Isa::from_name(&i.name().to_uppercase()), Some(i));
        }
        assert_eq!(Isa::from_name("avx9000"), None);
        assert!(Isa::best().supported());
        assert!(Isa::Compiled.supported());
        assert!(isa().supported());
        assert!(Isa::best().width() >= Isa::Compiled.width());
    }
}
