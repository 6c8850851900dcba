//! The objective of the fit, evaluated from a group's cache: the specular term per pixel for a
//! trial lobe (with its analytic derivatives, from `render::bsdf::ward` and `ggx`), the per-channel
//! least-squares moments, and the error metric ([`super::error`]) on the cache's tiles.

use super::cache::{CachePixel, GroupCache};
use super::error::{tiled_error, ErrorStats, PixelTerms};
use crate::math::Rgb;
use crate::render::bsdf::microfacet::{aniso_sums, ggx_sums, AnisoParams};
use crate::render::bsdf::plastic::plastic_sums;
use crate::render::bsdf::ward::{lobe_sums, LobeParams};
use crate::scene::{Distribution, WardVariant};
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
    /// Isotropic microfacet lobe.
    Microfacet {
        alpha: f32,
        distribution: Distribution,
    },
    /// Anisotropic microfacet lobe (θ in radians).
    AnisoMicrofacet {
        alpha_x: f32,
        alpha_y: f32,
        theta: f32,
        distribution: Distribution,
    },
    /// A diffuse base under a dielectric coat (`render::bsdf::plastic`): the diffuse term is
    /// the coat's, not the cache's Lambert D.
    Plastic {
        alpha: f32,
        eta: f32,
        distribution: Distribution,
    },
}

/// Per-pixel specular term S (per unit ρs), its halves, and the halves of
/// ∂S/∂(ln αx, ln αy, θ) (for the isotropic microfacet lobe: ∂S/∂ln α first, then zeros).
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

/// Each pixel's lobe term from `sums` of its samples (Σ c·g and Σ c·2∂g per shape parameter)
/// over each half: the halves scaled to estimate the whole, their derivatives as summed.
fn lobe_specs(
    cache: &GroupCache,
    sums: impl Fn(&[super::cache::Sample]) -> (Rgb, [Rgb; 3]) + Sync,
) -> Vec<PixelSpec> {
    cache
        .pixels
        .par_iter()
        .map(|p| {
            let mut out = PixelSpec::default();
            for (half, range) in [(0, p.start..p.mid), (1, p.mid..p.end)] {
                let samples = &cache.samples[range.start as usize..range.end as usize];
                (out.s_half[half], out.ds_half[half]) = sums(samples);
            }
            out.s = out.s_half[0] + out.s_half[1];
            out.s_half = [out.s_half[0] * 2.0, out.s_half[1] * 2.0];
            out
        })
        .collect()
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
            lobe_specs(cache, |samples| lobe_sums(samples, &lobe, derivatives))
        }
        Spec::Microfacet {
            alpha,
            distribution: Distribution::Ggx,
        } => lobe_specs(cache, |samples| {
            // The isotropic GGX lobe's own, faster form.
            let (s, ds) = ggx_sums(samples, alpha, derivatives);
            (s, [ds, Rgb::ZERO, Rgb::ZERO])
        }),
        Spec::Microfacet {
            alpha,
            distribution,
        } => {
            let lobe = AnisoParams {
                alpha_x: alpha,
                alpha_y: alpha,
                theta: 0.0,
                distribution,
            };
            lobe_specs(cache, |samples| {
                let (s, ds) = aniso_sums(samples, &lobe, derivatives);
                (s, [ds[0] + ds[1], Rgb::ZERO, Rgb::ZERO])
            })
        }
        Spec::AnisoMicrofacet {
            alpha_x,
            alpha_y,
            theta,
            distribution,
        } => {
            let lobe = AnisoParams {
                alpha_x,
                alpha_y,
                theta,
                distribution,
            };
            lobe_specs(cache, |samples| aniso_sums(samples, &lobe, derivatives))
        }
        Spec::Plastic {
            alpha,
            eta,
            distribution,
        } => {
            let coat = crate::render::bsdf::Coat::get(alpha, eta, distribution);
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

/// The cache's pixels and their terms summed over the error's tiles, as plain (not cross-half)
/// least-squares data: one pooled pixel per tile (photo, D, S and the derivatives summed, both
/// halves set to their mean), for the anisotropic microfacet level's cost. Per pixel, a lobe
/// much narrower than the spacing of the cache's directions makes S a few spikes, and the
/// cross-half cost then rewards narrowing it further (its ρs solve divides by a Σ s₀s₁ that the
/// spikes leave too small); a plain cost on pixels penalises the spikes' variance instead and
/// widens the lobe. Summed over a tile (~70 pixels) the variance is small and the tiles'
/// pattern still pins the shape (the measurements are in the commit that added it, b168191).
pub fn pooled(cache: &GroupCache, specs: &[PixelSpec]) -> (GroupCache, Vec<PixelSpec>) {
    let zero = Rgb::ZERO;
    let n = cache.tiles.max(1);
    let mut pixels: Vec<CachePixel> = (0..n as u32)
        .map(|t| CachePixel {
            pixel: t,
            photo: zero,
            d: zero,
            d_half: [zero; 2],
            mirror: zero,
            mirror_half: [zero; 2],
            start: 0,
            mid: 0,
            end: 0,
            tile: t,
        })
        .collect();
    let mut out = vec![PixelSpec::default(); n];
    for (p, s) in cache.pixels.iter().zip(specs) {
        let t = (p.tile as usize).min(n - 1);
        let (q, o) = (&mut pixels[t], &mut out[t]);
        q.photo += p.photo;
        q.d += p.d;
        q.mirror += p.mirror;
        for h in 0..2 {
            q.d_half[h] += p.d_half[h];
            q.mirror_half[h] += p.mirror_half[h];
            o.s_half[h] += s.s_half[h];
            for k in 0..3 {
                o.ds_half[h][k] += s.ds_half[h][k];
            }
        }
        o.s += s.s;
        if let Some((d, dh)) = s.d {
            let (od, odh) = o.d.get_or_insert((zero, [zero; 2]));
            *od += d;
            odh[0] += dh[0];
            odh[1] += dh[1];
        }
    }
    // Both halves become their mean: plain least squares on the tiles.
    let mean = |h: &mut [Rgb; 2]| *h = [(h[0] + h[1]) * 0.5; 2];
    for (q, o) in pixels.iter_mut().zip(&mut out) {
        mean(&mut q.d_half);
        mean(&mut q.mirror_half);
        mean(&mut o.s_half);
        for k in 0..3 {
            let m = (o.ds_half[0][k] + o.ds_half[1][k]) * 0.5;
            o.ds_half[0][k] = m;
            o.ds_half[1][k] = m;
        }
        if let Some((_, dh)) = &mut o.d {
            mean(dh);
        }
    }
    let cache = GroupCache {
        pixels,
        samples: cache.samples.clone(),
        tiles: n,
        ..Default::default()
    };
    (cache, out)
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
