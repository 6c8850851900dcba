//! The lights next-event estimation samples: every triangle of an emissive object (an area
//! light, sampled uniformly over its area; emission is one-sided, along the triangle's
//! geometric normal as wound, so a quad emits along edge_u × edge_v; one triangle is chosen per
//! sample in proportion to its power) and the punctual lights (`scene::light`: directional,
//! point, spot), every one of which is evaluated at every vertex, and the environment
//! (`scene::environment`), sampled once at every vertex by its own importance and MIS-weighted
//! against BSDF sampling like an area light.
//!
//! A punctual light is a delta: its "sample" is the one direction it arrives from, with the
//! radiance-like factor Li such that the reflected radiance is f · Li · cos θi (pbrt-v4's
//! `LightLiSample` for delta lights, §12.1): a directional light's irradiance E, a point
//! light's I / d², a spot's I · falloff / d². Its pdf is 1 (it is not chosen at random), and
//! BSDF sampling never finds it, so it takes no MIS weight. Evaluating them all rather than
//! choosing one leaves their light free of selection noise: a sun a hundred times stronger
//! than a spot would otherwise starve the spot of samples.

use crate::geometry::Ray;
use crate::math::{luminance_mean, warp, Rgb, Sampler, Vec2, Vec3};
use crate::scene::environment::Environment;
use crate::scene::{Punctual, Scene};
use std::sync::Arc;

pub struct Lights {
    /// Emissive triangles, in the order of `cdf`.
    tris: Vec<LightTri>,
    /// Punctual lights, all evaluated at every vertex.
    punctual: Vec<Punctual>,
    /// The environment, sampled once at every vertex besides the area light.
    environment: Option<Arc<Environment>>,
    /// Stray light (`Scene::stray_light`): seen by rays leaving the scene, never sampled.
    stray: Rgb,
    /// Directional lights of some angular size, each sampled once at every vertex.
    discs: Vec<Disc>,
    /// Cumulative selection probability, last entry 1.
    cdf: Vec<f32>,
    /// Per emissive object, sorted: (its first scene triangle, the end of its range, the index
    /// in `tris` of its first triangle). `pdf` finds a hit triangle's entry here rather than in
    /// a table over every scene triangle, which cost T floats per `PathTracer`, and one is made
    /// per cache build (bench/SCALE.md).
    spans: Vec<(u32, u32, u32)>,
    /// `tris` as rows of sixteen floats (`Lights::row`).
    rows: Vec<[f32; 16]>,
}

/// What sampling needs of one emissive triangle, gathered in one place.
#[derive(Clone, Copy, Debug)]
pub(super) struct LightTri {
    pub v: [Vec3; 3],
    /// Unit geometric normal, the side it emits to.
    pub n: Vec3,
    pub radiance: Rgb,
    /// Probability of choosing it divided by its area.
    pub pdf_area: f32,
}

/// A point sampled on a light, seen from a reference point.
#[derive(Clone, Copy, Debug)]
pub struct LightSample {
    /// Unit direction from the reference point to the light point.
    pub wi: Vec3,
    pub dist: f32,
    /// The sampled point on the light.
    pub point: Vec3,
    pub radiance: Rgb,
    /// Density per solid angle at the reference point; 1 for a punctual light.
    pub pdf: f32,
    /// From a punctual light: no BSDF sample can find it (MIS weight 1), `dist` may be
    /// infinite, and `radiance` is the Li of the module comment.
    pub delta: bool,
}

impl Lights {
    pub fn new(scene: &Scene) -> Lights {
        let g = &scene.geometry;
        let mut tris = Vec::new();
        let mut weights = Vec::new();
        let mut areas = Vec::new();
        let mut spans = Vec::new();
        for obj in scene.objects.iter().filter(|o| o.is_emitter()) {
            let r = &obj.tri_range;
            spans.push((r.start, r.end, tris.len() as u32));
            for t in r.clone() {
                let [a, b, c] = g.tris[t as usize].v.map(|i| g.positions[i as usize]);
                let area = 0.5 * (b - a).cross(c - a).length();
                tris.push(LightTri {
                    v: [a, b, c],
                    n: g.faces[t as usize].ng,
                    radiance: obj.emission,
                    pdf_area: 0.0,
                });
                weights.push(area * luminance_mean(obj.emission));
                areas.push(area);
            }
        }
        let (discs, punctual): (Vec<Punctual>, Vec<Punctual>) = scene
            .punctual_lights
            .iter()
            .map(|l| l.kind)
            .partition(|k| matches!(k, Punctual::Directional { angle, .. } if *angle > 0.0));
        let discs = discs.iter().filter_map(Disc::new).collect();
        let total: f32 = weights.iter().sum();
        let mut cdf = Vec::with_capacity(weights.len());
        let mut acc = 0.0;
        for (i, w) in weights.iter().enumerate() {
            acc += w / total;
            cdf.push(acc);
            tris[i].pdf_area = (w / total) / areas[i];
        }
        spans.sort_unstable();
        if let Some(last) = cdf.last_mut() {
            *last = 1.0;
        }
        let rows = tris
            .iter()
            .map(|t| {
                let mut r = [0.0; 16];
                for (k, v) in t.v.iter().enumerate() {
                    r[Self::V + 3 * k..Self::V + 3 * k + 3].copy_from_slice(&v.to_array());
                }
                r[Self::N..Self::N + 3].copy_from_slice(&t.n.to_array());
                r[Self::LE..Self::LE + 3].copy_from_slice(&t.radiance.to_array());
                r[Self::PDF_AREA] = t.pdf_area;
                r
            })
            .collect();
        Lights {
            tris,
            punctual,
            environment: scene.environment.clone(),
            stray: scene.stray_light,
            discs,
            cdf,
            spans,
            rows,
        }
    }

    pub fn is_empty(&self) -> bool {
        self.tris.is_empty()
            && self.punctual.is_empty()
            && self.environment.is_none()
            && self.discs.is_empty()
    }

    /// Whether the eight-lane path can sample these lights: area and punctual lights, but no
    /// environment or disc, whose samples draw sampler dimensions between the area light's and
    /// the BSDF's.
    pub fn eight_lane(&self) -> bool {
        self.environment.is_none() && self.discs.is_empty()
    }

    /// Whether there are area lights (`sample`, `pick_index` and `row` need one).
    pub(super) fn has_area(&self) -> bool {
        !self.tris.is_empty()
    }

    /// The punctual lights, in the order `punctual_samples` evaluates them.
    pub(super) fn punctual(&self) -> &[Punctual] {
        &self.punctual
    }

    /// The radiance of every light at infinity seen along unit direction `d` (the environment,
    /// the discs whose cone holds `d` and the stray light), each with the density its own
    /// sampling has for `d` (0 for the stray light: only paths that leave the scene find it, so
    /// MIS gives them its whole weight).
    #[inline]
    pub fn at_infinity(&self, d: Vec3, mut f: impl FnMut(Rgb, f32)) {
        if self.stray.max_element() > 0.0 {
            f(self.stray, 0.0);
        }
        if let Some(e) = &self.environment {
            let (le, pl) = e.radiance_and_pdf(d);
            f(le, pl);
        }
        for disc in &self.discs {
            if disc.axis.dot(d) >= disc.cos_max {
                f(disc.radiance, disc.pdf);
            }
        }
    }

    /// One direction towards each disc light (2 sampler dimensions each), as `k` = 0, 1, …
    #[inline]
    pub fn sample_disc(&self, k: usize, p: Vec3, sampler: &mut Sampler) -> Option<LightSample> {
        let disc = self.discs.get(k)?;
        let u = sampler.next_2d();
        let cos = 1.0 - u.x * (1.0 - disc.cos_max);
        let sin = (1.0 - cos * cos).max(0.0).sqrt();
        let phi = 2.0 * std::f32::consts::PI * u.y;
        let wi = disc
            .frame
            .to_world(Vec3::new(sin * phi.cos(), sin * phi.sin(), cos));
        Some(LightSample {
            wi,
            dist: f32::INFINITY,
            point: p,
            radiance: disc.radiance,
            pdf: disc.pdf,
            delta: false,
        })
    }

    pub fn disc_count(&self) -> usize {
        self.discs.len()
    }

    /// A direction towards the environment drawn by its importance (2 sampler dimensions, drawn
    /// only when there is an environment); None without one or for a lost sample.
    #[inline]
    pub fn sample_environment(&self, p: Vec3, sampler: &mut Sampler) -> Option<LightSample> {
        let env = self.environment.as_ref()?;
        let (wi, radiance, pdf) = env.sample(sampler.next_2d())?;
        (radiance.max_element() > 0.0).then_some(LightSample {
            wi,
            dist: f32::INFINITY,
            point: p,
            radiance,
            pdf,
            delta: false,
        })
    }

    /// Samples a point on a light as seen from `p`; None if there are no lights or the point is
    /// on the light's back side. Occlusion is not tested.
    #[inline(always)]
    pub fn sample(&self, p: Vec3, sampler: &mut Sampler) -> Option<LightSample> {
        let uc = sampler.next_1d();
        let u = sampler.next_2d();
        self.sample_with(p, uc, u)
    }

    /// [`Lights::sample`] from its three numbers: `uc` chooses the triangle, `u` the point.
    #[inline(always)]
    pub fn sample_with(&self, p: Vec3, uc: f32, u: Vec2) -> Option<LightSample> {
        if self.tris.is_empty() {
            return None;
        }
        let (q, light) = self.point(uc, u);
        let d = q - p;
        let dist2 = d.length_squared();
        let dist = dist2.sqrt();
        let wi = d / dist;
        let cos_l = -light.n.dot(wi);
        if cos_l <= 0.0 || dist <= 0.0 {
            return None;
        }
        Some(LightSample {
            wi,
            dist,
            point: q,
            radiance: light.radiance,
            pdf: light.pdf_area * dist2 / cos_l,
            delta: false,
        })
    }

    /// The point `sample_with` takes for `uc` and `u`, and its triangle (there must be one).
    #[inline(always)]
    pub(super) fn point(&self, uc: f32, u: Vec2) -> (Vec3, &LightTri) {
        let light = &self.tris[self.pick_index(uc)];
        let [a, b, c] = light.v;
        let (b1, b2) = warp::uniform_triangle(u);
        (a * (1.0 - b1 - b2) + b * b1 + c * b2, light)
    }

    /// The light triangle chosen by `uc` ∈ [0, 1) (there must be one), by its index (for
    /// `row`).
    #[inline(always)]
    pub(super) fn pick_index(&self, uc: f32) -> usize {
        debug_assert!(!self.tris.is_empty());
        self.cdf
            .partition_point(|&c| c <= uc)
            .min(self.tris.len() - 1)
    }

    /// What every punctual light sends to `p` (the module comment): all of them at every
    /// vertex, which costs a shadow ray each and leaves no noise from choosing among them.
    #[inline]
    pub fn punctual_samples(&self, p: Vec3) -> impl Iterator<Item = LightSample> + '_ {
        self.punctual
            .iter()
            .filter_map(move |l| punctual_sample(l, p))
    }

    /// Triangle `k` as sixteen floats: vertices (`V`), normal (`N`), radiance (`LE`), and
    /// selection pdf / area (`PDF_AREA`).
    #[inline(always)]
    pub(super) fn row(&self, k: usize) -> &[f32; 16] {
        &self.rows[k]
    }
    pub(super) const V: usize = 0;
    pub(super) const N: usize = 9;
    pub(super) const LE: usize = 12;
    pub(super) const PDF_AREA: usize = 15;

    /// Density per solid angle with which `sample` would have produced the point on triangle
    /// `prim` at distance `dist` along `wi`, whose geometric normal is `n`.
    #[inline]
    pub fn pdf(&self, prim: u32, dist: f32, wi: Vec3, n: Vec3) -> f32 {
        let cos_l = -n.dot(wi);
        if cos_l <= 0.0 {
            return 0.0;
        }
        self.pdf_area(prim) * dist * dist / cos_l
    }

    /// Probability of choosing scene triangle `prim` divided by its area; 0 if not a light.
    #[inline]
    pub(super) fn pdf_area(&self, prim: u32) -> f32 {
        let k = self.spans.partition_point(|s| s.0 <= prim);
        match k.checked_sub(1).map(|k| self.spans[k]) {
            Some((start, end, first)) if prim < end => {
                self.tris[(first + prim - start) as usize].pdf_area
            }
            _ => 0.0,
        }
    }

    /// Whether the segment from `origin` (a surface point already offset off its surface) to the
    /// sampled light point is unblocked; the segment stops short of the light by the same
    /// scale-relative epsilon that `offset_origin` uses.
    pub fn visible(&self, scene: &Scene, origin: Vec3, s: &LightSample) -> bool {
        if s.dist == f32::INFINITY {
            return !scene.occluded(&Ray::new(origin, s.wi), f32::INFINITY);
        }
        let d = s.point - origin;
        let len = d.length();
        let eps = 2e-4 * (1.0 + s.point.abs().max_element());
        len > eps && !scene.occluded(&Ray::new(origin, d / len), len - eps)
    }
}

/// The light a punctual light sends to `p` (module comment); None where it sends none (outside
/// a spot's cone, nothing at all).
pub(super) fn punctual_sample(light: &Punctual, p: Vec3) -> Option<LightSample> {
    let (wi, dist, li) = match *light {
        Punctual::Directional {
            direction,
            irradiance,
            ..
        } => (-direction, f32::INFINITY, irradiance),
        Punctual::Point {
            position,
            intensity,
        }
        | Punctual::Spot {
            position,
            intensity,
            ..
        } => {
            let d = position - p;
            let dist2 = d.length_squared();
            if !(dist2 > 0.0) {
                return None;
            }
            let dist = dist2.sqrt();
            let wi = d / dist;
            (wi, dist, intensity * (light.falloff(-wi) / dist2))
        }
    };
    (li.max_element() > 0.0).then_some(LightSample {
        wi,
        dist,
        point: if dist.is_finite() { p + wi * dist } else { p },
        radiance: li,
        pdf: 1.0,
        delta: true,
    })
}

/// A directional light of angular diameter 2θmax: a disc at infinity of uniform radiance
/// L = E / (π sin²θmax), so that a surface facing it receives E (∫ L cos θ dω over the cone),
/// sampled uniformly in solid angle over its cone: pdf = 1 / (2π (1 − cos θmax)).
struct Disc {
    /// Unit direction towards the light, and a frame around it.
    axis: Vec3,
    frame: crate::math::Frame,
    cos_max: f32,
    radiance: Rgb,
    pdf: f32,
}

impl Disc {
    fn new(light: &Punctual) -> Option<Disc> {
        let Punctual::Directional {
            direction,
            irradiance,
            angle,
        } = *light
        else {
            return None;
        };
        let half = 0.5 * angle;
        let (sin, cos) = half.sin_cos();
        let axis = -direction;
        Some(Disc {
            axis,
            frame: crate::math::Frame::from_normal(axis),
            cos_max: cos,
            radiance: irradiance / (std::f32::consts::PI * sin * sin),
            pdf: 1.0 / (2.0 * std::f32::consts::PI * (1.0 - cos)),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `pdf_area` by emitter spans is the table over every scene triangle it replaces: each
    /// emissive triangle's `LightTri::pdf_area`, 0 on the others.
    #[test]
    fn pdf_area_is_the_emitters_and_zero_elsewhere() {
        let text = "[camera]\nwidth = 8\nheight = 8\nfov_y_deg = 40\n\
            eye = [0, 1, 3]\ntarget = [0, 1, 0]\n\
            [[object]]\nname = \"a\"\ngroup = \"a\"\nshape = \"quad\"\n\
            corner = [-1, 2, -1]\nedge_u = [1, 0, 0]\nedge_v = [0, 0, 2]\nemission = 5\n\
            [[object]]\nname = \"ball\"\ngroup = \"ball\"\nshape = \"sphere\"\n\
            center = [0, 0.5, 0]\nradius = 0.5\nsegments = 8\n\
            [[object]]\nname = \"b\"\ngroup = \"b\"\nshape = \"quad\"\n\
            corner = [0, 2, -1]\nedge_u = [2, 0, 0]\nedge_v = [0, 0, 2]\nemission = 1\n";
        let scene = crate::scene::load::parse_scene(text, std::path::Path::new("s.toml")).unwrap();
        let lights = Lights::new(&scene);
        let mut emissive = 0;
        for (o, obj) in scene.objects.iter().enumerate() {
            for t in obj.tri_range.clone() {
                let p = lights.pdf_area(t);
                if obj.is_emitter() {
                    let k = emissive;
                    emissive += 1;
                    assert_eq!(p, lights.tris[k].pdf_area, "object {o} triangle {t}");
                    assert!(p > 0.0);
                } else {
                    assert_eq!(p, 0.0, "object {o} triangle {t}");
                }
            }
        }
        assert_eq!(emissive, lights.tris.len());
        assert_eq!(lights.pdf_area(u32::MAX), 0.0);
    }
}
