//! Sums of the Ward lobe over many weighted direction pairs, eight at a time: what the fitter's
//! objective needs for each trial lobe (Σ c·g and Σ c·∂g), the inner loop of a recovery.

use super::half_vector::{ward_at, HalfVector, LobeParams};
use crate::math::{Rgb, Vec3};
use wide::f32x8;

/// A direction pair reduced to its half vector, with the weight c it is summed with (for the
/// cache: incident radiance · cos θi · MIS weight / (pdf · N)).
#[derive(Clone, Copy, Debug)]
pub struct LobeSample {
    pub half: HalfVector,
    pub c: Rgb,
}

impl LobeSample {
    pub fn new(wo: Vec3, wi: Vec3, c: Rgb) -> LobeSample {
        LobeSample {
            half: HalfVector::new(wo, wi),
            c,
        }
    }
}

/// Σ c·g over `samples` and, if asked, Σ c·2∂g/∂k for k = ln αx, ln αy, θ (zero otherwise):
/// [`ward_at`] on eight samples at a time (AVX), the rest one by one. The eight-lane exp
/// (`wide`'s) flushes results below e⁻⁸⁷·³ to zero and may differ from libm's in the last bit.
pub fn lobe_sums(samples: &[LobeSample], p: &LobeParams, derivatives: bool) -> (Rgb, [Rgb; 3]) {
    let splat = f32x8::splat;
    let (cos_t, sin_t) = (splat(p.cos_t), splat(p.sin_t));
    let (inv_ax2, inv_ay2, inv_axay) = (splat(p.inv_ax2), splat(p.inv_ay2), splat(p.inv_axay));
    let mut s = [f32x8::ZERO; 3];
    let mut ds = [[f32x8::ZERO; 3]; 3];
    let mut chunks = samples.chunks_exact(8);
    for chunk in &mut chunks {
        let lanes = |f: &dyn Fn(&LobeSample) -> f32| {
            f32x8::from(std::array::from_fn::<f32, 8, _>(|i| f(&chunk[i])))
        };
        let (hx, hy) = (lanes(&|x| x.half.hx), lanes(&|x| x.half.hy));
        let inv_hz2 = lanes(&|x| x.half.inv_hz2);
        let norm = lanes(&|x| x.half.norm[p.variant]);
        let c = [lanes(&|x| x.c.x), lanes(&|x| x.c.y), lanes(&|x| x.c.z)];
        let rx = hx * cos_t + hy * sin_t;
        let ry = -hx * sin_t + hy * cos_t;
        let a2 = rx * rx * inv_ax2 * inv_hz2;
        let b2 = ry * ry * inv_ay2 * inv_hz2;
        let g = (-(a2 + b2)).exp() * inv_axay * norm;
        for ch in 0..3 {
            s[ch] += c[ch] * g;
        }
        if derivatives {
            let dg = [
                g * (splat(2.0) * a2 - f32x8::ONE),
                g * (splat(2.0) * b2 - f32x8::ONE),
                -g * splat(2.0) * rx * ry * (inv_ax2 - inv_ay2) * inv_hz2,
            ];
            for k in 0..3 {
                for ch in 0..3 {
                    ds[k][ch] += c[ch] * (splat(2.0) * dg[k]);
                }
            }
        }
    }
    let sum = |v: &[f32x8; 3]| Rgb::from_array(v.map(|x| x.reduce_add()));
    let (mut s, mut ds) = (sum(&s), ds.map(|d| sum(&d)));
    for smp in chunks.remainder() {
        let (g, dg) = ward_at(&smp.half, p);
        s += smp.c * g;
        if derivatives {
            for k in 0..3 {
                ds[k] += smp.c * (2.0 * dg[k]);
            }
        }
    }
    (s, ds)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::WardVariant;

    #[test]
    fn eight_lane_lobe_sums_match_the_one_sample_lobe() {
        let mut rng = crate::math::sampler::TestRng(21);
        let mut dir = || {
            let v = Vec3::new(rng.f32() - 0.5, rng.f32() - 0.5, rng.f32() - 0.1);
            v.normalize()
        };
        // 37 samples: four chunks of eight and a tail; some directions below the surface.
        let samples: Vec<LobeSample> = (0..37)
            .map(|i| {
                LobeSample::new(
                    dir(),
                    dir(),
                    Rgb::new(0.2, 0.5, 1.0) * (1.0 + i as f32 / 9.0),
                )
            })
            .collect();
        for variant in [WardVariant::Ward1992, WardVariant::Balanced] {
            for (ax, ay, th) in [
                (0.3f32, 0.3f32, 0.0f32),
                (0.12, 0.35, 0.7),
                (0.05, 0.02, -1.2),
            ] {
                let p = LobeParams::new(ax, ay, th, variant);
                let (s, ds) = lobe_sums(&samples, &p, true);
                let (mut s1, mut ds1) = (Rgb::ZERO, [Rgb::ZERO; 3]);
                for smp in &samples {
                    let (g, dg) = ward_at(&smp.half, &p);
                    s1 += smp.c * g;
                    for k in 0..3 {
                        ds1[k] += smp.c * (2.0 * dg[k]);
                    }
                }
                assert!(s1.max_element() > 0.0);
                let tol = 1e-5
                    * (s1.abs().max_element()
                        + ds1
                            .iter()
                            .map(|d| d.abs().max_element())
                            .fold(0.0, f32::max));
                assert!(
                    (s - s1).abs().max_element() <= tol,
                    "{variant:?} {ax} {ay} {th}: {s} vs {s1}"
                );
                for k in 0..3 {
                    assert!(
                        (ds[k] - ds1[k]).abs().max_element() <= tol,
                        "d{k}: {} vs {}",
                        ds[k],
                        ds1[k]
                    );
                }
                let (s0, ds0) = lobe_sums(&samples, &p, false);
                assert_eq!(s0, s);
                assert_eq!(ds0, [Rgb::ZERO; 3]);
            }
        }
    }
}
