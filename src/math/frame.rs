//! Orthonormal shading frame: tangent `s`, bitangent `t`, normal `n`.
//!
//! Local coordinates put the normal on +z, the tangent on +x: the frame in which the BSDFs of
//! `render::bsdf` are written.

use glam::Vec3;

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Frame {
    pub s: Vec3,
    pub t: Vec3,
    pub n: Vec3,
}

impl Frame {
    /// A frame around `n` with an arbitrary tangent (Duff et al. 2017, "Building an orthonormal
    /// basis, revisited").
    pub fn from_normal(n: Vec3) -> Frame {
        let sign = 1.0f32.copysign(n.z);
        let a = -1.0 / (sign + n.z);
        let b = n.x * n.y * a;
        let s = Vec3::new(1.0 + sign * n.x * n.x * a, sign * b, -sign * n.x);
        let t = Vec3::new(b, sign + n.y * n.y * a, -n.y);
        Frame { s, t, n }
    }

    /// A frame around `n` whose tangent is `tangent` projected onto the plane of `n`
    /// (Gram-Schmidt); falls back to an arbitrary tangent when `tangent` is parallel to `n`.
    pub fn from_normal_tangent(n: Vec3, tangent: Vec3) -> Frame {
        let s = tangent - n * n.dot(tangent);
        let len = s.length();
        if !(len > 1e-6) {
            return Frame::from_normal(n);
        }
        let s = s / len;
        Frame {
            s,
            t: n.cross(s),
            n,
        }
    }

    /// The same frame with its tangent rotated by `angle` (radians) about the normal.
    pub fn rotated(&self, angle: f32) -> Frame {
        if angle == 0.0 {
            return *self;
        }
        let (sin, cos) = angle.sin_cos();
        let s = self.s * cos + self.t * sin;
        let t = self.n.cross(s);
        Frame { s, t, n: self.n }
    }

    #[inline]
    pub fn to_local(&self, v: Vec3) -> Vec3 {
        Vec3::new(v.dot(self.s), v.dot(self.t), v.dot(self.n))
    }

    #[inline]
    pub fn to_world(&self, v: Vec3) -> Vec3 {
        self.s * v.x + self.t * v.y + self.n * v.z
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frames_are_orthonormal_and_invert() {
        for n in [
            Vec3::Z,
            -Vec3::Z,
            Vec3::new(0.3, -0.8, 0.2).normalize(),
            Vec3::new(-1e-7, 0.0, -1.0).normalize(),
        ] {
            let f = Frame::from_normal(n);
            assert!((f.s.length() - 1.0).abs() < 1e-5);
            assert!((f.t.length() - 1.0).abs() < 1e-5);
            assert!(f.s.dot(f.t).abs() < 1e-5 && f.s.dot(n).abs() < 1e-5);
            assert!((f.s.cross(f.t) - n).length() < 1e-5, "right-handed");
            let v = Vec3::new(0.2, 0.5, -0.7);
            assert!((f.to_world(f.to_local(v)) - v).length() < 1e-5);
        }
        let f = Frame::from_normal_tangent(Vec3::Y, Vec3::new(1.0, 0.3, 0.0)).rotated(0.5);
        assert!((f.s - Vec3::new(0.5f32.cos(), 0.0, -(0.5f32.sin()))).length() < 1e-5);
    }
}
