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

/// `v`, its three components read one float at a time. Where `v` was written a float at a time
/// (the eight-lane path loop writes each lane's state back from its registers, `render::batch`),
/// the compiler's wider loads (two or four floats) cannot be forwarded from the store buffer
/// and wait until the stores reach the cache; `black_box` keeps the reads apart (an
/// optimisation barrier only: the value is unchanged). Measured where it is used.
#[inline(always)]
pub fn read_apart(v: &Vec3) -> Vec3 {
    use std::hint::black_box;
    Vec3::new(black_box(v.x), black_box(v.y), black_box(v.z))
}

/// Mean of the three channels.
#[inline]
pub fn luminance_mean(c: Rgb) -> f32 {
    (c.x + c.y + c.z) / 3.0
}

/// exp(−x), the same number as `(-x).exp()`, without the cost of underflow: glibc's `expf`
/// returns 0 for arguments below −103.97 through a slow path that also sets `errno`, and a
/// glossy Ward lobe exp(−E) is there for most directions (that path was 6% of a recovery's
/// time on figure6, and as much again in `expf` itself).
#[inline]
pub fn exp_neg(x: f32) -> f32 {
    if x > 104.0 {
        0.0
    } else {
        (-x).exp()
    }
}

/// `f` applied to the lanes of `x` whose bit is set in `mask`, one at a time (0 in the others):
/// the eight-lane code's way to a transcendental that must be the scalar code's to the bit.
#[inline(always)]
pub fn lanewise(x: wide::f32x8, mask: u32, f: impl Fn(f32) -> f32) -> wide::f32x8 {
    let a = x.to_array();
    let mut out = [0.0f32; 8];
    let mut bits = mask;
    while bits != 0 {
        let j = bits.trailing_zeros() as usize;
        bits &= bits - 1;
        out[j] = f(a[j]);
    }
    wide::f32x8::from(out)
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn exp_neg_is_libms_exp_to_the_bit() {
        let mut x = 0.0f32;
        while x < 200.0 {
            assert_eq!(exp_neg(x).to_bits(), (-x).exp().to_bits(), "x = {x}");
            x = x * 1.001 + 1e-3;
        }
        for x in [f32::INFINITY, 103.9, 103.98, 104.0, 104.01] {
            assert_eq!(exp_neg(x).to_bits(), (-x).exp().to_bits(), "x = {x}");
        }
        assert!(exp_neg(f32::NAN).is_nan());
    }
}
