//! BSDFs in the local shading frame (normal +z). Convention (pbrt's, not Mitsuba's): `eval`
//! returns f(ωo, ωi) *without* the cosine factor; the integrator multiplies by cos θi.
//! Surfaces are two-sided: the integrator flips the frame so that ωo is in the upper hemisphere.
//!
//! A BSDF is a plain enum (no trait objects): the shapes of reflection of the hierarchy.

pub mod albedo;
pub mod lambert;
pub mod microfacet;
pub mod mirror;
pub mod plastic;
pub mod ward;

pub use microfacet::MicrofacetLobe;
pub use plastic::Coat;
pub use ward::{Lobes8, WardLobe};

use crate::math::{Rgb, Sampler, Vec3, INV_PI};
use wide::f32x8;

#[derive(Clone, Copy, Debug)]
pub enum Bsdf {
    /// ρd / π.
    Diffuse { rho_d: Rgb },
    /// ρd / π plus an ideal mirror of reflectance ρs (ρd may be zero: a plain mirror).
    DiffuseMirror { rho_d: Rgb, rho_s: Rgb },
    /// ρd / π plus ρs × a Ward lobe.
    Ward {
        rho_d: Rgb,
        rho_s: Rgb,
        lobe: WardLobe,
    },
    /// ρd / π plus ρs × a GGX microfacet lobe of a perfect conductor (`microfacet.rs`).
    Microfacet {
        rho_d: Rgb,
        rho_s: Rgb,
        lobe: MicrofacetLobe,
    },
    /// A diffuse base of reflectance ρd under a rough dielectric coat of reflectance ρs at
    /// normal incidence (`plastic.rs`).
    Plastic {
        rho_d: Rgb,
        rho_s: Rgb,
        coat: &'static Coat,
    },
    /// Reflects nothing.
    Black,
}

/// A direction drawn from a BSDF.
#[derive(Clone, Copy, Debug)]
pub struct BsdfSample {
    pub wi: Vec3,
    /// f cos θi / pdf (for a delta lobe, its reflectance over the probability of choosing it).
    pub weight: Rgb,
    /// Density per solid angle of the whole BSDF's sampling (for a delta lobe, the probability
    /// of choosing it).
    pub pdf: f32,
    /// Drawn from a Dirac delta lobe.
    pub delta: bool,
}

impl Bsdf {
    /// Whether the BSDF has a non-delta part (light sampling is worth doing).
    pub fn has_smooth_part(&self) -> bool {
        match self {
            Bsdf::Diffuse { rho_d } | Bsdf::DiffuseMirror { rho_d, .. } => {
                rho_d.max_element() > 0.0
            }
            Bsdf::Ward { .. } | Bsdf::Microfacet { .. } | Bsdf::Plastic { .. } => true,
            Bsdf::Black => false,
        }
    }

    /// Probability of sampling the diffuse component rather than the specular one: their
    /// shares of the summed channels (their mean reflectances' shares, without two divisions).
    #[inline]
    pub(crate) fn diffuse_prob(rho_d: Rgb, rho_s: Rgb) -> f32 {
        let (d, s) = (rho_d.x + rho_d.y + rho_d.z, rho_s.x + rho_s.y + rho_s.z);
        if d + s <= 0.0 {
            0.5
        } else {
            d / (d + s)
        }
    }

    /// [`Bsdf::diffuse_prob`] on eight lanes, to the bit.
    #[inline(always)]
    pub(crate) fn diffuse_prob8(rho_d: &[f32x8; 3], rho_s: &[f32x8; 3]) -> f32x8 {
        use wide::CmpLe;
        let sum = |c: &[f32x8; 3]| c[0] + c[1] + c[2];
        let (d, s) = (sum(rho_d), sum(rho_s));
        (d + s)
            .cmp_le(f32x8::ZERO)
            .blend(f32x8::splat(0.5), d / (d + s))
    }

    /// f(ωo, ωi) of the non-delta part.
    #[inline]
    pub fn eval(&self, wo: Vec3, wi: Vec3) -> Rgb {
        match self {
            Bsdf::Diffuse { rho_d } | Bsdf::DiffuseMirror { rho_d, .. } => {
                lambert::eval(*rho_d, wo, wi)
            }
            Bsdf::Ward { rho_d, rho_s, lobe } => {
                lambert::eval(*rho_d, wo, wi) + *rho_s * lobe.eval(wo, wi)
            }
            Bsdf::Microfacet { rho_d, rho_s, lobe } => {
                lambert::eval(*rho_d, wo, wi) + *rho_s * lobe.eval(wo, wi)
            }
            Bsdf::Plastic { rho_d, rho_s, coat } => {
                if wo.z <= 0.0 || wi.z <= 0.0 {
                    return Rgb::ZERO;
                }
                *rho_d * coat.diffuse(wo.z, wi.z) + *rho_s * coat.specular(wo, wi)
            }
            Bsdf::Black => Rgb::ZERO,
        }
    }

    /// Density of `sample` for the non-delta part.
    #[inline]
    pub fn pdf(&self, wo: Vec3, wi: Vec3) -> f32 {
        match self {
            Bsdf::Diffuse { .. } => lambert::pdf(wo, wi),
            Bsdf::DiffuseMirror { rho_d, rho_s } => {
                Self::diffuse_prob(*rho_d, *rho_s) * lambert::pdf(wo, wi)
            }
            Bsdf::Ward { rho_d, rho_s, lobe } => {
                let pd = Self::diffuse_prob(*rho_d, *rho_s);
                pd * lambert::pdf(wo, wi) + (1.0 - pd) * lobe.pdf(wo, wi)
            }
            Bsdf::Microfacet { rho_d, rho_s, lobe } => {
                let pd = Self::diffuse_prob(*rho_d, *rho_s);
                pd * lambert::pdf(wo, wi) + (1.0 - pd) * lobe.pdf(wo, wi)
            }
            Bsdf::Plastic { rho_d, rho_s, coat } => {
                let pd = Self::diffuse_prob(*rho_d, *rho_s);
                pd * lambert::pdf(wo, wi) + (1.0 - pd) * coat.lobe.pdf(wo, wi)
            }
            Bsdf::Black => 0.0,
        }
    }

    /// Draws an incident direction; None if the sample is lost (below the surface, or black).
    #[inline]
    pub fn sample(&self, wo: Vec3, sampler: &mut Sampler) -> Option<BsdfSample> {
        if wo.z <= 0.0 {
            return None;
        }
        let uc = sampler.next_1d();
        let u = sampler.next_2d();
        match self {
            Bsdf::Diffuse { rho_d } => {
                let wi = lambert::sample(u);
                (wi.z > 0.0).then(|| BsdfSample {
                    wi,
                    weight: *rho_d,
                    pdf: lambert::pdf(wo, wi),
                    delta: false,
                })
            }
            Bsdf::DiffuseMirror { rho_d, rho_s } => {
                let pd = Self::diffuse_prob(*rho_d, *rho_s);
                if uc < pd {
                    let wi = lambert::sample(u);
                    (wi.z > 0.0).then(|| BsdfSample {
                        wi,
                        weight: *rho_d / pd,
                        pdf: pd * lambert::pdf(wo, wi),
                        delta: false,
                    })
                } else {
                    Some(BsdfSample {
                        wi: mirror::reflect_local(wo),
                        weight: *rho_s / (1.0 - pd),
                        pdf: 1.0 - pd,
                        delta: true,
                    })
                }
            }
            Bsdf::Ward { rho_d, rho_s, lobe } => {
                // `smooth_sample`, with the lobe's exp(−E) taken once for f and the density,
                // and from the lobe's own draw where it drew (the eight lanes do the same).
                let pd = Self::diffuse_prob(*rho_d, *rho_s);
                let (wi, e) = if uc < pd {
                    let wi = lambert::sample(u);
                    (wi, lobe.gaussian(wo, wi))
                } else {
                    lobe.sample_with_gaussian(wo, u)?
                };
                if wi.z <= 0.0 {
                    return None;
                }
                let pdf = pd * lambert::pdf(wo, wi) + (1.0 - pd) * lobe.pdf_with(wo, wi, e);
                (pdf > 0.0).then(|| BsdfSample {
                    wi,
                    weight: (lambert::eval(*rho_d, wo, wi) + *rho_s * lobe.eval_with(wo, wi, e))
                        * (wi.z / pdf),
                    pdf,
                    delta: false,
                })
            }
            Bsdf::Microfacet { rho_d, rho_s, lobe } => {
                self.smooth_sample(wo, *rho_d, *rho_s, uc, u, |u| lobe.sample(wo, u))
            }
            Bsdf::Plastic { rho_d, rho_s, coat } => {
                self.smooth_sample(wo, *rho_d, *rho_s, uc, u, |u| coat.lobe.sample(wo, u))
            }
            Bsdf::Black => None,
        }
    }

    /// A sample of a Lambert + lobe mixture: Lambert with probability `diffuse_prob`, else
    /// the lobe's `sample_lobe`; the weight and density are the whole mixture's (one-sample MIS
    /// between the parts).
    #[inline]
    fn smooth_sample(
        &self,
        wo: Vec3,
        rho_d: Rgb,
        rho_s: Rgb,
        uc: f32,
        u: crate::math::Vec2,
        sample_lobe: impl FnOnce(crate::math::Vec2) -> Option<Vec3>,
    ) -> Option<BsdfSample> {
        let wi = if uc < Self::diffuse_prob(rho_d, rho_s) {
            lambert::sample(u)
        } else {
            sample_lobe(u)?
        };
        if wi.z <= 0.0 {
            return None;
        }
        let pdf = self.pdf(wo, wi);
        (pdf > 0.0).then(|| BsdfSample {
            wi,
            weight: self.eval(wo, wi) * (wi.z / pdf),
            pdf,
            delta: false,
        })
    }

    /// [`Bsdf::eval`] of eight `Bsdf::Ward`s, one a lane (ρd, ρs, lobe), where ωo and ωi are
    /// above the surface, given `e` = `lobes.gaussian(wo, wi)`: the same arithmetic, so each
    /// lane's value is the scalar one to the bit ([`Lobes8`]).
    #[inline(always)]
    pub(crate) fn ward_eval8(
        rho_d: &[f32x8; 3],
        rho_s: &[f32x8; 3],
        lobes: &Lobes8,
        wo: &[f32x8; 3],
        wi: &[f32x8; 3],
        e: f32x8,
    ) -> [f32x8; 3] {
        let g = lobes.eval(wo, wi, e);
        std::array::from_fn(|k| rho_d[k] * f32x8::splat(INV_PI) + rho_s[k] * g)
    }

    /// [`Bsdf::pdf`] of eight `Bsdf::Ward`s whose diffuse probabilities (`diffuse_prob`) are
    /// `pd`, likewise.
    #[inline(always)]
    pub(crate) fn ward_pdf8(
        pd: f32x8,
        lobes: &Lobes8,
        wo: &[f32x8; 3],
        wi: &[f32x8; 3],
        e: f32x8,
    ) -> f32x8 {
        let lambert = wi[2].max(f32x8::ZERO) * f32x8::splat(INV_PI);
        pd * lambert + (f32x8::ONE - pd) * lobes.pdf(wo, wi, e)
    }

    /// The delta lobe's reflectance, if the BSDF has one.
    pub fn mirror_reflectance(&self) -> Option<Rgb> {
        match self {
            Bsdf::DiffuseMirror { rho_s, .. } => Some(*rho_s),
            _ => None,
        }
    }
}

#[cfg(test)]
mod tests {
    //! Goodness-of-fit of every sampling routine against its pdf (the test pbrt-v4 and Mitsuba 3
    //! keep for their BSDFs): histogram many samples over (cos θ, φ) bins of the *world* frame,
    //! integrate the pdf numerically over the same bins, merge sparse bins, and run Pearson's χ²
    //! test at significance 1% (with a Šidák correction over the cases).
    use super::*;
    use crate::math::{Frame, Sampler, Vec2, PI};
    use crate::scene::{Distribution, WardVariant};
    use statrs::distribution::{ChiSquared, ContinuousCDF};

    const THETA_BINS: usize = 24;
    const PHI_BINS: usize = 48;

    fn bin_of(w: Vec3) -> Option<usize> {
        if w.z <= 0.0 {
            return None;
        }
        let t = ((1.0 - w.z) * THETA_BINS as f32) as usize;
        let phi = w.y.atan2(w.x).rem_euclid(2.0 * PI);
        let p = (phi / (2.0 * PI) * PHI_BINS as f32) as usize;
        Some(t.min(THETA_BINS - 1) * PHI_BINS + p.min(PHI_BINS - 1))
    }

    /// χ² test of `bsdf` sampled in `frame` (world = the standard frame) for outgoing `wo_world`.
    fn chi2(bsdf: Bsdf, frame: Frame, wo_world: Vec3, cases: usize) -> (f64, f64) {
        let n = 400_000u32;
        let wo = frame.to_local(wo_world);
        let mut observed = vec![0.0f64; THETA_BINS * PHI_BINS];
        let mut s = Sampler::new(11, 0);
        for i in 0..n {
            s.start_sample(i);
            if let Some(bs) = bsdf.sample(wo, &mut s) {
                assert!(!bs.delta);
                let pdf = bsdf.pdf(wo, bs.wi);
                assert!(
                    (pdf - bs.pdf).abs() <= 1e-3 * pdf,
                    "sample's pdf {} vs pdf() {pdf}",
                    bs.pdf
                );
                if let Some(b) = bin_of(frame.to_world(bs.wi)) {
                    observed[b] += 1.0;
                }
            }
        }
        // Expected counts: midpoint rule on a fine grid in (1 − cos θ, φ), whose measure is
        // exactly the solid angle.
        let sub = 24;
        let mut expected = vec![0.0f64; THETA_BINS * PHI_BINS];
        for (b, e) in expected.iter_mut().enumerate() {
            let (t, p) = (b / PHI_BINS, b % PHI_BINS);
            let mut acc = 0.0f64;
            for i in 0..sub {
                for j in 0..sub {
                    let one_minus_cos =
                        (t as f32 + (i as f32 + 0.5) / sub as f32) / THETA_BINS as f32;
                    let phi =
                        2.0 * PI * (p as f32 + (j as f32 + 0.5) / sub as f32) / PHI_BINS as f32;
                    let z = 1.0 - one_minus_cos;
                    let r = (1.0 - z * z).max(0.0).sqrt();
                    let w = Vec3::new(r * phi.cos(), r * phi.sin(), z);
                    acc += bsdf.pdf(wo, frame.to_local(w)) as f64;
                }
            }
            let cell = (1.0 / THETA_BINS as f64) * (2.0 * std::f64::consts::PI / PHI_BINS as f64);
            *e = acc / (sub * sub) as f64 * cell * n as f64;
        }
        // Merge bins with fewer than 5 expected samples into one pooled bin (pbrt does the same).
        let (mut stat, mut dof, mut pool_o, mut pool_e) = (0.0f64, 0usize, 0.0f64, 0.0f64);
        for (o, e) in observed.iter().zip(&expected) {
            if *e < 5.0 {
                pool_o += o;
                pool_e += e;
            } else {
                stat += (o - e) * (o - e) / e;
                dof += 1;
            }
        }
        if pool_e > 0.0 {
            stat += (pool_o - pool_e) * (pool_o - pool_e) / pool_e.max(1.0);
            dof += 1;
        }
        let p = 1.0 - ChiSquared::new((dof - 1) as f64).unwrap().cdf(stat);
        let threshold = 1.0 - (1.0 - 0.01f64).powf(1.0 / cases as f64);
        (p, threshold)
    }

    fn wo(theta_deg: f32, phi_deg: f32) -> Vec3 {
        let (t, p) = (theta_deg.to_radians(), phi_deg.to_radians());
        Vec3::new(t.sin() * p.cos(), t.sin() * p.sin(), t.cos())
    }

    #[test]
    fn sampling_matches_pdf_chi_square() {
        let ward = |rd: f32, rs: f32, ax: f32, ay: f32, variant| Bsdf::Ward {
            rho_d: Rgb::splat(rd),
            rho_s: Rgb::splat(rs),
            lobe: WardLobe {
                alpha_x: ax,
                alpha_y: ay,
                variant,
            },
        };
        let ggx = |rd: f32, rs: f32, ax: f32, ay: f32| Bsdf::Microfacet {
            rho_d: Rgb::splat(rd),
            rho_s: Rgb::splat(rs),
            lobe: MicrofacetLobe::ggx(ax, ay),
        };
        let beckmann = |rd: f32, rs: f32, ax: f32, ay: f32| Bsdf::Microfacet {
            rho_d: Rgb::splat(rd),
            rho_s: Rgb::splat(rs),
            lobe: MicrofacetLobe {
                alpha_x: ax,
                alpha_y: ay,
                distribution: crate::scene::Distribution::Beckmann,
            },
        };
        let tilted = Frame::from_normal(Vec3::new(0.1, -0.2, 1.0).normalize());
        let std_frame = Frame::from_normal(Vec3::Z);
        let cases: Vec<(&str, Bsdf, Frame, Vec3)> = vec![
            (
                "lambert",
                Bsdf::Diffuse {
                    rho_d: Rgb::splat(0.5),
                },
                std_frame,
                wo(30.0, 10.0),
            ),
            (
                "diffuse+mirror (smooth part)",
                Bsdf::DiffuseMirror {
                    rho_d: Rgb::splat(0.4),
                    rho_s: Rgb::ZERO,
                },
                tilted,
                wo(50.0, 80.0),
            ),
            (
                "ward iso",
                ward(0.0, 1.0, 0.15, 0.15, WardVariant::Ward1992),
                std_frame,
                wo(40.0, 0.0),
            ),
            (
                "ward aniso",
                ward(0.0, 1.0, 0.07, 0.11, WardVariant::Ward1992),
                std_frame,
                wo(30.0, 60.0),
            ),
            (
                "ward aniso θ=35°",
                ward(0.1, 0.9, 0.08, 0.3, WardVariant::Ward1992),
                std_frame.rotated(35f32.to_radians()),
                wo(45.0, 200.0),
            ),
            (
                "ward aniso θ=-70° tilted, grazing",
                ward(0.3, 0.5, 0.25, 0.1, WardVariant::Balanced),
                tilted.rotated(-70f32.to_radians()),
                wo(75.0, 120.0),
            ),
            (
                "ward wide",
                ward(0.5, 0.5, 0.5, 0.4, WardVariant::Balanced),
                std_frame,
                wo(10.0, 0.0),
            ),
            (
                "plastic",
                Bsdf::Plastic {
                    rho_d: Rgb::new(0.7, 0.1, 0.1),
                    rho_s: Rgb::splat(0.04),
                    coat: Coat::get(0.1, plastic::DEFAULT_ETA, Distribution::Ggx),
                },
                tilted,
                wo(60.0, 30.0),
            ),
            (
                "beckmann plastic",
                Bsdf::Plastic {
                    rho_d: Rgb::new(0.2, 0.5, 0.6),
                    rho_s: Rgb::splat(0.04),
                    coat: Coat::get(0.3, plastic::DEFAULT_ETA, Distribution::Beckmann),
                },
                std_frame,
                wo(45.0, 60.0),
            ),
            ("ggx iso", ggx(0.0, 1.0, 0.2, 0.2), std_frame, wo(40.0, 0.0)),
            (
                "ggx aniso θ=25° tilted, grazing",
                ggx(0.3, 0.6, 0.06, 0.25),
                tilted.rotated(25f32.to_radians()),
                wo(70.0, 150.0),
            ),
            (
                "beckmann aniso θ=25° tilted",
                beckmann(0.2, 0.7, 0.08, 0.3),
                tilted.rotated(25f32.to_radians()),
                wo(50.0, 100.0),
            ),
        ];
        let n = cases.len();
        for (name, bsdf, frame, w) in cases {
            let (p, threshold) = chi2(bsdf, frame, w, n);
            assert!(
                p > threshold,
                "{name}: χ² p-value {p:.2e} below {threshold:.2e}"
            );
        }
    }

    #[test]
    fn bsdfs_are_reciprocal_and_lambert_albedo_is_rho() {
        let b = Bsdf::Ward {
            rho_d: Rgb::splat(0.2),
            rho_s: Rgb::splat(0.7),
            lobe: WardLobe {
                alpha_x: 0.1,
                alpha_y: 0.3,
                variant: WardVariant::Ward1992,
            },
        };
        let (a, c) = (wo(20.0, 30.0), wo(35.0, 190.0));
        assert!((b.eval(a, c) - b.eval(c, a)).abs().max_element() < 1e-5);
        // Lambert: ∫ f cos = ρ, estimated by its own sampling (exactly ρ per sample).
        let d = Bsdf::Diffuse {
            rho_d: Rgb::new(0.2, 0.5, 0.9),
        };
        let mut s = Sampler::new(1, 1);
        s.start_sample(0);
        let bs = d.sample(wo(10.0, 0.0), &mut s).unwrap();
        assert!((bs.weight - Rgb::new(0.2, 0.5, 0.9)).abs().max_element() < 1e-6);
        let _ = Vec2::ZERO;
    }
}
