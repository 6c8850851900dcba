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

/// The cache's pixels and their terms summed over the error's tiles: one pooled pixel per tile
/// (photo, D, S and the derivatives summed), for the anisotropic microfacet level's cost. Per
/// pixel, a lobe much narrower than the spacing of the cache's directions makes S a few spikes,
/// and the cross-half cost then rewards narrowing it further (its ρs solve divides by a Σ s₀s₁
/// that the spikes leave too small); summed over a tile (~70 pixels) the spikes are a small
/// part of S, and the tiles' pattern still pins the shape.
///
/// Without `debias` both halves of a tile are its mean: plain least squares on the tiles, whose
/// cost also holds each tile's noise Σ var(S), smaller for a wider lobe. With it the halves are
/// the mean ± the pixels' noise (below), so that the cross-half products of `solve::Moments`
/// subtract from each tile's squares the noise its pixels' halves measure.
pub fn pooled(
    cache: &GroupCache,
    specs: &[PixelSpec],
    debias: bool,
) -> (GroupCache, Vec<PixelSpec>) {
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
            normal: crate::math::Vec3::ZERO,
        })
        .collect();
    let mut out = vec![PixelSpec::default(); n];
    // Per tile (zero without `debias`), the pixels' noise as their halves show it: Σ Δs²/4, Σ Δd Δs/4, Σ Δd²/4 and
    // Σ Δg_k Δs/4 (Δ the difference of a pixel's two half estimates; Δ²/4 estimates the
    // variance of their mean, and pixels are independent).
    let mut noise = vec![TileNoise::default(); n];
    for (p, s) in cache.pixels.iter().zip(specs) {
        let t = (p.tile as usize).min(n - 1);
        let (q, o, v) = (&mut pixels[t], &mut out[t], &mut noise[t]);
        let (d, d_half) = s.diffuse(p);
        if debias {
            let ds = (s.s_half[0] - s.s_half[1]) * 0.5;
            let dd = (d_half[0] - d_half[1]) * 0.5;
            v.ss += ds * ds;
            v.ds += dd * ds;
            v.dd += dd * dd;
            for k in 0..3 {
                v.gs[k] += (s.ds_half[0][k] - s.ds_half[1][k]) * 0.5 * ds;
            }
        }
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
        if s.d.is_some() {
            let (od, odh) = o.d.get_or_insert((zero, [zero; 2]));
            *od += d;
            odh[0] += d_half[0];
            odh[1] += d_half[1];
        }
    }
    // Each tile's halves become its sums ± the pixels' noise, δs = √(Σ Δs²/4) and the other
    // terms' δ in proportion to their covariance with s (δd δs = Σ Δd Δs/4): the cross-half
    // products of `solve::Moments` then subtract from the tile's squares exactly the noise
    // the pixels' halves measure, S² − Σ Δs²/4 and DS − Σ Δd Δs/4 (D² loses at most its own
    // Σ Δd²/4, by Cauchy–Schwarz).
    for ((q, o), v) in pixels.iter_mut().zip(&mut out).zip(&noise) {
        let ds = v.ss.map(|x| x.sqrt());
        let along = |cov: Rgb| {
            Rgb::new(
                if ds.x > 0.0 { cov.x / ds.x } else { 0.0 },
                if ds.y > 0.0 { cov.y / ds.y } else { 0.0 },
                if ds.z > 0.0 { cov.z / ds.z } else { 0.0 },
            )
        };
        let dd = along(v.ds).clamp(-v.dd.map(|x| x.sqrt()), v.dd.map(|x| x.sqrt()));
        let split = |h: &mut [Rgb; 2], delta: Rgb| {
            let m = (h[0] + h[1]) * 0.5;
            *h = [m + delta, m - delta];
        };
        split(&mut q.d_half, dd);
        split(&mut q.mirror_half, zero);
        split(&mut o.s_half, ds);
        for k in 0..3 {
            let mut g = o.ds_half.map(|h| h[k]);
            split(&mut g, along(v.gs[k]));
            (o.ds_half[0][k], o.ds_half[1][k]) = (g[0], g[1]);
        }
        if let Some((_, dh)) = &mut o.d {
            split(dh, dd);
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

/// A tile's noise sums in [`pooled`].
#[derive(Clone, Copy, Default)]
struct TileNoise {
    ss: Rgb,
    ds: Rgb,
    dd: Rgb,
    gs: [Rgb; 3],
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

/// What pixel `p` contributes to the error of the model ρd, ρs with its specular term `s`.
pub fn terms(p: &CachePixel, s: &PixelSpec, rho_d: Rgb, rho_s: Rgb) -> PixelTerms {
    let (d, d_half) = s.diffuse(p);
    PixelTerms {
        syn: rho_d * d + rho_s * s.s,
        photo: p.photo,
        halves: [
            rho_d * d_half[0] + rho_s * s.s_half[0],
            rho_d * d_half[1] + rho_s * s.s_half[1],
        ],
    }
}

/// ε and the noise floor of the model ρd, ρs with the given specular terms.
pub fn error(cache: &GroupCache, specs: &[PixelSpec], rho_d: Rgb, rho_s: Rgb) -> ErrorStats {
    let pixels = (cache.pixels.iter().zip(specs))
        .map(|(p, s)| (p.tile as usize, terms(p, s, rho_d, rho_s)));
    tiled_error(cache.tiles.max(1), pixels).unwrap_or_default()
}

/// The photo's own noise in ε's units under the model ρd, ρs with the given specular terms
/// ([`super::error::photo_noise`]), from neighbouring pixels of the cache's first photo. None
/// without an image width or neighbouring pixels.
pub fn photo_noise(cache: &GroupCache, specs: &[PixelSpec], rho_d: Rgb, rho_s: Rgb) -> Option<f32> {
    let first = cache.first_view();
    let n = first.len();
    if cache.width == 0 || n == 0 {
        return None;
    }
    let pixels: Vec<(usize, PixelTerms)> = (first.iter().zip(specs))
        .map(|(p, s)| (p.tile as usize, terms(p, s, rho_d, rho_s)))
        .collect();
    let grid = super::cache::PixelGrid::new(first, cache.width);
    let pairs: Vec<(usize, usize)> = (0..n)
        .flat_map(|k| [(1, 0), (0, 1)].map(|(dx, dy)| grid.neighbour(k, dx, dy).map(|j| (k, j))))
        .flatten()
        .collect();
    super::error::photo_noise(cache.tiles.max(1), &pixels, &pairs)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::sampler::{mix64, unit_f32};

    /// Pooled with `debias`, a tile's cross-half products estimate the noise-free products of
    /// its sums (Σ S², Σ D S and Σ G S for a derivative G), where plain pooling exceeds them by
    /// the pixels' noise: pixels of known means whose two half estimates carry independent
    /// noise, correlated between the terms as a sample's weight moves them all.
    #[test]
    fn debiased_tiles_subtract_the_noise_the_pixels_halves_measure() {
        let (tiles, per) = (4000usize, 20usize);
        let mut key = 0u64;
        let mut noise = || {
            key += 1;
            3.0 * (2.0 * unit_f32(mix64(key)) - 1.0)
        };
        let mut cache = GroupCache {
            tiles,
            ..Default::default()
        };
        let mut specs = Vec::new();
        let mut truth = [0.0f64; 3];
        for t in 0..tiles {
            let (mut s_t, mut d_t, mut g_t) = (0.0f64, 0.0f64, 0.0f64);
            for k in 0..per {
                let s = 1.0 + 0.5 * ((t * per + k) as f32 * 0.37).sin();
                let (d, g) = (0.8, -0.3 * s);
                let e = [noise(), noise()];
                let f = [noise(), noise()];
                let half = |m: f32, a: f32, b: f32| Rgb::new(m + a, m + b, m);
                let s_half = [half(s, e[0], 0.0), half(s, e[1], 0.0)];
                let d_half = [
                    half(d, 0.5 * e[0] + 0.2 * f[0], 0.0),
                    half(d, 0.5 * e[1] + 0.2 * f[1], 0.0),
                ];
                let g_half = [half(g, -0.3 * e[0], 0.0), half(g, -0.3 * e[1], 0.0)];
                (s_t, d_t, g_t) = (s_t + s as f64, d_t + d as f64, g_t + g as f64);
                cache.pixels.push(CachePixel {
                    pixel: (t * per + k) as u32,
                    photo: Rgb::ZERO,
                    d: (d_half[0] + d_half[1]) * 0.5,
                    d_half,
                    mirror: Rgb::ZERO,
                    mirror_half: [Rgb::ZERO; 2],
                    start: 0,
                    mid: 0,
                    end: 0,
                    tile: t as u32,
                    normal: crate::math::Vec3::ZERO,
                });
                specs.push(PixelSpec {
                    s: (s_half[0] + s_half[1]) * 0.5,
                    s_half,
                    ds_half: [[g_half[0]; 3], [g_half[1]; 3]],
                    d: None,
                });
            }
            truth[0] += s_t * s_t;
            truth[1] += d_t * s_t;
            truth[2] += g_t * s_t;
        }
        // Channel 0 is noisy, channel 2 noise-free: there both poolings are exact.
        for debias in [false, true] {
            let (tc, ts) = pooled(&cache, &specs, debias);
            let m = moments(&tc, &ts);
            let gs: [f64; 3] = std::array::from_fn(|c| {
                ts.iter()
                    .map(|s| {
                        let (g, h) = (s.ds_half[0][0][c] as f64, s.ds_half[1][0][c] as f64);
                        0.5 * (g * s.s_half[1][c] as f64 + h * s.s_half[0][c] as f64)
                    })
                    .sum()
            });
            let rel = |x: f64, t: f64| x / t - 1.0;
            let got = [
                rel(m[0].ss, truth[0]),
                rel(m[0].ds, truth[1]),
                rel(gs[0], truth[2]),
            ];
            for (x, t) in [(m[2].ss, truth[0]), (m[2].ds, truth[1]), (gs[2], truth[2])] {
                assert!(
                    rel(x, t).abs() < 1e-4,
                    "noise-free channel, debias {debias}"
                );
            }
            if debias {
                assert!(got.iter().all(|r| r.abs() < 0.01), "{got:?}");
            } else {
                // Per tile Σ var(s) = 20 × 1.5 (a half's variance 3, their mean's 1.5) over S²
                // ≈ 400, Σ cov(d, s) = 20 × 0.75 over D S ≈ 320, and the same for G.
                assert!(got.iter().all(|r| r.abs() > 0.03), "{got:?}");
            }
        }
    }
}
