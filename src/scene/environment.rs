//! An environment light: an equirectangular HDR light probe (latitude–longitude map) of the
//! radiance arriving from infinitely far away, rotated into the scene. It means what Mitsuba 3's
//! `envmap` emitter means, so that the export is exact:
//!
//! * a direction d, taken into the map's frame (d_m = R⁻¹ d), has the map coordinates
//!   u = atan2(d_m.x, −d_m.z) / 2π (mod 1), v = acos(d_m.y) / π: +y is the top row, and the
//!   middle of the map looks along −z;
//! * the radiance is the map interpolated bilinearly with texel (i, j) at u = (i + ½) / W (the
//!   map wraps around in u) and v = j / (H − 1) (the first and last rows are the poles), times
//!   `scale`.
//!
//! Importance sampling (pbrt-v4 §12.5, "Image infinite lights"): a piecewise-constant density
//! over the W × (H − 1) cells of that bilinear interpolant, each cell weighted by its four
//! texels' mean luminance times sin θ at its centre (the solid angle a cell spans), drawn as a
//! row (marginal) then a cell in the row (conditional), uniformly within the cell. A cell whose
//! four texels are black has weight 0 and the interpolant is 0 all over it, so the density
//! covers every direction that carries light. The density per solid angle is
//! p(u, v) / (2π² sin θ).

use crate::io::image::Image;
use crate::math::{luminance_mean, Mat3, Rgb, Vec2, Vec3, PI};

pub struct Environment {
    image: Image,
    pub scale: f32,
    /// Map frame to world (a rotation), and its inverse.
    to_world: Mat3,
    to_map: Mat3,
    /// Cumulative weights of the rows of cells (last entry 1), and per row of its cells.
    row_cdf: Vec<f32>,
    cell_cdf: Vec<f32>,
    /// Probability of each cell (row-major, W × (H − 1)).
    cell_p: Vec<f32>,
}

impl std::fmt::Debug for Environment {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "Environment({}×{}, scale {})",
            self.image.width, self.image.height, self.scale
        )
    }
}

impl Environment {
    /// The light of `image` (linear radiance) times `scale`, with the map's frame turned into the
    /// world by `to_world`. The image must be at least 2 × 2 and not all black.
    pub fn new(image: Image, scale: f32, to_world: Mat3) -> Result<Environment, String> {
        let (w, h) = (image.width, image.height);
        if w < 2 || h < 2 {
            return Err(format!(
                "an environment map needs at least 2×2 pixels, got {w}×{h}"
            ));
        }
        if let Some(c) = image
            .data
            .iter()
            .find(|c| !c.is_finite() || c.min_element() < 0.0)
        {
            return Err(format!(
                "an environment map's values must be finite and non-negative, found {c}"
            ));
        }
        if !(scale.is_finite() && scale > 0.0) {
            return Err(format!("`scale` must be positive, got {scale}"));
        }
        let rows = h - 1;
        let lum = |i: usize, j: usize| luminance_mean(image.data[j * w + i % w]);
        let mut cell_p = vec![0.0f32; w * rows];
        let mut row_w = vec![0.0f64; rows];
        for j in 0..rows {
            let sin = (PI * (j as f32 + 0.5) / rows as f32).sin();
            for i in 0..w {
                let m = 0.25 * (lum(i, j) + lum(i + 1, j) + lum(i, j + 1) + lum(i + 1, j + 1));
                cell_p[j * w + i] = m * sin;
                row_w[j] += (m * sin) as f64;
            }
        }
        let total: f64 = row_w.iter().sum();
        if !(total > 0.0) {
            return Err("the environment map is black everywhere: it lights nothing".into());
        }
        let mut row_cdf = Vec::with_capacity(rows);
        let mut cell_cdf = vec![0.0f32; w * rows];
        let mut acc = 0.0f64;
        for j in 0..rows {
            acc += row_w[j];
            row_cdf.push((acc / total) as f32);
            let mut a = 0.0f64;
            for i in 0..w {
                a += cell_p[j * w + i] as f64;
                cell_cdf[j * w + i] = if row_w[j] > 0.0 {
                    (a / row_w[j]) as f32
                } else {
                    (i + 1) as f32 / w as f32
                };
            }
            cell_cdf[j * w + w - 1] = 1.0;
        }
        *row_cdf.last_mut().expect("rows ≥ 1") = 1.0;
        for p in &mut cell_p {
            *p = (*p as f64 / total) as f32;
        }
        Ok(Environment {
            image,
            scale,
            to_world,
            to_map: to_world.transpose(),
            row_cdf,
            cell_cdf,
            cell_p,
        })
    }

    /// The map, linear, before `scale`.
    pub fn image(&self) -> &Image {
        &self.image
    }

    /// The rotation from the map's frame to the world.
    pub fn to_world(&self) -> Mat3 {
        self.to_world
    }

    /// Where a unit world direction falls on the map: x = u · W − ½ in [0, W) (texel i at
    /// x = i: the module comment), v, and cos θ (the map frame's y).
    #[inline]
    fn coords(&self, d: Vec3) -> (f32, f32, f32) {
        let m = self.to_map * d;
        let w = self.image.width as f32;
        let x = m.x.atan2(-m.z) / (2.0 * PI) * w - 0.5;
        let cos = m.y.clamp(-1.0, 1.0);
        (x - (x / w).floor() * w, cos.acos() / PI, cos)
    }

    /// Radiance arriving along −d, i.e. seen looking along unit direction `d`.
    pub fn radiance(&self, d: Vec3) -> Rgb {
        let (x, v, _) = self.coords(d);
        self.lookup(x, v) * self.scale
    }

    /// [`Environment::radiance`] and [`Environment::pdf`] of one direction, which share their
    /// map coordinates (a ray that leaves the scene needs both).
    pub fn radiance_and_pdf(&self, d: Vec3) -> (Rgb, f32) {
        let (x, v, cos) = self.coords(d);
        (self.lookup(x, v) * self.scale, self.cell_pdf(x, v, cos))
    }

    /// The bilinear interpolant at x ∈ [0, W) (`coords`), v ∈ [0, 1].
    fn lookup(&self, x: f32, v: f32) -> Rgb {
        let (w, h) = (self.image.width, self.image.height);
        let y = v * (h - 1) as f32;
        let (x0, y0) = (x.floor(), y.floor().min((h - 2) as f32));
        let (fx, fy) = (x - x0, y - y0);
        let (i0, j0) = (x0 as usize % w, y0 as usize);
        let (i1, j1) = ((i0 + 1) % w, j0 + 1);
        let at = |i: usize, j: usize| self.image.data[j * w + i];
        (at(i0, j0) * (1.0 - fx) + at(i1, j0) * fx) * (1.0 - fy)
            + (at(i0, j1) * (1.0 - fx) + at(i1, j1) * fx) * fy
    }

    /// A direction drawn from the density (module comment), with the radiance from it and its
    /// density per solid angle; None at the poles' degenerate directions.
    pub fn sample(&self, u: Vec2) -> Option<(Vec3, Rgb, f32)> {
        let (w, rows) = (self.image.width, self.row_cdf.len());
        let j = self.row_cdf.partition_point(|&c| c <= u.x).min(rows - 1);
        let (lo, hi) = (
            if j == 0 { 0.0 } else { self.row_cdf[j - 1] },
            self.row_cdf[j],
        );
        let fy = if hi > lo {
            ((u.x - lo) / (hi - lo)).clamp(0.0, 1.0)
        } else {
            0.5
        };
        let row = &self.cell_cdf[j * w..(j + 1) * w];
        let i = row.partition_point(|&c| c <= u.y).min(w - 1);
        let (lo, hi) = (if i == 0 { 0.0 } else { row[i - 1] }, row[i]);
        let fx = if hi > lo {
            ((u.y - lo) / (hi - lo)).clamp(0.0, 1.0)
        } else {
            0.5
        };
        let (su, sv) = (
            (i as f32 + fx + 0.5) / w as f32,
            (j as f32 + fy) / rows as f32,
        );
        let (theta, phi) = (PI * sv, 2.0 * PI * su);
        let sin = theta.sin();
        if !(sin > 0.0) {
            return None;
        }
        let m = Vec3::new(sin * phi.sin(), theta.cos(), -sin * phi.cos());
        let d = (self.to_world * m).normalize();
        let pdf = self.cell_p[j * w + i] * (w * rows) as f32 / (2.0 * PI * PI * sin);
        (pdf > 0.0).then(|| (d, self.radiance(d), pdf))
    }

    /// The density of `sample` per solid angle at unit world direction `d`.
    pub fn pdf(&self, d: Vec3) -> f32 {
        let (x, v, cos) = self.coords(d);
        self.cell_pdf(x, v, cos)
    }

    /// The density per solid angle at map coordinates (x, v) of `coords`, whose cos θ is `cos`.
    fn cell_pdf(&self, x: f32, v: f32, cos: f32) -> f32 {
        let (w, rows) = (self.image.width, self.row_cdf.len());
        let sin = (1.0 - cos * cos).max(0.0).sqrt();
        if !(sin > 0.0) {
            return 0.0;
        }
        let i = (x as usize).min(w - 1);
        let j = ((v * rows as f32) as usize).min(rows - 1);
        self.cell_p[j * w + i] * (w * rows) as f32 / (2.0 * PI * PI * sin)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::Sampler;

    /// A sky: a bright blob (a sun) on a gradient, on a map of odd size.
    fn sky() -> Environment {
        let (w, h) = (37, 19);
        let mut img = Image::new(w, h);
        for j in 0..h {
            for i in 0..w {
                let (di, dj) = (i as f32 - 9.0, j as f32 - 5.0);
                let sun = 40.0 * (-(di * di + dj * dj) / 3.0).exp();
                img.set(
                    i,
                    j,
                    Rgb::new(
                        0.2 + sun,
                        0.3 + 0.5 * sun,
                        0.6 * (1.0 - j as f32 / h as f32),
                    ),
                );
            }
        }
        let r = Mat3::from_rotation_y(0.7) * Mat3::from_rotation_x(0.2);
        Environment::new(img, 1.5, r).unwrap()
    }

    #[test]
    fn sampling_integrates_the_map_and_its_pdf_is_the_samples() {
        let env = sky();
        // ∫ L dω estimated by importance sampling and by uniform sphere sampling must agree,
        // and each sample's pdf must be `pdf` of its direction.
        let (mut is, mut us) = (Rgb::ZERO, Rgb::ZERO);
        let n = 200_000;
        let mut off = 0u32;
        let mut s = Sampler::new(3, 0);
        for k in 0..n {
            s.start_sample(k);
            if let Some((d, l, p)) = env.sample(s.next_2d()) {
                // The direction's round trip through the rotation may move a sample on a
                // cell's edge into its neighbour: rare, and then both densities are right.
                let q = env.pdf(d);
                off += u32::from((q - p).abs() > 1e-3 * p);
                assert!((env.radiance(d) - l).abs().max_element() < 1e-6);
                is += l / p;
            }
            let u = s.next_2d();
            let z = 1.0 - 2.0 * u.x;
            let r = (1.0 - z * z).max(0.0).sqrt();
            let d = Vec3::new(r * (2.0 * PI * u.y).cos(), r * (2.0 * PI * u.y).sin(), z);
            us += env.radiance(d) * (4.0 * PI);
        }
        assert!(
            off < n / 200,
            "{off} of {n} samples' pdf differs from pdf()"
        );
        let (is, us) = (is / n as f32, us / n as f32);
        assert!(
            ((is - us) / us).abs().max_element() < 0.02,
            "importance {is} vs uniform {us}"
        );
    }

    #[test]
    fn the_map_is_read_in_mitsubas_orientation() {
        // One bright texel at column 2 of 8, the middle row: u = 2.5/8, the direction
        // (sin θ sin φ, cos θ, −sin θ cos φ) with θ = π/2, φ = 2π u.
        let (w, h) = (8, 5);
        let mut img = Image::new(w, h);
        img.set(2, 2, Rgb::ONE);
        let phi = 2.0 * PI * 2.5 / 8.0;
        let d = Vec3::new(phi.sin(), 0.0, -phi.cos());
        let env = Environment::new(img, 1.0, Mat3::IDENTITY).unwrap();
        assert!((env.radiance(d) - Rgb::ONE).abs().max_element() < 1e-5);
        assert_eq!(env.radiance(-d), Rgb::ZERO);
        // Rotated by 90° about y, that texel is seen along R·d.
        let r = Mat3::from_rotation_y(PI / 2.0);
        let env = Environment::new(env.image, 1.0, r).unwrap();
        assert!((env.radiance(r * d) - Rgb::ONE).abs().max_element() < 1e-5);
    }
}
