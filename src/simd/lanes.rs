//! strahl's lane types: fixed-size arrays with one loop per operation, written so that the
//! compiler turns each into one instruction of whatever vector width the *enclosing function* is
//! compiled for.
//!
//! `wide`, which these replace, picks its instructions when the crate is compiled
//! (`#[cfg(target_feature = "avx")]`), so a crate built for baseline x86-64 gets SSE2 code even
//! inside a function compiled for AVX2. These types pick nothing: every method is
//! `#[inline(always)]` array code, and LLVM's vectorizer turns `[f32; 8]` loops into one `ymm`
//! instruction inside a `#[target_feature(enable = "avx2,fma")]` function (the kernels' dispatch,
//! [`super::dispatch`]) and into two `xmm` instructions elsewhere: `vcmpps` + `vmovmskps` for
//! [`to_bitmask`](f32x8::to_bitmask), `vblendvps` for [`select`](f32x8::select), `vminps` for
//! [`fast_min`](f32x8::fast_min) (checked in the disassembly, PERFORMANCE.md).
//!
//! Fused multiply-add is the one operation whose *result* depends on the instruction set, so it
//! is not a method here: [`Isa::madd`](super::Isa::madd) fuses only on an ISA that has FMA (an
//! unfused `f32::mul_add` would become a slow library call on one that has not).
#![allow(non_camel_case_types)]
// A lane library: not every type uses every operation.
#![allow(dead_code)]

use core::ops::{Add, AddAssign, BitAnd, BitOr, BitXor, Div, Mul, MulAssign, Neg, Not, Sub, SubAssign};

/// All bits set: a true lane of a comparison mask.
const TRUE: u32 = u32::MAX;

macro_rules! lanes_common {
    ($name:ident, $elem:ty, $n:expr) => {
        impl $name {
            /// The lanes `a`.
            #[inline(always)]
            pub const fn new(a: [$elem; $n]) -> Self {
                Self(a)
            }
            /// Every lane `x`.
            #[inline(always)]
            pub const fn splat(x: $elem) -> Self {
                Self([x; $n])
            }
            /// The lanes as an array.
            #[inline(always)]
            pub const fn to_array(self) -> [$elem; $n] {
                self.0
            }
            /// The lanes as an array, borrowed.
            #[inline(always)]
            pub const fn as_array(&self) -> &[$elem; $n] {
                &self.0
            }
            #[inline(always)]
            fn map(self, f: impl Fn($elem) -> $elem) -> Self {
                Self(core::array::from_fn(|i| f(self.0[i])))
            }
            #[inline(always)]
            fn zip(self, o: Self, f: impl Fn($elem, $elem) -> $elem) -> Self {
                Self(core::array::from_fn(|i| f(self.0[i], o.0[i])))
            }
        }
        impl Default for $name {
            #[inline(always)]
            fn default() -> Self {
                Self([<$elem>::default(); $n])
            }
        }
        impl From<[$elem; $n]> for $name {
            #[inline(always)]
            fn from(a: [$elem; $n]) -> Self {
                Self(a)
            }
        }
        // SAFETY: the type is `repr(C)` around one array of a `Pod` element type, so it has no
        // padding (the alignment divides the array's size) and every bit pattern is a value.
        unsafe impl bytemuck::Zeroable for $name {}
        // SAFETY: as above.
        unsafe impl bytemuck::Pod for $name {}
    };
}

macro_rules! float_lanes {
    ($name:ident, $int:ident, $n:expr, $align:expr) => {
        /// Lanes of `f32`, one loop per operation (see the module documentation).
        #[derive(Clone, Copy, Debug, PartialEq)]
        #[repr(C, align($align))]
        pub(crate) struct $name([f32; $n]);

        lanes_common!($name, f32, $n);

        impl $name {
            #[inline(always)]
            fn mask(self, o: Self, f: impl Fn(f32, f32) -> bool) -> Self {
                Self(core::array::from_fn(|i| f32::from_bits(if f(self.0[i], o.0[i]) { TRUE } else { 0 })))
            }
            /// Lanes where `self < o`, as a mask (all bits set or clear).
            #[inline(always)]
            pub fn simd_lt(self, o: Self) -> Self {
                self.mask(o, |a, b| a < b)
            }
            /// Lanes where `self <= o`.
            #[inline(always)]
            pub fn simd_le(self, o: Self) -> Self {
                self.mask(o, |a, b| a <= b)
            }
            /// Lanes where `self > o`.
            #[inline(always)]
            pub fn simd_gt(self, o: Self) -> Self {
                self.mask(o, |a, b| a > b)
            }
            /// Lanes where `self >= o`.
            #[inline(always)]
            pub fn simd_ge(self, o: Self) -> Self {
                self.mask(o, |a, b| a >= b)
            }
            /// Lanes where `self == o`.
            #[inline(always)]
            pub fn simd_eq(self, o: Self) -> Self {
                self.mask(o, |a, b| a == b)
            }
            /// Lanes where `self != o` (NaN lanes included).
            #[inline(always)]
            pub fn simd_ne(self, o: Self) -> Self {
                self.mask(o, |a, b| a != b)
            }
            /// Lanes that are neither infinite nor NaN.
            #[inline(always)]
            pub fn is_finite(self) -> Self {
                self.map(|x| f32::from_bits(if x.to_bits() << 1 & 0xff00_0000 != 0xff00_0000 { TRUE } else { 0 }))
            }
            /// Lanes that are NaN.
            #[inline(always)]
            pub fn is_nan(self) -> Self {
                self.simd_ne(self)
            }
            /// Bit `i` set where lane `i`'s sign bit is (`movmskps`).
            #[inline(always)]
            pub fn to_bitmask(self) -> u32 {
                let mut m = 0;
                for i in 0..$n {
                    m |= (self.0[i].to_bits() >> 31) << i;
                }
                m
            }
            /// Whether any lane's sign bit is set.
            #[inline(always)]
            pub fn any(self) -> bool {
                self.to_bitmask() != 0
            }
            /// Whether every lane's sign bit is set.
            #[inline(always)]
            pub fn all(self) -> bool {
                self.to_bitmask() == super::low_bits($n)
            }
            /// Whether no lane's sign bit is set.
            #[inline(always)]
            pub fn none(self) -> bool {
                self.to_bitmask() == 0
            }
            /// `t` in the lanes whose sign bit is set in the mask `self`, `f` elsewhere
            /// (`blendvps`: masks from comparisons set all bits or none).
            #[inline(always)]
            pub fn select(self, t: Self, f: Self) -> Self {
                Self(core::array::from_fn(|i| if (self.0[i].to_bits() as i32) < 0 { t.0[i] } else { f.0[i] }))
            }
            /// `minps`: `self < o ? self : o` (so `o` where either is NaN).
            #[inline(always)]
            pub fn fast_min(self, o: Self) -> Self {
                self.zip(o, |a, b| if a < b { a } else { b })
            }
            /// `maxps`: `self > o ? self : o` (so `o` where either is NaN).
            #[inline(always)]
            pub fn fast_max(self, o: Self) -> Self {
                self.zip(o, |a, b| if a > b { a } else { b })
            }
            /// Minimum ignoring a NaN operand (as `f32::min`).
            #[inline(always)]
            pub fn min(self, o: Self) -> Self {
                self.zip(o, |a, b| if b.is_nan() || a < b { a } else { b })
            }
            /// Maximum ignoring a NaN operand (as `f32::max`).
            #[inline(always)]
            pub fn max(self, o: Self) -> Self {
                self.zip(o, |a, b| if b.is_nan() || a > b { a } else { b })
            }
            /// Absolute values (sign bits cleared).
            #[inline(always)]
            pub fn abs(self) -> Self {
                self.map(|x| f32::from_bits(x.to_bits() & 0x7fff_ffff))
            }
            /// `self`'s magnitudes with `sign`'s sign bits.
            #[inline(always)]
            pub fn copysign(self, sign: Self) -> Self {
                self.zip(sign, |a, s| f32::from_bits(a.to_bits() & 0x7fff_ffff | s.to_bits() & 0x8000_0000))
            }
            /// Square roots.
            #[inline(always)]
            pub fn sqrt(self) -> Self {
                self.map(f32::sqrt)
            }
            /// Truncation to integers (`cvttps2dq`); out-of-range and NaN lanes are
            /// unspecified, so callers clamp first.
            #[inline(always)]
            pub fn fast_trunc_int(self) -> $int {
                $int(core::array::from_fn(|i| self.0[i] as i32))
            }
            /// `self·b + c`, fused (one rounding) where the function is compiled with FMA and by
            /// a slow library call elsewhere: call it through [`Isa::madd`](super::Isa::madd).
            #[inline(always)]
            pub(super) fn fused_mul_add(self, b: Self, c: Self) -> Self {
                Self(core::array::from_fn(|i| self.0[i].mul_add(b.0[i], c.0[i])))
            }
        }

        impl Add for $name {
            type Output = Self;
            #[inline(always)]
            fn add(self, o: Self) -> Self {
                self.zip(o, |a, b| a + b)
            }
        }
        impl Sub for $name {
            type Output = Self;
            #[inline(always)]
            fn sub(self, o: Self) -> Self {
                self.zip(o, |a, b| a - b)
            }
        }
        impl Mul for $name {
            type Output = Self;
            #[inline(always)]
            fn mul(self, o: Self) -> Self {
                self.zip(o, |a, b| a * b)
            }
        }
        impl Div for $name {
            type Output = Self;
            #[inline(always)]
            fn div(self, o: Self) -> Self {
                self.zip(o, |a, b| a / b)
            }
        }
        impl Mul<f32> for $name {
            type Output = Self;
            #[inline(always)]
            fn mul(self, o: f32) -> Self {
                self.map(|a| a * o)
            }
        }
        impl Add<f32> for $name {
            type Output = Self;
            #[inline(always)]
            fn add(self, o: f32) -> Self {
                self.map(|a| a + o)
            }
        }
        impl Sub<f32> for $name {
            type Output = Self;
            #[inline(always)]
            fn sub(self, o: f32) -> Self {
                self.map(|a| a - o)
            }
        }
        impl Neg for $name {
            type Output = Self;
            #[inline(always)]
            fn neg(self) -> Self {
                self.map(|a| -a)
            }
        }
        impl AddAssign for $name {
            #[inline(always)]
            fn add_assign(&mut self, o: Self) {
                *self = *self + o;
            }
        }
        impl SubAssign for $name {
            #[inline(always)]
            fn sub_assign(&mut self, o: Self) {
                *self = *self - o;
            }
        }
        impl MulAssign for $name {
            #[inline(always)]
            fn mul_assign(&mut self, o: Self) {
                *self = *self * o;
            }
        }
        impl BitAnd for $name {
            type Output = Self;
            #[inline(always)]
            fn bitand(self, o: Self) -> Self {
                self.zip(o, |a, b| f32::from_bits(a.to_bits() & b.to_bits()))
            }
        }
        impl BitOr for $name {
            type Output = Self;
            #[inline(always)]
            fn bitor(self, o: Self) -> Self {
                self.zip(o, |a, b| f32::from_bits(a.to_bits() | b.to_bits()))
            }
        }
        impl BitXor for $name {
            type Output = Self;
            #[inline(always)]
            fn bitxor(self, o: Self) -> Self {
                self.zip(o, |a, b| f32::from_bits(a.to_bits() ^ b.to_bits()))
            }
        }
        impl Not for $name {
            type Output = Self;
            #[inline(always)]
            fn not(self) -> Self {
                self.map(|a| f32::from_bits(!a.to_bits()))
            }
        }
    };
}

macro_rules! int_lanes {
    ($name:ident, $n:expr, $align:expr) => {
        /// Lanes of `i32`, one loop per operation (see the module documentation).
        #[derive(Clone, Copy, Debug, PartialEq, Eq)]
        #[repr(C, align($align))]
        pub(crate) struct $name([i32; $n]);

        lanes_common!($name, i32, $n);

        impl $name {
            #[inline(always)]
            fn mask(self, o: Self, f: impl Fn(i32, i32) -> bool) -> Self {
                Self(core::array::from_fn(|i| if f(self.0[i], o.0[i]) { -1 } else { 0 }))
            }
            /// Lanes where `self > o`, as a mask (-1 or 0).
            #[inline(always)]
            pub fn simd_gt(self, o: Self) -> Self {
                self.mask(o, |a, b| a > b)
            }
            /// Lanes where `self < o`.
            #[inline(always)]
            pub fn simd_lt(self, o: Self) -> Self {
                self.mask(o, |a, b| a < b)
            }
            /// Lanes where `self == o`.
            #[inline(always)]
            pub fn simd_eq(self, o: Self) -> Self {
                self.mask(o, |a, b| a == b)
            }
            /// Signed maxima (`pmaxsd`).
            #[inline(always)]
            pub fn max(self, o: Self) -> Self {
                self.zip(o, |a, b| a.max(b))
            }
            /// Signed minima (`pminsd`).
            #[inline(always)]
            pub fn min(self, o: Self) -> Self {
                self.zip(o, |a, b| a.min(b))
            }
            /// Bit `i` set where lane `i`'s sign bit is.
            #[inline(always)]
            pub fn to_bitmask(self) -> u32 {
                let mut m = 0;
                for i in 0..$n {
                    m |= ((self.0[i] as u32) >> 31) << i;
                }
                m
            }
            /// Whether any lane's sign bit is set.
            #[inline(always)]
            pub fn any(self) -> bool {
                self.to_bitmask() != 0
            }
            /// Lanes that are negative, as a mask.
            #[inline(always)]
            pub fn is_negative(self) -> Self {
                self.map(|a| a >> 31)
            }
            /// `t` in the lanes whose sign bit is set in the mask `self`, `f` elsewhere.
            #[inline(always)]
            pub fn select(self, t: Self, f: Self) -> Self {
                Self(core::array::from_fn(|i| if self.0[i] < 0 { t.0[i] } else { f.0[i] }))
            }
        }

        impl Add for $name {
            type Output = Self;
            #[inline(always)]
            fn add(self, o: Self) -> Self {
                self.zip(o, i32::wrapping_add)
            }
        }
        impl Sub for $name {
            type Output = Self;
            #[inline(always)]
            fn sub(self, o: Self) -> Self {
                self.zip(o, i32::wrapping_sub)
            }
        }
        impl BitAnd for $name {
            type Output = Self;
            #[inline(always)]
            fn bitand(self, o: Self) -> Self {
                self.zip(o, |a, b| a & b)
            }
        }
        impl BitOr for $name {
            type Output = Self;
            #[inline(always)]
            fn bitor(self, o: Self) -> Self {
                self.zip(o, |a, b| a | b)
            }
        }
        impl BitXor for $name {
            type Output = Self;
            #[inline(always)]
            fn bitxor(self, o: Self) -> Self {
                self.zip(o, |a, b| a ^ b)
            }
        }
        impl Not for $name {
            type Output = Self;
            #[inline(always)]
            fn not(self) -> Self {
                self.map(|a| !a)
            }
        }
        impl core::ops::BitOrAssign for $name {
            #[inline(always)]
            fn bitor_assign(&mut self, o: Self) {
                *self = *self | o;
            }
        }
        impl core::ops::BitAndAssign for $name {
            #[inline(always)]
            fn bitand_assign(&mut self, o: Self) {
                *self = *self & o;
            }
        }
    };
}

float_lanes!(f32x4, i32x4, 4, 16);
float_lanes!(f32x8, i32x8, 8, 32);
float_lanes!(f32x16, i32x16, 16, 64);
int_lanes!(i32x4, 4, 16);
int_lanes!(i32x8, 8, 32);
int_lanes!(i32x16, 16, 64);
