//! Watertight ray–triangle intersection (Woop, Benthin & Wald 2013, "Watertight Ray/Triangle
//! Intersection", JCGT 2(1)): rays that hit a shared edge hit exactly one of the two triangles,
//! never neither, so no light leaks through the seams of a mesh.

use glam::Vec3;

/// Per-ray precomputation of the shear transform: the axis along which the ray travels most
/// becomes z, and the other two are sheared so the ray is (0, 0, 1).
#[derive(Clone, Copy, Debug)]
pub struct RayShear {
    kx: usize,
    ky: usize,
    kz: usize,
    sx: f32,
    sy: f32,
    sz: f32,
}

impl RayShear {
    pub fn new(d: Vec3) -> RayShear {
        let a = d.abs();
        let kz = if a.x > a.y {
            if a.x > a.z {
                0
            } else {
                2
            }
        } else if a.y > a.z {
            1
        } else {
            2
        };
        let mut kx = (kz + 1) % 3;
        let mut ky = (kx + 1) % 3;
        if d[kz] < 0.0 {
            std::mem::swap(&mut kx, &mut ky);
        }
        RayShear {
            kx,
            ky,
            kz,
            sx: d[kx] / d[kz],
            sy: d[ky] / d[kz],
            sz: 1.0 / d[kz],
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
