//! The path tracer: next-event estimation on area lights combined with BSDF sampling by
//! multiple importance sampling (power heuristic; Veach 1997), Russian roulette, and a maximum
//! depth with Mitsuba's meaning: `max_depth` = the largest number of segments of a path
//! (1: emitters seen directly, 2: direct lighting, …).
//!
//! Surfaces are two-sided: the shading frame is flipped towards the viewer.

use super::bsdf::{Bsdf, MicrofacetLobe, WardLobe};
use super::lights::Lights;
use super::mirror_lights::MirrorLights;
use crate::geometry::{offset_origin, Hit, Ray};
use crate::math::{power_heuristic, Frame, Rgb, Sampler, Vec2, Vec3};
use crate::scene::{Material, Object, Scene, SurfaceHit, WardVariant};

/// The BSDF of `material` at a hit, with the shading frame it is expressed in.
#[inline]
pub fn bsdf_at(material: &Material, hit: &SurfaceHit, variant: WardVariant) -> (Bsdf, Frame) {
    let (bsdf, theta) = material_bsdf(material, |t| t.at(hit), variant);
    (bsdf, hit.frame.rotated(theta))
}

/// The BSDF of `material` where its textures read `texel` (a texture's value at the point),
/// and the angle its lobe's frame is turned by about the shading normal (θ of a Ward or
/// microfacet lobe, or of a textured group's varnish; 0 for the rest).
#[inline]
pub fn material_bsdf(
    material: &Material,
    texel: impl Fn(&crate::scene::texture::Texture) -> Rgb,
    variant: WardVariant,
) -> (Bsdf, f32) {
    (bsdf_of(material, texel, variant), lobe_rotation(material))
}

/// The angle a material's lobe frame is turned by about the shading normal: θ of a Ward or
/// microfacet lobe, or of a textured group's varnish; 0 for the rest.
#[inline]
pub fn lobe_rotation(material: &Material) -> f32 {
    match material {
        Material::Ward { theta, .. } | Material::Microfacet { theta, .. } => *theta,
        Material::Textured {
            varnish: Some(v), ..
        } => v.theta,
        _ => 0.0,
    }
}

/// `material_bsdf`'s BSDF.
#[inline]
fn bsdf_of(
    material: &Material,
    texel: impl Fn(&crate::scene::texture::Texture) -> Rgb,
    variant: WardVariant,
) -> Bsdf {
    match material {
        Material::Textured {
            texture,
            scale,
            varnish: None,
        } => Bsdf::Diffuse {
            rho_d: *scale * texel(texture),
        },
        Material::Textured {
            texture,
            scale,
            varnish: Some(v),
        } => uniform_bsdf(
            &Material::Ward {
                rho_d: *scale * texel(texture),
                rho_s: v.rho_s,
                alpha_x: v.alpha_x,
                alpha_y: v.alpha_y,
                theta: v.theta,
            },
            variant,
        )
        .unwrap_or(Bsdf::Black),
        Material::TexturedPlastic {
            texture,
            scale,
            rho_s,
            alpha,
            eta,
            distribution,
        } => Bsdf::Plastic {
            rho_d: *scale * texel(texture),
            rho_s: *rho_s,
            coat: super::bsdf::Coat::get(*alpha, *eta, *distribution),
        },
        _ => uniform_bsdf(material, variant).unwrap_or(Bsdf::Black),
    }
}

/// The BSDF of a material that is the same everywhere, in its lobe's own frame (a Ward or
/// microfacet lobe's rotation θ is the frame's, left to the caller); None for a textured one.
#[inline]
pub fn uniform_bsdf(material: &Material, variant: WardVariant) -> Option<Bsdf> {
    Some(match material {
        Material::Diffuse { rho_d } => Bsdf::Diffuse { rho_d: *rho_d },
        Material::Mirror { rho_s } => Bsdf::DiffuseMirror {
            rho_d: Rgb::ZERO,
            rho_s: *rho_s,
        },
        Material::DiffuseMirror { rho_d, rho_s } => Bsdf::DiffuseMirror {
            rho_d: *rho_d,
            rho_s: *rho_s,
        },
        Material::Ward {
            rho_d,
            rho_s,
            alpha_x,
            alpha_y,
            ..
        } => Bsdf::Ward {
            rho_d: *rho_d,
            rho_s: *rho_s,
            lobe: WardLobe {
                alpha_x: *alpha_x,
                alpha_y: *alpha_y,
                variant,
            },
        },
        Material::Microfacet {
            rho_d,
            rho_s,
            alpha_x,
            alpha_y,
            distribution,
            ..
        } => Bsdf::Microfacet {
            rho_d: *rho_d,
            rho_s: *rho_s,
            lobe: MicrofacetLobe {
                alpha_x: *alpha_x,
                alpha_y: *alpha_y,
                distribution: *distribution,
            },
        },
        Material::Plastic {
            rho_d,
            rho_s,
            alpha,
            eta,
            distribution,
        } => Bsdf::Plastic {
            rho_d: *rho_d,
            rho_s: *rho_s,
            coat: super::bsdf::Coat::get(*alpha, *eta, *distribution),
        },
        Material::Black => Bsdf::Black,
        Material::Textured { .. } | Material::TexturedPlastic { .. } => return None,
    })
}

/// The ray an ideal mirror at `hit` reflects `ray` into (about the shading normal, on the
/// viewer's side), from just off the surface; None where that direction goes below the
/// geometric surface. What the index buffers' mirror ids and the fitter's mirror radiance trace.
#[inline]
pub fn mirror_ray(ray: &Ray, hit: &SurfaceHit) -> Option<Ray> {
    let (frame, ng) = facing(hit.frame, hit.ng, -ray.d);
    let r = crate::math::reflect(-ray.d, frame.n);
    (r.dot(ng) > 0.0).then(|| Ray::new(offset_origin(hit.p, ng, r), r))
}

/// Flips a frame (and so the BSDF's hemisphere) to the side of `wo`; also flips the geometric
/// normal it is paired with. Returns the frame and the geometric normal on the viewer's side.
#[inline]
pub fn facing(frame: Frame, ng: Vec3, wo: Vec3) -> (Frame, Vec3) {
    if ng.dot(wo) >= 0.0 {
        let f = if frame.n.dot(ng) < 0.0 {
            Frame {
                s: frame.s,
                t: -frame.t,
                n: -frame.n,
            }
        } else {
            frame
        };
        (f, ng)
    } else {
        let f = if frame.n.dot(ng) > 0.0 {
            Frame {
                s: frame.s,
                t: -frame.t,
                n: -frame.n,
            }
        } else {
            frame
        };
        (f, -ng)
    }
}

/// A path in flight: its current ray, throughput, radiance gathered so far, and what the MIS
/// weight of emission at its next hit needs.
#[derive(Clone, Copy, Debug)]
pub struct PathState {
    pub ray: Ray,
    pub beta: Rgb,
    pub l: Rgb,
    /// Segments of the path so far, `ray`'s included once it has arrived.
    pub segments: u32,
    /// How `ray`'s direction was drawn: None = delta or camera (emission counts fully), else the
    /// BSDF sampling density.
    pub prev_pdf: Option<f32>,
    /// `ray` is the path's first segment.
    pub first: bool,
    /// Whether emission seen at the first hit counts fully (a camera ray, or a ray after a
    /// delta reflection); otherwise it is left out entirely (the caller did next-event
    /// estimation for it without MIS).
    pub count_emission: bool,
    /// Where its segments arrived.
    pub touched: Touched,
    /// When `ray` left a planar mirror of `PathTracer::mirrors` that the segment before it
    /// reached by BSDF sampling: that sampling's density (else 0), and the length of that
    /// segment. Emission found at the end of `ray` is then MIS-weighted against the mirror's
    /// virtual light (`render::mirror_lights`).
    pub mirror_pdf: f32,
    pub mirror_t: f32,
}

/// The groups whose surfaces a path's segments arrived at, and whether one left the scene
/// where what it finds there counts (not a first segment whose emission the caller takes).
/// A path's radiance depends on a group's material only through its vertices there (light
/// sampling, shadow rays and Russian roulette read the materials of the path's own vertices
/// alone), and on the stray light only where it leaves the scene: traced again with the same
/// random numbers in a scene where only those changed, a path that touched neither gives the
/// same radiance to the bit. Bit g stands for group g below 63, bit 63 for all the others.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Touched {
    groups: u64,
    escaped: bool,
}

impl Touched {
    #[inline(always)]
    fn arrive(&mut self, group: usize) {
        self.groups |= 1 << group.min(63);
    }

    /// Whether a segment may have arrived at group `g` (certainly, for g below 63).
    pub fn group(&self, g: usize) -> bool {
        self.groups >> g.min(63) & 1 == 1
    }

    /// Whether the path found what lies outside the scene.
    pub fn escaped(&self) -> bool {
        self.escaped
    }
}

impl PathState {
    /// A path whose next segment is `ray`, after `depth` segments elsewhere.
    pub fn new(ray: Ray, depth: u32, count_emission: bool) -> PathState {
        PathState {
            ray,
            beta: Rgb::ONE,
            l: Rgb::ZERO,
            segments: depth,
            prev_pdf: None,
            first: true,
            count_emission,
            touched: Touched::default(),
            mirror_pdf: 0.0,
            mirror_t: 0.0,
        }
    }

    /// Makes this the path `new(ray, depth, count_emission)` in place, field by field
    /// (`*self = PathState::new(..)` built a copy on the stack and moved it in pieces that
    /// straddled its smaller stores, which missed store forwarding). The pattern names every
    /// field, so a field added to the struct must be given its start here too.
    #[inline(always)]
    pub fn restart(&mut self, ray: Ray, depth: u32, count_emission: bool) {
        let PathState {
            ray: r,
            beta,
            l,
            segments,
            prev_pdf,
            first,
            count_emission: counts,
            touched,
            mirror_pdf,
            mirror_t,
        } = self;
        *r = ray;
        *beta = Rgb::ONE;
        *l = Rgb::ZERO;
        *segments = depth;
        *prev_pdf = None;
        *first = true;
        *counts = count_emission;
        *touched = Touched::default();
        *mirror_pdf = 0.0;
        *mirror_t = 0.0;
    }
}

/// What a path met on its way, told as the path tracer goes (`PathTracer::trace_recorded`),
/// so that the path can be weighed again under other materials (`render::replay`): everything
/// it found that does not depend on the materials of its vertices (emission and light samples,
/// with their MIS weights, the densities its directions were drawn with, Russian roulette's
/// survival factors), and where each vertex's BSDF is to be read. `()` records nothing, which
/// the compiler removes.
pub trait Record {
    /// Whether the hooks keep anything: the eight-lane loop (`batch::trace_recorded_jobs`)
    /// skips, for `()` alone, the hit record that `vertex` is told of.
    const KEEPS: bool = true;
    /// Whether light samples the BSDF does not reflect (f = 0, whose shadow rays the path
    /// tracer skips) are to be traced and told too: under other materials they may count.
    const EVERY_LIGHT: bool = false;
    /// Emission (or the environment's radiance) found where the path arrived, times its MIS
    /// weight: the path's radiance gains it times the throughput so far.
    #[inline(always)]
    fn found(&mut self, _le: Rgb) {}
    /// A vertex at `hit`, its shading frame turned to the viewer's side (`flipped`: turned
    /// over), ωo in that frame (after the lobe's rotation), and the BSDF it scatters by.
    #[inline(always)]
    fn vertex(&mut self, _hit: &SurfaceHit, _flipped: bool, _wo: Vec3, _bsdf: &Bsdf) {}
    /// The path ends at a black surface.
    #[inline(always)]
    fn black(&mut self, _hit: &SurfaceHit) {}
    /// A light sample at the current vertex: ωi in its frame, and the light's radiance times
    /// cos θi × MIS weight / density (the radiance gains it times f(ωo, ωi) and the throughput).
    #[inline(always)]
    fn light(&mut self, _wi: Vec3, _term: Rgb) {}
    /// The path goes on from the current vertex along ωi (in its frame), drawn with density
    /// `pdf` (for a delta lobe, the probability of choosing it), its throughput then divided
    /// by Russian roulette's survival probability (`rr`: 1 / that, or 1).
    #[inline(always)]
    fn scattered(&mut self, _wi: Vec3, _pdf: f32, _delta: bool, _rr: f32) {}
}

impl Record for () {
    const KEEPS: bool = false;
}

/// A surface point to scatter from: the BSDF in its shading frame, both turned to the side the
/// path arrives from, and the outgoing direction in that frame.
#[derive(Clone, Copy, Debug)]
pub(super) struct Vertex {
    pub p: Vec3,
    pub bsdf: Bsdf,
    pub frame: Frame,
    /// Geometric normal on the arriving side.
    pub ng: Vec3,
    pub wo: Vec3,
}

pub struct PathTracer<'a> {
    pub scene: &'a Scene,
    pub lights: Lights,
    /// Planar mirrors whose images of the area lights next-event estimation samples
    /// (`render::mirror_lights`); none unless `with_mirror_lights`.
    pub mirrors: MirrorLights,
    pub max_depth: u32,
    pub rr_depth: u32,
}

impl<'a> PathTracer<'a> {
    pub fn new(scene: &'a Scene) -> PathTracer<'a> {
        PathTracer {
            scene,
            lights: Lights::new(scene),
            mirrors: MirrorLights::default(),
            max_depth: scene.render.max_depth,
            rr_depth: scene.render.rr_depth,
        }
    }

    /// This path tracer, sampling the area lights' images in the scene's planar mirrors too
    /// (`render::mirror_lights`): less noise where light arrives through a mirror. What
    /// `matfit render` uses (`film::render_image`); the recovery's caches do not, because a
    /// path's radiance then depends on a mirror's reflectance without the path touching the
    /// mirror, and they trace again only the paths that touched a group whose material changed
    /// (`Touched`).
    pub fn with_mirror_lights(mut self) -> PathTracer<'a> {
        self.mirrors = MirrorLights::new(self.scene, &self.lights);
        self
    }

    /// Radiance arriving along `ray` (towards its origin).
    pub fn li(&self, ray: Ray, sampler: &mut Sampler) -> Rgb {
        self.trace(ray, sampler, 0, true)
    }

    /// Radiance along `ray` for a path that already has `depth` segments before this one.
    /// `count_emission`: whether emission seen at the first hit counts fully (a camera ray, or a
    /// ray after a delta reflection); otherwise it is left out entirely (the caller did next-event
    /// estimation for it without MIS).
    pub fn trace(&self, ray: Ray, sampler: &mut Sampler, depth: u32, count_emission: bool) -> Rgb {
        let first_hit = self.scene.intersect_hit(&ray, f32::INFINITY);
        self.trace_from(ray, first_hit, sampler, depth, count_emission)
    }

    /// [`PathTracer::trace`] for a caller that has already intersected `ray`: `first_hit` is
    /// `scene.intersect_hit(&ray, ∞)`.
    pub fn trace_from(
        &self,
        ray: Ray,
        first_hit: Option<Hit>,
        sampler: &mut Sampler,
        depth: u32,
        count_emission: bool,
    ) -> Rgb {
        self.trace_path(ray, first_hit, sampler, depth, count_emission)
            .l
    }

    /// [`PathTracer::trace_from`], the whole path at its end: its radiance and where it went.
    pub fn trace_path(
        &self,
        ray: Ray,
        first_hit: Option<Hit>,
        sampler: &mut Sampler,
        depth: u32,
        count_emission: bool,
    ) -> PathState {
        self.trace_recorded(ray, first_hit, sampler, depth, count_emission, &mut ())
    }

    /// [`PathTracer::trace_path`], telling `rec` what the path met on its way (`Record`).
    pub fn trace_recorded(
        &self,
        ray: Ray,
        first_hit: Option<Hit>,
        sampler: &mut Sampler,
        depth: u32,
        count_emission: bool,
        rec: &mut impl Record,
    ) -> PathState {
        let mut st = PathState::new(ray, depth, count_emission);
        let mut hit = first_hit;
        while let Some(obj) = self.arrive(&mut st, hit.as_ref(), rec) {
            let Some(v) = hit.and_then(|h| self.vertex(&st, &h, obj, rec)) else {
                break;
            };
            if !self.scatter(&mut st, &v, sampler, rec) {
                break;
            }
            hit = self.scene.intersect_hit(&st.ray, f32::INFINITY);
        }
        st
    }

    /// The first half of a path segment: `hit` is where `st.ray` lands. Adds the emission seen
    /// there (MIS-weighted against next-event estimation at the previous vertex), telling `rec`,
    /// and returns the object hit, or None where the path ends (no hit, maximum depth). Needs
    /// only the BVH's hit: the rest of the hit record waits for `vertex`.
    #[inline(always)]
    pub(super) fn arrive(
        &self,
        st: &mut PathState,
        hit: Option<&Hit>,
        rec: &mut impl Record,
    ) -> Option<&'a Object> {
        st.segments += 1;
        let Some(hit) = hit else {
            // A first segment whose emission does not count finds no stray light either.
            st.touched.escaped |= !st.first || st.count_emission;
            // The path leaves the scene: the environment, MIS-weighted as an emitter is.
            self.lights.at_infinity(st.ray.d, |le, pl| {
                let w = match st.prev_pdf {
                    _ if st.first => f32::from(u8::from(st.count_emission)),
                    None => 1.0,
                    Some(pb) => power_heuristic(pb, pl),
                };
                st.l += st.beta * le * w;
                rec.found(le * w);
            });
            return None;
        };
        let g = &*self.scene.geometry;
        let obj = &self.scene.objects[g.tris[hit.prim as usize].object as usize];
        st.touched.arrive(obj.group);
        let via_mirror = std::mem::replace(&mut st.mirror_pdf, 0.0);
        // Emission (front side only).
        if obj.is_emitter() {
            let ng = g.faces[hit.prim as usize].ng;
            if ng.dot(-st.ray.d) > 0.0 {
                let w = match st.prev_pdf {
                    _ if st.first => {
                        if st.count_emission {
                            1.0
                        } else {
                            0.0
                        }
                    }
                    // A BSDF-sampled path through a planar mirror, which the mirror's virtual
                    // light also samples: the light's density at the vertex before the mirror
                    // is over the whole length of the reflected path.
                    None if via_mirror > 0.0 => {
                        let dist = st.mirror_t + hit.t;
                        let pl = self.lights.pdf(hit.prim, dist, st.ray.d, ng);
                        power_heuristic(via_mirror, pl)
                    }
                    None => 1.0,
                    Some(pb) => {
                        let pl = self.lights.pdf(hit.prim, hit.t, st.ray.d, ng);
                        power_heuristic(pb, pl)
                    }
                };
                st.l += st.beta * obj.emission * w;
                rec.found(obj.emission * w);
            }
        }
        if !self.mirrors.is_empty() && !st.first {
            if let Some(pb) = st.prev_pdf {
                if self.mirrors.contains(hit.prim) {
                    st.mirror_pdf = pb;
                    st.mirror_t = hit.t;
                }
            }
        }
        st.first = false;
        if st.segments >= self.max_depth {
            return None;
        }
        Some(obj)
    }

    /// The vertex to scatter from where `st.ray` has arrived (`arrive` gave `obj`) at `hit`, or
    /// None on a black surface; `rec` is told where it is.
    #[inline(always)]
    pub(super) fn vertex(
        &self,
        st: &PathState,
        hit: &Hit,
        obj: &Object,
        rec: &mut impl Record,
    ) -> Option<Vertex> {
        let sh = self.scene.surface_hit(&st.ray, hit);
        let (bsdf, frame) = bsdf_at(&obj.material, &sh, self.scene.render.ward_variant);
        if matches!(bsdf, Bsdf::Black) {
            rec.black(&sh);
            return None;
        }
        let wo_world = -st.ray.d;
        let (faced, ng) = facing(frame, sh.ng, wo_world);
        let wo = faced.to_local(wo_world);
        rec.vertex(&sh, faced.n.dot(frame.n) < 0.0, wo, &bsdf);
        Some(Vertex {
            p: sh.p,
            bsdf,
            frame: faced,
            ng,
            wo,
        })
    }

    /// Next-event estimation at `v` of the light point that `uc` and `u` choose (as
    /// `Lights::sample_with`), seen through each planar mirror (`render::mirror_lights`),
    /// MIS-weighted against BSDF sampling; for paths within `max_depth` (two segments more).
    pub(super) fn sample_mirror_lights(&self, st: &mut PathState, v: &Vertex, uc: f32, u: Vec2) {
        if st.segments + 2 > self.max_depth || !self.lights.has_area() {
            return;
        }
        let (y, tri) = self.lights.point(uc, u);
        for k in 0..self.mirrors.len() {
            let Some(ms) = self
                .mirrors
                .sample(k, v.p, y, tri.n, tri.radiance, tri.pdf_area)
            else {
                continue;
            };
            let wi = v.frame.to_local(ms.wi);
            if wi.z <= 0.0 || v.ng.dot(ms.wi) <= 0.0 {
                continue;
            }
            let f = v.bsdf.eval(v.wo, wi);
            if !(f.max_element() > 0.0) {
                continue;
            }
            // Both segments unblocked: to the mirror, and from it to the light.
            let origin = offset_origin(v.p, v.ng, ms.wi);
            let m_origin = offset_origin(ms.m, ms.mirror_n, ms.point - ms.m);
            if !self.clear(origin, ms.m) || !self.clear(m_origin, ms.point) {
                continue;
            }
            st.touched.arrive(ms.group);
            let w = power_heuristic(ms.pdf, v.bsdf.pdf(v.wo, wi));
            st.l += st.beta * f * ms.radiance * (wi.z * w / ms.pdf);
        }
    }

    /// Whether the segment from `origin` (already offset off its surface) to `end` is
    /// unblocked, stopping short of `end` as `Lights::visible` does.
    fn clear(&self, origin: Vec3, end: Vec3) -> bool {
        let d = end - origin;
        let len = d.length();
        let eps = 2e-4 * (1.0 + end.abs().max_element());
        len > eps && !self.scene.occluded(&Ray::new(origin, d / len), len - eps)
    }

    /// The second half of a path segment: next-event estimation at `v`, then the BSDF-sampled
    /// direction and Russian roulette. Sets `st.ray` to the next segment and returns true, or
    /// returns false where the path ends. Draws 3 + 3 + 1 sampler dimensions (light, BSDF,
    /// roulette) in that order; `batch.rs` relies on it. `rec` is told the light samples and
    /// the direction drawn.
    #[inline(always)]
    pub(super) fn scatter<R: Record>(
        &self,
        st: &mut PathState,
        v: &Vertex,
        sampler: &mut Sampler,
        rec: &mut R,
    ) -> bool {
        let (bsdf, frame, ng, wo) = (&v.bsdf, &v.frame, v.ng, v.wo);
        // Next-event estimation: one point on an area light, one direction to the environment
        // and to each disc light, and every punctual light.
        if bsdf.has_smooth_part() {
            let (uc, u) = (sampler.next_1d(), sampler.next_2d());
            // The light point's images in planar mirrors first: the eight-lane loop adds them
            // before its lanes' own light samples (`batch::lane_mirror_lights`).
            if !self.mirrors.is_empty() {
                self.sample_mirror_lights(st, v, uc, u);
            }
            let area = self.lights.sample_with(v.p, uc, u);
            let env = self.lights.sample_environment(v.p, sampler);
            let punctual = self.lights.punctual_samples(v.p);
            let discs = (0..self.lights.disc_count())
                .filter_map(|k| self.lights.sample_disc(k, v.p, sampler));
            for ls in area.into_iter().chain(env).chain(punctual).chain(discs) {
                let wi = frame.to_local(ls.wi);
                let cos_g = ng.dot(ls.wi);
                if wi.z > 0.0 && cos_g > 0.0 {
                    let f = bsdf.eval(wo, wi);
                    let reflects = f.max_element() > 0.0;
                    if reflects || R::EVERY_LIGHT {
                        let origin = offset_origin(v.p, ng, ls.wi);
                        if self.lights.visible(self.scene, origin, &ls) {
                            let w = if ls.delta {
                                1.0
                            } else {
                                power_heuristic(ls.pdf, bsdf.pdf(wo, wi))
                            };
                            if reflects {
                                st.l += st.beta * f * ls.radiance * (wi.z * w / ls.pdf);
                            }
                            rec.light(wi, ls.radiance * (wi.z * w / ls.pdf));
                        }
                    }
                }
            }
        } else {
            // Consume the same dimensions so that paths stay stratified alike.
            sampler.next_1d();
            sampler.next_2d();
        }
        // Continue the path by sampling the BSDF.
        let Some(bs) = bsdf.sample(wo, sampler) else {
            return false;
        };
        let wi_world = frame.to_world(bs.wi);
        if ng.dot(wi_world) <= 0.0 {
            return false; // shading normal sent the path into the surface
        }
        st.beta *= bs.weight;
        st.prev_pdf = (!bs.delta).then_some(bs.pdf);
        if st.beta.max_element() <= 0.0 || !st.beta.is_finite() {
            return false;
        }
        // Russian roulette from segment `rr_depth` on, as Mitsuba 3 plays it: continue with
        // probability min(max β, 0.95). From segment 5 by default, the most efficient start
        // on figure6 (bench/README.md, "Design measurements").
        let u_rr = sampler.next_1d();
        if st.segments >= self.rr_depth {
            let q = (1.0 - st.beta.max_element()).max(0.05);
            if u_rr < q {
                return false;
            }
            st.beta /= 1.0 - q;
            rec.scattered(bs.wi, bs.pdf, bs.delta, 1.0 / (1.0 - q));
        } else {
            rec.scattered(bs.wi, bs.pdf, bs.delta, 1.0);
        }
        st.ray = Ray::new(offset_origin(v.p, ng, wi_world), wi_world);
        true
    }
}
