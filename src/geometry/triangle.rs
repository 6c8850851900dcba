//! Watertight ray–triangle intersection (Woop, Benthin & Wald 2013, "Watertight Ray/Triangle
//! Intersection", JCGT 2(1)): rays that hit a shared edge hit exactly one of the two triangles,
//! never neither, so no light leaks through the seams of a mesh.

use glam::Vec3;
use wide::{f32x4, CmpEq, CmpGe, CmpGt, CmpLe, CmpLt};

/// Per-ray precomputation of the shear transform: the axis along which the ray travels most
/// becomes z, and the other two are sheared so the ray is (0, 0, 1).
#[derive(Clone, Copy, Debug)]
pub struct RayShear {
    pub kx: usize,
    pub ky: usize,
    pub kz: usize,
    pub sx: f32,
    pub sy: f32,
    pub sz: f32,
}

impl RayShear {
    /// Without branches on the ray's direction (conditional moves and array loads; glam's
    /// `Vec3` indexed by a variable is a `match`): the axes of random rays are unpredictable,
    /// and their mispredicted branches were a tenth of a render's (cachegrind's model).
    #[inline(always)]
    pub fn new(d: Vec3) -> RayShear {
        let a = d.abs().to_array();
        let d = d.to_array();
        let kxy = usize::from(!(a[0] > a[1]));
        let kz = if a[kxy] > a[2] { kxy } else { 2 };
        let neg = usize::from(d[kz] < 0.0);
        // (kz + 1, kz + 2) mod 3, swapped where the ray runs down kz (keeps the winding); from
        // a table, as the two remainders by 3 took ~20 instructions per ray.
        const NEXT: [usize; 5] = [0, 1, 2, 0, 1];
        let kx = NEXT[kz + 1 + neg];
        let ky = NEXT[kz + 2 - neg];
        // One division: |d[kz]| ≥ |d| / √3, so the reciprocal is well conditioned.
        let sz = 1.0 / d[kz];
        RayShear {
            kx,
            ky,
            kz,
            sx: d[kx] * sz,
            sy: d[ky] * sz,
            sz,
        }
    }
}

/// Intersects the ray (o, sheared by `sh`) with triangle (p0, p1, p2) for 0 < t < t_max.
/// Returns (t, b1, b2) with the hit point = (1-b1-b2) p0 + b1 p1 + b2 p2.
#[inline(always)]
pub fn intersect(
    o: Vec3,
    sh: &RayShear,
    p0: Vec3,
    p1: Vec3,
    p2: Vec3,
    t_max: f32,
) -> Option<(f32, f32, f32)> {
    // Arrays rather than Vec3: indexing an array by the ray's axes is a plain load.
    let a = (p0 - o).to_array();
    let b = (p1 - o).to_array();
    let c = (p2 - o).to_array();
    let ax = a[sh.kx] - sh.sx * a[sh.kz];
    let ay = a[sh.ky] - sh.sy * a[sh.kz];
    let bx = b[sh.kx] - sh.sx * b[sh.kz];
    let by = b[sh.ky] - sh.sy * b[sh.kz];
    let cx = c[sh.kx] - sh.sx * c[sh.kz];
    let cy = c[sh.ky] - sh.sy * c[sh.kz];
    let mut u = cx * by - cy * bx;
    let mut v = ax * cy - ay * cx;
    let mut w = bx * ay - by * ax;
    // Fall back to double precision on an edge, as the paper prescribes.
    if u == 0.0 || v == 0.0 || w == 0.0 {
        u = (cx as f64 * by as f64 - cy as f64 * bx as f64) as f32;
        v = (ax as f64 * cy as f64 - ay as f64 * cx as f64) as f32;
        w = (bx as f64 * ay as f64 - by as f64 * ax as f64) as f32;
    }
    if (u < 0.0 || v < 0.0 || w < 0.0) && (u > 0.0 || v > 0.0 || w > 0.0) {
        return None;
    }
    let det = u + v + w;
    if det == 0.0 {
        return None;
    }
    let az = sh.sz * a[sh.kz];
    let bz = sh.sz * b[sh.kz];
    let cz = sh.sz * c[sh.kz];
    let t_scaled = u * az + v * bz + w * cz;
    // Sign-aware range test 0 < t < t_max without dividing.
    if det < 0.0 {
        if t_scaled >= 0.0 || t_scaled < t_max * det {
            return None;
        }
    } else if t_scaled <= 0.0 || t_scaled > t_max * det {
        return None;
    }
    let inv = 1.0 / det;
    let t = t_scaled * inv;
    if !(t > 0.0) {
        return None;
    }
    Some((t, v * inv, w * inv))
}

/// Four triangles in structure-of-arrays form, for [`intersect4`]: `v[k][axis]` holds vertex k's
/// coordinate along `axis` for the four triangles. A block of fewer than four triangles repeats
/// its last one.
#[derive(Clone, Copy, Debug)]
pub struct Tri4 {
    pub v: [[f32x4; 3]; 3],
}

impl Tri4 {
    /// Packs 1 to 4 triangles.
    pub fn new(tris: &[[Vec3; 3]]) -> Tri4 {
        assert!((1..=4).contains(&tris.len()));
        let mut v = [[[0.0f32; 4]; 3]; 3];
        for lane in 0..4 {
            let t = tris[lane.min(tris.len() - 1)];
            for (k, p) in t.iter().enumerate() {
                for axis in 0..3 {
                    v[k][axis][lane] = p[axis];
                }
            }
        }
        Tri4 {
            v: v.map(|vk| vk.map(f32x4::from)),
        }
    }

    /// Triangle `lane`'s vertices.
    pub fn triangle(&self, lane: usize) -> [Vec3; 3] {
        self.v.map(|vk| {
            Vec3::new(
                vk[0].as_array_ref()[lane],
                vk[1].as_array_ref()[lane],
                vk[2].as_array_ref()[lane],
            )
        })
    }
}

/// The hits of one ray with the four triangles of a [`Tri4`]: bit i of `valid` says triangle i is
/// hit with 0 < t < t_max, at distance `t[i]` with barycentrics (`b1[i]`, `b2[i]`).
#[derive(Clone, Copy, Debug)]
pub struct Hits4 {
    pub valid: u32,
    pub t: [f32; 4],
    pub b1: [f32; 4],
    pub b2: [f32; 4],
}

impl Hits4 {
    /// The nearest hit lane, of equally near ones the one whose triangle index in `ids` is
    /// lowest: the first of them, as a block's triangles are in index order (`bvh_build.rs`; a
    /// block of fewer than four repeats its last). `ids` only checks that order in debug builds.
    #[inline(always)]
    pub fn nearest(&self, ids: &[u32; 4]) -> Option<usize> {
        if self.valid == 0 {
            return None;
        }
        debug_assert!(ids.is_sorted());
        let inf = f32::INFINITY;
        let tv: [f32; 4] = std::array::from_fn(|i| {
            if self.valid & (1 << i) != 0 {
                self.t[i]
            } else {
                inf
            }
        });
        // `a < b ? a : b`, one `minss`: `f32::min` adds a NaN test, and no t is NaN (misses
        // are +∞).
        let min = |a: f32, b: f32| if a < b { a } else { b };
        let t_min = min(min(tv[0], tv[1]), min(tv[2], tv[3]));
        let at = f32x4::from(tv).cmp_eq(f32x4::splat(t_min)).move_mask() as u32 & self.valid;
        Some(at.trailing_zeros() as usize)
    }
}

/// [`intersect`] for four triangles at once, lane for lane the same arithmetic (the same
/// numbers to the bit). The rare lanes that sit on an edge in single precision (some u, v, w =
/// 0) are handed to the scalar test, which redoes them in double precision.
///
/// `t_max` is the ray's own limit, not the closest hit so far: which triangle is closest is the
/// caller's decision, made on the exact distances, so that a hit does not depend on the order
/// in which leaves are visited (`bvh.rs`, `packet.rs`).
#[inline(always)]
pub fn intersect4(o: Vec3, sh: &RayShear, tri: &Tri4, t_max: f32) -> Hits4 {
    let o = o.to_array();
    let (ox, oy, oz) = (
        f32x4::splat(o[sh.kx]),
        f32x4::splat(o[sh.ky]),
        f32x4::splat(o[sh.kz]),
    );
    let (sx, sy, sz) = (
        f32x4::splat(sh.sx),
        f32x4::splat(sh.sy),
        f32x4::splat(sh.sz),
    );
    let rel = |k: usize| {
        let vz = tri.v[k][sh.kz] - oz;
        (
            (tri.v[k][sh.kx] - ox) - sx * vz,
            (tri.v[k][sh.ky] - oy) - sy * vz,
            sz * vz,
        )
    };
    let (ax, ay, az) = rel(0);
    let (bx, by, bz) = rel(1);
    let (cx, cy, cz) = rel(2);
    let u = cx * by - cy * bx;
    let v = ax * cy - ay * cx;
    let w = bx * ay - by * ax;
    let zero = f32x4::ZERO;
    let on_edge = (u.cmp_eq(zero) | v.cmp_eq(zero) | w.cmp_eq(zero)).move_mask() as u32;
    let outside = (u.cmp_lt(zero) | v.cmp_lt(zero) | w.cmp_lt(zero))
        & (u.cmp_gt(zero) | v.cmp_gt(zero) | w.cmp_gt(zero));
    let det = u + v + w;
    let t_scaled = u * az + v * bz + w * cz;
    let tmd = f32x4::splat(t_max) * det;
    // Sign-aware range test 0 < t < t_max, as in `intersect`.
    let in_range = (det.cmp_lt(zero) & t_scaled.cmp_lt(zero) & t_scaled.cmp_ge(tmd))
        | (det.cmp_gt(zero) & t_scaled.cmp_gt(zero) & t_scaled.cmp_le(tmd));
    let inv = f32x4::ONE / det;
    let t = t_scaled * inv;
    let mut hits = Hits4 {
        valid: (in_range & t.cmp_gt(zero)).move_mask() as u32
            & !(outside.move_mask() as u32)
            & !on_edge,
        t: t.to_array(),
        b1: (v * inv).to_array(),
        b2: (w * inv).to_array(),
    };
    let mut edge = on_edge;
    while edge != 0 {
        let lane = edge.trailing_zeros() as usize;
        edge &= edge - 1;
        let [p0, p1, p2] = tri.triangle(lane);
        if let Some((t, b1, b2)) = intersect(Vec3::from_array(o), sh, p0, p1, p2, t_max) {
            hits.valid |= 1 << lane;
            (hits.t[lane], hits.b1[lane], hits.b2[lane]) = (t, b1, b2);
        }
    }
    hits
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hits_inside_misses_outside() {
        let (p0, p1, p2) = (Vec3::ZERO, Vec3::X, Vec3::Y);
        let d = -Vec3::Z;
        let sh = RayShear::new(d);
        let (t, b1, b2) = intersect(Vec3::new(0.25, 0.25, 2.0), &sh, p0, p1, p2, 10.0).unwrap();
        assert!((t - 2.0).abs() < 1e-6 && (b1 - 0.25).abs() < 1e-6 && (b2 - 0.25).abs() < 1e-6);
        assert!(intersect(Vec3::new(0.75, 0.75, 2.0), &sh, p0, p1, p2, 10.0).is_none());
        assert!(intersect(Vec3::new(0.25, 0.25, 2.0), &sh, p0, p1, p2, 1.5).is_none());
        assert!(intersect(Vec3::new(0.25, 0.25, -2.0), &sh, p0, p1, p2, 10.0).is_none());
    }

    #[test]
    fn four_wide_test_matches_the_scalar_one_to_the_bit() {
        // Random blocks of 1–4 triangles and random rays, plus rays through shared vertices
        // and edges (where u, v or w is 0 and the scalar test's double-precision path runs).
        let mut rng = crate::math::sampler::TestRng(11);
        let mut r = || rng.f32();
        let mut edge_cases = 0;
        for case in 0..20000 {
            let n = 1 + case % 4;
            let mut tris = Vec::new();
            let shared = Vec3::new(r(), r(), r());
            for _ in 0..n {
                let c = Vec3::new(r(), r(), r()) * 2.0;
                // Every triangle of a block shares vertex `shared`, like a fan.
                tris.push([shared, c, c + Vec3::new(r(), r(), r()) - 0.5]);
            }
            let o = Vec3::new(r(), r(), r()) * 4.0 - 2.0;
            let target = match case % 3 {
                0 => shared,
                1 => (tris[0][0] + tris[0][1]) * 0.5,
                _ => Vec3::new(r(), r(), r()) * 2.0,
            };
            let d = target - o;
            let sh = RayShear::new(d);
            let t_max = if case % 5 == 0 { 0.9 } else { f32::INFINITY };
            let got = intersect4(o, &sh, &Tri4::new(&tris), t_max);
            for lane in 0..4 {
                let t = tris[lane.min(n - 1)];
                let want = intersect(o, &sh, t[0], t[1], t[2], t_max);
                let hit = got.valid & (1 << lane) != 0;
                assert_eq!(hit, want.is_some(), "case {case} lane {lane}");
                if let Some(w) = want {
                    assert_eq!((got.t[lane], got.b1[lane], got.b2[lane]), w, "case {case}");
                    edge_cases += usize::from(case % 3 != 2 && lane == 0);
                }
            }
        }
        assert!(edge_cases > 1000, "{edge_cases}");
    }

    #[test]
    fn shared_edge_is_watertight() {
        // Two triangles sharing the diagonal of the unit square: rays along the diagonal must hit
        // at least one of them.
        let (a, b, c, d) = (Vec3::ZERO, Vec3::X, Vec3::new(1.0, 1.0, 0.0), Vec3::Y);
        let dir = Vec3::new(0.1, -0.2, -1.0);
        let sh = RayShear::new(dir);
        for i in 1..1000 {
            let s = i as f32 / 1000.0;
            let target = Vec3::new(s, s, 0.0);
            let o = target - dir * 3.0;
            let h1 = intersect(o, &sh, a, b, c, 10.0).is_some();
            let h2 = intersect(o, &sh, a, c, d, 10.0).is_some();
            assert!(h1 || h2, "leak at s = {s}");
        }
    }
}
