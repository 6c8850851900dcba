//! The texture atlas of a textured group (§5.2 and Figure 2 of the notes: a texture extracted
//! from the photo is unwarped into a rectangular image). It needs no UVs from the model, so it
//! works on quads, boxes and meshes alike, and it gives every object of the group its own texels
//! (the built-in shapes' UVs overlap: every face of a box spans the whole [0,1]²).
//!
//! Every triangle belongs to the chart of its object and of the axis its geometric normal points
//! along most (±x, ±y, ±z). A chart is projected orthographically onto the plane of its
//! area-weighted mean normal, its axes fixed by the world's up direction, and cut into square
//! texels of side `texel` (world units). Charts are packed on shelves, tallest first, each with a
//! one-texel gap around it. Lookups are bilinear and clamped to the chart's own texels, so no
//! colour bleeds between charts. The layout is a pure function of the group's geometry and the
//! texel size: a scene file stores only `texel_size`, and loading rebuilds the same atlas.

use super::Geometry;
use crate::math::{Rgb, Vec3};

/// The most texels an atlas may have; a finer texel size asked for is coarsened to fit.
pub const MAX_TEXELS: usize = 1 << 22;

#[derive(Clone, Debug, PartialEq)]
struct Chart {
    /// Projection axes: s = p·u, t = p·v.
    u: Vec3,
    v: Vec3,
    s_min: f32,
    t_max: f32,
    /// Interior texels: columns x0..x0+w, rows y0..y0+h of the atlas (row 0 at the top).
    x0: u32,
    y0: u32,
    w: u32,
    h: u32,
}

/// Where a group's surface points land in its texture.
#[derive(Clone, Debug, PartialEq)]
pub struct Atlas {
    /// World units per texel side.
    pub texel: f32,
    pub width: usize,
    pub height: usize,
    charts: Vec<Chart>,
    /// Per scene object, its first entry in `chart_of` (u32::MAX: not in the group).
    slot: Vec<u32>,
    /// Per (slot, axis): the chart index, u32::MAX where the object has no triangle there.
    chart_of: Vec<u32>,
}

/// The axis class of a normal: 2·(dominant axis) + (1 if it points negative).
fn axis_class(n: Vec3) -> usize {
    let a = n.abs();
    let k = if a.x >= a.y && a.x >= a.z {
        0
    } else if a.y >= a.z {
        1
    } else {
        2
    };
    2 * k + usize::from(n[k] < 0.0)
}

/// Projection axes of a chart with mean normal `n`: `u` horizontal where the chart is not
/// horizontal, so that a wall's texture comes out upright.
fn axes(n: Vec3) -> (Vec3, Vec3) {
    let up = if n.y.abs() < 0.9 { Vec3::Y } else { Vec3::Z };
    let u = up.cross(n).normalize();
    (u, n.cross(u))
}

impl Atlas {
    /// The atlas of the given scene objects (a group's, in scene order) at `texel` world units
    /// per texel (coarsened if the layout would exceed [`MAX_TEXELS`]).
    pub fn build(geometry: &Geometry, objects: &[usize], object_count: usize, texel: f32) -> Atlas {
        let mut slot = vec![u32::MAX; object_count];
        for (k, &o) in objects.iter().enumerate() {
            slot[o] = k as u32;
        }
        // Per (slot, axis): area-weighted normal and the triangles.
        let n_keys = objects.len() * 6;
        let mut normal = vec![Vec3::ZERO; n_keys];
        let mut tris: Vec<Vec<usize>> = vec![Vec::new(); n_keys];
        for (i, (tri, face)) in geometry.tris.iter().zip(&geometry.faces).enumerate() {
            let s = slot[tri.object as usize];
            if s == u32::MAX {
                continue;
            }
            let key = s as usize * 6 + axis_class(face.ng);
            let [a, b, c] = tri.v.map(|j| geometry.positions[j as usize]);
            normal[key] += (b - a).cross(c - a);
            tris[key].push(i);
        }
        let mut texel = if texel.is_finite() && texel > 0.0 {
            texel
        } else {
            1e-2
        };
        loop {
            let atlas = Self::layout(geometry, &slot, &normal, &tris, texel);
            if atlas.width * atlas.height <= MAX_TEXELS {
                return atlas;
            }
            texel *= 1.25;
        }
    }

    fn layout(
        geometry: &Geometry,
        slot: &[u32],
        normal: &[Vec3],
        tris: &[Vec<usize>],
        texel: f32,
    ) -> Atlas {
        let mut charts = Vec::new();
        let mut chart_of = vec![u32::MAX; tris.len()];
        for (key, list) in tris.iter().enumerate() {
            if list.is_empty() {
                continue;
            }
            let n = normal[key].normalize_or_zero();
            let n = if n == Vec3::ZERO {
                // Degenerate (zero-area) triangles only: any axis of the class.
                let mut a = Vec3::ZERO;
                a[(key % 6) / 2] = if key % 2 == 0 { 1.0 } else { -1.0 };
                a
            } else {
                n
            };
            let (u, v) = axes(n);
            let (mut s0, mut s1, mut t0, mut t1) = (f32::MAX, f32::MIN, f32::MAX, f32::MIN);
            for &i in list {
                for j in geometry.tris[i].v {
                    let p = geometry.positions[j as usize];
                    let (s, t) = (p.dot(u), p.dot(v));
                    s0 = s0.min(s);
                    s1 = s1.max(s);
                    t0 = t0.min(t);
                    t1 = t1.max(t);
                }
            }
            let cells = |len: f32| ((len / texel).ceil() as u32).max(1);
            chart_of[key] = charts.len() as u32;
            charts.push(Chart {
                u,
                v,
                s_min: s0,
                t_max: t1,
                x0: 0,
                y0: 0,
                w: cells(s1 - s0),
                h: cells(t1 - t0),
            });
        }
        // Shelf packing, tallest first (ties in chart order): deterministic.
        let mut order: Vec<usize> = (0..charts.len()).collect();
        order.sort_by_key(|&c| std::cmp::Reverse(charts[c].h));
        let area: u64 = charts
            .iter()
            .map(|c| (c.w as u64 + 2) * (c.h as u64 + 2))
            .sum();
        let widest = charts.iter().map(|c| c.w + 2).max().unwrap_or(1);
        let width = widest.max((area as f64).sqrt().ceil() as u32);
        let (mut x, mut y, mut shelf) = (0u32, 0u32, 0u32);
        for &c in &order {
            let (w, h) = (charts[c].w + 2, charts[c].h + 2);
            if x + w > width {
                y += shelf;
                x = 0;
                shelf = 0;
            }
            charts[c].x0 = x + 1;
            charts[c].y0 = y + 1;
            x += w;
            shelf = shelf.max(h);
        }
        Atlas {
            texel,
            width: width as usize,
            height: (y + shelf).max(1) as usize,
            charts,
            slot: slot.to_vec(),
            chart_of,
        }
    }

    /// The chart a surface point of `object` with geometric normal `ng` lies in.
    fn chart(&self, object: u32, ng: Vec3) -> Option<&Chart> {
        let s = *self.slot.get(object as usize)?;
        if s == u32::MAX {
            return None;
        }
        let c = self.chart_of[s as usize * 6 + axis_class(ng)];
        self.charts.get(c as usize)
    }

    /// The four texels (index, bilinear weight) a surface point reads, clamped to its chart.
    /// None for a point of another object.
    pub fn taps(&self, object: u32, p: Vec3, ng: Vec3) -> Option<[(u32, f32); 4]> {
        let c = self.chart(object, ng)?;
        let fx = ((p.dot(c.u) - c.s_min) / self.texel - 0.5).clamp(0.0, (c.w - 1) as f32);
        let fy = ((c.t_max - p.dot(c.v)) / self.texel - 0.5).clamp(0.0, (c.h - 1) as f32);
        let (ix, iy) = (fx.floor() as u32, fy.floor() as u32);
        let (ax, ay) = (fx - ix as f32, fy - iy as f32);
        let (jx, jy) = ((ix + 1).min(c.w - 1), (iy + 1).min(c.h - 1));
        let at = |x: u32, y: u32| ((c.y0 + y) as usize * self.width + (c.x0 + x) as usize) as u32;
        Some([
            (at(ix, iy), (1.0 - ax) * (1.0 - ay)),
            (at(jx, iy), ax * (1.0 - ay)),
            (at(ix, jy), (1.0 - ax) * ay),
            (at(jx, jy), ax * ay),
        ])
    }

    /// The continuous atlas position of a surface point, in texels from the atlas's top-left
    /// corner (texel (i, j) covers [i, i+1) × [j, j+1)), not clamped: where a renderer that
    /// samples the atlas through UVs must look (`export::gltf`). None off the group.
    pub fn position(&self, object: u32, p: Vec3, ng: Vec3) -> Option<[f32; 2]> {
        let c = self.chart(object, ng)?;
        Some([
            c.x0 as f32 + (p.dot(c.u) - c.s_min) / self.texel,
            c.y0 as f32 + (c.t_max - p.dot(c.v)) / self.texel,
        ])
    }

    /// The texel whose square holds a surface point (None off the group or outside its chart):
    /// for box-filtering a reference texture onto the atlas.
    pub fn texel_at(&self, object: u32, p: Vec3, ng: Vec3) -> Option<u32> {
        let c = self.chart(object, ng)?;
        let fx = ((p.dot(c.u) - c.s_min) / self.texel).floor();
        let fy = ((c.t_max - p.dot(c.v)) / self.texel).floor();
        if fx < 0.0 || fy < 0.0 || fx >= c.w as f32 || fy >= c.h as f32 {
            return None;
        }
        Some(((c.y0 + fy as u32) as usize * self.width + (c.x0 + fx as u32) as usize) as u32)
    }

    /// The texture's value at a surface point (black off the group).
    pub fn lookup(&self, texels: &[Rgb], object: u32, p: Vec3, ng: Vec3) -> Rgb {
        match self.taps(object, p, ng) {
            Some(taps) => taps
                .iter()
                .fold(Rgb::ZERO, |a, &(i, w)| a + texels[i as usize] * w),
            None => Rgb::ZERO,
        }
    }

    /// The scene object each chart belongs to, in the order of [`Atlas::chart_rects`].
    pub fn chart_objects(&self) -> Vec<u32> {
        let mut out = vec![u32::MAX; self.charts.len()];
        for (object, &s) in self.slot.iter().enumerate() {
            if s == u32::MAX {
                continue;
            }
            for &c in &self.chart_of[s as usize * 6..s as usize * 6 + 6] {
                if let Some(o) = out.get_mut(c as usize) {
                    *o = object as u32;
                }
            }
        }
        out
    }

    /// The texel rectangles of the charts (x0, y0, w, h), for per-chart hole filling.
    pub fn chart_rects(&self) -> Vec<[usize; 4]> {
        self.charts
            .iter()
            .map(|c| [c.x0 as usize, c.y0 as usize, c.w as usize, c.h as usize])
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::shapes;
    use crate::scene::{load::build_geometry_for_tests, Tri};

    fn geometry_of(meshes: Vec<crate::geometry::TriangleMesh>) -> Geometry {
        build_geometry_for_tests(meshes)
    }

    #[test]
    fn a_quad_is_one_upright_chart_and_texels_map_back_to_their_points() {
        // A 2 × 1 wall facing +z, texel 0.1: one chart of 20 × 10 texels.
        let wall = shapes::quad(Vec3::ZERO, Vec3::X * 2.0, Vec3::Y);
        let g = geometry_of(vec![wall]);
        let a = Atlas::build(&g, &[0], 1, 0.1);
        assert_eq!(a.charts.len(), 1);
        assert_eq!((a.charts[0].w, a.charts[0].h), (20, 10));
        assert!(a.width >= 22 && a.height == 12, "{}×{}", a.width, a.height);
        // The centre of texel (3, 2) of the chart, counted from the top-left.
        let p = Vec3::new(0.35, 1.0 - 0.25, 0.0);
        let taps = a.taps(0, p, Vec3::Z).unwrap();
        let (x0, y0) = (a.charts[0].x0 as usize, a.charts[0].y0 as usize);
        assert_eq!(taps[0], (((y0 + 2) * a.width + x0 + 3) as u32, 1.0));
        // A texture that is a linear ramp in x reads back linearly between texel centres.
        let mut tex = vec![Rgb::ZERO; a.width * a.height];
        for (i, t) in tex.iter_mut().enumerate() {
            *t = Rgb::splat((i % a.width) as f32);
        }
        let v = a.lookup(&tex, 0, Vec3::new(0.4, 0.5, 0.0), Vec3::Z);
        assert!((v.x - (x0 as f32 + 3.5)).abs() < 1e-4, "{v:?}");
        // Off the group: nothing.
        assert!(a.taps(1, p, Vec3::Z).is_none());
    }

    #[test]
    fn a_box_has_six_disjoint_charts_and_two_objects_do_not_share_texels() {
        let b1 = shapes::cuboid(Vec3::ZERO, Vec3::new(1.0, 0.5, 0.25));
        let b2 = shapes::cuboid(Vec3::X * 2.0, Vec3::new(2.5, 0.5, 0.5));
        let g = geometry_of(vec![b1, b2]);
        let a = Atlas::build(&g, &[0, 1], 2, 0.05);
        assert_eq!(a.charts.len(), 12);
        let mut owner = vec![usize::MAX; a.width * a.height];
        for (k, c) in a.chart_rects().iter().enumerate() {
            assert!(c[0] >= 1 && c[1] >= 1 && c[0] + c[2] < a.width && c[1] + c[3] < a.height);
            for y in c[1]..c[1] + c[3] {
                for x in c[0]..c[0] + c[2] {
                    assert_eq!(owner[y * a.width + x], usize::MAX, "charts overlap");
                    owner[y * a.width + x] = k;
                }
            }
        }
        // Every triangle's centroid reads only texels of one chart, its own.
        let tris: Vec<Tri> = g.tris.clone();
        let mut charts_seen = std::collections::BTreeSet::new();
        for (t, f) in tris.iter().zip(&g.faces) {
            let [p0, p1, p2] = t.v.map(|j| g.positions[j as usize]);
            let taps = a.taps(t.object, (p0 + p1 + p2) / 3.0, f.ng).unwrap();
            let k = owner[taps[0].0 as usize];
            assert!(taps.iter().all(|&(i, _)| owner[i as usize] == k));
            charts_seen.insert(k);
        }
        assert_eq!(charts_seen.len(), 12);
        // The same inputs give the same layout; a huge request is coarsened to fit.
        assert_eq!(a, Atlas::build(&g, &[0, 1], 2, 0.05));
        let coarse = Atlas::build(&g, &[0, 1], 2, 1e-5);
        assert!(coarse.width * coarse.height <= MAX_TEXELS && coarse.texel > 1e-5);
    }
}
