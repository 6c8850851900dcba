//! Vector types, shading frames, warps and the low-discrepancy sampler.
//!
//! matfit works in `f32` throughout (glam's `Vec3`); colours are linear RGB `Vec3`s.

pub mod frame;
pub mod sampler;
pub mod warp;

pub use frame::Frame;
pub use glam::{Mat3, Vec2, Vec3};
pub use sampler::Sampler;

/// Linear RGB radiance or reflectance.
pub type Rgb = Vec3;

pub const PI: f32 = std::f32::consts::PI;
pub const INV_PI: f32 = std::f32::consts::FRAC_1_PI;

/// Mean of the three channels.
#[inline]
pub fn luminance_mean(c: Rgb) -> f32 {
    (c.x + c.y + c.z) / 3.0
}

/// Mirror reflection of `w` about the normal `n` (both pointing away from the surface).
#[inline]
pub fn reflect(w: Vec3, n: Vec3) -> Vec3 {
    2.0 * w.dot(n) * n - w
}

/// Power heuristic (β = 2) for multiple importance sampling (Veach 1997, §9.2.4).
#[inline]
pub fn power_heuristic(pa: f32, pb: f32) -> f32 {
    let a = pa * pa;
    let b = pb * pb;
    if a + b == 0.0 {
        0.0
    } else {
        a / (a + b)
    }
}
