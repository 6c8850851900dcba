//! BSDFs in the local shading frame (normal +z). Convention (pbrt's, not Mitsuba's): `eval`
//! returns f(ωo, ωi) *without* the cosine factor; the integrator multiplies by cos θi.
//! Surfaces are two-sided: the integrator flips the frame so that ωo is in the upper hemisphere.
//!
//! A BSDF is a plain enum (no trait objects): the four shapes of reflection of the hierarchy.

pub mod lambert;
pub mod mirror;
pub mod ward;

pub use ward::WardLobe;

use crate::math::{luminance_mean, Rgb, Sampler, Vec3};

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
            Bsdf::Ward { .. } => true,
            Bsdf::Black => false,
        }
    }

    /// Probability of sampling the diffuse component rather than the specular one.
    #[inline]
    fn diffuse_prob(rho_d: Rgb, rho_s: Rgb) -> f32 {
        let (d, s) = (luminance_mean(rho_d), luminance_mean(rho_s));
        if d + s <= 0.0 {
            0.5
        } else {
            d / (d + s)
        }
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
            Bsdf::Black => 0.0,
        }
    }

    /// Draws an incident direction; None if the sample is lost (below the surface, or black).
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
                let pd = Self::diffuse_prob(*rho_d, *rho_s);
                let wi = if uc < pd {
                    lambert::sample(u)
                } else {
                    lobe.sample(wo, u)?
                };
                if wi.z <= 0.0 {
                    return None;
                }
                let pdf = self.pdf(wo, wi);
                (pdf > 0.0).then(|| BsdfSample {
                    wi,
                    weight: self.eval(wo, wi) * wi.z / pdf,
                    pdf,
                    delta: false,
                })
            }
            Bsdf::Black => None,
        }
    }

    /// The delta lobe's reflectance, if the BSDF has one.
    pub fn mirror_reflectance(&self) -> Option<Rgb> {
        match self {
            Bsdf::DiffuseMirror { rho_s, .. } => Some(*rho_s),
            _ => None,
        }
    }
}
