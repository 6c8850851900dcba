//! Warps from the unit square to the domains the renderer samples, each with its density.

use super::{Vec2, Vec3, INV_PI, PI};
use wide::f32x8;

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
    // θ = π/4 · y/x in the first case, π/2 − π/4 · x/y in the second (cos and sin swap).
    if o.x.abs() > o.y.abs() {
        let (sin, cos) = sin_cos_quarter(PI / 4.0 * (o.y / o.x));
        o.x * Vec2::new(cos, sin)
    } else {
        let (sin, cos) = sin_cos_quarter(PI / 4.0 * (o.x / o.y));
        o.y * Vec2::new(sin, cos)
    }
}

/// (sin x, cos x) for |x| ≤ π/4 by their Taylor series to x⁹ and x¹⁰: the truncation error is
/// below 2·10⁻⁹, a small fraction of an f32 ulp. Inlined polynomials instead of libm's
/// `sincosf`, a call the renderer's hot loop cannot inline (`bench/README.md`, "Design
/// measurements").
#[inline(always)]
pub(crate) fn sin_cos_quarter(x: f32) -> (f32, f32) {
    let x2 = x * x;
    let sin = x
        * (1.0
            + x2 * (-1.0 / 6.0
                + x2 * (1.0 / 120.0 + x2 * (-1.0 / 5040.0 + x2 * (1.0 / 362_880.0)))));
    let cos = 1.0
        + x2 * (-0.5
            + x2 * (1.0 / 24.0
                + x2 * (-1.0 / 720.0 + x2 * (1.0 / 40_320.0 + x2 * (-1.0 / 3_628_800.0)))));
    (sin, cos)
}

/// Uniform barycentric coordinates (b1, b2) on a triangle (Heitz 2019's low-distortion map
/// is not needed here; this is the classical square-root map).
/// [`sin_cos_quarter`] on eight lanes: the same operations in the same order, so each lane's
/// result is the scalar one to the bit (the batch integrator relies on it).
#[inline(always)]
pub(crate) fn sin_cos_quarter_x8(x: f32x8) -> (f32x8, f32x8) {
    let c = f32x8::splat;
    let x2 = x * x;
    let sin = x
        * (c(1.0)
            + x2 * (c(-1.0 / 6.0)
                + x2 * (c(1.0 / 120.0) + x2 * (c(-1.0 / 5040.0) + x2 * c(1.0 / 362_880.0)))));
    let cos = c(1.0)
        + x2 * (c(-0.5)
            + x2 * (c(1.0 / 24.0)
                + x2 * (c(-1.0 / 720.0) + x2 * (c(1.0 / 40_320.0) + x2 * c(-1.0 / 3_628_800.0)))));
    (sin, cos)
}

/// (sin 2πu, cos 2πu) for u ∈ [0, 1]: u less its nearest quarter k/4 (exact), whose angle
/// |x| ≤ π/4 goes to [`sin_cos_quarter`], then turned by k quarter turns (swaps and signs, also
/// exact). By the same operations as [`sin_cos_turn_x8`], so the two agree to the bit (the
/// Ward lobe's sampling on the eight lanes), and within 2·10⁻⁷ of the true values.
#[inline(always)]
pub fn sin_cos_turn(u: f32) -> (f32, f32) {
    let k = (u * 4.0 + 0.5).floor();
    let (s, c) = sin_cos_quarter((u - k * 0.25) * (2.0 * PI));
    match k as u32 & 3 {
        0 => (s, c),
        1 => (c, -s),
        2 => (-s, -c),
        _ => (-c, s),
    }
}

/// [`sin_cos_turn`] on eight lanes, to the bit.
#[inline(always)]
pub fn sin_cos_turn_x8(u: f32x8) -> (f32x8, f32x8) {
    use wide::CmpEq;
    let splat = f32x8::splat;
    let k = (u * splat(4.0) + splat(0.5)).floor();
    let (s, c) = sin_cos_quarter_x8((u - k * splat(0.25)) * splat(2.0 * PI));
    let is = |q: f32| k.cmp_eq(splat(q));
    let swap = is(1.0) | is(3.0);
    let (s, c) = (swap.blend(c, s), swap.blend(s, c));
    // A sign flip, as the scalar `-` (wide's `-x` is 0 − x, which leaves +0 positive).
    let neg = |x: f32x8| x ^ splat(-0.0);
    let (s_neg, c_neg) = (is(2.0) | is(3.0), is(1.0) | is(2.0));
    (s_neg.blend(neg(s), s), c_neg.blend(neg(c), c))
}

#[inline]
pub fn uniform_triangle(u: Vec2) -> (f32, f32) {
    let su = u.x.sqrt();
    (1.0 - su, u.y * su)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quarter_sin_cos_matches_libm() {
        for i in -1000..=1000 {
            let x = PI / 4.0 * i as f32 / 1000.0;
            let (s, c) = sin_cos_quarter(x);
            let (s64, c64) = (x as f64).sin_cos();
            assert!((s as f64 - s64).abs() < 1.2e-7, "sin {x}: {s} vs {s64}");
            assert!((c as f64 - c64).abs() < 1.2e-7, "cos {x}: {c} vs {c64}");
        }
    }

    #[test]
    fn eight_lane_sin_cos_is_the_scalar_one_to_the_bit() {
        for i in (-1000..=1000).step_by(8) {
            let xs: [f32; 8] =
                std::array::from_fn(|k| PI / 4.0 * (i + k as i32).min(1000) as f32 / 1000.0);
            let (s8, c8) = sin_cos_quarter_x8(f32x8::from(xs));
            for (k, &x) in xs.iter().enumerate() {
                let (s, c) = sin_cos_quarter(x);
                assert_eq!(s8.to_array()[k].to_bits(), s.to_bits(), "sin {x}");
                assert_eq!(c8.to_array()[k].to_bits(), c.to_bits(), "cos {x}");
            }
        }
    }

    #[test]
    fn a_turns_sin_cos_matches_libm_and_is_the_same_on_eight_lanes() {
        let mut rng = crate::math::sampler::TestRng(11);
        let mut us: Vec<f32> = (0..=4096).map(|i| i as f32 / 4096.0).collect();
        us.extend((0..100_000).map(|_| rng.f32()));
        us.extend([0.125, 0.375, 0.625, 0.875, 1.0 - f32::EPSILON / 2.0]);
        for chunk in us.chunks(8) {
            let xs: [f32; 8] = std::array::from_fn(|k| chunk[k.min(chunk.len() - 1)]);
            let (s8, c8) = sin_cos_turn_x8(f32x8::from(xs));
            for (k, &u) in xs.iter().enumerate() {
                let (s, c) = sin_cos_turn(u);
                let (s64, c64) = (std::f64::consts::TAU * u as f64).sin_cos();
                assert!((s as f64 - s64).abs() < 2e-7, "sin 2π·{u}: {s} vs {s64}");
                assert!((c as f64 - c64).abs() < 2e-7, "cos 2π·{u}: {c} vs {c64}");
                assert_eq!(s8.to_array()[k].to_bits(), s.to_bits(), "sin 2π·{u}");
                assert_eq!(c8.to_array()[k].to_bits(), c.to_bits(), "cos 2π·{u}");
            }
        }
    }

    #[test]
    fn concentric_map_is_the_shirley_chiu_map() {
        for i in 0..65 {
            for j in 0..65 {
                let u = Vec2::new(i as f32 / 64.0, j as f32 / 64.0);
                let (x, y) = (2.0 * u.x as f64 - 1.0, 2.0 * u.y as f64 - 1.0);
                let expected = if x == 0.0 && y == 0.0 {
                    (0.0, 0.0)
                } else if x.abs() > y.abs() {
                    let t = std::f64::consts::FRAC_PI_4 * y / x;
                    (x * t.cos(), x * t.sin())
                } else {
                    let t = std::f64::consts::FRAC_PI_2 - std::f64::consts::FRAC_PI_4 * x / y;
                    (y * t.cos(), y * t.sin())
                };
                let d = concentric_disk(u);
                assert!(
                    (d.x as f64 - expected.0).abs() < 3e-7,
                    "{u:?}: {d:?} vs {expected:?}"
                );
                assert!(
                    (d.y as f64 - expected.1).abs() < 3e-7,
                    "{u:?}: {d:?} vs {expected:?}"
                );
            }
        }
    }

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
