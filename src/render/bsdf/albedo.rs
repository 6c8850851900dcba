//! The directional-hemispherical albedo of a BSDF: the share of the light arriving from one
//! direction that the surface reflects, over every direction, delta lobes included,
//!
//!   a(ωo) = ∫ f(ωo, ωi) cos θi dωi   (+ ρs of a mirror)
//!
//! (by reciprocity also the reflectance seen from ωo under a uniform sky). Every level's model
//! has it, so it compares materials fitted at different levels, and with the truth of a
//! material that is none of matfit's (Mitsuba's BSDFs give theirs the same way: the mean of
//! their sampling weight).

use super::Bsdf;
use crate::math::{Rgb, Sampler, Vec3};

/// Samples per azimuth: Sobol points of the BSDF's own importance sampling, so a narrow lobe
/// costs no more than a wide one (the estimate's 1σ is well under 0.1% for matfit's lobes).
const SAMPLES: u32 = 2048;
/// Azimuths of the incident direction averaged over: an anisotropic lobe's albedo depends on
/// the azimuth, and a group's surfaces face the light at many.
const AZIMUTHS: u32 = 8;

impl Bsdf {
    /// a(θ) averaged over the azimuth, at incidence cos θ = `cos_theta`, per channel: the mean
    /// of `sample`'s weight f cos θi / pdf. Deterministic (a fixed Sobol sequence), so that
    /// albedos of nearby parameters differ smoothly (their finite differences are the
    /// derivatives, not noise).
    pub fn albedo(&self, cos_theta: f32) -> Rgb {
        let mu = cos_theta.clamp(1e-4, 1.0);
        let sin = (1.0 - mu * mu).sqrt();
        let mut sum = [0f64; 3];
        for k in 0..AZIMUTHS {
            let phi = std::f32::consts::TAU * (k as f32 + 0.5) / AZIMUTHS as f32;
            let wo = Vec3::new(sin * phi.cos(), sin * phi.sin(), mu);
            let mut sampler = Sampler::new(0x00a1_bed0, k as u64);
            for i in 0..SAMPLES {
                sampler.start_sample(i);
                if let Some(s) = self.sample(wo, &mut sampler) {
                    for (c, v) in sum.iter_mut().zip([s.weight.x, s.weight.y, s.weight.z]) {
                        *c += v as f64;
                    }
                }
            }
        }
        let n = (SAMPLES * AZIMUTHS) as f64;
        Rgb::new((sum[0] / n) as f32, (sum[1] / n) as f32, (sum[2] / n) as f32)
    }
}

#[cfg(test)]
mod tests {
    use super::super::{Coat, MicrofacetLobe, WardLobe};
    use super::*;
    use crate::scene::{Distribution, WardVariant};

    /// Lambert reflects ρd at every incidence, a mirror ρs: the estimator is exact for them.
    #[test]
    fn lambert_and_mirror_albedos_are_their_reflectances() {
        let d = Bsdf::Diffuse {
            rho_d: Rgb::new(0.2, 0.5, 0.8),
        };
        let m = Bsdf::DiffuseMirror {
            rho_d: Rgb::splat(0.3),
            rho_s: Rgb::new(0.1, 0.2, 0.4),
        };
        for mu in [1.0, 0.5, 0.1] {
            let a = d.albedo(mu);
            assert!((a - Rgb::new(0.2, 0.5, 0.8)).abs().max_element() < 1e-3, "{mu}: {a:?}");
            let a = m.albedo(mu);
            assert!((a - Rgb::new(0.4, 0.5, 0.7)).abs().max_element() < 2e-2, "{mu}: {a:?}");
        }
    }

    /// ∫ f cos θi dωi by brute force: a midpoint grid in (cos² θi, φ), i.e. cosine-weighted,
    /// which knows nothing of the BSDF's sampling.
    fn quadrature(b: &Bsdf, mu: f32) -> f32 {
        let n = 600;
        let wo = Vec3::new((1.0 - mu * mu).sqrt(), 0.0, mu);
        let mut sum = 0f64;
        for i in 0..n {
            let ct = ((i as f32 + 0.5) / n as f32).sqrt();
            let st = (1.0 - ct * ct).sqrt();
            for j in 0..n {
                let ph = std::f32::consts::TAU * (j as f32 + 0.5) / n as f32;
                let wi = Vec3::new(st * ph.cos(), st * ph.sin(), ct);
                sum += (b.eval(wo, wi).x * std::f32::consts::PI) as f64;
            }
        }
        (sum / (n * n) as f64) as f32
    }

    /// The sampled estimate agrees with the quadrature for every smooth model, narrow lobes
    /// and wide, at normal incidence and at 60°; a narrow conductor lobe keeps nearly all.
    #[test]
    fn sampled_albedo_agrees_with_quadrature() {
        let ggx = |a: f32| Bsdf::Microfacet {
            rho_d: Rgb::ZERO,
            rho_s: Rgb::ONE,
            lobe: MicrofacetLobe {
                alpha_x: a,
                alpha_y: a,
                distribution: Distribution::Ggx,
            },
        };
        let ward = |a: f32| Bsdf::Ward {
            rho_d: Rgb::splat(0.2),
            rho_s: Rgb::splat(0.5),
            lobe: WardLobe {
                alpha_x: a,
                alpha_y: a,
                variant: WardVariant::Balanced,
            },
        };
        let plastic = Bsdf::Plastic {
            rho_d: Rgb::splat(0.7),
            rho_s: Rgb::splat(0.04),
            coat: Coat::get(0.3, 1.5, Distribution::Beckmann),
        };
        for (name, b) in [
            ("ggx 0.2", ggx(0.2)),
            ("ggx 0.5", ggx(0.5)),
            ("ward 0.15", ward(0.15)),
            ("plastic", plastic),
        ] {
            for mu in [1.0, 0.5] {
                let (a, q) = (b.albedo(mu).x, quadrature(&b, mu));
                assert!((a - q).abs() < 0.005, "{name} at {mu}: {a} against {q}");
            }
        }
        let narrow = ggx(0.05).albedo(1.0).x;
        assert!((narrow - 1.0).abs() < 0.01, "{narrow}");
    }

    /// A plastic never reflects more than it receives, its coat's share rises towards
    /// grazing, and its base's falls (the coat lets less through).
    #[test]
    fn a_plastic_splits_its_albedo_between_base_and_coat_with_the_angle() {
        let coat = Coat::get(0.2, 1.5, Distribution::Ggx);
        let base = Bsdf::Plastic {
            rho_d: Rgb::ONE,
            rho_s: Rgb::ZERO,
            coat,
        };
        let top = Bsdf::Plastic {
            rho_d: Rgb::ZERO,
            rho_s: Rgb::ONE,
            coat,
        };
        let (b0, b60) = (base.albedo(1.0).x, base.albedo(0.5).x);
        let (t0, t60) = (top.albedo(1.0).x, top.albedo(0.5).x);
        assert!(b60 < b0 && t60 > t0, "{b0} {b60} {t0} {t60}");
        // ρs is the coat's F0 (4% at η 1.5) times `specular_reflectance`: the coat at ρs 1
        // reflects 1/F0 times what the real coat does.
        assert!(b0 + coat.f0 * t0 <= 1.0, "{b0} {t0}");
        assert!((t0 - 1.0).abs() < 0.1, "{t0}");
    }

    /// An anisotropic lobe's albedo is averaged over the azimuth: turning the lobe by 90°
    /// (swapping αx and αy) does not change it.
    #[test]
    fn an_anisotropic_albedo_does_not_depend_on_the_lobe_turn() {
        let ward = |ax: f32, ay: f32| Bsdf::Ward {
            rho_d: Rgb::ZERO,
            rho_s: Rgb::ONE,
            lobe: WardLobe {
                alpha_x: ax,
                alpha_y: ay,
                variant: WardVariant::Balanced,
            },
        };
        let (a, b) = (ward(0.1, 0.3).albedo(0.5).x, ward(0.3, 0.1).albedo(0.5).x);
        assert!((a - b).abs() < 0.01, "{a} {b}");
    }
}
