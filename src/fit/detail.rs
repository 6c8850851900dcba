//! Texel-scale structure in the residual of a group's uniform model: the texture threshold of
//! Algorithm 1 on what the error metric cannot see (its tiles average fine detail away), asked
//! so that only a texture explains what it finds.
//!
//! The residual e = photo − model (mean of the channels) is high-passed, HP(v)ₖ = vₖ − the mean
//! of v over the 5×5 neighbourhood of cached pixels, which removes every smooth misfit: a wrong
//! fall-off of n·l, of the view angle or of the indirect light. What remains and is not texture
//! is sharp misfit that follows the model's own features, so HP(e) is regressed (least squares
//! in windows of 8×8 cached pixels, each fitted with a margin of 4 around it) on
//!
//!   HP(m), HP(∂ₓm), HP(∂ᵧm), HP(∂ₓₓm), HP(∂ᵧᵧm), HP(∂ₓᵧm), and the same of s
//!
//! with m the model's radiance and s its specular part: a registration off by δ leaves
//! e ≈ −δ·∇m, a highlight too strong or misplaced leaves e ≈ a·s + b·∇s, a lobe a little too
//! rough or too sharp blurs or sharpens the reflections it holds (e ≈ c·∇²s, per axis for an
//! anisotropic one), and none of them survives.
//! The coefficients are the window's own because such misfit differs from place to place: a
//! box whose top face the cache lights a little brighter than the photo does, and whose front
//! face a little darker, leaves after the high pass a band of ± along the crease between them,
//! which no single coefficient for the whole group removes. A printed pattern is uncorrelated
//! with all six in every window and survives whole, whether it covers the group or only a
//! part of it (a rug's border). The statistic is the covariance c₁ of neighbouring pixels'
//! remaining residuals (horizontal and vertical pairs):
//! independent per-pixel noise (the photo's, the cache's) contributes nothing to it (slightly
//! less), while a texture's strokes span neighbouring pixels. A pixel whose cache holds a
//! spike (a few bright samples in one half of its paths) is judged on its other half
//! ([`despike`]). Before the model's features, what the surface's shape explains is regressed
//! out over the whole group: its normal, how far the normal turns from its neighbours' and
//! within the pixel, alone and times the model's light (a bevel, a groove between faces).
//! The statistic is taken over the pixels where the model's diffuse term is at least its
//! specular one: a print is a diffuse reflectance, and where a glossy surface shows a bright
//! reflection its residual is that reflection's misfit. Unless the lobe is too broad to show
//! its surroundings at all (α ≥ [`BROAD_ALPHA`]):
//! such a lobe spreads each reflection over more than a radian, so the residual at the texel
//! scale is the surface's own wherever it is, and a diffuse print under a coat fitted that
//! rough (a broad coat standing in for part of the diffuse light) is judged on every pixel.
//! Either way, pixels within the high pass's reach of a shape feature ([`SHAPE_FEATURE`]) are
//! left out: there the shading's misfit runs along the groove or the edge as a streak.
//! Reported are √c₁ as a fraction of those pixels' mean radiance, and c₁'s z-score
//! against its own standard error, so a texture is tried only where the structure is both large
//! and certain.
//!
//! Neighbours are those of the cache's pixel grid: within a subsampled cache's blocks they are
//! the image's own pixels (`cache::choose_pixels`).

use super::cache::{GroupCache, PixelGrid};
use super::level::Level;
use super::params::GroupParams;
use super::texture::UniformParts;
use crate::math::Rgb;
use crate::scene::WardVariant;

/// Below this z-score the structure is not told from noise.
pub const MIN_Z: f32 = 4.0;

/// The fewest cached pixels (in the group's first view) on which texel-scale structure is
/// judged, and a texture tried at all (`hierarchy::texture_gate`): a texture on fewer has
/// about as many free texels as pixels, and fits whatever the pixels show.
pub const MIN_PIXELS: usize = 16;

/// A lobe at least this rough (its smaller α) reflects nothing of its surroundings at the
/// texel scale: a GGX or Beckmann lobe of α 0.5 spreads a reflected ray over ±50°.
pub const BROAD_ALPHA: f32 = 0.5;

/// The texel-scale structure a uniform model leaves ([`uniform_detail`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Detail {
    /// RMS of the coherent residual as a fraction of the group's mean radiance.
    pub rms: f32,
    /// Its covariance's z-score against the covariance's standard error.
    pub z: f32,
    /// The share of the high-passed residual's variance that registration and highlight
    /// misfit explained (what the regression removed).
    pub explained: f32,
}

impl Detail {
    /// Whether the structure is a texture's: at least `threshold` RMS and certain.
    pub fn is_texture(&self, threshold: f32) -> bool {
        self.rms >= threshold && self.z >= MIN_Z
    }

    /// The structure of one model measured on several caches (independent path samples, the
    /// same photo): the mean RMS and explained share, and Stouffer's z, Σz / √n. A statistic
    /// near its threshold on one cache decides by the cache's noise, and so by the seed;
    /// pooled, it decides by what the model leaves.
    pub fn pooled(all: &[Detail]) -> Option<Detail> {
        if all.is_empty() {
            return None;
        }
        let n = all.len() as f32;
        Some(Detail {
            rms: all.iter().map(|d| d.rms).sum::<f32>() / n,
            z: all.iter().map(|d| d.z).sum::<f32>() / n.sqrt(),
            explained: all.iter().map(|d| d.explained).sum::<f32>() / n,
        })
    }
}

/// The detail a uniform level's model with `params` leaves on `cache`. Zero at level 7, and
/// where a texture could only paint reflections ([`reflection_holds_the_light`]).
pub fn uniform_detail(
    cache: &GroupCache,
    level: Level,
    params: &GroupParams,
    variant: WardVariant,
) -> Detail {
    if level == Level::Textured {
        return Detail::default();
    }
    let parts = super::texture::uniform_parts(cache, level, params, variant);
    parts_detail(cache, level, params, &parts)
}

/// [`uniform_detail`] of the model's parts per cached pixel, already computed
/// (`texture::uniform_parts`).
pub fn parts_detail(
    cache: &GroupCache,
    level: Level,
    params: &GroupParams,
    parts: &UniformParts,
) -> Detail {
    if reflection_holds_the_light(level, params, &parts.model, &parts.spec) {
        return Detail::default();
    }
    let halves = [&parts.halves[0][..], &parts.halves[1][..]];
    let broad = broad_lobe(level, params);
    detail(cache, &parts.model, halves, &parts.spec, cache.width, broad)
}

/// Whether the level's lobe is at least [`BROAD_ALPHA`] rough on both axes.
fn broad_lobe(level: Level, params: &GroupParams) -> bool {
    level.has_lobe() && params.alpha_x.min(params.alpha_y) >= BROAD_ALPHA
}

/// A uniform model whose reflection (its mirror or its lobe, `spec`) carries at least this
/// share of the group's light in the photo is mostly reflection.
pub const MOSTLY_REFLECTION: f32 = 0.5;

/// Whether a texture could hold this uniform model's light only by painting its reflections:
/// level 7 puts a diffuse texture under a lobe only where a Ward level earned its place
/// (`hierarchy::climb`'s varnish); on every other level the texture is bare, and so takes the
/// place of the model's mirror, metal lobe or coat. Where that reflection carries at least
/// [`MOSTLY_REFLECTION`] of the group's light (`model`, `spec` per cached pixel), a bare
/// texture fits the photo by freezing what the group reflects from this one viewpoint into
/// reflectance: right in the photo, wrong from every other (at full resolution the interior's
/// mirror, diffuse 0.16 under a mirror of 0.63, was replaced by a texture of the room it
/// showed). Its residual's structure is the reflection's, and it is no texture's evidence.
/// A lobe too broad to reflect anything at the texel scale ([`BROAD_ALPHA`]) is not such a
/// reflection.
pub fn reflection_holds_the_light(
    level: Level,
    params: &GroupParams,
    model: &[Rgb],
    spec: &[Rgb],
) -> bool {
    if level.is_ward() || !(level.is_mirror() || level.has_lobe()) || broad_lobe(level, params) {
        return false;
    }
    let lum = |c: &Rgb| (c.x + c.y + c.z) as f64;
    let total: f64 = model.iter().map(lum).sum();
    let reflected: f64 = spec.iter().map(lum).sum();
    total > 0.0 && reflected >= MOSTLY_REFLECTION as f64 * total
}

/// The module's statistic for `model` (and its specular part `spec`) per cached pixel, whose
/// estimates from each half of the pixel's samples alone are `halves` (for [`despike`]);
/// `broad_lobe`: the specular part is a lobe too rough to reflect texel-scale detail, and every
/// pixel is judged.
pub fn detail(
    cache: &GroupCache,
    model: &[Rgb],
    halves: [&[Rgb]; 2],
    spec: &[Rgb],
    width: usize,
    broad_lobe: bool,
) -> Detail {
    // Neighbours are those of one image: a cache of several photos is judged on its first.
    let n = cache.first_view().len();
    if n < MIN_PIXELS || width == 0 {
        return Detail::default();
    }
    let grid = PixelGrid::new(cache.first_view(), width);
    let lum = |c: Rgb| (c.x + c.y + c.z) / 3.0;
    let mut m: Vec<f32> = model[..n].iter().map(|&c| lum(c)).collect();
    let mut s: Vec<f32> = spec[..n].iter().map(|&c| lum(c)).collect();
    let mut h = halves.map(|h| h[..n].iter().map(|&c| lum(c)).collect::<Vec<f32>>());
    despike(&mut m, &mut s, &mut h);
    let residual = |model: &[f32]| -> Vec<f32> {
        (0..n)
            .map(|k| lum(cache.pixels[k].photo) - model[k])
            .collect()
    };
    let high_pass = |v: &[f32]| -> Vec<f32> {
        (0..n)
            .map(|k| {
                let (mut sum, mut count) = (0.0f32, 0usize);
                for dy in -2..=2 {
                    for dx in -2..=2 {
                        if let Some(j) = grid.neighbour(k, dx, dy) {
                            sum += v[j];
                            count += 1;
                        }
                    }
                }
                v[k] - sum / count.max(1) as f32
            })
            .collect()
    };
    // Central differences where both neighbours are cached, one-sided at a block's edge.
    let gradient = |v: &[f32], dx: i64, dy: i64| -> Vec<f32> {
        (0..n)
            .map(
                |k| match (grid.neighbour(k, dx, dy), grid.neighbour(k, -dx, -dy)) {
                    (Some(a), Some(b)) => 0.5 * (v[a] - v[b]),
                    (Some(a), None) => v[a] - v[k],
                    (None, Some(b)) => v[k] - v[b],
                    (None, None) => 0.0,
                },
            )
            .collect()
    };
    // A feature's shifts (first derivatives) and its blur or sharpening (second derivatives:
    // a lobe's roughness, a penumbra's width, a little off).
    let shapes = |v: &[f32]| -> Vec<Vec<f32>> {
        let (gx, gy) = (gradient(v, 1, 0), gradient(v, 0, 1));
        vec![
            high_pass(v),
            high_pass(&gx),
            high_pass(&gy),
            high_pass(&gradient(&gx, 1, 0)),
            high_pass(&gradient(&gy, 0, 1)),
            high_pass(&gradient(&gx, 0, 1)),
        ]
    };
    let mut features = shapes(&m);
    if s.iter().any(|&v| v != 0.0) {
        features.extend(shapes(&s));
    }
    // The surface's orientation: a misfit of any shading (the light a face receives, the
    // angle it is seen at) is a function of the normal, and so steps where the faces of a box
    // or a stair meet, whether the model steps there or not. On a flat group these are zero
    // and left out; on a curved one they are smooth, and the high pass leaves little of them.
    let normals: Vec<[f32; 3]> = cache.pixels[..n]
        .iter()
        .map(|p| p.normal.to_array())
        .collect();
    let axes: Vec<Vec<f32>> = (0..3)
        .map(|a| normals.iter().map(|v| v[a]).collect())
        .collect();
    let local: Vec<Vec<f32>> = axes
        .iter()
        .map(|v| v.iter().zip(high_pass(v)).map(|(x, h)| x - h).collect())
        .collect();
    // How far the normal turns from its neighbourhood's mean, |n − n̄|², and within the pixel,
    // 1 − |n| of the pixel's mean normal: a bevel or a groove between two faces, wider or
    // narrower than a pixel, where a misfit of the shading is the same on both of its sides.
    let turn: Vec<f32> = (0..n)
        .map(|k| (0..3).map(|a| (axes[a][k] - local[a][k]).powi(2)).sum())
        .collect();
    let within: Vec<f32> = normals
        .iter()
        .map(|v| 1.0 - (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt())
        .collect();
    // Near such a feature (within the high pass's reach of one) the residual is mostly the
    // shading's misfit there, which no regression removes whole: it runs along a groove as a
    // streak, which neighbouring pairs take for a print's stroke. The statistic is judged
    // where the surface is smooth; a print covers the faces between the features too.
    let feature: Vec<bool> = (0..n)
        .map(|k| turn[k] > SHAPE_FEATURE || (within[k] > SHAPE_FEATURE && within[k] < 1.0))
        .collect();
    let smooth: Vec<bool> = (0..n)
        .map(|k| {
            !(-2..=2).any(|dy| {
                (-2..=2).any(|dx| grid.neighbour(k, dx, dy).is_some_and(|j| feature[j]))
            })
        })
        .collect();
    // These are regressed out over the whole group first (one coefficient each: one material's
    // misfit on one kind of bevel), leaving each window's few pixels to the model's features.
    // A misfit of the light there is in proportion to the light, and so is the bevel's share.
    let lit_within: Vec<f32> = (0..n).map(|k| m[k] * within[k]).collect();
    let geometry: Vec<Vec<f32>> = axes
        .iter()
        .chain([&turn, &within, &lit_within])
        .map(|v| high_pass(v))
        .filter(|hp| hp.iter().any(|&x| x.abs() > 1e-4))
        .collect();
    let all: Vec<usize> = (0..n).collect();
    let shaded = |y: Vec<f32>| -> Vec<f32> {
        if geometry.is_empty() {
            return y;
        }
        match least_squares(&y, &geometry, &all) {
            Some(beta) => (0..n).map(|k| y[k] - fitted(&beta, &geometry, k)).collect(),
            None => y,
        }
    };
    let y = shaded(high_pass(&residual(&m)));
    let r = regress_out_locally(&y, &features, &grid);
    let var = |v: &[f32]| v.iter().map(|&x| (x as f64).powi(2)).sum::<f64>();
    let explained = {
        let before = var(&y);
        if before > 0.0 {
            (1.0 - var(&r) / before).clamp(0.0, 1.0) as f32
        } else {
            0.0
        }
    };
    // A print is a diffuse reflectance: it is judged where the diffuse term dominates. Where a
    // glossy group shows a reflection brighter than its own diffuse light, the residual is the
    // reflection's misfit (a neighbour's edge, the lobe's exact shape), whatever its scale.
    let diffuse = |k: usize| smooth[k] && (broad_lobe || s[k] <= m[k] - s[k]);
    let (mut cov, mut cov2, mut pairs) = (0.0f64, 0.0f64, 0usize);
    let (mut sum, mut count) = (0.0f64, 0usize);
    for k in (0..n).filter(|&k| diffuse(k)) {
        sum += lum(cache.pixels[k].photo) as f64;
        count += 1;
        for (dx, dy) in [(1, 0), (0, 1)] {
            if let Some(j) = grid.neighbour(k, dx, dy).filter(|&j| diffuse(j)) {
                let p = (r[k] * r[j]) as f64;
                cov += p;
                cov2 += p * p;
                pairs += 1;
            }
        }
    }
    let mean = (sum / count.max(1) as f64) as f32;
    if pairs < 16 || !(mean > 0.0) {
        return Detail::default();
    }
    let c1 = cov / pairs as f64;
    // The standard error of a mean of products (neighbouring pairs share pixels, which this
    // ignores: the threshold on z is set with room for it).
    let se = ((cov2 / pairs as f64 - c1 * c1).max(0.0) / pairs as f64).sqrt();
    Detail {
        rms: (c1.max(0.0).sqrt() as f32) / mean,
        z: if se > 0.0 { (c1 / se) as f32 } else { 0.0 },
        explained,
    }
}

/// A pixel whose normal turns from its neighbourhood's mean by more than this (|n − n̄|²), or
/// whose mean normal is shorter than 1 by more (its normals spread by some 8° within it), is
/// on a shape feature: a bevel, a groove, an edge. A curved surface of 10 pixels' radius
/// reaches a twentieth of either.
const SHAPE_FEATURE: f32 = 0.01;

/// A pixel whose two halves differ by more than this many times the group's median
/// difference (relative to the model) holds a spike: a few bright samples in one half.
const SPIKE: f32 = 6.0;

/// Replaces each spiked pixel's model `m`, specular part `s` and halves `h` (luminance) by its
/// lower half, the one without the spike. A spike is noise, but it is one pixel's: the high
/// pass spreads it over its 24 neighbours, and a window's regression on the model's features
/// (which hold half of it) is fitted to it and adds the model's own structure to the
/// residual, which the photo's own structure then matches.
fn despike(m: &mut [f32], s: &mut [f32], h: &mut [Vec<f32>; 2]) {
    let relative: Vec<f32> = (0..m.len())
        .map(|k| (h[0][k] - h[1][k]).abs() / m[k].max(1e-6))
        .collect();
    let mut sorted: Vec<f32> = relative.iter().copied().filter(|q| q.is_finite()).collect();
    if sorted.is_empty() {
        return;
    }
    let mid = sorted.len() / 2;
    let median = *sorted.select_nth_unstable_by(mid, f32::total_cmp).1;
    if !(median > 0.0) {
        return;
    }
    for (k, &q) in relative.iter().enumerate() {
        if q > SPIKE * median && m[k] > 0.0 {
            let low = h[0][k].min(h[1][k]).max(0.0);
            s[k] *= low / m[k];
            m[k] = low;
            h[0][k] = low;
            h[1][k] = low;
        }
    }
}

/// Side of the square windows in which the misfit is regressed out on its own, and the margin
/// of neighbours each window's fit reads too, in grid steps.
const WINDOW: i64 = 8;
const MARGIN: i64 = 4;

/// A window's fit needs this many pixels per feature (fewer would take the print for misfit:
/// a thin group's windows hold a few dozen pixels); a window with fewer takes the group's.
const ROWS_PER_FEATURE: usize = 16;

/// `y` minus its least-squares projection on `features`, fitted window by window (each
/// [`WINDOW`]² core with its [`MARGIN`]): misfit that follows the model's features differently
/// in different places is removed where it is. A window with too few pixels takes the
/// coefficients of the whole group.
fn regress_out_locally(y: &[f32], features: &[Vec<f32>], grid: &PixelGrid) -> Vec<f32> {
    let n = y.len();
    let all: Vec<usize> = (0..n).collect();
    let group = least_squares(y, features, &all);
    let mut windows: std::collections::BTreeMap<(i64, i64), Vec<usize>> = Default::default();
    for k in 0..n {
        let (x, v) = grid.position(k);
        windows
            .entry((x.div_euclid(WINDOW), v.div_euclid(WINDOW)))
            .or_default()
            .push(k);
    }
    let mut r = y.to_vec();
    for (&(wx, wy), core) in &windows {
        let (x0, y0) = (wx * WINDOW - MARGIN, wy * WINDOW - MARGIN);
        let (x1, y1) = ((wx + 1) * WINDOW + MARGIN, (wy + 1) * WINDOW + MARGIN);
        let support: Vec<usize> = (-1..=1)
            .flat_map(|dy| (-1..=1).map(move |dx| (wx + dx, wy + dy)))
            .filter_map(|w| windows.get(&w))
            .flatten()
            .copied()
            .filter(|&k| {
                let (x, v) = grid.position(k);
                (x0..x1).contains(&x) && (y0..y1).contains(&v)
            })
            .collect();
        let local = (support.len() >= ROWS_PER_FEATURE * features.len())
            .then(|| least_squares(y, features, &support))
            .flatten();
        if let Some(beta) = local.as_ref().or(group.as_ref()) {
            for &k in core {
                r[k] = y[k] - fitted(beta, features, k);
            }
        }
    }
    r
}

/// Σᵢ βᵢ featureᵢ at pixel `k`: what the regression explains there.
fn fitted(beta: &[f64], features: &[Vec<f32>], k: usize) -> f32 {
    (0..features.len())
        .map(|i| beta[i] * features[i][k] as f64)
        .sum::<f64>() as f32
}

/// The least-squares coefficients of `y` on `features` over the pixels `rows` (a tiny ridge
/// keeps a feature that is zero or repeats another from making the normal matrix singular).
fn least_squares(y: &[f32], features: &[Vec<f32>], rows: &[usize]) -> Option<Vec<f64>> {
    let p = features.len();
    let mut a = vec![vec![0.0f64; p]; p];
    let mut b = vec![0.0f64; p];
    for &k in rows {
        for i in 0..p {
            let fi = features[i][k] as f64;
            b[i] += fi * y[k] as f64;
            for j in 0..p {
                a[i][j] += fi * features[j][k] as f64;
            }
        }
    }
    let trace = (0..p).map(|i| a[i][i]).sum::<f64>().max(1e-30);
    for (i, row) in a.iter_mut().enumerate() {
        row[i] += 1e-9 * trace;
    }
    let inv = super::solve::invert(&a)?;
    Some(
        (0..p)
            .map(|i| (0..p).map(|j| inv[i][j] * b[j]).sum())
            .collect(),
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fit::cache::CachePixel;
    use crate::math::Vec3;

    /// A cache of a `w`×`h` image, every pixel cached (the model is given directly).
    fn cache_of(photo: &[f32], w: usize) -> GroupCache {
        GroupCache {
            pixels: photo
                .iter()
                .enumerate()
                .map(|(i, &v)| CachePixel::bare(i as u32, Rgb::splat(v)))
                .collect(),
            width: w,
            ..Default::default()
        }
    }

    fn noise(i: usize, seed: u64) -> f32 {
        let h = crate::math::sampler::mix64(i as u64 ^ seed.wrapping_mul(0x9e37_79b9_7f4a_7c15));
        (h >> 40) as f32 / (1u64 << 24) as f32 - 0.5
    }

    /// A lit sphere-like blob: smooth shading with a highlight, on a 64×64 image.
    fn shading(x: f32, y: f32) -> (f32, f32) {
        let (dx, dy) = (x - 32.0, y - 30.0);
        let r2 = (dx * dx + dy * dy) / (28.0 * 28.0);
        let diffuse = 0.4 * (1.0 - r2).max(0.0).sqrt() + 0.05;
        let (hx, hy) = (x - 38.0, y - 24.0);
        let highlight = 0.6 * (-(hx * hx + hy * hy) / 6.0).exp();
        (diffuse + highlight, highlight)
    }

    fn run(photo_at: impl Fn(f32, f32, usize) -> f32) -> Detail {
        let w = 64;
        let photo: Vec<f32> = (0..w * w)
            .map(|i| photo_at((i % w) as f32, (i / w) as f32, i))
            .collect();
        let (model, spec): (Vec<Rgb>, Vec<Rgb>) = (0..w * w)
            .map(|i| {
                let (m, s) = shading((i % w) as f32, (i / w) as f32);
                (Rgb::splat(m), Rgb::splat(s))
            })
            .unzip();
        detail(&cache_of(&photo, w), &model, [&model, &model], &spec, w, false)
    }

    #[test]
    fn a_printed_pattern_is_texture_and_noise_is_not() {
        // Diamonds of ±10% contrast and a 6-pixel period on the shading, plus 1% noise.
        let pattern = run(|x, y, i| {
            let (m, _) = shading(x, y);
            let d = ((x + y) / 6.0 * std::f32::consts::TAU).sin()
                * ((x - y) / 6.0 * std::f32::consts::TAU).sin();
            m * (1.0 + 0.1 * d.signum()) + 0.01 * noise(i, 1)
        });
        assert!(pattern.is_texture(0.02), "{pattern:?}");
        // The same shading with 3% noise alone: large but incoherent.
        let noisy = run(|x, y, i| shading(x, y).0 * (1.0 + 0.06 * noise(i, 2)));
        assert!(!noisy.is_texture(0.02), "{noisy:?}");
    }

    /// Three faces of a box, 16 rows each, one above the other: top, front and a side far
    /// brighter. The photo's top face is 40% brighter than the model's, its side 25% darker and
    /// its front exact, so the high-passed residual is a band of ± along each crease, of
    /// opposite sign to the model's step at one and the same sign at the other: no one
    /// coefficient of the model's features for the group fits both, a window's own does.
    #[test]
    fn a_misfit_that_differs_between_faces_is_not_texture() {
        let (w, h) = (64, 48);
        let face = |row: usize| [(0.3, 1.4), (0.2, 1.0), (0.7, 0.75)][row / 16];
        let model: Vec<Rgb> = (0..w * h)
            .map(|i| Rgb::splat(face(i / w).0 * (1.0 + 0.002 * (i % w) as f32)))
            .collect();
        let photo: Vec<f32> = (0..w * h)
            .map(|i| model[i].x * face(i / w).1 + 0.003 * noise(i, 5))
            .collect();
        let zero = vec![Rgb::splat(0.0); w * h];
        let d = detail(&cache_of(&photo, w), &model, [&model, &model], &zero, w, false);
        assert!(!d.is_texture(0.02), "{d:?}");
    }

    /// A print on a part of the group only, as a rug's border: a frame of ±30% two pixels wide
    /// around a uniform field, on the smooth shading. Its strokes lie where the model is smooth.
    #[test]
    fn a_print_on_part_of_the_group_is_texture() {
        let border = |x: f32, y: f32| {
            let inside = |a: f32| (a - 32.0).abs() < 20.0;
            let ring = |a: f32| ((a - 32.0).abs() - 16.0).abs() < 1.5;
            (inside(x) && inside(y) && (ring(x) || ring(y))) as u8 as f32
        };
        let rug = run(|x, y, i| {
            let (m, _) = shading(x, y);
            m * (1.0 + 0.3 * border(x, y)) + 0.003 * noise(i, 6)
        });
        assert!(rug.is_texture(0.02), "{rug:?}");
    }

    /// A printed wall under a coat fitted at the roughest α, whose smooth sheen carries most of
    /// the light: no pixel's diffuse term dominates, but the lobe reflects nothing at the
    /// texel scale, so the print is judged (and found) on every pixel; a sharp lobe's
    /// reflection keeps its pixels out.
    #[test]
    fn a_print_under_a_broad_dominant_coat_is_texture() {
        let w = 64;
        let parts = |x: f32, y: f32| {
            let d = 0.1 + 0.001 * x;
            (d, 0.3 + 0.002 * (x + y))
        };
        let print = |x: f32, y: f32| {
            (((x + y) / 6.0 * std::f32::consts::TAU).sin()
                * ((x - y) / 6.0 * std::f32::consts::TAU).sin())
            .signum()
        };
        let (mut model, mut spec, mut photo) = (Vec::new(), Vec::new(), Vec::new());
        for i in 0..w * w {
            let (x, y) = ((i % w) as f32, (i / w) as f32);
            let (d, s) = parts(x, y);
            model.push(Rgb::splat(d + s));
            spec.push(Rgb::splat(s));
            photo.push(d * (1.0 + 0.3 * print(x, y)) + s + 0.002 * noise(i, 7));
        }
        let cache = cache_of(&photo, w);
        let broad = detail(&cache, &model, [&model, &model], &spec, w, true);
        assert!(broad.is_texture(0.02), "{broad:?}");
        let sharp = detail(&cache, &model, [&model, &model], &spec, w, false);
        assert!(!sharp.is_texture(0.02), "{sharp:?}");
    }

    /// A bare texture would replace a mirror's or a metal lobe's reflection, not a Ward lobe's
    /// (level 7 varnishes the texture with it), and only where the reflection carries most of
    /// the light.
    #[test]
    fn a_texture_is_no_answer_where_a_bare_one_would_paint_the_reflection() {
        let model = vec![Rgb::splat(1.0); 8];
        let mostly = vec![Rgb::splat(0.8); 8];
        let little = vec![Rgb::splat(0.1); 8];
        let p = GroupParams {
            alpha_x: 0.1,
            alpha_y: 0.1,
            ..GroupParams::default()
        };
        for level in [Level::DiffuseSpecular, Level::Microfacet, Level::Plastic] {
            assert!(reflection_holds_the_light(level, &p, &model, &mostly), "{level:?}");
            assert!(!reflection_holds_the_light(level, &p, &model, &little), "{level:?}");
        }
        assert!(!reflection_holds_the_light(Level::Isotropic, &p, &model, &mostly));
        assert!(!reflection_holds_the_light(Level::Diffuse, &p, &model, &mostly));
        // A coat at the roughest α reflects nothing in particular: a print may lie under it.
        let broad = GroupParams {
            alpha_x: 1.0,
            alpha_y: 1.0,
            ..p
        };
        assert!(!reflection_holds_the_light(Level::Plastic, &broad, &model, &mostly));
    }

    /// A grooved face (a stair's side): in each one-pixel groove the normals within the pixel
    /// spread, and the model misses the groove's light by an amount that changes along it, so
    /// the residual runs in streaks down the grooves. That is the shading's misfit, not a
    /// print; a print on the same face is one.
    #[test]
    fn streaks_along_grooves_are_not_texture_and_a_print_across_them_is() {
        let w = 64;
        let groove = |i: usize| (i % w).is_multiple_of(6);
        let run = |print: f32| {
            let shade = |i: usize| 0.3 + 0.002 * (i / w) as f32;
            let model: Vec<Rgb> = (0..w * w)
                .map(|i| Rgb::splat(shade(i) * if groove(i) { 0.6 } else { 1.0 }))
                .collect();
            let halves = [0u64, 1].map(|h| {
                (0..w * w)
                    .map(|i| model[i] * (1.0 + 0.02 * noise(i, 20 + h)))
                    .collect::<Vec<Rgb>>()
            });
            let photo: Vec<f32> = (0..w * w)
                .map(|i| {
                    let (x, y) = (i % w, i / w);
                    let misfit = if groove(i) {
                        0.85 + 0.8 * noise(x * 1000 + y / 8, 21)
                    } else {
                        1.0
                    };
                    let p = if (x / 3 + y / 3) % 2 == 0 { 1.0 + print } else { 1.0 - print };
                    model[i].x * misfit * p * (1.0 + 0.02 * noise(i, 22))
                })
                .collect();
            let mut cache = cache_of(&photo, w);
            for (i, p) in cache.pixels.iter_mut().enumerate() {
                p.normal = if groove(i) {
                    Vec3::new(0.3, 0.0, 0.85)
                } else {
                    Vec3::new(0.0, 0.0, 1.0)
                };
            }
            let spec = vec![Rgb::ZERO; w * w];
            detail(&cache, &model, [&halves[0], &halves[1]], &spec, w, false)
        };
        let streaks = run(0.0);
        assert!(!streaks.is_texture(0.02), "{streaks:?}");
        let print = run(0.1);
        assert!(print.is_texture(0.02), "{print:?}");
    }

    /// Stepped faces (a stair's side: a groove every 6 pixels, in the model and in the photo
    /// alike) whose cache holds a few spikes, one half's bright samples 10× the pixel's light:
    /// no texture. The model is right; the spikes are noise.
    #[test]
    fn a_few_bright_samples_on_a_structured_surface_are_not_texture() {
        let w = 64;
        let shade = |i: usize| {
            let (x, y) = ((i % w) as f32, (i / w) as f32);
            let groove = if (x as usize).is_multiple_of(6) { 0.6 } else { 1.0 };
            (0.3 + 0.002 * y) * groove
        };
        let halves: [Vec<Rgb>; 2] = [11u64, 12].map(|seed| {
            (0..w * w)
                .map(|i| {
                    let spike = crate::math::sampler::mix64(i as u64 ^ seed).is_multiple_of(97);
                    let v = shade(i) * (1.0 + 0.2 * noise(i, seed));
                    Rgb::splat(if spike { 10.0 * v } else { v })
                })
                .collect()
        });
        let model: Vec<Rgb> = (0..w * w)
            .map(|i| (halves[0][i] + halves[1][i]) * 0.5)
            .collect();
        let spec = vec![Rgb::ZERO; w * w];
        let photo: Vec<f32> = (0..w * w)
            .map(|i| shade(i) * (1.0 + 0.05 * noise(i, 13)))
            .collect();
        let d = detail(
            &cache_of(&photo, w),
            &model,
            [&halves[0], &halves[1]],
            &spec,
            w,
            false,
        );
        assert!(!d.is_texture(0.02), "{d:?}");
    }

    #[test]
    fn a_misregistered_or_misshaded_uniform_surface_is_not_texture() {
        // The photo of the same surface shifted by 0.7 px: e ≈ −δ·∇m, explained away.
        let shifted = run(|x, y, i| shading(x - 0.7, y + 0.3).0 + 0.003 * noise(i, 3));
        assert!(!shifted.is_texture(0.02), "{shifted:?}");
        assert!(shifted.explained > 0.5, "{shifted:?}");
        // A highlight 30% stronger than the model's and a shading fall-off it does not have.
        let misshaded = run(|x, y, i| {
            let (m, s) = shading(x, y);
            (m + 0.3 * s) * (1.0 + 0.002 * (x - 32.0)) + 0.003 * noise(i, 4)
        });
        assert!(!misshaded.is_texture(0.02), "{misshaded:?}");
    }
}
