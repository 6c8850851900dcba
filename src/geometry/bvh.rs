//! The bounding volume hierarchy: sixteen-wide, each node's child boxes laid out as Embree
//! lays out its eight-wide nodes for AVX (Wald et al. 2014, "Embree: a kernel framework for
//! efficient CPU ray tracing") in two eight-wide halves, each tested with one SIMD slab test;
//! each leaf four triangles tested at once by the watertight test of `triangle.rs`
//! ([`intersect4`]). Built by `bvh_build.rs` (binned SAH, then collapsed from binary to
//! sixteen-wide).
//!
//! Sixteen-wide over eight-wide by measurement. A room's rays start inside the root's box and
//! enter several children of every node they visit, so what costs is the node visit (its
//! branches on how many children were entered, its stack traffic), not the box test. A small
//! room's leaves all sit under the root, where eight-wide needed a root and two nodes, so a
//! ray visits fewer nodes; large meshes are unchanged. Eight-wide had replaced four-wide the
//! same way. The figures are in `bench/README.md`, "Design measurements".
//!
//! Chosen by measurement over the obvhs crate's eight-wide compressed BVH, which tested one
//! triangle at a time with the scalar test: the same images to the bit, faster renders and
//! primary rays on large meshes (only the camera's coherent rays on a tiny scene favoured
//! obvhs's ordered eight-wide nodes).
//!
//! Traversal is front-to-back for closest hits (children sorted by entry distance, popped
//! entries culled against the closest hit so far) and stops at the first hit for shadow rays.
//! The slab test is the robust one of Ize 2013 ("Robust BVH ray traversal"): exit distances
//! are scaled up by 1 + 2γ(3), so a ray never slips between boxes that share a face.

use super::aabb::Aabb;
use super::triangle::{intersect4, RayShear, Tri4};
use super::{Hit, Ray};
use arrayvec::ArrayVec;
use glam::Vec3A;
use wide::{f32x8, CmpLe};

/// A child reference with this bit set is a leaf: the rest is the index of its `Tri4` block.
pub(super) const LEAF: u32 = 1 << 31;
/// The child reference of an unused slot (its box is empty, so it is never entered).
pub(super) const EMPTY: u32 = u32::MAX;

/// Eight-wide SIMD registers per node (AVX; two SSE registers where the CPU has no AVX).
pub(super) const HALVES: usize = 2;
/// Children per node: one lane each of `HALVES` eight-wide registers.
pub(super) const WIDTH: usize = 8 * HALVES;

/// `WIDTH` child boxes in structure-of-arrays form: `b[h][0][axis]` the minima, `b[h][1][axis]`
/// the maxima, lane i of half h for child 8h + i.
#[derive(Clone, Copy, Debug)]
pub(super) struct Node {
    pub b: [[[f32x8; 3]; 2]; HALVES],
    pub child: [u32; WIDTH],
    /// Bit i: child i is a leaf.
    pub leaves: u32,
}

impl Node {
    pub(super) const EMPTY: Node = Node {
        b: [[
            [f32x8::new([f32::INFINITY; 8]); 3],
            [f32x8::new([f32::NEG_INFINITY; 8]); 3],
        ]; HALVES],
        child: [EMPTY; WIDTH],
        leaves: 0,
    };

    pub(super) fn set(&mut self, slot: usize, bounds: &Aabb, child: u32) {
        let (h, lane) = (slot / 8, slot % 8);
        for axis in 0..3 {
            self.b[h][0][axis].as_array_mut()[lane] = bounds.min[axis];
            self.b[h][1][axis].as_array_mut()[lane] = bounds.max[axis];
        }
        self.child[slot] = child;
        if child != EMPTY && child & LEAF != 0 {
            self.leaves |= 1 << slot;
        }
    }

    /// Child `slot`'s box: (minimum, maximum) along `axis`.
    #[inline(always)]
    pub(super) fn bounds(&self, slot: usize, axis: usize) -> (f32, f32) {
        let b = &self.b[slot / 8];
        (
            b[0][axis].as_array_ref()[slot % 8],
            b[1][axis].as_array_ref()[slot % 8],
        )
    }
}

pub struct Bvh {
    /// Node 0 is the root (when there is any triangle).
    pub(super) nodes: Vec<Node>,
    pub(super) tris: Vec<Tri4>,
    /// For each block of `tris`, the index of each lane's triangle in the caller's list.
    pub(super) ids: Vec<[u32; 4]>,
    pub(super) bounds: Aabb,
}

/// What a ray needs for the slab tests: its origin and reciprocal direction splatted, and for
/// each axis which of a box's planes (0: min, 1: max) it meets first.
struct SlabRay {
    o: [f32x8; 3],
    inv: [f32x8; 3],
    near: [usize; 3],
}

impl SlabRay {
    fn new(ray: &Ray) -> SlabRay {
        let d = Vec3A::from(ray.d.to_array().map(slab_component));
        // One SIMD division for the three reciprocals.
        let inv = (Vec3A::ONE / d).to_array();
        let neg = d.is_negative_bitmask() as usize;
        SlabRay {
            o: [
                f32x8::splat(ray.o.x),
                f32x8::splat(ray.o.y),
                f32x8::splat(ray.o.z),
            ],
            inv: [
                f32x8::splat(inv[0]),
                f32x8::splat(inv[1]),
                f32x8::splat(inv[2]),
            ],
            near: [neg & 1, neg >> 1 & 1, neg >> 2 & 1],
        }
    }

    /// Entry distances of the node's boxes and the mask (bit i: child i) of those entered within
    /// [0, t_max]: one eight-wide test per half.
    #[inline(always)]
    fn hit(&self, node: &Node, t_max: f32) -> ([f32; WIDTH], u32) {
        let mut t0s = [0.0f32; WIDTH];
        let mut mask = 0;
        for (h, b) in node.b.iter().enumerate() {
            let mut t0 = f32x8::ZERO;
            let mut t1 = f32x8::splat(f32::INFINITY);
            for axis in 0..3 {
                let n = self.near[axis];
                t0 = t0.fast_max((b[n][axis] - self.o[axis]) * self.inv[axis]);
                t1 = t1.fast_min((b[1 - n][axis] - self.o[axis]) * self.inv[axis]);
            }
            // Ize 2013: 1 + 2γ(3), γ(n) = nε / (1 − nε).
            let t1 = (t1 * f32x8::splat(1.000_000_4)).fast_min(f32x8::splat(t_max));
            t0s[8 * h..8 * h + 8].copy_from_slice(&t0.to_array());
            mask |= (t0.cmp_le(t1).move_mask() as u32) << (8 * h);
        }
        (t0s, mask)
    }
}

/// A traversal stack of entries `E` (a child reference and what the traversal keeps with it):
/// 64 entries inline, uninitialised until pushed (far more than a balanced tree needs), a heap
/// spill beyond that for pathological trees. Also the packet traversal's (`packet.rs`).
pub(super) struct Stack<E> {
    inline: ArrayVec<E, 64>,
    spill: Vec<E>,
}

impl<E> Stack<E> {
    #[inline(always)]
    pub(super) fn new() -> Stack<E> {
        Stack {
            inline: ArrayVec::new(),
            spill: Vec::new(),
        }
    }
    #[inline(always)]
    pub(super) fn push(&mut self, e: E) {
        if let Err(e) = self.inline.try_push(e) {
            self.spill.push(e.element());
        }
    }
    #[inline(always)]
    pub(super) fn pop(&mut self) -> Option<E> {
        self.spill.pop().or_else(|| self.inline.pop())
    }
}

/// A ray direction component made safe to take the reciprocal of for slab tests: a zero
/// becomes ±1e-30, so that (b − o) / d is never 0 × ∞ = NaN, and ±1e30 is far beyond any scene.
#[inline(always)]
pub(super) fn slab_component(c: f32) -> f32 {
    if c.abs() < 1e-30 {
        1e-30f32.copysign(c)
    } else {
        c
    }
}

impl Bvh {
    pub fn bounds(&self) -> Aabb {
        self.bounds
    }

    pub fn node_count(&self) -> usize {
        self.nodes.len()
    }

    /// The closest hit with 0 < t < `t_max`. Of triangles hit at the same distance, the one
    /// with the lowest index: the answer does not depend on the order of traversal, so the
    /// packet traversal of `packet.rs` gives the same hit to the bit.
    pub fn intersect(&self, ray: &Ray, t_max: f32) -> Option<Hit> {
        let mut best = None;
        self.intersect_into(ray, t_max, &mut best);
        best
    }

    /// [`Bvh::intersect`], written into `best` where the caller keeps it: the traversal writes
    /// the hit a field at a time, and a copy of it read as a whole right after could not be
    /// forwarded from the store buffer (`read_apart`).
    #[inline]
    pub fn intersect_into(&self, ray: &Ray, t_max: f32, best: &mut Option<Hit>) {
        *best = None;
        if !self.nodes.is_empty() {
            self.intersect_subtree(0, ray, t_max, best);
        }
    }

    /// [`Bvh::intersect`] within the subtree under child reference `start` (a node, or a leaf
    /// with `LEAF` set), improving on `best`, a hit found elsewhere.
    pub(super) fn intersect_subtree(
        &self,
        start: u32,
        ray: &Ray,
        t_max: f32,
        best: &mut Option<Hit>,
    ) {
        let ray = &read_apart(ray);
        let slab = SlabRay::new(ray);
        let sh = RayShear::new(ray.d);
        let mut t_best = best.map_or(t_max, |b| b.t);
        let mut stack = Stack::new();
        let mut node = start;
        loop {
            if node & LEAF != 0 {
                let block = (node & !LEAF) as usize;
                let h = intersect4(ray.o, &sh, &self.tris[block], t_max);
                if let Some(i) = h.nearest(&self.ids[block]) {
                    let prim = self.ids[block][i];
                    if closer(h.t[i], prim, best) {
                        t_best = h.t[i];
                        *best = Some(Hit {
                            t: t_best,
                            prim,
                            b1: h.b1[i],
                            b2: h.b2[i],
                        });
                    }
                }
            } else {
                let n = &self.nodes[node as usize];
                let (t0, mut mask) = slab.hit(n, t_best * CULL_SLACK);
                if mask != 0 {
                    let a = mask.trailing_zeros() as usize;
                    mask &= mask - 1;
                    if mask == 0 {
                        node = n.child[a];
                        continue;
                    }
                    let b = mask.trailing_zeros() as usize;
                    mask &= mask - 1;
                    // Two children entered (the common case): the nearer now, the other later.
                    let (near, far) = if t0[b] < t0[a] { (b, a) } else { (a, b) };
                    if mask == 0 {
                        stack.push((n.child[far], t0[far]));
                        node = n.child[near];
                        continue;
                    }
                    // Three or more: sort them, farthest first; visit the nearest now.
                    let mut hits = [(0u32, 0.0f32); WIDTH];
                    hits[0] = (n.child[far], t0[far]);
                    hits[1] = (n.child[near], t0[near]);
                    let mut k = 2;
                    while mask != 0 {
                        let i = mask.trailing_zeros() as usize;
                        mask &= mask - 1;
                        let e = (n.child[i], t0[i]);
                        let mut j = k;
                        while j > 0 && hits[j - 1].1 < e.1 {
                            hits[j] = hits[j - 1];
                            j -= 1;
                        }
                        hits[j] = e;
                        k += 1;
                    }
                    for &h in &hits[..k - 1] {
                        stack.push(h);
                    }
                    node = hits[k - 1].0;
                    continue;
                }
            }
            // Pop, skipping subtrees entered beyond the closest hit so far.
            loop {
                match stack.pop() {
                    None => return,
                    Some((n, t0)) if t0 <= t_best * CULL_SLACK => {
                        node = n;
                        break;
                    }
                    Some(_) => {}
                }
            }
        }
    }

    /// Whether anything is hit with 0 < t < `t_max` (shadow rays).
    pub fn occluded(&self, ray: &Ray, t_max: f32) -> bool {
        !self.nodes.is_empty() && self.occluded_subtree(0, ray, t_max)
    }

    /// [`Bvh::occluded`] within the subtree under child reference `start`.
    pub(super) fn occluded_subtree(&self, start: u32, ray: &Ray, t_max: f32) -> bool {
        let ray = &read_apart(ray);
        let slab = SlabRay::new(ray);
        // Most shadow rays in a room reach no leaf (figure6: 0.3 leaf tests per ray), so the
        // triangle test's setup waits for the first leaf.
        let mut sh: Option<RayShear> = None;
        let mut stack = Stack::new();
        let mut node = start;
        loop {
            if node & LEAF != 0 {
                let block = (node & !LEAF) as usize;
                let sh = sh.get_or_insert_with(|| RayShear::new(ray.d));
                if intersect4(ray.o, sh, &self.tris[block], t_max).valid != 0 {
                    return true;
                }
            } else {
                let n = &self.nodes[node as usize];
                let (_, mask) = slab.hit(n, t_max);
                // The leaves entered are tested at once, in child order (any hit will do),
                // without going through the stack.
                let mut leaves = mask & n.leaves;
                while leaves != 0 {
                    let block = (n.child[leaves.trailing_zeros() as usize] & !LEAF) as usize;
                    leaves &= leaves - 1;
                    let sh = sh.get_or_insert_with(|| RayShear::new(ray.d));
                    if intersect4(ray.o, sh, &self.tris[block], t_max).valid != 0 {
                        return true;
                    }
                }
                let mut inner = mask & !n.leaves;
                if inner != 0 {
                    let first = inner.trailing_zeros() as usize;
                    inner &= inner - 1;
                    while inner != 0 {
                        let i = inner.trailing_zeros() as usize;
                        inner &= inner - 1;
                        stack.push((n.child[i], 0.0));
                    }
                    node = n.child[first];
                    continue;
                }
            }
            match stack.pop() {
                None => return false,
                Some((n, _)) => node = n,
            }
        }
    }
}

/// The ray, its six components read one float at a time (`math::read_apart`): the path loop
/// writes lanes' rays a float at a time, and reading them whole would stall on those narrow
/// stores. Writing the rays with wide stores instead (rows of eight-lane transposes) measured
/// slower: the copy into a `Ray` then split its direction across two stores
/// (`bench/README.md`, "Design measurements").
#[inline(always)]
fn read_apart(ray: &Ray) -> Ray {
    Ray::new(
        crate::math::read_apart(&ray.o),
        crate::math::read_apart(&ray.d),
    )
}

/// Boxes are culled against the closest hit so far only beyond `t_best × CULL_SLACK`: a box's
/// entry distance and a triangle's hit distance are rounded differently, and a triangle hit at
/// t_best (a tie) must still be found whatever the order of traversal.
pub(super) const CULL_SLACK: f32 = 1.000_002;

/// Whether a hit at `t` on triangle `prim` replaces `best`: nearer, or as near with a lower
/// index.
#[inline(always)]
pub(super) fn closer(t: f32, prim: u32, best: &Option<Hit>) -> bool {
    match best {
        None => true,
        Some(b) => t < b.t || (t == b.t && prim < b.prim),
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::super::triangle::intersect;
    use super::*;
    use crate::math::sampler::TestRng as Rng;
    use glam::Vec3;

    /// Reference: test every triangle.
    pub(crate) fn brute(tris: &[[Vec3; 3]], ray: &Ray, t_max: f32) -> Option<Hit> {
        let sh = RayShear::new(ray.d);
        let mut best: Option<Hit> = None;
        for (i, t) in tris.iter().enumerate() {
            let lim = best.map_or(t_max, |b| b.t);
            if let Some((t, b1, b2)) = intersect(ray.o, &sh, t[0], t[1], t[2], lim) {
                best = Some(Hit {
                    t,
                    prim: i as u32,
                    b1,
                    b2,
                });
            }
        }
        best
    }

    /// Asserts that two closest-hit answers agree: same distance, and the same triangle unless
    /// two triangles are hit at the same distance.
    pub(crate) fn assert_same_hit(a: Option<Hit>, b: Option<Hit>) {
        match (a, b) {
            (None, None) => {}
            (Some(a), Some(b)) => {
                assert!((a.t - b.t).abs() <= 1e-5 * b.t, "t {} vs {}", a.t, b.t);
                assert!(
                    a.prim == b.prim || a.t == b.t,
                    "prim {} vs {}",
                    a.prim,
                    b.prim
                );
            }
            _ => panic!("hit mismatch: {a:?} vs {b:?}"),
        }
    }

    #[test]
    fn surfaces_very_close_to_the_origin_are_hit() {
        // A triangle 10⁻⁵ in front of the origin and another behind it (obvhs, the BVH used
        // before, skipped boxes left before t = 10⁻⁴).
        let tris = vec![
            [
                Vec3::new(-1.0, -1.0, 1e-5),
                Vec3::new(1.0, -1.0, 1e-5),
                Vec3::new(0.0, 1.0, 1e-5),
            ],
            [
                Vec3::new(-1.0, -1.0, -1e-5),
                Vec3::new(1.0, -1.0, -1e-5),
                Vec3::new(0.0, 1.0, -1e-5),
            ],
            [
                Vec3::new(-1.0, -1.0, 5.0),
                Vec3::new(1.0, -1.0, 5.0),
                Vec3::new(0.0, 1.0, 5.0),
            ],
        ];
        let bvh = Bvh::build(&tris);
        let ray = Ray::new(Vec3::ZERO, Vec3::Z);
        let h = bvh.intersect(&ray, f32::INFINITY).unwrap();
        assert_eq!(h.prim, 0);
        assert!((h.t - 1e-5).abs() < 1e-9, "{}", h.t);
        assert!(bvh.occluded(&ray, 1e-3));
        assert!(!bvh.occluded(&ray, 5e-6));
        assert_eq!(
            bvh.intersect(&Ray::new(Vec3::ZERO, -Vec3::Z), 1.0)
                .unwrap()
                .prim,
            1
        );
    }

    #[test]
    fn degenerate_and_skewed_inputs_build_usable_trees() {
        let mut rng = Rng(5);
        // 3000 copies of one triangle (all centroids coincide: no SAH split exists), and
        // triangles at exponentially growing distances (the SAH peels one off per level, so
        // the depth limit and the stack's spill are exercised).
        let one = [Vec3::ZERO, Vec3::X, Vec3::Y];
        let same = vec![one; 3000];
        let skewed: Vec<[Vec3; 3]> = (0..120)
            .map(|i| {
                let c = Vec3::splat(1.2f32.powi(i));
                [c, c + Vec3::X * 0.1, c + Vec3::Y * 0.1]
            })
            .collect();
        for (k, tris) in [same, skewed].into_iter().enumerate() {
            let bvh = Bvh::build(&tris);
            assert!(bvh.ids.iter().all(|ids| ids.is_sorted()));
            for _ in 0..3000 {
                let o = rng.vec3() * 2.0 - 0.5;
                let ray = Ray::new(o, rng.vec3() - 0.5);
                let b = brute(&tris, &ray, f32::INFINITY);
                assert_same_hit(bvh.intersect(&ray, f32::INFINITY), b);
                assert_eq!(bvh.occluded(&ray, f32::INFINITY), b.is_some());
                if k == 0 {
                    // Every copy is hit at once: the lowest index wins.
                    let prim = bvh.intersect(&ray, f32::INFINITY).map(|h| h.prim);
                    assert_eq!(prim, b.map(|_| 0));
                }
            }
            // Rays along the skewed diagonal meet many boxes at once.
            for i in 0..500 {
                let ray = Ray::new(
                    Vec3::splat(-1.0),
                    Vec3::new(1.0, 1.0 + i as f32 * 1e-4, 1.0),
                );
                let b = brute(&tris, &ray, f32::INFINITY);
                assert_same_hit(bvh.intersect(&ray, f32::INFINITY), b);
            }
        }
    }

    #[test]
    fn bvh_matches_brute_force_on_random_triangles() {
        let mut rng = Rng(3);
        let mut tris = Vec::new();
        for _ in 0..2000 {
            let c = rng.vec3() * 10.0;
            tris.push([c, c + rng.vec3() - 0.5, c + rng.vec3() - 0.5]);
        }
        let bvh = Bvh::build(&tris);
        for _ in 0..5000 {
            let ray = Ray::new(rng.vec3() * 14.0 - 2.0, rng.vec3() - 0.5);
            let b = brute(&tris, &ray, f32::INFINITY);
            assert_same_hit(bvh.intersect(&ray, f32::INFINITY), b);
            assert_eq!(bvh.occluded(&ray, f32::INFINITY), b.is_some());
        }
        // Axis-aligned directions, whose zero components are −0 when negated.
        for k in 0..3000 {
            let axis = [Vec3::X, Vec3::Y, Vec3::Z][k % 3];
            let d = if k % 2 == 0 { axis } else { -axis };
            let ray = Ray::new(rng.vec3() * 10.0, d);
            let b = brute(&tris, &ray, f32::INFINITY);
            assert_same_hit(bvh.intersect(&ray, f32::INFINITY), b);
            assert_eq!(bvh.occluded(&ray, f32::INFINITY), b.is_some());
        }
    }
}
