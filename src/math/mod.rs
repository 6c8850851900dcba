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

/// exp(−x) for x ≥ 0 (0 from x = 87 on, and for NaN), by the same operations as
/// [`exp_neg_poly8`], so that the two agree to the bit: the renderer's Ward lobe, which the
/// eight-lane path loop evaluates on lanes, takes it rather than libm's `expf` (a call per lane,
/// with a branch on underflow that glossy lobes mispredict). Cody–Waite reduction
/// x = n ln 2 + r, |r| ≤ ln 2 / 2, then exp(−r) by its Taylor polynomial to degree 7
/// (truncation below 6·10⁻⁹) scaled by 2⁻ⁿ; within 2 ulp of exp(−x) (a test holds it), and the
/// results libm would make subnormal are 0.
#[inline(always)]
pub fn exp_neg_poly(x: f32) -> f32 {
    if !(x < EXP_NEG_LIMIT) {
        return 0.0;
    }
    let m = x * std::f32::consts::LOG2_E + ROUND_MAGIC;
    let n = m - ROUND_MAGIC;
    let r = (x - n * LN2_HI) - n * LN2_LO;
    let p = exp_taylor(-r, 1.0, |c| c);
    let n_bits = m.to_bits() as i32 - ROUND_MAGIC.to_bits() as i32;
    p * f32::from_bits(((127 - n_bits) << 23) as u32)
}

/// [`exp_neg_poly`] on eight lanes, to the bit.
#[inline(always)]
pub fn exp_neg_poly8(x: wide::f32x8) -> wide::f32x8 {
    use wide::{f32x8, i32x8, CmpLt};
    let splat = f32x8::splat;
    let m = x * splat(std::f32::consts::LOG2_E) + splat(ROUND_MAGIC);
    let n = m - splat(ROUND_MAGIC);
    let r = (x - n * splat(LN2_HI)) - n * splat(LN2_LO);
    let p = exp_taylor(-r, splat(1.0), splat);
    let n_bits: i32x8 =
        bytemuck::cast::<f32x8, i32x8>(m) - i32x8::splat(ROUND_MAGIC.to_bits() as i32);
    let scale: f32x8 = bytemuck::cast((i32x8::splat(127) - n_bits) << 23);
    x.cmp_lt(splat(EXP_NEG_LIMIT)).blend(p * scale, f32x8::ZERO)
}

/// Eight rows of `N` floats (`N` a multiple of eight) as `N` eight-lane registers: element k of
/// the result holds value k of every row. Row loads and in-register transposes, where reading a
/// value at a time would insert single floats.
#[inline(always)]
pub fn transpose<const N: usize>(rows: [&[f32; N]; 8]) -> [wide::f32x8; N] {
    use wide::f32x8;
    let mut out = [f32x8::ZERO; N];
    for (g, chunk) in out.chunks_exact_mut(8).enumerate() {
        let t = f32x8::transpose(std::array::from_fn(|j| {
            f32x8::from(rows[j].as_chunks::<8>().0[g])
        }));
        chunk.copy_from_slice(&t);
    }
    out
}

/// Below this `exp_neg_poly` computes, from it on it gives 0 (2⁻¹²⁶ is the smallest scale).
const EXP_NEG_LIMIT: f32 = 87.0;
/// 1.5 · 2²³: adding it rounds to an integer, which its low mantissa bits then hold.
const ROUND_MAGIC: f32 = 12_582_912.0;
/// ln 2 in two parts, the first with few enough bits that n · `LN2_HI` is exact.
const LN2_HI: f32 = 355.0 / 512.0;
const LN2_LO: f32 = -2.121_944_4e-4;

/// exp(s) for |s| ≤ ln 2 / 2: Taylor to degree 7 by Horner's rule, for f32 and f32x8 alike.
#[inline(always)]
fn exp_taylor<T>(s: T, one: T, c: impl Fn(f32) -> T) -> T
where
    T: Copy + std::ops::Add<Output = T> + std::ops::Mul<Output = T>,
{
    one + s
        * (one
            + s * (c(1.0 / 2.0)
                + s * (c(1.0 / 6.0)
                    + s * (c(1.0 / 24.0)
                        + s * (c(1.0 / 120.0) + s * (c(1.0 / 720.0) + s * c(1.0 / 5040.0)))))))
}

/// ln x for a normal, finite x > 0, by the same operations as [`ln_poly8`], so that the two
/// agree to the bit: the Ward lobe's sampling, which the eight-lane path loop runs on lanes,
/// takes it rather than libm's `logf` (a call per lane). Cephes' `logf`: x = 2ᵉ·f with
/// f ∈ [√½, √2), then ln(1 + t), t = f − 1, as t − t²/2 + t³·P(t) with P its degree-8
/// polynomial, and e·ln 2 added in two parts; without fused multiply-adds, so a portable build
/// gives the same bits. Within 2 ulp of ln x, or 2·10⁻⁸ absolute near x = 1 (a test holds it).
#[inline(always)]
pub fn ln_poly(x: f32) -> f32 {
    let bits = x.to_bits() as i32;
    let f = f32::from_bits(((bits & 0x007f_ffff) | 0x3f80_0000) as u32);
    let e = ((bits >> 23) - 127) as f32;
    let big = f > std::f32::consts::SQRT_2;
    let (f, e) = if big { (f * 0.5, e + 1.0) } else { (f, e) };
    ln_series(f - 1.0, e, |c| c)
}

/// [`ln_poly`] on eight lanes, to the bit.
#[inline(always)]
pub fn ln_poly8(x: wide::f32x8) -> wide::f32x8 {
    use wide::{f32x8, i32x8, CmpGt};
    let splat = f32x8::splat;
    let bits: i32x8 = bytemuck::cast(x);
    let f: f32x8 = bytemuck::cast((bits & i32x8::splat(0x007f_ffff)) | i32x8::splat(0x3f80_0000));
    let e = ((bits >> 23_i32) - i32x8::splat(127)).round_float();
    let big = f.cmp_gt(splat(std::f32::consts::SQRT_2));
    let (f, e) = (big.blend(f * splat(0.5), f), big.blend(e + splat(1.0), e));
    ln_series(f - splat(1.0), e, splat)
}

/// ln(1 + t) + e ln 2 for t ∈ [√½ − 1, √2 − 1]: Cephes' `logf` polynomial, for f32 and f32x8.
#[inline(always)]
fn ln_series<T>(t: T, e: T, c: impl Fn(f32) -> T) -> T
where
    T: Copy + std::ops::Add<Output = T> + std::ops::Sub<Output = T> + std::ops::Mul<Output = T>,
{
    let p = c(7.037_683_6e-2);
    let p = p * t + c(-1.151_461e-1);
    let p = p * t + c(1.167_699_9e-1);
    let p = p * t + c(-1.242_014_1e-1);
    let p = p * t + c(1.424_932_3e-1);
    let p = p * t + c(-1.666_805_8e-1);
    let p = p * t + c(2.000_071_5e-1);
    let p = p * t + c(-2.499_999_4e-1);
    let p = p * t + c(3.333_333e-1);
    let t2 = t * t;
    let y = t * t2 * p + e * c(LN2_LO) - c(0.5) * t2;
    t + y + e * c(LN2_HI)
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
    fn polynomial_exp_neg_is_within_two_ulp_and_the_same_on_eight_lanes() {
        let mut rng = sampler::TestRng(3);
        let mut worst = 0.0f64;
        for i in 0..200_000 {
            // Uniform over [0, 90) and, as often, log-uniform over [1e-6, 90).
            let x = if i % 2 == 0 {
                90.0 * rng.f32()
            } else {
                1e-6 * (90e6f32).powf(rng.f32())
            };
            let y = exp_neg_poly(x);
            if x < 87.0 {
                let exact = (-(x as f64)).exp();
                let ulp = f64::from(f32::EPSILON) * exact;
                worst = worst.max((y as f64 - exact).abs() / ulp);
            } else {
                assert_eq!(y, 0.0);
            }
        }
        assert!(worst <= 2.0, "{worst} ulp");
        let mut xs = [0.0f32; 8];
        for i in 0..100_000 {
            xs[i % 8] = if i % 3 == 0 {
                120.0 * rng.f32()
            } else {
                4.0 * rng.f32()
            };
            if i % 8 == 7 {
                let y8 = exp_neg_poly8(wide::f32x8::from(xs)).to_array();
                for (x, y) in xs.iter().zip(y8) {
                    assert_eq!(exp_neg_poly(*x).to_bits(), y.to_bits(), "x = {x}");
                }
            }
        }
        let special = [0.0, -0.0, 86.99, 87.0, f32::INFINITY, f32::NAN, 1e-30];
        let y8 = exp_neg_poly8(wide::f32x8::from([
            special[0], special[1], special[2], special[3], special[4], special[5], special[6], 0.5,
        ]));
        for (x, y) in special.iter().zip(y8.to_array()) {
            assert_eq!(exp_neg_poly(*x).to_bits(), y.to_bits(), "x = {x}");
        }
        assert_eq!(exp_neg_poly(0.0), 1.0);
    }

    #[test]
    fn polynomial_ln_is_within_two_ulp_and_the_same_on_eight_lanes() {
        let mut rng = sampler::TestRng(5);
        let mut worst = 0.0f64;
        let mut xs = [0.0f32; 8];
        for i in 0..400_000 {
            // 1 − u as the Ward sampling takes it, log-uniform down to the smallest normal, and
            // up to 1e30.
            let x = match i % 3 {
                0 => 1.0 - rng.f32(),
                1 => f32::MIN_POSITIVE * (1e38f32).powf(rng.f32()),
                _ => (1e30f32).powf(rng.f32()),
            }
            .max(f32::MIN_POSITIVE);
            let y = ln_poly(x);
            let exact = (x as f64).ln();
            let ulp = f64::from(f32::EPSILON) * exact.abs();
            let err = (y as f64 - exact).abs();
            if err > 2e-8 {
                worst = worst.max(err / ulp);
            }
            xs[i % 8] = x;
            if i % 8 == 7 {
                let y8 = ln_poly8(wide::f32x8::from(xs)).to_array();
                for (x, y) in xs.iter().zip(y8) {
                    assert_eq!(ln_poly(*x).to_bits(), y.to_bits(), "x = {x}");
                }
            }
        }
        assert!(worst <= 2.0, "{worst} ulp");
        for x in [
            1.0f32,
            f32::MIN_POSITIVE,
            2.0,
            0.5,
            std::f32::consts::SQRT_2,
        ] {
            assert!(
                (ln_poly(x) as f64 - (x as f64).ln()).abs()
                    <= 1e-7 * (x as f64).ln().abs().max(0.2),
                "{x}"
            );
        }
        assert_eq!(ln_poly(1.0), 0.0);
    }
}
