//! Triangle meshes in world space, with optional shading normals and UVs.

use glam::{Affine3A, Vec2, Vec3};

#[derive(Clone, Debug, Default)]
pub struct TriangleMesh {
    pub positions: Vec<Vec3>,
    /// Per-vertex shading normals (same length as `positions`), if the source had them.
    pub normals: Option<Vec<Vec3>>,
    /// Per-vertex texture coordinates, if the source had them.
    pub uvs: Option<Vec<Vec2>>,
    pub indices: Vec<[u32; 3]>,
}

/// What is wrong with a mesh, for the loader's error message.
#[derive(Debug, Clone, PartialEq)]
pub enum MeshProblem {
    NoTriangles,
    NonFiniteVertex(usize),
    IndexOutOfRange { triangle: usize, index: u32 },
    AllDegenerate,
}

impl std::fmt::Display for MeshProblem {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            MeshProblem::NoTriangles => write!(f, "the mesh has no triangles"),
            MeshProblem::NonFiniteVertex(i) => {
                write!(f, "vertex {i} has a NaN or infinite coordinate")
            }
            MeshProblem::IndexOutOfRange { triangle, index } => {
                write!(
                    f,
                    "triangle {triangle} refers to vertex {index}, which does not exist"
                )
            }
            MeshProblem::AllDegenerate => {
                write!(f, "every triangle of the mesh is degenerate (zero area)")
            }
        }
    }
}

impl TriangleMesh {
    /// Applies an affine transform to positions and normals (normals by the inverse transpose).
    pub fn transform(&mut self, m: &Affine3A) {
        for p in &mut self.positions {
            *p = m.transform_point3(*p);
        }
        if let Some(ns) = &mut self.normals {
            let nm = m.matrix3.inverse().transpose();
            for n in ns.iter_mut() {
                *n = (nm * glam::Vec3A::from(*n)).normalize_or_zero().into();
            }
        }
    }

    pub fn triangle(&self, i: usize) -> [Vec3; 3] {
        let [a, b, c] = self.indices[i];
        [
            self.positions[a as usize],
            self.positions[b as usize],
            self.positions[c as usize],
        ]
    }

    /// Checks the mesh and removes degenerate triangles. Returns how many were removed.
    pub fn validate(&mut self) -> Result<usize, MeshProblem> {
        if self.indices.is_empty() {
            return Err(MeshProblem::NoTriangles);
        }
        if let Some(i) = self.positions.iter().position(|p| !p.is_finite()) {
            return Err(MeshProblem::NonFiniteVertex(i));
        }
        let n = self.positions.len() as u32;
        for (t, tri) in self.indices.iter().enumerate() {
            if let Some(&index) = tri.iter().find(|&&i| i >= n) {
                return Err(MeshProblem::IndexOutOfRange { triangle: t, index });
            }
        }
        let before = self.indices.len();
        let pos = &self.positions;
        self.indices.retain(|&[a, b, c]| {
            let (a, b, c) = (pos[a as usize], pos[b as usize], pos[c as usize]);
            let area2 = (b - a).cross(c - a).length();
            let scale = (b - a).length().max((c - a).length()).max(1e-30);
            area2 > 1e-7 * scale * scale
        });
        if self.indices.is_empty() {
            return Err(MeshProblem::AllDegenerate);
        }
        if let Some(ns) = &mut self.normals {
            // A zero or NaN shading normal would poison shading: drop normals that are unusable.
            if ns.len() != self.positions.len()
                || ns
                    .iter()
                    .any(|n| !n.is_finite() || n.length_squared() < 1e-12)
            {
                self.normals = None;
            }
        }
        if let Some(uv) = &self.uvs {
            if uv.len() != self.positions.len() || uv.iter().any(|u| !u.is_finite()) {
                self.uvs = None;
            }
        }
        Ok(before - self.indices.len())
    }

    /// Total surface area.
    pub fn area(&self) -> f32 {
        (0..self.indices.len())
            .map(|i| {
                let [a, b, c] = self.triangle(i);
                0.5 * (b - a).cross(c - a).length()
            })
            .sum()
    }
}
