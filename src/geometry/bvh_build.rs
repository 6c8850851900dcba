//! Builds the sixteen-wide BVH of `bvh.rs`: a binary tree by the binned surface area heuristic
//! (Wald 2007, "On fast construction of SAH-based bounding volume hierarchies"), leaves of at
//! most four triangles (one SIMD block), then collapsed to `WIDTH` children per node by
//! opening, while a node has fewer, the child of largest surface area (Wald, Benthin & Boulos
//! 2008, "Getting rid of packets").

use super::aabb::Aabb;
use super::bvh::{Bvh, Node, LEAF, WIDTH};
use super::triangle::Tri4;
use glam::Vec3;

const BINS: usize = 16;
/// Triangles per leaf: one `Tri4` block.
const MAX_LEAF: usize = 4;
/// Cost of a node visit relative to a four-triangle test (both one SIMD pass; the node's is
/// lighter). Set low by measurement: the SAH's area ratios assume rays from outside the box,
/// while a room's rays start inside it and meet a thin wall's box only near that wall. At 0.5,
/// figure6's ceiling and right wall shared one leaf whose box was the whole room; at 0.1 every
/// wall has its own leaf, and rays test far fewer leaves (`bench/README.md`, "Design
/// measurements").
const TRAVERSAL_COST: f32 = 0.1;
/// Below this depth of the binary tree, splits fall back to the object median, which halves
/// the count: the tree's depth stays below SAH_DEPTH + log2(n) however the SAH behaves.
const SAH_DEPTH: usize = 40;

/// Subtrees of at least this many triangles build their two halves in parallel (`rayon::join`);
/// smaller ones are not worth a task.
const PARALLEL_MIN: usize = 1 << 14;

struct BuildPrim {
    bounds: Aabb,
    centroid: Vec3,
    id: u32,
}

/// A node of the binary tree: a leaf holds `prims[start..start + count]`.
struct BinNode {
    bounds: Aabb,
    kind: Kind,
}

enum Kind {
    Leaf { start: usize, count: usize },
    Inner { left: usize, right: usize },
}

pub(super) fn build(tris: &[[Vec3; 3]]) -> Bvh {
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
    let mut bvh = Bvh {
        nodes: Vec::new(),
        tris: Vec::new(),
        ids: Vec::new(),
        bounds: Aabb::EMPTY,
    };
    if prims.is_empty() {
        return bvh;
    }
    let mut bin = Vec::with_capacity(2 * prims.len()); // a binary tree has < 2n nodes
    let root = build_binary(&mut prims, 0, 0, &mut bin);
    bvh.bounds = bin[root].bounds;
    // The root is always a node (node 0), even over a single leaf.
    emit_node(&bin, root, &prims, tris, &mut bvh);
    bvh
}

/// Up to `WIDTH` nodes under `node` that together cover its triangles: `node` itself if it is
/// a leaf, else its children with the largest inner one opened until there are `WIDTH`.
fn open_children(bin: &[BinNode], node: usize) -> Vec<usize> {
    let mut kids = match bin[node].kind {
        Kind::Leaf { .. } => return vec![node],
        Kind::Inner { left, right } => vec![left, right],
    };
    while kids.len() < WIDTH {
        let largest = kids
            .iter()
            .enumerate()
            .filter(|(_, &k)| matches!(bin[k].kind, Kind::Inner { .. }))
            .max_by(|a, b| bin[*a.1].bounds.area().total_cmp(&bin[*b.1].bounds.area()))
            .map(|(i, _)| i);
        let Some(i) = largest else { break };
        let Kind::Inner { left, right } = bin[kids[i]].kind else {
            unreachable!()
        };
        kids[i] = left;
        kids.push(right);
    }
    kids
}

/// Emits the sixteen-wide subtree of binary node `node`; returns its child reference.
fn collapse(
    bin: &[BinNode],
    node: usize,
    prims: &[BuildPrim],
    tris: &[[Vec3; 3]],
    bvh: &mut Bvh,
) -> u32 {
    if let Kind::Leaf { start, count } = bin[node].kind {
        // In triangle order, so that of a block's lanes hit at the same distance the first has
        // the lowest index (`Hits4::nearest`).
        let mut leaf: Vec<&BuildPrim> = prims[start..start + count].iter().collect();
        leaf.sort_by_key(|p| p.id);
        let vertices: Vec<[Vec3; 3]> = leaf.iter().map(|p| tris[p.id as usize]).collect();
        let mut ids = [0u32; 4];
        for (lane, id) in ids.iter_mut().enumerate() {
            *id = leaf[lane.min(count - 1)].id;
        }
        bvh.tris.push(Tri4::new(&vertices));
        bvh.ids.push(ids);
        return LEAF | (bvh.tris.len() - 1) as u32;
    }
    emit_node(bin, node, prims, tris, bvh)
}

/// Emits a sixteen-wide node over [`open_children`] of binary node `node` (which may be a leaf,
/// for the root); returns its index.
fn emit_node(
    bin: &[BinNode],
    node: usize,
    prims: &[BuildPrim],
    tris: &[[Vec3; 3]],
    bvh: &mut Bvh,
) -> u32 {
    let me = bvh.nodes.len();
    bvh.nodes.push(Node::EMPTY);
    for (slot, k) in open_children(bin, node).into_iter().enumerate() {
        let r = collapse(bin, k, prims, tris, bvh);
        bvh.nodes[me].set(slot, &bin[k].bounds, r);
    }
    me as u32
}

/// Builds the binary subtree over `prims` (which start at `first` in the final order);
/// returns its index in `bin`.
fn build_binary(
    prims: &mut [BuildPrim],
    first: usize,
    depth: usize,
    bin: &mut Vec<BinNode>,
) -> usize {
    let mut bounds = Aabb::EMPTY;
    let mut cbounds = Aabb::EMPTY;
    for p in prims.iter() {
        bounds = bounds.union(&p.bounds);
        cbounds.grow(p.centroid);
    }
    let n = prims.len();
    let leaf = BinNode {
        bounds,
        kind: Kind::Leaf {
            start: first,
            count: n,
        },
    };
    let split = if depth < SAH_DEPTH {
        best_split(prims, &bounds, &cbounds)
    } else {
        None
    };
    let mid = match split {
        Some((axis, pos, cost)) => {
            // A leaf costs one block test; splitting a small set can still pay when its
            // triangles lie far apart (two walls in one box).
            if n <= MAX_LEAF && cost >= 1.0 {
                bin.push(leaf);
                return bin.len() - 1;
            }
            let mid = partition(prims, |p| p.centroid[axis] < pos);
            if mid == 0 || mid == n {
                median_split(prims, &cbounds)
            } else {
                mid
            }
        }
        None if n <= MAX_LEAF => {
            bin.push(leaf);
            return bin.len() - 1;
        }
        None => median_split(prims, &cbounds),
    };
    let (left, right) = prims.split_at_mut(mid);
    let (l, r) = if n >= PARALLEL_MIN {
        // The two halves on two threads, each into its own list, then appended with their
        // indices moved: the serial order (left's nodes, right's, this one), so the tree is
        // the same on any thread count.
        let half = |prims: &mut [BuildPrim], first: usize| {
            let mut nodes = Vec::with_capacity(prims.len() / 2);
            build_binary(prims, first, depth + 1, &mut nodes);
            nodes
        };
        let (lv, rv) = rayon::join(|| half(left, first), || half(right, first + mid));
        let l = append_moved(bin, lv);
        (l, append_moved(bin, rv))
    } else {
        let l = build_binary(left, first, depth + 1, bin);
        (l, build_binary(right, first + mid, depth + 1, bin))
    };
    bin.push(BinNode {
        bounds,
        kind: Kind::Inner { left: l, right: r },
    });
    bin.len() - 1
}

/// Appends `nodes`, a subtree built into a list of its own (its root last), to `bin`, its
/// child indices moved by where it starts; returns its root's index in `bin`.
fn append_moved(bin: &mut Vec<BinNode>, nodes: Vec<BinNode>) -> usize {
    let base = bin.len();
    bin.extend(nodes.into_iter().map(|mut b| {
        if let Kind::Inner { left, right } = &mut b.kind {
            *left += base;
            *right += base;
        }
        b
    }));
    bin.len() - 1
}

/// Splits at the object median along the centroids' widest axis (in list order when they all
/// coincide).
fn median_split(prims: &mut [BuildPrim], cbounds: &Aabb) -> usize {
    let e = cbounds.max - cbounds.min;
    let axis = if e.x >= e.y && e.x >= e.z {
        0
    } else if e.y >= e.z {
        1
    } else {
        2
    };
    let mid = prims.len() / 2;
    if e[axis] > 0.0 {
        prims.select_nth_unstable_by(mid, |a, b| a.centroid[axis].total_cmp(&b.centroid[axis]));
    }
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

/// Leaf blocks needed for `n` triangles.
fn blocks(n: u32) -> f32 {
    n.div_ceil(MAX_LEAF as u32) as f32
}

/// The binned-SAH split: (axis, plane position, cost in units of block tests).
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
                + (acc.area() * blocks(n) + right_area[i + 1] * blocks(right_count[i + 1]))
                    / parent_area;
            if best.is_none_or(|b| cost < b.2) {
                let pos = cbounds.min[axis] + (i + 1) as f32 / scale;
                best = Some((axis, pos, cost));
            }
        }
    }
    best
}

impl Bvh {
    /// Builds the hierarchy over `tris` (the index of a triangle in this slice is what `Hit::prim`
    /// reports).
    pub fn build(tris: &[[Vec3; 3]]) -> Bvh {
        build(tris)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::sampler::TestRng;

    /// The tree is the same on one thread and on several: the halves built in parallel are
    /// laid out as the serial build lays them out (nodes, blocks, ids and boxes to the bit).
    #[test]
    fn the_tree_does_not_depend_on_the_thread_count() {
        let mut rng = TestRng(11);
        let mut p = || Vec3::new(rng.f32(), rng.f32(), rng.f32()) * 10.0;
        let tris: Vec<[Vec3; 3]> = (0..6 * PARALLEL_MIN)
            .map(|_| {
                let a = p();
                [a, a + p() * 0.01, a + p() * 0.01]
            })
            .collect();
        let on = |threads: usize| {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            pool.install(|| build(&tris))
        };
        let (one, three) = (on(1), on(3));
        let node_bits = |n: &Node| {
            let boxes = n.b.iter().flatten().flatten().flat_map(|v| v.to_array());
            (
                boxes.map(f32::to_bits).collect::<Vec<_>>(),
                n.child,
                n.leaves,
            )
        };
        assert!(one.nodes.len() > 1000);
        assert_eq!(one.nodes.len(), three.nodes.len());
        for (a, b) in one.nodes.iter().zip(&three.nodes) {
            assert_eq!(node_bits(a), node_bits(b));
        }
        assert_eq!(one.ids, three.ids);
        assert_eq!(format!("{:?}", one.tris), format!("{:?}", three.tris));
        // And it finds what testing every triangle finds.
        for _ in 0..300 {
            let o = p();
            let ray = crate::geometry::Ray::new(o, (p() - o).normalize());
            let want = crate::geometry::bvh::tests::brute(&tris, &ray, f32::INFINITY);
            crate::geometry::bvh::tests::assert_same_hit(
                three.intersect(&ray, f32::INFINITY),
                want,
            );
        }
    }
}
