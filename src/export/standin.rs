//! The microfacet lobe that stands for a Ward lobe in a renderer without Ward (Mitsuba 3).
//!
//! No microfacet lobe has Ward's shape: Beckmann's D is Ward's Gaussian, but the microfacet
//! BRDF D·G/(4 cosθi cosθo) differs from Ward 1992's exp(−E)/(4π αx αy √(cosθi cosθo)) by
//! G/(cos⁴δ √(cosθi cosθo)), which grows at grazing views, and GGX has a longer tail. So the
//! stand-in is *fitted*, not copied: its distribution (Beckmann or GGX) and roughness (α, or
//! αu and αv along the same axes) minimise the relative L1 difference Σ|k·L_mf − L_ward| /
//! Σ L_ward of the lobe's outgoing radiance, with the weight k on ρs that keeps the total
//! (Σ k·L_mf = Σ L_ward: the group as bright on average as Ward makes it), over what this
//! scene makes of the group: the camera's view of its surfaces (a grid of camera rays that
//! land on it) and its view through diffuse bounces (camera paths off the other surfaces,
//! cosine-distributed, weighted by their ρd: a wall lit by a glossy floor, directly or through
//! the ceiling the floor sends the lamp's highlight to, shows the floor's lobe in directions
//! the camera never looks along), and at each of those
//! points a fixed set of incident directions with the radiance that arrives along them,
//! path-traced once through the scene (the fitter's incident-radiance cache, in small). The
//! directions come from a defensive mixture of the Ward lobe itself, the area lights and the
//! cosine, weighted by the balance heuristic, plus every punctual light; the same samples
//! serve every trial, so the objective is deterministic. The fit states what remains: the
//! lobe's L1 difference, and the difference relative to all the light the group reflects
//! there (diffuse part included), which is what a user sees in a render.

use crate::geometry::{offset_origin, Ray};
use crate::math::sampler::{mix64, unit_f32};
use crate::math::{warp, Rgb, Sampler, Vec2, Vec3};
use crate::render::bsdf::{MicrofacetLobe, WardLobe};
use crate::render::integrator::facing;
use crate::render::PathTracer;
use crate::scene::{Distribution, Material, Scene};
use rayon::prelude::*;

/// A fitted microfacet stand-in for a Ward lobe, and how well it stands in.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StandIn {
    pub distribution: Distribution,
    pub alpha_x: f32,
    pub alpha_y: f32,
    /// Weight on ρs: the stand-in's specular reflectance is k·ρs.
    pub k: f32,
    /// Σ|k·L_mf − L_ward| / Σ L_ward over the samples (the lobe's own radiance).
    pub lobe_error: f32,
    /// The same difference over all the radiance the group reflects there (lobe + diffuse).
    pub error: f32,
    /// Σ(k·L_mf − L_ward) / Σ(L_ward + L_diffuse): the mean brightness difference, signed.
    pub bias: f32,
    /// What a Beckmann lobe of Ward's own α, with its best k, leaves (the naive mapping).
    pub naive_error: f32,
    /// Camera views of the group the fit used, and views through diffuse bounces.
    pub views: usize,
    pub bounced: usize,
}

/// Incident directions per camera view: half from the Ward lobe, a quarter each from the area
/// lights and the cosine.
const DIRECTIONS: u32 = 64;
/// At most this many camera views of a group, and as many through bounces (evenly thinned).
const MAX_VIEWS: usize = 384;
/// Diffuse bounces a camera path may take before it lands on the group.
const BOUNCES: u32 = 3;

/// One camera view of the group: ωo in the lobe's frame, the incident samples (ωi in that
/// frame, Li cos θi / (N q(ωi))), and the material's reflectances there.
struct View {
    wo: Vec3,
    samples: Vec<(Vec3, Rgb)>,
    rho_d: Rgb,
    rho_s: Rgb,
    /// Seen through diffuse bounces (ρd and ρs then carry their reflectance).
    bounced: bool,
}

/// Fits the stand-in for the Ward lobe `lobe`, rotated by `theta`, over the camera's view of
/// `objects` (a group's objects, whose materials give ρd and ρs). None where the camera sees
/// none of them or no light reaches what it sees.
pub fn fit_ward(scene: &Scene, objects: &[usize], lobe: WardLobe, theta: f32) -> Option<StandIn> {
    let views = views(scene, objects, lobe, theta);
    if views.is_empty() {
        return None;
    }
    let target: Vec<Rgb> = views
        .iter()
        .map(|v| v.rho_s * sum(v, |wo, wi| lobe.eval(wo, wi)))
        .collect();
    let diffuse: Vec<Rgb> = views
        .iter()
        .map(|v| {
            v.rho_d
                * sum(
                    v,
                    |_, wi| if wi.z > 0.0 { crate::math::INV_PI } else { 0.0 },
                )
        })
        .collect();
    let total_target: f64 = target.iter().map(|t| sum3(*t)).sum();
    if !(total_target > 0.0) {
        return None;
    }
    let eval = |m: MicrofacetLobe| -> (f32, f64) {
        let model: Vec<Rgb> = views
            .iter()
            .map(|v| v.rho_s * sum(v, |wo, wi| m.eval(wo, wi)))
            .collect();
        best_scale(&model, &target)
    };
    let naive = eval(MicrofacetLobe {
        alpha_x: lobe.alpha_x,
        alpha_y: lobe.alpha_y,
        distribution: Distribution::Beckmann,
    });
    let isotropic = lobe.alpha_x == lobe.alpha_y;
    let mut best: Option<(MicrofacetLobe, f32, f64)> = None;
    for distribution in [Distribution::Beckmann, Distribution::Ggx] {
        let at = |lx: f32, ly: f32| {
            let m = MicrofacetLobe {
                alpha_x: (lobe.alpha_x * lx.exp()).clamp(1e-3, 1.0),
                alpha_y: (lobe.alpha_y * if isotropic { lx } else { ly }.exp()).clamp(1e-3, 1.0),
                distribution,
            };
            let (k, e) = eval(m);
            (m, k, e)
        };
        // A coarse grid in log α around Ward's own, then a pattern search that halves its step.
        let steps: Vec<f32> = (-6..=6).map(|i| i as f32 * 0.2).collect();
        let mut here = (0.0f32, 0.0f32);
        let mut cur = at(0.0, 0.0);
        for &lx in &steps {
            for &ly in if isotropic { &steps[6..7] } else { &steps[..] } {
                let c = at(lx, ly);
                if c.2 < cur.2 {
                    (here, cur) = ((lx, ly), c);
                }
            }
        }
        let mut step = 0.1f32;
        while step > 0.004 {
            let mut moved = false;
            let dirs: &[(f32, f32)] = if isotropic {
                &[(1.0, 0.0), (-1.0, 0.0)]
            } else {
                &[(1.0, 0.0), (-1.0, 0.0), (0.0, 1.0), (0.0, -1.0)]
            };
            for &(dx, dy) in dirs {
                let p = (here.0 + dx * step, here.1 + dy * step);
                let c = at(p.0, p.1);
                if c.2 < cur.2 {
                    (here, cur, moved) = (p, c, true);
                }
            }
            if !moved {
                step *= 0.5;
            }
        }
        if best.as_ref().is_none_or(|b| cur.2 < b.2) {
            best = Some(cur);
        }
    }
    let (m, k, err) = best?;
    let model: Vec<Rgb> = views
        .iter()
        .map(|v| v.rho_s * sum(v, |wo, wi| m.eval(wo, wi)))
        .collect();
    let whole: f64 = target
        .iter()
        .zip(&diffuse)
        .map(|(t, d)| sum3(*t + *d))
        .sum();
    let signed: f64 = model
        .iter()
        .zip(&target)
        .map(|(m, t)| sum3(*m * k - *t))
        .sum();
    Some(StandIn {
        distribution: m.distribution,
        alpha_x: m.alpha_x,
        alpha_y: m.alpha_y,
        k,
        lobe_error: (err / total_target) as f32,
        error: (err / whole) as f32,
        bias: (signed / whole) as f32,
        naive_error: (naive.1 / total_target) as f32,
        views: views.iter().filter(|v| !v.bounced).count(),
        bounced: views.iter().filter(|v| v.bounced).count(),
    })
}

fn sum3(c: Rgb) -> f64 {
    f64::from(c.x) + f64::from(c.y) + f64::from(c.z)
}

/// Σ f(ωo, ωi) · weight over a view's samples.
fn sum(v: &View, f: impl Fn(Vec3, Vec3) -> f32) -> Rgb {
    v.samples
        .iter()
        .fold(Rgb::ZERO, |acc, &(wi, w)| acc + w * f(v.wo, wi))
}

/// The k that makes the stand-in reflect, over all the views, as much as Ward does
/// (Σ k·m = Σ t: a render keeps the group's brightness), and the L1 difference Σ|k·m − t| that
/// remains, which the roughness search minimises.
fn best_scale(model: &[Rgb], target: &[Rgb]) -> (f32, f64) {
    let (m, t): (f64, f64) = model
        .iter()
        .zip(target)
        .fold((0.0, 0.0), |(a, b), (m, t)| (a + sum3(*m), b + sum3(*t)));
    let k = if m > 0.0 { t / m } else { 1.0 };
    let err = model
        .iter()
        .zip(target)
        .map(|(m, t)| {
            (0..3)
                .map(|c| (k * f64::from(m[c]) - f64::from(t[c])).abs())
                .sum::<f64>()
        })
        .sum();
    (k as f32, err)
}

/// The camera's views of `objects` with their incident samples (module comment): the points
/// the camera sees on them, and the points it sees through diffuse bounces off the other
/// surfaces (a wall lit by a glossy floor), weighted by the bounces' reflectance.
fn views(scene: &Scene, objects: &[usize], lobe: WardLobe, theta: f32) -> Vec<View> {
    let on_group = |h: &crate::scene::SurfaceHit| objects.contains(&(h.object as usize));
    let mut hits = Vec::new();
    for (nx, ny) in [(64, 48), (192, 144)] {
        hits = scene.camera_grid_hits(nx, ny);
        if hits.iter().filter(|(_, _, h)| on_group(h)).count() >= MAX_VIEWS {
            break;
        }
    }
    // (camera or bounce ray, its hit on the group, the bounce's reflectance, path segments).
    // Thinned to MAX_VIEWS, each view then standing for `stride` pixels' worth.
    let thin = |v: Vec<(Ray, crate::scene::SurfaceHit, Rgb, u32)>| -> Vec<_> {
        let stride = v.len().div_ceil(MAX_VIEWS).max(1);
        (v.into_iter().step_by(stride))
            .map(|(r, h, w, d)| (r, h, w * stride as f32, d))
            .collect::<Vec<_>>()
    };
    let direct: Vec<_> = (hits.iter())
        .filter(|(_, _, h)| on_group(h))
        .map(|(_, r, h)| (*r, *h, Rgb::ONE, 1))
        .collect();
    // Camera paths through up to BOUNCES cosine-distributed bounces off the other surfaces,
    // to where they first land on the group: its light reaches the image there with the
    // product of the bounces' ρd (a glossy floor lights the walls directly, and through the
    // ceiling it sends the lamp's highlight to).
    let bounced: Vec<_> = (hits.iter().enumerate())
        .filter(|(_, (_, _, h))| !on_group(h))
        .filter_map(|(i, (_, ray, h))| {
            let (mut ray, mut h, mut weight) = (*ray, *h, Rgb::ONE);
            for depth in 2..(2 + BOUNCES).min(scene.render.max_depth) {
                let o = &scene.objects[h.object as usize];
                // A mirror or black surface has no diffuse albedo: the walk ends below.
                weight *= o.material.rho_d_at(&h);
                if o.is_emitter() || weight.max_element() <= 0.0 {
                    return None;
                }
                let (frame, ng) = facing(h.frame, h.ng, -ray.d);
                let hash = mix64(0x424f_554e_4345 ^ ((i as u64) << 8) ^ u64::from(depth));
                let u = Vec2::new(unit_f32(hash), unit_f32(mix64(hash)));
                let d = frame.to_world(warp::cosine_hemisphere(u));
                if d.dot(ng) <= 0.0 {
                    return None;
                }
                ray = Ray::new(offset_origin(h.p, ng, d), d);
                h = scene.intersect(&ray, f32::INFINITY)?;
                if on_group(&h) {
                    return Some((ray, h, weight, depth));
                }
            }
            None
        })
        .collect();
    let all: Vec<_> = thin(direct).into_iter().chain(thin(bounced)).collect();
    let pt = PathTracer::new(scene);
    all.par_iter()
        .enumerate()
        .filter_map(|(i, (ray, hit, weight, depth))| {
            let (rho_d, rho_s) = match &scene.objects[hit.object as usize].material {
                Material::Ward { rho_d, rho_s, .. } => (*rho_d, *rho_s),
                Material::Textured {
                    texture,
                    scale,
                    varnish: Some(v),
                } => (*scale * texture.at(hit), v.rho_s),
                _ => return None,
            };
            let (rho_d, rho_s) = (rho_d * *weight, rho_s * *weight);
            let (frame, ng) = facing(hit.frame.rotated(theta), hit.ng, -ray.d);
            let wo = frame.to_local(-ray.d);
            if wo.z <= 0.0 {
                return None;
            }
            let mut sampler = Sampler::new(0x0053_5441_4e44_494e, i as u64);
            let mut samples = Vec::with_capacity(DIRECTIONS as usize);
            let n = DIRECTIONS as f32;
            for s in 0..DIRECTIONS {
                sampler.start_sample(s);
                let wi_world = match s % 4 {
                    0 | 1 => lobe
                        .sample(wo, sampler.next_2d())
                        .map(|w| frame.to_world(w)),
                    2 => pt.lights.sample(hit.p, &mut sampler).map(|l| l.wi),
                    _ => Some(frame.to_world(warp::cosine_hemisphere(sampler.next_2d()))),
                };
                let Some(wi_world) = wi_world else { continue };
                let wi = frame.to_local(wi_world);
                if wi.z <= 0.0 || wi_world.dot(ng) <= 0.0 {
                    continue;
                }
                let r = Ray::new(offset_origin(hit.p, ng, wi_world), wi_world);
                let first = scene.intersect_hit(&r, f32::INFINITY);
                let p_light = first.map_or(0.0, |h| {
                    let n = scene.geometry.faces[h.prim as usize].ng;
                    pt.lights.pdf(h.prim, h.t, wi_world, n)
                });
                let q = 0.5 * lobe.pdf(wo, wi)
                    + 0.25 * p_light
                    + 0.25 * warp::cosine_hemisphere_pdf(wi.z);
                if !(q > 0.0) {
                    continue;
                }
                let li = pt.trace_from(r, first, &mut sampler, *depth, true);
                samples.push((wi, li * (wi.z / (n * q))));
            }
            for l in pt.lights.punctual_samples(hit.p) {
                let wi = frame.to_local(l.wi);
                let origin = offset_origin(hit.p, ng, l.wi);
                if wi.z > 0.0 && l.wi.dot(ng) > 0.0 && pt.lights.visible(scene, origin, &l) {
                    samples.push((wi, l.radiance * wi.z));
                }
            }
            Some(View {
                wo,
                samples,
                rho_d,
                rho_s,
                bounced: *depth > 1,
            })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_scale_keeps_the_total() {
        let m = [Rgb::splat(1.0), Rgb::splat(1.0), Rgb::splat(1.0)];
        let t = [Rgb::splat(2.0), Rgb::splat(2.0), Rgb::splat(5.0)];
        let (k, e) = best_scale(&m, &t);
        assert_eq!(k, 3.0);
        assert!((e - 12.0).abs() < 1e-9);
    }

    /// Seen from the figure's camera, directly and through the walls, the fitted stand-in of
    /// figure6's anisotropic Ward floor leaves no more than the naive mapping (Beckmann with
    /// Ward's α) and well under a sixth of the floor's light.
    #[test]
    fn figure6_floor_stand_in_beats_the_naive_mapping() {
        let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
        let mut scene = crate::scene::load_scene(&root.join("scenes/figure6/scene.toml")).unwrap();
        scene.render.max_depth = scene.render.max_depth.min(3);
        let oi = scene
            .objects
            .iter()
            .position(|o| o.name == "floor")
            .unwrap();
        let Material::Ward {
            alpha_x,
            alpha_y,
            theta,
            ..
        } = scene.objects[oi].material
        else {
            panic!("figure6's floor is Ward");
        };
        let lobe = WardLobe {
            alpha_x,
            alpha_y,
            variant: scene.render.ward_variant,
        };
        let s = fit_ward(&scene, &[oi], lobe, theta).unwrap();
        assert!(s.views > 100, "{s:?}");
        assert!(s.lobe_error <= s.naive_error, "{s:?}");
        assert!(s.bounced > 50 && s.error < 0.15, "{s:?}");
    }
}
