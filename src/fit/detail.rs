//! Texel-scale structure in the residual of a group's uniform model: the texture threshold of
//! Algorithm 1 on what the error metric cannot see (its tiles average fine detail away), asked
//! so that only a texture explains what it finds.
//!
//! The residual e = photo − model (mean of the channels) is high-passed, HP(v)ₖ = vₖ − the mean
//! of v over the 5×5 neighbourhood of cached pixels, which removes every smooth misfit: a wrong
//! fall-off of n·l, of the view angle or of the indirect light. What remains and is not texture
//! is sharp misfit that follows the model's own features, so HP(e) is regressed (least squares
//! over the group) on
//!
//!   HP(m), HP(∂ₓm), HP(∂ᵧm), HP(∂ₓₓm), HP(∂ᵧᵧm), HP(∂ₓᵧm), and the same of s
//!
//! with m the model's radiance and s its specular part: a registration off by δ leaves
//! e ≈ −δ·∇m, a highlight too strong or misplaced leaves e ≈ a·s + b·∇s, a lobe a little too
//! rough or too sharp blurs or sharpens the reflections it holds (e ≈ c·∇²s, per axis for an
//! anisotropic one), and none of them survives.
//! A printed pattern is uncorrelated with all six and survives whole. The statistic is the
//! covariance c₁ of neighbouring pixels' remaining residuals (horizontal and vertical pairs):
//! independent per-pixel noise (the photo's, the cache's) contributes nothing to it (slightly
//! less), while a texture's strokes span neighbouring pixels. It is taken over the pixels where
//! the model's diffuse term is at least its specular one: a print is a diffuse reflectance,
//! and where a glossy surface shows a bright reflection its residual is that reflection's
//! misfit. Reported are √c₁ as a fraction of those pixels' mean radiance, and c₁'s z-score
//! against its own standard error, so a texture is tried only where the structure is both large
//! and certain.
//!
//! Neighbours are those of the cache's pixel grid: within a subsampled cache's blocks they are
//! the image's own pixels (`cache::choose_pixels`).

use super::cache::{GroupCache, PixelGrid};
use super::level::Level;
use super::params::GroupParams;
use crate::math::Rgb;
use crate::scene::WardVariant;

/// Below this z-score the structure is not told from noise.
pub const MIN_Z: f32 = 4.0;

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

/// The detail a uniform level's model with `params` leaves on `cache`. Zero at level 7.
pub fn uniform_detail(
    cache: &GroupCache,
    level: Level,
    params: &GroupParams,
    variant: WardVariant,
) -> Detail {
    if level == Level::Textured {
        return Detail::default();
    }
    let (model, spec) = super::texture::uniform_parts(cache, level, params, variant);
    detail(cache, &model, &spec, cache.width)
}

/// The module's statistic for `model` (and its specular part `spec`) per cached pixel.
pub fn detail(cache: &GroupCache, model: &[Rgb], spec: &[Rgb], width: usize) -> Detail {
    // Neighbours are those of one image: a cache of several photos is judged on its first.
    let n = cache.first_view().len();
    if n < 16 || width == 0 {
        return Detail::default();
    }
    let grid = PixelGrid::new(cache.first_view(), width);
    let lum = |c: Rgb| (c.x + c.y + c.z) / 3.0;
    let e: Vec<f32> = (0..n)
        .map(|k| lum(cache.pixels[k].photo - model[k]))
        .collect();
    let m: Vec<f32> = model[..n].iter().map(|&c| lum(c)).collect();
    let s: Vec<f32> = spec[..n].iter().map(|&c| lum(c)).collect();
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
    let y = high_pass(&e);
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
    let r = regress_out(&y, &features);
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
    let diffuse = |k: usize| s[k] <= m[k] - s[k];
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

/// `y` minus its least-squares projection on `features` (a tiny ridge keeps a feature that is
/// zero or repeats another from making the normal matrix singular).
fn regress_out(y: &[f32], features: &[Vec<f32>]) -> Vec<f32> {
    let p = features.len();
    let mut a = vec![vec![0.0f64; p]; p];
    let mut b = vec![0.0f64; p];
    for k in 0..y.len() {
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
    let Some(inv) = super::solve::invert(&a) else {
        return y.to_vec();
    };
    let beta: Vec<f64> = (0..p)
        .map(|i| (0..p).map(|j| inv[i][j] * b[j]).sum())
        .collect();
    (0..y.len())
        .map(|k| y[k] - (0..p).map(|i| beta[i] * features[i][k] as f64).sum::<f64>() as f32)
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fit::cache::CachePixel;

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
        detail(&cache_of(&photo, w), &model, &spec, w)
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
