//! Groups no usable pixel speaks for ("unseen": a ceiling out of view, an object behind
//! another) still reflect light onto the seen groups. Their diffuse reflectance is estimated
//! from that light, jointly with the seen groups, instead of assumed (the notes' white default
//! made every seen group of a typical room 2–4% too dark).
//!
//! Every cache measures how its pixels change with each unseen group's ρd_u: its indirect rays
//! are traced again through the scene with ρd_u moved, with the same random numbers
//! (`cache::UnseenShares`), which gives ∂D/∂ρd_u and ∂S/∂ρd_u with the light that bounced on u
//! any number of times and anywhere along the path; a mirror's cache does the same for the
//! radiance along its reflection, so a surface seen only in a mirror is fitted from its image
//! there (∂S/∂ρd_u of the mirror levels). Per channel, a tile T of a seen group g is then, to
//! first order in the change δ_u of ρd_u,
//!
//!   photo_T ≈ ρd_g (D_T + Σ_u δ_u ∂D_T/∂ρd_u) + ρs_g (S_T + Σ_u δ_u ∂S_T/∂ρd_u),
//!
//! with D, S the cache's diffuse and specular sums (S at the group's fitted lobe).
//! [`solve_channel`] fits every seen group's ρd, ρs and every δ_u together (Gauss–Newton on this
//! bilinear model, weights 1/(the group's mean tile)² so that every group counts by its relative
//! error, as ε): the seen groups' reflectances are refitted for each trial δ, which is what a
//! brighter ceiling does to them. The unseen group is told apart by the *shape* of its light
//! across the tiles (it fills shadows, it lights one side more), so it can be weakly
//! determined; its 1σ is the larger of the formula's (residual scatter × the inverse normal
//! matrix) and half the difference between the fits on the caches' two independent halves.
//!
//! [`update`] moves ρd_u part of the way ([`UnseenOptions::damping`]: the light is not linear in
//! ρd_u, a path can bounce on u more than once) and the next global iteration, whose caches see
//! the new ρd_u, measures again. Where the estimate is not determined (σ above
//! [`UnseenOptions::max_sigma`] in a channel), the group gets a stated scene-derived default
//! instead: the seen groups' area-weighted mean albedo (ρd + ρs). [`UnseenEstimate`] says which
//! rule gave the value, how well it is determined and what the user can do about it.
//!
//! The stray light (`Scene::stray_light`, `recover --stray-light`) is one more such
//! unknown, tracked last as [`STRAY_LIGHT`]: the probe scene has it moved ([`moved_stray`]),
//! and its δ is a radiance, not a reflectance (no upper bound; a channel never determined keeps
//! its given value). Where no ray leaves the scene its column is empty, and the channel is
//! solved without it, so a closed room's unseen groups come out as without the option.

use super::cache::{CacheNeeds, GroupCache, Sample, STRAY_LIGHT};
use super::group::{GroupState, Status};
use super::level::Level;
use super::objective::Spec;
use super::stray::StrayEstimate;
use crate::math::{Rgb, Vec3};
use crate::render::bsdf::ward::{lobe_sums, LobeParams};
use crate::scene::{Scene, WardVariant};
use serde::{Deserialize, Serialize};

#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct UnseenOptions {
    /// Estimate unseen groups' ρd (false: the old rule, `RecoverOptions::default_rho_d`).
    pub enabled: bool,
    /// The fraction of the way from the current ρd to the fitted one an iteration moves (the
    /// first three times; then less, [`History`]).
    pub damping: f32,
    /// Largest 1σ (any channel) for which the estimate is used; above it the scene default.
    pub max_sigma: f32,
}

impl Default for UnseenOptions {
    fn default() -> Self {
        UnseenOptions {
            enabled: true,
            damping: 0.8,
            max_sigma: 0.1,
        }
    }
}

/// Which rule gave an unseen group's reflectance.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Rule {
    /// Estimated from the light it reflects onto the seen groups.
    Estimated,
    /// Not determined by the photo: the seen groups' area-weighted mean albedo.
    SceneMean,
}

/// The estimate of one unseen group's ρd.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct UnseenEstimate {
    pub group: usize,
    pub rule: Rule,
    pub rho_d: [f32; 3],
    /// 1σ of the estimate from the photo (also given when the scene default was used instead,
    /// to show how poorly it was determined).
    pub sigma: [f32; 3],
    /// The share of the seen pixels' radiance that this group's ρd moves (d ln L / d ln ρ,
    /// averaged over the sampled pixels): how much of its light reaches what the camera sees.
    pub influence: f32,
    /// What the user can do to determine it better.
    pub remedy: String,
}

impl UnseenEstimate {
    /// One line for the log and the summary.
    pub fn describe(&self) -> String {
        let [r, g, b] = self.rho_d;
        let [sr, sg, sb] = self.sigma;
        let how = match self.rule {
            Rule::Estimated => "estimated from the light it reflects onto seen groups",
            Rule::SceneMean => {
                "not determined by the photo: given the seen groups' area-weighted mean albedo"
            }
        };
        // σ < 0: the photo gave no estimate at all in that channel; σ ≥ 1 (the cap) spans all
        // of [0, 1]. Neither is an error bar.
        let one = |s: f32| {
            if (0.0..1.0).contains(&s) {
                format!("{s:.3}")
            } else {
                "not determined".to_string()
            }
        };
        let sigma = if self.sigma.iter().all(|&s| s < 0.0) {
            "no estimate from the photo".to_string()
        } else {
            format!("photo's 1σ ({}, {}, {})", one(sr), one(sg), one(sb))
        };
        format!(
            "no usable pixels; {how}: ρd ({r:.3}, {g:.3}, {b:.3}), {sigma}, influence {:.1}% of \
             the seen light. {}",
            100.0 * self.influence,
            self.remedy
        )
    }
}

/// One tile of a seen group, per channel sums over its cached pixels and per cache half (each
/// half alone an estimate of the whole, as `CachePixel::d_half`).
#[derive(Clone, Debug)]
pub struct TileShare {
    pub photo: Rgb,
    /// D and S of the cache (S at the group's fitted lobe).
    pub d: [Rgb; 2],
    pub s: [Rgb; 2],
    /// Per tracked unseen group: ∂D/∂ρd_u and ∂S/∂ρd_u.
    pub du: Vec<[Rgb; 2]>,
    pub su: Vec<[Rgb; 2]>,
}

/// A seen group's tiles as the unseen estimate reads them, with its fitted reflectances.
#[derive(Clone, Debug)]
pub struct GroupShares {
    pub group: usize,
    /// Whether ρd is free at the group's level (false: held at its value, 0 for a mirror).
    pub diffuse: bool,
    /// Whether ρs is free at the group's level (false: held at its value, 0 for Lambert, 1 for
    /// a perfect mirror).
    pub specular: bool,
    pub rho_d: Rgb,
    pub rho_s: Rgb,
    pub tiles: Vec<TileShare>,
}

/// The tiles of `cache` with their derivatives along the unseen groups, for the group's fitted
/// model in `state`. None when the cache tracks no unseen group, or for a texture (a texture
/// can take any shape, so it says nothing about the unseen light).
pub fn shares(
    cache: &GroupCache,
    group: usize,
    state: &GroupState,
    variant: WardVariant,
) -> Option<GroupShares> {
    let tracked = cache.unseen.as_ref()?;
    let k = tracked.groups.len();
    let level = state.level;
    let spec = match level {
        Level::Diffuse => Spec::None,
        Level::PerfectSpecular | Level::Specular | Level::DiffuseSpecular => Spec::Mirror,
        Level::Isotropic | Level::Anisotropic => Spec::Lobe {
            alpha_x: state.params.alpha_x,
            alpha_y: if level == Level::Isotropic {
                state.params.alpha_x
            } else {
                state.params.alpha_y
            },
            theta: if level == Level::Isotropic {
                0.0
            } else {
                state.params.theta
            },
        },
        Level::Microfacet | Level::AnisotropicMicrofacet | Level::Plastic => {
            super::fitter::spec_of(level, &state.params)
        }
        Level::Textured => return None,
    };
    if k == 0 || cache.tiles == 0 {
        return None;
    }
    // Levels 8–10: the model's terms, and their derivatives along each tracked group, from
    // the objective's own evaluation (`pixel_specs`) of the cache and of its derivative: the
    // model is linear in the samples' radiance, so the derivative of a term is the term
    // evaluated on the samples' derivatives. The coat of level 9 scales the diffuse term too.
    let generic = matches!(
        spec,
        Spec::Microfacet { .. } | Spec::AnisoMicrofacet { .. } | Spec::Plastic { .. }
    );
    let generic_terms = if generic {
        if tracked.dc.len() != k * cache.samples.len() {
            return None;
        }
        Some(derivative_terms(cache, tracked, spec, variant))
    } else {
        None
    };
    let lobe = match spec {
        Spec::Lobe {
            alpha_x,
            alpha_y,
            theta,
        } => Some(LobeParams::new(alpha_x, alpha_y, theta, variant)),
        _ => None,
    };
    let empty = TileShare {
        photo: Rgb::ZERO,
        d: [Rgb::ZERO; 2],
        s: [Rgb::ZERO; 2],
        du: vec![[Rgb::ZERO; 2]; k],
        su: vec![[Rgb::ZERO; 2]; k],
    };
    let mut tiles = vec![empty; cache.tiles];
    // Per tile: its pixels, and those that measured the derivatives.
    let mut counts = vec![(0u32, 0u32); cache.tiles];
    let mut moved: Vec<Sample> = Vec::new();
    for (i, p) in cache.pixels.iter().enumerate() {
        let t = &mut tiles[p.tile as usize];
        t.photo += p.photo;
        let probed = tracked.probed.get(i).copied().unwrap_or(true);
        counts[p.tile as usize].0 += 1;
        counts[p.tile as usize].1 += probed as u32;
        if let Some(terms) = &generic_terms {
            let (d, s, du, su) = &terms[i];
            for h in 0..2 {
                t.d[h] += d[h];
                t.s[h] += s[h];
                for j in (0..k).filter(|_| probed) {
                    t.du[j][h] += du[j][h];
                    t.su[j][h] += su[j][h];
                }
            }
            continue;
        }
        for h in 0..2 {
            t.d[h] += p.d_half[h];
            for j in 0..k {
                t.du[j][h] += tracked.d_half[i * k + j][h];
            }
        }
        match (&lobe, spec) {
            (Some(lobe), _) if tracked.dc.len() == k * cache.samples.len() => {
                for (h, range) in [(0, p.start..p.mid), (1, p.mid..p.end)] {
                    let (a, b) = (range.start as usize, range.end as usize);
                    // A half's sums estimate the whole as twice their value (as d_half).
                    t.s[h] += lobe_sums(&cache.samples[a..b], lobe, false).0 * 2.0;
                    for j in (0..k).filter(|_| probed) {
                        moved.clear();
                        moved.extend((a..b).map(|s| Sample {
                            c: tracked.dc[s * k + j],
                            ..cache.samples[s]
                        }));
                        t.su[j][h] += lobe_sums(&moved, lobe, false).0 * 2.0;
                    }
                }
            }
            (None, Spec::Mirror) => {
                t.s[0] += p.mirror_half[0];
                t.s[1] += p.mirror_half[1];
                for j in (0..k).filter(|_| probed) {
                    if let Some(dm) = tracked.mirror_half.get(i * k + j) {
                        t.su[j][0] += dm[0];
                        t.su[j][1] += dm[1];
                    }
                }
            }
            (None, _) => {}
            // A lobe without its samples' derivatives: no estimate from this group.
            (Some(_), _) => return None,
        }
    }
    // The derivatives summed over the probed pixels, scaled to the whole tile.
    for (t, &(all, probed)) in tiles.iter_mut().zip(&counts) {
        let f = if probed > 0 {
            all as f32 / probed as f32
        } else {
            0.0
        };
        for v in t.du.iter_mut().chain(t.su.iter_mut()) {
            *v = [v[0] * f, v[1] * f];
        }
    }
    tiles.retain(|t| t.photo.max_element() > 0.0);
    Some(GroupShares {
        group,
        diffuse: !matches!(level, Level::PerfectSpecular | Level::Specular),
        specular: !matches!(level, Level::Diffuse | Level::PerfectSpecular),
        rho_d: state.params.rho_d,
        rho_s: state.params.rho_s,
        tiles,
    })
}

/// Per cached pixel of a level 8–10 group: its diffuse and specular terms per half, and their
/// derivatives along each tracked group (per group, per half), from `pixel_specs` of the cache
/// and of a copy whose samples and diffuse sums are their derivatives.
#[allow(clippy::type_complexity)]
fn derivative_terms(
    cache: &GroupCache,
    tracked: &crate::fit::cache::UnseenShares,
    spec: Spec,
    variant: WardVariant,
) -> Vec<([Rgb; 2], [Rgb; 2], Vec<[Rgb; 2]>, Vec<[Rgb; 2]>)> {
    let k = tracked.groups.len();
    let terms = |c: &GroupCache| -> Vec<([Rgb; 2], [Rgb; 2])> {
        let specs = super::objective::pixel_specs(c, spec, variant, false);
        c.pixels
            .iter()
            .zip(&specs)
            .map(|(p, s)| (s.diffuse(p).1, s.s_half))
            .collect()
    };
    let mut out: Vec<_> = terms(cache)
        .into_iter()
        .map(|(d, s)| (d, s, Vec::with_capacity(k), Vec::with_capacity(k)))
        .collect();
    for j in 0..k {
        // What `pixel_specs` reads (pixels, samples, tiles), not the texel rows or the
        // tracked derivatives a whole copy would carry.
        let mut moved = GroupCache {
            pixels: cache.pixels.clone(),
            samples: (0..cache.samples.len())
                .map(|s| Sample {
                    c: tracked.dc[s * k + j],
                    ..cache.samples[s]
                })
                .collect(),
            tiles: cache.tiles,
            width: cache.width,
            ..Default::default()
        };
        for (i, p) in moved.pixels.iter_mut().enumerate() {
            p.d_half = tracked.d_half[i * k + j];
            p.d = p.d_half[0] * 0.5 + p.d_half[1] * 0.5;
        }
        for (o, (d, s)) in out.iter_mut().zip(terms(&moved)) {
            o.2.push(d);
            o.3.push(s);
        }
    }
    out
}

/// What [`solve_channel`] does with each tile: (its group, its weight, the unknowns its model
/// reads, the Jacobian of each cache half along them, the residual of each half).
type TileVisit<'a> = dyn FnMut(usize, f64, &[usize], [&[f64]; 2], [f64; 2]) + 'a;

/// Which tiles of every group a fit reads: all, or every other one (two fits on independent
/// pixels, whose difference measures the estimate's whole noise, photo's and cache's).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Tiles {
    All,
    Even,
    Odd,
}

impl Tiles {
    fn keeps(self, i: usize) -> bool {
        match self {
            Tiles::All => true,
            Tiles::Even => i.is_multiple_of(2),
            Tiles::Odd => i % 2 == 1,
        }
    }
}

/// The mean of a term's two halves in channel `c`.
fn mean(v: &[Rgb; 2], c: usize) -> f64 {
    0.5 * (v[0][c] as f64 + v[1][c] as f64)
}

/// The fit of every δ_u (the change of ρd_u) in channel `c` jointly with every seen group's ρd
/// (and ρs where free), and the δs' 1σ from the residual scatter. None when there are too few
/// tiles, or when some δ_u is not identifiable: nearly all of its column is explained by the
/// others (the unseen surface's light looks like a change of the seen groups' own reflectance).
///
/// The normal equations take products of the two cache halves' terms (Jacobian of one half
/// times residual and Jacobian of the other), as the fitter's moments do (`solve.rs`): the
/// halves' noise is independent, so the products hold no noise², which in plain least squares
/// biases a weak column (the δs came out 5% low on figure6 at the default sample counts).
pub fn solve_channel(
    groups: &[GroupShares],
    k: usize,
    c: usize,
    tiles: Tiles,
) -> Option<(Vec<f64>, Vec<f64>)> {
    // Unknowns: per group ρd and ρs where free; then the k δs. A fixed one reads its value.
    let mut offset: Vec<(Option<usize>, Option<usize>)> = Vec::with_capacity(groups.len());
    let mut n = 0usize;
    for g in groups {
        let od = g.diffuse.then_some(n);
        n += g.diffuse as usize;
        let os = g.specular.then_some(n);
        n += g.specular as usize;
        offset.push((od, os));
    }
    let tau0 = n;
    n += k;
    let mut x = vec![0.0f64; n];
    for (g, &(od, os)) in groups.iter().zip(&offset) {
        if let Some(o) = od {
            x[o] = g.rho_d[c] as f64;
        }
        if let Some(o) = os {
            x[o] = g.rho_s[c] as f64;
        }
    }
    // First pass: per group 1/(mean tile photo)², each tile's residual relative, as ε. Second
    // pass: that divided by the group's own residual variance in the first, so each tile counts
    // by the inverse of its variance (a group its model does not yet fit, a glossy floor at the
    // diffuse level, then counts little) and the inverse normal matrix is the covariance.
    let relative: Vec<f64> = groups
        .iter()
        .map(|g| {
            let m = g.tiles.iter().map(|t| t.photo[c] as f64).sum::<f64>()
                / g.tiles.len().max(1) as f64;
            if m > 0.0 {
                1.0 / (m * m)
            } else {
                0.0
            }
        })
        .collect();
    let kept = |g: &GroupShares| (0..g.tiles.len()).filter(|&i| tiles.keeps(i)).count();
    let rows: usize = groups
        .iter()
        .zip(&relative)
        .filter(|(_, &w)| w > 0.0)
        .map(|(g, _)| kept(g))
        .sum();
    if rows < n + 2 {
        return None;
    }
    // Per tile, the unknowns its model reads, and per cache half the Jacobian and residual.
    let visit = |x: &[f64], weight: &[f64], f: &mut TileVisit| {
        let mut idx: Vec<usize> = Vec::with_capacity(2 + k);
        let mut jac: [Vec<f64>; 2] = [Vec::new(), Vec::new()];
        for (gi, ((g, &(od, os)), &w)) in groups.iter().zip(&offset).zip(weight).enumerate() {
            if w == 0.0 {
                continue;
            }
            let rd = od.map_or(g.rho_d[c] as f64, |o| x[o]);
            let rs = os.map_or(g.rho_s[c] as f64, |o| x[o]);
            for (_, t) in g.tiles.iter().enumerate().filter(|(i, _)| tiles.keeps(*i)) {
                idx.clear();
                idx.extend((0..k).map(|j| tau0 + j));
                idx.extend(od);
                idx.extend(os);
                let mut r = [0.0f64; 2];
                for h in 0..2 {
                    let (mut d, mut s) = (t.d[h][c] as f64, t.s[h][c] as f64);
                    jac[h].clear();
                    for j in 0..k {
                        let (du, su) = (t.du[j][h][c] as f64, t.su[j][h][c] as f64);
                        d += x[tau0 + j] * du;
                        s += x[tau0 + j] * su;
                        jac[h].push(rd * du + rs * su);
                    }
                    if od.is_some() {
                        jac[h].push(d);
                    }
                    if os.is_some() {
                        jac[h].push(s);
                    }
                    r[h] = rd * d + rs * s - t.photo[c] as f64;
                }
                f(gi, w, &idx, [&jac[0], &jac[1]], r);
            }
        }
    };
    // The normal equations, the cross-half cost Σ w r₀ r₁ and, per group, Σ w r̄².
    let normal = |x: &[f64], weight: &[f64]| {
        let mut a = vec![vec![0.0f64; n]; n];
        let mut b = vec![0.0f64; n];
        let mut cost = 0.0f64;
        let mut plain = vec![0.0f64; groups.len()];
        visit(x, weight, &mut |gi, w, idx, [j0, j1], [r0, r1]| {
            cost += w * r0 * r1;
            plain[gi] += w * (0.5 * (r0 + r1)).powi(2);
            for (p, &u) in idx.iter().enumerate() {
                b[u] -= 0.5 * w * (j0[p] * r1 + j1[p] * r0);
                for (q, &v) in idx.iter().enumerate() {
                    a[u][v] += 0.5 * w * (j0[p] * j1[q] + j1[p] * j0[q]);
                }
            }
        });
        (a, b, cost, plain)
    };
    // Levenberg–Marquardt (the model is bilinear: a few steps).
    let solve = |x: &mut Vec<f64>, weight: &[f64]| {
        let mut mu = 1e-6;
        let (mut a, mut b, mut cost, mut plain) = normal(x, weight);
        for _ in 0..50 {
            let mut damped = a.clone();
            for (u, row) in damped.iter_mut().enumerate() {
                if !(row[u] > 0.0) {
                    row[u] = 1.0;
                }
                row[u] *= 1.0 + mu;
            }
            let Some(inv) = super::solve::invert(&damped) else {
                break;
            };
            let step: Vec<f64> = (0..n)
                .map(|u| (0..n).map(|v| inv[u][v] * b[v]).sum())
                .collect();
            let trial: Vec<f64> = x.iter().zip(&step).map(|(a, s)| a + s).collect();
            let (ta, tb, tc, tp) = normal(&trial, weight);
            if tc <= cost {
                let small = step
                    .iter()
                    .zip(x.iter())
                    .all(|(s, v)| s.abs() <= 1e-7 * (1.0 + v.abs()));
                (*x, a, b, cost, plain) = (trial, ta, tb, tc, tp);
                mu = (mu * 0.1).max(1e-12);
                if small {
                    break;
                }
            } else {
                mu *= 10.0;
                if mu > 1e6 {
                    break;
                }
            }
        }
        (a, plain)
    };
    let (_, plain) = solve(&mut x, &relative);
    let weight: Vec<f64> = groups
        .iter()
        .zip(&relative)
        .zip(&plain)
        .map(|((g, &w), &p)| {
            // The group's residual variance per tile (its own fitted unknowns discounted).
            let m = kept(g) as f64;
            let own = (g.diffuse as usize + g.specular as usize) as f64;
            let var = p / (m - own).max(1.0);
            if w > 0.0 && m > own {
                w / var.max(1e-12)
            } else {
                0.0
            }
        })
        .collect();
    tracing::trace!(
        "channel {c} {tiles:?}: relative residual variance per group {:?}",
        groups
            .iter()
            .zip(&relative)
            .zip(&plain)
            .map(|((g, &w), &p)| (g.group, if w > 0.0 { p / kept(g) as f64 } else { 0.0 }))
            .collect::<Vec<_>>()
    );
    let (mut a, _) = solve(&mut x, &weight);
    // A column with no weight at all (a group all of whose tiles are dark in this channel) is
    // pinned; a δ with none is not identifiable.
    for (u, row) in a.iter_mut().enumerate() {
        if !(row[u] > 0.0) {
            if u >= tau0 {
                return None;
            }
            row[u] = 1.0;
        }
    }
    let inv = super::solve::invert(&a)?;
    // 1 / (A⁻¹_uu A_uu) is the share of column u the other columns do not explain.
    if (tau0..n).any(|u| !(inv[u][u] * a[u][u] < 1e6)) {
        return None;
    }
    let sigma = (tau0..n).map(|u| inv[u][u].max(0.0).sqrt()).collect();
    Some((x[tau0..].to_vec(), sigma))
}

/// The seen (fitted) groups' area-weighted mean albedo ρd + ρs, per channel; grey 0.5 when no
/// group is fitted.
pub fn scene_mean_albedo(scene: &Scene, states: &[GroupState]) -> Rgb {
    let g = &*scene.geometry;
    let mut area = vec![0.0f64; states.len()];
    for t in &g.tris {
        let [a, b, c] = t.v.map(|i| g.positions[i as usize]);
        let gi = scene.objects[t.object as usize].group;
        area[gi] += 0.5 * (b - a).cross(c - a).length() as f64;
    }
    let (mut sum, mut total) = (Vec3::ZERO, 0.0f64);
    for (s, &ar) in states.iter().zip(&area) {
        if s.is_fitted() && ar > 0.0 {
            sum += (s.params.rho_d + s.params.rho_s) * ar as f32;
            total += ar;
        }
    }
    if total > 0.0 {
        (sum / total as f32).clamp(Rgb::ZERO, Rgb::ONE)
    } else {
        Rgb::splat(0.5)
    }
}

/// The groups whose ρd [`update`] estimates: no usable pixel, not fixed, not an emitter.
pub fn unseen_groups(states: &[GroupState]) -> Vec<usize> {
    (0..states.len())
        .filter(|&g| states[g].status == Status::Default)
        .collect()
}

/// A cache that holds only diffuse light measures its derivative along an unseen group only if
/// its group's last cache took at least this share of its light from that group per unit of
/// the group's ρd. Below it the derivative cannot inform the estimate (a group whose light is
/// known to 0.3% would put it at ±0.6 from such a cache), and measuring it retraces the
/// cache's indirect rays: the 1920×1080 office's hidden book row took at most 0.1% of any
/// group's light per unit ρd, and cost every cache build of every iteration.
pub const PROBE_SHARE: f32 = 0.005;

/// Whether the next cache of a group (state `s`, needing `needs`) measures its light's
/// derivative along unseen group `su`'s ρd. Always where the group's model can read more than
/// its diffuse light (a lobe or a mirror reflection can be all that group, whatever its share
/// of the diffuse light) or before its first cache; else where the group's last cache took
/// [`PROBE_SHARE`] of its light or more from `su` per unit of its ρd (its smallest channel,
/// from 0.05 up: a dark estimate must not hide a strong influence).
pub fn worth_probing(s: &GroupState, needs: CacheNeeds, u: usize, su: &GroupState) -> bool {
    if needs.lobe_samples || needs.mirror {
        return true;
    }
    // Unknown before the first cache (`lit_by` empty).
    let share = s.lit_by.get(u).copied().unwrap_or(f32::INFINITY);
    share >= PROBE_SHARE * su.params.rho_d.min_element().max(0.05)
}

/// The scene with unseen group `u`'s ρd moved by the step its cache derivative is measured
/// along, and the step: 0.2 towards the middle of [0, 1] per channel (large enough that Russian
/// roulette ending a path differently in the two renders adds little noise).
pub fn moved_scene(current: &Scene, u: &GroupState) -> (Scene, Rgb) {
    let step = u.params.rho_d.map(|r| if r < 0.5 { 0.2 } else { -0.2 });
    let mut p = u.params;
    p.rho_d += step;
    let mut moved = current.clone();
    let g = current.group_index(&u.name);
    for o in moved.objects.iter_mut().filter(|o| Some(o.group) == g) {
        o.material = p.material(u.level);
    }
    (moved, step)
}

/// The scene with its stray light moved by the step its cache derivative is measured along,
/// and the step (1 per channel: the light is linear in the stray radiance, and paths do not
/// depend on it, so any step gives the derivative).
pub fn moved_stray(current: &Scene) -> (Scene, Rgb) {
    let mut moved = current.clone();
    moved.stray_light += Rgb::ONE;
    (moved, Rgb::ONE)
}

/// The determined proposals of the last [`History::WINDOW`] global iterations, per unseen
/// group and channel, for an honest 1σ: each iteration's fit is noisy (its own cache samples)
/// and the seen groups move between iterations, so the reported σ is the larger of the
/// proposals' scatter and their mean σ (not divided by √n: the proposals share the photo and
/// the seen groups' fits, so they are not independent).
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct History {
    /// Per unseen group, per channel: (proposed ρd, its σ) of recent iterations, oldest first.
    runs: Vec<[Vec<(f32, f32)>; 3]>,
    /// Per unseen group, per channel: how many determined proposals there have been since a
    /// seen group last changed its model ([`History::restart_steps`]).
    #[serde(default)]
    count: Vec<[u32; 3]>,
    /// Per unseen group, per channel: the running estimate, not clipped to ρd ≤ 1 (the scene
    /// gets it clipped). Noisy proposals around a white surface's 1 would, clipped, average
    /// below it.
    #[serde(default)]
    state: Vec<[Option<f32>; 3]>,
    /// Per unseen group (and the stray light): the sum of the values the seen groups' fits saw
    /// since their averages last started afresh ([`History::restart_drift`]), and how many
    /// iterations that is; [`update`] measures the drift from their mean.
    #[serde(default)]
    seen_sum: Vec<[f64; 3]>,
    #[serde(default)]
    seen_n: u32,
}

impl History {
    pub const WINDOW: usize = 4;
    /// See [`History::is_outlier`].
    pub const OUTLIER_SIGMAS: f32 = 5.0;

    fn add(&mut self, j: usize, c: usize, rho: f32, sigma: f32) {
        if self.runs.len() <= j {
            self.runs.resize(j + 1, Default::default());
        }
        if self.count.len() <= j {
            self.count.resize(j + 1, [0; 3]);
        }
        self.count[j][c] += 1;
        let r = &mut self.runs[j][c];
        r.push((rho, sigma));
        if r.len() > Self::WINDOW {
            r.remove(0);
        }
    }

    /// The fraction of the way to its newest proposal group `j` moves in channel `c`: `first`
    /// for the first three, then shrinking as 3/n down to a quarter of it, so that once near
    /// its value the estimate averages the proposals' noise over iterations (stochastic
    /// approximation) instead of following each one.
    fn step(&self, j: usize, c: usize, first: f32) -> f32 {
        let n = self.count.get(j).map_or(1, |n| n[c].max(1)) as f32;
        first * (3.0 / n).clamp(0.25, 1.0)
    }

    /// Whether a proposal `rho` ± `sigma` for group `j` in channel `c` lies more than
    /// [`Self::OUTLIER_SIGMAS`] of its own σ from the running estimate, once that estimate has
    /// had three determined proposals since the last change of model (before, the estimate is
    /// still on its way and may be far from the truth). Such a proposal is not used: the
    /// tiles' solve can put one channel of a weakly lit unseen group at its bound with a
    /// formal σ under the limit (figure6, seed 1, one iteration: the ceiling's blue 0 ± 0.08
    /// against 0.99 ± 0.02, which moved it to 0.69 and every seen group by up to 0.05).
    fn is_outlier(&self, j: usize, c: usize, rho: f32, sigma: f32) -> bool {
        let settled = self.count.get(j).is_some_and(|n| n[c] >= 3);
        settled
            && self
                .state(j, c)
                .is_some_and(|x| (rho - x).abs() > Self::OUTLIER_SIGMAS * sigma)
    }

    /// The running estimate of group `j` in channel `c` (None before the first).
    fn state(&self, j: usize, c: usize) -> Option<f32> {
        self.state.get(j).and_then(|s| s[c])
    }

    fn set_state(&mut self, j: usize, c: usize, v: f32) {
        if self.state.len() <= j {
            self.state.resize(j + 1, [None; 3]);
        }
        self.state[j][c] = Some(v);
    }

    /// Starts every step's decay afresh ([`History::step`]), when a seen group changed its
    /// model: the proposals so far were made against the old one, and the estimate's value
    /// moved with it; the first steps to the new one are full again, or an estimate whose
    /// steps had already shrunk would stop short of it.
    pub fn restart_steps(&mut self) {
        self.count.iter_mut().for_each(|n| *n = [0; 3]);
    }

    /// The seen groups' averages start afresh: the drift is measured from the values the fits
    /// from the next iteration on see.
    pub fn restart_drift(&mut self) {
        self.seen_sum.clear();
        self.seen_n = 0;
    }

    /// Records the values this iteration's fits saw.
    fn saw(&mut self, values: &[Rgb]) {
        self.seen_sum.resize(values.len(), [0.0; 3]);
        for (s, v) in self.seen_sum.iter_mut().zip(values) {
            for c in 0..3 {
                s[c] += v[c] as f64;
            }
        }
        self.seen_n += 1;
    }

    /// The mean of the values the fits since the last restart saw, for tracked unknown `j`.
    fn mean_seen(&self, j: usize) -> Option<Rgb> {
        let s = self.seen_sum.get(j).filter(|_| self.seen_n > 0)?;
        let n = self.seen_n as f64;
        Some(Rgb::new(
            (s[0] / n) as f32,
            (s[1] / n) as f32,
            (s[2] / n) as f32,
        ))
    }

    /// The σ to report for group `j` in channel `c`; None before its first determined proposal.
    fn sigma(&self, j: usize, c: usize) -> Option<f32> {
        let r = self.runs.get(j).map(|r| &r[c]).filter(|r| !r.is_empty())?;
        let n = r.len() as f32;
        let mean = r.iter().map(|e| e.0).sum::<f32>() / n;
        let single = r.iter().map(|e| e.1).sum::<f32>() / n;
        let scatter = if r.len() > 1 {
            (r.iter().map(|e| (e.0 - mean).powi(2)).sum::<f32>() / (n - 1.0)).sqrt()
        } else {
            0.0
        };
        Some(scatter.max(single))
    }
}

/// What [`update`] found: the unseen groups' estimates, the stray light's (when fitted), and
/// how far they moved. A move is measured by the relative change of the seen light it makes
/// (for a group, its influence times the relative change of its ρd), so that a change that is
/// noise to the seen groups' fits does not count as news for them.
#[derive(Clone, Debug, Default)]
pub struct Estimates {
    pub groups: Vec<UnseenEstimate>,
    pub stray: Option<StrayEstimate>,
    /// The largest move in this iteration.
    pub moved: f32,
    /// The largest difference between the values now and the mean of the values the seen
    /// groups' fits saw since [`History::restart_drift`]: how stale their averages are.
    pub drift: f32,
}

/// The stray light is determined in a channel when its 1σ adds at most this share of the seen
/// groups' light there.
pub const STRAY_MAX_SHARE: f64 = 0.005;

/// The largest running estimate: above 1 only so that noise around a white surface averages
/// to 1 (see `History::state`).
const RHO_MAX: f32 = 1.5;

/// The smallest ρd an estimate moves an unseen group to: its shares vanish at 0, and the next
/// iteration could not measure it again.
const RHO_FLOOR: f32 = 0.01;

/// Re-estimates every unseen group's ρd from the seen groups' `shares` (one per seen group
/// whose model [`shares`] reads, from this iteration's caches), updates `states` and `current`,
/// and returns the estimates and how far they moved ([`Estimates`]). When `frozen` nothing
/// moves (the proposals still count towards the σ): in the last global iterations the seen
/// groups' averages are made with the values as they are.
pub fn update(
    current: &mut Scene,
    states: &mut [GroupState],
    shares: &[GroupShares],
    tracked: &[usize],
    opts: &UnseenOptions,
    history: &mut History,
    frozen: bool,
) -> Estimates {
    let k = tracked.len();
    if k == 0 {
        return Estimates::default();
    }
    let stray = |u: usize| u == STRAY_LIGHT;
    let rho0: Vec<Rgb> = tracked
        .iter()
        .map(|&u| {
            if stray(u) {
                current.stray_light
            } else {
                states[u].params.rho_d
            }
        })
        .collect();
    history.saw(&rho0);
    // The bounds of the running estimate: a reflectance's, or a radiance's (any S ≥ 0).
    let bounds = |u: usize| {
        if stray(u) {
            (0.0, f32::INFINITY)
        } else {
            (RHO_FLOOR, RHO_MAX)
        }
    };
    let shares_rho0 = &rho0;
    let mut proposal = rho0.clone();
    let mut sigma = vec![Rgb::splat(f32::INFINITY); k];
    // Without the stray light's column, for a channel where it cannot be told apart (a closed
    // room: no ray leaves it), so that the unseen groups are still estimated.
    let stray_at = tracked.iter().position(|&u| stray(u));
    let without: Option<Vec<GroupShares>> = stray_at.map(|j| drop_column(shares, j));
    for c in 0..3 {
        let (set, cols, solved): (&[GroupShares], Vec<usize>, _) =
            match (solve_channel(shares, k, c, Tiles::All), &without) {
                (Some(r), _) => (shares, (0..k).collect(), Some(r)),
                (None, Some(w)) => {
                    let cols: Vec<usize> = (0..k).filter(|&j| Some(j) != stray_at).collect();
                    let r = solve_channel(w, cols.len(), c, Tiles::All);
                    (w, cols, r)
                }
                (None, None) => continue,
            };
        let Some((delta, s)) = solved else {
            continue;
        };
        let halves = [
            solve_channel(set, cols.len(), c, Tiles::Even),
            solve_channel(set, cols.len(), c, Tiles::Odd),
        ];
        for (i, &j) in cols.iter().enumerate() {
            let split = match &halves {
                [Some(a), Some(b)] => 0.5 * (a.0[i] - b.0[i]).abs(),
                _ => f64::INFINITY,
            };
            let hi = bounds(tracked[j]).1 as f64;
            proposal[j][c] = (rho0[j][c] as f64 + delta[i]).clamp(0.0, hi) as f32;
            sigma[j][c] = s[i].max(split) as f32;
        }
    }
    // d ln L / d ln ρ_u over the seen tiles: how much of their light follows u's ρd.
    let influence: Vec<f32> = (0..k)
        .map(|j| {
            let (mut num, mut den) = (0.0f64, 0.0f64);
            for g in shares {
                for t in &g.tiles {
                    for c in 0..3 {
                        let (rd, rs) = (g.rho_d[c] as f64, g.rho_s[c] as f64);
                        let r = shares_rho0[j][c] as f64;
                        num += r * (rd * mean(&t.du[j], c) + rs * mean(&t.su[j], c));
                        den += rd * mean(&t.d, c) + rs * mean(&t.s, c);
                    }
                }
            }
            if den > 0.0 {
                (num / den) as f32
            } else {
                0.0
            }
        })
        .collect();
    let mean = scene_mean_albedo(current, states);
    let mut out = Estimates::default();
    for (j, &u) in tracked.iter().enumerate() {
        // Per channel: a determined proposal moves ρd part of the way there (the model is
        // linear in ρd_u, the light is not: a path can bounce on u more than once); a channel
        // determined before but not now (the seen groups' fits moved, a level changed) stays;
        // one never determined takes the scene's mean albedo (the stray light: stays as given).
        let (lo, hi) = bounds(u);
        // The stray light's share of the seen light per unit, per channel (zero for a group).
        let unit: [f64; 3] = std::array::from_fn(|c| {
            if stray(u) {
                per_unit(shares, j, c)
            } else {
                0.0
            }
        });
        // The largest 1σ that determines the value: for the stray light, the σ whose light is
        // STRAY_MAX_SHARE of the seen light.
        let limit = |c: usize| {
            if !stray(u) {
                opts.max_sigma
            } else if unit[c] > 0.0 {
                (STRAY_MAX_SHARE / unit[c]) as f32
            } else {
                0.0
            }
        };
        let mut value = rho0[j];
        let mut sigma_j = sigma[j];
        let mut estimated = true;
        for c in 0..3 {
            let max_sigma = limit(c);
            let outlier = history.is_outlier(j, c, proposal[j][c], sigma[j][c]);
            if outlier {
                tracing::debug!(
                    "unseen {u}: channel {c}'s proposal {} ± {} ignored (an outlier)",
                    proposal[j][c],
                    sigma[j][c]
                );
            }
            let now = sigma[j][c] <= max_sigma && !outlier;
            if now {
                history.add(j, c, proposal[j][c], sigma[j][c]);
            }
            // A weaker proposal still carries information once the channel has an estimate:
            // it moves it by its precision relative to a determined one's, (max_sigma / σ)², so
            // one lucky determined proposal cannot freeze a poorly determined channel. A
            // proposal at a bound of the solve is not an estimate.
            let inside = proposal[j][c] > 0.0 && proposal[j][c] < hi;
            let weight = if now {
                1.0
            } else if inside && !outlier && sigma[j][c].is_finite() && history.state(j, c).is_some()
            {
                (max_sigma / sigma[j][c]).powi(2)
            } else {
                0.0
            };
            if weight > 0.0 && !frozen {
                let step = history.step(j, c, opts.damping) * weight;
                let from = history.state(j, c).unwrap_or(rho0[j][c]);
                let to = (from + (proposal[j][c] - from) * step).clamp(lo, hi);
                history.set_state(j, c, to);
                value[c] = if stray(u) { to } else { to.min(1.0) };
            }
            match history.sigma(j, c) {
                Some(s) => sigma_j[c] = if now { s } else { s.max(sigma[j][c].min(1.0)) },
                None => {
                    if !frozen && !stray(u) {
                        value[c] = mean[c];
                    }
                    estimated = false;
                }
            }
        }
        let value = value.max(Rgb::splat(lo));
        tracing::debug!(
            "unseen {u}: from {} proposed {} ± {}, now {value} (estimated: {estimated})",
            rho0[j],
            proposal[j],
            sigma[j],
        );
        let sigma_out = sigma_j
            .to_array()
            .map(|s| if s.is_finite() { s } else { -1.0 });
        // The relative change of the seen light that moving from `from` to `value` makes.
        let seen_change = |from: Rgb| {
            (0..3)
                .map(|c| {
                    let d = (value[c] - from[c]).abs();
                    if stray(u) {
                        d * unit[c] as f32
                    } else {
                        influence[j] * d / from[c].max(RHO_FLOOR)
                    }
                })
                .fold(0.0f32, f32::max)
        };
        let before = rho0[j];
        let seen = history.mean_seen(j).unwrap_or(before);
        out.moved = out.moved.max(seen_change(before));
        out.drift = out.drift.max(seen_change(seen));
        if stray(u) {
            current.stray_light = value;
            out.stray = Some(StrayEstimate {
                radiance: value.to_array(),
                sigma: sigma_out,
                estimated,
                share: influence[j],
                open: unit.iter().any(|&x| x > 0.0),
            });
            continue;
        }
        let (rule, remedy) = if estimated {
            (
                Rule::Estimated,
                "To pin it down, give it a visible surface's group if it shares its paint, or \
                 mark it fixed with a measured value."
                    .to_string(),
            )
        } else {
            (
                Rule::SceneMean,
                format!(
                    "Too little of its light reaches the seen pixels (1σ above {} in some \
                     channel): give it a visible surface's group if it shares its paint, or mark \
                     it fixed with a measured value.",
                    opts.max_sigma
                ),
            )
        };
        states[u].params.rho_d = value;
        for o in current.objects.iter_mut().filter(|o| o.group == u) {
            o.material = states[u].params.material(states[u].level);
        }
        let e = UnseenEstimate {
            group: u,
            rule,
            rho_d: value.to_array(),
            sigma: sigma_out,
            influence: influence[j],
            remedy,
        };
        states[u].note = Some(e.describe());
        out.groups.push(e);
    }
    out
}

/// `shares` without tracked parameter `j`'s derivatives.
fn drop_column(shares: &[GroupShares], j: usize) -> Vec<GroupShares> {
    let mut out = shares.to_vec();
    for g in out.iter_mut() {
        for t in g.tiles.iter_mut() {
            t.du.remove(j);
            t.su.remove(j);
        }
    }
    out
}

/// Per unit of tracked parameter `j` in channel `c`, the share of the seen tiles' light it
/// adds: Σ (ρd ∂D/∂x + ρs ∂S/∂x) / Σ (ρd D + ρs S).
fn per_unit(shares: &[GroupShares], j: usize, c: usize) -> f64 {
    let (mut num, mut den) = (0.0f64, 0.0f64);
    for g in shares {
        let (rd, rs) = (g.rho_d[c] as f64, g.rho_s[c] as f64);
        for t in &g.tiles {
            num += rd * mean(&t.du[j], c) + rs * mean(&t.su[j], c);
            den += rd * mean(&t.d, c) + rs * mean(&t.s, c);
        }
    }
    if den > 0.0 {
        num / den
    } else {
        0.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::sampler::mix64;

    /// A uniform draw in [−1, 1) from a seed and an index.
    fn noise(seed: u64, i: u64) -> f32 {
        2.0 * ((mix64(mix64(seed) ^ i) >> 40) as f32 / (1u64 << 24) as f32) - 1.0
    }

    /// Three seen groups (one with a specular term) whose tiles receive light from two unseen
    /// groups with derivatives of different shapes across the tiles. The photo is rendered with
    /// the unseen groups' ρd moved by `delta` and with the seen groups' true reflectances; the
    /// groups start from wrong ones (as after fits against the current unseen values), and each
    /// half of the cache carries its own noise of relative size `cache_noise`.
    fn synthetic(
        delta: [f64; 2],
        photo_noise: f32,
        cache_noise: f32,
        seed: u64,
        gain: f32,
    ) -> Vec<GroupShares> {
        let truth = [(0.5f32, 0.0f32), (0.3, 0.4), (0.7, 0.0)];
        (0..3)
            .map(|g| {
                let tiles = (0..48u64)
                    .map(|i| {
                        let x = i as f32 / 47.0;
                        let id = (g as u64) << 32 | i;
                        let jitter =
                            |h: u64, v: f32| v * (1.0 + cache_noise * noise(seed ^ 0x5eed ^ h, id));
                        let d = 0.3 + 0.2 * x + 0.05 * g as f32;
                        let s = if g == 1 {
                            0.2 + 0.3 * (1.0 - x) * (1.0 - x)
                        } else {
                            0.0
                        };
                        let du = [
                            gain * 0.1 * (1.0 + x),
                            gain * 0.05 * (2.0 - x * x + g as f32 * x),
                        ];
                        let su = [if g == 1 { gain * 0.05 * x } else { 0.0 }, 0.0];
                        let (rd, rs) = truth[g];
                        let model = |t: [f64; 2]| {
                            rd * (d + t[0] as f32 * du[0] + t[1] as f32 * du[1])
                                + rs * (s + t[0] as f32 * su[0] + t[1] as f32 * su[1])
                        };
                        let photo = model(delta) * (1.0 + photo_noise * noise(seed, id));
                        let pair = |v: f32| [Rgb::splat(jitter(1, v)), Rgb::splat(jitter(2, v))];
                        TileShare {
                            photo: Rgb::splat(photo),
                            d: pair(d),
                            s: pair(s),
                            du: du.iter().map(|&v| pair(v)).collect(),
                            su: su.iter().map(|&v| pair(v)).collect(),
                        }
                    })
                    .collect();
                GroupShares {
                    group: g,
                    diffuse: true,
                    specular: truth[g].1 > 0.0,
                    rho_d: Rgb::splat(truth[g].0 * 1.04),
                    rho_s: Rgb::splat(truth[g].1 * 0.95),
                    tiles,
                }
            })
            .collect()
    }

    #[test]
    fn recovers_the_unseen_changes_while_refitting_the_seen_groups() {
        let groups = synthetic([0.3, -0.4], 0.0, 0.0, 1, 1.0);
        let (delta, s) = solve_channel(&groups, 2, 0, Tiles::All).unwrap();
        assert!(
            (delta[0] - 0.3).abs() < 1e-4 && (delta[1] + 0.4).abs() < 1e-4,
            "{delta:?}"
        );
        assert!(s.iter().all(|&s| s < 1e-4), "{s:?}");
    }

    /// With noise on the photo and on the cache's halves, the truth lies within 4σ in every
    /// trial (σ as `update` takes it: the formula's or the halves' difference, the larger), and
    /// σ is not inflated: the spread of the estimates over trials is within a factor 2.5 of it.
    #[test]
    fn the_uncertainty_is_honest() {
        let mut errs = Vec::new();
        let mut sig = Vec::new();
        for seed in 0..40 {
            let groups = synthetic([0.3, -0.4], 0.02, 0.02, seed, 1.0);
            let (delta, s) = solve_channel(&groups, 2, 0, Tiles::All).unwrap();
            let halves =
                [Tiles::Even, Tiles::Odd].map(|h| solve_channel(&groups, 2, 0, h).unwrap().0);
            let sigma = s[0].max(0.5 * (halves[0][0] - halves[1][0]).abs());
            errs.push(delta[0] - 0.3);
            sig.push(sigma);
            assert!((delta[0] - 0.3).abs() < 4.0 * sigma, "{delta:?} ± {sigma}");
        }
        let rms = (errs.iter().map(|e| e * e).sum::<f64>() / errs.len() as f64).sqrt();
        let mean_sigma = sig.iter().sum::<f64>() / sig.len() as f64;
        assert!(
            rms < 2.5 * mean_sigma && mean_sigma < 2.5 * rms,
            "rms {rms} σ {mean_sigma}"
        );
    }

    /// An unseen group whose light barely reaches the seen tiles has a large σ (so the caller
    /// uses the scene default); one whose light does not reach them at all is not identifiable.
    #[test]
    fn a_weak_unknown_is_reported_undetermined() {
        let groups = synthetic([0.3, -0.4], 0.02, 0.02, 3, 1e-3);
        let (_, s) = solve_channel(&groups, 2, 0, Tiles::All).unwrap();
        assert!(s[0] > 0.5 && s[1] > 0.5, "{s:?}");
        let mut flat = groups.clone();
        for g in &mut flat {
            for t in &mut g.tiles {
                t.du = vec![[Rgb::ZERO; 2]; 2];
                t.su = vec![[Rgb::ZERO; 2]; 2];
            }
        }
        assert!(solve_channel(&flat, 2, 0, Tiles::All).is_none());
    }

    /// The probe rule: a Lambert-only cache skips an unseen group that gave its group's last
    /// cache under 0.5% of its light per unit ρd (a dark estimate counts as 0.05), and probes
    /// before any cache, or wherever a lobe or a mirror reflection may read the group.
    #[test]
    fn an_unseen_group_is_probed_only_where_its_light_can_inform_the_fit() {
        use crate::fit::cache::CacheNeeds;
        use crate::fit::group::{GroupState, Status};
        use crate::fit::params::GroupParams;
        let mut seen = GroupState::new("wall", Status::Confirmed, GroupParams::default());
        let mut unseen = GroupState::new("ceiling", Status::Default, GroupParams::default());
        unseen.params.rho_d = Rgb::new(0.8, 0.6, 0.4);
        let diffuse = CacheNeeds::default();
        assert!(worth_probing(&seen, diffuse, 1, &unseen), "no cache yet");
        // 0.5% per unit of the smallest channel (0.4): the bound is 0.002.
        seen.lit_by = vec![0.0, 0.0021];
        assert!(worth_probing(&seen, diffuse, 1, &unseen));
        seen.lit_by = vec![0.0, 0.0019];
        assert!(!worth_probing(&seen, diffuse, 1, &unseen));
        for needs in [
            CacheNeeds {
                lobe_samples: true,
                ..diffuse
            },
            CacheNeeds {
                mirror: true,
                ..diffuse
            },
        ] {
            assert!(worth_probing(&seen, needs, 1, &unseen), "{needs:?}");
        }
        // A near-black estimate must not hide an influence: ρd is taken as at least 0.05.
        unseen.params.rho_d = Rgb::splat(0.0);
        seen.lit_by = vec![0.0, 0.0003];
        assert!(worth_probing(&seen, diffuse, 1, &unseen));
        seen.lit_by = vec![0.0, 0.0002];
        assert!(!worth_probing(&seen, diffuse, 1, &unseen));
    }

    /// A derivative proportional to a group's own light is that group's reflectance, not the
    /// unknown's: it cannot be identified.
    #[test]
    fn a_share_shaped_like_the_seen_light_is_not_identifiable() {
        let mut groups = synthetic([0.0, 0.0], 0.0, 0.0, 4, 1.0);
        groups.truncate(1);
        for t in &mut groups[0].tiles {
            t.du = vec![[t.d[0] * 0.3, t.d[1] * 0.3]];
            t.su = vec![[Rgb::ZERO; 2]];
        }
        assert!(solve_channel(&groups, 1, 0, Tiles::All).is_none());
    }

    /// The values the fits saw since the last restart are averaged; a restart starts afresh.
    #[test]
    fn the_drift_is_measured_from_the_mean_the_averaged_fits_saw() {
        let mut h = History::default();
        assert_eq!(h.mean_seen(0), None);
        h.restart_drift();
        assert_eq!(h.mean_seen(0), None);
        for v in [0.90, 0.94, 0.98] {
            h.saw(&[Rgb::splat(v)]);
        }
        let m = h.mean_seen(0).unwrap();
        assert!((m.x - 0.94).abs() < 1e-6 && (m.z - 0.94).abs() < 1e-6);
        assert_eq!(h.mean_seen(1), None);
        h.restart_drift();
        assert_eq!(h.mean_seen(0), None);
        h.saw(&[Rgb::splat(0.98)]);
        assert!((h.mean_seen(0).unwrap().y - 0.98).abs() < 1e-6);
    }

    /// A proposal far from the running estimate, in its own σ, is ignored once the estimate has
    /// had three determined proposals since the last change of model, and not before.
    #[test]
    fn a_far_proposal_is_an_outlier_only_once_the_estimate_has_settled() {
        let mut h = History::default();
        let far = (0.0, 0.08); // 12σ below the estimate
        h.set_state(0, 2, 0.99);
        for _ in 0..2 {
            h.add(0, 2, 0.99, 0.02);
        }
        // Two proposals: still on its way.
        assert!(!h.is_outlier(0, 2, far.0, far.1));
        h.add(0, 2, 0.99, 0.02);
        assert!(h.is_outlier(0, 2, far.0, far.1));
        // Within five of its own σ, or in another channel, it counts.
        assert!(!h.is_outlier(0, 2, 0.99 - 4.9 * 0.08, 0.08));
        assert!(!h.is_outlier(0, 1, far.0, far.1));
        // After a change of model the estimate is on its way again.
        h.restart_steps();
        assert!(!h.is_outlier(0, 2, far.0, far.1));
    }

    /// The steps shrink as determined proposals accumulate, per channel, and are full again
    /// once a seen group changed its model.
    #[test]
    fn the_steps_shrink_with_proposals_and_start_afresh_on_a_new_model() {
        let mut h = History::default();
        assert_eq!(h.step(0, 0, 0.8), 0.8);
        for _ in 0..6 {
            h.add(0, 0, 0.3, 0.01);
        }
        h.add(0, 1, 0.3, 0.01);
        assert!((h.step(0, 0, 0.8) - 0.8 * 0.5).abs() < 1e-6);
        assert_eq!(h.step(0, 1, 0.8), 0.8);
        h.restart_steps();
        assert_eq!(h.step(0, 0, 0.8), 0.8);
        // The σ still reads the proposals made before.
        assert_eq!(h.sigma(0, 0), Some(0.01));
    }

    /// The model is linear in the samples' radiance, so a tracked group whose derivative is
    /// the cache's own light (dc = c, ∂D = D) has ∂S = S and ∂D = D in every tile, at the
    /// Ward levels (their own lobe sums) and at levels 8–10 (the objective's evaluation), the
    /// coat's diffuse term included: the stray light is estimated at every level.
    #[test]
    fn derivatives_at_every_lobe_level_are_the_model_on_the_derivative_light() {
        use crate::fit::cache::{synthetic_cache, UnseenShares};
        use crate::fit::params::GroupParams;
        use crate::scene::Distribution;
        let mut cache = synthetic_cache(24, 8, 4, 5, |_, _| Rgb::splat(0.3));
        for (i, p) in cache.pixels.iter_mut().enumerate() {
            p.photo = Rgb::splat(0.3 + 0.01 * i as f32);
        }
        cache.unseen = Some(UnseenShares {
            groups: vec![7],
            d_half: cache.pixels.iter().map(|p| p.d_half).collect(),
            dc: cache.samples.iter().map(|s| s.c).collect(),
            mirror_half: cache.pixels.iter().map(|p| p.mirror_half).collect(),
            probed: vec![true; cache.pixels.len()],
        });
        for level in [
            Level::Isotropic,
            Level::Anisotropic,
            Level::Microfacet,
            Level::AnisotropicMicrofacet,
            Level::Plastic,
        ] {
            let mut st = GroupState::new("g", Status::Confirmed, GroupParams::default());
            st.level = level;
            st.params.rho_d = Rgb::splat(0.4);
            st.params.rho_s = Rgb::splat(0.1);
            st.params.alpha_x = 0.15;
            st.params.alpha_y = 0.25;
            st.params.distribution = Distribution::Beckmann;
            let sh = shares(&cache, 0, &st, WardVariant::Ward1992)
                .unwrap_or_else(|| panic!("{level:?}: no shares"));
            assert!(!sh.tiles.is_empty());
            for t in &sh.tiles {
                for h in 0..2 {
                    let (ds, dd) = (t.su[0][h] - t.s[h], t.du[0][h] - t.d[h]);
                    let tol = 1e-4 * (1.0 + t.s[h].max_element() + t.d[h].max_element());
                    assert!(ds.abs().max_element() < tol, "{level:?}: {ds:?}");
                    assert!(dd.abs().max_element() < tol, "{level:?}: {dd:?}");
                    assert!(t.s[h].max_element() > 0.0, "{level:?}: no specular term");
                }
            }
        }
    }
}
