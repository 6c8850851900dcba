//! The objective of the fit, evaluated from a group's cache: the specular term per pixel for a
//! trial lobe (with its analytic derivatives), the per-channel least-squares moments, and the
//! error metric with its noise floor.
//!
//! **Error** (DESIGN.md): ε = Σ|L_syn − L_photo| / Σ L_photo over the usable pixels and the
//! three channels. To keep Monte Carlo noise from deciding hypotheses, both images are first
//! summed over small tiles of the group's pixels (`CacheOptions::tile`), which averages noise
//! away while a wrong model's systematic error (a missing highlight) stays. The **noise floor**
//! is the same metric between the two independent halves of the cache's samples, halved (each
//! half has twice the variance of the whole; their difference four times).

use super::cache::GroupCache;
use crate::math::Rgb;
use crate::render::bsdf::ward::{lobe_sums, LobeParams};
use crate::scene::WardVariant;
use rayon::prelude::*;

/// The specular term of a trial model.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Spec {
    /// No specular part.
    None,
    /// Ideal mirror: the cached mirror radiance.
    Mirror,
    /// Ward lobe (θ in radians).
    Lobe {
        alpha_x: f32,
        alpha_y: f32,
        theta: f32,
    },
}

/// Per-pixel specular term S (per unit ρs), its halves, and the halves of
/// ∂S/∂(ln αx, ln αy, θ).
#[derive(Clone, Copy, Debug, Default)]
pub struct PixelSpec {
    pub s: Rgb,
    pub s_half: [Rgb; 2],
    pub ds_half: [[Rgb; 3]; 2],
}

/// The specular term of every cached pixel (derivatives only if asked and the term is a lobe).
pub fn pixel_specs(
    cache: &GroupCache,
    spec: Spec,
    variant: WardVariant,
    derivatives: bool,
) -> Vec<PixelSpec> {
    match spec {
        Spec::None => vec![PixelSpec::default(); cache.pixels.len()],
        Spec::Mirror => cache
            .pixels
            .iter()
            .map(|p| PixelSpec {
                s: p.mirror,
                s_half: p.mirror_half,
                ds_half: [[Rgb::ZERO; 3]; 2],
            })
            .collect(),
        Spec::Lobe {
            alpha_x,
            alpha_y,
            theta,
        } => {
            let lobe = LobeParams::new(alpha_x, alpha_y, theta, variant);
            cache
                .pixels
                .par_iter()
                .map(|p| {
                    let mut out = PixelSpec::default();
                    for (half, range) in [(0, p.start..p.mid), (1, p.mid..p.end)] {
                        let samples = &cache.samples[range.start as usize..range.end as usize];
                        (out.s_half[half], out.ds_half[half]) =
                            lobe_sums(samples, &lobe, derivatives);
                    }
                    out.s = out.s_half[0] + out.s_half[1];
                    out.s_half = [out.s_half[0] * 2.0, out.s_half[1] * 2.0];
                    out
                })
                .collect()
        }
    }
}

/// Per-channel least-squares moments of the cache's pixels for the given specular terms.
pub fn moments(cache: &GroupCache, specs: &[PixelSpec]) -> [super::solve::Moments; 3] {
    let mut m = [super::solve::Moments::default(); 3];
    for (p, s) in cache.pixels.iter().zip(specs) {
        for c in 0..3 {
            m[c].add(
                [p.d_half[0][c], p.d_half[1][c]],
                [s.s_half[0][c], s.s_half[1][c]],
                p.photo[c],
            );
        }
    }
    m
}

/// The error of a model on a cache: ε, the noise floor, and ε of each half of the samples
/// alone (for paired comparisons of two models on the same samples).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ErrorStats {
    pub error: f32,
    pub noise_floor: f32,
    pub halves: [f32; 2],
}

/// ε and the noise floor of the model ρd, ρs with the given specular terms.
pub fn error(cache: &GroupCache, specs: &[PixelSpec], rho_d: Rgb, rho_s: Rgb) -> ErrorStats {
    let n = cache.tiles.max(1);
    let mut syn = vec![Rgb::ZERO; n];
    let mut photo = vec![Rgb::ZERO; n];
    let mut halves = [vec![Rgb::ZERO; n], vec![Rgb::ZERO; n]];
    for (p, s) in cache.pixels.iter().zip(specs) {
        let t = p.tile as usize;
        syn[t] += rho_d * p.d + rho_s * s.s;
        photo[t] += p.photo;
        for h in 0..2 {
            halves[h][t] += rho_d * p.d_half[h] + rho_s * s.s_half[h];
        }
    }
    let total: f32 = photo.iter().map(|c| c.x + c.y + c.z).sum();
    if !total.is_finite() {
        // A NaN or infinite photo value (or a sum that overflowed) must not pass for ε = 0:
        // the error is NaN, which `recover` reports as a diverged fit.
        return ErrorStats {
            error: f32::NAN,
            noise_floor: f32::NAN,
            halves: [f32::NAN; 2],
        };
    }
    if !(total > 0.0) {
        return ErrorStats::default();
    }
    let l1 = |a: &[Rgb], b: &[Rgb]| {
        a.iter()
            .zip(b)
            .map(|(x, y)| (*x - *y).abs())
            .map(|d| d.x + d.y + d.z)
            .sum::<f32>()
    };
    ErrorStats {
        error: l1(&syn, &photo) / total,
        noise_floor: 0.5 * l1(&halves[0], &halves[1]) / total,
        halves: [
            l1(&halves[0], &photo) / total,
            l1(&halves[1], &photo) / total,
        ],
    }
}
