//! The defensive mixture from which the cache draws its indirect directions (docs/DESIGN.md,
//! "Making it fast" 1): a cosine lobe plus isotropic Ward lobes of several widths around the mirror
//! direction, and, from points that see the lights' images in a planar mirror
//! (`mirror_images.rs`), a share aimed at those. It does not depend on the parameters being
//! fitted, so the same samples serve every trial (common random numbers) and its pdf is known
//! exactly for the MIS weights.

use super::mirror_images::MirrorImages;
use crate::math::{warp, Frame, Sampler, Vec2, Vec3};
use crate::render::bsdf::WardLobe;
use crate::scene::WardVariant;

/// Widths of the Ward components.
const ALPHAS: [f32; 4] = [0.03, 0.08, 0.2, 0.5];
/// Probability of the cosine component of the defensive mixture; the Ward components share the
/// rest equally. A cache may use weight 1 (cosine alone) when it needs no lobe.
pub const DEFENSIVE_COSINE_WEIGHT: f32 = 0.3;
/// Share of the draws aimed at the lights' mirror images, from a point that sees one; the
/// other components share the rest in their usual proportions.
pub const IMAGE_WEIGHT: f32 = 0.2;

fn lobe(alpha: f32) -> WardLobe {
    WardLobe {
        alpha_x: alpha,
        alpha_y: alpha,
        variant: WardVariant::Balanced,
    }
}

/// The mixture at one surface point: `frame` its shading frame, `p` the point.
pub struct Mixture<'a> {
    cosine_weight: f32,
    /// The images, where any is seen from the point.
    images: Option<&'a MirrorImages>,
    p: Vec3,
    frame: Frame,
}

impl<'a> Mixture<'a> {
    pub fn at(cosine_weight: f32, images: &'a MirrorImages, p: Vec3, frame: Frame) -> Self {
        Mixture {
            cosine_weight,
            images: (!images.is_empty() && images.seen_from(p)).then_some(images),
            p,
            frame,
        }
    }

    /// Draws a direction in the local frame for outgoing `wo`; None if the draw fell below the
    /// surface (its probability mass is accounted for by `pdf`, which is not renormalised).
    pub fn sample(&self, wo: Vec3, sampler: &mut Sampler) -> Option<Vec3> {
        let uc = sampler.next_1d();
        let u = sampler.next_2d();
        match self.images {
            Some(m) if uc < IMAGE_WEIGHT => {
                let w = self.frame.to_local(m.sample(self.p, uc / IMAGE_WEIGHT, u)?);
                (w.z > 0.0).then_some(w)
            }
            Some(_) => local_sample(
                wo,
                (uc - IMAGE_WEIGHT) / (1.0 - IMAGE_WEIGHT),
                u,
                self.cosine_weight,
            ),
            None => local_sample(wo, uc, u, self.cosine_weight),
        }
    }

    /// Density per solid angle of [`sample`](Self::sample) for local `wi`.
    pub fn pdf(&self, wo: Vec3, wi: Vec3) -> f32 {
        let local = local_pdf(wo, wi, self.cosine_weight);
        match self.images {
            Some(m) => {
                IMAGE_WEIGHT * m.pdf(self.p, self.frame.to_world(wi)) + (1.0 - IMAGE_WEIGHT) * local
            }
            None => local,
        }
    }
}

/// The cosine and Ward components, `uc` choosing among them and `u` drawing from the chosen.
fn local_sample(wo: Vec3, uc: f32, u: Vec2, cosine_weight: f32) -> Option<Vec3> {
    if uc < cosine_weight {
        Some(warp::cosine_hemisphere(u))
    } else {
        let k = (((uc - cosine_weight) / (1.0 - cosine_weight)) * ALPHAS.len() as f32) as usize;
        lobe(ALPHAS[k.min(ALPHAS.len() - 1)]).sample(wo, u)
    }
}

/// Density per solid angle of [`local_sample`].
fn local_pdf(wo: Vec3, wi: Vec3, cosine_weight: f32) -> f32 {
    let cosine = cosine_weight * warp::cosine_hemisphere_pdf(wi.z);
    if cosine_weight >= 1.0 {
        return cosine;
    }
    let w = (1.0 - cosine_weight) / ALPHAS.len() as f32;
    cosine + ALPHAS.iter().map(|&a| w * lobe(a).pdf(wo, wi)).sum::<f32>()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn mixture_pdf_integrates_to_its_acceptance_rate() {
        // E[1/pdf] over accepted samples estimates the hemisphere's solid angle 2π only if pdf
        // is the true density; samples lost below the horizon are counted as zeros.
        // With the lights' mirror images seen from the point, the images' share too.
        let wo = Vec3::new(0.5, 0.1, 0.86).normalize();
        let none = MirrorImages::default();
        let room = super::super::mirror_images::tests::scene();
        let images = MirrorImages::new(&room);
        let p = Vec3::new(0.8, 0.0, 0.1);
        assert!(images.seen_from(p));
        for (images, frame) in [
            (&none, Frame::from_normal(Vec3::Z)),
            (&images, Frame::from_normal(Vec3::Y)),
        ] {
            let mix = Mixture::at(DEFENSIVE_COSINE_WEIGHT, images, p, frame);
            let mut s = Sampler::new(4, 0);
            let n = 200_000;
            let mut sum = 0.0f64;
            for i in 0..n {
                s.start_sample(i);
                if let Some(wi) = mix.sample(wo, &mut s) {
                    sum += 1.0 / mix.pdf(wo, wi) as f64;
                }
            }
            let solid_angle = sum / n as f64;
            assert!(
                (solid_angle - 2.0 * std::f64::consts::PI).abs()
                    < 0.03 * 2.0 * std::f64::consts::PI,
                "{solid_angle}"
            );
        }
    }
}
