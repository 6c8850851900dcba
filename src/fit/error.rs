//! The error metric, the one measure of how far a model is from the photo (docs/DESIGN.md,
//! "Error"), used on a group's cache while fitting and on the final render.
//!
//! ε = Σ|L_syn − L_photo| / Σ L_photo over a group's usable pixels and the three channels. To keep
//! Monte Carlo noise from deciding hypotheses, both images are first summed over small tiles of
//! the group's pixels, which averages noise away while a wrong model's systematic error (a
//! missing highlight) stays. The **noise floor** is the same metric between two independent
//! halves of the synthetic image's samples, halved (each half has twice the variance of the
//! whole; their difference four times). The tiling is the caller's: the cache's tiles grow with
//! the group (`cache::choose_pixels`); the final render uses squares of [`block_side`] pixels.

use crate::math::Rgb;

/// The error of a model: ε, the noise floor, and ε of each half of the samples alone (for
/// paired comparisons of two models on the same samples).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ErrorStats {
    pub error: f32,
    pub noise_floor: f32,
    pub halves: [f32; 2],
}

/// What one pixel contributes: the synthetic value, the photo's, and the synthetic value from
/// each half of the samples alone.
#[derive(Clone, Copy, Debug)]
pub struct PixelTerms {
    pub syn: Rgb,
    pub photo: Rgb,
    pub halves: [Rgb; 2],
}

/// Side in pixels of the square tiles of a 64-spp image's error.
pub const BLOCK: usize = 4;

/// Side in pixels of the error's tiles on an image of `spp` samples per pixel: [`BLOCK`] from 64
/// spp up, larger below so that a tile still holds BLOCK²·64 = 1,024 samples or more. The noise
/// that a tile's sum leaves in ε then does not grow as the samples per pixel fall, so ε and its
/// noise floor mean the same at any spp.
pub fn block_side(spp: u32) -> usize {
    let mut k = 1;
    while (k * k) as u64 * (spp as u64) < 64 {
        k += 1;
    }
    BLOCK * k
}

/// The tile of image pixel `i` among `side`-pixel squares of an image `width` wide, numbered
/// row by row.
pub fn block_tile(i: usize, width: usize, side: usize) -> usize {
    (i / width / side) * width.div_ceil(side) + (i % width) / side
}

/// The number of [`block_tile`]s of a `width` × `height` image.
pub fn block_tiles(width: usize, height: usize, side: usize) -> usize {
    width.div_ceil(side) * height.div_ceil(side)
}

/// ε, the noise floor and the halves' ε of `pixels` (each with its tile index, below `n_tiles`).
/// None when the photo holds no light there (no pixels, or all black); all NaN when its sum is
/// not finite (NaN or infinite values, or a sum that overflowed), which must not pass for ε = 0.
pub fn tiled_error(
    n_tiles: usize,
    pixels: impl IntoIterator<Item = (usize, PixelTerms)>,
) -> Option<ErrorStats> {
    let mut syn = vec![Rgb::ZERO; n_tiles];
    let mut photo = vec![Rgb::ZERO; n_tiles];
    let mut halves = [vec![Rgb::ZERO; n_tiles], vec![Rgb::ZERO; n_tiles]];
    for (t, p) in pixels {
        syn[t] += p.syn;
        photo[t] += p.photo;
        for h in 0..2 {
            halves[h][t] += p.halves[h];
        }
    }
    let total: f32 = photo.iter().map(|c| c.x + c.y + c.z).sum();
    if !total.is_finite() {
        return Some(ErrorStats {
            error: f32::NAN,
            noise_floor: f32::NAN,
            halves: [f32::NAN; 2],
        });
    }
    if !(total > 0.0) {
        return None;
    }
    let l1 = |a: &[Rgb], b: &[Rgb]| {
        a.iter()
            .zip(b)
            .map(|(x, y)| (*x - *y).abs())
            .map(|d| d.x + d.y + d.z)
            .sum::<f32>()
    };
    Some(ErrorStats {
        error: l1(&syn, &photo) / total,
        noise_floor: 0.5 * l1(&halves[0], &halves[1]) / total,
        halves: [
            l1(&halves[0], &photo) / total,
            l1(&halves[1], &photo) / total,
        ],
    })
}

/// The photo's own noise in ε's units: the ε a model free of misfit would still leave from the
/// photo's noise alone, which the noise floor (the synthetic image's) does not hold. Residual
/// differences of neighbouring pixels `pairs` (indices into `pixels`), taken against each half
/// of the samples, Δr₀ = Δ(photo − half₀) and Δr₁ = Δ(photo − half₁), have the expected product
/// 2σ² + (Δmisfit)²: the halves' noise is independent and drops out, a smooth misfit barely
/// differs between neighbours, and what remains is the photo's per-pixel variance σ². Pooled
/// over the group as a variance per unit of the photo's value (shot noise's law; a tile's own
/// few products are too noisy to take a root of), a tile of photo sum P has variance κP, and as
/// for the floor, Gaussian noise of variance V adds √(2V/π) to Σ|r|. None without pairs or
/// light.
pub fn photo_noise(
    n_tiles: usize,
    pixels: &[(usize, PixelTerms)],
    pairs: &[(usize, usize)],
) -> Option<f32> {
    let total: f32 = pixels.iter().map(|(_, p)| p.photo.x + p.photo.y + p.photo.z).sum();
    if pairs.is_empty() || !(total > 0.0) || !total.is_finite() {
        return None;
    }
    let (mut variance, mut light) = (Rgb::ZERO, Rgb::ZERO);
    for &(a, b) in pairs {
        let (p, q) = (&pixels[a].1, &pixels[b].1);
        let d = |h: usize| (p.photo - p.halves[h]) - (q.photo - q.halves[h]);
        variance += d(0) * d(1);
        light += p.photo + q.photo;
    }
    let kappa = variance / light;
    let mut tile_light = vec![Rgb::ZERO; n_tiles];
    for (t, p) in pixels {
        tile_light[*t] += p.photo;
    }
    let root = |v: f32| (2.0 * v.max(0.0) / std::f32::consts::PI).sqrt();
    let noise: f32 = (tile_light.iter().map(|&l| l * kappa))
        .map(|v| root(v.x) + root(v.y) + root(v.z))
        .sum();
    noise.is_finite().then_some(noise / total)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn px(syn: f32, photo: f32, h0: f32, h1: f32) -> PixelTerms {
        PixelTerms {
            syn: Rgb::splat(syn),
            photo: Rgb::splat(photo),
            halves: [Rgb::splat(h0), Rgb::splat(h1)],
        }
    }

    /// A 64×64 group in 8×8 tiles whose model misses by a smooth 0–5% ramp, with noise of
    /// its own in each half: the photo's noise is measured as the ε it alone adds, and a
    /// photo without noise has next to none beside the floor, whatever the model's noise and
    /// misfit.
    #[test]
    fn the_photo_noise_is_what_its_own_noise_adds_and_not_the_models() {
        use crate::math::sampler::{mix64, unit_f32};
        let (side, tile) = (64usize, 8usize);
        let run = |noise: f32| {
            let mut key = 7u64;
            let mut uniform = |a: f32| {
                key += 1;
                a * (2.0 * unit_f32(mix64(key)) - 1.0)
            };
            let mut pixels = Vec::new();
            let mut pairs = Vec::new();
            for y in 0..side {
                for x in 0..side {
                    let truth = 1.0 + 0.3 * (x as f32 / 9.0).sin() * (y as f32 / 13.0).cos();
                    let model = truth * (1.0 + 0.05 * x as f32 / side as f32);
                    let halves = [model + uniform(0.3), model + uniform(0.3)];
                    let p = px(
                        0.5 * (halves[0] + halves[1]),
                        truth + uniform(noise),
                        halves[0],
                        halves[1],
                    );
                    let k = pixels.len();
                    pixels.push(((y / tile) * (side / tile) + x / tile, p));
                    if x + 1 < side {
                        pairs.push((k, k + 1));
                    }
                    if y + 1 < side {
                        pairs.push((k, k + side));
                    }
                }
            }
            let tiles = side * side / (tile * tile);
            let total: f32 = pixels.iter().map(|(_, p)| 3.0 * p.photo.x).sum();
            let floor = tiled_error(tiles, pixels.iter().copied()).unwrap().noise_floor;
            (photo_noise(tiles, &pixels, &pairs).unwrap(), total, floor)
        };
        // Uniform noise of half-width a has variance a²/3; a tile sums 64 pixels.
        let a = 0.2f32;
        let (noisy, total, _) = run(a);
        let tiles = (side * side / (tile * tile)) as f32;
        let want = 3.0 * tiles * (2.0 * 64.0 * a * a / 3.0 / std::f32::consts::PI).sqrt() / total;
        assert!((noisy / want - 1.0).abs() < 0.1, "{noisy} for {want}");
        // Without noise in the photo, what the estimate's own noise leaves adds under 5% to
        // the noise that ε is judged against (in quadrature with the floor).
        let (quiet, _, floor) = run(0.0);
        assert!(quiet * quiet < 0.05 * floor * floor, "{quiet} for none (floor {floor})");
        assert_eq!(photo_noise(1, &[], &[]), None);
    }

    #[test]
    fn tiles_cancel_noise_within_them_and_the_metric_matches_its_definition() {
        // Two pixels of one tile over- and under-shoot by the same amount: ε = 0 on one tile,
        // 2·0.1 / (2·0.5) = 0.2 on two.
        let pixels = [(0, px(0.6, 0.5, 0.7, 0.5)), (0, px(0.4, 0.5, 0.3, 0.5))];
        let one = tiled_error(1, pixels).unwrap();
        assert_eq!(one.error, 0.0);
        let two = tiled_error(2, [(0, pixels[0].1), (1, pixels[1].1)]).unwrap();
        assert!((two.error - 0.2).abs() < 1e-6, "{two:?}");
        // Noise floor: ½ Σ|h0 − h1| / Σ photo = ½ · 3·(0.2 + 0.2) / (3·1.0) = 0.2.
        assert!((two.noise_floor - 0.2).abs() < 1e-6, "{two:?}");
        assert!((two.halves[0] - 0.4).abs() < 1e-6 && two.halves[1] == 0.0);
        assert_eq!(tiled_error(3, []), None);
        assert_eq!(tiled_error(1, [(0, px(1.0, 0.0, 1.0, 1.0))]), None);
        assert!(tiled_error(1, [(0, px(1.0, f32::INFINITY, 1.0, 1.0))])
            .unwrap()
            .error
            .is_nan());
    }

    #[test]
    fn block_tiles_number_every_square_once() {
        let (w, h) = (10, 7);
        let n = block_tiles(w, h, BLOCK);
        assert_eq!(n, 3 * 2);
        let mut seen = vec![0; n];
        for i in 0..w * h {
            seen[block_tile(i, w, BLOCK)] += 1;
        }
        // 4×4, 4×4, 2×4 on the first row of tiles; 4×3, 4×3, 2×3 on the second.
        assert_eq!(seen, [16, 16, 8, 12, 12, 6]);
        // 8-pixel squares: 8×7 and 2×7.
        let mut seen = vec![0; block_tiles(w, h, 8)];
        for i in 0..w * h {
            seen[block_tile(i, w, 8)] += 1;
        }
        assert_eq!(seen, [56, 14]);
    }

    #[test]
    fn a_tile_holds_at_least_a_64_spp_blocks_samples() {
        for spp in 1..200u32 {
            let side = block_side(spp);
            let samples = side * side * spp as usize;
            assert!(samples >= BLOCK * BLOCK * 64, "{spp} spp: side {side}");
            // The smallest such square (of a whole multiple of BLOCK).
            let smaller = (side - BLOCK).pow(2) * spp as usize;
            assert!(
                side == BLOCK || smaller < BLOCK * BLOCK * 64,
                "{spp} spp: side {side}"
            );
        }
        assert_eq!((block_side(64), block_side(16), block_side(2)), (4, 8, 24));
    }
}
