//! The one place that names SIMD lane types and touches processor state.
//!
//! Every other module imports its lane types from here, so that switching the lane library or the
//! packet width is a change to this file alone. The kernels are written against `wide`, which turns
//! `f32x8`/`f32x16` into AVX2/AVX-512 instructions when the crate is built with the CPU's features
//! (`.cargo/config.toml` sets `-C target-cpu=native`); without them they fall back to narrower code
//! that gives the same answers.
#![allow(unsafe_code)]

use wide::i32x16;
pub(crate) use wide::{bytemuck, i32x8};
pub(crate) use wide::{f32x4, f32x8, f32x16};

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

/// Fused multiply-add on lane vectors: `madd(a, b, c) = a·b + c`, `msub(a, b, c) = a·b − c`, one
/// rounding each where the CPU has FMA (Embree's `madd`/`msub`).
pub(crate) trait Fma: Copy + core::ops::Mul<Output = Self> {
    fn madd(self, b: Self, c: Self) -> Self;
    fn msub(self, b: Self, c: Self) -> Self;
}

macro_rules! fma {
    ($($f:ty),*) => {$(
        impl Fma for $f {
            #[inline(always)]
            fn madd(self, b: Self, c: Self) -> Self {
                self.mul_add(b, c)
            }
            #[inline(always)]
            fn msub(self, b: Self, c: Self) -> Self {
                self.mul_sub(b, c)
            }
        }
    )*};
}
fma!(f32x4, f32x8, f32x16);

/// Near-to-far order of the children a ray enters in an 8-wide node, for closest-hit walks.
///
/// Each entered child gets the key `(bits of its entry distance with the low three cleared) | slot`:
/// keys are distinct, and for non-negative distances they order like the distances up to the
/// cleared bits (8 ulps; negative distances, from `tnear < 0`, order backwards among themselves,
/// which costs visits, not hits). Children not entered get `i32::MAX`. The eight keys are sorted
/// in registers by Batcher's 19-comparator network, then the entered children but the nearest
/// are written farthest first with their exact distances: `node[..n − 1]` and `dist[..n − 1]` for
/// `n` entered children (the later slots get unspecified values). Returns the nearest child.
/// Embree does the same with AVX-512 (`traverseClosestHitAVX512VL8`: keys from the distance bits
/// and the slot, ordered in registers); a network needs no branch on the number of children.
///
/// `hits` must have at least one of its low 8 bits set and no others.
#[inline(always)]
pub(crate) fn order8(tn: f32x8, hits: u32, child: &[u32; 8], node: &mut [u32; 8], dist: &mut [f32; 8]) -> u32 {
    debug_assert!(hits != 0 && hits <= 0xff);
    #[cfg(all(target_arch = "x86_64", target_feature = "avx2"))]
    {
        order8_avx2(tn, hits, child, node, dist)
    }
    #[cfg(not(all(target_arch = "x86_64", target_feature = "avx2")))]
    {
        order8_portable(tn, hits, child, node, dist)
    }
}

/// [`order8`] in AVX2 registers: no memory besides the arguments, no branch.
#[cfg(all(target_arch = "x86_64", target_feature = "avx2"))]
#[inline(always)]
fn order8_avx2(tn: f32x8, hits: u32, child: &[u32; 8], node: &mut [u32; 8], dist: &mut [f32; 8]) -> u32 {
    use core::arch::x86_64::*;
    // SAFETY: the intrinsics need AVX2, which this build enables for every function (the `cfg`
    // above is true only then); none of them reads or writes memory: vectors move in and out by
    // value (`bytemuck` casts of plain 32-byte arrays).
    unsafe {
        let t: __m256i = bytemuck::cast(tn);
        let step = _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7);
        let bit = _mm256_setr_epi32(1, 2, 4, 8, 16, 32, 64, 128);
        let entered = _mm256_cmpeq_epi32(_mm256_and_si256(_mm256_set1_epi32(hits as i32), bit), bit);
        let key = _mm256_or_si256(_mm256_and_si256(t, _mm256_set1_epi32(!7)), step);
        let key = _mm256_blendv_epi8(_mm256_set1_epi32(i32::MAX), key, entered);
        // One layer of comparators: lanes paired by a permutation, the lanes of `HI` take the maximum.
        macro_rules! layer {
            ($v:expr, $p:expr, $hi:literal) => {{
                let (v, p) = ($v, $p);
                _mm256_blend_epi32::<$hi>(_mm256_min_epi32(v, p), _mm256_max_epi32(v, p))
            }};
        }
        let k = layer!(key, _mm256_shuffle_epi32::<0xB1>(key), 0xAA); // (0,1) (2,3) (4,5) (6,7)
        let k = layer!(k, _mm256_shuffle_epi32::<0x4E>(k), 0xCC); // (0,2) (1,3) (4,6) (5,7)
        let k = layer!(k, _mm256_shuffle_epi32::<0xD8>(k), 0x44); // (1,2) (5,6)
        let k = layer!(k, _mm256_permute4x64_epi64::<0x4E>(k), 0xF0); // (0,4) (1,5) (2,6) (3,7)
        let k = layer!(k, _mm256_permute4x64_epi64::<0xD8>(k), 0x30); // (2,4) (3,5)
        let k = layer!(k, _mm256_permutevar8x32_epi32(k, _mm256_setr_epi32(0, 2, 1, 4, 3, 6, 5, 7)), 0x54); // (1,2) (3,4) (5,6)
        // Lane i of the reversal takes sorted key n − 1 − i; `vpermd` reads the low three bits of an
        // index only, so a key selects its own slot directly.
        let n = hits.count_ones() as i32;
        let rev = _mm256_permutevar8x32_epi32(k, _mm256_sub_epi32(_mm256_set1_epi32(n - 1), step));
        let c: __m256i = bytemuck::cast(*child);
        *node = bytemuck::cast(_mm256_permutevar8x32_epi32(c, rev));
        *dist = bytemuck::cast(_mm256_permutevar8x32_ps(bytemuck::cast(tn), rev));
        // The nearest by a reduction of its own (three steps instead of the network's six): the walk
        // waits for it, the stack writes do not.
        let m = _mm256_min_epi32(key, _mm256_shuffle_epi32::<0xB1>(key));
        let m = _mm256_min_epi32(m, _mm256_shuffle_epi32::<0x4E>(m));
        let m = _mm256_min_epi32(m, _mm256_permute4x64_epi64::<0x4E>(m));
        child[(_mm256_cvtsi256_si32(m) & 7) as usize]
    }
}

/// [`order8`] in scalar code, with the same keys and so the same order.
#[cfg_attr(all(target_arch = "x86_64", target_feature = "avx2"), allow(dead_code))]
fn order8_portable(tn: f32x8, hits: u32, child: &[u32; 8], node: &mut [u32; 8], dist: &mut [f32; 8]) -> u32 {
    let t = tn.to_array();
    let mut keys = [i32::MAX; 8];
    for (i, k) in keys.iter_mut().enumerate() {
        if hits & (1 << i) != 0 {
            *k = (t[i].to_bits() as i32 & !7) | i as i32;
        }
    }
    keys.sort_unstable();
    let n = hits.count_ones() as usize;
    for j in 0..n - 1 {
        let s = (keys[n - 1 - j] & 7) as usize;
        node[j] = child[s];
        dist[j] = t[s];
    }
    child[(keys[0] & 7) as usize]
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

/// Smallest lane of a packet vector, by pairwise halving (log₂ 16 = 4 dependent steps instead of
/// 16). NaN lanes must not occur (callers select +inf for inactive lanes).
#[inline(always)]
pub(crate) fn hmin(x: Pf) -> f32 {
    let a = x.to_array();
    let (lo, hi) = a.split_at(8);
    let m = f32x8::new(lo.try_into().unwrap_or([0.0; 8])).fast_min(f32x8::new(hi.try_into().unwrap_or([0.0; 8])));
    let m = m.to_array();
    let (lo, hi) = m.split_at(4);
    let m = f32x4::new(lo.try_into().unwrap_or([0.0; 4])).fast_min(f32x4::new(hi.try_into().unwrap_or([0.0; 4])));
    let m = m.to_array();
    m[0].min(m[1]).min(m[2].min(m[3]))
}

/// Largest lane of a packet vector (see [`hmin`]).
#[inline(always)]
pub(crate) fn hmax(x: Pf) -> f32 {
    -hmin(-x)
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
    fn order8_sorts_entered_children_near_to_far() {
        // Distances from a small set (ties between slots), negative ones and -0.0 included, under
        // every mask; the kernel must match the scalar form and put the entered children in order.
        let pool = [0.0f32, -0.0, 1.0, 1.0, 2.5, 1e-30, 7.0, 3.0, -2.0, 1e30, 0.5, 2.5];
        let mut seed = 0x9e37_79b9u32;
        let mut next = || {
            seed ^= seed << 13;
            seed ^= seed >> 17;
            seed ^= seed << 5;
            seed
        };
        let child: [u32; 8] = std::array::from_fn(|i| 100 + i as u32);
        for round in 0..2000 {
            let d: [f32; 8] = std::array::from_fn(|_| pool[next() as usize % pool.len()]);
            let hits = (round % 255) as u32 + 1;
            let (mut n1, mut d1, mut n2, mut d2) = ([0; 8], [0.0; 8], [0; 8], [0.0; 8]);
            let c1 = order8(f32x8::new(d), hits, &child, &mut n1, &mut d1);
            let c2 = order8_portable(f32x8::new(d), hits, &child, &mut n2, &mut d2);
            let n = hits.count_ones() as usize;
            assert_eq!(c1, c2);
            assert_eq!(n1[..n - 1], n2[..n - 1]);
            assert_eq!(
                d1[..n - 1].iter().map(|x| x.to_bits()).collect::<Vec<_>>(),
                d2[..n - 1].iter().map(|x| x.to_bits()).collect::<Vec<_>>()
            );
            // Every entered child exactly once, each with its own distance, farthest first.
            let mut seen: Vec<u32> = n1[..n - 1].to_vec();
            seen.push(c1);
            seen.sort_unstable();
            let want: Vec<u32> = (0..8).filter(|i| hits & (1 << i) != 0).map(|i| child[i]).collect();
            assert_eq!(seen, want);
            for j in 0..n - 1 {
                assert_eq!(d1[j].to_bits(), d[(n1[j] - 100) as usize].to_bits());
            }
            let nonneg = |x: f32| x.is_sign_positive();
            let order: Vec<f32> = n1[..n - 1].iter().rev().map(|&c| d[(c - 100) as usize]).collect();
            let first = d[(c1 - 100) as usize];
            if nonneg(first) && order.iter().all(|&x| nonneg(x)) {
                let mut prev = first;
                for &x in &order {
                    assert!(x >= prev, "{d:?} {hits:#x}: {first} then {order:?}");
                    prev = x;
                }
            }
        }
    }

    #[test]
    fn lane_mask_sets_exactly_the_given_lanes() {
        for bits in [0u32, 1, 0x8000, 0xa5a5, 0xffff] {
            assert_eq!(lane_mask(bits).to_bitmask(), bits);
        }
    }

    #[test]
    fn low_bits_edges() {
        assert_eq!(low_bits(0), 0);
        assert_eq!(low_bits(3), 0b111);
        assert_eq!(low_bits(32), u32::MAX);
    }
}
