//! Triangle leaf storage: blocks of `BLOCK` (4) triangles in SoA form, laid out for the triangle test
//! chosen at build time ([`TriangleTest`]), and the `Kernel` interface the traversal calls.
//!
//! Each test lives in its own file: `moeller` (Embree's default),
//! `badouel` (the seeds' plane-and-projection test) and
//! `watertight` (Woop–Benthin–Wald 2013).

use glam::{DVec3, Vec3};

use crate::simd::*;

/// Triangles per leaf block (M in Embree's naming).
pub(crate) const BLOCK: usize = 4;

/// The ray–triangle test a scene is built for. See `../shared/ACCURACY.md` for where each fails.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum TriangleTest {
    /// Möller & Trumbore (JGT 1997) on precomputed edges, as Embree's default scenes do: the
    /// fastest; not watertight (rays can slip through shared edges and vertices).
    #[default]
    MollerTrumbore,
    /// Badouel (Graphics Gems 1990; the seeds' slides): intersect the plane, project onto the
    /// coordinate plane that drops the normal's dominant axis, test 2D barycentrics. Precomputed
    /// in Wald's form ("Realtime Ray Tracing and Interactive Global Illumination", 2004, §7.1).
    /// Not watertight: neighbours projected on different axes disagree at their shared edge.
    Badouel,
    /// Woop, Benthin & Wald, "Watertight Ray/Triangle Intersection" (JCGT 2013): shear the
    /// triangle into ray space and test signed edge functions, recomputed in float64 when one is
    /// exactly zero. No ray passes between two triangles sharing an edge or a vertex.
    Watertight,
}

impl TriangleTest {
    /// Every triangle test.
    pub const ALL: [TriangleTest; 3] = [TriangleTest::MollerTrumbore, TriangleTest::Badouel, TriangleTest::Watertight];

    /// The test's name, as the harness and scene files spell it.
    pub fn name(self) -> &'static str {
        match self {
            TriangleTest::MollerTrumbore => "moller_trumbore",
            TriangleTest::Badouel => "badouel",
            TriangleTest::Watertight => "watertight",
        }
    }

    /// Whether the test closes every shared edge and vertex.
    pub fn is_watertight(self) -> bool {
        self == TriangleTest::Watertight
    }
}

/// [`BLOCK`] triangles in SoA form. What the nine rows hold depends on the test:
/// Möller–Trumbore `v0, e1 = v0 − v1, e2 = v2 − v0` (Embree's `Triangle4`); watertight `v0, v1, v2`;
/// Badouel `n_u, n_v, n_d, β_u, β_v, β_d, γ_u, γ_v, γ_d`, with the projection axis and the normal's
/// sign in the top [`AUX_BITS`] bits of `geom` (so blocks stay 176 bytes for every test). Unused
/// lanes hold NaN, which fails every depth test, and `prim = u32::MAX`.
#[derive(Clone, Copy, Debug)]
#[repr(C, align(16))]
pub(crate) struct TriBlock {
    pub rows: [[f32; BLOCK]; 9],
    pub geom: [u32; BLOCK],
    pub prim: [u32; BLOCK],
}

/// Bits at the top of a Badouel block's geometry ids holding the axis k (2 bits) and normal sign.
pub(crate) const AUX_BITS: u32 = 3;
/// Geometry ids a Badouel scene can hold.
pub(crate) const BADOUEL_MAX_GEOMETRIES: usize = 1 << (32 - AUX_BITS);

impl TriBlock {
    /// Packs up to [`BLOCK`] triangles `(geom_id, prim_id, corners)` for `test`.
    pub fn new(test: TriangleTest, tris: &[(u32, u32, [Vec3; 3])]) -> Self {
        let mut b = TriBlock::EMPTY;
        for (lane, &(g, p, corners)) in tris.iter().take(BLOCK).enumerate() {
            b.set_lane(test, lane, g, p, corners);
        }
        b
    }

    /// A block with no triangle: every lane's rows NaN, its ids `u32::MAX`.
    pub const EMPTY: TriBlock =
        TriBlock { rows: [[f32::NAN; BLOCK]; 9], geom: [u32::MAX; BLOCK], prim: [u32::MAX; BLOCK] };

    /// Puts triangle `(g, p, [a, b, c])` into lane `lane` (below [`BLOCK`]) for `test`, in place.
    /// The builder's leaf blocks are filled this way: gathering a block's triangles into an
    /// array first and packing them after copied each corner twice through the stack, which in
    /// a build without AVX went through integer registers (PERFORMANCE.md).
    #[inline(always)]
    pub fn set_lane(&mut self, test: TriangleTest, lane: usize, g: u32, p: u32, [a, bb, c]: [Vec3; 3]) {
        self.geom[lane] = g;
        let rows: [f32; 9] = match test {
            TriangleTest::MollerTrumbore => {
                let (e1, e2) = (a - bb, c - a);
                [a.x, a.y, a.z, e1.x, e1.y, e1.z, e2.x, e2.y, e2.z]
            }
            TriangleTest::Watertight => [a.x, a.y, a.z, bb.x, bb.y, bb.z, c.x, c.y, c.z],
            TriangleTest::Badouel => {
                let (rows, aux) = super::badouel::precompute(a, bb, c);
                self.geom[lane] = (g & (u32::MAX >> AUX_BITS)) | ((aux as u32) << (32 - AUX_BITS));
                rows
            }
        };
        for (r, v) in self.rows.iter_mut().zip(rows) {
            r[lane] = v;
        }
        self.prim[lane] = p;
    }

    /// Bit `l` set for each lane `l` that holds a triangle (the filled lanes come first).
    #[inline(always)]
    pub fn filled(&self) -> u32 {
        self.prim.iter().enumerate().fold(0, |m, (l, &p)| m | u32::from(p != u32::MAX) << l)
    }

    /// The geometry id of lane `lane` (without Badouel's extra bits).
    #[inline(always)]
    pub fn geom_id(&self, test: TriangleTest, lane: usize) -> u32 {
        match test {
            TriangleTest::Badouel => self.geom[lane] & (u32::MAX >> AUX_BITS),
            _ => self.geom[lane],
        }
    }

    /// Badouel's axis and sign bits of lane `lane`.
    #[inline(always)]
    pub fn aux(&self, lane: usize) -> u8 {
        (self.geom[lane] >> (32 - AUX_BITS)) as u8
    }

    #[inline(always)]
    pub fn row3(&self, first: usize, lane: usize) -> Vec3 {
        Vec3::new(self.rows[first][lane], self.rows[first + 1][lane], self.rows[first + 2][lane])
    }

    /// Geometric normal of lane `lane`: `(v1 − v0) × (v2 − v0)` for Möller–Trumbore and watertight;
    /// for Badouel the same direction scaled so that its dominant component is ±1.
    #[inline(always)]
    pub fn ng(&self, test: TriangleTest, lane: usize) -> Vec3 {
        match test {
            TriangleTest::MollerTrumbore => self.row3(6, lane).cross(self.row3(3, lane)),
            TriangleTest::Watertight => {
                let v0 = self.row3(0, lane);
                (self.row3(3, lane) - v0).cross(self.row3(6, lane) - v0)
            }
            TriangleTest::Badouel => super::badouel::normal(self, lane),
        }
    }
}

/// A ray splatted for one block test, with per-ray data some tests precompute.
#[derive(Clone, Copy)]
pub(crate) struct Ray4<L: Level> {
    pub o: [L::F4; 3],
    pub d: [L::F4; 3],
    /// The direction itself, for tests that permute axes per ray.
    pub ds: Vec3,
}

impl<L: Level> Ray4<L> {
    #[inline(always)]
    pub fn new(o: Vec3, d: Vec3) -> Self {
        let s = <L::F4 as SimdF>::splat;
        Self { o: [s(o.x), s(o.y), s(o.z)], d: [s(d.x), s(d.y), s(d.z)], ds: d }
    }
}

/// Packet lanes in SoA form for the broadcast tests. Kept to the vectors the tests use, so that
/// they stay in registers (with two per-lane `Vec3` arrays added, Sponza's primary packets lost 13%).
#[derive(Clone, Copy)]
pub(crate) struct RayK<L: Level> {
    pub o: [L::Pf; 3],
    pub d: [L::Pf; 3],
    pub tnear: L::Pf,
}

/// A block test's result for one ray: `(valid, t, u, v)`, four lanes each.
pub(crate) type BlockHits<V> = (V, V, V, V);

/// One ray–triangle test in its two SIMD forms, for every [`Level`]. `Pre` is what the test
/// precomputes per ray.
pub(crate) trait Kernel {
    type Pre: Copy;

    fn pre<L: Level>(r: &Ray4<L>) -> Self::Pre;

    /// Every triangle of a block one ray hits in `(tnear, tfar]`: the valid lanes (all bits set)
    /// with their `t`, `u`, `v`; `None` where no lane can hit. Lanes outside the mask hold
    /// anything.
    fn lanes1<L: Level>(b: &TriBlock, r: &Ray4<L>, pre: &Self::Pre, tnear: f32, tfar: f32) -> Option<BlockHits<L::F4>>;

    /// The nearest hit of one ray among the triangles of a block in `(tnear, tfar]`, as
    /// `(lane, t, u, v)`; among equal distances the lowest lane wins.
    #[inline(always)]
    fn intersect1<L: Level>(
        b: &TriBlock,
        r: &Ray4<L>,
        pre: &Self::Pre,
        tnear: f32,
        tfar: f32,
    ) -> Option<(usize, f32, f32, f32)> {
        Self::lanes1(b, r, pre, tnear, tfar).and_then(|(valid, t, u, v)| nearest(valid, t, u, v))
    }

    /// The lanes of a packet (within `active`) hitting triangle `lane` of `b` in `(tnear, tfar]`,
    /// with their `t`, `u`, `v`.
    fn intersect_packet<L: Level>(
        b: &TriBlock,
        lane: usize,
        r: &RayK<L>,
        tfar: L::Pf,
        active: L::Pf,
    ) -> (L::Pf, L::Pf, L::Pf, L::Pf);
}

/// The last checks of a hit whose depth test passed in its scaled form (`tnear·|den| < t·|den|`):
/// the reciprocal `inv` of the determinant is finite (a determinant near 1e-38 would make the
/// barycentrics `u·inv` infinite or NaN), and `t = t_scaled·inv` is finite and still above
/// `tnear` and at most `tfar` once divided (a huge determinant — directions near 1e34 — rounds a
/// tiny `t` to 0; a tiny one, without flush-to-zero, lets `tfar·|det|` round up to the smallest
/// denormal and a `t` of twice `tfar` through: hits outside the interval `(tnear, tfar]`).
#[inline(always)]
pub(crate) fn sane<V: SimdF>(inv: V, t: V, tnear: V, tfar: V) -> V {
    let inf = V::splat(f32::INFINITY);
    inv.abs().simd_lt(inf) & t.simd_lt(inf) & tnear.simd_lt(t) & t.simd_le(tfar)
}

/// Picks the nearest valid lane of a block test: `(lane, t, u, v)`.
#[inline(always)]
pub(crate) fn nearest<V: Four>(valid: V, t: V, u: V, v: V) -> Option<(usize, f32, f32, f32)> {
    let bits = valid.to_bitmask();
    if bits == 0 {
        return None;
    }
    let t = valid.select(t, V::splat(f32::INFINITY));
    // In registers (see `min4`). The kernels' valid lanes hold finite distances, so the minimum
    // is one of theirs; the fallback only keeps the lane index inside the block.
    let tmin = t.min4();
    let at_min = t.simd_eq(V::splat(tmin)).to_bitmask() & bits;
    debug_assert!(at_min != 0, "a valid lane holds the minimum");
    let best = if at_min != 0 { at_min } else { bits }.trailing_zeros() as usize;
    Some((best, tmin, u.lane4(best), v.lane4(best)))
}

/// `a × b` in Embree's form (`vec3.h`): `msub(a.y, b.z, a.z·b.y)` per component, fused where the
/// CPU has FMA: three multiplies and three fused operations instead of six and three.
#[inline(always)]
pub(crate) fn cross<T: Fma>(a: [T; 3], b: [T; 3]) -> [T; 3] {
    [a[1].msub(b[2], a[2] * b[1]), a[2].msub(b[0], a[0] * b[2]), a[0].msub(b[1], a[1] * b[0])]
}

/// `a · b` in Embree's form: `madd(a.x, b.x, madd(a.y, b.y, a.z·b.z))`.
#[inline(always)]
pub(crate) fn dot<T: Fma>(a: [T; 3], b: [T; 3]) -> T {
    a[0].madd(b[0], a[1].madd(b[1], a[2] * b[2]))
}

/// One ray against one triangle with `test`: `(t, u, v)` in `(tnear, tfar]`, as the BVH's leaves
/// compute it (used to measure per-triangle behaviour, e.g. double hits on shared edges).
pub fn intersect_triangle(test: TriangleTest, ray: &crate::ray::Ray, tri: [Vec3; 3]) -> Option<(f32, f32, f32)> {
    use super::{badouel::Badouel, moeller::Moller, watertight::Watertight};
    // With the kernels' active level, as the walks compute it.
    #[inline(always)]
    fn run<K: Kernel, L: Level>(b: &TriBlock, ray: &crate::ray::Ray) -> Option<(f32, f32, f32)> {
        let r = Ray4::<L>::new(ray.origin, ray.dir);
        K::intersect1(b, &r, &K::pre(&r), ray.tnear, ray.tfar).map(|(_, t, u, v)| (t, u, v))
    }
    if !ray.is_valid() {
        return None;
    }
    let b = TriBlock::new(test, &[(0, 0, tri)]);
    match test {
        TriangleTest::MollerTrumbore => with_level!(|L| L::call(
            #[inline(always)]
            || run::<Moller, L>(&b, ray)
        )),
        TriangleTest::Badouel => with_level!(|L| L::call(
            #[inline(always)]
            || run::<Badouel, L>(&b, ray)
        )),
        TriangleTest::Watertight => with_level!(|L| L::call(
            #[inline(always)]
            || run::<Watertight, L>(&b, ray)
        )),
    }
}

/// Float64 Möller–Trumbore without range checks, `(t, [w0, w1, w2])` (weights of v0, v1, v2), or
/// `None` for a ray parallel to the plane: the reference every test's `t` is measured against.
pub fn exact_hit(origin: Vec3, dir: Vec3, tri: [Vec3; 3]) -> Option<(f64, [f64; 3])> {
    let o = origin.as_dvec3();
    let d = dir.as_dvec3();
    let [a, b, c]: [DVec3; 3] = tri.map(|p| p.as_dvec3());
    let e1 = b - a;
    let e2 = c - a;
    let p = d.cross(e2);
    let det = e1.dot(p);
    if det == 0.0 || !det.is_finite() {
        return None;
    }
    let s = o - a;
    let u = s.dot(p) / det;
    let q = s.cross(e1);
    let v = d.dot(q) / det;
    let t = e2.dot(q) / det;
    Some((t, [1.0 - u - v, u, v]))
}

#[cfg(test)]
mod tests {
    use super::super::{badouel::Badouel, moeller::Moller, watertight::Watertight};
    use super::*;
    use crate::ray::PACKET_WIDTH;

    fn block1(test: TriangleTest, a: Vec3, b: Vec3, c: Vec3) -> TriBlock {
        TriBlock::new(test, &[(0, 7, [a, b, c])])
    }

    fn one<K: Kernel>(b: &TriBlock, o: Vec3, d: Vec3, tnear: f32, tfar: f32) -> Option<(usize, f32, f32, f32)> {
        let r = Ray4::<Native>::new(o, d);
        K::intersect1(b, &r, &K::pre(&r), tnear, tfar)
    }

    fn each(f: impl Fn(TriangleTest, &dyn Fn(&TriBlock, Vec3, Vec3, f32, f32) -> Option<(usize, f32, f32, f32)>)) {
        f(TriangleTest::MollerTrumbore, &one::<Moller>);
        f(TriangleTest::Badouel, &one::<Badouel>);
        f(TriangleTest::Watertight, &one::<Watertight>);
    }

    #[test]
    fn barycentrics_and_normal_match_the_definition() {
        each(|test, hit| {
            let (a, b, c) = (Vec3::new(0.0, 0.0, 0.0), Vec3::new(2.0, 0.0, 0.0), Vec3::new(0.0, 2.0, 0.0));
            let blk = block1(test, a, b, c);
            let o = Vec3::new(0.5, 0.25, 3.0);
            let d = Vec3::new(0.0, 0.0, -1.5);
            let (lane, t, u, v) = hit(&blk, o, d, 0.0, f32::INFINITY).unwrap();
            assert_eq!(lane, 0);
            assert!((t - 2.0).abs() < 1e-6, "{test:?} t {t}");
            let p = a * (1.0 - u - v) + b * u + c * v;
            assert!((p - (o + d * t)).length() < 1e-5, "{test:?} {p}");
            let n = blk.ng(test, 0);
            assert!(n.normalize().dot((b - a).cross(c - a).normalize()) > 0.9999, "{test:?} {n}");
        });
    }

    #[test]
    fn depth_test_is_half_open_and_both_windings_hit() {
        each(|test, hit| {
            let blk = block1(test, Vec3::new(-1.0, -1.0, 0.0), Vec3::new(1.0, -1.0, 0.0), Vec3::new(0.0, 1.0, 0.0));
            let (o, d) = (Vec3::new(0.0, 0.0, 1.0), Vec3::new(0.0, 0.0, -1.0));
            assert!(hit(&blk, o, d, 0.0, 1.0).is_some(), "{test:?}: t == tfar hits");
            assert!(hit(&blk, o, d, 1.0, 2.0).is_none(), "{test:?}: t == tnear misses");
            assert!(hit(&blk, o, d, 0.0, 0.999).is_none(), "{test:?}");
            assert!(hit(&blk, -o, -d, 0.0, 5.0).is_some(), "{test:?}: back face");
            // Outside the triangle.
            assert!(hit(&blk, Vec3::new(0.9, 0.9, 1.0), d, 0.0, 5.0).is_none(), "{test:?}");
        });
    }

    #[test]
    fn padding_lanes_never_hit() {
        each(|test, hit| {
            let blk = TriBlock::new(test, &[]);
            assert!(hit(&blk, Vec3::ZERO, Vec3::X, f32::NEG_INFINITY, f32::INFINITY).is_none(), "{test:?}");
            assert!(hit(&blk, Vec3::new(1.0, 2.0, 3.0), Vec3::new(-1.0, 0.5, 0.1), 0.0, f32::INFINITY).is_none());
        });
    }

    fn packet_matches_single<K: Kernel>(test: TriangleTest) {
        let blk = block1(test, Vec3::new(-1.0, -1.0, 0.0), Vec3::new(1.0, -1.0, 0.0), Vec3::new(0.0, 1.0, 0.0));
        let mut os = [Vec3::ZERO; PACKET_WIDTH];
        let mut ds = [Vec3::ZERO; PACKET_WIDTH];
        for i in 0..PACKET_WIDTH {
            os[i] = Vec3::new(-1.2 + 0.16 * i as f32, 0.3 - 0.1 * i as f32, 2.0);
            ds[i] = Vec3::new(0.01 * i as f32, 0.0, -1.0);
        }
        let col = |f: fn(Vec3) -> f32, v: &[Vec3; PACKET_WIDTH]| Pf::new(std::array::from_fn(|i| f(v[i])));
        let rk = RayK {
            o: [col(|v| v.x, &os), col(|v| v.y, &os), col(|v| v.z, &os)],
            d: [col(|v| v.x, &ds), col(|v| v.y, &ds), col(|v| v.z, &ds)],
            tnear: Pf::splat(0.0),
        };
        let all = Pf::splat(0.0).simd_eq(Pf::splat(0.0));
        let (valid, t, _, _) = K::intersect_packet::<Native>(&blk, 0, &rk, Pf::splat(f32::INFINITY), all);
        let (bits, t) = (valid.to_bitmask(), t.to_array());
        let mut hits = 0;
        for i in 0..PACKET_WIDTH {
            let s = one::<K>(&blk, os[i], ds[i], 0.0, f32::INFINITY);
            assert_eq!(s.is_some(), bits & (1 << i) != 0, "{test:?} lane {i}");
            if let Some((_, ts, _, _)) = s {
                assert_eq!(ts, t[i], "{test:?}");
                hits += 1;
            }
        }
        assert!(hits > 3 && hits < PACKET_WIDTH, "the test rays should both hit and miss: {hits}");
    }

    #[test]
    fn packet_forms_match_single_forms() {
        packet_matches_single::<Moller>(TriangleTest::MollerTrumbore);
        packet_matches_single::<Badouel>(TriangleTest::Badouel);
        packet_matches_single::<Watertight>(TriangleTest::Watertight);
    }

    #[test]
    fn exact_reference() {
        let (t, b) =
            exact_hit(Vec3::new(0.25, 0.5, 2.0), Vec3::new(0.0, 0.0, -1.0), [Vec3::ZERO, Vec3::X, Vec3::Y]).unwrap();
        assert!((t - 2.0).abs() < 1e-12 && (b[1] - 0.25).abs() < 1e-12 && (b[2] - 0.5).abs() < 1e-12);
    }
}
