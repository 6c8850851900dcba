//! A textured group's cached irradiance, averaged over neighbouring pixels.
//!
//! A pixel's texel rows (`cache::TexelRows`) are the light its samples brought, spread over the
//! texels their hits read: w_pt = Σ_s b_t(x_s) c_s / π, whose total over t is the pixel's
//! irradiance E_p / π (times the share of its samples that landed on the group). That total is
//! estimated from the pixel's own few hundred samples, and a texel, fitted from the one or two
//! pixels that see it, inherits its noise whole. But the irradiance, unlike the texture, is
//! smooth across a surface except at shadow edges and creases, so it can be averaged over
//! neighbouring pixels without blurring the texture at all: each pixel's rows are rescaled to
//! a weighted mean of its neighbours' irradiance, and keep their own split among the texels.
//!
//! The weights are a bilateral filter with a range term scaled by the estimates' own noise,
//! in the manner of Rousselle, Knaus & Zwicker 2012 ("Adaptive rendering with non-local means
//! filtering"): a neighbour counts fully while its irradiance differs from the pixel's by
//! no more than the noise of that difference (from the spread of the two halves' estimates),
//! and fades fast beyond it, so a shadow edge, or a face of the group turned another way, is
//! not averaged across. Each half is averaged from the same half of its neighbours (with
//! weights from both).
//!
//! Only the texture is solved on the smoothed rows; the error that weighs levels against each
//! other reads the rows as sampled, like every other level's model (`texture::fit_textured`).

use super::pixels::{CachePixel, PixelGrid, TexelRows};
use crate::math::Rgb;

/// Neighbours within this many grid steps (either way, in x and y) are averaged.
pub const RADIUS: i64 = 2;

/// The spatial weight's width: exp(−d² / 2σ²) at d grid steps.
pub const SPATIAL_SIGMA: f32 = 1.5;

/// A neighbour lends its irradiance only if at least this share of its samples (in each half)
/// landed on the group: one at the group's silhouette estimates it from a few samples.
pub const MIN_COVERAGE: f32 = 0.5;

/// The range weight's tolerance k: exp(−max(0, Δ² − v) / k²v) for a difference Δ whose noise
/// variance is v.
pub const RANGE: f32 = 2.0;

/// Per pixel and half, the factor that takes the texel rows of `pixels` (one image `width`
/// pixels wide; `coverage[k][h]` the share of pixel k's half-h samples that hit the group) to
/// their neighbourhood's irradiance (`TexelRows::scale`).
pub fn smoothing_scale(
    rows: &TexelRows,
    pixels: &[CachePixel],
    coverage: &[[f32; 2]],
    width: usize,
) -> Vec<[Rgb; 2]> {
    let n = pixels.len();
    if n == 0 || rows.ranges.len() != n || coverage.len() != n {
        return Vec::new();
    }
    let grid = PixelGrid::new(pixels, width);
    let lum = |c: Rgb| c.x + c.y + c.z;
    // Per pixel and half: the rows' total R and the irradiance R / coverage.
    let total = |k: usize, h: usize| -> Rgb {
        let r = rows.ranges[k];
        rows.rows[r[h] as usize..r[h + 1] as usize]
            .iter()
            .fold(Rgb::ZERO, |a, x| a + x.1)
    };
    let sums: Vec<[Rgb; 2]> = (0..n).map(|k| [total(k, 0), total(k, 1)]).collect();
    // A pixel with a half or a channel that no light reached (deep shadow, few samples) is
    // left as it is: it could not be rescaled in that half or channel alone.
    let irradiance: Vec<Option<[Rgb; 2]>> = (0..n)
        .map(|k| {
            let (c, r) = (coverage[k], sums[k]);
            let lit = (0..2).all(|h| c[h] > 0.0 && (0..3).all(|ch| r[h][ch] > 0.0));
            lit.then(|| [r[0] / c[0], r[1] / c[1]])
        })
        .collect();
    let lends =
        |j: usize| irradiance[j].is_some() && coverage[j].iter().all(|&c| c >= MIN_COVERAGE);
    // The mean's luminance and its variance, (E⁰ − E¹)² / 4 for the mean of two halves,
    // averaged over the neighbourhood (one pixel's is a single degree of freedom).
    let value: Vec<f32> = irradiance
        .iter()
        .map(|e| e.map_or(0.0, |[a, b]| 0.5 * lum(a + b)))
        .collect();
    let spread: Vec<f32> = irradiance
        .iter()
        .map(|e| e.map_or(0.0, |[a, b]| 0.25 * (lum(a) - lum(b)).powi(2)))
        .collect();
    // Each pixel's neighbours with an estimate, and their spatial weights exp(−d² / 2σ²).
    let windows: Vec<Vec<(usize, f32)>> = (0..n)
        .map(|k| {
            let mut w = Vec::new();
            for dy in -RADIUS..=RADIUS {
                for dx in -RADIUS..=RADIUS {
                    let Some(j) = grid.neighbour(k, dx, dy) else {
                        continue;
                    };
                    if j == k || lends(j) {
                        let d2 = (dx * dx + dy * dy) as f32;
                        w.push((j, (-d2 / (2.0 * SPATIAL_SIGMA * SPATIAL_SIGMA)).exp()));
                    }
                }
            }
            w
        })
        .collect();
    let variance: Vec<f32> = (0..n)
        .map(|k| {
            let w = &windows[k];
            w.iter().map(|&(j, _)| spread[j]).sum::<f32>() / w.len().max(1) as f32
        })
        .collect();
    let mut scale = vec![[Rgb::ONE; 2]; n];
    for k in 0..n {
        if irradiance[k].is_none() || windows[k].len() < 2 {
            continue;
        }
        let mut acc = [Rgb::ZERO; 2];
        let mut weight = 0.0f32;
        for &(j, spatial) in &windows[k] {
            // d² = ((E_k − E_j)² − (v_k + v_j)) / (v_k + v_j): zero while the difference is
            // within its noise.
            let v = variance[k] + variance[j];
            let diff = (value[k] - value[j]).powi(2);
            let range = if j == k {
                1.0
            } else if v > 0.0 {
                (-((diff - v) / (RANGE * RANGE * v)).max(0.0)).exp()
            } else if diff == 0.0 {
                1.0
            } else {
                0.0
            };
            let w = spatial * range;
            let e = irradiance[j].unwrap();
            acc[0] += e[0] * w;
            acc[1] += e[1] * w;
            weight += w;
        }
        for h in 0..2 {
            scale[k][h] = acc[h] / weight * coverage[k][h] / sums[k][h];
        }
    }
    scale
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::sampler::TestRng;

    /// A 40×30 image of one group whose irradiance is a smooth gradient with a shadow edge
    /// (×0.3 for x ≥ 20), each pixel's halves estimating it with 10% noise and spread over two
    /// texels (0.7 and 0.3 of it). One pixel in five lies partly off the group (coverage 0.6
    /// in half 0, 0.4 in half 1). Returns the true irradiance, the coverage, the pixels and
    /// the rows.
    #[allow(clippy::type_complexity)]
    fn shadowed(seed: u64) -> (Vec<f32>, Vec<[f32; 2]>, Vec<CachePixel>, TexelRows) {
        let (w, h) = (40usize, 30usize);
        let mut rng = TestRng(seed);
        // Uniform noise of unit variance (sum of three, centred, scaled).
        let mut noise = || ((rng.f32() + rng.f32() + rng.f32()) - 1.5) * 2.0;
        let (mut truth, mut coverage, mut pixels) = (Vec::new(), Vec::new(), Vec::new());
        let mut rows = TexelRows::default();
        for y in 0..h {
            for x in 0..w {
                let e =
                    (1.0 + 0.01 * x as f32 + 0.005 * y as f32) * if x >= 20 { 0.3 } else { 1.0 };
                let k = pixels.len() as u32;
                let c = if k % 5 == 2 { [0.6, 0.4] } else { [1.0, 1.0] };
                let mut range = [rows.rows.len() as u32, 0, 0];
                for half in 0..2 {
                    let v = 0.5 * e * c[half] * (1.0 + 0.1 * noise());
                    rows.rows.push((2 * k, Rgb::splat(0.7 * v)));
                    rows.rows.push((2 * k + 1, Rgb::splat(0.3 * v)));
                    range[half + 1] = rows.rows.len() as u32;
                }
                rows.ranges.push(range);
                pixels.push(CachePixel::bare((y * w + x) as u32, Rgb::ZERO));
                truth.push(e);
                coverage.push(c);
            }
        }
        (truth, coverage, pixels, rows)
    }

    /// The smoothed irradiance is several times closer to the truth than the pixels' own
    /// estimates away from the shadow's edge, in each half and for pixels partly off the
    /// group, is not dragged across the edge, and each pixel keeps its split among its texels.
    #[test]
    fn averages_noise_but_not_across_a_shadow_edge() {
        let (truth, coverage, pixels, rows) = shadowed(7);
        let mut scaled = rows.clone();
        scaled.scale = smoothing_scale(&rows, &pixels, &coverage, 40);
        let smoothed = scaled.smoothed();
        let half = |r: &TexelRows, k: usize, h: usize| {
            let g = r.ranges[k].map(|i| i as usize);
            r.rows[g[h]..g[h + 1]].iter().map(|x| x.1.x).sum::<f32>()
        };
        let (mut raw, mut fine, mut m) = (0.0f32, 0.0f32, 0usize);
        let mut edge = [(0.0f32, 0usize); 2];
        for (k, e) in truth.iter().enumerate() {
            let x = k % 40;
            for h in 0..2 {
                // Each half's rows sum to half the irradiance times the half's coverage.
                let expected = 0.5 * e * coverage[k][h];
                let (r, s) = (
                    half(&rows, k, h) / expected - 1.0,
                    half(&smoothed, k, h) / expected - 1.0,
                );
                if (x as i64 - 19).abs() > RADIUS && (x as i64 - 20).abs() > RADIUS {
                    raw += r * r;
                    fine += s * s;
                    m += 1;
                }
                if x == 19 || x == 20 {
                    let side = &mut edge[x - 19];
                    side.0 += s;
                    side.1 += 1;
                }
                let a = smoothed.ranges[k][h] as usize;
                let (t0, t1) = (smoothed.rows[a].1.x, smoothed.rows[a + 1].1.x);
                assert!(
                    (t0 / (t0 + t1) - 0.7).abs() < 1e-4,
                    "pixel {k}: split {t0} {t1}"
                );
            }
        }
        let (raw, fine) = ((raw / m as f32).sqrt(), (fine / m as f32).sqrt());
        assert!(raw > 0.05 && fine < 0.4 * raw, "rms {raw} → {fine}");
        // A 5×5 box filter would put the shadow's first column 93% too bright and the lit
        // side's last 28% too dark.
        for (bias, n) in edge {
            assert!(
                (bias / n as f32).abs() < 0.02,
                "edge bias {}",
                bias / n as f32
            );
        }
    }
}
