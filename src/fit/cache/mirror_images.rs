//! The lights as seen in the scene's planar mirrors: every emissive triangle reflected across
//! the plane of every planar object whose current material is an ideal mirror. The cache's
//! mixture (`mixture.rs`) draws some of its indirect directions towards these images.
//!
//! Why: next-event estimation cannot reach a light by way of an ideal mirror (the mirror's
//! reflection is a delta), so the light a glossy floor receives from the lights' images in a
//! mirror came only from the indirect samples that happened to hit them. With 32 per pixel a
//! narrow lobe's cached radiance was a few spikes, and the fit's answer moved with them: the
//! office's floor (Ward αx/αy 0.07/0.11, ρs 0.6) came out at ρs 0.36–0.42 and α at its grid
//! point, where 256 indirect samples per pixel recover it. Aiming at the images is the
//! sampling side of the classic virtual-light construction for planar mirrors; the path itself
//! is still traced through the scene (it may miss the mirror or be blocked), so the estimate
//! stays unbiased for any mixture weight.

use crate::geometry::triangle::{intersect, RayShear};
use crate::math::{luminance_mean, warp, Vec2, Vec3};
use crate::scene::{Material, Scene};

/// At most this many image triangles (lights × mirrors): the mixture's density sums over all
/// of them at every cached sample. Beyond it (an emissive mesh in a mirror) no image is drawn.
pub const MAX_IMAGES: usize = 64;

/// A light triangle reflected in a mirror's plane.
#[derive(Clone, Copy, Debug)]
struct Image {
    v: [Vec3; 3],
    /// Unit normal of the side the image emits to (the light's, reflected).
    n: Vec3,
    /// Probability of choosing it divided by its area.
    pdf_area: f32,
    /// The mirror's plane, n·x = d, oriented so that the light is on its positive side: the
    /// image is seen from there only.
    plane: (Vec3, f32),
}

impl Image {
    /// Whether a direction from `p` may reach the light through this image: `p` on the
    /// light's side of the mirror and on the side the image emits to.
    fn seen_from(&self, p: Vec3) -> bool {
        let (m, d) = self.plane;
        m.dot(p) > d && self.n.dot(p - self.v[0]) > 0.0
    }
}

/// The lights' images in the current scene's planar mirrors.
#[derive(Clone, Debug, Default)]
pub struct MirrorImages {
    images: Vec<Image>,
    /// Cumulative selection probability, last entry 1.
    cdf: Vec<f32>,
}

impl MirrorImages {
    /// The images of `scene`'s emissive triangles in its planar objects whose material is an
    /// ideal mirror (`Mirror`, or `DiffuseMirror` with ρs > 0). An object is planar when all
    /// its triangles lie in one plane (to 1e-4 of its extent); a curved mirror has no image
    /// this construction could draw. Chosen in proportion to the light's power.
    pub fn new(scene: &Scene) -> MirrorImages {
        let g = &scene.geometry;
        let tri = |t: u32| g.tris[t as usize].v.map(|i| g.positions[i as usize]);
        let lights: Vec<([Vec3; 3], Vec3, f32)> = scene
            .objects
            .iter()
            .filter(|o| o.is_emitter())
            .flat_map(|o| {
                o.tri_range.clone().map(move |t| {
                    let v = tri(t);
                    let area = 0.5 * (v[1] - v[0]).cross(v[2] - v[0]).length();
                    (v, g.faces[t as usize].ng, area * luminance_mean(o.emission))
                })
            })
            .filter(|l| l.2 > 0.0)
            .collect();
        let mut images = Vec::new();
        let mut weights = Vec::new();
        for o in &scene.objects {
            let mirror = match &o.material {
                Material::Mirror { rho_s } | Material::DiffuseMirror { rho_s, .. } => {
                    rho_s.max_element() > 0.0
                }
                _ => false,
            };
            if !mirror || o.is_emitter() {
                continue;
            }
            let Some((m, d)) = plane_of(o.tri_range.clone().map(tri)) else {
                continue;
            };
            for (v, n, power) in &lights {
                let side: Vec<f32> = v.iter().map(|x| m.dot(*x) - d).collect();
                let s = if side.iter().all(|&x| x > 0.0) {
                    1.0
                } else if side.iter().all(|&x| x < 0.0) {
                    -1.0
                } else {
                    continue;
                };
                let reflect = |x: Vec3| x - m * (2.0 * (m.dot(x) - d));
                let dir = |x: Vec3| x - m * (2.0 * m.dot(x));
                images.push(Image {
                    v: v.map(reflect),
                    n: dir(*n),
                    pdf_area: 0.0,
                    plane: (m * s, d * s),
                });
                weights.push(*power);
            }
        }
        if images.len() > MAX_IMAGES {
            tracing::debug!(
                "{} images of lights in mirrors, more than {MAX_IMAGES}: none drawn",
                images.len()
            );
            return MirrorImages::default();
        }
        let total: f32 = weights.iter().sum();
        let mut cdf = Vec::with_capacity(images.len());
        let mut acc = 0.0;
        for (im, w) in images.iter_mut().zip(&weights) {
            acc += w / total;
            cdf.push(acc);
            let area = 0.5 * (im.v[1] - im.v[0]).cross(im.v[2] - im.v[0]).length();
            im.pdf_area = (w / total) / area;
        }
        if let Some(last) = cdf.last_mut() {
            *last = 1.0;
        }
        MirrorImages { images, cdf }
    }

    pub fn is_empty(&self) -> bool {
        self.images.is_empty()
    }

    /// Whether any image is seen from `p` (the mixture draws towards them only there).
    pub fn seen_from(&self, p: Vec3) -> bool {
        self.images.iter().any(|im| im.seen_from(p))
    }

    /// A direction (world) from `p` to a point drawn on an image, the image chosen by
    /// `uc` ∈ [0, 1) in proportion to its light's power and the point uniformly by `u`; None
    /// when the chosen image is not seen from `p` (its probability is lost, not renormalised,
    /// as [`pdf`](Self::pdf) counts it).
    pub fn sample(&self, p: Vec3, uc: f32, u: Vec2) -> Option<Vec3> {
        let k = self
            .cdf
            .partition_point(|&c| c <= uc)
            .min(self.images.len().checked_sub(1)?);
        let im = &self.images[k];
        if !im.seen_from(p) {
            return None;
        }
        let (b1, b2) = warp::uniform_triangle(u);
        let q = im.v[0] * (1.0 - b1 - b2) + im.v[1] * b1 + im.v[2] * b2;
        (q - p).try_normalize()
    }

    /// Density per solid angle at `p` with which [`sample`](Self::sample) draws unit direction
    /// `w`: over the images seen from `p` that the ray meets, the point's area density
    /// converted to solid angle, pdf_area · t² / cos θ at the image.
    pub fn pdf(&self, p: Vec3, w: Vec3) -> f32 {
        let sh = RayShear::new(w);
        self.images
            .iter()
            .filter(|im| im.seen_from(p))
            .filter_map(|im| {
                let (t, _, _) = intersect(p, &sh, im.v[0], im.v[1], im.v[2], f32::INFINITY)?;
                let cos = -im.n.dot(w);
                (cos > 0.0).then(|| im.pdf_area * t * t / cos)
            })
            .sum()
    }
}

/// The plane n·x = d of a set of triangles, if they all lie in one (every vertex within 1e-4
/// of the set's extent from the first non-degenerate triangle's plane).
fn plane_of(tris: impl Iterator<Item = [Vec3; 3]>) -> Option<(Vec3, f32)> {
    let tris: Vec<[Vec3; 3]> = tris.collect();
    let n = tris
        .iter()
        .find_map(|v| (v[1] - v[0]).cross(v[2] - v[0]).try_normalize())?;
    let d = n.dot(
        tris.iter()
            .find(|v| (v[1] - v[0]).cross(v[2] - v[0]).length() > 0.0)?[0],
    );
    let (lo, hi) = tris.iter().flatten().fold(
        (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)),
        |(lo, hi), &x| (lo.min(x), hi.max(x)),
    );
    let tol = 1e-4 * (hi - lo).length().max(1e-6);
    tris.iter()
        .flatten()
        .all(|&x| (n.dot(x) - d).abs() <= tol)
        .then_some((n, d))
}

#[cfg(test)]
pub(super) mod tests {
    use super::*;
    use crate::math::Sampler;

    /// A ceiling light, a mirror on the wall x = 0 facing +x, and a floor point in front of it.
    pub(in crate::fit) fn scene() -> Scene {
        crate::scene::load::parse_scene(
            r#"
[camera]
width = 8
height = 8
eye = [2, 1, 2]
target = [0, 1, 0]
fov_y_deg = 60

[[object]]
name = "light"
group = "light"
shape = "quad"
corner = [1, 2, -0.25]
edge_u = [0.5, 0, 0]
edge_v = [0, 0, 0.5]
emission = 10.0

[[object]]
name = "mirror"
group = "mirror"
shape = "quad"
corner = [0, 0, 1]
edge_u = [0, 0, -2]
edge_v = [0, 2, 0]
material = { type = "mirror", rho_s = 0.9 }
"#,
            std::path::Path::new("mirror.toml"),
        )
        .unwrap()
    }

    #[test]
    fn a_ceiling_light_has_one_image_behind_a_wall_mirror() {
        let s = scene();
        let m = MirrorImages::new(&s);
        assert_eq!(m.images.len(), 2, "the light quad's two triangles");
        for im in &m.images {
            for v in im.v {
                assert!(
                    (v.x + 1.25).abs() < 0.25 + 1e-5 && (v.y - 2.0).abs() < 1e-5,
                    "{v}"
                );
            }
            // The light emits down (−y): so does its image.
            assert!(im.n.y < -0.99, "{}", im.n);
        }
        assert!(m.seen_from(Vec3::new(1.0, 0.0, 0.0)));
        assert!(!m.seen_from(Vec3::new(-1.0, 0.0, 0.0)), "behind the mirror");
        assert!(
            !m.seen_from(Vec3::new(1.0, 2.5, 0.0)),
            "above the light's image"
        );
    }

    /// `pdf` is the density of `sample`: E[1/pdf] over the draws is the solid angle the
    /// images subtend from the point, which is the light's own solid angle from the point's
    /// reflection (the mirror is an isometry), computed here by its own draws.
    #[test]
    fn the_image_pdf_integrates_to_the_images_solid_angle() {
        let s = scene();
        let m = MirrorImages::new(&s);
        let p = Vec3::new(0.8, 0.0, 0.1);
        let reflected = Vec3::new(-p.x, p.y, p.z);
        let lights = crate::render::lights::Lights::new(&s);
        let mut sampler = Sampler::new(7, 0);
        let n = 100_000;
        let (mut inv_image, mut inv_light) = (0.0f64, 0.0f64);
        for i in 0..n {
            sampler.start_sample(i);
            let uc = sampler.next_1d();
            let u = sampler.next_2d();
            let w = m.sample(p, uc, u).expect("seen from p");
            let pdf = m.pdf(p, w);
            assert!(pdf > 0.0, "a drawn direction has density");
            inv_image += 1.0 / pdf as f64;
            let ls = lights.sample(reflected, &mut sampler).unwrap();
            inv_light += 1.0 / ls.pdf as f64;
        }
        let (a, b) = (inv_image / n as f64, inv_light / n as f64);
        assert!((a / b - 1.0).abs() < 0.01, "image {a} sr, light {b} sr");
        // A direction away from the image has none.
        assert_eq!(m.pdf(p, Vec3::new(1.0, 0.0, 0.0)), 0.0);
    }

    #[test]
    fn a_diffuse_or_curved_mirror_has_no_image() {
        let mut s = scene();
        let k = s.objects.iter().position(|o| o.name == "mirror").unwrap();
        s.objects[k].material = Material::Diffuse {
            rho_d: crate::math::Rgb::splat(0.5),
        };
        assert!(MirrorImages::new(&s).is_empty());
        let bent = [
            [Vec3::ZERO, Vec3::X, Vec3::Y],
            [Vec3::X, Vec3::new(1.0, 1.0, 0.3), Vec3::Y],
        ];
        assert!(plane_of(bent.into_iter()).is_none());
        assert!(plane_of(bent[..1].iter().copied()).is_some());
    }
}
