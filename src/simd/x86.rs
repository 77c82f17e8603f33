//! The run-time levels' lanes on `core::arch` vectors: [`V4`] (`__m128`), [`V8`] (`__m256`),
//! [`W16`] (two `__m256`, the AVX2 level's packets) and [`V16`] (`__m512`, the AVX-512 level's).
//!
//! # Soundness
//! Every method calls AVX, AVX2, FMA or AVX-512 intrinsics without the features being enabled for
//! the crate. That is sound because values of these types exist only inside code generic over a
//! [`Level`](super::Level) that was instantiated with [`Avx2`](super::Avx2) (for `V4`, `V8`,
//! `W16`) or [`Avx512`](super::Avx512) (for all four), and such code runs only inside that
//! level's `Level::call`, which is entered only after the processor was found to have the
//! level's features (see `level.rs`). The types are crate-private and built only through their
//! level. The methods are `#[inline(always)]`, so they are compiled inside the level's
//! `#[target_feature]` function and become single instructions there.
//!
//! The lanes mean what `wide`'s do: comparisons give all bits set where they hold (ordered,
//! except `!=`), `fast_max`/`fast_min` are the bare `maxps`/`minps`.
#![allow(unused_unsafe)]

use core::arch::x86_64::*;
use core::ops::{Add, BitAnd, BitAndAssign, BitOr, BitOrAssign, BitXor, Div, Mul, Neg, Not, Sub};

use super::{BitOrder, Four, Packet, SimdF};

/// Four float lanes in an SSE register.
#[derive(Clone, Copy, Debug)]
#[repr(transparent)]
pub(crate) struct V4(__m128);

/// Eight float lanes in an AVX register.
#[derive(Clone, Copy, Debug)]
#[repr(transparent)]
pub(crate) struct V8(__m256);

/// Sixteen float lanes as two AVX registers (the AVX2 level's packets).
#[derive(Clone, Copy, Debug)]
pub(crate) struct W16(V8, V8);

/// Sixteen float lanes in an AVX-512 register.
#[derive(Clone, Copy, Debug)]
#[repr(transparent)]
pub(crate) struct V16(__m512);

/// `unsafe { $e }` for the intrinsics of this module; sound by the module's argument.
macro_rules! isa {
    ($e:expr) => {
        // SAFETY: the lane types exist only inside their level's `Level::call`, which runs only
        // on processors with the level's features (module documentation).
        unsafe { $e }
    };
}

macro_rules! binops {
    ($t:ident, $add:ident, $sub:ident, $mul:ident, $div:ident, $and:ident, $or:ident, $xor:ident) => {
        impl Add for $t {
            type Output = Self;
            #[inline(always)]
            fn add(self, b: Self) -> Self {
                $t(isa!($add(self.0, b.0)))
            }
        }
        impl Sub for $t {
            type Output = Self;
            #[inline(always)]
            fn sub(self, b: Self) -> Self {
                $t(isa!($sub(self.0, b.0)))
            }
        }
        impl Mul for $t {
            type Output = Self;
            #[inline(always)]
            fn mul(self, b: Self) -> Self {
                $t(isa!($mul(self.0, b.0)))
            }
        }
        impl Div for $t {
            type Output = Self;
            #[inline(always)]
            fn div(self, b: Self) -> Self {
                $t(isa!($div(self.0, b.0)))
            }
        }
        impl BitAnd for $t {
            type Output = Self;
            #[inline(always)]
            fn bitand(self, b: Self) -> Self {
                $t(isa!($and(self.0, b.0)))
            }
        }
        impl BitOr for $t {
            type Output = Self;
            #[inline(always)]
            fn bitor(self, b: Self) -> Self {
                $t(isa!($or(self.0, b.0)))
            }
        }
        impl BitXor for $t {
            type Output = Self;
            #[inline(always)]
            fn bitxor(self, b: Self) -> Self {
                $t(isa!($xor(self.0, b.0)))
            }
        }
        impl Neg for $t {
            type Output = Self;
            #[inline(always)]
            fn neg(self) -> Self {
                self ^ <$t as SimdF>::splat(-0.0)
            }
        }
        impl Not for $t {
            type Output = Self;
            #[inline(always)]
            fn not(self) -> Self {
                self ^ <$t as SimdF>::splat(f32::from_bits(u32::MAX))
            }
        }
        impl BitAndAssign for $t {
            #[inline(always)]
            fn bitand_assign(&mut self, b: Self) {
                *self = *self & b;
            }
        }
        impl BitOrAssign for $t {
            #[inline(always)]
            fn bitor_assign(&mut self, b: Self) {
                *self = *self | b;
            }
        }
    };
}

binops!(V4, _mm_add_ps, _mm_sub_ps, _mm_mul_ps, _mm_div_ps, _mm_and_ps, _mm_or_ps, _mm_xor_ps);
binops!(V8, _mm256_add_ps, _mm256_sub_ps, _mm256_mul_ps, _mm256_div_ps, _mm256_and_ps, _mm256_or_ps, _mm256_xor_ps);
binops!(V16, _mm512_add_ps, _mm512_sub_ps, _mm512_mul_ps, _mm512_div_ps, _mm512_and_ps, _mm512_or_ps, _mm512_xor_ps);

/// The methods V4 and V8 share: vector masks, `blendv`, `movemask`.
macro_rules! vector_mask_lanes {
    ($t:ident, $n:expr, $set1:ident, $loadu:ident, $storeu:ident, $max:ident, $min:ident,
     $cmp:ident, $blendv:ident, $movemask:ident, $fmadd:ident, $fmsub:ident, $sqrt:ident) => {
        impl $t {
            #[inline(always)]
            fn cmp<const P: i32>(self, b: Self) -> Self {
                $t(isa!($cmp::<P>(self.0, b.0)))
            }
        }
        impl SimdF for $t {
            type Arr = [f32; $n];
            #[inline(always)]
            fn splat(x: f32) -> Self {
                $t(isa!($set1(x)))
            }
            #[inline(always)]
            fn new(a: Self::Arr) -> Self {
                // The load reads the array's `$n` floats.
                $t(isa!($loadu(a.as_ptr())))
            }
            #[inline(always)]
            fn to_array(self) -> Self::Arr {
                let mut a = [0.0; $n];
                // The store writes the array's `$n` floats.
                isa!($storeu(a.as_mut_ptr(), self.0));
                a
            }
            #[inline(always)]
            fn abs(self) -> Self {
                self & Self::splat(f32::from_bits(i32::MAX as u32))
            }
            #[inline(always)]
            fn sqrt(self) -> Self {
                $t(isa!($sqrt(self.0)))
            }
            #[inline(always)]
            fn copysign(self, s: Self) -> Self {
                let sign = Self::splat(-0.0);
                (s & sign) | (self & !sign)
            }
            #[inline(always)]
            fn fast_max(self, b: Self) -> Self {
                $t(isa!($max(self.0, b.0)))
            }
            #[inline(always)]
            fn fast_min(self, b: Self) -> Self {
                $t(isa!($min(self.0, b.0)))
            }
            #[inline(always)]
            fn simd_lt(self, b: Self) -> Self {
                self.cmp::<_CMP_LT_OQ>(b)
            }
            #[inline(always)]
            fn simd_le(self, b: Self) -> Self {
                self.cmp::<_CMP_LE_OQ>(b)
            }
            #[inline(always)]
            fn simd_gt(self, b: Self) -> Self {
                self.cmp::<_CMP_GT_OQ>(b)
            }
            #[inline(always)]
            fn simd_ge(self, b: Self) -> Self {
                self.cmp::<_CMP_GE_OQ>(b)
            }
            #[inline(always)]
            fn simd_eq(self, b: Self) -> Self {
                self.cmp::<_CMP_EQ_OQ>(b)
            }
            #[inline(always)]
            fn simd_ne(self, b: Self) -> Self {
                self.cmp::<_CMP_NEQ_UQ>(b)
            }
            #[inline(always)]
            fn select(self, t: Self, f: Self) -> Self {
                $t(isa!($blendv(f.0, t.0, self.0)))
            }
            #[inline(always)]
            fn to_bitmask(self) -> u32 {
                isa!($movemask(self.0)) as u32
            }
            #[inline(always)]
            fn mul_add(self, b: Self, c: Self) -> Self {
                $t(isa!($fmadd(self.0, b.0, c.0)))
            }
            #[inline(always)]
            fn mul_sub(self, b: Self, c: Self) -> Self {
                $t(isa!($fmsub(self.0, b.0, c.0)))
            }
        }
    };
}

vector_mask_lanes!(
    V4,
    4,
    _mm_set1_ps,
    _mm_loadu_ps,
    _mm_storeu_ps,
    _mm_max_ps,
    _mm_min_ps,
    _mm_cmp_ps,
    _mm_blendv_ps,
    _mm_movemask_ps,
    _mm_fmadd_ps,
    _mm_fmsub_ps,
    _mm_sqrt_ps
);
vector_mask_lanes!(
    V8,
    8,
    _mm256_set1_ps,
    _mm256_loadu_ps,
    _mm256_storeu_ps,
    _mm256_max_ps,
    _mm256_min_ps,
    _mm256_cmp_ps,
    _mm256_blendv_ps,
    _mm256_movemask_ps,
    _mm256_fmadd_ps,
    _mm256_fmsub_ps,
    _mm256_sqrt_ps
);

impl Four for V4 {
    #[inline(always)]
    fn min4(self) -> f32 {
        isa!({
            let x = self.0;
            let m = _mm_min_ps(x, _mm_permute_ps::<0b01_00_11_10>(x));
            let m = _mm_min_ps(m, _mm_permute_ps::<0b10_11_00_01>(m));
            _mm_cvtss_f32(m)
        })
    }
    #[inline(always)]
    fn lane4(self, l: usize) -> f32 {
        isa!(_mm_cvtss_f32(_mm_permutevar_ps(self.0, _mm_cvtsi32_si128((l & 3) as i32))))
    }
}

impl V8 {
    #[inline(always)]
    fn bits(self) -> __m256i {
        isa!(_mm256_castps_si256(self.0))
    }
    #[inline(always)]
    fn of_bits(x: __m256i) -> Self {
        V8(isa!(_mm256_castsi256_ps(x)))
    }
    /// Smallest lane, in registers.
    #[inline(always)]
    fn hmin8(self) -> f32 {
        let lo = V4(isa!(_mm256_castps256_ps128(self.0)));
        let hi = V4(isa!(_mm256_extractf128_ps::<1>(self.0)));
        lo.fast_min(hi).min4()
    }
    /// A mask with the lanes of the low eight bits of `bits` set.
    #[inline(always)]
    fn lane_mask8(bits: u32) -> Self {
        isa!({
            let lane = _mm256_setr_epi32(1, 2, 4, 8, 16, 32, 64, 128);
            let m = _mm256_and_si256(_mm256_set1_epi32(bits as i32), lane);
            V8::of_bits(_mm256_cmpeq_epi32(m, lane))
        })
    }
}

impl BitOrder for V8 {
    #[inline(always)]
    fn max_bits(self, b: Self) -> Self {
        V8::of_bits(isa!(_mm256_max_epi32(self.bits(), b.bits())))
    }
    #[inline(always)]
    fn min_bits(self, b: Self) -> Self {
        V8::of_bits(isa!(_mm256_min_epi32(self.bits(), b.bits())))
    }
    #[inline(always)]
    fn le_bits(self, b: Self) -> u32 {
        !V8::of_bits(isa!(_mm256_cmpgt_epi32(self.bits(), b.bits()))).to_bitmask() & 0xff
    }
    #[inline(always)]
    fn le_mask(self, b: Self) -> Self {
        !V8::of_bits(isa!(_mm256_cmpgt_epi32(self.bits(), b.bits())))
    }
}

// --- W16: two halves -------------------------------------------------------------------------

macro_rules! halves_binop {
    ($($tr:ident $f:ident),*) => {$(
        impl $tr for W16 {
            type Output = Self;
            #[inline(always)]
            fn $f(self, b: Self) -> Self {
                W16(self.0.$f(b.0), self.1.$f(b.1))
            }
        }
    )*};
}
halves_binop!(Add add, Sub sub, Mul mul, Div div, BitAnd bitand, BitOr bitor, BitXor bitxor);

impl Neg for W16 {
    type Output = Self;
    #[inline(always)]
    fn neg(self) -> Self {
        W16(-self.0, -self.1)
    }
}
impl Not for W16 {
    type Output = Self;
    #[inline(always)]
    fn not(self) -> Self {
        W16(!self.0, !self.1)
    }
}
impl BitAndAssign for W16 {
    #[inline(always)]
    fn bitand_assign(&mut self, b: Self) {
        *self = *self & b;
    }
}
impl BitOrAssign for W16 {
    #[inline(always)]
    fn bitor_assign(&mut self, b: Self) {
        *self = *self | b;
    }
}

macro_rules! halves {
    ($($f:ident),*) => {$(
        #[inline(always)]
        fn $f(self, b: Self) -> Self {
            W16(self.0.$f(b.0), self.1.$f(b.1))
        }
    )*};
}

impl SimdF for W16 {
    type Arr = [f32; 16];
    #[inline(always)]
    fn splat(x: f32) -> Self {
        W16(V8::splat(x), V8::splat(x))
    }
    #[inline(always)]
    fn new(a: Self::Arr) -> Self {
        let (lo, hi) = a.split_at(8);
        W16(V8::new(lo.try_into().unwrap_or([0.0; 8])), V8::new(hi.try_into().unwrap_or([0.0; 8])))
    }
    #[inline(always)]
    fn to_array(self) -> Self::Arr {
        let mut a = [0.0; 16];
        let (lo, hi) = a.split_at_mut(8);
        lo.copy_from_slice(&self.0.to_array());
        hi.copy_from_slice(&self.1.to_array());
        a
    }
    #[inline(always)]
    fn abs(self) -> Self {
        W16(self.0.abs(), self.1.abs())
    }
    #[inline(always)]
    fn sqrt(self) -> Self {
        W16(self.0.sqrt(), self.1.sqrt())
    }
    halves!(copysign, fast_max, fast_min, simd_lt, simd_le, simd_gt, simd_ge, simd_eq, simd_ne);
    #[inline(always)]
    fn select(self, t: Self, f: Self) -> Self {
        W16(self.0.select(t.0, f.0), self.1.select(t.1, f.1))
    }
    #[inline(always)]
    fn to_bitmask(self) -> u32 {
        self.0.to_bitmask() | self.1.to_bitmask() << 8
    }
    #[inline(always)]
    fn mul_add(self, b: Self, c: Self) -> Self {
        W16(self.0.mul_add(b.0, c.0), self.1.mul_add(b.1, c.1))
    }
    #[inline(always)]
    fn mul_sub(self, b: Self, c: Self) -> Self {
        W16(self.0.mul_sub(b.0, c.0), self.1.mul_sub(b.1, c.1))
    }
}

impl BitOrder for W16 {
    halves!(max_bits, min_bits, le_mask);
    #[inline(always)]
    fn le_bits(self, b: Self) -> u32 {
        self.0.le_bits(b.0) | self.1.le_bits(b.1) << 8
    }
}

impl Packet for W16 {
    #[inline(always)]
    fn hmin(self) -> f32 {
        self.0.fast_min(self.1).hmin8()
    }
    #[inline(always)]
    fn hmax(self) -> f32 {
        -(-self).hmin()
    }
    #[inline(always)]
    fn lane_mask(bits: u32) -> Self {
        W16(V8::lane_mask8(bits), V8::lane_mask8(bits >> 8))
    }
}

// --- V16: AVX-512 ----------------------------------------------------------------------------

impl V16 {
    #[inline(always)]
    fn bits(self) -> __m512i {
        isa!(_mm512_castps_si512(self.0))
    }
    /// The vector mask of a k-mask.
    #[inline(always)]
    fn of_mask(k: __mmask16) -> Self {
        V16(isa!(_mm512_castsi512_ps(_mm512_movm_epi32(k))))
    }
    /// The k-mask of a vector mask's sign bits.
    #[inline(always)]
    fn mask(self) -> __mmask16 {
        isa!(_mm512_movepi32_mask(self.bits()))
    }
    #[inline(always)]
    fn cmp<const P: i32>(self, b: Self) -> Self {
        V16::of_mask(isa!(_mm512_cmp_ps_mask::<P>(self.0, b.0)))
    }
}

impl SimdF for V16 {
    type Arr = [f32; 16];
    #[inline(always)]
    fn splat(x: f32) -> Self {
        V16(isa!(_mm512_set1_ps(x)))
    }
    #[inline(always)]
    fn new(a: Self::Arr) -> Self {
        // The load reads the array's sixteen floats.
        V16(isa!(_mm512_loadu_ps(a.as_ptr())))
    }
    #[inline(always)]
    fn to_array(self) -> Self::Arr {
        let mut a = [0.0; 16];
        // The store writes the array's sixteen floats.
        isa!(_mm512_storeu_ps(a.as_mut_ptr(), self.0));
        a
    }
    #[inline(always)]
    fn abs(self) -> Self {
        self & Self::splat(f32::from_bits(i32::MAX as u32))
    }
    #[inline(always)]
    fn sqrt(self) -> Self {
        V16(isa!(_mm512_sqrt_ps(self.0)))
    }
    #[inline(always)]
    fn copysign(self, s: Self) -> Self {
        let sign = Self::splat(-0.0);
        (s & sign) | (self & !sign)
    }
    #[inline(always)]
    fn fast_max(self, b: Self) -> Self {
        V16(isa!(_mm512_max_ps(self.0, b.0)))
    }
    #[inline(always)]
    fn fast_min(self, b: Self) -> Self {
        V16(isa!(_mm512_min_ps(self.0, b.0)))
    }
    #[inline(always)]
    fn simd_lt(self, b: Self) -> Self {
        self.cmp::<_CMP_LT_OQ>(b)
    }
    #[inline(always)]
    fn simd_le(self, b: Self) -> Self {
        self.cmp::<_CMP_LE_OQ>(b)
    }
    #[inline(always)]
    fn simd_gt(self, b: Self) -> Self {
        self.cmp::<_CMP_GT_OQ>(b)
    }
    #[inline(always)]
    fn simd_ge(self, b: Self) -> Self {
        self.cmp::<_CMP_GE_OQ>(b)
    }
    #[inline(always)]
    fn simd_eq(self, b: Self) -> Self {
        self.cmp::<_CMP_EQ_OQ>(b)
    }
    #[inline(always)]
    fn simd_ne(self, b: Self) -> Self {
        self.cmp::<_CMP_NEQ_UQ>(b)
    }
    #[inline(always)]
    fn select(self, t: Self, f: Self) -> Self {
        V16(isa!(_mm512_mask_blend_ps(self.mask(), f.0, t.0)))
    }
    #[inline(always)]
    fn to_bitmask(self) -> u32 {
        self.mask() as u32
    }
    #[inline(always)]
    fn mul_add(self, b: Self, c: Self) -> Self {
        V16(isa!(_mm512_fmadd_ps(self.0, b.0, c.0)))
    }
    #[inline(always)]
    fn mul_sub(self, b: Self, c: Self) -> Self {
        V16(isa!(_mm512_fmsub_ps(self.0, b.0, c.0)))
    }
}

impl BitOrder for V16 {
    #[inline(always)]
    fn max_bits(self, b: Self) -> Self {
        V16(isa!(_mm512_castsi512_ps(_mm512_max_epi32(self.bits(), b.bits()))))
    }
    #[inline(always)]
    fn min_bits(self, b: Self) -> Self {
        V16(isa!(_mm512_castsi512_ps(_mm512_min_epi32(self.bits(), b.bits()))))
    }
    #[inline(always)]
    fn le_bits(self, b: Self) -> u32 {
        isa!(_mm512_cmple_epi32_mask(self.bits(), b.bits())) as u32
    }
    #[inline(always)]
    fn le_mask(self, b: Self) -> Self {
        V16::of_mask(isa!(_mm512_cmple_epi32_mask(self.bits(), b.bits())))
    }
}

impl Packet for V16 {
    #[inline(always)]
    fn hmin(self) -> f32 {
        isa!(_mm512_reduce_min_ps(self.0))
    }
    #[inline(always)]
    fn hmax(self) -> f32 {
        isa!(_mm512_reduce_max_ps(self.0))
    }
    #[inline(always)]
    fn lane_mask(bits: u32) -> Self {
        V16::of_mask(bits as __mmask16)
    }
}
