//! Lambert's perfectly diffuse reflection: f = ρd / π. Sampled cosine-weighted.

use crate::math::{warp, Rgb, Vec2, Vec3, INV_PI};

#[inline]
pub fn eval(rho_d: Rgb, wo: Vec3, wi: Vec3) -> Rgb {
    if wo.z <= 0.0 || wi.z <= 0.0 {
        Rgb::ZERO
    } else {
        rho_d * INV_PI
    }
}

#[inline]
pub fn pdf(wo: Vec3, wi: Vec3) -> f32 {
    if wo.z <= 0.0 {
        0.0
    } else {
        warp::cosine_hemisphere_pdf(wi.z)
    }
}

#[inline]
pub fn sample(u: Vec2) -> Vec3 {
    warp::cosine_hemisphere(u)
}
