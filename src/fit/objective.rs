//! The objective of the fit, evaluated from a group's cache: the specular term per pixel for a
//! trial lobe (with its analytic derivatives, from `render::bsdf::ward` and `ggx`), the per-channel
//! least-squares moments, and the error metric ([`super::error`]) on the cache's tiles.

use super::cache::{CachePixel, GroupCache};
use super::error::{tiled_error, ErrorStats, PixelTerms};
use crate::math::Rgb;
use crate::render::bsdf::ggx::ggx_sums;
use crate::render::bsdf::plastic::plastic_sums;
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
    /// Isotropic GGX lobe.
    Microfacet { alpha: f32 },
    /// A diffuse base under a GGX dielectric coat (`render::bsdf::plastic`): the diffuse term
    /// is the coat's, not the cache's Lambert D.
    Plastic { alpha: f32, eta: f32 },
}

/// Per-pixel specular term S (per unit ρs), its halves, and the halves of
/// ∂S/∂(ln αx, ln αy, θ) (for the microfacet lobe: ∂S/∂ln α first, then zeros).
#[derive(Clone, Copy, Debug, Default)]
pub struct PixelSpec {
    pub s: Rgb,
    pub s_half: [Rgb; 2],
    pub ds_half: [[Rgb; 3]; 2],
    /// The diffuse term and its halves where the model's is not Lambert's (the coat's).
    pub d: Option<(Rgb, [Rgb; 2])>,
}

impl PixelSpec {
    /// The diffuse term per unit ρd of pixel `p` under this model, and its halves.
    #[inline]
    pub fn diffuse(&self, p: &CachePixel) -> (Rgb, [Rgb; 2]) {
        self.d.unwrap_or((p.d, p.d_half))
    }
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
                ..Default::default()
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
        Spec::Microfacet { alpha } => cache
            .pixels
            .par_iter()
            .map(|p| {
                let mut out = PixelSpec::default();
                for (half, range) in [(0, p.start..p.mid), (1, p.mid..p.end)] {
                    let samples = &cache.samples[range.start as usize..range.end as usize];
                    (out.s_half[half], out.ds_half[half][0]) =
                        ggx_sums(samples, alpha, derivatives);
                }
                out.s = out.s_half[0] + out.s_half[1];
                out.s_half = [out.s_half[0] * 2.0, out.s_half[1] * 2.0];
                out
            })
            .collect(),
        Spec::Plastic { alpha, eta } => {
            let coat = crate::render::bsdf::Coat::get(alpha, eta);
            cache
                .pixels
                .par_iter()
                .map(|p| {
                    let (mut s, mut d) = ([Rgb::ZERO; 2], [Rgb::ZERO; 2]);
                    for (half, range) in [(0, p.start..p.mid), (1, p.mid..p.end)] {
                        let samples = &cache.samples[range.start as usize..range.end as usize];
                        (s[half], d[half]) = plastic_sums(samples, coat);
                    }
                    PixelSpec {
                        s: s[0] + s[1],
                        s_half: [s[0] * 2.0, s[1] * 2.0],
                        ds_half: [[Rgb::ZERO; 3]; 2],
                        d: Some((d[0] + d[1], [d[0] * 2.0, d[1] * 2.0])),
                    }
                })
                .collect()
        }
    }
}

/// Per-channel least-squares moments of the cache's pixels for the given specular terms.
pub fn moments(cache: &GroupCache, specs: &[PixelSpec]) -> [super::solve::Moments; 3] {
    let mut m = [super::solve::Moments::default(); 3];
    for (p, s) in cache.pixels.iter().zip(specs) {
        let (_, d_half) = s.diffuse(p);
        for c in 0..3 {
            m[c].add(
                [d_half[0][c], d_half[1][c]],
                [s.s_half[0][c], s.s_half[1][c]],
                p.photo[c],
            );
        }
    }
    m
}

/// ε and the noise floor of the model ρd, ρs with the given specular terms.
pub fn error(cache: &GroupCache, specs: &[PixelSpec], rho_d: Rgb, rho_s: Rgb) -> ErrorStats {
    let pixels = cache.pixels.iter().zip(specs).map(|(p, s)| {
        let (d, d_half) = s.diffuse(p);
        let terms = PixelTerms {
            syn: rho_d * d + rho_s * s.s,
            photo: p.photo,
            halves: [
                rho_d * d_half[0] + rho_s * s.s_half[0],
                rho_d * d_half[1] + rho_s * s.s_half[1],
            ],
        };
        (p.tile as usize, terms)
    });
    tiled_error(cache.tiles.max(1), pixels).unwrap_or_default()
}
