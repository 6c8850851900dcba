//! Bounding volume hierarchy over triangles, built with the binned surface area heuristic
//! (Wald 2007, "On fast construction of SAH-based bounding volume hierarchies") and traversed
//! front-to-back with the watertight triangle test of `triangle.rs`.
//!
//! Nodes are stored depth-first: an interior node's left child follows it, its right child is
//! at `offset`. Leaves hold `count` consecutive triangles starting at `offset` in `tris`, which
//! keeps the vertices of each leaf together in memory.

use super::aabb::Aabb;
use super::triangle::{intersect, RayShear};
use super::{Hit, Ray};
use glam::Vec3;

const BINS: usize = 16;
const MAX_LEAF: usize = 8;
/// Cost of a traversal step relative to one triangle test.
const TRAVERSAL_COST: f32 = 1.0;

#[derive(Clone, Copy, Debug)]
struct Node {
    bounds: Aabb,
    /// Interior: index of the right child. Leaf: first triangle.
    offset: u32,
    /// 0 for an interior node.
    count: u16,
    axis: u16,
}

pub struct Bvh {
    nodes: Vec<Node>,
    /// Triangle vertices in leaf order.
    tris: Vec<[Vec3; 3]>,
    /// For each entry of `tris`, the index of the triangle in the caller's list.
    ids: Vec<u32>,
}

struct BuildPrim {
    bounds: Aabb,
    centroid: Vec3,
    id: u32,
}

impl Bvh {
    /// Builds the hierarchy over `tris` (the index of a triangle in this slice is what `Hit::prim`
    /// reports).
    pub fn build(tris: &[[Vec3; 3]]) -> Bvh {
        let mut prims: Vec<BuildPrim> = tris
            .iter()
            .enumerate()
            .map(|(i, t)| {
                let mut b = Aabb::EMPTY;
                t.iter().for_each(|&p| b.grow(p));
                BuildPrim {
                    bounds: b,
                    centroid: b.centroid(),
                    id: i as u32,
                }
            })
            .collect();
        let mut nodes = Vec::with_capacity(2 * tris.len() / MAX_LEAF.max(1) + 1);
        if !prims.is_empty() {
            build_node(&mut prims, 0, &mut nodes);
        }
        let ids: Vec<u32> = prims.iter().map(|p| p.id).collect();
        let tris = ids.iter().map(|&i| tris[i as usize]).collect();
        Bvh { nodes, tris, ids }
    }

    pub fn bounds(&self) -> Aabb {
        self.nodes.first().map(|n| n.bounds).unwrap_or(Aabb::EMPTY)
    }

    pub fn node_count(&self) -> usize {
        self.nodes.len()
    }

    /// The closest hit with 0 < t < `t_max`.
    pub fn intersect(&self, ray: &Ray, t_max: f32) -> Option<Hit> {
        self.traverse::<false>(ray, t_max)
    }

    /// Whether anything is hit with 0 < t < `t_max` (shadow rays).
    pub fn occluded(&self, ray: &Ray, t_max: f32) -> bool {
        self.traverse::<true>(ray, t_max).is_some()
    }

    #[inline]
    fn traverse<const ANY: bool>(&self, ray: &Ray, t_max: f32) -> Option<Hit> {
        if self.nodes.is_empty() {
            return None;
        }
        let inv_d = ray.d.recip();
        let sh = RayShear::new(ray.d);
        let neg = [ray.d.x < 0.0, ray.d.y < 0.0, ray.d.z < 0.0];
        let mut best: Option<Hit> = None;
        let mut t_best = t_max;
        let mut stack = [0u32; 64];
        let mut sp = 0usize;
        let mut idx = 0usize;
        self.nodes[0].bounds.hit(ray.o, inv_d, t_best)?;
        loop {
            let node = &self.nodes[idx];
            if node.count > 0 {
                let first = node.offset as usize;
                for i in first..first + node.count as usize {
                    let [p0, p1, p2] = self.tris[i];
                    if let Some((t, b1, b2)) = intersect(ray.o, &sh, p0, p1, p2, t_best) {
                        t_best = t;
                        best = Some(Hit {
                            t,
                            prim: self.ids[i],
                            b1,
                            b2,
                        });
                        if ANY {
                            return best;
                        }
                    }
                }
            } else {
                let (mut near, mut far) = (idx + 1, node.offset as usize);
                if neg[node.axis as usize] {
                    std::mem::swap(&mut near, &mut far);
                }
                let hn = self.nodes[near].bounds.hit(ray.o, inv_d, t_best);
                let hf = self.nodes[far].bounds.hit(ray.o, inv_d, t_best);
                match (hn, hf) {
                    (Some(tn), Some(tf)) => {
                        // Visit the nearer box first.
                        let (first, second) = if tf < tn { (far, near) } else { (near, far) };
                        stack[sp] = second as u32;
                        sp += 1;
                        idx = first;
                        continue;
                    }
                    (Some(_), None) => {
                        idx = near;
                        continue;
                    }
                    (None, Some(_)) => {
                        idx = far;
                        continue;
                    }
                    (None, None) => {}
                }
            }
            // Pop, skipping nodes that the current best hit already rules out.
            loop {
                if sp == 0 {
                    return best;
                }
                sp -= 1;
                idx = stack[sp] as usize;
                if self.nodes[idx].bounds.hit(ray.o, inv_d, t_best).is_some() {
                    break;
                }
            }
        }
    }
}

/// Builds the subtree over `prims` (whose first element sits at `first` in the final triangle
/// order) and returns its node index.
fn build_node(prims: &mut [BuildPrim], first: usize, nodes: &mut Vec<Node>) -> usize {
    let mut bounds = Aabb::EMPTY;
    let mut cbounds = Aabb::EMPTY;
    for p in prims.iter() {
        bounds = bounds.union(&p.bounds);
        cbounds.grow(p.centroid);
    }
    let me = nodes.len();
    nodes.push(Node {
        bounds,
        offset: first as u32,
        count: prims.len() as u16,
        axis: 0,
    });
    if prims.len() <= 2 {
        return me;
    }
    let split = best_split(prims, &bounds, &cbounds);
    let mid = match split {
        Some((axis, pos, cost)) => {
            let leaf_cost = prims.len() as f32;
            if cost >= leaf_cost && prims.len() <= MAX_LEAF {
                return me;
            }
            let mid = partition(prims, |p| p.centroid[axis] < pos);
            nodes[me].axis = axis as u16;
            if mid == 0 || mid == prims.len() {
                median_split(prims, axis)
            } else {
                mid
            }
        }
        None => {
            // All centroids coincide: split in the middle of the list if the leaf is too big.
            if prims.len() <= MAX_LEAF {
                return me;
            }
            prims.len() / 2
        }
    };
    nodes[me].count = 0;
    let (left, right) = prims.split_at_mut(mid);
    build_node(left, first, nodes);
    let r = build_node(right, first + mid, nodes);
    nodes[me].offset = r as u32;
    me
}

fn median_split(prims: &mut [BuildPrim], axis: usize) -> usize {
    let mid = prims.len() / 2;
    prims.select_nth_unstable_by(mid, |a, b| a.centroid[axis].total_cmp(&b.centroid[axis]));
    mid
}

fn partition(prims: &mut [BuildPrim], pred: impl Fn(&BuildPrim) -> bool) -> usize {
    let mut i = 0;
    for j in 0..prims.len() {
        if pred(&prims[j]) {
            prims.swap(i, j);
            i += 1;
        }
    }
    i
}

/// The binned-SAH split: (axis, plane position, cost in units of triangle tests).
fn best_split(prims: &[BuildPrim], bounds: &Aabb, cbounds: &Aabb) -> Option<(usize, f32, f32)> {
    let extent = cbounds.max - cbounds.min;
    let parent_area = bounds.area().max(f32::MIN_POSITIVE);
    let mut best: Option<(usize, f32, f32)> = None;
    for axis in 0..3 {
        if !(extent[axis] > 0.0) {
            continue;
        }
        let scale = BINS as f32 / extent[axis];
        let mut bin_bounds = [Aabb::EMPTY; BINS];
        let mut bin_count = [0u32; BINS];
        for p in prims {
            let b = (((p.centroid[axis] - cbounds.min[axis]) * scale) as usize).min(BINS - 1);
            bin_count[b] += 1;
            bin_bounds[b] = bin_bounds[b].union(&p.bounds);
        }
        // Sweep from the right, then from the left.
        let mut right_area = [0.0f32; BINS];
        let mut right_count = [0u32; BINS];
        let (mut acc, mut n) = (Aabb::EMPTY, 0);
        for i in (1..BINS).rev() {
            acc = acc.union(&bin_bounds[i]);
            n += bin_count[i];
            right_area[i] = acc.area();
            right_count[i] = n;
        }
        let (mut acc, mut n) = (Aabb::EMPTY, 0);
        for i in 0..BINS - 1 {
            acc = acc.union(&bin_bounds[i]);
            n += bin_count[i];
            if n == 0 || right_count[i + 1] == 0 {
                continue;
            }
            let cost = TRAVERSAL_COST
                + (acc.area() * n as f32 + right_area[i + 1] * right_count[i + 1] as f32)
                    / parent_area;
            if best.is_none_or(|b| cost < b.2) {
                let pos = cbounds.min[axis] + (i + 1) as f32 / scale;
                best = Some((axis, pos, cost));
            }
        }
    }
    best
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Reference: test every triangle.
    fn brute(tris: &[[Vec3; 3]], ray: &Ray, t_max: f32) -> Option<Hit> {
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

    /// A tiny deterministic generator for test data (SplitMix64).
    pub(crate) struct Rng(pub u64);
    impl Rng {
        pub(crate) fn f32(&mut self) -> f32 {
            self.0 = self.0.wrapping_add(1);
            (crate::math::sampler::mix64(self.0) >> 40) as f32 / (1u64 << 24) as f32
        }
        pub(crate) fn vec3(&mut self) -> Vec3 {
            Vec3::new(self.f32(), self.f32(), self.f32())
        }
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
    }
}
