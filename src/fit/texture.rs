//! Level 7, the radiosity texture (§5.2 and Algorithms 1–2 of the notes), with an optional
//! uniform Ward lobe on top (a varnish).
//!
//! A texture cut from the photo holds the light that fell on it; rendered lit again it is lit
//! twice. The notes correct it iteratively: each global iteration multiplies the texture by the
//! ratio of the photo's texture to the synthetic image's. Here that ratio is taken on the
//! group's incident-radiance cache instead of on a noisy re-render: with the texel rows of D
//! (`cache::TexelRows`), a pixel is L_p = Σ_t A_pt ρ_t + ρs S_p, linear in the texels, and the
//! notes' update becomes the multiplicative least-squares iteration (ISRA, Daube-Witherspoon &
//! Muehllehner 1986)
//!
//!   ρ_t ← ρ_t · Σ_p A_pt (photo_p − ρs S_p) / Σ_p A_pt L_p(ρ),
//!
//! which keeps ρ ≥ 0 and converges to the non-negative least-squares texture, the irradiance
//! divided out exactly. The global iterations then carry the texture's own interreflections to
//! the rest of the scene and back.
//!
//! The lobe is fitted first with a uniform ρd (the texture's variation is then only noise to it,
//! averaged away by the error's tiles), then the texture under it, then the lobe again on what
//! the texture leaves, then the texture again. In one image a texture fitted texel by texel
//! could absorb any highlight, so the evidence for a lobe is that a uniform Ward level earned
//! its place on held-out tiles, and `hierarchy.rs` keeps it over the bare texture unless the
//! bare one fits significantly better.
//!
//! Texels seen by no pixel (a book's back, texels between a sub-sampled cache's pixels) are
//! marked unseen and filled by pull–push from the seen texels of the same chart, fading to the
//! mean of its object's seen texels away from them, or to the chart's own repeating print where
//! its seen texels repeat (`periodic.rs`: a papered wall seen in a strip); a chart seen nowhere
//! gets that mean (or the group's).

use super::cache::{GroupCache, TexelRows};
use super::error::{tiled_error, ErrorStats, PixelTerms};
use super::fitter::{fit_level, spec_of, LevelFit};
use super::level::Level;
use super::objective::{pixel_specs, PixelSpec};
use super::periodic;
use super::params::GroupParams;
use crate::math::{Rgb, Vec2};
use crate::scene::atlas::Atlas;
use crate::scene::{Scene, WardVariant};

/// A texel counts as seen when its weight in the photo is at least this fraction of the median
/// weight of the texels that have any: a texel clipped by the group's edge is fitted from the
/// little light the photo shows of it, and below this its value would be mostly noise.
pub const SEEN_FRACTION: f32 = 0.1;

/// The weights of the smoothness penalty (relative to each texel's own data weight, `solve`)
/// among which each textured group's is chosen by cross-validation ([`choose_smoothing`]).
/// Less leaves stripes where pixel and texel grids beat and lets the photo's noise through,
/// more blurs edges, and which wins depends on how the texture's detail compares with the
/// photo's pixels, so no one weight suits every texture (the poster scene's full-size poster
/// asks for 0.003, the facing-mirrors room's painting for 0.1).
pub const SMOOTHING_CHOICES: [f32; 6] = [0.001, 0.003, 0.01, 0.03, 0.1, 0.3];

/// The weights a climb's texture trial chooses among (every other of [`SMOOTHING_CHOICES`]).
pub const TRIAL_SMOOTHING_CHOICES: [f32; 3] = [0.003, 0.03, 0.3];

/// The folds of [`choose_smoothing`]'s cross-validation: each fit leaves out one pixel in this
/// many, which keeps the fits close to the whole cache's (every texel still seen by most of its
/// pixels) while every pixel is predicted once.
pub const FOLDS: usize = 4;

/// ISRA iterations per global iteration (warm-started from the previous texture).
pub const ITERATIONS: usize = 40;

/// A group's texture: its texels (atlas layout) and which of them the photo sees.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct TextureState {
    /// The level whose specular part lies on top of the texture: diffuse (none), isotropic or
    /// anisotropic (a varnish, with the group's ρs, α, θ).
    pub base: super::level::Level,
    pub width: usize,
    pub height: usize,
    /// World units per texel.
    pub texel: f32,
    pub texels: Vec<Rgb>,
    pub seen: Vec<bool>,
    /// Texels inside the charts (the rest are the gaps between them).
    pub charted: usize,
    /// The smoothness weight the texture was solved with ([`choose_smoothing`]).
    #[serde(default = "default_smoothing")]
    pub smoothing: f32,
    /// Whether that weight was chosen on a cache of the textured level (whose pixels draw
    /// [`super::recovery::run::TEXTURED_SAMPLES`] times the samples) and is kept from then on; the
    /// climb's is chosen on the uniform level's cache.
    #[serde(default)]
    pub smoothing_settled: bool,
    /// When this fit chose the weight: per weight of [`SMOOTHING_CHOICES`], its held-out error
    /// relative to the chosen one's (empty when the weight was kept from before).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub held_out: Vec<f32>,
    /// Unseen texels filled from a repeating print of their chart's seen texels
    /// (`periodic.rs`) rather than their object's mean.
    #[serde(default)]
    pub repeated: usize,
}

/// What a checkpoint written before the smoothing was chosen per group was solved with.
fn default_smoothing() -> f32 {
    0.03
}

impl TextureState {
    pub fn seen_count(&self) -> usize {
        self.seen.iter().filter(|&&s| s).count()
    }

    /// Mean of the seen texels.
    pub fn mean(&self) -> Rgb {
        let (sum, n) = self
            .texels
            .iter()
            .zip(&self.seen)
            .filter(|x| *x.1)
            .fold((Rgb::ZERO, 0usize), |(a, n), (t, _)| (a + *t, n + 1));
        if n == 0 {
            Rgb::ZERO
        } else {
            sum / n as f32
        }
    }
}

/// ISRA iterations for a texture solved from a uniform start (a climb to level 7).
pub const FIRST_ITERATIONS: usize = 150;

/// The texel size of a group's atlas: one texel per photo pixel at the group's median pixel
/// footprint. A pixel's footprint is the longer side of the parallelogram its two neighbours'
/// rays cut out of the tangent plane at its hit (the longer side: where the surface is seen
/// obliquely, texels as fine as the shorter side would outnumber the pixels along the other, and
/// the texels the photo cannot tell apart would alternate freely); the median is over (at most
/// 4096 of) the group's usable pixels.
pub fn footprint(scene: &Scene, pixels: &[usize]) -> Option<f32> {
    let cam = &scene.camera;
    let w = cam.width as usize;
    let step = pixels.len().div_ceil(4096).max(1);
    let mut sizes: Vec<f32> = pixels
        .iter()
        .step_by(step)
        .filter_map(|&i| {
            let (x, y) = ((i % w) as f32 + 0.5, (i / w) as f32 + 0.5);
            let hit = scene.intersect(&cam.ray(Vec2::new(x, y)), f32::INFINITY)?;
            let on_plane = |fx: f32, fy: f32| {
                let r = cam.ray(Vec2::new(fx, fy));
                let dn = r.d.dot(hit.ng);
                (dn.abs() > 1e-6).then(|| r.o + r.d * ((hit.p - r.o).dot(hit.ng) / dn))
            };
            let (a, b) = (on_plane(x + 1.0, y)?, on_plane(x, y + 1.0)?);
            let side = (a - hit.p).length().max((b - hit.p).length());
            (side.is_finite() && side > 0.0).then_some(side)
        })
        .collect();
    if sizes.is_empty() {
        return None;
    }
    sizes.sort_by(f32::total_cmp);
    Some(sizes[sizes.len() / 2])
}

/// The model's radiance per cached pixel for a uniform level's parameters.
pub fn uniform_model(
    cache: &GroupCache,
    level: Level,
    params: &GroupParams,
    variant: WardVariant,
) -> Vec<Rgb> {
    uniform_parts(cache, level, params, variant).model
}

/// A uniform level's model per cached pixel ([`uniform_parts`]).
pub struct UniformParts {
    /// The model's radiance.
    pub model: Vec<Rgb>,
    /// Its specular part ρs·S.
    pub spec: Vec<Rgb>,
    /// The radiance on each half of the pixel's samples alone (each an estimate of the whole):
    /// two estimates whose noise is independent.
    pub halves: [Vec<Rgb>; 2],
}

/// [`uniform_model`] with its specular part and its halves.
pub fn uniform_parts(
    cache: &GroupCache,
    level: Level,
    params: &GroupParams,
    variant: WardVariant,
) -> UniformParts {
    let specs = pixel_specs(cache, spec_of(level, params), variant, false);
    let (rho_d, rho_s) = match level {
        Level::PerfectSpecular => (Rgb::ZERO, Rgb::ONE),
        _ => (params.rho_d, params.rho_s),
    };
    let n = cache.pixels.len();
    let mut out = UniformParts {
        model: Vec::with_capacity(n),
        spec: Vec::with_capacity(n),
        halves: [Vec::with_capacity(n), Vec::with_capacity(n)],
    };
    for (p, s) in cache.pixels.iter().zip(&specs) {
        let t = super::objective::terms(p, s, rho_d, rho_s);
        out.model.push(t.syn);
        out.spec.push(rho_s * s.s);
        for h in 0..2 {
            out.halves[h].push(t.halves[h]);
        }
    }
    out
}

/// The radiance of `texture` (with its lobe `lobe` on top) per cached pixel; None if the cache
/// has no texel rows.
pub fn textured_model(
    cache: &GroupCache,
    texture: &TextureState,
    lobe: &GroupParams,
    variant: WardVariant,
) -> Option<Vec<Rgb>> {
    let rows = cache.texels.as_ref()?;
    let (spec, _) = specular(cache, texture.base, lobe, variant);
    let n = texture.texels.len();
    if rows.rows.iter().any(|r| r.0 as usize >= n) {
        return None;
    }
    Some(
        (0..cache.pixels.len())
            .map(|p| {
                let [h0, h1] = model(rows, &texture.texels, p);
                h0 + h1 + spec[p]
            })
            .collect(),
    )
}

/// Fits level 7 on the cache: the `base` level's uniform lobe (none for diffuse), then the
/// texture under it from the `previous` texture or, on a climb, from the lobe fit's uniform
/// ρd. The smoothness weight is the previous one once settled, else chosen on this cache
/// ([`choose_smoothing`]; settled when there was a previous texture). The fit's ρd is the mean
/// of the seen texels (what a report or an exporter that cannot take the texture shows). None
/// if the cache has no texel rows.
pub fn fit_textured(
    cache: &GroupCache,
    atlas: &Atlas,
    base: Level,
    params: &GroupParams,
    previous: Option<&TextureState>,
    variant: WardVariant,
    trial: bool,
) -> Option<(LevelFit, TextureState)> {
    // Solved on the smoothed rows, judged on the rows as sampled (`TexelRows::scale`).
    let sampled = cache.texels.as_ref()?;
    let smoothed;
    let rows = if sampled.scale.is_empty() {
        sampled
    } else {
        smoothed = sampled.smoothed();
        &smoothed
    };
    let n = atlas.width * atlas.height;
    let (mut lobe, mut evals) = if base.is_ward() {
        let f = fit_level(cache, base, params, variant);
        (f.params, f.evals)
    } else {
        (
            GroupParams {
                rho_s: Rgb::ZERO,
                ..*params
            },
            0,
        )
    };
    let (mut spec, mut spec_half) = specular(cache, base, &lobe, variant);
    let uniform = vec![lobe.rho_d; n];
    let previous = previous.filter(|t| t.texels.len() == n);
    let (start, iterations) = match previous {
        Some(t) => (t.texels.clone(), ITERATIONS),
        None => (uniform.clone(), FIRST_ITERATIONS),
    };
    let charts = atlas.chart_rects();
    let (smoothing, held_out) = match previous {
        Some(t) if t.smoothing_settled || trial => (t.smoothing, Vec::new()),
        // A trial's weight from three choices on one fold: a sixth of the full choice's cost.
        // It decides only whether a texture earns its place; level 7's first fit chooses again.
        None if trial => {
            let (w, _) = choose_smoothing_among(
                cache,
                rows,
                &spec,
                &uniform,
                &charts,
                atlas.width,
                &TRIAL_SMOOTHING_CHOICES,
                1,
            );
            (w, Vec::new())
        }
        _ => choose_smoothing(cache, rows, &spec, &uniform, &charts, atlas.width),
    };
    let mut texels = solve(
        cache,
        rows,
        &spec,
        &start,
        iterations,
        &charts,
        atlas.width,
        smoothing,
    );
    if base.is_ward() {
        // One alternation: the lobe refitted on what the texture leaves (the photo minus the
        // texture's diffuse radiance: its ρd comes out near zero), then the texture under it.
        // The uniform fit's lobe absorbs part of the texture's contrast; this one does not.
        // The refit's texture is solved without the highlight's pixels
        // (`texture_without_highlight`): texels solved from them would hand the refit back the
        // lobe they were solved under. Unless the refitted lobe explains the highlight's
        // residual, that residual is the unsolved texels' error, not a highlight, and the lobe
        // is refitted on the whole texture instead.
        // The pixels copied, the samples shared; the texel rows are not needed for a lobe.
        let residual = |texels: &[Rgb]| {
            let mut rest = GroupCache {
                pixels: cache.pixels.clone(),
                samples: cache.samples.clone(),
                tiles: cache.tiles,
                width: cache.width,
                views: cache.views.clone(),
                ..Default::default()
            };
            for (p, px) in rest.pixels.iter_mut().enumerate() {
                let [h0, h1] = model(rows, texels, p);
                px.photo -= h0 + h1;
            }
            rest
        };
        let (without, hot) =
            texture_without_highlight(cache, rows, &spec, &texels, atlas, smoothing);
        let rest = residual(&without);
        let mut f = fit_level(&rest, base, &lobe, variant);
        let share = explained_share(&rest, &hot, base, &f.params, variant);
        if !(share >= HIGHLIGHT_EXPLAINED) {
            evals += f.evals;
            f = fit_level(&residual(&texels), base, &lobe, variant);
        }
        evals += f.evals;
        lobe = GroupParams {
            rho_d: lobe.rho_d,
            ..f.params
        };
        (spec, spec_half) = specular(cache, base, &lobe, variant);
        texels = solve(
            cache,
            rows,
            &spec,
            &texels,
            ITERATIONS,
            &charts,
            atlas.width,
            smoothing,
        );
    }
    let seen = seen_texels(&column_weights(sampled, n));
    let mut state = TextureState {
        base,
        width: atlas.width,
        height: atlas.height,
        texel: atlas.texel,
        texels: Vec::new(),
        seen,
        charted: charts.iter().map(|r| r[2] * r[3]).sum(),
        smoothing,
        smoothing_settled: previous.is_some() && !trial,
        held_out,
        repeated: 0,
    };
    state.texels = texels;
    let mean = state.mean();
    state.repeated = fill_unseen(atlas, &mut state.texels, &state.seen, mean);
    let st = error(cache, sampled, &state.texels, &spec, &spec_half);
    let fit = LevelFit {
        level: Level::Textured,
        params: GroupParams {
            rho_d: mean,
            ..lobe
        },
        error: st.error,
        noise_floor: st.noise_floor,
        halves: st.halves,
        cost: 0.0,
        evals: evals + iterations as u32,
    };
    Some((fit, state))
}

/// A pixel belongs to a varnish's highlight when the lobe gives at least this fraction of its
/// radiance (summed over the channels). Much lower and most of a varnished surface counts as
/// highlight (its lobe also reflects the room), leaving too few pixels to solve the texture
/// from.
pub const HIGHLIGHT_FRACTION: f32 = 0.1;

/// The least share of the highlight's residual (photo − the texture solved without it) that
/// the refitted lobe must explain for that refit to stand ([`explained_share`]). On the poster
/// scene's desk (a true varnish) it is 0.56–0.74; on the facing-mirrors room's book (a diffuse
/// texture whose uniform fit found a lobe in its detail) 0.007, and that refit gave the book a
/// false varnish (ρs 0.01–0.03) and cost it 2 dB.
pub const HIGHLIGHT_EXPLAINED: f32 = 0.25;

/// The texture solved (from `start`, the previous texture, under the lobe's radiance `spec`)
/// without the pixels where the lobe gives at least [`HIGHLIGHT_FRACTION`] of the radiance, and
/// which pixels those are.
///
/// Why: in one photo a free texel can absorb any lobe. Solved from the highlight's pixels under
/// a lobe too wide, the texels at its centre come out bright and those in its tails dark,
/// photo − texture is that same lobe again, and a refit returns it (on the poster scene's desk,
/// α +8.6%, moved by 0.0005 per alternation). Without those pixels, a texel that only the
/// highlight sees has no data term: its ISRA steps are the smoothness penalty's alone, each
/// moving it towards its neighbours' mean from the previous texture, so it relaxes towards its
/// surroundings instead of re-absorbing the current lobe, and over the global iterations the
/// lobe moves to the one the highlight's shape asks for. Those texels are not interpolated
/// from around the highlight: the grain interpolated across it is further off than the lobe.
fn texture_without_highlight(
    cache: &GroupCache,
    rows: &TexelRows,
    spec: &[Rgb],
    start: &[Rgb],
    atlas: &Atlas,
    smoothing: f32,
) -> (Vec<Rgb>, Vec<bool>) {
    let sum = |c: Rgb| c.x + c.y + c.z;
    let mut without = rows.clone();
    let hot: Vec<bool> = cache
        .pixels
        .iter()
        .zip(spec)
        .map(|(px, &s)| sum(s) >= HIGHLIGHT_FRACTION * sum(px.photo))
        .collect();
    for (p, _) in hot.iter().enumerate().filter(|h| *h.1) {
        let a = without.ranges[p][0];
        without.ranges[p] = [a; 3];
    }
    let charts = atlas.chart_rects();
    let texels = solve(
        cache,
        &without,
        spec,
        start,
        ITERATIONS,
        &charts,
        atlas.width,
        smoothing,
    );
    (texels, hot)
}

/// The share of the `hot` pixels' radiance in `rest` (squared, summed over channels) that the
/// uniform level `level` at `params` explains: 1 − Σ|rest − model|² / Σ|rest|².
fn explained_share(
    rest: &GroupCache,
    hot: &[bool],
    level: Level,
    params: &GroupParams,
    variant: WardVariant,
) -> f32 {
    let model = uniform_model(rest, level, params, variant);
    let sq = |c: Rgb| (c.x * c.x + c.y * c.y + c.z * c.z) as f64;
    let (mut r0, mut r1) = (0.0f64, 0.0f64);
    for ((px, m), _) in rest.pixels.iter().zip(&model).zip(hot).filter(|x| *x.1) {
        r0 += sq(px.photo);
        r1 += sq(px.photo - *m);
    }
    if r0 > 0.0 {
        (1.0 - r1 / r0) as f32
    } else {
        0.0
    }
}

/// The lobe's specular radiance ρs·S per cached pixel, for all samples and each half (zero for
/// a diffuse base: ρs is zero there).
fn specular(
    cache: &GroupCache,
    base: Level,
    lobe: &GroupParams,
    variant: WardVariant,
) -> (Vec<Rgb>, Vec<[Rgb; 2]>) {
    let specs: Vec<PixelSpec> = pixel_specs(cache, spec_of(base, lobe), variant, false);
    let spec = specs.iter().map(|s| lobe.rho_s * s.s).collect();
    let half = specs
        .iter()
        .map(|s| s.s_half.map(|h| lobe.rho_s * h))
        .collect();
    (spec, half)
}

/// The per-pixel model of a texture (and a specular term): Σ_t A_pt ρ_t + spec_p, for all
/// samples and each half.
fn model(rows: &TexelRows, texels: &[Rgb], p: usize) -> [Rgb; 2] {
    let [a, b, c] = rows.ranges[p].map(|x| x as usize);
    let sum = |r: &[(u32, Rgb)]| {
        r.iter()
            .fold(Rgb::ZERO, |acc, &(t, w)| acc + texels[t as usize] * w)
    };
    [sum(&rows.rows[a..b]), sum(&rows.rows[b..c])]
}

/// The weight of every texel in the photo (Σ_p A_pt over the channels).
fn column_weights(rows: &TexelRows, n: usize) -> Vec<f32> {
    let mut w = vec![0.0f32; n];
    for &(t, r) in &rows.rows {
        w[t as usize] += r.x + r.y + r.z;
    }
    w
}

/// Which texels the cache sees well enough to fit ([`SEEN_FRACTION`]).
fn seen_texels(weights: &[f32]) -> Vec<bool> {
    let mut nz: Vec<f32> = weights.iter().copied().filter(|&w| w > 0.0).collect();
    if nz.is_empty() {
        return vec![false; weights.len()];
    }
    nz.sort_by(f32::total_cmp);
    let cut = SEEN_FRACTION * nz[nz.len() / 2];
    weights.iter().map(|&w| w > 0.0 && w >= cut).collect()
}

/// Solves the texture on the cache by ISRA from `start`, with `spec[p]` (all samples) the
/// specular radiance of each cached pixel, and a smoothness penalty of weight `smoothing`
/// between texels that are neighbours in `chart` (a list of texel rectangles; none: no
/// penalty).
///
/// The penalty is what makes one texel per pixel solvable: a pattern alternating from texel to
/// texel is invisible to a pixel that straddles two texels, so where the pixel grid runs half a
/// texel off the texel grid the photo does not determine it, and unpenalised it grows freely
/// (stripes beating with the two grids). Minimising |Aρ − y|² + Σ_t λ_t Σ_{n ~ t} (ρ_t − ρ_n)²
/// with λ_t = smoothing · max((AᵀA)_tt, the median texel's), the one-step-late multiplicative form
///   ρ_t ← ρ_t (Aᵀy + λ_t Σ_n ρ_n)_t / (AᵀAρ + λ_t deg_t ρ_t)_t
/// keeps ρ ≥ 0 and has the penalised normal equations as its fixed point.
pub fn solve(
    cache: &GroupCache,
    rows: &TexelRows,
    spec: &[Rgb],
    start: &[Rgb],
    iterations: usize,
    charts: &[[usize; 4]],
    width: usize,
    smoothing: f32,
) -> Vec<Rgb> {
    let n = start.len();
    let mut rho: Vec<Rgb> = start
        .iter()
        .map(|t| t.max(Rgb::splat(1e-3)).min(Rgb::ONE))
        .collect();
    // Σ_p A_pt · target_p: the photo's texture, irradiance not yet divided out.
    let mut num = vec![Rgb::ZERO; n];
    for (p, px) in cache.pixels.iter().enumerate() {
        let target = (px.photo - spec[p]).max(Rgb::ZERO);
        let [a, _, c] = rows.ranges[p].map(|x| x as usize);
        for &(t, w) in &rows.rows[a..c] {
            num[t as usize] += w * target;
        }
    }
    // (AᵀA)_tt per channel, for the penalty's scale.
    let mut diag = vec![Rgb::ZERO; n];
    for p in 0..cache.pixels.len() {
        let [a, _, c] = rows.ranges[p].map(|x| x as usize);
        let d: Rgb = rows.rows[a..c].iter().fold(Rgb::ZERO, |s, r| s + r.1);
        for &(t, w) in &rows.rows[a..c] {
            diag[t as usize] += w * d;
        }
    }
    // Floored at the median texel's: a texel at a chart's edge, seen by a sliver of a pixel,
    // would otherwise be nearly free and drift to any value the little light on it allows.
    let mut seen_diag: Vec<f32> = diag
        .iter()
        .map(|d| d.x + d.y + d.z)
        .filter(|&d| d > 0.0)
        .collect();
    seen_diag.sort_by(f32::total_cmp);
    let floor = seen_diag.get(seen_diag.len() / 2).copied().unwrap_or(0.0) / 3.0;
    let lambda: Vec<Rgb> = diag
        .iter()
        .map(|d| d.max(Rgb::splat(floor)) * smoothing)
        .collect();
    // Neighbours within each chart (4-connected).
    let mut neighbours: Vec<Vec<u32>> = vec![Vec::new(); n];
    for &[x0, y0, w, h] in charts {
        for y in 0..h {
            for x in 0..w {
                let i = (y0 + y) * width + x0 + x;
                if i >= n {
                    continue;
                }
                let nb = &mut neighbours[i];
                if x > 0 {
                    nb.push((i - 1) as u32);
                }
                if x + 1 < w {
                    nb.push((i + 1) as u32);
                }
                if y > 0 {
                    nb.push((i - width) as u32);
                }
                if y + 1 < h {
                    nb.push((i + width) as u32);
                }
            }
        }
    }
    let mut den = vec![Rgb::ZERO; n];
    for _ in 0..iterations {
        den.iter_mut().for_each(|d| *d = Rgb::ZERO);
        for p in 0..cache.pixels.len() {
            let [h0, h1] = model(rows, &rho, p);
            let l = h0 + h1;
            let [a, _, c] = rows.ranges[p].map(|x| x as usize);
            for &(t, w) in &rows.rows[a..c] {
                den[t as usize] += w * l;
            }
        }
        let old = rho.clone();
        for t in 0..n {
            let nb = &neighbours[t];
            let sum_nb = nb.iter().fold(Rgb::ZERO, |a, &j| a + old[j as usize]);
            let up = num[t] + lambda[t] * sum_nb;
            let down = den[t] + lambda[t] * old[t] * nb.len() as f32;
            for ch in 0..3 {
                if down[ch] > 0.0 {
                    rho[t][ch] = (old[t][ch] * up[ch] / down[ch]).clamp(0.0, 1.0);
                }
            }
        }
    }
    rho
}

/// The smoothness weight among [`SMOOTHING_CHOICES`] whose texture best predicts pixels it was
/// not solved from: K-fold cross-validation over the cached pixels (Stone 1974; for the weight
/// of a roughness penalty, Wahba & Wold 1975). The pixels are dealt into [`FOLDS`] folds by a
/// hash of their index; for each weight and fold the texture is solved (by `solve`, from the
/// uniform `start`) with that fold's rows emptied, and the fold's pixels are predicted; the
/// weight with the least summed squared prediction error wins. A weight too small lets the
/// texels a left-out pixel straddles alternate freely (nothing else pins the pattern the pixel
/// would have seen) or follow the photo's noise; one too large blurs edges the remaining pixels
/// do pin. Returns the weight and, per weight, the held-out error relative to the best.
pub fn choose_smoothing(
    cache: &GroupCache,
    rows: &TexelRows,
    spec: &[Rgb],
    start: &[Rgb],
    charts: &[[usize; 4]],
    width: usize,
) -> (f32, Vec<f32>) {
    choose_smoothing_among(
        cache,
        rows,
        spec,
        start,
        charts,
        width,
        &SMOOTHING_CHOICES,
        FOLDS,
    )
}

/// [`choose_smoothing`] among `choices`, holding out the first `folds` of the [`FOLDS`] folds
/// in turn.
#[allow(clippy::too_many_arguments)]
fn choose_smoothing_among(
    cache: &GroupCache,
    rows: &TexelRows,
    spec: &[Rgb],
    start: &[Rgb],
    charts: &[[usize; 4]],
    width: usize,
    choices: &[f32],
    folds: usize,
) -> (f32, Vec<f32>) {
    use rayon::prelude::*;
    let fold = |p: usize| (crate::math::sampler::hash_seed(&[p as u64]) % FOLDS as u64) as usize;
    let runs: Vec<(usize, usize)> = (0..choices.len())
        .flat_map(|c| (0..folds).map(move |k| (c, k)))
        .collect();
    // Each (weight, fold) alone, in parallel; summed in their order (deterministic).
    let errors: Vec<f64> = runs
        .par_iter()
        .map(|&(c, k)| {
            let mut kept = rows.clone();
            for (p, r) in kept.ranges.iter_mut().enumerate() {
                if fold(p) == k {
                    *r = [r[0]; 3];
                }
            }
            let texels = solve(
                cache,
                &kept,
                spec,
                start,
                FIRST_ITERATIONS,
                charts,
                width,
                choices[c],
            );
            (0..cache.pixels.len())
                .filter(|&p| fold(p) == k)
                .map(|p| {
                    let [h0, h1] = model(rows, &texels, p);
                    let d = h0 + h1 + spec[p] - cache.pixels[p].photo;
                    (d.x * d.x + d.y * d.y + d.z * d.z) as f64
                })
                .sum()
        })
        .collect();
    let per_weight: Vec<f64> = (0..choices.len())
        .map(|c| errors[c * folds..(c + 1) * folds].iter().sum())
        .collect();
    let best = (0..per_weight.len())
        .min_by(|&a, &b| per_weight[a].total_cmp(&per_weight[b]))
        .unwrap_or(0);
    let relative = per_weight
        .iter()
        .map(|&e| (e / per_weight[best].max(1e-30)) as f32)
        .collect();
    (choices[best], relative)
}

/// ε, the noise floor and the halves' ε of a texture (plus specular terms) on the cache.
pub fn error(
    cache: &GroupCache,
    rows: &TexelRows,
    texels: &[Rgb],
    spec: &[Rgb],
    spec_half: &[[Rgb; 2]],
) -> ErrorStats {
    let pixels = cache.pixels.iter().enumerate().map(|(p, px)| {
        let [h0, h1] = model(rows, texels, p);
        let terms = PixelTerms {
            syn: h0 + h1 + spec[p],
            photo: px.photo,
            halves: [h0 * 2.0 + spec_half[p][0], h1 * 2.0 + spec_half[p][1]],
        };
        (px.tile as usize, terms)
    });
    tiled_error(cache.tiles.max(1), pixels).unwrap_or_default()
}

/// Fills the unseen texels of each chart by pull–push (Gortler et al. 1996) from its seen
/// ones, blended towards the mean m of its object's seen texels with the distance d from the
/// nearest seen texel: m + (pull–push − m)·e^(−d/L), L = [`FILL_FADE_TEXELS`]. A chart with no
/// seen texel gets m, or `fallback` (the group's mean) if the object has none. Where a chart's
/// seen texels repeat (`periodic::find`), the repeat's tile takes m's place, with L a texel.
/// The gaps between charts are left as they are (the export pads them; lookups clamp to the
/// chart). Returns how many texels the repeats filled.
pub fn fill_unseen(atlas: &Atlas, texels: &mut [Rgb], seen: &[bool], fallback: Rgb) -> usize {
    // Per object, the mean of its seen texels: a chart seen nowhere (a book's top, its sides)
    // more likely shares its own object's colours than the group's.
    let rects = atlas.chart_rects();
    let objects = atlas.chart_objects();
    let mut repeated = 0;
    let mut object_mean: std::collections::HashMap<u32, (Rgb, usize)> = Default::default();
    for (&[x0, y0, w, h], &o) in rects.iter().zip(&objects) {
        let e = object_mean.entry(o).or_insert((Rgb::ZERO, 0));
        for y in 0..h {
            for x in 0..w {
                let i = (y0 + y) * atlas.width + x0 + x;
                if seen[i] {
                    e.0 += texels[i];
                    e.1 += 1;
                }
            }
        }
    }
    for (&[x0, y0, w, h], o) in rects.iter().zip(&objects) {
        let mean = match object_mean.get(o) {
            Some(&(sum, n)) if n > 0 => sum / n as f32,
            _ => fallback,
        };
        let mut img = vec![(Rgb::ZERO, 0.0f32); w * h];
        for y in 0..h {
            for x in 0..w {
                let i = (y0 + y) * atlas.width + x0 + x;
                if seen[i] {
                    img[y * w + x] = (texels[i], 1.0);
                }
            }
        }
        if img.iter().all(|p| p.1 == 0.0) {
            for y in 0..h {
                for x in 0..w {
                    texels[(y0 + y) * atlas.width + x0 + x] = mean;
                }
            }
            continue;
        }
        let filled = pull_push(&img, w, h);
        let d = distance_to_seen(&img, w, h);
        // Far from the seen texels: a repeating print's own tile where the chart's seen texels
        // repeat, else the object's mean. (A chart seen whole has nothing to fill.)
        let repeat = img
            .iter()
            .any(|p| p.1 == 0.0)
            .then(|| periodic::find(&img, w, h))
            .flatten();
        for y in 0..h {
            for x in 0..w {
                let i = (y0 + y) * atlas.width + x0 + x;
                if !seen[i] {
                    let tile = repeat.as_ref().and_then(|r| r.fill[y * w + x]);
                    repeated += usize::from(tile.is_some());
                    let fade = if tile.is_some() { 1.0 } else { FILL_FADE_TEXELS };
                    let far = tile.unwrap_or(mean);
                    let k = (-d[y * w + x] / fade).exp();
                    texels[i] = far + (filled[y * w + x] - far) * k;
                }
            }
        }
    }
    repeated
}

/// How far (in texels) an unseen texel's fill keeps the look of the nearest seen texels before
/// it fades to its object's mean (to a repeating print's tile it fades within a texel: the tile
/// was checked against held-out texels, pull–push's smoothness was not). Pull–push alone
/// carries the seen edge's texels across a whole hole, as streaks of whatever detail lies at
/// the edge (the poster scene's desk). Far from every seen texel the object's mean is the
/// estimate with the least expected error for a texture whose detail is not correlated over
/// more than a few texels.
const FILL_FADE_TEXELS: f32 = 4.0;

/// Per pixel of a w × h weighted image, the distance in pixels to the nearest pixel of weight
/// > 0 (a two-pass chamfer transform, steps 1 and √2; infinite where no pixel is seen).
fn distance_to_seen(img: &[(Rgb, f32)], w: usize, h: usize) -> Vec<f32> {
    let mut d: Vec<f32> = img
        .iter()
        .map(|p| if p.1 > 0.0 { 0.0 } else { f32::INFINITY })
        .collect();
    let diag = std::f32::consts::SQRT_2;
    for y in 0..h {
        for x in 0..w {
            let mut v = d[y * w + x];
            if x > 0 {
                v = v.min(d[y * w + x - 1] + 1.0);
            }
            if y > 0 {
                v = v.min(d[(y - 1) * w + x] + 1.0);
                if x > 0 {
                    v = v.min(d[(y - 1) * w + x - 1] + diag);
                }
                if x + 1 < w {
                    v = v.min(d[(y - 1) * w + x + 1] + diag);
                }
            }
            d[y * w + x] = v;
        }
    }
    for y in (0..h).rev() {
        for x in (0..w).rev() {
            let mut v = d[y * w + x];
            if x + 1 < w {
                v = v.min(d[y * w + x + 1] + 1.0);
            }
            if y + 1 < h {
                v = v.min(d[(y + 1) * w + x] + 1.0);
                if x + 1 < w {
                    v = v.min(d[(y + 1) * w + x + 1] + diag);
                }
                if x > 0 {
                    v = v.min(d[(y + 1) * w + x - 1] + diag);
                }
            }
            d[y * w + x] = v;
        }
    }
    d
}

/// Pull–push on a weighted image: each coarser level averages 2×2 blocks by weight; every
/// pixel of weight < 1 is then blended with the coarser level's value.
fn pull_push(img: &[(Rgb, f32)], w: usize, h: usize) -> Vec<Rgb> {
    if w <= 1 && h <= 1 {
        let (c, wt) = img[0];
        return vec![if wt > 0.0 { c / wt } else { Rgb::ZERO }];
    }
    let (cw, ch) = (w.div_ceil(2), h.div_ceil(2));
    let mut coarse = vec![(Rgb::ZERO, 0.0f32); cw * ch];
    for y in 0..h {
        for x in 0..w {
            let (c, wt) = img[y * w + x];
            let k = (y / 2) * cw + x / 2;
            coarse[k].0 += c * wt;
            coarse[k].1 += wt;
        }
    }
    for c in coarse.iter_mut() {
        if c.1 > 0.0 {
            c.0 /= c.1;
            c.1 = c.1.min(1.0);
        }
    }
    let up = pull_push(&coarse, cw, ch);
    (0..w * h)
        .map(|i| {
            let (x, y) = (i % w, i / w);
            let (c, wt) = img[i];
            let wt = wt.min(1.0);
            c * wt + up[(y / 2) * cw + x / 2] * (1.0 - wt)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fit::cache::CachePixel;

    /// A 1-D "image" of one pixel per texel over `truth`, each pixel reading 0.6 of its own
    /// texel and 0.2 of each neighbour (a blur) under `irradiance(p)`, its photo value scaled by
    /// `1 + noise(p)`.
    fn one_d(
        truth: &[Rgb],
        irradiance: impl Fn(usize) -> Rgb,
        noise: impl Fn(usize) -> f32,
    ) -> (GroupCache, TexelRows) {
        let n = truth.len();
        let mut rows = TexelRows::default();
        let mut cache = GroupCache {
            tiles: 4,
            ..Default::default()
        };
        for p in 0..n {
            let start = rows.rows.len() as u32;
            let mut photo = Rgb::ZERO;
            for (t, f) in [(p.wrapping_sub(1), 0.2f32), (p, 0.6), (p + 1, 0.2)] {
                if t < n {
                    // Half 0 and half 1 each carry half the weight.
                    let w = irradiance(p) * f * 0.5;
                    rows.rows.push((t as u32, w));
                    photo += truth[t] * w * 2.0;
                }
            }
            let mid = rows.rows.len() as u32;
            let copy: Vec<_> = rows.rows[start as usize..mid as usize].to_vec();
            rows.rows.extend(copy);
            rows.ranges.push([start, mid, rows.rows.len() as u32]);
            cache.pixels.push(CachePixel {
                tile: (p * 4 / n) as u32,
                ..CachePixel::bare(p as u32, photo * (1.0 + noise(p)))
            });
        }
        (cache, rows)
    }

    /// The test texture: saturated red bands, dark single texels, blue between.
    fn bands(n: usize) -> Vec<Rgb> {
        (0..n)
            .map(|i| match i % 7 {
                0 | 1 => Rgb::new(0.9, 0.1, 0.05),
                3 => Rgb::splat(0.03),
                _ => Rgb::new(0.2, 0.5, 0.7),
            })
            .collect()
    }

    /// 40 pixels over 40 texels under an irradiance that varies along the row: ISRA recovers a
    /// texture with sharp detail and dark texels exactly, which dividing the photo by the
    /// irradiance pixel by pixel does not (the blur).
    #[test]
    fn isra_divides_the_irradiance_out_and_undoes_the_blur() {
        let n = 40;
        let truth = bands(n);
        let irradiance = |p: usize| Rgb::new(1.0 + p as f32 / 20.0, 1.2, 0.8 - p as f32 / 100.0);
        let (cache, rows) = one_d(&truth, irradiance, |_| 0.0);
        let zero = vec![Rgb::ZERO; n];
        let got = solve(
            &cache,
            &rows,
            &zero,
            &vec![Rgb::splat(0.5); n],
            2000,
            &[],
            n,
            0.0,
        );
        let worst = got
            .iter()
            .zip(&truth)
            .map(|(g, t)| ((*g - *t).abs() / *t).max_element())
            .fold(0.0f32, f32::max);
        assert!(worst < 0.01, "worst relative texel error {worst}");
        let e = error(&cache, &rows, &got, &zero, &vec![[Rgb::ZERO; 2]; n]);
        assert!(e.error < 1e-3, "{e:?}");
        // Dividing each pixel by its irradiance instead keeps the blur: dark texels come out
        // several times too bright.
        let naive = (cache.pixels[3].photo / irradiance(3)).x;
        assert!(naive > 3.0 * truth[3].x, "{naive}");
    }

    /// Cross-validation asks for little smoothing where the pixels pin every texel (detail two
    /// texels wide, a clean photo) and for much where they show only noise (a uniform texture
    /// under a photo with up to ±10% noise per pixel), and the weight it picks recovers each
    /// texture better than the other end of the range would.
    #[test]
    fn cross_validation_smooths_noise_and_keeps_detail() {
        let n = 120;
        let charts = [[0, 0, n, 1]];
        let zero = vec![Rgb::ZERO; n];
        let start = vec![Rgb::splat(0.4); n];
        let rms = |got: &[Rgb], truth: &[Rgb]| {
            let s: f32 = got
                .iter()
                .zip(truth)
                .map(|(g, t)| (*g - *t).length_squared())
                .sum();
            (s / n as f32).sqrt()
        };
        let solved = |cache: &GroupCache, rows: &TexelRows, w: f32| {
            solve(cache, rows, &zero, &start, FIRST_ITERATIONS, &charts, n, w)
        };
        let (lo, hi) = (
            SMOOTHING_CHOICES[0],
            SMOOTHING_CHOICES[SMOOTHING_CHOICES.len() - 1],
        );

        // Its bands two texels wide: detail the pixels resolve.
        let sharp: Vec<Rgb> = bands(n).iter().flat_map(|&b| [b, b]).take(n).collect();
        let (cache, rows) = one_d(&sharp, |_| Rgb::ONE, |_| 0.0);
        let (w, cv) = choose_smoothing(&cache, &rows, &zero, &start, &charts, n);
        assert!(w <= 0.003, "sharp, clean: chose {w} ({cv:?})");
        let e = rms(&solved(&cache, &rows, w), &sharp);
        assert!(e < 0.5 * rms(&solved(&cache, &rows, hi), &sharp), "{e}");

        let flat = vec![Rgb::new(0.5, 0.4, 0.3); n];
        let noise = |p: usize| {
            0.1 * (2.0 * (crate::math::sampler::hash_seed(&[p as u64, 7]) >> 40) as f32
                / (1u64 << 24) as f32
                - 1.0)
        };
        let (cache, rows) = one_d(&flat, |_| Rgb::ONE, noise);
        let (w, cv) = choose_smoothing(&cache, &rows, &zero, &start, &charts, n);
        assert!(w >= 0.1, "flat, noisy: chose {w} ({cv:?})");
        let e = rms(&solved(&cache, &rows, w), &flat);
        assert!(e < 0.5 * rms(&solved(&cache, &rows, lo), &flat), "{e}");
    }

    #[test]
    fn pull_push_fills_holes_from_the_seen_texels_and_keeps_them() {
        let (w, h) = (8, 6);
        let mut img = vec![(Rgb::ZERO, 0.0); w * h];
        for y in 0..h {
            for x in 0..4 {
                img[y * w + x] = (Rgb::splat(0.2), 1.0);
            }
        }
        img[5 * w + 7] = (Rgb::splat(0.8), 1.0);
        let out = pull_push(&img, w, h);
        for y in 0..h {
            for x in 0..4 {
                assert_eq!(out[y * w + x], Rgb::splat(0.2));
            }
        }
        assert_eq!(out[5 * w + 7], Rgb::splat(0.8));
        // Holes take values between the seen ones, nearer the nearer.
        let a = out[w + 4].x;
        assert!((0.2..=0.8).contains(&a) && a < 0.5, "{a}");
        assert!(out.iter().all(|c| c.x >= 0.2 - 1e-6 && c.x <= 0.8 + 1e-6));
    }

    #[test]
    fn unseen_texels_continue_the_seen_edge_and_fade_to_the_objects_mean() {
        // A 4 × 1 wall, texel 0.1: one 40 × 10 chart whose first ten columns are seen, 0.2 but
        // for a bright last column (0.9). The object's mean is 0.27.
        let wall = crate::geometry::shapes::quad(
            crate::math::Vec3::ZERO,
            crate::math::Vec3::X * 4.0,
            crate::math::Vec3::Y,
        );
        let g = crate::scene::load::build_geometry_for_tests(vec![wall]);
        let atlas = Atlas::build(&g, &[0], 1, 0.1);
        let [x0, y0, w, h] = atlas.chart_rects()[0];
        assert_eq!((w, h), (40, 10));
        let at = |x: usize, y: usize| (y0 + y) * atlas.width + x0 + x;
        let mut texels = vec![Rgb::ZERO; atlas.width * atlas.height];
        let mut seen = vec![false; texels.len()];
        for y in 0..h {
            for x in 0..10 {
                texels[at(x, y)] = Rgb::splat(if x == 9 { 0.9 } else { 0.2 });
                seen[at(x, y)] = true;
            }
        }
        let before = texels.clone();
        fill_unseen(&atlas, &mut texels, &seen, Rgb::ONE);
        for y in 0..h {
            for x in 0..10 {
                assert_eq!(texels[at(x, y)], before[at(x, y)]);
            }
            // Next to the seen edge the fill keeps its look (pull–push alone gives ≈ 0.55
            // there), ...
            let near = texels[at(10, y)].x;
            assert!(near > 0.4 && near < 0.9, "{near}");
            // ... far from it the object's mean, not the edge's bright column stretched across.
            let far = texels[at(39, y)].x;
            assert!((far - 0.27).abs() < 2e-3, "{far}");
            // In between, monotone towards the mean.
            for x in 11..40 {
                assert!(texels[at(x, y)].x <= texels[at(x - 1, y)].x + 1e-6);
            }
        }
    }
}
