//! Eight rays traced through the BVH together (packet traversal: Wald, Slusallek, Benthin &
//! Wagner 2001, "Interactive rendering with coherent ray tracing"), with a switch to one ray at
//! a time where a packet thins out (Embree's hybrid traversal: Benthin, Wald, Woop, Ernst &
//! Mark 2012, "Combining single and packet-ray tracing for arbitrary ray distributions on the
//! Intel MIC architecture").
//!
//! A node's child boxes are tested one box at a time against the eight rays, a leaf's
//! triangles one triangle at a time, each on the eight lanes of one SIMD register. Rays of
//! different paths rarely share a subtree of a large scene, but in a room every ray crosses the
//! few boxes near the root, and one packet visit there replaces eight visits with their
//! mispredicted branches. A subtree that a single ray of the packet enters is finished by
//! that ray alone (`Bvh::intersect_subtree`).
//!
//! Used for camera rays (`render::batch::render_pixels`: a pixel's samples, nearly one ray).
//! For incoherent rays a packet does more work than it saves: its rays part ways near the
//! root, and the packet visits the union of the nodes and leaves each ray alone would visit
//! (`bench/README.md`, "Design measurements").
//!
//! Every answer is `Bvh::intersect`'s (or `occluded`'s) for the same ray to the bit: the
//! triangle test is `triangle::intersect4`'s arithmetic lane for lane, and the closest hit is
//! chosen on exact distances with ties to the lower triangle index, which no order of
//! traversal can change.

use super::bvh::{closer, Bvh, Node, Stack, CULL_SLACK, EMPTY, LEAF, WIDTH};
use super::triangle::{intersect, RayShear};
use super::{Hit, Ray};
use arrayvec::ArrayVec;
use glam::Vec3;
use wide::{f32x8, CmpEq, CmpGe, CmpGt, CmpLe, CmpLt};

/// Rays per packet: one lane each of an eight-wide SIMD register.
pub const LANES: usize = 8;

/// A subtree entered by at most this many rays of a packet is traversed one ray at a time.
const SINGLE: u32 = 1;

/// Picks, lane by lane, component 0, 1 or 2 of a vector: lanes in `is0` take c[0], lanes in
/// `is1` c[1], the rest c[2].
#[derive(Clone, Copy)]
struct Select {
    is0: f32x8,
    is1: f32x8,
}

impl Select {
    #[inline(always)]
    fn pick(&self, c: &[f32x8; 3]) -> f32x8 {
        self.is0.blend(c[0], self.is1.blend(c[1], c[2]))
    }
}

/// Up to eight rays in structure-of-arrays form, with what the slab and triangle tests need.
pub struct Packet {
    /// Lanes that carry a ray (bit i: lane i).
    active: u32,
    rays: [Ray; LANES],
    t_max: [f32; LANES],
    /// Each lane's `t_max`; −1 in idle lanes, so that they enter no box and hit nothing.
    t_far: f32x8,
    o: [f32x8; 3],
    inv: [f32x8; 3],
    /// The watertight test's shear (`RayShear`) per lane: its axes as selections, its factors.
    kx: Select,
    ky: Select,
    kz: Select,
    s: [f32x8; 3],
}

impl Packet {
    /// A packet of the rays in lanes `active` (bit i: `rays[i]`, up to `t_max[i]`). The slab
    /// reciprocals and the shear are `SlabRay`'s and `RayShear::new`'s arithmetic on eight
    /// lanes (the same bits; a test holds them to the scalar ones): one at a time they took
    /// 24 scalar divisions and eight branch-free but long axis selections per packet.
    pub fn new(rays: [Ray; LANES], t_max: [f32; LANES], active: u32) -> Packet {
        let idle = Ray::new(Vec3::ZERO, Vec3::Z);
        let rays: [Ray; LANES] = std::array::from_fn(|i| {
            if active & (1 << i) != 0 {
                rays[i]
            } else {
                idle
            }
        });
        let comp = |f: fn(&Ray) -> f32| f32x8::from(rays.each_ref().map(f));
        let o = [comp(|r| r.o.x), comp(|r| r.o.y), comp(|r| r.o.z)];
        let d = [comp(|r| r.d.x), comp(|r| r.d.y), comp(|r| r.d.z)];
        let zero = f32x8::ZERO;
        // `slab_component`: a zero (|c| < 1e-30) becomes ±1e-30.
        let tiny = f32x8::splat(1e-30);
        let sign = f32x8::splat(-0.0);
        let inv = d.map(|c| f32x8::ONE / c.abs().cmp_lt(tiny).blend((c & sign) | tiny, c));
        // `RayShear::new`: kz = the axis of the largest |d| (x before y, x or y before z on
        // ties); kx, ky the next two, swapped where the ray runs down kz.
        let a = d.map(|c| c.abs());
        let kxy_is_y = !a[0].cmp_gt(a[1]);
        let kz_is_z = !kxy_is_y.blend(a[1], a[0]).cmp_gt(a[2]);
        let kz = Select {
            is0: !kz_is_z & !kxy_is_y,
            is1: !kz_is_z & kxy_is_y,
        };
        let dz = kz.pick(&d);
        let neg = dz.cmp_lt(zero);
        // kx = (kz + 1 + neg) mod 3, ky = (kz + 2 − neg) mod 3.
        let kx = Select {
            is0: (kz.is1 & neg) | (kz_is_z & !neg),
            is1: (kz.is0 & !neg) | (kz_is_z & neg),
        };
        let ky = Select {
            is0: (kz.is1 & !neg) | (kz_is_z & neg),
            is1: (kz.is0 & neg) | (kz_is_z & !neg),
        };
        let sz = f32x8::ONE / dz;
        Packet {
            active,
            rays,
            t_max,
            t_far: f32x8::from(std::array::from_fn::<f32, LANES, _>(|i| {
                if active & (1 << i) != 0 {
                    t_max[i]
                } else {
                    -1.0
                }
            })),
            o,
            inv,
            kx,
            ky,
            kz,
            s: [kx.pick(&d) * sz, ky.pick(&d) * sz, sz],
        }
    }

    /// Entry distances of child `c`'s box for the eight rays, and the lanes that enter it
    /// within [0, t_far] (the robust slab test of `bvh.rs`, with Ize's scaled exit).
    #[inline(always)]
    fn slab(&self, node: &Node, c: usize, t_far: f32x8) -> (f32x8, f32x8) {
        let mut t0 = f32x8::ZERO;
        let mut t1 = f32x8::splat(f32::INFINITY);
        for axis in 0..3 {
            let (lo, hi) = node.bounds(c, axis);
            let (lo, hi) = (f32x8::splat(lo), f32x8::splat(hi));
            let a = (lo - self.o[axis]) * self.inv[axis];
            let b = (hi - self.o[axis]) * self.inv[axis];
            t0 = t0.fast_max(a.fast_min(b));
            t1 = t1.fast_min(a.fast_max(b));
        }
        let t1 = (t1 * f32x8::splat(1.000_000_4)).fast_min(t_far);
        (t0, t0.cmp_le(t1))
    }

    /// The watertight test (`triangle::intersect4`, lane for lane the same arithmetic) of the
    /// eight rays against triangle `lane` of leaf block `block`: the lanes hit with
    /// 0 < t < t_max (idle lanes never), t, b1, b2, and the lanes on an edge in single
    /// precision, which the caller redoes with the scalar test.
    #[inline(always)]
    fn triangle(&self, bvh: &Bvh, block: usize, lane: usize) -> (u32, f32x8, f32x8, f32x8, u32) {
        let tri = &bvh.tris[block];
        let rel = |k: usize| {
            let c: [f32x8; 3] = std::array::from_fn(|axis| {
                f32x8::splat(tri.v[k][axis].as_array_ref()[lane]) - self.o[axis]
            });
            let vz = self.kz.pick(&c);
            (
                self.kx.pick(&c) - self.s[0] * vz,
                self.ky.pick(&c) - self.s[1] * vz,
                self.s[2] * vz,
            )
        };
        let (ax, ay, az) = rel(0);
        let (bx, by, bz) = rel(1);
        let (cx, cy, cz) = rel(2);
        let u = cx * by - cy * bx;
        let v = ax * cy - ay * cx;
        let w = bx * ay - by * ax;
        let zero = f32x8::ZERO;
        let on_edge = (u.cmp_eq(zero) | v.cmp_eq(zero) | w.cmp_eq(zero)).move_mask() as u32;
        let outside = (u.cmp_lt(zero) | v.cmp_lt(zero) | w.cmp_lt(zero))
            & (u.cmp_gt(zero) | v.cmp_gt(zero) | w.cmp_gt(zero));
        let det = u + v + w;
        let t_scaled = u * az + v * bz + w * cz;
        let tmd = self.t_far * det;
        let in_range = (det.cmp_lt(zero) & t_scaled.cmp_lt(zero) & t_scaled.cmp_ge(tmd))
            | (det.cmp_gt(zero) & t_scaled.cmp_gt(zero) & t_scaled.cmp_le(tmd));
        let inv = f32x8::ONE / det;
        let t = t_scaled * inv;
        let valid = (in_range & t.cmp_gt(zero)).move_mask() as u32
            & !(outside.move_mask() as u32)
            & !on_edge
            & self.active;
        (valid, t, v * inv, w * inv, on_edge & self.active)
    }

    /// The scalar test, in double precision where needed, of lane `j`'s ray against triangle
    /// `lane` of `block`.
    fn triangle_one(
        &self,
        bvh: &Bvh,
        block: usize,
        lane: usize,
        j: usize,
    ) -> Option<(f32, f32, f32)> {
        let [p0, p1, p2] = bvh.tris[block].triangle(lane);
        let r = &self.rays[j];
        intersect(r.o, &RayShear::new(r.d), p0, p1, p2, self.t_max[j])
    }
}

/// A closest-hit stack entry: a child reference and the entry distance of each lane into its
/// box (+∞ for lanes that do not enter it).
type Entry = (u32, f32x8);

/// The triangles of a leaf block: a block of fewer than four repeats its last one.
fn distinct(ids: &[u32; 4]) -> usize {
    1 + (1..4).take_while(|&k| ids[k] != ids[k - 1]).count()
}

fn lanes(mask: f32x8) -> u32 {
    mask.move_mask() as u32
}

impl Bvh {
    /// [`Bvh::intersect`] for each active lane of the packet (idle lanes: `None`).
    pub fn intersect8(&self, p: &Packet) -> [Option<Hit>; LANES] {
        let mut best = [None; LANES];
        self.intersect8_into(p, &mut best);
        best
    }

    /// [`Bvh::intersect8`], written into `best` where the caller keeps it (as
    /// `Bvh::intersect_into`).
    pub fn intersect8_into(&self, p: &Packet, best: &mut [Option<Hit>; LANES]) {
        *best = [None; LANES];
        if self.nodes.is_empty() || p.active == 0 {
            return;
        }
        let inf = f32x8::splat(f32::INFINITY);
        let mut t_best = p.t_far;
        let mut stack: Stack<Entry> = Stack::new();
        stack.push((0, f32x8::ZERO));
        while let Some((node, t_entry)) = stack.pop() {
            let cull = t_best * f32x8::splat(CULL_SLACK);
            let entered = t_entry.cmp_le(cull);
            let live = lanes(entered) & p.active;
            if live == 0 {
                continue;
            }
            if live.count_ones() <= SINGLE {
                let mut t = t_best.to_array();
                for j in bits(live) {
                    self.intersect_subtree(node, &p.rays[j], p.t_max[j], &mut best[j]);
                    if let Some(h) = best[j] {
                        t[j] = h.t;
                    }
                }
                t_best = f32x8::from(t);
                continue;
            }
            if node & LEAF != 0 {
                let block = (node & !LEAF) as usize;
                let ids = &self.ids[block];
                for (k, &prim) in ids.iter().enumerate().take(distinct(ids)) {
                    let (valid, t, b1, b2, edge) = p.triangle(self, block, k);
                    let cand = valid & live & lanes(t.cmp_le(t_best));
                    let edge = edge & live;
                    if cand | edge == 0 {
                        continue;
                    }
                    let (t, b1, b2) = (t.to_array(), b1.to_array(), b2.to_array());
                    let mut tb = t_best.to_array();
                    for j in bits(cand) {
                        if closer(t[j], prim, &best[j]) {
                            tb[j] = t[j];
                            best[j] = Some(Hit {
                                t: t[j],
                                prim,
                                b1: b1[j],
                                b2: b2[j],
                            });
                        }
                    }
                    for j in bits(edge) {
                        if let Some((t, b1, b2)) = p.triangle_one(self, block, k, j) {
                            if closer(t, prim, &best[j]) {
                                tb[j] = t;
                                best[j] = Some(Hit { t, prim, b1, b2 });
                            }
                        }
                    }
                    t_best = f32x8::from(tb);
                }
                continue;
            }
            // An inner node: its children that some live lane enters, nearest (by the least
            // entry distance over lanes) popped first.
            let n = &self.nodes[node as usize];
            let mut kids: ArrayVec<(f32, Entry), WIDTH> = ArrayVec::new();
            for c in 0..WIDTH {
                let child = n.child[c];
                if child == EMPTY {
                    break;
                }
                let (t0, hit) = p.slab(n, c, cull);
                let hit = hit & entered;
                if lanes(hit) & p.active == 0 {
                    continue;
                }
                let t0 = hit.blend(t0, inf);
                let key = t0.to_array().into_iter().fold(f32::INFINITY, f32::min);
                let e = (key, (child, t0));
                // Insertion sort, farthest first.
                let mut j = kids.len();
                kids.push(e);
                while j > 0 && kids[j - 1].0 < key {
                    kids[j] = kids[j - 1];
                    j -= 1;
                }
                kids[j] = e;
            }
            for (_, e) in kids {
                stack.push(e);
            }
        }
    }

    /// [`Bvh::occluded`] for each active lane of the packet: bit i set if lane i's ray is
    /// blocked.
    pub fn occluded8(&self, p: &Packet) -> u32 {
        let mut blocked = 0u32;
        if self.nodes.is_empty() || p.active == 0 {
            return 0;
        }
        // Entries: a child reference and the lanes that enter it (bit i: lane i).
        let mut stack: Stack<(u32, u32)> = Stack::new();
        stack.push((0, p.active));
        while let Some((node, m)) = stack.pop() {
            let live = m & !blocked;
            if live == 0 {
                continue;
            }
            if live.count_ones() <= SINGLE {
                for j in bits(live) {
                    if self.occluded_subtree(node, &p.rays[j], p.t_max[j]) {
                        blocked |= 1 << j;
                    }
                }
            } else if node & LEAF != 0 {
                let block = (node & !LEAF) as usize;
                for k in 0..distinct(&self.ids[block]) {
                    let (valid, _, _, _, edge) = p.triangle(self, block, k);
                    blocked |= valid & live;
                    for j in bits(edge & live & !blocked) {
                        if p.triangle_one(self, block, k, j).is_some() {
                            blocked |= 1 << j;
                        }
                    }
                    if live & !blocked == 0 {
                        break;
                    }
                }
            } else {
                let n = &self.nodes[node as usize];
                for c in 0..WIDTH {
                    let child = n.child[c];
                    if child == EMPTY {
                        break;
                    }
                    let hit = lanes(p.slab(n, c, p.t_far).1) & live;
                    if hit != 0 {
                        stack.push((child, hit));
                    }
                }
            }
            if blocked == p.active {
                break;
            }
        }
        blocked
    }
}

/// The set bits of `m`, lowest first.
fn bits(mut m: u32) -> impl Iterator<Item = usize> {
    std::iter::from_fn(move || {
        (m != 0).then(|| {
            let j = m.trailing_zeros() as usize;
            m &= m - 1;
            j
        })
    })
}

#[cfg(test)]
mod tests {
    use super::super::bvh::slab_component;
    use super::*;
    use crate::math::sampler::TestRng as Rng;

    #[test]
    fn packet_setup_is_the_one_ray_setup_lane_for_lane() {
        // Reciprocals and shears of random directions and of the awkward ones: on an axis
        // (±0 components), on ties between axes, below 1e-30.
        let mut rng = Rng(21);
        let mut dirs: Vec<Vec3> = (0..400).map(|_| rng.vec3() * 2.0 - 1.0).collect();
        for (x, y, z) in [
            (1.0, 0.0, 0.0),
            (-0.0, -1.0, 0.0),
            (0.0, 0.0, -1.0),
            (1.0, 1.0, 0.5),
            (-1.0, 1.0, 1.0),
            (0.5, -1.0, 1.0),
            (1.0, -1.0, -1.0),
            (1e-31, -1e-31, 1.0),
            (-2e-30, 1.0, -0.0),
        ] {
            dirs.push(Vec3::new(x, y, z));
        }
        for chunk in dirs.chunks(LANES) {
            let rays: [Ray; LANES] = std::array::from_fn(|i| {
                Ray::new(Vec3::ZERO, chunk.get(i).copied().unwrap_or(Vec3::Z))
            });
            let p = Packet::new(rays, [1.0; LANES], (1 << chunk.len()) - 1);
            let at = |v: f32x8, i: usize| v.to_array()[i].to_bits();
            for (i, r) in rays.iter().enumerate().take(chunk.len()) {
                let d = r.d.to_array();
                for axis in 0..3 {
                    let want = 1.0 / slab_component(d[axis]);
                    assert_eq!(at(p.inv[axis], i), want.to_bits(), "{:?}", r.d);
                }
                let sh = RayShear::new(r.d);
                let axis = |sel: &Select| {
                    let c: [f32x8; 3] = std::array::from_fn(|k| f32x8::splat(k as f32));
                    sel.pick(&c).to_array()[i] as usize
                };
                assert_eq!(
                    (axis(&p.kx), axis(&p.ky), axis(&p.kz)),
                    (sh.kx, sh.ky, sh.kz),
                    "{:?}",
                    r.d
                );
                let s = [sh.sx, sh.sy, sh.sz].map(f32::to_bits);
                assert_eq!([0, 1, 2].map(|k| at(p.s[k], i)), s, "{:?}", r.d);
            }
        }
    }

    /// Packets of random rays (some lanes idle) give each ray's one-ray answer to the bit.
    fn check(tris: &[[Vec3; 3]], rays: &[(Ray, f32)], seed: u64) {
        let bvh = Bvh::build(tris);
        let mut rng = Rng(seed);
        let mut checked = 0;
        for chunk in rays.chunks(LANES) {
            let mut r = [Ray::new(Vec3::ZERO, Vec3::Z); LANES];
            let mut t = [0.0; LANES];
            let mut active = 0;
            for (i, &(ray, t_max)) in chunk.iter().enumerate() {
                (r[i], t[i]) = (ray, t_max);
                if rng.f32() < 0.9 {
                    active |= 1 << i;
                }
            }
            let p = Packet::new(r, t, active);
            let hits = bvh.intersect8(&p);
            let blocked = bvh.occluded8(&p);
            for i in 0..LANES {
                if active & (1 << i) == 0 {
                    assert!(hits[i].is_none() && blocked & (1 << i) == 0);
                    continue;
                }
                assert_eq!(hits[i], bvh.intersect(&r[i], t[i]), "ray {:?}", r[i]);
                assert_eq!(blocked & (1 << i) != 0, bvh.occluded(&r[i], t[i]));
                checked += 1;
            }
        }
        assert!(checked > rays.len() / 2);
    }

    #[test]
    fn packets_give_the_one_ray_answers_to_the_bit() {
        let mut rng = Rng(7);
        // A closed box of quads (every ray inside hits, ties on the diagonals and edges), and a
        // cloud of random triangles (deep tree: packets thin out to single rays).
        let cube: Vec<[Vec3; 3]> = {
            let c = |x: f32, y: f32, z: f32| Vec3::new(x, y, z) * 2.0 - 1.0;
            let q = [
                [c(0., 0., 0.), c(1., 0., 0.), c(1., 1., 0.), c(0., 1., 0.)],
                [c(0., 0., 1.), c(1., 0., 1.), c(1., 1., 1.), c(0., 1., 1.)],
                [c(0., 0., 0.), c(0., 1., 0.), c(0., 1., 1.), c(0., 0., 1.)],
                [c(1., 0., 0.), c(1., 1., 0.), c(1., 1., 1.), c(1., 0., 1.)],
                [c(0., 0., 0.), c(1., 0., 0.), c(1., 0., 1.), c(0., 0., 1.)],
                [c(0., 1., 0.), c(1., 1., 0.), c(1., 1., 1.), c(0., 1., 1.)],
            ];
            q.iter()
                .flat_map(|q| [[q[0], q[1], q[2]], [q[0], q[2], q[3]]])
                .collect()
        };
        let mut cloud = Vec::new();
        for _ in 0..3000 {
            let c = rng.vec3() * 10.0;
            cloud.push([c, c + rng.vec3() - 0.5, c + rng.vec3() - 0.5]);
        }
        let mut inside = Vec::new();
        for k in 0..4000 {
            let o = rng.vec3() * 1.6 - 0.8;
            // Rays at the box's corners and diagonals, where two triangles tie.
            let d = match k % 4 {
                0 => Vec3::ONE - o,
                1 => Vec3::new(1.0, 1.0, 0.0) - o,
                _ => rng.vec3() - 0.5,
            };
            let t_max = if k % 3 == 0 { 0.7 } else { f32::INFINITY };
            inside.push((Ray::new(o, d), t_max));
        }
        check(&cube, &inside, 1);
        let mut through = Vec::new();
        for k in 0..4000 {
            let d = if k % 5 == 0 {
                [Vec3::X, -Vec3::Y, Vec3::Z][k % 3]
            } else {
                rng.vec3() - 0.5
            };
            let t_max = if k % 3 == 0 { 4.0 } else { f32::INFINITY };
            through.push((Ray::new(rng.vec3() * 14.0 - 2.0, d), t_max));
        }
        check(&cloud, &through, 2);
    }
}
