//! Several photos of one scene, one set of materials (beyond the notes; `scene::view`).
//!
//! Each global iteration builds every group's cache in each photo through that photo's view of
//! the scene (its camera, its lights, the current materials) and fits the group once on all of
//! them together ([`GroupCache::append`]): a highlight seen in one photo and not in another
//! constrains the same lobe, and a light's calibration error in one photo no longer sets every
//! reflectance.
//!
//! Each photo k has its own exposure factor e_k (photo_k = e_k × radiance): a light whose
//! power is off by 5% in one photo is one factor there. After every group is refitted, e_k is
//! the weighted median of Y(photo_k) / Y(model_k) over photo k's cached pixels of the groups at a
//! uniform level (Y the mean of the channels, weights Y(model)), and the factors are then
//! divided by their geometric mean, so that the materials' scale is the consensus of all photos
//! rather than the first's. A median, because in the first iterations a glossy group is still
//! fitted as Lambert, and its misfit (the highlights, a different share of each photo's light)
//! must not be read as exposure. One photo keeps e = 1 and the method's single-image case is
//! unchanged to the bit.

use super::cache::GroupCache;
use crate::math::Rgb;

/// Per photo, the sums the exposure factors and residuals are computed from.
#[derive(Clone, Debug, Default)]
pub struct ExposureSums {
    photo: Vec<f64>,
    abs: Vec<f64>,
    pixels: Vec<usize>,
    /// Per photo, (photo / model, model) of every pixel the model lights.
    ratios: Vec<Vec<(f64, f64)>>,
}

fn lum(c: Rgb) -> f64 {
    (c.x as f64 + c.y as f64 + c.z as f64) / 3.0
}

impl ExposureSums {
    pub fn new(views: usize) -> ExposureSums {
        ExposureSums {
            photo: vec![0.0; views],
            abs: vec![0.0; views],
            pixels: vec![0; views],
            ratios: vec![Vec::new(); views],
        }
    }

    /// Adds a group's cache (its photo values already divided by `exposures`) and its model's
    /// radiance per cached pixel.
    pub fn add(&mut self, cache: &GroupCache, model: &[Rgb], exposures: &[f32]) {
        for (k, (p, m)) in cache.pixels.iter().zip(model).enumerate() {
            let v = cache.view_of(k);
            let (y, ym) = (lum(p.photo), lum(*m));
            self.photo[v] += y * exposures[v] as f64;
            self.abs[v] += (y - ym).abs();
            self.pixels[v] += 1;
            if ym > 0.0 {
                self.ratios[v].push((y * exposures[v] as f64 / ym, ym));
            }
        }
    }

    /// The new exposure factors (geometric mean 1), or None where no photo has pixels.
    pub fn exposures(&self) -> Option<Vec<f32>> {
        let e: Vec<f64> = self
            .ratios
            .iter()
            .map(|r| weighted_median(r.clone()))
            .collect::<Option<_>>()?;
        if e.iter().any(|&x| !(x > 0.0 && x.is_finite())) {
            return None;
        }
        let log_mean = e.iter().map(|x| x.ln()).sum::<f64>() / e.len() as f64;
        Some(e.iter().map(|x| (x / log_mean.exp()) as f32).collect())
    }

    /// Per photo: Σ|Y(photo/e) − Y(model)| / Σ Y(photo/e), and the pixels it is over.
    pub fn residuals(&self, exposures: &[f32]) -> Vec<(f32, usize)> {
        (0..self.photo.len())
            .map(|v| {
                let scaled = self.photo[v] / exposures[v] as f64;
                let r = if scaled > 0.0 {
                    self.abs[v] / scaled
                } else {
                    0.0
                };
                (r as f32, self.pixels[v])
            })
            .collect()
    }
}

/// The value below which half the total weight lies (None if there is none).
fn weighted_median(mut v: Vec<(f64, f64)>) -> Option<f64> {
    v.retain(|(x, w)| x.is_finite() && *w > 0.0);
    v.sort_by(|a, b| a.0.total_cmp(&b.0));
    let total: f64 = v.iter().map(|p| p.1).sum();
    let mut acc = 0.0;
    for (x, w) in &v {
        acc += w;
        if acc >= 0.5 * total {
            return Some(*x);
        }
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fit::cache::CachePixel;

    fn pixel(photo: f32) -> CachePixel {
        CachePixel::bare(0, Rgb::splat(photo))
    }

    /// Three photos whose true exposures are 1.1, 0.9 and 1.0 (relative), of a surface the model
    /// predicts at 0.5 and 0.25: the factors come out in those ratios with geometric mean 1,
    /// and a perfect model leaves no residual.
    #[test]
    fn factors_are_the_photos_ratios_with_unit_geometric_mean() {
        let truth = [1.1f32, 0.9, 1.0];
        let mut cache = GroupCache::default();
        let mut model = Vec::new();
        for (v, e) in truth.iter().enumerate() {
            if v > 0 {
                cache.views.push(cache.pixels.len());
            }
            for m in [0.5f32, 0.25] {
                // The cache holds the photo divided by the current factors (all 1 here).
                cache.pixels.push(pixel(e * m));
                model.push(Rgb::splat(m));
            }
        }
        let mut sums = ExposureSums::new(3);
        sums.add(&cache, &model, &[1.0; 3]);
        let e = sums.exposures().unwrap();
        let g = (truth[0] * truth[1] * truth[2]).cbrt();
        for (got, want) in e.iter().zip(truth) {
            assert!((got - want / g).abs() < 1e-6, "{e:?}");
        }
        assert!((e.iter().product::<f32>() - 1.0).abs() < 1e-6);
        // Against the fitted factors, the model explains each photo exactly.
        let mut scaled = cache.clone();
        for (k, p) in scaled.pixels.iter_mut().enumerate() {
            p.photo /= e[cache.view_of(k)];
        }
        let mut sums = ExposureSums::new(3);
        sums.add(
            &scaled,
            &model.iter().map(|&m| m * g).collect::<Vec<_>>(),
            &e,
        );
        for (r, n) in sums.residuals(&e) {
            assert!(r < 1e-5 && n == 2, "{r} over {n}");
        }
    }
}
