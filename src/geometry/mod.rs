//! Geometry: rays, boxes, triangle meshes, built-in shapes and the BVH that intersects them.

pub mod aabb;
pub mod bvh;
mod bvh_build;
pub mod mesh;
pub mod packet;
pub mod shapes;
pub mod triangle;

pub use aabb::Aabb;
pub use bvh::Bvh;
pub use mesh::TriangleMesh;

use glam::Vec3;

/// A ray `o + t d`; `d` need not be normalised (distances are in units of |d|).
#[derive(Clone, Copy, Debug)]
pub struct Ray {
    pub o: Vec3,
    pub d: Vec3,
}

impl Ray {
    pub fn new(o: Vec3, d: Vec3) -> Ray {
        Ray { o, d }
    }
    #[inline]
    pub fn at(&self, t: f32) -> Vec3 {
        self.o + self.d * t
    }
}

/// The closest hit along a ray: distance, triangle index (into the scene's triangle list) and
/// barycentric coordinates of the hit (b1 weights vertex 1, b2 vertex 2).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hit {
    pub t: f32,
    pub prim: u32,
    pub b1: f32,
    pub b2: f32,
}

/// Offsets a ray origin off a surface along the geometric normal, on the side of `dir`, by an
/// amount that scales with the magnitude of the position (robust to scenes in millimetres).
#[inline]
pub fn offset_origin(p: Vec3, ng: Vec3, dir: Vec3) -> Vec3 {
    let eps = 1e-4 * (1.0 + p.abs().max_element());
    if ng.dot(dir) >= 0.0 {
        p + ng * eps
    } else {
        p - ng * eps
    }
}
