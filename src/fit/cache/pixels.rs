//! What a group's incident-radiance cache holds: its pixels, each with its samples and their
//! weights, and what a cache must hold for a group's level (`build.rs` traces it).
//! The model it gives for any BSDF parameters is the one `build.rs` opens with.

use super::pseudo_textures::PseudoMirror;
use crate::math::{Rgb, Vec3};
#[cfg(test)]
use crate::math::Vec2;
#[cfg(test)]
use crate::math::{INV_PI, PI};
use std::sync::Arc;

/// How many samples the cache draws.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize, PartialEq)]
pub struct CacheOptions {
    /// Light samples per pixel.
    pub light_samples: u32,
    /// Indirect (mixture) samples per pixel.
    pub indirect_samples: u32,
    /// Samples of the mirror direction per pixel.
    pub mirror_samples: u32,
    /// At most this many pixels per group (a regular subsample of the usable ones).
    pub max_pixels: usize,
    /// About this many tiles per group: the error is aggregated over tiles (square blocks of
    /// the group's usable pixels), so that tiles grow with the group and noise stays low.
    pub tiles_per_group: usize,
}

impl Default for CacheOptions {
    fn default() -> Self {
        CacheOptions {
            light_samples: 32,
            indirect_samples: 32,
            mirror_samples: 16,
            max_pixels: 12_000,
            tiles_per_group: 48,
        }
    }
}

/// One cached incident sample: the half vector of its directions in the local shading frame of
/// its hit (unrotated by θ), as the lobe's evaluation needs it, and its radiance weight.
pub use crate::render::bsdf::ward::LobeSample as Sample;

/// One cached pixel.
#[derive(Clone, Debug)]
pub struct CachePixel {
    /// Index of the pixel in the image.
    pub pixel: u32,
    /// The photo's value.
    pub photo: Rgb,
    /// D of the module comment, for all samples and for each half.
    pub d: Rgb,
    pub d_half: [Rgb; 2],
    /// Radiance along the mirror direction (all samples, each half).
    pub mirror: Rgb,
    pub mirror_half: [Rgb; 2],
    /// The pixel's samples: half 0 is `samples[start..mid]`, half 1 `samples[mid..end]`.
    pub start: u32,
    pub mid: u32,
    pub end: u32,
    /// Tile for error aggregation.
    pub tile: u32,
    /// The mean of the shading normals (world space) of the pixel's primary hits, not
    /// normalized: shorter than 1 where they face different ways within the pixel (a bevel, a
    /// groove). For the texture gate's test of misfit that follows the surface's shape
    /// (`detail.rs`); zero where unknown.
    pub normal: Vec3,
}

impl CachePixel {
    /// Pixel `pixel` with photo value `photo` and nothing cached (for tests that fill in what
    /// they need).
    #[cfg(test)]
    pub(crate) fn bare(pixel: u32, photo: Rgb) -> CachePixel {
        CachePixel {
            pixel,
            photo,
            d: Rgb::ZERO,
            d_half: [Rgb::ZERO; 2],
            mirror: Rgb::ZERO,
            mirror_half: [Rgb::ZERO; 2],
            start: 0,
            mid: 0,
            end: 0,
            tile: 0,
            normal: Vec3::ZERO,
        }
    }
}

/// The cache of one group.
#[derive(Clone, Debug, Default)]
pub struct GroupCache {
    pub pixels: Vec<CachePixel>,
    /// Shared: a cache copied to refit on other target values (`texture.rs`) keeps its samples.
    pub samples: Arc<[Sample]>,
    pub tiles: usize,
    /// Jittered primary rays that left the group (counted, dropped).
    pub stray: usize,
    /// Per pixel, how each texel of the group's atlas enters its D (when asked for).
    pub texels: Option<TexelRows>,
    /// The image's width (pixel indices are row-major in it); 0 where unknown.
    pub width: usize,
    /// The light each pixel receives by way of the tracked unseen groups (when asked for).
    pub unseen: Option<UnseenShares>,
    /// Per group of the scene, the share of the cached light (all channels' sum) whose indirect
    /// ray first landed on that group: how much this group is lit by each other one
    /// (`schedule::climbers`).
    pub light_from: Vec<f32>,
    /// The cosine-weighted share of the pixels' hemisphere from which nothing of the scene is
    /// seen (their indirect rays that leave it at once, mean over the pixels): what a stray
    /// light would light.
    pub open: f32,
    /// The mirror radiance with the groups still being analysed read from the photo (§5.1,
    /// `pseudo.rs`), when the build was asked for it.
    pub pseudo: Option<PseudoMirror>,
    /// Where the pixels of each further photo begin, when the cache holds several photos'
    /// pixels ([`GroupCache::append`]); empty for one photo. Pixel indices are per photo.
    pub views: Vec<usize>,
}

/// How each pixel of a cache changes with the diffuse reflectance of the unseen groups it
/// tracks (`fit/unseen.rs`): the indirect rays are traced a second time through the scene with
/// one such group's ρd moved ([`UnseenProbe`]), with the same random numbers, so the difference
/// is the derivative of every sample's weight, light that bounced there any number of times and
/// anywhere along the path included (a Lambert surface's ρd does not change the directions a
/// path samples; only Russian roulette, which reads the path's throughput, can end a path
/// differently).
#[derive(Clone, Debug, Default)]
pub struct UnseenShares {
    /// The tracked groups.
    pub groups: Vec<usize>,
    /// Per cached pixel, then per tracked group (`pixel * groups.len() + j`): ∂/∂ρd_u (per
    /// channel) of `CachePixel::d_half`.
    pub d_half: Vec<[Rgb; 2]>,
    /// Per sample of `GroupCache::samples`, then per tracked group: ∂c/∂ρd_u (empty when the
    /// cache keeps no samples).
    pub dc: Vec<Rgb>,
    /// Per cached pixel, then per tracked group: ∂/∂ρd_u of `CachePixel::mirror_half` (zero
    /// where the cache traces no mirror radiance).
    pub mirror_half: Vec<[Rgb; 2]>,
    /// Per cached pixel: whether its derivatives were measured (every [`DERIVATIVE_STRIDE`]-th
    /// pixel; the others' are zero).
    pub probed: Vec<bool>,
}

/// One cached pixel in this many measures the derivatives along the unseen groups: the second
/// trace of its indirect rays is most of their cost, and a tile's sum over every other pixel,
/// scaled, estimates the whole tile's at about half the cost.
pub const DERIVATIVE_STRIDE: usize = 2;

/// `UnseenProbe::group` and `UnseenShares::groups` entry of the stray light.
pub const STRAY_LIGHT: usize = usize::MAX;

/// The textured form of D: a pixel's diffuse radiance is Σ_t ρ_t w_t over the texels its
/// samples' primary hits read (bilinear weight × c / π), so for a texture ρ the pixel is
/// L = Σ_t ρ_t w_t + ρs S: linear in every texel, with no new rays (`fit/texture.rs`).
#[derive(Clone, Debug, Default)]
pub struct TexelRows {
    /// Per cached pixel: its rows of half 0 are `rows[r[0]..r[1]]`, of half 1 `rows[r[1]..r[2]]`.
    pub ranges: Vec<[u32; 3]>,
    /// (texel, weight per channel), raw sums over the half's samples (D = both halves' sum;
    /// a half alone estimates D as twice its sum, as `CachePixel::d_half`).
    pub rows: Vec<(u32, Rgb)>,
    /// Per cached pixel and half, the factor that takes its rows to its neighbourhood's
    /// irradiance (`irradiance.rs`; empty: none). The texture is solved on the rows so
    /// scaled; the error that decides levels reads the rows as sampled, whose noise is that
    /// of every other level's model.
    pub scale: Vec<[Rgb; 2]>,
}

impl TexelRows {
    /// The rows with each pixel's halves multiplied by their `scale` (a copy as they are
    /// where there is none).
    pub fn smoothed(&self) -> TexelRows {
        let mut out = TexelRows {
            ranges: self.ranges.clone(),
            rows: self.rows.clone(),
            scale: Vec::new(),
        };
        for (r, s) in self.ranges.iter().zip(&self.scale) {
            for h in 0..2 {
                for row in &mut out.rows[r[h] as usize..r[h + 1] as usize] {
                    row.1 *= s[h];
                }
            }
        }
        out
    }
}

/// The cached pixels of one image as a grid: a pixel's neighbours are those `stride` image
/// pixels away, `stride` the smallest step between cached pixels of a row (1 for a cache of
/// whole blocks, `build::choose_pixels`).
pub struct PixelGrid {
    /// Per image pixel from `first` on (up to the last cached one), the index of the cached
    /// pixel there plus one, 0 where none is: a lookup is one load, where a hash map of the
    /// cached pixels hashed every neighbour asked for (the texture test and the irradiance
    /// smoothing ask for 8 to 24 per pixel, for every cache with texel rows).
    at: Vec<u32>,
    first: u32,
    pixel: Vec<u32>,
    width: i64,
    /// Image pixels between neighbouring cached pixels.
    stride: i64,
}

impl PixelGrid {
    /// The grid of `pixels` (all of one image `width` pixels wide).
    pub fn new(pixels: &[CachePixel], width: usize) -> PixelGrid {
        let stride = pixels
            .windows(2)
            .filter(|w| w[1].pixel / width as u32 == w[0].pixel / width as u32)
            .map(|w| (w[1].pixel - w[0].pixel) as i64)
            .min()
            .unwrap_or(1)
            .max(1);
        let first = pixels.iter().map(|p| p.pixel).min().unwrap_or(0);
        let last = pixels.iter().map(|p| p.pixel).max().unwrap_or(0);
        let mut at = vec![0u32; if pixels.is_empty() { 0 } else { (last - first) as usize + 1 }];
        // A pixel listed twice is found at its last index, as a map built in this order finds it.
        for (k, p) in pixels.iter().enumerate() {
            at[(p.pixel - first) as usize] = k as u32 + 1;
        }
        PixelGrid {
            at,
            first,
            pixel: pixels.iter().map(|p| p.pixel).collect(),
            width: width.max(1) as i64,
            stride,
        }
    }

    /// Cached pixel `k`'s position in grid steps (column, row).
    pub fn position(&self, k: usize) -> (i64, i64) {
        let p = self.pixel[k] as i64;
        (p % self.width / self.stride, p / self.width / self.stride)
    }

    /// The cached pixel `dx`, `dy` grid steps from cached pixel `k`, if there is one.
    pub fn neighbour(&self, k: usize, dx: i64, dy: i64) -> Option<usize> {
        let p = self.pixel[k] as i64;
        let (x, y) = (
            p % self.width + dx * self.stride,
            p / self.width + dy * self.stride,
        );
        if x < 0 || y < 0 || x >= self.width {
            return None;
        }
        let q = (y * self.width + x) as u32;
        let slot = q.checked_sub(self.first)? as usize;
        match self.at.get(slot) {
            Some(&k) if k > 0 => Some(k as usize - 1),
            _ => None,
        }
    }
}

impl GroupCache {
    /// The pixels of the first photo (all of them for a cache of one photo).
    pub fn first_view(&self) -> &[CachePixel] {
        &self.pixels[..self.views.first().copied().unwrap_or(self.pixels.len())]
    }

    /// Which photo cached pixel `k` belongs to (0: the first).
    pub fn view_of(&self, k: usize) -> usize {
        self.views.partition_point(|&start| start <= k)
    }

    /// Adds the cache of the same group in a further photo, whose values are divided by that
    /// photo's exposure factor `exposure` (its photo = exposure × the scene's radiance). Its
    /// tiles follow this cache's, so the error weighs every photo's tiles alike. The parts
    /// that read pixels of one image (the pseudo-textured mirror radiance) are dropped.
    pub fn append(&mut self, other: GroupCache, exposure: f32) {
        let (base, tiles, rows) = (
            self.samples.len() as u32,
            self.tiles as u32,
            self.texels.as_ref().map_or(0, |t| t.rows.len() as u32),
        );
        let (n0, n1) = (self.pixels.len() as f32, other.pixels.len() as f32);
        self.views.push(self.pixels.len());
        self.pixels
            .extend(other.pixels.into_iter().map(|p| CachePixel {
                photo: p.photo / exposure,
                start: p.start + base,
                mid: p.mid + base,
                end: p.end + base,
                tile: p.tile + tiles,
                ..p
            }));
        self.samples = self
            .samples
            .iter()
            .chain(other.samples.iter())
            .copied()
            .collect();
        self.tiles += other.tiles;
        self.stray += other.stray;
        self.texels = match (self.texels.take(), other.texels) {
            (Some(mut a), Some(b)) => {
                let (na, nb) = (a.ranges.len(), b.ranges.len());
                if !(a.scale.is_empty() && b.scale.is_empty()) {
                    a.scale.resize(na, [Rgb::ONE; 2]);
                    a.scale.extend(b.scale);
                    a.scale.resize(na + nb, [Rgb::ONE; 2]);
                }
                a.ranges
                    .extend(b.ranges.iter().map(|r| r.map(|i| i + rows)));
                a.rows.extend(b.rows);
                Some(a)
            }
            _ => None,
        };
        self.unseen = match (self.unseen.take(), other.unseen) {
            (Some(mut a), Some(b)) if a.groups == b.groups => {
                a.d_half.extend(b.d_half);
                a.dc.extend(b.dc);
                a.mirror_half.extend(b.mirror_half);
                a.probed.extend(b.probed);
                Some(a)
            }
            _ => None,
        };
        if n0 + n1 > 0.0 {
            for (a, b) in self.light_from.iter_mut().zip(&other.light_from) {
                *a = (*a * n0 + b * n1) / (n0 + n1);
            }
            self.open = (self.open * n0 + other.open * n1) / (n0 + n1);
        }
        self.pseudo = None;
    }

    /// The pixels of the even and of the odd tiles as two caches (their samples copied, tiles
    /// renumbered). Tiles are numbered in scan order, so the two interleave over the group: a
    /// model fitted on one half is judged on pixels it has not seen but that see the same
    /// lights (see `hierarchy::predicts`).
    pub fn split_tiles(&self) -> [GroupCache; 2] {
        let mut out: [GroupCache; 2] = Default::default();
        let mut samples: [Vec<Sample>; 2] = Default::default();
        for p in &self.pixels {
            let (c, samples) = (
                &mut out[(p.tile % 2) as usize],
                &mut samples[(p.tile % 2) as usize],
            );
            let base = samples.len() as u32;
            samples.extend_from_slice(&self.samples[p.start as usize..p.end as usize]);
            c.pixels.push(CachePixel {
                start: base,
                mid: base + (p.mid - p.start),
                end: base + (p.end - p.start),
                tile: p.tile / 2,
                ..p.clone()
            });
        }
        out[0].tiles = self.tiles.div_ceil(2);
        out[1].tiles = self.tiles / 2;
        for (c, s) in out.iter_mut().zip(samples) {
            c.samples = s.into();
        }
        out
    }
}

/// How many more mirror samples a group at a mirror level draws (`CacheNeeds::mirror_fitted`).
pub const MIRROR_LEVEL_FACTOR: u32 = 4;

/// Which parts a cache needs: D alone suffices for a group confirmed at level 1.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub struct CacheNeeds {
    pub lobe_samples: bool,
    pub mirror: bool,
    /// The group is at a mirror level: its ρs is fitted from the mirror radiance, whose noise
    /// then sets its error, so that is traced with `MIRROR_LEVEL_FACTOR` × the samples (a
    /// climbing group only needs the level decided).
    pub mirror_fitted: bool,
    /// The texel rows of D (a textured group, or one that may climb to the textured level).
    pub texels: bool,
    /// The rows' smoothing factors (`TexelRows::scale`): a group at the textured level. A
    /// climb's cache has none: there the varnish is weighed against the bare texture, and a
    /// bare texture solved on smoothed rows fitted a highlight so much better than the varnish
    /// under a climb cache's noisy lobe refit that the poster scene's desk lost its varnish.
    pub smoothed_irradiance: bool,
}

impl CacheNeeds {
    /// Mirror samples per pixel and half.
    pub fn mirror_samples_per_half(&self, opts: &CacheOptions) -> u32 {
        let factor = if self.mirror_fitted {
            MIRROR_LEVEL_FACTOR
        } else {
            1
        };
        (opts.mirror_samples * factor).max(2).div_ceil(2)
    }

    /// The mixture's cosine weight: a group that only needs D (diffuse, not climbing) draws its
    /// indirect directions by cosine alone, which has the lowest variance for it.
    pub fn cosine_weight(&self) -> f32 {
        if self.lobe_samples || self.mirror {
            super::mixture::DEFENSIVE_COSINE_WEIGHT
        } else {
            1.0
        }
    }
}

/// D of the cache's model (Σ c / π) for the reference samples [`synthetic_cache`] hands to its
/// photo function: a Lambert surface's radiance per unit ρd.
#[cfg(test)]
pub(crate) fn synthetic_diffuse(s: &[(Vec3, Vec3, Rgb)]) -> Rgb {
    s.iter().fold(Rgb::ZERO, |a, x| a + x.2) * INV_PI
}

/// A cache built without a scene, for tests of the fit: `n` pixels of `per_half` samples in
/// each half, each pixel seen from a random direction under a sky with a bright region (so
/// that lobes matter), directions cosine-sampled with weight c = π L / N, `tiles` tiles. The
/// photo is `photo(pixel, reference)`, where `reference` are 64 times as many samples of the
/// same sky drawn independently of the cached ones (a photo's noise is independent of the
/// cache's), each `(ωo, ωi, c)`: a material's radiance is Σ f(ωo, ωi) c.
#[cfg(test)]
pub(crate) fn synthetic_cache(
    n: usize,
    per_half: usize,
    tiles: usize,
    seed: u64,
    photo: impl Fn(&CachePixel, &[(Vec3, Vec3, Rgb)]) -> Rgb,
) -> GroupCache {
    use crate::math::sampler::TestRng;
    let mut rng = TestRng(seed);
    let mut cache = GroupCache {
        tiles,
        ..Default::default()
    };
    let mut samples: Vec<Sample> = Vec::new();
    let sun = Vec3::new(0.3, -0.2, 0.9).normalize();
    let draw = |rng: &mut TestRng, wo: Vec3, count: usize| -> Vec<(Vec3, Vec3, Rgb)> {
        (0..count)
            .map(|_| {
                let wi = crate::math::warp::cosine_hemisphere(Vec2::new(rng.f32(), rng.f32()));
                let l = 0.3 + 3.0 * wi.dot(sun).max(0.0).powi(8);
                (wo, wi, Rgb::new(l, 0.8 * l, 0.6 * l) * (PI / count as f32))
            })
            .collect()
    };
    for i in 0..n {
        let wo = Vec3::new(rng.f32() - 0.5, rng.f32() - 0.5, 0.4 + rng.f32()).normalize();
        let start = samples.len() as u32;
        let raw = draw(&mut rng, wo, 2 * per_half);
        let mut d_half = [Rgb::ZERO; 2];
        for (k, &(wo, wi, c)) in raw.iter().enumerate() {
            samples.push(Sample::new(wo, wi, c));
            d_half[k / per_half] += c * INV_PI;
        }
        let m = Rgb::splat(0.5 + rng.f32());
        let mut p = CachePixel {
            pixel: i as u32,
            photo: Rgb::ZERO,
            d: d_half[0] + d_half[1],
            d_half: [d_half[0] * 2.0, d_half[1] * 2.0],
            mirror: m,
            mirror_half: [m * 0.98, m * 1.02],
            start,
            mid: start + per_half as u32,
            end: start + 2 * per_half as u32,
            tile: (i * tiles / n) as u32,
            normal: Vec3::ZERO,
        };
        let reference = draw(&mut rng, wo, 128 * per_half);
        p.photo = photo(&p, &reference);
        cache.pixels.push(p);
    }
    cache.samples = samples.into();
    cache
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The neighbours as a hash map of the cached pixels finds them (the grid's former form).
    fn neighbour_by_map(pixels: &[CachePixel], grid: &PixelGrid, k: usize, dx: i64, dy: i64) -> Option<usize> {
        let at: std::collections::HashMap<u32, usize> =
            pixels.iter().enumerate().map(|(k, p)| (p.pixel, k)).collect();
        let p = pixels[k].pixel as i64;
        let (x, y) = (p % grid.width + dx * grid.stride, p / grid.width + dy * grid.stride);
        if x < 0 || y < 0 || x >= grid.width {
            return None;
        }
        at.get(&((y * grid.width + x) as u32)).copied()
    }

    #[test]
    fn the_grid_finds_the_neighbours_a_map_of_the_pixels_finds() {
        let width = 37usize;
        // Whole blocks, a strided lattice, and scattered pixels near the image's edges.
        let sets: Vec<Vec<u32>> = vec![
            (0..width as u32 * 20).filter(|p| (p % 37) % 8 < 5 && (p / 37) % 8 < 5).collect(),
            (0..width as u32 * 30).filter(|p| (p % 37) % 3 == 1 && (p / 37) % 3 == 2).collect(),
            vec![0, 1, 36, 37, 38, 73, 74, 500, 501, 1100],
            vec![400],
            Vec::new(),
        ];
        for set in sets {
            let pixels: Vec<CachePixel> =
                set.iter().map(|&p| CachePixel::bare(p, Rgb::ZERO)).collect();
            let grid = PixelGrid::new(&pixels, width);
            for k in 0..pixels.len() {
                for dy in -3..=3 {
                    for dx in -3..=3 {
                        assert_eq!(
                            grid.neighbour(k, dx, dy),
                            neighbour_by_map(&pixels, &grid, k, dx, dy),
                            "pixel {} step ({dx}, {dy})",
                            pixels[k].pixel
                        );
                    }
                }
            }
        }
    }
}
