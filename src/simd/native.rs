//! The compiled level's lanes: `wide`'s types, as the crate itself is compiled (AVX-512 or AVX2
//! where `-C target-cpu` enables them, SSE2 on a default x86-64 build, NEON on aarch64). Each
//! method is `wide`'s own, so kernels instantiated with [`Native`](super::Native) compile to the
//! code they compiled to before they were generic over a level.

use wide::{f32x4, f32x8, f32x16};

macro_rules! simd_f {
    ($t:ty, $n:expr) => {
        impl super::SimdF for $t {
            type Arr = [f32; $n];
            #[inline(always)]
            fn splat(x: f32) -> Self {
                <$t>::splat(x)
            }
            #[inline(always)]
            fn new(a: Self::Arr) -> Self {
                <$t>::new(a)
            }
            #[inline(always)]
            fn to_array(self) -> Self::Arr {
                <$t>::to_array(self)
            }
            #[inline(always)]
            fn abs(self) -> Self {
                <$t>::abs(self)
            }
            #[inline(always)]
            fn sqrt(self) -> Self {
                <$t>::sqrt(self)
            }
            #[inline(always)]
            fn copysign(self, s: Self) -> Self {
                <$t>::copysign(self, s)
            }
            #[inline(always)]
            fn fast_max(self, b: Self) -> Self {
                <$t>::fast_max(self, b)
            }
            #[inline(always)]
            fn fast_min(self, b: Self) -> Self {
                <$t>::fast_min(self, b)
            }
            #[inline(always)]
            fn simd_lt(self, b: Self) -> Self {
                <$t>::simd_lt(self, b)
            }
            #[inline(always)]
            fn simd_le(self, b: Self) -> Self {
                <$t>::simd_le(self, b)
            }
            #[inline(always)]
            fn simd_gt(self, b: Self) -> Self {
                <$t>::simd_gt(self, b)
            }
            #[inline(always)]
            fn simd_ge(self, b: Self) -> Self {
                <$t>::simd_ge(self, b)
            }
            #[inline(always)]
            fn simd_eq(self, b: Self) -> Self {
                <$t>::simd_eq(self, b)
            }
            #[inline(always)]
            fn simd_ne(self, b: Self) -> Self {
                <$t>::simd_ne(self, b)
            }
            #[inline(always)]
            fn select(self, t: Self, f: Self) -> Self {
                <$t>::select(self, t, f)
            }
            #[inline(always)]
            fn to_bitmask(self) -> u32 {
                <$t>::to_bitmask(self)
            }
            #[inline(always)]
            fn mul_add(self, b: Self, c: Self) -> Self {
                <$t>::mul_add(self, b, c)
            }
            #[inline(always)]
            fn mul_sub(self, b: Self, c: Self) -> Self {
                <$t>::mul_sub(self, b, c)
            }
        }
    };
}
simd_f!(f32x4, 4);
simd_f!(f32x8, 8);
simd_f!(f32x16, 16);

impl super::Four for f32x4 {
    #[inline(always)]
    fn min4(self) -> f32 {
        super::min4(self)
    }
    #[inline(always)]
    fn lane4(self, l: usize) -> f32 {
        super::lane4(self, l)
    }
}

impl super::Packet for f32x16 {
    #[inline(always)]
    fn hmin(self) -> f32 {
        super::hmin(self)
    }
    #[inline(always)]
    fn hmax(self) -> f32 {
        super::hmax(self)
    }
    #[inline(always)]
    fn lane_mask(bits: u32) -> Self {
        super::lane_mask(bits)
    }
}
