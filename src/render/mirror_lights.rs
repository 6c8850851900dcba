//! Next-event estimation through planar mirrors: the image of each area light in each flat
//! ideal mirror, sampled as a light of its own.
//!
//! Light that reaches a diffuse surface by way of a mirror (a caustic) is otherwise found only
//! when a BSDF-sampled direction happens to reflect into the light, which makes it the noisiest
//! light in a scene with a mirror. But a planar mirror makes an exact virtual image of the
//! light: seen from x, a point y on the light reflected in the mirror's plane lies on a straight
//! line from x's mirror image x′ = x − 2((x − p₀)·n)n, and the path x → m → y, with m where the
//! segment x′y crosses the plane, has length |x′ − y|. So the light point that next-event
//! estimation samples on the light also gives a sample of the virtual light: the estimate is
//!
//!   f(ωo, ωi) ρs Le cos θi / p,   p = pdf_area(y) |x′ − y|² / cos θy,
//!
//! ωi the direction from x to m and θy the angle at the light between its normal and the ray
//! from m, valid where m lies on the mirror and both segments are unblocked (the classic
//! mirror-image method for planar reflectors: Wallace, Cohen & Greenberg 1987, "A two-pass
//! solution to the rendering equation", whose virtual images of the scene in planar mirrors
//! carry light the same way). It is
//! weighted by multiple importance sampling (power heuristic, Veach 1997, §9.2) against the
//! BSDF-sampled path x → m → y, whose density at x is the BSDF's pdf of ωi (the mirror's
//! reflection being certain); `PathTracer::arrive` gives that path the other weight.
//!
//! Only objects whose material is an ideal mirror and whose triangles are all flat and in one
//! plane count; paths through two mirrors are left to BSDF sampling.

use super::lights::Lights;
use crate::math::{Rgb, Vec3};
use crate::scene::{Material, Scene};

/// A flat ideal mirror: its plane, its triangles and its reflectance.
struct PlanarMirror {
    /// A point of the plane and its unit normal (either side reflects).
    p0: Vec3,
    n: Vec3,
    /// Its triangles' vertices, for the test of where the reflected path meets the plane.
    tris: Vec<[Vec3; 3]>,
    /// Its scene triangles and its group.
    prims: std::ops::Range<u32>,
    group: usize,
    rho_s: Rgb,
}

/// The scene's planar mirrors (module comment).
#[derive(Default)]
pub struct MirrorLights {
    mirrors: Vec<PlanarMirror>,
}

/// A light point seen from a vertex through a mirror.
#[derive(Clone, Copy, Debug)]
pub struct MirrorSample {
    /// Unit direction from the vertex to the mirror point `m`.
    pub wi: Vec3,
    pub m: Vec3,
    /// The mirror's normal on the vertex's side, and its group.
    pub mirror_n: Vec3,
    pub group: usize,
    /// The light point.
    pub point: Vec3,
    /// The light's radiance times the mirror's reflectance.
    pub radiance: Rgb,
    /// Density per solid angle at the vertex.
    pub pdf: f32,
}

impl MirrorLights {
    /// The planar ideal mirrors of `scene` (none when it has no area light to image).
    pub fn new(scene: &Scene, lights: &Lights) -> MirrorLights {
        if !lights.has_area() {
            return MirrorLights::default();
        }
        let g = &scene.geometry;
        let mirrors = scene
            .objects
            .iter()
            .filter_map(|obj| {
                let Material::Mirror { rho_s } = obj.material else {
                    return None;
                };
                if obj.is_emitter() || obj.tri_range.is_empty() || !(rho_s.max_element() > 0.0)
                {
                    return None;
                }
                let tris: Vec<[Vec3; 3]> = obj
                    .tri_range
                    .clone()
                    .map(|t| g.tris[t as usize].v.map(|i| g.positions[i as usize]))
                    .collect();
                let n = g.faces[obj.tri_range.start as usize].ng;
                let p0 = tris[0][0];
                let scale = 1e-4 * (1.0 + p0.abs().max_element());
                let flat = obj.tri_range.clone().zip(&tris).all(|(t, v)| {
                    let face = &g.faces[t as usize];
                    face.ng.dot(n).abs() > 1.0 - 1e-5
                        && face.frame.is_some_and(|f| f.n.dot(n).abs() > 1.0 - 1e-5)
                        && v.iter().all(|p| (*p - p0).dot(n).abs() < scale)
                });
                flat.then(|| PlanarMirror {
                    p0,
                    n,
                    tris,
                    prims: obj.tri_range.clone(),
                    group: obj.group,
                    rho_s,
                })
            })
            .collect();
        MirrorLights { mirrors }
    }

    pub fn is_empty(&self) -> bool {
        self.mirrors.is_empty()
    }

    pub fn len(&self) -> usize {
        self.mirrors.len()
    }

    /// Whether scene triangle `prim` belongs to one of these mirrors.
    #[inline]
    pub fn contains(&self, prim: u32) -> bool {
        self.mirrors.iter().any(|m| m.prims.contains(&prim))
    }

    /// The light point `y` (on a light triangle of normal `ny`, radiance `le`, selection pdf
    /// per area `pdf_area`) seen from `x` through mirror `k`; None where the reflected path
    /// misses the mirror or the light faces away from it.
    #[inline]
    pub fn sample(
        &self,
        k: usize,
        x: Vec3,
        y: Vec3,
        ny: Vec3,
        le: Rgb,
        pdf_area: f32,
    ) -> Option<MirrorSample> {
        let mirror = &self.mirrors[k];
        let (sx, sy) = ((x - mirror.p0).dot(mirror.n), (y - mirror.p0).dot(mirror.n));
        // Both in front of the same side of the plane.
        if !(sx * sy > 0.0) {
            return None;
        }
        let x_image = x - 2.0 * sx * mirror.n;
        let m = x_image + (y - x_image) * (sx / (sx + sy));
        if !mirror.tris.iter().any(|t| inside(t, m, mirror.n)) {
            return None;
        }
        let to_m = m - x;
        let len = to_m.length();
        let along = y - x_image;
        let dist2 = along.length_squared();
        if !(len > 0.0) || !(dist2 > 0.0) {
            return None;
        }
        let cos_y = -ny.dot(along / dist2.sqrt());
        if cos_y <= 0.0 {
            return None;
        }
        Some(MirrorSample {
            wi: to_m / len,
            m,
            mirror_n: mirror.n * sx.signum(),
            group: mirror.group,
            point: y,
            radiance: mirror.rho_s * le,
            pdf: pdf_area * dist2 / cos_y,
        })
    }
}

/// Whether `p`, in the plane of triangle `t` (normal `n`), lies inside it.
#[inline]
fn inside(t: &[Vec3; 3], p: Vec3, n: Vec3) -> bool {
    let [a, b, c] = *t;
    let e = [
        (b - a).cross(p - a).dot(n),
        (c - b).cross(p - b).dot(n),
        (a - c).cross(p - c).dot(n),
    ];
    (e[0] >= 0.0 && e[1] >= 0.0 && e[2] >= 0.0) || (e[0] <= 0.0 && e[1] <= 0.0 && e[2] <= 0.0)
}

#[cfg(test)]
mod tests {
    use crate::render::film::render_pixel;
    use crate::render::PathTracer;

    /// A diffuse floor in front of a mirror, lit by a light that faces the mirror: much of the
    /// floor's light comes by way of the mirror.
    fn scene() -> crate::scene::Scene {
        let text = "[render]\nmax_depth = 3\n\
            [camera]\nwidth = 8\nheight = 6\nfov_y_deg = 60\n\
            eye = [0, 2, 2]\ntarget = [0, 0, -0.5]\n\
            [[object]]\nname = \"floor\"\ngroup = \"floor\"\nshape = \"quad\"\n\
            corner = [-1.5, 0, 1.5]\nedge_u = [3, 0, 0]\nedge_v = [0, 0, -3]\n\
            material = { type = \"diffuse\", rho_d = 0.8 }\n\
            [[object]]\nname = \"mirror\"\ngroup = \"mirror\"\nshape = \"quad\"\n\
            corner = [-1, 0.05, -1]\nedge_u = [2, 0, 0]\nedge_v = [0, 1.5, 0]\n\
            material = { type = \"mirror\", rho_s = 0.9 }\n\
            [[object]]\nname = \"light\"\ngroup = \"light\"\nshape = \"quad\"\n\
            corner = [-0.3, 1.3, 0.5]\nedge_u = [0.6, 0, 0]\nedge_v = [0, -0.6, 0]\n\
            emission = 10\n";
        crate::scene::load::parse_scene(text, std::path::Path::new("m.toml")).unwrap()
    }

    #[test]
    fn mirror_lights_keep_the_image_and_take_its_noise() {
        let sc = scene();
        let plain = PathTracer::new(&sc);
        let imaged = PathTracer::new(&sc).with_mirror_lights();
        assert_eq!(imaged.mirrors.len(), 1);
        let (w, h) = (sc.camera.width as usize, sc.camera.height as usize);
        let image = |pt: &PathTracer, spp: u32, seed: u64| -> Vec<f64> {
            (0..w * h)
                .map(|i| render_pixel(pt, &sc.camera, i % w, i / w, spp, seed).x as f64)
                .collect()
        };
        let mean = |im: &[f64]| im.iter().sum::<f64>() / im.len() as f64;
        // The image's mean: unbiased both ways.
        let reference = mean(&image(&plain, 4096, 1));
        let runs: Vec<Vec<f64>> = (0..4).map(|s| image(&imaged, 256, 10 + s)).collect();
        let m = runs.iter().map(|r| mean(r)).sum::<f64>() / runs.len() as f64;
        assert!(
            (m - reference).abs() < 0.01 * reference,
            "{m} vs {reference}"
        );
        // The pixels' spread over seeds at 64 spp: far less with the mirror's light sampled.
        let spread = |pt: &PathTracer| -> f64 {
            let runs: Vec<Vec<f64>> = (0..6).map(|s| image(pt, 64, 100 + s)).collect();
            (0..w * h)
                .map(|i| {
                    let v: Vec<f64> = runs.iter().map(|r| r[i]).collect();
                    let mu = mean(&v);
                    v.iter().map(|x| (x - mu).powi(2)).sum::<f64>() / (v.len() - 1) as f64
                })
                .sum::<f64>()
        };
        let (with, without) = (spread(&imaged), spread(&plain));
        assert!(with < 0.5 * without, "variance {with} with, {without} without");
    }
}
