//! The defensive mixture from which the cache draws its indirect directions (docs/DESIGN.md,
//! "Making it fast" 1): a cosine lobe plus isotropic Ward lobes of several widths around the mirror
//! direction. It does not depend on the parameters being fitted, so the same samples serve every
//! trial (common random numbers) and its pdf is known exactly for the MIS weights.

use crate::math::{warp, Sampler, Vec3};
use crate::render::bsdf::WardLobe;
use crate::scene::WardVariant;

/// Widths of the Ward components.
const ALPHAS: [f32; 4] = [0.03, 0.08, 0.2, 0.5];
/// Probability of the cosine component of the defensive mixture; the Ward components share the
/// rest equally. A cache may use weight 1 (cosine alone) when it needs no lobe.
pub const DEFENSIVE_COSINE_WEIGHT: f32 = 0.3;

fn lobe(alpha: f32) -> WardLobe {
    WardLobe {
        alpha_x: alpha,
        alpha_y: alpha,
        variant: WardVariant::Balanced,
    }
}

/// Draws a direction in the local frame for outgoing `wo`; None if the draw fell below the
/// surface (its probability mass is accounted for by `pdf`, which is not renormalised).
pub fn sample(wo: Vec3, sampler: &mut Sampler, cosine_weight: f32) -> Option<Vec3> {
    let uc = sampler.next_1d();
    let u = sampler.next_2d();
    if uc < cosine_weight {
        Some(warp::cosine_hemisphere(u))
    } else {
        let k = (((uc - cosine_weight) / (1.0 - cosine_weight)) * ALPHAS.len() as f32) as usize;
        lobe(ALPHAS[k.min(ALPHAS.len() - 1)]).sample(wo, u)
    }
}

/// Density per solid angle of [`sample`].
pub fn pdf(wo: Vec3, wi: Vec3, cosine_weight: f32) -> f32 {
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
        let wo = Vec3::new(0.5, 0.1, 0.86).normalize();
        let mut s = Sampler::new(4, 0);
        let n = 200_000;
        let mut sum = 0.0f64;
        for i in 0..n {
            s.start_sample(i);
            if let Some(wi) = sample(wo, &mut s, DEFENSIVE_COSINE_WEIGHT) {
                sum += 1.0 / pdf(wo, wi, DEFENSIVE_COSINE_WEIGHT) as f64;
            }
        }
        let solid_angle = sum / n as f64;
        assert!(
            (solid_angle - 2.0 * std::f64::consts::PI).abs() < 0.03 * 2.0 * std::f64::consts::PI,
            "{solid_angle}"
        );
    }
}
