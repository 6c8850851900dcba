//! The built-in shapes of the scene file, as triangle meshes.

use super::TriangleMesh;
use glam::{Vec2, Vec3};
use std::f32::consts::PI;

/// A parallelogram with corner `c` and edges `u`, `v`; its front side faces `u × v`.
/// UV (0,0) at `c`, (1,0) at `c + u`, (0,1) at `c + v`.
pub fn quad(c: Vec3, u: Vec3, v: Vec3) -> TriangleMesh {
    let n = u.cross(v).normalize_or_zero();
    TriangleMesh {
        positions: vec![c, c + u, c + u + v, c + v],
        normals: Some(vec![n; 4]),
        uvs: Some(vec![
            Vec2::new(0.0, 0.0),
            Vec2::new(1.0, 0.0),
            Vec2::new(1.0, 1.0),
            Vec2::new(0.0, 1.0),
        ]),
        indices: vec![[0, 1, 2], [0, 2, 3]],
    }
}

/// An axis-aligned box from `min` to `max` with outward-facing sides (flat normals).
pub fn cuboid(min: Vec3, max: Vec3) -> TriangleMesh {
    let d = max - min;
    let (x, y, z) = (Vec3::X * d.x, Vec3::Y * d.y, Vec3::Z * d.z);
    let faces = [
        quad(min, y, x),     // -z
        quad(min + z, x, y), // +z
        quad(min, z, y),     // -x
        quad(min + x, y, z), // +x
        quad(min, x, z),     // -y
        quad(min + y, z, x), // +y
    ];
    merge(&faces)
}

/// A UV sphere with smooth normals; `segments` around, `segments / 2` from pole to pole.
pub fn sphere(center: Vec3, radius: f32, segments: u32) -> TriangleMesh {
    let seg = segments.max(8);
    let rings = seg / 2;
    let mut m = TriangleMesh {
        normals: Some(Vec::new()),
        uvs: Some(Vec::new()),
        ..Default::default()
    };
    for r in 0..=rings {
        let theta = PI * r as f32 / rings as f32;
        for s in 0..=seg {
            let phi = 2.0 * PI * s as f32 / seg as f32;
            let n = Vec3::new(
                theta.sin() * phi.cos(),
                theta.cos(),
                theta.sin() * phi.sin(),
            );
            m.positions.push(center + radius * n);
            m.normals.as_mut().unwrap().push(n);
            m.uvs
                .as_mut()
                .unwrap()
                .push(Vec2::new(s as f32 / seg as f32, r as f32 / rings as f32));
        }
    }
    let row = seg + 1;
    for r in 0..rings {
        for s in 0..seg {
            let a = r * row + s;
            let (b, c, d) = (a + 1, a + row, a + row + 1);
            // Outward winding; skip the degenerate triangles at the poles.
            if r != 0 {
                m.indices.push([a, b, c]);
            }
            if r != rings - 1 {
                m.indices.push([b, d, c]);
            }
        }
    }
    m
}

/// Concatenates meshes, keeping normals/UVs only if all parts have them.
pub fn merge(parts: &[TriangleMesh]) -> TriangleMesh {
    let mut m = TriangleMesh::default();
    let all_n = parts.iter().all(|p| p.normals.is_some());
    let all_uv = parts.iter().all(|p| p.uvs.is_some());
    let (mut ns, mut uvs) = (Vec::new(), Vec::new());
    for p in parts {
        let base = m.positions.len() as u32;
        m.positions.extend_from_slice(&p.positions);
        m.indices.extend(
            p.indices
                .iter()
                .map(|t| [t[0] + base, t[1] + base, t[2] + base]),
        );
        if all_n {
            ns.extend_from_slice(p.normals.as_ref().unwrap());
        }
        if all_uv {
            uvs.extend_from_slice(p.uvs.as_ref().unwrap());
        }
    }
    m.normals = all_n.then_some(ns);
    m.uvs = all_uv.then_some(uvs);
    m
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shapes_have_expected_areas_and_outward_normals() {
        let q = quad(Vec3::ZERO, Vec3::X * 2.0, Vec3::Z * 3.0);
        assert!((q.area() - 6.0).abs() < 1e-5);
        let b = cuboid(Vec3::ZERO, Vec3::new(1.0, 2.0, 3.0));
        assert!((b.area() - 22.0).abs() < 1e-4);
        let center = Vec3::new(0.5, 1.0, 1.5);
        for i in 0..b.indices.len() {
            let [p0, p1, p2] = b.triangle(i);
            let n = (p1 - p0).cross(p2 - p0);
            assert!(
                n.dot((p0 + p1 + p2) / 3.0 - center) > 0.0,
                "face {i} points inward"
            );
        }
        let s = sphere(Vec3::ZERO, 1.0, 64);
        assert!((s.area() - 4.0 * PI).abs() / (4.0 * PI) < 0.01);
        for i in 0..s.indices.len() {
            let [p0, p1, p2] = s.triangle(i);
            assert!((p1 - p0).cross(p2 - p0).dot(p0 + p1 + p2) > 0.0);
        }
    }
}
