//! The one place that names SIMD lane types and touches processor state.
//!
//! Every other module imports its lane types from here. The triangle and box kernels are written
//! once against the lane traits (`SimdF`, `Four`, `Packet`, `BitOrder`) and are generic
//! over an instruction-set `Level` (see `level.rs`): `wide`'s types as the crate is compiled
//! (AVX-512 or AVX2 with the repository's `-C target-cpu=native`, SSE2 in a default build), or
//! `core::arch` vectors for AVX2 and AVX-512 chosen at run time (`x86.rs`), so that a crate
//! depending on strahl runs the wide kernels without any compiler flags. The sphere tests are
//! written against `Lanes` (short names over `SimdF`) and run at every level too.
#![allow(unsafe_code)]

mod level;
mod native;
#[cfg(target_arch = "x86_64")]
mod x86;

#[cfg(target_arch = "x86_64")]
pub(crate) use level::{Avx2, Avx512};
pub use level::{Isa, isa, set_isa};
pub(crate) use level::{Level, Native, with_level};

use wide::i32x16;
pub(crate) use wide::{bytemuck, i32x8};
pub(crate) use wide::{f32x4, f32x8, f32x16};

/// Returns its argument: lets a closure bound to a name carry `#[inline(always)]` (see [`hot!`](hot)).
#[inline(always)]
pub(crate) fn hot_fn<F>(f: F) -> F {
    f
}

/// A closure that is always inlined: `let f = hot!(|x| …);`. Closures in the kernels must be, so
/// that they are compiled inside the level's `#[target_feature]` function: one left out of line
/// is compiled for the crate's own target, where the level's lane operations become calls.
macro_rules! hot {
    ($c:expr) => {
        $crate::simd::hot_fn(
            #[inline(always)]
            $c,
        )
    };
}
pub(crate) use hot;

/// Asks the processor to bring the cache lines of `*p` (up to 256 bytes) into the L1 cache: a hint
/// that does not change what the program computes.
#[inline(always)]
pub(crate) fn prefetch<T>(p: &T) {
    #[cfg(target_arch = "x86_64")]
    {
        use core::arch::x86_64::{_MM_HINT_T0, _mm_prefetch};
        let p = (p as *const T).cast::<i8>();
        let n = core::mem::size_of::<T>().min(256);
        let mut off = 0;
        while off < n {
            // SAFETY: a prefetch never faults and reads nothing the program can observe, whatever
            // the address; `p.wrapping_add(off)` stays within `*p`'s size, so no pointer
            // arithmetic overflows either.
            unsafe { _mm_prefetch::<_MM_HINT_T0>(p.wrapping_add(off)) };
            off += 64;
        }
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = p;
}

/// `*x`, read with a load of its own four bytes. A caller that has just written a ray field by
/// field would otherwise see its fields read back eight or sixteen bytes at a time (the compiler
/// merges neighbouring loads), and a load spanning two recent stores cannot take their values on
/// the way to the cache: it waits until both have reached it (PERFORMANCE.md measures this per
/// single-ray call).
#[inline(always)]
pub(crate) fn load_f32(x: &f32) -> f32 {
    // SAFETY: `x` is a valid, aligned reference to an initialized `f32`; a volatile read of it is
    // an ordinary read that the compiler may not merge with others.
    unsafe { core::ptr::read_volatile(x) }
}

/// Minima, maxima and `<=` of floats compared as signed integers: one-cycle `vpmaxsd`/`vpminsd`
/// instead of four-cycle `vmaxps`/`vminps` on the traversal's critical path (Embree's
/// `maxi`/`mini`). Non-negative floats order like their bit patterns; negative ones order
/// backwards but below every non-negative one. So:
/// - `max_bits(a, b)` is the float maximum when at least one operand is a non-negative number; a
///   slab test whose last maximum takes `tnear ≥ +0` gets exact entry distances;
/// - `min_bits(a, b)` is the float minimum when both are non-negative, and has its sign bit set
///   when either is negative: a negative exit distance is a miss either way;
/// - `le_bits(a, b)` is `a <= b` when `a` is non-negative and `b` is not `-0.0` (a box left at
///   exactly `t = 0` holds no hit in `(tnear ≥ 0, ·]` either way).
pub(crate) trait BitOrder: Copy {
    fn max_bits(self, b: Self) -> Self;
    fn min_bits(self, b: Self) -> Self;
    fn le_bits(self, b: Self) -> u32;
    /// `le_bits` as a select mask (all bits set in the lanes where `a <= b`).
    fn le_mask(self, b: Self) -> Self;
}

macro_rules! bit_order {
    ($f:ty, $i:ty, $lanes:expr) => {
        impl BitOrder for $f {
            #[inline(always)]
            fn max_bits(self, b: Self) -> Self {
                let (a, b): ($i, $i) = (bytemuck::cast(self), bytemuck::cast(b));
                bytemuck::cast(a.max(b))
            }
            #[inline(always)]
            fn min_bits(self, b: Self) -> Self {
                let (a, b): ($i, $i) = (bytemuck::cast(self), bytemuck::cast(b));
                bytemuck::cast(a.min(b))
            }
            #[inline(always)]
            fn le_bits(self, b: Self) -> u32 {
                let (a, b): ($i, $i) = (bytemuck::cast(self), bytemuck::cast(b));
                !a.simd_gt(b).to_bitmask() & low_bits($lanes)
            }
            #[inline(always)]
            fn le_mask(self, b: Self) -> Self {
                let (a, b): ($i, $i) = (bytemuck::cast(self), bytemuck::cast(b));
                bytemuck::cast(!a.simd_gt(b))
            }
        }
    };
}
bit_order!(f32x8, i32x8, 8);
bit_order!(f32x16, i32x16, 16);

/// Integer lanes, one per child of a BVH node ([`WIDTH`](crate::bvh::node::WIDTH) lanes; the
/// float ones are each level's [`Level::Nf`]). 16 lanes per node ran 4–15% slower (PERFORMANCE.md).
pub(crate) type Ni = i32x8;

/// Fused multiply-add on lane vectors: `madd(a, b, c) = a·b + c`, `msub(a, b, c) = a·b − c`, one
/// rounding each where the CPU has FMA (Embree's `madd`/`msub`).
pub(crate) trait Fma: Copy + core::ops::Mul<Output = Self> {
    fn madd(self, b: Self, c: Self) -> Self;
    fn msub(self, b: Self, c: Self) -> Self;
}

impl<T: SimdF> Fma for T {
    #[inline(always)]
    fn madd(self, b: Self, c: Self) -> Self {
        self.mul_add(b, c)
    }
    #[inline(always)]
    fn msub(self, b: Self, c: Self) -> Self {
        self.mul_sub(b, c)
    }
}

/// The lane operations the triangle and box kernels are written against, once for every level
/// ([`Level`]) and width: `wide`'s names and meanings (comparisons return masks with all bits
/// set in the lanes where they hold; `fast_max`/`fast_min` are the bare `maxps`/`minps`), so that the compiled level's code is `wide`'s own.
pub(crate) trait SimdF:
    Copy
    + Send
    + Sync
    + 'static
    + core::ops::Add<Output = Self>
    + core::ops::Sub<Output = Self>
    + core::ops::Mul<Output = Self>
    + core::ops::Div<Output = Self>
    + core::ops::Neg<Output = Self>
    + core::ops::BitAnd<Output = Self>
    + core::ops::BitOr<Output = Self>
    + core::ops::BitXor<Output = Self>
    + core::ops::Not<Output = Self>
    + core::ops::BitAndAssign
    + core::ops::BitOrAssign
{
    /// The lanes as an array (`[f32; N]`).
    type Arr: Copy + AsRef<[f32]> + AsMut<[f32]>;
    fn splat(x: f32) -> Self;
    fn new(a: Self::Arr) -> Self;
    fn to_array(self) -> Self::Arr;
    fn abs(self) -> Self;
    /// Square root per lane (correctly rounded, as `sqrtps`).
    fn sqrt(self) -> Self;
    /// `self` with the sign of `s`.
    fn copysign(self, s: Self) -> Self;
    /// `maxps`: `b` where either is NaN.
    fn fast_max(self, b: Self) -> Self;
    /// `minps`: `b` where either is NaN.
    fn fast_min(self, b: Self) -> Self;
    fn simd_lt(self, b: Self) -> Self;
    fn simd_le(self, b: Self) -> Self;
    fn simd_gt(self, b: Self) -> Self;
    fn simd_ge(self, b: Self) -> Self;
    fn simd_eq(self, b: Self) -> Self;
    /// Unordered: true where either lane is NaN.
    fn simd_ne(self, b: Self) -> Self;
    /// Per lane: `t` where the mask `self` is set, else `f`.
    fn select(self, t: Self, f: Self) -> Self;
    /// The lanes' sign bits, lane 0 lowest.
    fn to_bitmask(self) -> u32;
    /// `self·b + c`, fused where the level has FMA.
    fn mul_add(self, b: Self, c: Self) -> Self;
    /// `self·b − c`, fused where the level has FMA.
    fn mul_sub(self, b: Self, c: Self) -> Self;
}

/// Four-lane extras: a block test's nearest lane.
pub(crate) trait Four: SimdF<Arr = [f32; 4]> {
    /// Smallest lane (no NaN lanes).
    fn min4(self) -> f32;
    /// Lane `l & 3`.
    fn lane4(self, l: usize) -> f32;
}

/// Packet extras (sixteen lanes).
pub(crate) trait Packet: SimdF<Arr = [f32; 16]> + BitOrder {
    /// Smallest lane (no NaN lanes).
    fn hmin(self) -> f32;
    /// Largest lane (no NaN lanes).
    fn hmax(self) -> f32;
    /// A select mask with the lanes of `bits` set.
    fn lane_mask(bits: u32) -> Self;
}

/// The lane operations the shape kernels are written against once for every width: four
/// lanes (one ray against a leaf block), sixteen (a packet against one shape); short names over
/// [`SimdF`], so every level's lanes have them.
pub(crate) trait Lanes: SimdF {
    fn min(self, b: Self) -> Self;
    fn max(self, b: Self) -> Self;
    /// All bits set where `self < b`.
    fn lt(self, b: Self) -> Self;
    /// All bits set where `self <= b`.
    fn le(self, b: Self) -> Self;
    /// Per lane: `t` where the mask `self` is set, else `f`.
    fn sel(self, t: Self, f: Self) -> Self;
}

impl<T: SimdF> Lanes for T {
    #[inline(always)]
    fn min(self, b: Self) -> Self {
        self.fast_min(b)
    }
    #[inline(always)]
    fn max(self, b: Self) -> Self {
        self.fast_max(b)
    }
    #[inline(always)]
    fn lt(self, b: Self) -> Self {
        self.simd_lt(b)
    }
    #[inline(always)]
    fn le(self, b: Self) -> Self {
        self.simd_le(b)
    }
    #[inline(always)]
    fn sel(self, t: Self, f: Self) -> Self {
        self.select(t, f)
    }
}

/// Lane count of a ray packet (K in Embree's naming): 16 rays, a 4×4 pixel tile.
pub const PACKET_WIDTH: usize = 16;

/// The SIMD type holding one float per packet lane.
pub(crate) type Pf = f32x16;

/// Bit mask with the low `n` bits set.
#[inline(always)]
pub(crate) const fn low_bits(n: usize) -> u32 {
    if n >= 32 { u32::MAX } else { (1u32 << n) - 1 }
}

/// A packet select mask with the lanes of `bits` set.
#[inline(always)]
pub(crate) fn lane_mask(bits: u32) -> Pf {
    const LANE_BITS: [i32; 16] = [1, 2, 4, 8, 16, 32, 64, 128, 256, 512, 1024, 2048, 4096, 8192, 16384, 32768];
    let m = i32x16::splat(bits as i32) & i32x16::new(LANE_BITS);
    bytemuck::cast(!m.simd_eq(i32x16::splat(0)))
}

/// Smallest lane of a packet vector. NaN lanes must not occur (callers select +inf for inactive
/// lanes).
#[inline(always)]
pub(crate) fn hmin(x: Pf) -> f32 {
    #[cfg(all(target_arch = "x86_64", target_feature = "avx512f"))]
    {
        use core::arch::x86_64::{__m512, _mm512_reduce_min_ps};
        // In registers (`vextractf64x4`, `vshufps`, `vminps`), where the halving below went
        // through memory twice: 2–6% on packets (PERFORMANCE.md).
        // SAFETY: `Pf` is sixteen `f32` lanes in 64 bytes, in lane order, as `__m512` is; the
        // target feature of this block guarantees the instructions.
        unsafe { _mm512_reduce_min_ps(core::mem::transmute::<Pf, __m512>(x)) }
    }
    #[cfg(not(all(target_arch = "x86_64", target_feature = "avx512f")))]
    {
        // Pairwise halving: log₂ 16 = 4 dependent steps instead of 16.
        let a = x.to_array();
        let (lo, hi) = a.split_at(8);
        let m = f32x8::new(lo.try_into().unwrap_or([0.0; 8])).fast_min(f32x8::new(hi.try_into().unwrap_or([0.0; 8])));
        let m = m.to_array();
        let (lo, hi) = m.split_at(4);
        let m = f32x4::new(lo.try_into().unwrap_or([0.0; 4])).fast_min(f32x4::new(hi.try_into().unwrap_or([0.0; 4])));
        let m = m.to_array();
        m[0].min(m[1]).min(m[2].min(m[3]))
    }
}

/// Largest lane of a packet vector (see [`hmin`]).
#[inline(always)]
pub(crate) fn hmax(x: Pf) -> f32 {
    #[cfg(all(target_arch = "x86_64", target_feature = "avx512f"))]
    {
        use core::arch::x86_64::{__m512, _mm512_reduce_max_ps};
        // SAFETY: as in `hmin`.
        unsafe { _mm512_reduce_max_ps(core::mem::transmute::<Pf, __m512>(x)) }
    }
    #[cfg(not(all(target_arch = "x86_64", target_feature = "avx512f")))]
    {
        -hmin(-x)
    }
}

/// Truncates four floats to integers in one instruction (`cvttps2dq`). Out-of-range and NaN lanes
/// give `i32::MIN`, so callers clamp the inputs first.
#[inline(always)]
pub(crate) fn trunc4(v: [f32; 4]) -> [i32; 4] {
    f32x4::new(v).fast_trunc_int().to_array()
}

/// Turns flush-to-zero and denormals-are-zero on for the calling thread and returns the previous
/// control word, so that the caller can restore it with [`restore_float_mode`].
///
/// Denormal operands cost a microcode assist of about a hundred cycles each on x86; ray tracers
/// (Embree's tutorials, the comparison harness) run with both flags set on every tracing thread.
/// Results differ from IEEE only for magnitudes below 1.2e-38, which no hit distance reaches.
/// On other architectures this does nothing and returns 0.
pub fn set_flush_denormals() -> u32 {
    #[cfg(target_arch = "x86_64")]
    {
        let mut old: u32 = 0;
        // SAFETY: stmxcsr only writes the 4-byte control word to the pointed-to local, and ldmxcsr
        // loads a value built from the current word with only the FTZ (bit 15) and DAZ (bit 6)
        // bits added, both defined on every x86_64 processor with SSE2; no memory is touched besides
        // `old`, and no other register state changes.
        unsafe {
            core::arch::asm!("stmxcsr [{}]", in(reg) &mut old, options(nostack, preserves_flags));
            let new = old | (1 << 15) | (1 << 6);
            core::arch::asm!("ldmxcsr [{}]", in(reg) &new, options(nostack, preserves_flags));
        }
        old
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        0
    }
}

/// Restores a floating-point control word returned by [`set_flush_denormals`].
pub fn restore_float_mode(word: u32) {
    #[cfg(target_arch = "x86_64")]
    {
        // Keep only the architecturally defined MXCSR bits (0..=15) so that a bad value cannot
        // raise a general-protection fault.
        let word = word & 0xffff;
        // SAFETY: ldmxcsr reads 4 bytes from a live local; the mask above leaves only defined bits.
        unsafe {
            core::arch::asm!("ldmxcsr [{}]", in(reg) &word, options(nostack, preserves_flags));
        }
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        let _ = word;
    }
}

/// Whether flush-to-zero is on for the calling thread (for tests and harness checks).
pub fn flush_denormals_enabled() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        let mut word: u32 = 0;
        // SAFETY: stmxcsr only writes the 4-byte control word into the local.
        unsafe {
            core::arch::asm!("stmxcsr [{}]", in(reg) &mut word, options(nostack, preserves_flags));
        }
        word & (1 << 15) != 0
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

/// Smallest lane of a four-lane vector, in registers (two `vpermilps` and `vminps`): a block
/// test's nearest hit, which the halving through a store and reloads made wait on the way to the
/// next node test (PERFORMANCE.md). NaN lanes must not occur.
#[inline(always)]
pub(crate) fn min4(t: f32x4) -> f32 {
    #[cfg(all(target_arch = "x86_64", target_feature = "avx"))]
    {
        use core::arch::x86_64::{__m128, _mm_cvtss_f32, _mm_min_ps, _mm_permute_ps};
        // SAFETY: `f32x4` and `__m128` are four `f32` lanes in 16 bytes, in lane order; the target
        // feature of this block guarantees the instructions.
        unsafe {
            let x = core::mem::transmute::<f32x4, __m128>(t);
            let m = _mm_min_ps(x, _mm_permute_ps::<0b01_00_11_10>(x));
            let m = _mm_min_ps(m, _mm_permute_ps::<0b10_11_00_01>(m));
            _mm_cvtss_f32(m)
        }
    }
    #[cfg(not(all(target_arch = "x86_64", target_feature = "avx")))]
    {
        let a = t.to_array();
        a[0].min(a[1]).min(a[2].min(a[3]))
    }
}

/// Lane `l` of a four-lane vector, moved to the low lane in registers (`vpermilps`).
#[inline(always)]
pub(crate) fn lane4(x: f32x4, l: usize) -> f32 {
    #[cfg(all(target_arch = "x86_64", target_feature = "avx"))]
    {
        use core::arch::x86_64::{__m128, _mm_cvtsi32_si128, _mm_cvtss_f32, _mm_permutevar_ps};
        // SAFETY: as in `min4`; the index vector's low lane selects lane `l & 3`.
        unsafe {
            let v = core::mem::transmute::<f32x4, __m128>(x);
            _mm_cvtss_f32(_mm_permutevar_ps(v, _mm_cvtsi32_si128((l & 3) as i32)))
        }
    }
    #[cfg(not(all(target_arch = "x86_64", target_feature = "avx")))]
    {
        x.to_array()[l & 3]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn flush_denormals_round_trip() {
        let old = set_flush_denormals();
        assert!(cfg!(not(target_arch = "x86_64")) || flush_denormals_enabled());
        // A denormal product becomes zero with FTZ on.
        let tiny = std::hint::black_box(1e-30f32);
        let product = tiny * std::hint::black_box(1e-10f32);
        if cfg!(target_arch = "x86_64") {
            assert_eq!(product, 0.0);
        }
        restore_float_mode(old);
        assert_eq!(flush_denormals_enabled(), old & (1 << 15) != 0);
    }

    #[test]
    fn bit_order_matches_floats_where_documented() {
        let vals = [0.0f32, -0.0, 1e-30, 0.5, 3.0, 1e30, f32::INFINITY, -1e-30, -0.5, -3.0, f32::NEG_INFINITY];
        for &a in &vals {
            for &b in &vals {
                let (x, y) = (f32x8::splat(a), f32x8::splat(b));
                let max = x.max_bits(y).to_array()[0];
                let min = x.min_bits(y).to_array()[0];
                if a >= 0.0 && a.is_sign_positive() || b >= 0.0 && b.is_sign_positive() {
                    assert_eq!(max, a.max(b), "max_bits({a}, {b})");
                }
                if a >= 0.0 && b >= 0.0 && a.is_sign_positive() && b.is_sign_positive() {
                    assert_eq!(min, a.min(b), "min_bits({a}, {b})");
                }
                if a < 0.0 || b < 0.0 {
                    assert!(min.is_sign_negative(), "min_bits({a}, {b}) = {min} must have its sign bit set");
                }
                if a.is_sign_positive() && b.to_bits() != (-0.0f32).to_bits() {
                    assert_eq!(x.le_bits(y) == 0xff, a <= b, "le_bits({a}, {b})");
                    assert_eq!(f32x16::splat(a).le_bits(f32x16::splat(b)) == 0xffff, a <= b);
                }
            }
        }
        // `-0.0` is the smallest value as bits: why exit distances stay float in the packet tests.
        assert_eq!(f32x8::splat(-0.0).min_bits(f32x8::splat(-3.0)).to_array()[0].to_bits(), (-0.0f32).to_bits());
    }

    #[test]
    fn lane_mask_sets_exactly_the_given_lanes() {
        for bits in [0u32, 1, 0x8000, 0xa5a5, 0xffff] {
            assert_eq!(lane_mask(bits).to_bitmask(), bits);
        }
    }

    #[test]
    fn horizontal_minimum_and_maximum_find_the_extreme_lane() {
        // Each lane in turn holds the extreme, among finite, infinite and negative values.
        let base: [f32; 16] = std::array::from_fn(|i| (i as f32 - 7.5) * 3.25);
        for l in 0..16 {
            for (lo, hi) in [(-1e30, 1e30), (f32::NEG_INFINITY, f32::INFINITY), (-100.0, 100.0)] {
                let mut a = base;
                a[l] = lo;
                assert_eq!(hmin(Pf::new(a)), lo, "lane {l}");
                a[l] = hi;
                assert_eq!(hmax(Pf::new(a)), hi, "lane {l}");
            }
        }
        assert_eq!(hmin(Pf::splat(2.5)), 2.5);
        assert_eq!(hmax(Pf::new(base)), 7.5 * 3.25);
        assert_eq!(hmin(Pf::new(base)), -7.5 * 3.25);
    }

    #[test]
    fn four_lane_minimum_and_lane_picks() {
        let v = f32x4::new([3.0, -1.5, f32::INFINITY, 2.0]);
        assert_eq!(min4(v), -1.5);
        assert_eq!(min4(f32x4::new([f32::INFINITY, 7.0, 7.0, 5.0])), 5.0);
        for l in 0..4 {
            assert_eq!(lane4(v, l), v.to_array()[l]);
        }
    }

    #[test]
    fn low_bits_edges() {
        assert_eq!(low_bits(0), 0);
        assert_eq!(low_bits(3), 0b111);
        assert_eq!(low_bits(32), u32::MAX);
    }
}
