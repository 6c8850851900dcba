//! Paths kept to be weighed again under other materials, without tracing a ray.
//!
//! A path's radiance depends on the materials of the surfaces it meets only through the BSDF
//! values at its vertices. With what the path found kept (`integrator::Record`: the emission
//! and light samples with their MIS weights, the density each direction was drawn with, Russian
//! roulette's survival factors), its radiance under new materials is
//!
//!   L' = Σ_k β'_k (E_k + Σ_l f'_k(ωo, ωl) T_kl),   β'_{k+1} = β'_k f'_k(ωo, ωi) cos θi / p_k · r_k
//!
//! with E_k the emission found on arriving at vertex k, T_kl its light samples' radiance × cos ×
//! MIS weight / density, p_k the density its direction ωi was drawn with under the old
//! materials and r_k = 1 / (roulette's survival probability). This is importance sampling with
//! the old materials' densities (the weights of multiple importance sampling need only sum to
//! one over the techniques, which the old ones do), so L' is an unbiased estimate of the new
//! scene's radiance wherever the old densities cover the new BSDFs (Veach 1997, §9.2; the reuse
//! of paths across parameter changes is that of Bitterli et al. 2020, "Spatiotemporal reservoir
//! resampling", and of path re-weighting in inverse rendering, Nimier-David et al. 2020,
//! "Radiative backpropagation", §4). A vertex whose BSDF changed kind — gained or lost a smooth
//! part (light sampling was done or not), or a mirror lobe (a direction only a delta draws) —
//! cannot be weighed so: such a path is not replayed (`replay` gives None) and is traced again.
//! Nor is a path that ended on a black surface that is black no more, nor one through a surface
//! that now reads a texture where it did not (where it was hit is kept only for textures).
//!
//! Directions are kept in the vertex's shading frame as it was turned for the lobe's rotation θ
//! then; a new θ turns them about the normal by the difference (the other way where the frame
//! was turned over to face the viewer).

use super::batch::{trace_recorded_jobs, Job};
use super::bsdf::Bsdf;
use super::incident::IndirectRay;
use super::integrator::{lobe_rotation, material_bsdf, PathTracer, Record, Touched};
use crate::math::{Rgb, Vec2, Vec3};
use crate::scene::{Material, Scene, SurfaceHit};
use std::cell::Cell;
use std::collections::VecDeque;

/// One vertex of a kept path.
#[derive(Clone, Copy, Debug)]
struct KeptVertex {
    object: u32,
    /// Emission found on arriving here, MIS-weighted.
    found: Rgb,
    /// ωo in the shading frame as turned when traced (lobe rotation `theta`, `flipped`).
    wo: Vec3,
    theta: f32,
    flipped: bool,
    /// The BSDF's kind when traced: a smooth part (light samples drawn), a mirror lobe; or
    /// black (the path ended here).
    smooth: bool,
    mirror: bool,
    black: bool,
    /// Its light samples: `lights[first_light..first_light + n_lights]`.
    first_light: u32,
    n_lights: u32,
    /// Where its texture is read (`points`), or `u32::MAX` for a material without one.
    point: u32,
    /// The direction the path went on along, its density (a delta lobe's: the probability of
    /// choosing it), and roulette's factor; `pdf` 0: the path ended here.
    wi: Vec3,
    pdf: f32,
    delta: bool,
    rr: f32,
}

/// Where a textured vertex's texture is read (`Texture::at_point`).
#[derive(Clone, Copy, Debug)]
struct TexPoint {
    uv: Vec2,
    p: Vec3,
    ng: Vec3,
}

/// One kept path: its vertices, and what it found after the last of them.
#[derive(Clone, Copy, Debug)]
struct KeptPath {
    first: u32,
    count: u32,
    tail: Rgb,
}

/// Paths kept by [`record`], in order.
#[derive(Default, Debug)]
pub struct PathBank {
    paths: Vec<KeptPath>,
    vertices: Vec<KeptVertex>,
    lights: Vec<(Vec3, Rgb)>,
    points: Vec<TexPoint>,
}

impl PathBank {
    pub fn len(&self) -> usize {
        self.paths.len()
    }

    pub fn is_empty(&self) -> bool {
        self.paths.is_empty()
    }

    /// Bytes held, for a caller that budgets memory.
    pub fn bytes(&self) -> usize {
        self.paths.len() * std::mem::size_of::<KeptPath>()
            + self.vertices.len() * std::mem::size_of::<KeptVertex>()
            + self.lights.len() * std::mem::size_of::<(Vec3, Rgb)>()
            + self.points.len() * std::mem::size_of::<TexPoint>()
    }

    fn clear(&mut self) {
        self.paths.clear();
        self.vertices.clear();
        self.lights.clear();
        self.points.clear();
    }

    /// Appends the paths of `from`, as recording them here would have kept them.
    fn append(&mut self, from: &PathBank) {
        let first = self.vertices.len() as u32;
        let (light, point) = (self.lights.len() as u32, self.points.len() as u32);
        let paths = from.paths.iter().map(|p| KeptPath {
            first: p.first + first,
            ..*p
        });
        let vertices = from.vertices.iter().map(|v| KeptVertex {
            first_light: v.first_light + light,
            point: if v.point == u32::MAX {
                u32::MAX
            } else {
                v.point + point
            },
            ..*v
        });
        self.paths.extend(paths);
        self.vertices.extend(vertices);
        self.lights.extend_from_slice(&from.lights);
        self.points.extend_from_slice(&from.points);
    }
}

/// Whether a material's BSDF depends on where it is hit.
fn reads_texture(material: &Material) -> bool {
    matches!(
        material,
        Material::Textured { .. } | Material::TexturedPlastic { .. }
    )
}

/// Whether a BSDF has a mirror lobe a path can be drawn along.
fn has_mirror(bsdf: &Bsdf) -> bool {
    matches!(bsdf, Bsdf::DiffuseMirror { rho_s, .. } if rho_s.max_element() > 0.0)
}

/// The `Record` that appends one path at a time to a bank.
struct Recorder<'a> {
    bank: PathBank,
    scene: &'a Scene,
    /// Emission found since the last vertex.
    pending: Rgb,
}

impl<'a> Recorder<'a> {
    fn new(scene: &'a Scene) -> Recorder<'a> {
        Recorder {
            bank: PathBank::default(),
            scene,
            pending: Rgb::ZERO,
        }
    }

    fn start(&mut self) {
        let first = self.bank.vertices.len() as u32;
        self.bank.paths.push(KeptPath {
            first,
            count: 0,
            tail: Rgb::ZERO,
        });
        self.pending = Rgb::ZERO;
    }

    fn finish(&mut self) {
        let n = self.bank.vertices.len() as u32;
        let path = self.bank.paths.last_mut().expect("a started path");
        path.count = n - path.first;
        path.tail = self.pending;
    }

    fn push_vertex(&mut self, hit: &SurfaceHit, flipped: bool, wo: Vec3, bsdf: Option<&Bsdf>) {
        let material = &self.scene.objects[hit.object as usize].material;
        let theta = lobe_rotation(material);
        let point = if reads_texture(material) {
            self.bank.points.push(TexPoint {
                uv: hit.uv,
                p: hit.p,
                ng: hit.ng,
            });
            self.bank.points.len() as u32 - 1
        } else {
            u32::MAX
        };
        self.bank.vertices.push(KeptVertex {
            object: hit.object,
            found: std::mem::replace(&mut self.pending, Rgb::ZERO),
            wo,
            theta,
            flipped,
            smooth: bsdf.is_some_and(Bsdf::has_smooth_part),
            mirror: bsdf.is_some_and(has_mirror),
            black: bsdf.is_none(),
            first_light: self.bank.lights.len() as u32,
            n_lights: 0,
            point,
            wi: Vec3::Z,
            pdf: 0.0,
            delta: false,
            rr: 1.0,
        });
    }
}

impl Record for Recorder<'_> {
    const EVERY_LIGHT: bool = true;

    fn found(&mut self, le: Rgb) {
        self.pending += le;
    }

    fn vertex(&mut self, hit: &SurfaceHit, flipped: bool, wo: Vec3, bsdf: &Bsdf) {
        self.push_vertex(hit, flipped, wo, Some(bsdf));
    }

    fn black(&mut self, hit: &SurfaceHit) {
        self.push_vertex(hit, false, Vec3::Z, None);
    }

    fn light(&mut self, wi: Vec3, term: Rgb) {
        self.bank.lights.push((wi, term));
        if let Some(v) = self.bank.vertices.last_mut() {
            v.n_lights += 1;
        }
    }

    fn scattered(&mut self, wi: Vec3, pdf: f32, delta: bool, rr: f32) {
        if let Some(v) = self.bank.vertices.last_mut() {
            (v.wi, v.pdf, v.delta, v.rr) = (wi, pdf, delta, rr);
        }
    }
}

/// What `render::incident::indirect_radiance` gives for the same rays, to the bit (traced as
/// it traces them, eight at a time), with the paths kept to be weighed again (`Replay`), in
/// the order of the rays: the bank `record_scalar`, one path at a time, keeps. `pt` is
/// `PathTracer::new`'s, as the caches' are: light sampled through a mirror
/// (`with_mirror_lights`) depends on the mirror's material too, which a kept vertex does not
/// say.
pub fn record(pt: &PathTracer, rays: Vec<IndirectRay>) -> (Vec<(Rgb, Touched)>, PathBank) {
    debug_assert!(pt.mirrors.is_empty(), "paths kept with mirror lights");
    let n = rays.len();
    let mut radiance = vec![(Rgb::ZERO, Touched::default()); n];
    let mut rays = rays.into_iter();
    // Each lane keeps the path it traces in its recorder's bank, of that path alone (`InOrder`
    // leaves it empty when the path ends).
    let next = |lane: &mut Job<Recorder>| {
        rays.next()
            .map(|r| {
                r.start(lane);
                lane.rec.start();
            })
            .is_some()
    };
    let mut kept = SCRATCH.take().unwrap_or_default();
    kept.bank.paths.reserve(n);
    let recorders = std::array::from_fn(|_| Recorder {
        bank: kept.spare.pop().unwrap_or_default(),
        ..Recorder::new(pt.scene)
    });
    let lanes = trace_recorded_jobs(pt, recorders, next, |i, lane| {
        lane.rec.finish();
        radiance[i] = (lane.st.l, lane.st.touched);
        kept.ended(i, &mut lane.rec.bank);
    });
    debug_assert!(kept.waiting.is_empty());
    kept.spare.extend(lanes.map(|r| r.bank));
    let bank = kept.hand_over();
    SCRATCH.set(Some(kept));
    (radiance, bank)
}

thread_local! {
    /// `record`'s `InOrder`, emptied and kept for its next call on the thread: a cache records
    /// a few dozen paths a pixel, whose banks and queue would otherwise be allocated (and the
    /// result grown) anew for each.
    static SCRATCH: Cell<Option<InOrder>> = const { Cell::new(None) };
}

/// A bank filled in the order of the rays from paths that end in another: those that end
/// before an earlier ray's wait for it.
#[derive(Default)]
struct InOrder {
    bank: PathBank,
    /// `waiting[k]`: ray `bank.len() + k`'s path, once it has ended (the first is the one
    /// waited for, never there).
    waiting: VecDeque<Option<PathBank>>,
    /// Empty banks, for the next path to wait in (no allocation per path).
    spare: Vec<PathBank>,
}

impl InOrder {
    /// The bank, leaving this one empty: a copy of its size where it is small (allocated once,
    /// while this one's room serves the next call), else the bank itself (a copy would cost
    /// more than the room it leaves unused).
    fn hand_over(&mut self) -> PathBank {
        if self.bank.bytes() > 1 << 20 {
            return std::mem::take(&mut self.bank);
        }
        let b = &self.bank;
        let bank = PathBank {
            paths: b.paths.to_vec(),
            vertices: b.vertices.to_vec(),
            lights: b.lights.to_vec(),
            points: b.points.to_vec(),
        };
        self.bank.clear();
        bank
    }

    /// Ray `i`'s path has ended, the one path of `path`, which is left empty.
    fn ended(&mut self, i: usize, path: &mut PathBank) {
        let k = i - self.bank.len();
        if k > 0 {
            if self.waiting.len() <= k {
                self.waiting.resize_with(k + 1, || None);
            }
            let mut held = self.spare.pop().unwrap_or_default();
            std::mem::swap(path, &mut held);
            self.waiting[k] = Some(held);
            return;
        }
        self.bank.append(path);
        path.clear();
        self.waiting.pop_front();
        while let Some(mut held) = self.waiting.front_mut().and_then(Option::take) {
            self.waiting.pop_front();
            self.bank.append(&held);
            held.clear();
            self.spare.push(held);
        }
    }
}

/// [`record`] one path at a time, by the scalar route the eight lanes repeat: the reference
/// its bank is held to.
#[cfg(test)]
fn record_scalar(pt: &PathTracer, rays: Vec<IndirectRay>) -> (Vec<(Rgb, Touched)>, PathBank) {
    let mut rec = Recorder::new(pt.scene);
    let radiance = rays
        .into_iter()
        .map(|mut r| {
            rec.start();
            let st = pt.trace_recorded(r.ray, r.hit, &mut r.sampler, 1, false, &mut rec);
            rec.finish();
            (st.l, st.touched)
        })
        .collect();
    (radiance, rec.bank)
}

/// A kept path weighed again: its radiance, and its importance weight, the ratio of the density
/// with which the new materials would have drawn its directions to that of the old (the product
/// over its vertices; roulette left out): paths whose weights spread far from one another say
/// the old samples serve the new materials badly ([`effective_share`]).
#[derive(Clone, Copy, Debug)]
pub struct Replayed {
    pub radiance: Rgb,
    pub weight: f32,
}

/// The effective sample size of importance weights as a share of their number, (Σw)² / (n Σw²)
/// (Kong 1992; Owen 2013, "Monte Carlo theory, methods and examples", §9.3): 1 where every
/// weight is the same, 1/n where one weight carries them all. 1 for no weights.
pub fn effective_share(weights: impl IntoIterator<Item = f32>) -> f64 {
    let (mut n, mut s, mut s2) = (0usize, 0.0f64, 0.0f64);
    for w in weights {
        let w = w as f64;
        n += 1;
        s += w;
        s2 += w * w;
    }
    if n == 0 || s2 <= 0.0 {
        return if n == 0 { 1.0 } else { 0.0 };
    }
    s * s / (n as f64 * s2)
}

/// The materials kept paths are weighed under: a scene's, with each uniform material's BSDF
/// and lobe rotation worked out once.
pub struct Replay<'a> {
    scene: &'a Scene,
    /// Per object: its BSDF and θ, or None where a texture is read per point.
    uniform: Vec<Option<(Bsdf, f32)>>,
}

impl<'a> Replay<'a> {
    pub fn new(scene: &'a Scene) -> Replay<'a> {
        let variant = scene.render.ward_variant;
        let uniform = scene
            .objects
            .iter()
            .map(|o| {
                (!reads_texture(&o.material))
                    .then(|| material_bsdf(&o.material, |_| Rgb::ZERO, variant))
            })
            .collect();
        Replay { scene, uniform }
    }

    /// Path `i` of `bank`'s radiance under these materials, or None where one of its vertices'
    /// BSDFs changed kind (module comment).
    pub fn radiance(&self, bank: &PathBank, i: usize) -> Option<Rgb> {
        self.replay(bank, i).map(|r| r.radiance)
    }

    /// Path `i` of `bank` under these materials: its radiance and its importance weight
    /// ([`Replayed`]), or None where one of its vertices' BSDFs changed kind.
    pub fn replay(&self, bank: &PathBank, i: usize) -> Option<Replayed> {
        let path = &bank.paths[i];
        let (mut beta, mut l, mut weight) = (Rgb::ONE, Rgb::ZERO, 1.0f32);
        for v in &bank.vertices[path.first as usize..(path.first + path.count) as usize] {
            l += beta * v.found;
            let (bsdf, theta) = self.bsdf(bank, v)?;
            let black = matches!(bsdf, Bsdf::Black);
            if v.black || black {
                return (v.black && black).then_some(Replayed {
                    radiance: l,
                    weight,
                });
            }
            if bsdf.has_smooth_part() != v.smooth || has_mirror(&bsdf) != v.mirror {
                return None;
            }
            let turn = Turn::new(if v.flipped {
                v.theta - theta
            } else {
                theta - v.theta
            });
            let wo = turn.apply(v.wo);
            let lights = v.first_light as usize..(v.first_light + v.n_lights) as usize;
            for &(wi, term) in &bank.lights[lights] {
                l += beta * bsdf.eval(wo, turn.apply(wi)) * term;
            }
            if v.pdf <= 0.0 {
                return Some(Replayed { radiance: l, weight });
            }
            if v.delta {
                let Bsdf::DiffuseMirror { rho_d, rho_s } = bsdf else {
                    return None;
                };
                beta *= rho_s * (v.rr / v.pdf);
                weight *= (1.0 - Bsdf::diffuse_prob(rho_d, rho_s)) / v.pdf;
            } else {
                let wi = turn.apply(v.wi);
                beta *= bsdf.eval(wo, wi) * (wi.z * v.rr / v.pdf);
                weight *= bsdf.pdf(wo, wi) / v.pdf;
            }
        }
        Some(Replayed {
            radiance: l + beta * path.tail,
            weight,
        })
    }

    /// A kept vertex's BSDF under these materials, and its lobe's rotation.
    /// None where the material now reads a texture and the vertex, kept under a uniform one,
    /// did not keep where it was.
    fn bsdf(&self, bank: &PathBank, v: &KeptVertex) -> Option<(Bsdf, f32)> {
        if let Some(b) = self.uniform[v.object as usize] {
            return Some(b);
        }
        let material = &self.scene.objects[v.object as usize].material;
        let at = bank.points.get(v.point as usize)?;
        Some(material_bsdf(
            material,
            |t| t.at_point(v.object, at.uv, at.p, at.ng),
            self.scene.render.ward_variant,
        ))
    }
}

/// A turn by an angle about the shading normal, applied to a direction in the shading frame:
/// its coordinates in the frame turned by that angle (`Frame::rotated`).
#[derive(Clone, Copy)]
struct Turn {
    cos: f32,
    sin: f32,
}

impl Turn {
    fn new(angle: f32) -> Turn {
        let (sin, cos) = if angle == 0.0 {
            (0.0, 1.0)
        } else {
            angle.sin_cos()
        };
        Turn { cos, sin }
    }

    #[inline]
    fn apply(&self, v: Vec3) -> Vec3 {
        if self.sin == 0.0 {
            return v;
        }
        Vec3::new(
            self.cos * v.x + self.sin * v.y,
            -self.sin * v.x + self.cos * v.y,
            v.z,
        )
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::math::Frame;
    use crate::render::incident::indirect_radiance;
    use crate::render::integrator::facing;
    use crate::scene::load::parse_scene;

    /// A floor, a back wall and an anisotropic Ward side wall, open above and in front, lit by
    /// the sun, an area light and a stray light; `{..}` are the materials that move. (Also the
    /// room of `fit::cache::build`'s kept-cache tests, whose floor the camera sees.)
    const ROOM: &str = r#"
[render]
spp = 1
seed = 1
[camera]
width = 40
height = 30
eye = [0.0, 1.2, 2.5]
target = [0.0, 0.3, -1.0]
up = [0.0, 1.0, 0.0]
fov_y_deg = 60.0
[[object]]
name = "floor"
group = "floor"
shape = "quad"
corner = [-2.0, 0.0, 1.0]
edge_u = [4.0, 0.0, 0.0]
edge_v = [0.0, 0.0, -3.0]
material = { type = "diffuse", rho_d = {floor} }
[[object]]
name = "wall"
group = "wall"
shape = "quad"
corner = [-2.0, 0.0, -2.0]
edge_u = [4.0, 0.0, 0.0]
edge_v = [0.0, 2.0, 0.0]
material = {wall}
[[object]]
name = "side"
group = "side"
shape = "quad"
corner = [-2.0, 0.0, 1.0]
edge_u = [0.0, 0.0, -3.0]
edge_v = [0.0, 2.0, 0.0]
tangent = [0.0, 1.0, 0.0]
material = {side}
[[object]]
name = "lamp"
group = "lamp"
shape = "quad"
corner = [1.9, 0.5, -1.5]
edge_u = [0.0, 0.0, 1.0]
edge_v = [0.0, 1.0, 0.0]
emission = 5.0
[[light]]
name = "sun"
type = "directional"
direction = [0.3, -1.0, -0.4]
irradiance = 2.0
[stray_light]
radiance = [0.3, 0.3, 0.3]
"#;

    pub(crate) const WALL: &str = r#"{ type = "diffuse", rho_d = [0.6, 0.5, 0.4] }"#;
    pub(crate) const SIDE: &str = r#"{ type = "ward", rho_d = 0.3, rho_s = 0.4, alpha_x = 0.1, alpha_y = 0.3, theta_deg = 0.0 }"#;

    pub(crate) fn room(floor: f32, wall: &str, side: &str) -> Scene {
        let text = ROOM
            .replace("{floor}", &floor.to_string())
            .replace("{wall}", wall)
            .replace("{side}", side);
        parse_scene(&text, std::path::Path::new("room.toml")).unwrap()
    }

    use crate::render::incident::tests::rays;

    fn close(a: Rgb, b: Rgb, rel: f32) -> bool {
        (0..3).all(|c| (a[c] - b[c]).abs() <= rel * a[c].abs().max(b[c].abs()) + 1e-7)
    }

    #[test]
    fn recording_a_path_changes_nothing_of_it() {
        let scene = room(0.5, WALL, SIDE);
        let pt = PathTracer::new(&scene);
        let traced = indirect_radiance(&pt, rays(&scene, 3000, 5));
        let (recorded, bank) = record(&pt, rays(&scene, 3000, 5));
        assert_eq!(bank.len(), 3000);
        for ((l, t), (m, u)) in traced.iter().zip(&recorded) {
            assert_eq!(l.to_array().map(f32::to_bits), m.to_array().map(f32::to_bits));
            assert_eq!(t, u);
        }
    }

    /// Recorded on the eight lanes, a bank is the scalar route's field for field (to the bit:
    /// `{:?}` tells every f32 apart but NaNs), and so are the paths' radiance and `Touched`.
    pub(crate) fn same_as_scalar(scene: &Scene, rays: Vec<IndirectRay>) -> PathBank {
        let pt = PathTracer::new(scene);
        let (got, bank) = record(&pt, rays.clone());
        let (want, scalar) = record_scalar(&pt, rays);
        assert_eq!(got.len(), want.len());
        for (i, ((l, t), (m, u))) in got.iter().zip(&want).enumerate() {
            let bits = |c: &Rgb| c.to_array().map(f32::to_bits);
            assert_eq!((bits(l), t), (bits(m), u), "path {i}");
        }
        fn same<T: std::fmt::Debug>(what: &str, a: &[T], b: &[T]) {
            assert_eq!(a.len(), b.len(), "{what}");
            for (i, (x, y)) in a.iter().zip(b).enumerate() {
                assert_eq!(format!("{x:?}"), format!("{y:?}"), "{what} {i}");
            }
        }
        same("path", &bank.paths, &scalar.paths);
        same("vertex", &bank.vertices, &scalar.vertices);
        same("light", &bank.lights, &scalar.lights);
        same("point", &bank.points, &scalar.points);
        bank
    }

    /// The room with a Ward side wall and a back wall diffuse, an ideal mirror, a Ward lobe or
    /// a varnished texture (the lanes' Lambert, Ward and mirror vertices, and the general
    /// route's); and under a sun of some width, a disc light, which keeps every vertex on the
    /// scalar route.
    #[test]
    fn recorded_on_eight_lanes_a_bank_is_the_scalar_one() {
        let d = tempfile::tempdir().unwrap();
        let mut t = crate::io::image::Image::new(4, 4);
        for (i, px) in t.data.iter_mut().enumerate() {
            *px = Rgb::new(0.1 + 0.05 * i as f32, 0.4, 0.3);
        }
        t.write(&d.path().join("t.pfm")).unwrap();
        for (k, wall) in [
            WALL,
            r#"{ type = "mirror", rho_s = 0.9 }"#,
            NEW_WALL,
            r#"{ type = "textured", texture = "t.pfm", rho_s = 0.2, alpha_x = 0.2, alpha_y = 0.2, theta_deg = 30 }"#,
            WALL,
        ]
        .into_iter()
        .enumerate()
        {
            let sun = if k == 4 { "angle_deg = 5.0\n" } else { "" };
            let text = ROOM
                .replace("irradiance = 2.0\n", &format!("irradiance = 2.0\n{sun}"))
                .replace("{floor}", "0.5")
                .replace("{wall}", wall)
                .replace("{side}", NEW_SIDE);
            let scene = parse_scene(&text, &d.path().join("room.toml")).unwrap();
            assert_eq!(PathTracer::new(&scene).lights.eight_lane(), k != 4);
            let bank = same_as_scalar(&scene, rays(&scene, 3000, 5));
            let (lit, delta) = (bank.lights.len(), bank.vertices.iter().filter(|v| v.delta));
            assert!(lit > 1000 && bank.vertices.len() > 2000, "wall {k}");
            assert_eq!(delta.count() > 100, k == 1, "wall {k}");
            assert_eq!(bank.points.len() > 500, k == 3, "wall {k}");
        }
    }

    #[test]
    fn weighed_again_under_the_same_materials_a_path_gives_its_radiance() {
        let scene = room(0.5, WALL, SIDE);
        let (recorded, bank) = record(&PathTracer::new(&scene), rays(&scene, 3000, 5));
        let replay = Replay::new(&scene);
        let mut lit = 0;
        for (i, (l, _)) in recorded.iter().enumerate() {
            let again = replay.replay(&bank, i).expect("nothing changed kind");
            let (w, again) = (again.weight, again.radiance);
            assert!(close(*l, again, 2e-5), "path {i}: {l:?} traced, {again:?} again");
            assert!((w - 1.0).abs() < 1e-3, "path {i}: weight {w}");
            lit += usize::from(l.max_element() > 0.0);
        }
        assert!(lit > 1000, "{lit} paths brought light");
    }

    const NEW_WALL: &str = r#"{ type = "ward", rho_d = [0.3, 0.35, 0.2], rho_s = 0.2, alpha_x = 0.3, alpha_y = 0.3, theta_deg = 0.0 }"#;
    pub(crate) const NEW_SIDE: &str = r#"{ type = "ward", rho_d = 0.1, rho_s = 0.6, alpha_x = 0.25, alpha_y = 0.12, theta_deg = 40.0 }"#;

    /// Every material but the lights moves (a diffuse ρ; a Ward lobe's reflectances, widths
    /// and rotation; a diffuse wall turned glossy): the replayed paths' mean agrees with that
    /// of paths traced afresh in the new scene, within their standard errors.
    #[test]
    fn weighed_again_under_new_materials_paths_agree_with_tracing_them() {
        agree(room(0.5, WALL, SIDE), room(0.7, NEW_WALL, NEW_SIDE));
    }

    /// A mirror's reflectance moves: the paths it reflected are weighed by the new one.
    #[test]
    fn a_mirror_weighed_again_agrees_with_tracing_it() {
        let mirror = |rho: f32| format!(r#"{{ type = "mirror", rho_s = {rho} }}"#);
        agree(room(0.5, &mirror(0.9), SIDE), room(0.5, &mirror(0.4), SIDE));
    }

    /// The mean radiance per channel of `n` paths replayed from `old` into `new` agrees with
    /// that of `n` paths traced in `new`, within 4 standard errors; and the two scenes differ
    /// by more than 10 in some channel (so that a replay that ignored the change would fail).
    fn agree(old: Scene, new: Scene) {
        let n = 40_000;
        let (_, bank) = record(&PathTracer::new(&old), rays(&old, n, 5));
        let replay = Replay::new(&new);
        let replayed: Vec<Rgb> = (0..bank.len())
            .map(|i| replay.radiance(&bank, i).expect("no kind changed"))
            .collect();
        let traced = |scene: &Scene| -> Vec<Rgb> {
            indirect_radiance(&PathTracer::new(scene), rays(scene, n, 9))
                .into_iter()
                .map(|(l, _)| l)
                .collect()
        };
        let (fresh, before) = (traced(&new), traced(&old));
        let stats = |x: &[Rgb], c: usize| {
            let m = x.iter().map(|v| v[c] as f64).sum::<f64>() / x.len() as f64;
            let var = x.iter().map(|v| (v[c] as f64 - m).powi(2)).sum::<f64>()
                / (x.len() - 1) as f64;
            (m, var / x.len() as f64)
        };
        let mut moved = 0.0f64;
        for c in 0..3 {
            let ((a, va), (b, vb), (o, vo)) =
                (stats(&replayed, c), stats(&fresh, c), stats(&before, c));
            let z = (a - b) / (va + vb).sqrt();
            assert!(z.abs() < 4.0, "channel {c}: replayed {a}, fresh {b}, z {z}");
            // Weighed by old densities, not much noisier than paths drawn for the new ones.
            assert!(va < 2.0 * vb, "channel {c}: variance {va} replayed, {vb} fresh");
            moved = moved.max(((o - b) / (vo + vb).sqrt()).abs());
        }
        assert!(moved > 10.0, "the scenes differ by {moved} standard errors");
    }

    /// A uniform wall turned textured: the paths that met it did not keep where (only a
    /// texture reads that), so they are refused, the others replayed.
    #[test]
    fn a_surface_turned_textured_refuses_the_paths_that_met_it() {
        let d = tempfile::tempdir().unwrap();
        let mut t = crate::io::image::Image::new(2, 2);
        t.data.fill(Rgb::new(0.5, 0.4, 0.3));
        t.write(&d.path().join("t.pfm")).unwrap();
        let text = ROOM
            .replace("{floor}", "0.5")
            .replace("{wall}", r#"{ type = "textured", texture = "t.pfm" }"#)
            .replace("{side}", SIDE);
        let textured = parse_scene(&text, &d.path().join("room.toml")).unwrap();
        let old = room(0.5, WALL, SIDE);
        let (traced, bank) = record(&PathTracer::new(&old), rays(&old, 3000, 5));
        let wall = old.group_index("wall").unwrap();
        let replay = Replay::new(&textured);
        for (i, (_, touched)) in traced.iter().enumerate() {
            let met = bank.vertices[bank.paths[i].first as usize..]
                .iter()
                .take(bank.paths[i].count as usize)
                .any(|v| old.objects[v.object as usize].group == wall);
            assert_eq!(replay.radiance(&bank, i).is_none(), met, "path {i}");
            assert!(touched.group(wall) || !met);
        }
    }

    /// A small move keeps the kept paths' weights close together, a large one (a diffuse wall
    /// turned glossy, a lobe turned) spreads them some; a wall turned a narrow glossy lobe
    /// (directions the old diffuse wall drew rarely) spreads them far.
    #[test]
    fn the_effective_share_falls_where_old_paths_serve_new_materials_badly() {
        let old = room(0.5, WALL, SIDE);
        let (_, bank) = record(&PathTracer::new(&old), rays(&old, 20_000, 5));
        let share = |new: &Scene| {
            let replay = Replay::new(new);
            effective_share((0..bank.len()).filter_map(|i| replay.replay(&bank, i).map(|r| r.weight)))
        };
        let near = share(&room(
            0.52,
            r#"{ type = "diffuse", rho_d = [0.58, 0.5, 0.42] }"#,
            r#"{ type = "ward", rho_d = 0.3, rho_s = 0.42, alpha_x = 0.11, alpha_y = 0.31, theta_deg = 3.0 }"#,
        ));
        let far = share(&room(
            0.5,
            r#"{ type = "ward", rho_d = 0.01, rho_s = 0.8, alpha_x = 0.03, alpha_y = 0.03, theta_deg = 0.0 }"#,
            SIDE,
        ));
        // The move of `weighed_again_under_new_materials_…`, whose replayed variance is
        // within twice a fresh one's.
        let moved = share(&room(0.7, NEW_WALL, NEW_SIDE));
        assert!(near > 0.95, "a small move: {near}");
        assert!(moved > 0.2, "a large move: {moved}");
        assert!(far < 0.05, "a narrow lobe: {far}");
        assert_eq!(effective_share([2.0f32; 5]), 1.0);
        assert!((effective_share([1.0, 0.0, 0.0, 0.0]) - 0.25).abs() < 1e-12);
    }

    /// A textured wall whose texels move (a checker whose squares trade places and darken,
    /// then under a varnish): each kept vertex reads the new texture where it was.
    #[test]
    fn a_texture_weighed_again_agrees_with_tracing_it() {
        let d = tempfile::tempdir().unwrap();
        let checker = |a: Rgb, b: Rgb, name: &str| {
            let mut t = crate::io::image::Image::new(4, 4);
            for (i, px) in t.data.iter_mut().enumerate() {
                *px = if (i % 4 + i / 4) % 2 == 0 { a } else { b };
            }
            t.write(&d.path().join(name)).unwrap();
        };
        checker(Rgb::new(0.8, 0.7, 0.6), Rgb::new(0.1, 0.2, 0.1), "old.pfm");
        checker(Rgb::new(0.05, 0.1, 0.2), Rgb::new(0.5, 0.6, 0.7), "new.pfm");
        let scene = |wall: &str| {
            let text = ROOM
                .replace("{floor}", "0.5")
                .replace("{wall}", wall)
                .replace("{side}", SIDE);
            parse_scene(&text, &d.path().join("room.toml")).unwrap()
        };
        let old = scene(r#"{ type = "textured", texture = "old.pfm" }"#);
        agree(old, scene(r#"{ type = "textured", texture = "new.pfm" }"#));
        let old = scene(r#"{ type = "textured", texture = "old.pfm" }"#);
        agree(
            old,
            scene(
                r#"{ type = "textured", texture = "new.pfm", rho_s = 0.2, alpha_x = 0.2, alpha_y = 0.2, theta_deg = 0 }"#,
            ),
        );
    }

    #[test]
    fn a_path_through_a_surface_that_changed_kind_is_not_weighed_again() {
        let old = room(0.5, WALL, SIDE);
        let new = room(0.5, r#"{ type = "mirror", rho_s = 0.9 }"#, SIDE);
        let (traced, bank) = record(&PathTracer::new(&old), rays(&old, 3000, 5));
        let wall = old.group_index("wall").unwrap();
        let replay = Replay::new(&new);
        let mut refused = 0;
        for (i, (_, touched)) in traced.iter().enumerate() {
            let again = replay.radiance(&bank, i);
            if !touched.group(wall) {
                assert!(again.is_some(), "path {i} never met the wall");
            } else if again.is_none() {
                refused += 1;
            }
        }
        assert!(refused > 300, "{refused} paths refused");
    }

    /// A direction's coordinates in a frame turned for a lobe at θ and faced to the viewer,
    /// turned by `Turn`, are its coordinates in the frame turned for another θ: on both sides.
    #[test]
    fn a_turn_takes_coordinates_from_one_lobe_rotation_to_another() {
        let frame = Frame::from_normal(Vec3::new(0.2, 0.9, -0.3).normalize());
        let v = Vec3::new(-0.4, 0.5, 0.7).normalize();
        for (ng, wo) in [
            (frame.n, frame.n),
            (frame.n, -frame.n),
            (-frame.n, frame.n),
        ] {
            for (a, b) in [(0.0f32, 0.7f32), (0.3, -1.1), (2.0, 0.0)] {
                let (fa, _) = facing(frame.rotated(a), ng, wo);
                let (fb, _) = facing(frame.rotated(b), ng, wo);
                let flipped = fa.n.dot(frame.n) < 0.0;
                let turn = Turn::new(if flipped { a - b } else { b - a });
                let (got, want) = (turn.apply(fa.to_local(v)), fb.to_local(v));
                assert!((got - want).length() < 1e-5, "{got:?} against {want:?}");
            }
        }
    }
}

/// What weighing kept paths again costs against tracing them, on the bundled figure6 room:
/// `cargo test --profile ci -p matfit --features internals --lib replay_costs -- --ignored
/// --nocapture` (one thread; it prints, and asserts only that the replay agrees with fresh
/// paths).
#[cfg(test)]
pub(crate) mod cost {
    use super::*;
    use crate::geometry::{offset_origin, Ray};
    use crate::math::{warp, Frame, Sampler, Vec2};
    use crate::render::incident::indirect_radiance;
    use crate::render::integrator::facing;
    use crate::scene::Material;
    use std::time::Instant;

    /// Indirect rays as a cache draws them: from the surface each pixel of a lattice sees,
    /// cosine-distributed about its normal, `per` of them a pixel.
    fn rays(scene: &Scene, per: u32, seed: u64) -> Vec<IndirectRay> {
        let cam = &scene.camera;
        let mut out = Vec::new();
        for y in (0..cam.height as usize).step_by(4) {
            for x in (0..cam.width as usize).step_by(4) {
                let ray = cam.ray(Vec2::new(x as f32 + 0.5, y as f32 + 0.5));
                let Some(hit) = scene.intersect_hit(&ray, f32::INFINITY) else {
                    continue;
                };
                let sh = scene.surface_hit(&ray, &hit);
                let (frame, ng) = facing(Frame::from_normal(sh.ng), sh.ng, -ray.d);
                for k in 0..per {
                    let mut sampler = Sampler::new(seed, (y * 4096 + x) as u64);
                    sampler.start_sample(k);
                    let d = frame.to_world(warp::cosine_hemisphere(sampler.next_2d()));
                    let r = Ray::new(offset_origin(sh.p, ng, d), d);
                    out.push(IndirectRay {
                        hit: scene.intersect_hit(&r, f32::INFINITY),
                        ray: r,
                        sampler,
                    });
                }
            }
        }
        out
    }

    /// Every reflectance down by a tenth and every lobe 20% wider: about what moves between
    /// two of a recovery's early iterations.
    pub(crate) fn moved(scene: &Scene) -> Scene {
        let mut s = scene.clone();
        for o in &mut s.objects {
            match &mut o.material {
                Material::Diffuse { rho_d } => *rho_d *= 0.9,
                Material::Ward {
                    rho_d,
                    rho_s,
                    alpha_x,
                    alpha_y,
                    ..
                } => {
                    *rho_d *= 0.9;
                    *rho_s *= 0.9;
                    *alpha_x *= 1.2;
                    *alpha_y *= 1.2;
                }
                _ => {}
            }
        }
        s
    }

    #[test]
    fn recorded_on_eight_lanes_a_bank_is_the_scalar_one_on_figure6() {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/figure6/scene.toml");
        let scene = crate::scene::load::load_scene(&path).unwrap();
        let bank = super::tests::same_as_scalar(&scene, rays(&scene, 2, 3));
        assert!(bank.vertices.len() > 2 * bank.len() && bank.lights.len() > bank.len());
    }

    fn mean_var(x: &[Rgb]) -> (f64, f64) {
        let l: Vec<f64> = x.iter().map(|v| (v.x + v.y + v.z) as f64 / 3.0).collect();
        let m = l.iter().sum::<f64>() / l.len() as f64;
        let v = l.iter().map(|a| (a - m).powi(2)).sum::<f64>() / (l.len() - 1) as f64;
        (m, v)
    }

    #[test]
    #[ignore]
    fn replay_costs_on_figure6() {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/figure6/scene.toml");
        let scene = crate::scene::load::load_scene(&path).unwrap();
        let pt = PathTracer::new(&scene);
        let rs = rays(&scene, 32, 3);
        let n = rs.len();
        let t = Instant::now();
        let lanes = indirect_radiance(&pt, rs.clone());
        let t_lanes = t.elapsed().as_secs_f64();
        let t = Instant::now();
        let (recorded, bank) = record(&pt, rs.clone());
        let t_record = t.elapsed().as_secs_f64();
        assert_eq!(lanes.len(), recorded.len());
        let new = moved(&scene);
        let t = Instant::now();
        let replay = Replay::new(&new);
        let kept: Vec<Replayed> = (0..n).filter_map(|i| replay.replay(&bank, i)).collect();
        let t_replay = t.elapsed().as_secs_f64();
        let replayed: Vec<Rgb> = kept.iter().map(|r| r.radiance).collect();
        let share = effective_share(kept.iter().map(|r| r.weight));
        let fresh: Vec<Rgb> = indirect_radiance(&PathTracer::new(&new), rays(&new, 32, 4))
            .into_iter()
            .map(|(l, _)| l)
            .collect();
        let ((a, va), (b, vb)) = (mean_var(&replayed), mean_var(&fresh));
        println!(
            "{n} paths, {:.1} vertices each, {:.0} bytes a path kept",
            bank.vertices.len() as f64 / n as f64,
            bank.bytes() as f64 / n as f64
        );
        println!(
            "traced (eight lanes) {t_lanes:.3} s, traced and kept (eight lanes) {t_record:.3} s \
             ({:.2}x), weighed again {t_replay:.3} s ({:.1}x faster than tracing)",
            t_record / t_lanes,
            t_lanes / t_replay
        );
        println!(
            "moved materials: replayed mean {a:.5} (variance {va:.3e}), fresh {b:.5} ({vb:.3e}); \
             {} of {n} not replayed; effective share {share:.3}",
            n - replayed.len()
        );
        let z = (a - b) / (va / n as f64 + vb / fresh.len() as f64).sqrt();
        assert!(z.abs() < 4.0, "replayed {a}, fresh {b}: z {z}");
    }
}

