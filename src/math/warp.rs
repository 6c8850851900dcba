//! Warps from the unit square to the domains the renderer samples, each with its density.

use super::{Vec2, Vec3, INV_PI, PI};

/// Cosine-weighted hemisphere around +z (Malley's method); pdf = cos θ / π.
#[inline]
pub fn cosine_hemisphere(u: Vec2) -> Vec3 {
    let d = concentric_disk(u);
    let z = (1.0 - d.x * d.x - d.y * d.y).max(0.0).sqrt();
    Vec3::new(d.x, d.y, z)
}

#[inline]
pub fn cosine_hemisphere_pdf(cos_theta: f32) -> f32 {
    cos_theta.max(0.0) * INV_PI
}

/// Shirley–Chiu concentric map of the square onto the unit disk.
#[inline]
pub fn concentric_disk(u: Vec2) -> Vec2 {
    let o = 2.0 * u - Vec2::ONE;
    if o.x == 0.0 && o.y == 0.0 {
        return Vec2::ZERO;
    }
    let (r, theta) = if o.x.abs() > o.y.abs() {
        (o.x, PI / 4.0 * (o.y / o.x))
    } else {
        (o.y, PI / 2.0 - PI / 4.0 * (o.x / o.y))
    };
    r * Vec2::new(theta.cos(), theta.sin())
}

/// Uniform barycentric coordinates (b1, b2) on a triangle (Heitz 2019's low-distortion map
/// is not needed here; this is the classical square-root map).
#[inline]
pub fn uniform_triangle(u: Vec2) -> (f32, f32) {
    let su = u.x.sqrt();
    (1.0 - su, u.y * su)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cosine_samples_lie_on_the_upper_hemisphere() {
        for i in 0..64 {
            for j in 0..64 {
                let u = Vec2::new((i as f32 + 0.5) / 64.0, (j as f32 + 0.5) / 64.0);
                let w = cosine_hemisphere(u);
                assert!((w.length() - 1.0).abs() < 1e-4 && w.z >= 0.0);
            }
        }
    }
}
