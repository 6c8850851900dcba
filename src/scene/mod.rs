//! Scenes: the TOML schema, mesh loaders, cameras, materials, and the loaded [`Scene`] that the
//! renderer and the fitter read.

pub mod atlas;
pub mod camera;
mod camera_spec;
mod context;
pub mod edit;
pub mod environment;
pub mod error;
pub mod light;
pub mod lint;
pub mod load;
pub mod material;
pub mod meshio;
pub mod schema;
pub mod texture;
pub mod view;
pub mod write;

pub use camera::Camera;
pub use error::SceneError;
pub use light::{Punctual, PunctualLight};
pub use load::load_scene;
pub use material::{Distribution, Material, RhoBound, Varnish, WardVariant};
pub use view::View;

use crate::geometry::packet::{Packet, LANES};
use crate::geometry::{Bvh, Hit, Ray};
use crate::math::{Frame, Rgb, Vec2, Vec3};
use std::path::PathBuf;
use std::sync::Arc;

/// Render settings of a scene (the `[render]` table).
#[derive(Clone, Debug, PartialEq)]
pub struct RenderSettings {
    pub spp: u32,
    pub max_depth: u32,
    /// Russian roulette applies from this path segment on (1: the camera ray's hit). 5, as
    /// Mitsuba 3's `rr_depth`: paths then do the same work per sample in both renderers.
    pub rr_depth: u32,
    pub seed: u64,
    pub ward_variant: WardVariant,
}

impl Default for RenderSettings {
    fn default() -> Self {
        RenderSettings {
            spp: 64,
            max_depth: 8,
            rr_depth: 5,
            seed: 0,
            ward_variant: WardVariant::Ward1992,
        }
    }
}

/// A group: objects assumed to share one reflectance (§3.1 of the notes).
#[derive(Clone, Debug)]
pub struct Group {
    pub name: String,
    /// Objects of this group, as indices into `Scene::objects`.
    pub objects: Vec<usize>,
    /// A fixed group keeps the material the scene gives it; `recover` does not fit it.
    pub fixed: bool,
}

/// One object of the scene: its place in the triangle list, its group, its surface.
#[derive(Clone, Debug)]
pub struct Object {
    pub name: String,
    pub group: usize,
    pub material: Material,
    /// Emitted radiance (front side only); zero for objects that are not lights.
    pub emission: Rgb,
    /// Reference direction of the anisotropy angle θ (world space), if given.
    pub tangent: Option<Vec3>,
    /// Range of this object's triangles in `Geometry::tris`.
    pub tri_range: std::ops::Range<u32>,
    /// Total area (world units²).
    pub area: f32,
    /// Line of the object's entry in the scene file (1-based), for messages.
    pub line: usize,
}

impl Object {
    pub fn is_emitter(&self) -> bool {
        self.emission.max_element() > 0.0
    }
}

/// A triangle of the scene: vertex indices into the shared arrays and its object.
#[derive(Clone, Copy, Debug)]
pub struct Tri {
    pub v: [u32; 3],
    pub object: u32,
}

/// The immutable geometry of a scene, shared between the scene and its edited copies.
pub struct Geometry {
    pub positions: Vec<Vec3>,
    /// Shading normals per vertex (the geometric normal where the source had none).
    pub normals: Vec<Vec3>,
    pub uvs: Vec<Vec2>,
    pub tris: Vec<Tri>,
    /// Per triangle, what a hit needs that does not depend on where the triangle is hit.
    pub faces: Vec<Face>,
    pub bvh: Bvh,
}

/// Precomputed per-triangle shading data (`Geometry::faces`).
#[derive(Clone, Copy, Debug)]
pub struct Face {
    /// Unit geometric normal, as wound.
    pub ng: Vec3,
    /// dp/du of the triangle's UV parametrisation (zero if degenerate): the default tangent.
    pub dpdu: Vec3,
    /// The shading frame, when it is the same all over the triangle (its three vertex normals
    /// are equal): every flat-shaded triangle.
    pub frame: Option<Frame>,
}

impl Geometry {
    /// Fills `faces` from the triangles (`tangents[object]` is the object's tangent, if any).
    pub fn compute_faces(&mut self, tangents: &[Option<Vec3>]) {
        let faces = self
            .tris
            .iter()
            .map(|tri| {
                let [i0, i1, i2] = tri.v.map(|i| i as usize);
                let (p0, p1, p2) = (self.positions[i0], self.positions[i1], self.positions[i2]);
                let ng = (p1 - p0).cross(p2 - p0).normalize();
                let (uv0, uv1, uv2) = (self.uvs[i0], self.uvs[i1], self.uvs[i2]);
                let (duv1, duv2) = (uv1 - uv0, uv2 - uv0);
                let det = duv1.x * duv2.y - duv1.y * duv2.x;
                let dpdu = if det.abs() > 1e-12 {
                    ((p1 - p0) * duv2.y - (p2 - p0) * duv1.y) / det
                } else {
                    Vec3::ZERO
                };
                let n = self.normals[i0];
                let flat = n == self.normals[i1] && n == self.normals[i2];
                let frame = flat.then(|| {
                    shading_frame(shading_normal(n, ng), tangents[tri.object as usize], dpdu)
                });
                Face { ng, dpdu, frame }
            })
            .collect();
        self.faces = faces;
    }
}

/// The interpolated normal, or the geometric one where interpolation degenerates.
#[inline]
fn shading_normal(n: Vec3, ng: Vec3) -> Vec3 {
    let ns = n.normalize_or_zero();
    if ns == Vec3::ZERO || !ns.is_finite() {
        ng
    } else {
        ns
    }
}

/// The shading frame around `ns`: its tangent is the object's tangent if given, else dp/du.
#[inline]
fn shading_frame(ns: Vec3, tangent: Option<Vec3>, dpdu: Vec3) -> Frame {
    match tangent {
        Some(t) => Frame::from_normal_tangent(ns, t),
        None if dpdu != Vec3::ZERO => Frame::from_normal_tangent(ns, dpdu),
        None => Frame::from_normal(ns),
    }
}

/// A loaded scene. Cloning is cheap: the geometry is shared; materials are per clone, which is
/// how the fitter tries new parameters.
#[derive(Clone)]
pub struct Scene {
    pub path: PathBuf,
    pub camera: Camera,
    pub render: RenderSettings,
    pub groups: Vec<Group>,
    pub objects: Vec<Object>,
    /// Lights that are not surfaces (`[[light]]`): directional, point, spot.
    pub punctual_lights: Vec<PunctualLight>,
    /// The light arriving from infinitely far away (`[environment]`), if any.
    pub environment: Option<Arc<environment::Environment>>,
    /// Stray light (`[stray_light]`): the radiance every ray leaving the scene sees besides
    /// the environment, the same in all directions; zero unless given or fitted
    /// (`recover --stray-light`).
    pub stray_light: Rgb,
    pub geometry: Arc<Geometry>,
    /// Groups' options and everything else of the source, for writing the scene back out.
    pub source: schema::SceneFile,
    /// The photos' views (`view.rs`); empty for a scene of one photo.
    pub views: Vec<View>,
    /// The view this scene is seen as (`Scene::in_view`), if any.
    pub view: Option<usize>,
}

/// Everything the renderer needs to know about a ray's hit point.
#[derive(Clone, Copy, Debug)]
pub struct SurfaceHit {
    pub p: Vec3,
    pub t: f32,
    /// Geometric normal, as wound (front side), unit length.
    pub ng: Vec3,
    /// Shading frame; its normal is the interpolated normal.
    pub frame: Frame,
    pub uv: Vec2,
    pub object: u32,
    pub prim: u32,
}

impl Scene {
    pub fn group_index(&self, name: &str) -> Option<usize> {
        self.groups.iter().position(|g| g.name == name)
    }

    /// Whether the model says no light comes from outside it: no environment and no stray
    /// light, so a ray that leaves the scene brings nothing.
    pub fn outside_light_is_none(&self) -> bool {
        self.environment.is_none() && !(self.stray_light.max_element() > 0.0)
    }

    /// What the camera sees through the centres of an `nx`×`ny` grid over its film: each camera
    /// ray that hits something, with its grid index (row-major) and its hit (a cheap survey of
    /// the view, not a render).
    pub fn camera_grid_hits(&self, nx: u32, ny: u32) -> Vec<(u32, Ray, SurfaceHit)> {
        let cam = &self.camera;
        let mut hits = Vec::new();
        for j in 0..ny {
            for i in 0..nx {
                let film = crate::math::Vec2::new(
                    (i as f32 + 0.5) / nx as f32 * cam.width as f32,
                    (j as f32 + 0.5) / ny as f32 * cam.height as f32,
                );
                let ray = cam.ray(film);
                if let Some(h) = self.intersect(&ray, f32::INFINITY) {
                    hits.push((j * nx + i, ray, h));
                }
            }
        }
        hits
    }

    /// The closest surface along `ray` within `t_max`.
    pub fn intersect(&self, ray: &Ray, t_max: f32) -> Option<SurfaceHit> {
        let hit = self.geometry.bvh.intersect(ray, t_max)?;
        Some(self.surface_hit(ray, &hit))
    }

    pub fn occluded(&self, ray: &Ray, t_max: f32) -> bool {
        self.geometry.bvh.occluded(ray, t_max)
    }

    /// The closest hit along `ray` within `t_max` as the BVH reports it: distance, triangle and
    /// barycentrics, which `surface_hit` expands.
    #[inline]
    pub fn intersect_hit(&self, ray: &Ray, t_max: f32) -> Option<Hit> {
        self.geometry.bvh.intersect(ray, t_max)
    }

    /// [`Scene::intersect_hit`] into `hit` (`Bvh::intersect_into`).
    #[inline]
    pub fn intersect_hit_into(&self, ray: &Ray, t_max: f32, hit: &mut Option<Hit>) {
        self.geometry.bvh.intersect_into(ray, t_max, hit)
    }

    /// [`Scene::intersect_hit`] for up to eight rays at once (lanes in `active`; the others give
    /// `None`), traced as a packet (`geometry::packet`): the same hits to the bit, written into
    /// `hits` where the caller keeps them (`Bvh::intersect_into`).
    pub fn intersect8_into(
        &self,
        rays: [Ray; LANES],
        active: u32,
        hits: &mut [Option<Hit>; LANES],
    ) {
        let packet = Packet::new(rays, [f32::INFINITY; LANES], active);
        self.geometry.bvh.intersect8_into(&packet, hits)
    }

    /// The point of a hit, interpolated from the triangle's vertices (`SurfaceHit::p`).
    #[inline(always)]
    pub fn hit_point(&self, hit: &Hit) -> Vec3 {
        let g = &*self.geometry;
        let [i0, i1, i2] = g.tris[hit.prim as usize].v.map(|i| i as usize);
        let b0 = 1.0 - hit.b1 - hit.b2;
        g.positions[i0] * b0 + g.positions[i1] * hit.b1 + g.positions[i2] * hit.b2
    }

    /// Expands a BVH hit into positions, normals, UVs and the shading frame.
    #[inline]
    pub fn surface_hit(&self, _ray: &Ray, hit: &Hit) -> SurfaceHit {
        let g = &*self.geometry;
        let tri = g.tris[hit.prim as usize];
        let face = &g.faces[hit.prim as usize];
        let [i0, i1, i2] = tri.v.map(|i| i as usize);
        let b0 = 1.0 - hit.b1 - hit.b2;
        let p = self.hit_point(hit);
        let uv = g.uvs[i0] * b0 + g.uvs[i1] * hit.b1 + g.uvs[i2] * hit.b2;
        let frame = face.frame.unwrap_or_else(|| {
            let n = g.normals[i0] * b0 + g.normals[i1] * hit.b1 + g.normals[i2] * hit.b2;
            let tangent = self.objects[tri.object as usize].tangent;
            shading_frame(shading_normal(n, face.ng), tangent, face.dpdu)
        });
        SurfaceHit {
            p,
            t: hit.t,
            ng: face.ng,
            frame,
            uv,
            object: tri.object,
            prim: hit.prim,
        }
    }

    /// Whether anything emits light: an emitting object, a punctual light, an environment.
    pub fn has_lights(&self) -> bool {
        !self.punctual_lights.is_empty()
            || self.environment.is_some()
            || self.stray_light.max_element() > 0.0
            || self.objects.iter().any(Object::is_emitter)
    }

    /// The number of triangles.
    pub fn triangle_count(&self) -> usize {
        self.geometry.tris.len()
    }
}
