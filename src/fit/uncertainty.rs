//! The 1σ of a group's fitted parameters: how far to trust each number. The model of a group's tile T in channel c is linear in ρd, ρs and,
//! locally, in the lobe's shape:
//!
//!   L_Tc = ρd_c D_Tc + ρs_c S_Tc(ln αx, ln αy, θ)
//!
//! (D, S the cache's sums over the tile's pixels, ∂S from `render::bsdf::ward`). With the
//! residuals r_Tc = photo_Tc − L_Tc weighted 1/(the channel's mean tile)², as ε weighs them,
//! the Gauss–Newton covariance of all free parameters together is s² (JᵀWJ)⁻¹ with
//! s² = Σ w r² / (rows − parameters): the residual scatter holds the photo's noise, the cache's
//! and whatever the model misses, so a level that fits badly reports wide error bars. The
//! parameters reported are a mean of `fits` global iterations' fits, each on its own cache: the
//! cache's share of s² (from its two independent halves, Σ w ((L₀ − L₁)/2)²) shrinks by that
//! count, the photo's and the model's do not.
//!
//! Misfit. s² treats residuals as independent, but a model that misses leaves residuals that
//! are alike over neighbouring tiles, and then s² (JᵀWJ)⁻¹ is too tight. The cluster-robust
//! sandwich (White; Liang & Zeger 1986) over clusters of neighbouring tiles is not; where it
//! exceeds the independent estimate, the excess is added. Across iterations, the group's 1σ
//! also holds the scatter of its single fits ([`with_scatter`]).

use super::cache::GroupCache;
use super::level::Level;
use super::objective::{pixel_specs, Spec};
use super::params::GroupParams;
use crate::math::Rgb;
use crate::scene::WardVariant;

/// Clusters of neighbouring tiles for the sandwich's misfit term (fewer for a group of few
/// tiles: four tiles a cluster at least).
const CLUSTERS: usize = 8;

/// Above this relative 1σ, a Ward lobe's ρs or α is reported as weakly determined.
pub const WEAK_LOBE: f32 = 0.5;

/// The note for a group whose Ward lobe the photo hardly determines: its ρs or α has
/// a 1σ above [`WEAK_LOBE`] of its value, which happens when its pixels show little specular
/// reflection of a light or a bright surface. None for other levels or a determined lobe.
pub fn weak_lobe(level: Level, params: &GroupParams, sigma: &GroupParams) -> Option<String> {
    if !level.has_lobe() {
        return None;
    }
    let rho = sigma.rho_s.max_element() / params.rho_s.max_element().max(1e-6);
    let alpha = (sigma.alpha_x / params.alpha_x.max(1e-6)).max(
        if matches!(level, Level::Anisotropic | Level::AnisotropicMicrofacet) {
            sigma.alpha_y / params.alpha_y.max(1e-6)
        } else {
            0.0
        },
    );
    (rho > WEAK_LOBE || alpha > WEAK_LOBE).then(|| {
        format!(
            "ρs and α weakly determined (1σ: ρs ±{:.0}%, α ±{:.0}%): its pixels show little \
             specular reflection of a light or a bright surface; read them as a range",
            100.0 * rho,
            100.0 * alpha
        )
    })
}

/// The 1σ of every parameter free at `level` (in the parameters' own units: ρ absolute, α
/// absolute, θ radians; zero where not free), for `params` fitted on `cache`. None for the
/// textured level (its texels are their own problem), without tiles, or when the normal matrix
/// is singular.
pub fn sigma(
    cache: &GroupCache,
    level: Level,
    params: &GroupParams,
    variant: WardVariant,
    fits: u32,
) -> Option<GroupParams> {
    let (alpha_y, theta) = match level {
        Level::Isotropic | Level::Microfacet | Level::Plastic => (params.alpha_x, 0.0),
        _ => (params.alpha_y, params.theta),
    };
    let spec = match level {
        Level::Diffuse => Spec::None,
        Level::PerfectSpecular | Level::Specular | Level::DiffuseSpecular => Spec::Mirror,
        Level::Isotropic | Level::Anisotropic => Spec::Lobe {
            alpha_x: params.alpha_x,
            alpha_y,
            theta,
        },
        Level::Microfacet | Level::AnisotropicMicrofacet | Level::Plastic => {
            super::fitter::spec_of(level, params)
        }
        Level::Textured => return None,
    };
    // A bare metal's ρd is not free: levels 8 and 10 pin it to 0 where it did not earn its place
    // (`fitter::fit_level_from`), in every fit of the mean.
    let metal = level.is_microfacet() && params.rho_d == Rgb::ZERO;
    let has_d = !matches!(level, Level::PerfectSpecular | Level::Specular) && !metal;
    let has_s = !matches!(level, Level::Diffuse | Level::PerfectSpecular);
    // The lobe's free shape parameters: ln α (both axes at once) or ln αx, ln αy, θ.
    let shape: &[[f32; 3]] = match level {
        Level::Isotropic => &[[1.0, 1.0, 0.0]],
        Level::Microfacet | Level::Plastic => &[[1.0, 0.0, 0.0]],
        Level::Anisotropic | Level::AnisotropicMicrofacet => {
            &[[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]
        }
        _ => &[],
    };
    let mut specs = pixel_specs(cache, spec, variant, !shape.is_empty());
    // The coat's α moves its diffuse term as well as its lobe, and neither has an analytic
    // derivative here: central differences in ln α, ∂S into `ds_half`, ∂D into `dd`.
    let mut dd = vec![Rgb::ZERO; specs.len()];
    if let Spec::Plastic {
        alpha,
        eta,
        distribution,
    } = spec
    {
        let h = 0.02f32;
        let at = |a: f32| {
            let spec = Spec::Plastic {
                alpha: a,
                eta,
                distribution,
            };
            pixel_specs(cache, spec, variant, false)
        };
        let (up, down) = (at(alpha * h.exp()), at(alpha / h.exp()));
        for (((s, d), u), w) in specs.iter_mut().zip(&mut dd).zip(&up).zip(&down) {
            for k in 0..2 {
                s.ds_half[k][0] = (u.s_half[k] - w.s_half[k]) / (2.0 * h);
            }
            let (du, dw) = (u.d.unwrap_or_default().0, w.d.unwrap_or_default().0);
            *d = (du - dw) / (2.0 * h);
        }
    }
    let n_tiles = cache.tiles;
    if n_tiles == 0 {
        return None;
    }
    // Per tile: photo, D, S, ∂S/∂(ln αx, ln αy, θ), and the model's half difference (L₀ − L₁)/2.
    let rd = if has_d { params.rho_d } else { Rgb::ZERO };
    let rs = if has_s { params.rho_s } else { Rgb::ZERO };
    let zero = Rgb::ZERO;
    let mut tiles = vec![(zero, zero, zero, [zero; 3], zero, zero); n_tiles];
    for ((p, s), dd) in cache.pixels.iter().zip(&specs).zip(&dd) {
        let t = &mut tiles[p.tile as usize];
        t.5 += *dd;
        t.0 += p.photo;
        let (d, d_half) = s.diffuse(p);
        t.1 += d;
        t.2 += s.s;
        for k in 0..3 {
            t.3[k] += (s.ds_half[0][k] + s.ds_half[1][k]) * 0.5;
        }
        t.4 += (rd * (d_half[0] - d_half[1]) + rs * (s.s_half[0] - s.s_half[1])) * 0.5;
    }
    tiles.retain(|t| t.0.max_element() > 0.0);
    // Columns: ρd per channel, ρs per channel, then the shape parameters.
    let col_d = |c: usize| c;
    let col_s = |c: usize| 3 * has_d as usize + c;
    let col_shape = 3 * (has_d as usize + has_s as usize);
    let n = col_shape + shape.len();
    if n == 0 || tiles.len() * 3 <= n {
        return None;
    }
    let mean: Vec<f64> = (0..3)
        .map(|c| tiles.iter().map(|t| t.0[c] as f64).sum::<f64>() / tiles.len() as f64)
        .collect();
    let mut a = vec![vec![0.0f64; n]; n];
    let (mut chi2, mut cache_noise, mut rows) = (0.0f64, 0.0f64, 0usize);
    let mut jac: Vec<(usize, f64)> = Vec::with_capacity(n);
    // The score Σ w r J of each cluster of neighbouring tiles, for the sandwich below.
    let clusters = CLUSTERS.min(tiles.len() / 4).max(1);
    let mut scores = vec![vec![0.0f64; n]; clusters];
    for (ti, t) in tiles.iter().enumerate() {
        let score = &mut scores[ti * clusters / tiles.len()];
        for c in 0..3 {
            if !(mean[c] > 0.0) {
                continue;
            }
            let w = 1.0 / (mean[c] * mean[c]);
            let (rd, rs) = (params.rho_d[c] as f64, params.rho_s[c] as f64);
            let (d, s) = (t.1[c] as f64, t.2[c] as f64);
            let r =
                t.0[c] as f64 - if has_d { rd * d } else { 0.0 } - if has_s { rs * s } else { 0.0 };
            jac.clear();
            if has_d {
                jac.push((col_d(c), d));
            }
            if has_s {
                jac.push((col_s(c), s));
            }
            for (i, mix) in shape.iter().enumerate() {
                let ds: f64 = (0..3).map(|k| mix[k] as f64 * t.3[k][c] as f64).sum();
                jac.push((col_shape + i, rs * ds + rd * t.5[c] as f64));
            }
            chi2 += w * r * r;
            cache_noise += w * (t.4[c] as f64).powi(2);
            rows += 1;
            for &(u, ju) in &jac {
                score[u] += w * r * ju;
            }
            for &(u, ju) in &jac {
                for &(v, jv) in &jac {
                    a[u][v] += w * ju * jv;
                }
            }
        }
    }
    if rows <= n {
        return None;
    }
    // A column nothing constrains (a channel the group is black in) is pinned, its σ left 0.
    let mut pinned = vec![false; n];
    for (u, row) in a.iter_mut().enumerate() {
        if !(row[u] > 0.0) {
            row[u] = 1.0;
            pinned[u] = true;
        }
    }
    let inv = super::solve::invert(&a)?;
    let s2_all = chi2 / (rows - n) as f64;
    let s2_cache = (cache_noise / rows as f64).min(s2_all);
    let s2 = s2_all - s2_cache + s2_cache / (fits.max(1) as f64).sqrt();
    // The misfit's share: the cluster-robust sandwich (A⁻¹ M A⁻¹, M = Σ over clusters of
    // their score's outer product, scaled by K/(K−1)) holds residuals that are correlated
    // across neighbouring tiles, as a model's systematic misfit is and independent noise is
    // not; what it finds beyond the Gauss–Newton variance of independent residuals is added.
    let sandwich = |u: usize| -> f64 {
        if clusters < 2 {
            return 0.0;
        }
        let k = clusters as f64 / (clusters - 1) as f64;
        k * scores
            .iter()
            .map(|g| (0..n).map(|v| inv[u][v] * g[v]).sum::<f64>().powi(2))
            .sum::<f64>()
    };
    let sd = |u: usize| -> f32 {
        if pinned[u] {
            0.0
        } else {
            let excess = (sandwich(u) - s2_all * inv[u][u]).max(0.0);
            (s2 * inv[u][u] + excess).max(0.0).sqrt() as f32
        }
    };
    let mut out = GroupParams::zero_sums();
    for c in 0..3 {
        if has_d {
            out.rho_d[c] = sd(col_d(c));
        }
        if has_s {
            out.rho_s[c] = sd(col_s(c));
        }
    }
    match level {
        Level::Isotropic | Level::Microfacet | Level::Plastic => {
            out.alpha_x = params.alpha_x * sd(col_shape);
            out.alpha_y = out.alpha_x;
        }
        Level::Anisotropic | Level::AnisotropicMicrofacet => {
            out.alpha_x = params.alpha_x * sd(col_shape);
            out.alpha_y = params.alpha_y * sd(col_shape + 1);
            out.theta = sd(col_shape + 2);
        }
        _ => {}
    }
    Some(out)
}

/// The 1σ of a mean of `n` fits on fresh caches: `sigma` from the last cache, plus the scatter
/// of the single fits across caches (`scatter`, their standard deviation), as the variance of
/// a mean, twice over: consecutive caches are traced through nearly the same neighbours'
/// models, so their fits are not independent, and half as many independent ones is the
/// honest count. The neighbours' changes, the exposure's and the cache's noise all move the
/// fits, and none of them is in one cache's Gauss–Newton estimate.
pub fn with_scatter(sigma: &GroupParams, scatter: &GroupParams, n: u32) -> GroupParams {
    let mut out = *sigma;
    let k = 2.0 / n.max(1) as f32;
    let add = |s: f32, d: f32| {
        if s > 0.0 {
            (s * s + k * d * d).sqrt()
        } else {
            s
        }
    };
    for c in 0..3 {
        out.rho_d[c] = add(sigma.rho_d[c], scatter.rho_d[c]);
        out.rho_s[c] = add(sigma.rho_s[c], scatter.rho_s[c]);
    }
    out.alpha_x = add(sigma.alpha_x, scatter.alpha_x);
    out.alpha_y = add(sigma.alpha_y, scatter.alpha_y);
    out.theta = add(sigma.theta, scatter.theta);
    out
}

/// How far a final ε may exceed its noise floor and still be noise: the floor is itself an
/// estimate (from the final render's two halves), and on the bundled scenes fitted at their
/// own models ε / floor reaches 1.21.
pub const NOISE_TOLERANCE: f32 = 1.25;

/// The relative 1σ of a group's light, and of its reflectances, that comes from its own
/// model's misfit: what its final ε exceeds its noise floor by (`error`, `noise`), beyond
/// the floor's own tolerance ([`NOISE_TOLERANCE`]). A group whose model leaves 5% of its own
/// pixels unexplained sends light that may be off by as much.
pub fn model_misfit(error: f32, noise: f32) -> f32 {
    (error - NOISE_TOLERANCE * noise).max(0.0)
}

/// The same misfit read from the group's cache (`error`, `noise_floor` of its last fit there,
/// `photo_noise` the photo's own share, [`super::objective::photo_noise`]). A cache pools
/// several iterations' paths, so its floor is lower than the final render's and a misfit of
/// a few tenths of a percent that hides under the final floor's tolerance shows: ε² beyond
/// the tolerance times the noise of both images, cache and photo, in quadrature. 0 where the
/// photo's noise is not known: without it the photo's noise would pass for misfit.
pub fn cache_misfit(error: f32, noise_floor: f32, photo_noise: Option<f32>) -> f32 {
    let Some(photo) = photo_noise else {
        return 0.0;
    };
    let noise = NOISE_TOLERANCE * noise_floor.hypot(photo);
    (error * error - noise * noise).max(0.0).sqrt()
}

/// The relative 1σ of an unseen group's reflectance, and so of the light it sends: its
/// photo's 1σ where the photo gave one, per channel the worst; where it did not (σ < 0, or
/// at the cap of 1), that of a reflectance known only to lie in [0, 1], 1/√12.
pub fn unseen_misfit(rho_d: [f32; 3], sigma: [f32; 3]) -> f32 {
    let unknown = 1.0 / 12f32.sqrt();
    (0..3)
        .map(|c| {
            let s = if (0.0..1.0).contains(&sigma[c]) {
                sigma[c].min(unknown)
            } else {
                unknown
            };
            s / rho_d[c].max(0.05)
        })
        .fold(0.0, f32::max)
}

/// `sigma` widened by the light that reaches the group by way of the others, which is only
/// as right as their models: with `lit_by[h]` the share of the group's cached light that came
/// by way of group h and `misfit[h]` the relative 1σ of h's light ([`model_misfit`],
/// [`unseen_misfit`]; 0 for a light or a group given), the group's light is uncertain by
/// u = √(Σₕ (lit_byₕ misfitₕ)²) relative, and so are the reflectances fitted to it: ρ's 1σ
/// gains ρ u in quadrature. The shape of a lobe (α, θ) does not scale with the light.
/// The group's own share is left out: its misfit is in its own residuals already.
pub fn with_neighbours(
    sigma: &GroupParams,
    params: &GroupParams,
    group: usize,
    lit_by: &[f32],
    misfit: &[f32],
) -> GroupParams {
    let u = (lit_by.iter().zip(misfit).enumerate())
        .filter(|&(h, _)| h != group)
        .map(|(_, (&x, &m))| (x * m).powi(2))
        .sum::<f32>()
        .sqrt();
    with_relative(sigma, params, u)
}

/// `sigma` with ρ u added in quadrature to every reflectance's 1σ that is free (non-zero): a
/// relative uncertainty u of the light, or of the model, that scales the reflectances and not
/// the lobe's shape.
fn with_relative(sigma: &GroupParams, params: &GroupParams, u: f32) -> GroupParams {
    let mut out = *sigma;
    let add = |s: f32, rho: f32| {
        if s > 0.0 {
            s.hypot(rho * u)
        } else {
            s
        }
    };
    for c in 0..3 {
        out.rho_d[c] = add(sigma.rho_d[c], params.rho_d[c]);
        out.rho_s[c] = add(sigma.rho_s[c], params.rho_s[c]);
    }
    out
}

/// The directional-hemispherical albedo (`render::bsdf::albedo`) of a group's material at
/// normal incidence and at 60°, per channel, with its 1σ: the one quantity every level's model
/// has, so a group's reflectance can be compared across levels and with a truth that is none
/// of matfit's models.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Albedo {
    /// At incidence 0° and 60°.
    pub value: [Rgb; 2],
    /// Per incidence and channel; None where a parameter it depends on is not determined.
    pub sigma: [[Option<f32>; 3]; 2],
}

/// Cosines of the incidences [`Albedo`] is given at: 0° and 60°.
pub const ALBEDO_COSINES: [f32; 2] = [1.0, 0.5];

/// The albedo of `params` at `level` and its 1σ from `sigma` (the parameters' own 1σ; None:
/// not computed). The albedo is linear in the reflectances it has free, a = ρd D + ρs S with D
/// and S the albedos of the model's two parts at unit reflectance, so ∂a/∂ρd = D and ∂a/∂ρs = S; the
/// lobe's widths enter through D and S (a central difference at ±5%). The parameters' 1σ add
/// in quadrature (their covariances are left out). None for a model with no uniform BSDF.
///
/// The model is uncertain too: `alternatives` are fits at levels the photo could not tell
/// from this one ([`GroupState::alternatives`](super::GroupState::alternatives)). Where
/// their albedo differs from this level's by Δ, the truth may lie at either, and the 1σ gains
/// Δ/2 (a two-point spread) in quadrature: a diffuse fit of a metal whose glossy fit did not
/// earn its place, say, reports the albedo of neither with confidence.
pub fn albedo(
    level: Level,
    params: &GroupParams,
    sigma: Option<&GroupParams>,
    alternatives: &[(Level, GroupParams)],
    variant: WardVariant,
) -> Option<Albedo> {
    use crate::render::integrator::uniform_bsdf;
    // D and S at each incidence for a lobe of widths (αx, αy).
    let parts = |ax: f32, ay: f32| -> Option<[[f32; 2]; 2]> {
        let unit = |d: f32, s: f32| {
            let p = GroupParams {
                rho_d: Rgb::splat(d),
                rho_s: Rgb::splat(s),
                alpha_x: ax,
                alpha_y: ay,
                ..*params
            };
            let b = uniform_bsdf(&p.material(level), variant)?;
            Some(ALBEDO_COSINES.map(|mu| b.albedo(mu).x))
        };
        Some([unit(1.0, 0.0)?, unit(0.0, 1.0)?])
    };
    let bsdf = uniform_bsdf(&params.material(level), variant)?;
    let value = ALBEDO_COSINES.map(|mu| bsdf.albedo(mu));
    let [d, s] = parts(params.alpha_x, params.alpha_y)?;
    let free = |name: &str| super::params::param(name).free_at(level);
    // ∂(D, S)/∂α per free width, by central differences.
    let mut widths = Vec::new();
    for (name, x) in [("alpha_x", params.alpha_x), ("alpha_y", params.alpha_y)] {
        if !free(name) {
            continue;
        }
        let h = 0.05 * x;
        let at = |v: f32| {
            if name == "alpha_x" {
                parts(v, params.alpha_y)
            } else {
                parts(params.alpha_x, v)
            }
        };
        let (Some(hi), Some(lo)) = (at(x + h), at(x - h)) else {
            continue;
        };
        let deriv = |i: usize, k: usize| (hi[i][k] - lo[i][k]) / (2.0 * h);
        widths.push((name, [[deriv(0, 0), deriv(0, 1)], [deriv(1, 0), deriv(1, 1)]]));
    }
    let sigma = match sigma {
        None => [[None; 3]; 2],
        Some(sd) => [0, 1].map(|k| {
            std::array::from_fn(|c| {
                // A free parameter with no 1σ (zero: not constrained; or not finite) that the
                // albedo depends on leaves it undetermined too.
                // A reflectance's 1σ of 1 spans its whole range: not determined either.
                let term = |free: bool, deriv: f32, s: f32, reflectance: bool| -> Option<f32> {
                    if !free || deriv == 0.0 {
                        Some(0.0)
                    } else if s > 0.0 && s.is_finite() && (s < 1.0 || !reflectance) {
                        Some(deriv * s)
                    } else {
                        None
                    }
                };
                let mut sum = 0.0;
                let rho = [
                    term(free("rho_d"), d[k], sd.rho_d[c], true)?,
                    term(free("rho_s"), s[k], sd.rho_s[c], true)?,
                ];
                sum += rho[0] * rho[0] + rho[1] * rho[1];
                for (name, dd) in &widths {
                    let deriv = params.rho_d[c] * dd[0][k] + params.rho_s[c] * dd[1][k];
                    let s = if *name == "alpha_x" { sd.alpha_x } else { sd.alpha_y };
                    let t = term(true, deriv, s, false)?;
                    sum += t * t;
                }
                Some(sum.sqrt())
            })
        }),
    };
    let mut spread = [Rgb::ZERO; 2];
    for (alt_level, alt) in alternatives {
        let Some(b) = uniform_bsdf(&alt.material(*alt_level), variant) else {
            continue;
        };
        for (k, mu) in ALBEDO_COSINES.into_iter().enumerate() {
            spread[k] = spread[k].max((b.albedo(mu) - value[k]).abs());
        }
    }
    let sigma = [0, 1].map(|k| {
        std::array::from_fn(|c| sigma[k][c].map(|s: f32| s.hypot(spread[k][c] / 2.0)))
    });
    Some(Albedo { value, sigma })
}

/// `sigma` widened by the group's own misfit `misfit` (the larger of [`model_misfit`] of its
/// final ε and [`cache_misfit`] of its last cache's):
/// where its model leaves its pixels off by m (relative, beyond the noise), a reflectance
/// fitted to them is known no better than that. A least-squares ρ is a weighted mean of
/// per-pixel ratios, and a misfit that does not average out over the group (a shading the
/// model lacks, a neighbour's error in the light it sends, a crease) moves that mean by up to
/// m; the sandwich holds the misfit's scatter, not this shift. ρ's 1σ gains ρ m in quadrature;
/// the lobe's shape does not scale with it.
pub fn with_own_misfit(sigma: &GroupParams, params: &GroupParams, misfit: f32) -> GroupParams {
    with_relative(sigma, params, misfit)
}

#[cfg(test)]
mod neighbour_tests {
    use super::*;

    /// A wall lit 30% by way of a neighbour whose model misses its pixels by 5% beyond the
    /// noise, and 4% by way of a ceiling nobody sees: its ρd's 1σ grows to hold both, its own
    /// share and its α's do not count.
    #[test]
    fn light_from_misfit_or_unseen_neighbours_widens_the_reflectances_only() {
        let params = GroupParams {
            rho_d: Rgb::new(0.6, 0.5, 0.4),
            alpha_x: 0.2,
            ..GroupParams::default()
        };
        let sigma = GroupParams {
            rho_d: Rgb::splat(0.002),
            alpha_x: 0.01,
            ..GroupParams::default()
        };
        let neighbour = model_misfit(0.0875, 0.03);
        assert!((neighbour - 0.05).abs() < 1e-6);
        assert_eq!(model_misfit(0.02, 0.03), 0.0);
        // Within the floor's own tolerance: noise, not misfit.
        assert_eq!(model_misfit(0.036, 0.03), 0.0);
        // The ceiling: no estimate from the photo, given ρd 0.4.
        let ceiling = unseen_misfit([0.4; 3], [-1.0; 3]);
        assert!((ceiling - 0.2887 / 0.4).abs() < 1e-3, "{ceiling}");
        // Estimated to ±0.02 of 0.5: 4%.
        assert!((unseen_misfit([0.5; 3], [0.02; 3]) - 0.04).abs() < 1e-6);
        let lit_by = [0.5, 0.3, 0.04];
        let misfit = [0.9, neighbour, ceiling];
        let wide = with_neighbours(&sigma, &params, 0, &lit_by, &misfit);
        let u = ((0.3f32 * 0.05).powi(2) + (0.04 * ceiling).powi(2)).sqrt();
        for c in 0..3 {
            let want = 0.002f32.hypot(params.rho_d[c] * u);
            assert!((wide.rho_d[c] - want).abs() < 1e-6, "{c}: {wide:?}");
        }
        assert_eq!(wide.alpha_x, 0.01);
        // Nothing free stays nothing (ρs of a diffuse fit).
        assert_eq!(wide.rho_s, Rgb::splat(0.0));
        // Neighbours at their noise floor and seen ceilings change nothing.
        let same = with_neighbours(&sigma, &params, 0, &lit_by, &[0.9, 0.0, 0.0]);
        assert_eq!(same.rho_d, sigma.rho_d);
    }
}

#[cfg(test)]
mod albedo_tests {
    use super::*;

    /// A group's own misfit widens its reflectances by ρ m and leaves its lobe's shape.
    #[test]
    fn own_misfit_widens_the_reflectances_by_its_share() {
        let params = GroupParams {
            rho_d: Rgb::new(0.6, 0.5, 0.4),
            rho_s: Rgb::splat(0.1),
            alpha_x: 0.2,
            ..GroupParams::default()
        };
        let sigma = GroupParams {
            rho_d: Rgb::splat(0.003),
            rho_s: Rgb::splat(0.01),
            alpha_x: 0.02,
            ..GroupParams::default()
        };
        let m = model_misfit(0.04, 0.02);
        assert!((m - 0.015).abs() < 1e-6);
        let wide = with_own_misfit(&sigma, &params, m);
        for c in 0..3 {
            assert!((wide.rho_d[c] - 0.003f32.hypot(params.rho_d[c] * m)).abs() < 1e-7);
            assert!((wide.rho_s[c] - 0.01f32.hypot(0.1 * m)).abs() < 1e-7);
        }
        assert_eq!(wide.alpha_x, 0.02);
        assert_eq!(with_own_misfit(&sigma, &params, 0.0), sigma);
    }

    /// A diffuse group's albedo is its ρd at every incidence, with ρd's 1σ; a glossy one's
    /// is the BSDF's, and its 1σ holds the lobe's width too, unless a parameter it depends on
    /// is not determined.
    #[test]
    fn albedo_and_its_sigma_follow_the_parameters() {
        let params = GroupParams {
            rho_d: Rgb::new(0.6, 0.5, 0.4),
            rho_s: Rgb::splat(0.3),
            alpha_x: 0.3,
            ..GroupParams::default()
        };
        let sigma = GroupParams {
            rho_d: Rgb::splat(0.01),
            rho_s: Rgb::splat(0.02),
            alpha_x: 0.05,
            ..GroupParams::default()
        };
        let v = WardVariant::Balanced;
        let d = albedo(Level::Diffuse, &params, Some(&sigma), &[], v).unwrap();
        for k in 0..2 {
            assert!((d.value[k] - params.rho_d).abs().max_element() < 1e-3, "{d:?}");
            for c in 0..3 {
                assert!((d.sigma[k][c].unwrap() - 0.01).abs() < 1e-4, "{d:?}");
            }
        }
        let m = albedo(Level::Microfacet, &params, Some(&sigma), &[], v).unwrap();
        let bsdf = crate::render::integrator::uniform_bsdf(&params.material(Level::Microfacet), v)
            .unwrap();
        assert_eq!(m.value[1], bsdf.albedo(0.5));
        // A GGX lobe of α 0.3 loses some light to masking, more with α: its width adds to
        // the 1σ what ρd's and ρs's do not.
        let lobe_only = GroupParams {
            rho_d: Rgb::ZERO,
            rho_s: Rgb::ONE,
            ..params
        };
        let s0 = crate::render::integrator::uniform_bsdf(&lobe_only.material(Level::Microfacet), v)
            .unwrap()
            .albedo(1.0)
            .x;
        let rho_only = 0.01f32.hypot(0.02 * s0);
        assert!(m.sigma[0][0].unwrap() > 1.05 * rho_only, "{m:?} {rho_only}");
        let no_alpha = GroupParams {
            alpha_x: 0.0,
            ..sigma
        };
        let u = albedo(Level::Microfacet, &params, Some(&no_alpha), &[], v).unwrap();
        assert_eq!(u.sigma, [[None; 3]; 2]);
        // Without σ at all (a group given): the value alone.
        let g = albedo(Level::Microfacet, &params, None, &[], v).unwrap();
        assert_eq!((g.value, g.sigma), (m.value, [[None; 3]; 2]));
        // A diffuse fit whose glossy alternative (ρd 0.3, ρs 0.5) the photo could not tell
        // apart: its albedo's 1σ holds half their difference.
        let glossy = GroupParams {
            rho_d: Rgb::splat(0.3),
            rho_s: Rgb::splat(0.5),
            ..params
        };
        let alt = [(Level::Microfacet, glossy)];
        let w = albedo(Level::Diffuse, &params, Some(&sigma), &alt, v).unwrap();
        let a_alt = crate::render::integrator::uniform_bsdf(&glossy.material(Level::Microfacet), v)
            .unwrap()
            .albedo(1.0);
        for c in 0..3 {
            let half = (a_alt[c] - params.rho_d[c]).abs() / 2.0;
            assert!((w.sigma[0][c].unwrap() - 0.01f32.hypot(half)).abs() < 1e-4, "{w:?}");
        }
    }
}

#[cfg(test)]
mod weak_lobe_tests {
    use super::*;

    #[test]
    fn a_lobe_with_wide_error_bars_is_flagged_and_a_tight_one_is_not() {
        let p = GroupParams {
            rho_s: Rgb::splat(0.2),
            alpha_x: 0.1,
            alpha_y: 0.2,
            ..GroupParams::default()
        };
        let tight = GroupParams {
            rho_s: Rgb::splat(0.01),
            alpha_x: 0.005,
            alpha_y: 0.01,
            ..GroupParams::default()
        };
        assert_eq!(weak_lobe(Level::Isotropic, &p, &tight), None);
        let wide_alpha = GroupParams {
            alpha_y: 0.15,
            ..tight
        };
        // αy counts only where it is free.
        assert_eq!(weak_lobe(Level::Isotropic, &p, &wide_alpha), None);
        let note = weak_lobe(Level::Anisotropic, &p, &wide_alpha).unwrap();
        assert!(note.contains("α ±75%"), "{note}");
        let wide_rho = GroupParams {
            rho_s: Rgb::new(0.01, 0.15, 0.01),
            ..tight
        };
        assert!(weak_lobe(Level::Isotropic, &p, &wide_rho)
            .unwrap()
            .contains("ρs ±75%"));
        // Not a Ward level: nothing to say.
        assert_eq!(weak_lobe(Level::Diffuse, &p, &wide_rho), None);
    }
}
