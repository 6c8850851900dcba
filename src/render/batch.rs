//! The path tracer of `integrator.rs`, eight paths at a time: the shading arithmetic of the
//! path loop — next-event estimation and BSDF sampling at Lambert and Ward surfaces, and the
//! reflection at ideal mirrors — runs on eight lanes of one SIMD register (AVX), as a
//! wavefront renderer does (Laine, Karras & Aila 2013, "Megakernels considered harmful:
//! wavefront path tracing on GPUs"; Mitsuba 3's `llvm` variants vectorise their whole path
//! loop the same way). Ray traversal stays one ray at a time, but for camera rays:
//! `render_pixels` traces them ahead, eight samples of a pixel as one packet
//! (`geometry::packet`), which walk the same nodes. Rays of different paths rarely share
//! nodes, so their packets are slower (bench/README.md, "Design measurements").
//!
//! Next-event estimation samples the area lights on the eight lanes and evaluates every punctual
//! light (directional, point, spot) on them too, each light's sample and shadow ray lane by
//! lane; a scene with an environment or a disc light keeps the scalar route, whose samples for
//! them draw sampler dimensions the lanes do not.
//!
//! Each lane runs the scalar integrator's state machine (`PathTracer::arrive`, `vertex`, then
//! `scatter` or its eight-lane copy here for Lambert, Ward and mirror surfaces) and draws its
//! random numbers from its own pixel's sampler in the same order, and the eight-lane
//! arithmetic repeats the scalar one operation for operation (Rust never fuses a·b + c; the
//! Ward lobe's exp, ln and sin/cos are polynomials written for f32 and f32x8 alike:
//! `bsdf::Lobes8`). So every sample — and every pixel,
//! whose samples are summed in sample order — is the scalar integrator's to the bit; a test
//! holds the two to that. A flat-shaded Lambert or Ward triangle goes from the BVH's hit
//! straight into the eight-lane arrays (`flat_lambert`, `flat_ward`), without the hit record
//! and `Vertex` of the general route, which saves instructions.
//!
//! Recording (`trace_recorded_jobs`, for `render::replay`) gives each lane a recorder, told
//! what `PathTracer::trace_recorded` tells it at the same points with the same values; its
//! vertices take the general route, whose hit record it is told of.
//!
//! Lanes that finish a path take the next job at once, so the eight lanes stay busy until the
//! jobs run out. Callers: `render_pixels` (a film's pixels, job = one (pixel, sample)), and
//! the recovery's cache builds (`render::incident`, job = an indirect sample's path), which
//! `render::replay::record` traces too, keeping the paths.
//!
//! Branches: lanes at different depths, paths that end at random and rays in random
//! directions make per-lane tests unpredictable, and a mispredicted branch costs about as much
//! as a slab test. So lanes are walked by bitmask (free lanes, lanes whose hit is unknown,
//! ended paths) rather than tested one by one, a lane's state is written back whether or not
//! its path goes on, and its seven random numbers come with one branch (`Sampler::next_n`).
//! All the lanes' rays are traced before any of them arrives (lane by lane is slower).

use super::bsdf::{mirror, Bsdf, Lobes8, WardLobe};
use super::integrator::{facing, PathState, PathTracer, Record, Vertex};
use super::lights::{punctual_sample, LightSample, Lights};
use crate::geometry::packet::LANES;
use crate::geometry::{Hit, Ray};
use crate::math::{transpose, warp, Frame, Rgb, Sampler, Vec2, Vec3, INV_PI, PI};
use crate::scene::{Camera, Material, Object, Punctual};
use wide::{f32x8, CmpEq, CmpGe, CmpGt, CmpLe, CmpLt};

/// A path to trace: its state before its next segment (`st.ray`), that segment's hit if the
/// caller has already intersected it, and the sampler it draws from. A lane of `trace_jobs`
/// is a `Job` filled in place, so a path's state is never moved while it is traced; its
/// recorder `rec` stays with the lane from job to job.
pub struct Job<R = ()> {
    pub st: PathState,
    /// Where `st.ray` lands (`Scene::intersect_hit`), when `traced`.
    pub hit: Option<Hit>,
    /// Whether `hit` is already known (else `trace_jobs` intersects `st.ray`).
    pub traced: bool,
    pub sampler: Sampler,
    pub rec: R,
}

impl<R> Job<R> {
    /// A lane's contents before its first job.
    fn idle(rec: R) -> Job<R> {
        Job {
            st: PathState::new(Ray::new(Vec3::ZERO, Vec3::Z), 0, true),
            hit: None,
            traced: false,
            sampler: Sampler::new(0, 0),
            rec,
        }
    }
}

/// Traces the paths that `next` writes into a free lane (returning false when there are no
/// more), numbered from 0, eight at a time; `done(i, st)` gets job i's path at its end, whose
/// radiance `st.l` is `PathTracer::trace_from`'s for the same job to the bit.
pub fn trace_jobs(
    pt: &PathTracer,
    next: impl FnMut(&mut Job) -> bool,
    mut done: impl FnMut(usize, &PathState),
) {
    trace_recorded_jobs(pt, [(); LANES], next, |i, lane| done(i, &lane.st));
}

/// [`trace_jobs`], each lane telling its recorder (`Job::rec`, from `recorders`) what its path
/// meets, as `PathTracer::trace_recorded` tells it; `done(i, lane)` gets the lane whose job i
/// has ended, its recorder with it. Gives the recorders back. (A recorder that keeps anything
/// has its vertices go by the general route, which builds the hit record it is told of.)
pub(super) fn trace_recorded_jobs<R: Record>(
    pt: &PathTracer,
    recorders: [R; LANES],
    mut next: impl FnMut(&mut Job<R>) -> bool,
    mut done: impl FnMut(usize, &mut Job<R>),
) -> [R; LANES] {
    let mut lanes: [Job<R>; LANES] = recorders.map(Job::idle);
    // Which job each lane holds; bit i of `live`: lane i holds one.
    let mut item = [0usize; LANES];
    let mut live = 0u32;
    // Bit i: lane i's next hit is already known (`Job::traced`). Lanes are walked by their
    // bits: a test per lane of which kind it is mispredicted often.
    let mut known = 0u32;
    let mut count = 0usize;
    let mut exhausted = false;
    // Lanes past `gathered.n` hold stale values; every use of them is masked.
    let mut gathered = SmoothLanes::default();
    loop {
        let mut free = !live & ((1 << LANES) - 1);
        while free != 0 && !exhausted {
            let i = free.trailing_zeros() as usize;
            free &= free - 1;
            if !next(&mut lanes[i]) {
                exhausted = true;
                break;
            }
            item[i] = count;
            live |= 1 << i;
            known |= u32::from(lanes[i].traced) << i;
            count += 1;
        }
        if live == 0 {
            break;
        }
        // Each lane's ray is traced and arrives; Lambert and Ward vertices gather into
        // `gathered`, the rest scatter alone.
        let mut mask = live & !known;
        while mask != 0 {
            let lane = &mut lanes[mask.trailing_zeros() as usize];
            mask &= mask - 1;
            pt.scene
                .intersect_hit_into(&lane.st.ray, f32::INFINITY, &mut lane.hit);
        }
        known = 0;
        gathered.n = 0;
        gathered.ward = 0;
        gathered.mirror = 0;
        // Every lane arrives; then the lanes on anything but Ward, then those on Ward, so that
        // each pass's branch on the material mostly goes one way (one pass mixing them
        // mispredicted it lane by lane).
        let mut objs: [Option<(&Object, Hit)>; LANES] = [None; LANES];
        let mut ward = 0u32;
        let mut mask = live;
        while mask != 0 {
            let i = mask.trailing_zeros() as usize;
            mask &= mask - 1;
            let lane = &mut lanes[i];
            match (pt.arrive(&mut lane.st, lane.hit.as_ref(), &mut lane.rec), lane.hit) {
                (Some(obj), Some(hit)) => {
                    objs[i] = Some((obj, hit));
                    ward |= u32::from(matches!(obj.material, Material::Ward { .. })) << i;
                }
                _ => {
                    live &= !(1 << i);
                    done(item[i], lane);
                }
            }
        }
        for pass in [live & !ward, live & ward] {
            let mut mask = pass;
            while mask != 0 {
                let i = mask.trailing_zeros() as usize;
                mask &= mask - 1;
                let lane = &mut lanes[i];
                let Some((obj, ref hit)) = objs[i] else {
                    continue;
                };
                let d = lane.st.ray.d;
                let alive = if let Some((ng, frame, rho_d)) = flat_lambert::<R>(pt, obj, hit, d) {
                        let p = pt.scene.hit_point(hit);
                        if !pt.mirrors.is_empty() {
                            let wo = frame.to_local(-lane.st.ray.d);
                            let bsdf = Bsdf::Diffuse { rho_d };
                            lane_mirror_lights(pt, lane, p, ng, &frame, bsdf, wo);
                        }
                        gathered.push(i, pt, p, ng, &frame, rho_d, lane);
                        true
                    } else if let Some(w) = flat_ward::<R>(pt, obj, hit, d) {
                        let (p, j) = (pt.scene.hit_point(hit), gathered.n);
                        if !pt.mirrors.is_empty() {
                            let bsdf = Bsdf::Ward {
                                rho_d: w.rho_d,
                                rho_s: w.rho_s,
                                lobe: w.lobe,
                            };
                            lane_mirror_lights(pt, lane, p, w.ng, &w.frame, bsdf, w.wo);
                        }
                        gathered.push(i, pt, p, w.ng, &w.frame, w.rho_d, lane);
                        gathered.push_ward(j, w.wo, w.rho_s, w.lobe);
                        true
                    } else {
                        match pt.vertex(&lane.st, hit, obj, &mut lane.rec) {
                            None => false,
                            Some(v) => match v.bsdf {
                                Bsdf::Diffuse { rho_d } if gathers(pt, rho_d, v.wo.z) => {
                                    if !pt.mirrors.is_empty() {
                                        let (p, ng, f, b) = (v.p, v.ng, &v.frame, v.bsdf);
                                        lane_mirror_lights(pt, lane, p, ng, f, b, v.wo);
                                    }
                                    gathered.push(i, pt, v.p, v.ng, &v.frame, rho_d, lane);
                                    true
                                }
                                Bsdf::Ward { rho_d, rho_s, lobe } if gathers_ward(pt, v.wo.z) => {
                                    if !pt.mirrors.is_empty() {
                                        let (p, ng, f, b) = (v.p, v.ng, &v.frame, v.bsdf);
                                        lane_mirror_lights(pt, lane, p, ng, f, b, v.wo);
                                    }
                                    let j = gathered.n;
                                    gathered.push(i, pt, v.p, v.ng, &v.frame, rho_d, lane);
                                    gathered.push_ward(j, v.wo, rho_s, lobe);
                                    true
                                }
                                Bsdf::DiffuseMirror { rho_d, rho_s }
                                    if gathers_mirror(pt, rho_d, rho_s, v.wo.z) =>
                                {
                                    // `Bsdf::sample`'s weight for the mirror (`pd` is 0).
                                    let pd = Bsdf::diffuse_prob(rho_d, rho_s);
                                    let (j, weight) = (gathered.n, rho_s / (1.0 - pd));
                                    gathered.push(i, pt, v.p, v.ng, &v.frame, weight, lane);
                                    gathered.push_mirror(j, mirror::reflect_local(v.wo));
                                    true
                                }
                                _ => {
                                    let (st, rec) = (&mut lane.st, &mut lane.rec);
                                    pt.scatter(st, &v, &mut lane.sampler, rec)
                                }
                            },
                        }
                    };
                if !alive {
                    live &= !(1 << i);
                    done(item[i], lane);
                }
            }
        }
        gathered.scatter(pt, &mut lanes, |i, lane| {
            live &= !(1 << i);
            done(item[i], lane);
        });
    }
    lanes.map(|lane| lane.rec)
}

/// A Lambert vertex straight from the BVH's hit, without the hit record and `Vertex` of the
/// general route (`PathTracer::vertex`): the geometric normal and shading frame turned to the
/// arriving side, and the reflectance, the same as that route gives to the bit. Only for
/// triangles with a precomputed frame (flat-shaded) under a Lambert material with some
/// reflectance, seen from the frame's side, in a scene with lights, and not for a recorder
/// `R` that keeps anything (told of the hit record); otherwise None.
#[inline(always)]
fn flat_lambert<R: Record>(
    pt: &PathTracer,
    obj: &Object,
    hit: &Hit,
    d: Vec3,
) -> Option<(Vec3, Frame, Rgb)> {
    let Material::Diffuse { rho_d } = obj.material else {
        return None;
    };
    if R::KEEPS {
        return None;
    }
    let face = &pt.scene.geometry.faces[hit.prim as usize];
    let wo = -d;
    let (frame, ng) = facing(face.frame?, face.ng, wo);
    // `wo.dot(frame.n)` is `frame.to_local(wo).z`, the general route's `wo.z`.
    gathers(pt, rho_d, wo.dot(frame.n)).then_some((ng, frame, rho_d))
}

/// A Ward vertex straight from the BVH's hit, as `flat_lambert` is: the geometric normal and
/// the shading frame (rotated by the material's θ) turned to the arriving side, ωo in that
/// frame and the BSDF's parameters, the same as the general route gives to the bit. Only for
/// flat-shaded triangles under a Ward material (not a textured one's varnish, whose ρd needs
/// the hit record's UV) seen from the frame's side, in a scene with lights, and not for a
/// recorder that keeps anything; otherwise None.
#[inline(always)]
fn flat_ward<R: Record>(pt: &PathTracer, obj: &Object, hit: &Hit, d: Vec3) -> Option<FlatWard> {
    let Material::Ward {
        rho_d,
        rho_s,
        alpha_x,
        alpha_y,
        theta,
    } = obj.material
    else {
        return None;
    };
    if R::KEEPS {
        return None;
    }
    let face = &pt.scene.geometry.faces[hit.prim as usize];
    let wo = -d;
    // `bsdf_at`'s frame, then `PathTracer::vertex`'s turn and ωo.
    let (frame, ng) = facing(face.frame?.rotated(theta), face.ng, wo);
    let wo = frame.to_local(wo);
    let lobe = WardLobe {
        alpha_x,
        alpha_y,
        variant: pt.scene.render.ward_variant,
    };
    gathers_ward(pt, wo.z).then_some(FlatWard {
        ng,
        frame,
        wo,
        rho_d,
        rho_s,
        lobe,
    })
}

/// What `flat_ward` gives.
struct FlatWard {
    ng: Vec3,
    frame: Frame,
    wo: Vec3,
    rho_d: Rgb,
    rho_s: Rgb,
    lobe: WardLobe,
}

/// Next-event estimation through planar mirrors (`PathTracer::sample_mirror_lights`) at a
/// vertex about to join the eight lanes, from the light numbers `SmoothLanes::push` is about
/// to draw, added to the path's radiance before `push` copies it: the order in which
/// `PathTracer::scatter` adds them, so that the pixels stay the scalar integrator's to the bit.
#[inline(never)]
fn lane_mirror_lights<R>(
    pt: &PathTracer,
    lane: &mut Job<R>,
    p: Vec3,
    ng: Vec3,
    frame: &Frame,
    bsdf: Bsdf,
    wo: Vec3,
) {
    let [uc, l0, l1] = lane.sampler.peek_n::<3>();
    let v = Vertex {
        p,
        bsdf,
        frame: *frame,
        ng,
        wo,
    };
    pt.sample_mirror_lights(&mut lane.st, &v, uc, Vec2::new(l0, l1));
}

/// Whether a Lambert vertex of reflectance `rho_d`, seen at `wo_z` (the outgoing direction's
/// cosine in the shading frame), goes to the eight-lane `SmoothLanes`: some reflectance, seen
/// from above, in a scene with lights, all of them area or punctual lights
/// (`Lights::eight_lane`). Otherwise `PathTracer::scatter` handles it alone.
#[inline(always)]
fn gathers(pt: &PathTracer, rho_d: Rgb, wo_z: f32) -> bool {
    rho_d.max_element() > 0.0 && wo_z > 0.0 && !pt.lights.is_empty() && pt.lights.eight_lane()
}

/// Whether a Ward vertex seen at `wo_z` goes to the eight lanes (`SmoothLanes::push_ward`):
/// seen from above, in a scene with lights, all of them area or punctual lights.
#[inline(always)]
fn gathers_ward(pt: &PathTracer, wo_z: f32) -> bool {
    wo_z > 0.0 && !pt.lights.is_empty() && pt.lights.eight_lane()
}

/// Whether an ideal-mirror vertex (ρd zero, so no light sampling, and the mirror always
/// chosen: `diffuse_prob` 0) seen at `wo_z` goes to the eight lanes
/// (`SmoothLanes::push_mirror`): seen from above, in a scene with lights, all of them area or
/// punctual lights.
#[inline(always)]
fn gathers_mirror(pt: &PathTracer, rho_d: Rgb, rho_s: Rgb, wo_z: f32) -> bool {
    !(rho_d.max_element() > 0.0)
        && Bsdf::diffuse_prob(rho_d, rho_s) == 0.0
        && wo_z > 0.0
        && !pt.lights.is_empty()
        && pt.lights.eight_lane()
}

/// The next camera packet's paths: eight samples of a pixel, their rays traced together.
struct CameraPacket {
    n: usize,
    /// The next of the `n` to hand out.
    k: usize,
    rays: [Ray; LANES],
    hits: [Option<Hit>; LANES],
    samplers: [Sampler; LANES],
    /// The pixel whose sampler each slot of `samplers` holds.
    pixel: [usize; LANES],
}

/// Renders pixels `x0..x0 + out.len()` of row `y` of `camera`'s image: `out[i]` is the mean of
/// pixel x0 + i's `spp` samples (at least one), the value `film::render_pixel` gives.
pub fn render_pixels(
    pt: &PathTracer,
    camera: &Camera,
    y: usize,
    x0: usize,
    spp: u32,
    seed: u64,
    out: &mut [Rgb],
) {
    let spp = spp.max(1);
    let spp_n = spp as usize;
    let total = out.len() * spp_n;
    let mut results = vec![Rgb::ZERO; total];
    let mut next = 0usize;
    // The sampler of the pixel whose samples are being handed out (items go pixel by pixel).
    let (mut template_x, mut template) = (usize::MAX, Sampler::new(seed, 0));
    // Camera rays are traced ahead, eight at a time as one packet: eight samples of a pixel
    // are nearly one ray and walk the same nodes (`geometry::packet`).
    let mut packet = CameraPacket {
        n: 0,
        k: 0,
        rays: [Ray::new(Vec3::ZERO, Vec3::Z); LANES],
        hits: [None; LANES],
        samplers: std::array::from_fn(|_| Sampler::new(seed, 0)),
        pixel: [usize::MAX; LANES],
    };
    let eye = camera.eye();
    // An orthographic camera's rays start across its film plane, each at its own point.
    let ortho = camera.is_orthographic();
    let jobs = |job: &mut Job| {
        let pk = &mut packet;
        if pk.k == pk.n {
            if next == total {
                return false;
            }
            pk.n = (total - next).min(LANES);
            pk.k = 0;
            let (mut film_x, mut film_y) = ([0.0f32; LANES], [0.0f32; LANES]);
            for k in 0..pk.n {
                let s = &mut pk.samplers[k];
                let x = x0 + next / spp_n;
                if x != template_x {
                    template = Sampler::new(seed, (y * camera.width as usize + x) as u64);
                    template_x = x;
                }
                // A slot keeps its pixel's sampler while the packets stay on that pixel.
                if pk.pixel[k] != x {
                    s.clone_from(&template);
                    pk.pixel[k] = x;
                }
                s.start_sample((next % spp_n) as u32);
                next += 1;
                let film = Vec2::new(x as f32, y as f32) + s.next_2d();
                (film_x[k], film_y[k]) = (film.x, film.y);
            }
            // `camera.ray` for the eight film positions.
            let d = camera.directions8(f32x8::from(film_x), f32x8::from(film_y));
            let d = d.map(|c| c.to_array());
            for (k, ray) in pk.rays.iter_mut().enumerate() {
                let o = if ortho {
                    camera.ray(Vec2::new(film_x[k], film_y[k])).o
                } else {
                    eye
                };
                *ray = Ray::new(o, Vec3::new(d[0][k], d[1][k], d[2][k]));
            }
            pt.scene
                .intersect8_into(pk.rays, (1u32 << pk.n) - 1, &mut pk.hits);
        }
        let k = pk.k;
        pk.k += 1;
        job.st.restart(pk.rays[k], 0, true);
        job.hit = pk.hits[k];
        job.traced = true;
        job.sampler.take_sample_from(&pk.samplers[k]);
        true
    };
    trace_jobs(pt, jobs, |i, st| results[i] = st.l);
    // Sums in sample order, as `render_pixel`.
    for (px, samples) in out.iter_mut().zip(results.chunks(spp_n)) {
        *px = pixel_mean(samples.iter().copied(), spp);
    }
}

/// Eight lanes of Lambert, Ward and ideal-mirror vertices: what `PathTracer::scatter` reads for
/// each (a Ward vertex's lobe, a mirror's direction in `ward_rows`), and the seven random
/// numbers it would draw (light: 3, BSDF: 3, roulette: 1). A lane's values are one row
/// (`row::*` gives the layout), written with a few wide copies and turned into eight-lane
/// registers by 8×8 transposes in `scatter`, because scattering them straight into
/// structure-of-arrays form takes a store per float.
#[derive(Default)]
struct SmoothLanes {
    n: usize,
    lane: [usize; LANES],
    rows: [Row; LANES],
    /// The chosen light triangle (`Lights::row`), 0 without area lights. Lanes past `n` keep
    /// an earlier one, or 0: `scatter` reads their rows too, when there are area lights.
    light: [usize; LANES],
    /// Bit j: lane j (of the `n`) is a Ward vertex, whose lobe is in `ward_rows[j]` (its ρd
    /// in `rows[j]`). Only read when some bit is set.
    ward: u32,
    /// Bit j: lane j is an ideal mirror's vertex: no light sampling, the reflected direction
    /// in `ward_rows[j]`'s ωo slot, the weight in `rows[j]`'s reflectance.
    mirror: u32,
    ward_rows: [WardRow; LANES],
}

/// The BSDF's value for ωi `wi_local` on each lane: Lambert's ρ/π, or `Bsdf::ward_eval8` on
/// the Ward lanes (`wardm`); with the Ward lobes' exp(−E) for their density (0 without them).
#[inline(always)]
fn eval(
    rho: &[f32x8; 3],
    ward: &Option<WardLanes>,
    wardm: f32x8,
    wi_local: &[f32x8; 3],
) -> ([f32x8; 3], f32x8) {
    let mut f = rho.map(|c| c * f32x8::splat(INV_PI));
    let mut gauss = f32x8::ZERO;
    if let Some((rho_s, lobes, _, wo)) = ward {
        gauss = lobes.gaussian(wo, wi_local);
        let fw = Bsdf::ward_eval8(rho, rho_s, lobes, wo, wi_local, gauss);
        for k in 0..3 {
            f[k] = wardm.blend(fw[k], f[k]);
        }
    }
    (f, gauss)
}

/// The Ward lanes' ρs, lobes, `Bsdf::diffuse_prob` and ωo (in the shading frame), as eight-lane
/// registers.
type WardLanes = ([f32x8; 3], Lobes8, f32x8, [f32x8; 3]);

/// What a Ward vertex adds to its lane's `Row` (`ward_row::*` gives the layout).
#[derive(Clone, Copy, Default)]
#[repr(align(32))]
struct WardRow([f32; 8]);

/// Where each value sits in a `WardRow`.
mod ward_row {
    pub const RHO_S: usize = 0;
    pub const ALPHA_X: usize = 3;
    pub const ALPHA_Y: usize = 4;
    /// ωo in the shading frame (a mirror's: the reflected direction).
    pub const WO: usize = 5;
}

/// One lane of `SmoothLanes`: four groups of eight floats.
#[derive(Clone, Copy, Default)]
#[repr(align(32))]
struct Row([f32; 32]);

/// Where each value sits in a `Row`.
mod row {
    /// Position, geometric normal (both on the arriving side).
    pub const P: usize = 0;
    pub const NG: usize = 3;
    /// Shading frame: tangent, bitangent, normal.
    pub const FRAME: usize = 6;
    pub const RHO: usize = 15;
    pub const BETA: usize = 18;
    pub const L: usize = 21;
    pub const U_LIGHT: usize = 24;
    pub const U_BSDF: usize = 26;
    pub const U_RR: usize = 28;
    /// 1 where roulette applies (the path has `PathTracer::rr_depth` segments or more), else 0.
    /// (`f32::from(u8::from(..))` of the comparison compiled to a branch, mispredicted a
    /// quarter of the time; the comparison's `u32` made a float compiles to `setae`.)
    pub const ROULETTE: usize = 29;
    /// The BSDF's lobe choice (Ward vertices only).
    pub const U_CHOICE: usize = 30;
}

fn put(row: &mut Row, at: usize, v: Vec3) {
    row.0[at..at + 3].copy_from_slice(&v.to_array());
}

fn vec(x: &[f32x8], at: usize) -> [f32x8; 3] {
    [x[at], x[at + 1], x[at + 2]]
}

/// Three `vec`s from nine registers at `at` (a frame's axes, a triangle's vertices), written
/// out: `[0, 3, 6].map(..)` compiled to an outlined call whose 64-byte copies of 32-byte stores
/// missed store forwarding.
#[inline(always)]
fn frame(x: &[f32x8], at: usize) -> [[f32x8; 3]; 3] {
    [vec(x, at), vec(x, at + 3), vec(x, at + 6)]
}

fn dot(a: &[f32x8; 3], b: &[f32x8; 3]) -> f32x8 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// The lanes whose bit is set in `bits`, as a mask.
#[inline(always)]
fn lanes_of(bits: u32) -> f32x8 {
    let one_if = |j: usize| if bits >> j & 1 != 0 { 1.0 } else { 0.0 };
    f32x8::from(std::array::from_fn::<f32, LANES, _>(one_if)).cmp_gt(f32x8::ZERO)
}

/// glam's `max_element`: max(x, max(y, z)) with max(a, b) = a > b ? a : b.
fn max_element(a: &[f32x8; 3]) -> f32x8 {
    let max = |a: f32x8, b: f32x8| a.cmp_gt(b).blend(a, b);
    max(a[0], max(a[1], a[2]))
}

/// max(|x|, |y|, |z|), as glam's `abs().max_element()` for finite values.
fn abs_max(a: &[f32x8; 3]) -> f32x8 {
    a[0].abs().max(a[1].abs().max(a[2].abs()))
}

/// `geometry::offset_origin(p, ng, dir)` on eight lanes.
fn offset_origin(p: &[f32x8; 3], ng: &[f32x8; 3], dir: &[f32x8; 3]) -> [f32x8; 3] {
    let eps = f32x8::splat(1e-4) * (f32x8::ONE + abs_max(p));
    let up = dot(ng, dir).cmp_ge(f32x8::ZERO);
    std::array::from_fn(|k| up.blend(p[k] + ng[k] * eps, p[k] - ng[k] * eps))
}

impl SmoothLanes {
    /// Adds lane `i` at vertex `v` (a Lambert surface of reflectance `rho`, seen from above,
    /// in a scene with lights), drawing its random numbers.
    #[allow(clippy::too_many_arguments)]
    #[inline(always)]
    fn push<R>(
        &mut self,
        i: usize,
        pt: &PathTracer,
        p: Vec3,
        ng: Vec3,
        frame: &Frame,
        rho: Rgb,
        lane: &mut Job<R>,
    ) {
        let j = self.n;
        self.n += 1;
        self.lane[j] = i;
        // `Lights::sample`: the triangle, then the point on it; `Bsdf::sample` (Diffuse): the
        // lobe choice (unused), then the direction; roulette.
        let [uc, l0, l1, u_choice, b0, b1, u_rr] = lane.sampler.next_n::<7>();
        let roulette = u32::from(lane.st.segments >= pt.rr_depth);
        self.light[j] = if pt.lights.has_area() {
            pt.lights.pick_index(uc)
        } else {
            0
        };
        let r = &mut self.rows[j];
        put(r, row::P, p);
        put(r, row::NG, ng);
        put(r, row::FRAME, frame.s);
        put(r, row::FRAME + 3, frame.t);
        put(r, row::FRAME + 6, frame.n);
        put(r, row::RHO, rho);
        put(r, row::BETA, lane.st.beta);
        put(r, row::L, lane.st.l);
        r.0[row::U_LIGHT..row::U_CHOICE + 1].copy_from_slice(&[
            l0,
            l1,
            b0,
            b1,
            u_rr,
            roulette as f32,
            u_choice,
        ]);
    }

    /// Makes lane `j`, just pushed with the mirror's sampling weight as its reflectance, an
    /// ideal mirror reflecting to `wi` (in the shading frame).
    fn push_mirror(&mut self, j: usize, wi: Vec3) {
        self.mirror |= 1 << j;
        let r = &mut self.ward_rows[j].0;
        r[ward_row::WO..ward_row::WO + 3].copy_from_slice(&wi.to_array());
    }

    /// Makes lane `j`, just pushed with its ρd as the reflectance, the Ward BSDF (ρd, ρs,
    /// `lobe`) seen from `wo` (in the shading frame, above the surface). Its normalisation is
    /// the scene's (`Scene::render`), which `scatter` gives all its lanes' lobes, and its
    /// `Bsdf::diffuse_prob` is computed there on the eight lanes.
    fn push_ward(&mut self, j: usize, wo: Vec3, rho_s: Rgb, lobe: WardLobe) {
        self.ward |= 1 << j;
        let r = &mut self.ward_rows[j].0;
        r[ward_row::RHO_S..ward_row::RHO_S + 3].copy_from_slice(&rho_s.to_array());
        r[ward_row::ALPHA_X] = lobe.alpha_x;
        r[ward_row::ALPHA_Y] = lobe.alpha_y;
        r[ward_row::WO..ward_row::WO + 3].copy_from_slice(&wo.to_array());
    }

    /// Adds what punctual light `light` sends through the `smooth` lanes' BSDFs to their
    /// radiance `l`: `PathTracer::scatter`'s next-event estimation for one
    /// `Lights::punctual_samples` sample (no MIS weight, pdf 1), its sample and shadow ray
    /// lane by lane, the BSDF on eight lanes.
    #[allow(clippy::too_many_arguments)]
    fn add_punctual<R: Record>(
        &self,
        pt: &PathTracer,
        lanes: &mut [Job<R>; LANES],
        light: &Punctual,
        p: &[f32x8; 3],
        ng: &[f32x8; 3],
        fr: &[[f32x8; 3]; 3],
        rho: &[f32x8; 3],
        beta: &[f32x8; 3],
        l: &mut [f32x8; 3],
        smooth: f32x8,
        ward: &Option<WardLanes>,
        wardm: f32x8,
    ) {
        let zero = f32x8::ZERO;
        let pa = p.map(|c| c.to_array());
        let mut samples: [Option<LightSample>; LANES] = [None; LANES];
        let (mut wi, mut li) = ([[0.0f32; LANES]; 3], [[0.0f32; LANES]; 3]);
        let mut mask = smooth.move_mask() as u32;
        while mask != 0 {
            let j = mask.trailing_zeros() as usize;
            mask &= mask - 1;
            let pj = Vec3::new(pa[0][j], pa[1][j], pa[2][j]);
            if let Some(s) = punctual_sample(light, pj) {
                for k in 0..3 {
                    (wi[k][j], li[k][j]) = (s.wi[k], s.radiance[k]);
                }
                samples[j] = Some(s);
            }
        }
        let have = lanes_of(
            samples
                .iter()
                .enumerate()
                .fold(0, |m, (j, s)| m | u32::from(s.is_some()) << j),
        );
        let wi = wi.map(f32x8::from);
        let wi_local = [dot(&wi, &fr[0]), dot(&wi, &fr[1]), dot(&wi, &fr[2])];
        let lit = have & wi_local[2].cmp_gt(zero) & dot(ng, &wi).cmp_gt(zero);
        let (f, _) = eval(rho, ward, wardm, &wi_local);
        let reflects = max_element(&f).cmp_gt(zero);
        let nee = if R::EVERY_LIGHT { lit } else { lit & reflects };
        let origin = offset_origin(p, ng, &wi).map(|c| c.to_array());
        let mut visible = [0.0f32; LANES];
        let mut mask = nee.move_mask() as u32;
        while mask != 0 {
            let j = mask.trailing_zeros() as usize;
            mask &= mask - 1;
            let o = Vec3::new(origin[0][j], origin[1][j], origin[2][j]);
            if let Some(s) = &samples[j] {
                visible[j] = f32::from(u8::from(pt.lights.visible(pt.scene, o, s)));
            }
        }
        let seen = nee & f32x8::from(visible).cmp_gt(zero);
        // `scatter`'s β f Li (cos θi w / pdf) with w = pdf = 1.
        let li = li.map(f32x8::from);
        if R::KEEPS {
            self.tell_lights(lanes, seen, &wi_local, &li.map(|c| c * wi_local[2]));
        }
        let nee = if R::EVERY_LIGHT { seen & reflects } else { seen };
        for k in 0..3 {
            l[k] = nee.blend(l[k] + beta[k] * f[k] * li[k] * wi_local[2], l[k]);
        }
    }

    /// Tells the recorders of the `seen` lanes their light sample: ωi in the shading frame, and
    /// the light's radiance × cos θi × MIS weight / density (`Record::light`).
    fn tell_lights<R: Record>(
        &self,
        lanes: &mut [Job<R>; LANES],
        seen: f32x8,
        wi: &[f32x8; 3],
        term: &[f32x8; 3],
    ) {
        let (wi, term) = (wi.map(|c| c.to_array()), term.map(|c| c.to_array()));
        let mut mask = seen.move_mask() as u32;
        while mask != 0 {
            let j = mask.trailing_zeros() as usize;
            mask &= mask - 1;
            lanes[self.lane[j]].rec.light(
                Vec3::new(wi[0][j], wi[1][j], wi[2][j]),
                Vec3::new(term[0][j], term[1][j], term[2][j]),
            );
        }
    }

    /// `PathTracer::scatter` for the gathered lanes, telling their recorders what it tells:
    /// each lane's path continues with its next ray or ends (`finish` gets its lane).
    fn scatter<R: Record>(
        &self,
        pt: &PathTracer,
        lanes: &mut [Job<R>; LANES],
        mut finish: impl FnMut(usize, &mut Job<R>),
    ) {
        if self.n == 0 {
            return;
        }
        let splat = f32x8::splat;
        let (zero, one) = (f32x8::ZERO, f32x8::ONE);
        let live = lanes_of((1 << self.n) - 1);
        let x: [f32x8; 32] = transpose(std::array::from_fn(|j| &self.rows[j].0));
        let p = vec(&x, row::P);
        let ng = vec(&x, row::NG);
        let fr = frame(&x, row::FRAME);
        let rho = vec(&x, row::RHO);
        let mut beta = vec(&x, row::BETA);
        let mut l = vec(&x, row::L);
        // The Ward vertices' lobes: ρs, the lobe, `Bsdf::diffuse_prob`, ωo (local); the
        // mirrors' directions.
        let (wardm, mirrorm) = (lanes_of(self.ward), lanes_of(self.mirror));
        let y: Option<[f32x8; 8]> = ((self.ward | self.mirror) != 0)
            .then(|| transpose(std::array::from_fn(|j| &self.ward_rows[j].0)));
        let ward: Option<WardLanes> = y.filter(|_| self.ward != 0).map(|y| {
            let lobes = Lobes8::new(
                y[ward_row::ALPHA_X],
                y[ward_row::ALPHA_Y],
                pt.scene.render.ward_variant,
            );
            let (wo, rho_s) = (vec(&y, ward_row::WO), vec(&y, ward_row::RHO_S));
            (rho_s, lobes, Bsdf::diffuse_prob8(&rho, &rho_s), wo)
        });

        // Next-event estimation, in `scatter`'s order: the area light (`Lights::sample`, then
        // `scatter`'s checks), then every punctual light.
        let smooth = live & !mirrorm;
        if pt.lights.has_area() {
            let light: [f32x8; 16] =
                transpose(std::array::from_fn(|j| pt.lights.row(self.light[j])));
            let su = x[row::U_LIGHT].sqrt();
            let b1 = one - su;
            let b2 = x[row::U_LIGHT + 1] * su;
            let b0 = one - b1 - b2;
            let lv = frame(&light, Lights::V);
            let q: [f32x8; 3] =
                std::array::from_fn(|k| lv[0][k] * b0 + lv[1][k] * b1 + lv[2][k] * b2);
            let d: [f32x8; 3] = std::array::from_fn(|k| q[k] - p[k]);
            let dist2 = dot(&d, &d);
            let dist = dist2.sqrt();
            let wi: [f32x8; 3] = d.map(|c| c / dist);
            let cos_l = -dot(&vec(&light, Lights::N), &wi);
            let light_ok = !cos_l.cmp_le(zero) & !dist.cmp_le(zero);
            let light_pdf = light[Lights::PDF_AREA] * dist2 / cos_l;
            let wi_local = [dot(&wi, &fr[0]), dot(&wi, &fr[1]), dot(&wi, &fr[2])];
            let cos_g = dot(&ng, &wi);
            let lit = smooth & light_ok & wi_local[2].cmp_gt(zero) & cos_g.cmp_gt(zero);
            // The Ward lobes' exp(−E) serves their density below too.
            let (f, gauss) = eval(&rho, &ward, wardm, &wi_local);
            let reflects = max_element(&f).cmp_gt(zero);
            // A recorder of every light sample (`Record::EVERY_LIGHT`) has the shadow rays of
            // those the BSDF does not reflect traced too; their radiance is left out below.
            let mut nee = if R::EVERY_LIGHT { lit } else { lit & reflects };
            // `Lights::visible`: the shadow ray from the offset origin to the light point.
            let origin = offset_origin(&p, &ng, &wi);
            let to_light: [f32x8; 3] = std::array::from_fn(|k| q[k] - origin[k]);
            let len = dot(&to_light, &to_light).sqrt();
            let eps = splat(2e-4) * (one + abs_max(&q));
            nee &= len.cmp_gt(eps);
            let dir = to_light.map(|c| c / len);
            let t_max = len - eps;
            let mut mask = nee.move_mask();
            let mut visible = [0.0f32; LANES];
            if mask != 0 {
                let (o, dir, t_max) = (
                    origin.map(|c| c.to_array()),
                    dir.map(|c| c.to_array()),
                    t_max.to_array(),
                );
                while mask != 0 {
                    let j = mask.trailing_zeros() as usize;
                    mask &= mask - 1;
                    let ray = Ray::new(
                        Vec3::new(o[0][j], o[1][j], o[2][j]),
                        Vec3::new(dir[0][j], dir[1][j], dir[2][j]),
                    );
                    if !pt.scene.occluded(&ray, t_max[j]) {
                        visible[j] = 1.0;
                    }
                }
            }
            let seen = nee & f32x8::from(visible).cmp_gt(zero);
            // Lambert's pdf (wo is above the surface) or Ward's, and the power heuristic.
            let mut bsdf_pdf = wi_local[2].max(zero) * splat(INV_PI);
            if let Some((_, lobes, pd, wo)) = &ward {
                let pw = Bsdf::ward_pdf8(*pd, lobes, wo, &wi_local, gauss);
                bsdf_pdf = wardm.blend(pw, bsdf_pdf);
            }
            let (a, b) = (light_pdf * light_pdf, bsdf_pdf * bsdf_pdf);
            let w = (a + b).cmp_eq(zero).blend(zero, a / (a + b));
            let scale = wi_local[2] * w / light_pdf;
            let le = vec(&light, Lights::LE);
            if R::KEEPS {
                self.tell_lights(lanes, seen, &wi_local, &le.map(|c| c * scale));
            }
            let nee = if R::EVERY_LIGHT { seen & reflects } else { seen };
            for k in 0..3 {
                l[k] = nee.blend(l[k] + beta[k] * f[k] * le[k] * scale, l[k]);
            }
        }
        for light in pt.lights.punctual() {
            self.add_punctual(
                pt, lanes, light, &p, &ng, &fr, &rho, &beta, &mut l, smooth, &ward, wardm,
            );
        }

        // The cosine-weighted direction (`warp::cosine_hemisphere`).
        let ox = splat(2.0) * x[row::U_BSDF] - one;
        let oy = splat(2.0) * x[row::U_BSDF + 1] - one;
        let centre = ox.cmp_eq(zero) & oy.cmp_eq(zero);
        let x_major = ox.abs().cmp_gt(oy.abs());
        let ratio = x_major.blend(oy, ox) / x_major.blend(ox, oy);
        let (sin, cos) = warp::sin_cos_quarter_x8(splat(PI / 4.0) * ratio);
        let r = x_major.blend(ox, oy);
        let dx = centre.blend(zero, r * x_major.blend(cos, sin));
        let dy = centre.blend(zero, r * x_major.blend(sin, cos));
        let z = (one - dx * dx - dy * dy).max(zero).sqrt();
        let mut wi = [dx, dy, z];
        let mut bsdf_pdf = z.max(zero) * splat(INV_PI);
        let mut weight = rho;
        let mut ok = z.cmp_gt(zero);
        if let Some((rho_s, lobes, pd, wo)) = &ward {
            // `Bsdf::sample` (Ward): the lobe's direction where the choice is not the diffuse
            // part, then the whole BSDF's density and f cos θi / pdf.
            let lobe = wardm & !x[row::U_CHOICE].cmp_lt(*pd);
            let (u0, u1) = (x[row::U_BSDF], x[row::U_BSDF + 1]);
            let (w, _, m) = lobes.sample(wo, u0, u1);
            for k in 0..3 {
                wi[k] = lobe.blend(w[k], wi[k]);
            }
            ok = wi[2].cmp_gt(zero);
            // exp(−E): the lobe's draw gives it, a Ward lane's Lambert draw computes it.
            let gauss = if (wardm & !lobe).move_mask() != 0 {
                lobe.blend(m, lobes.gaussian(wo, &wi))
            } else {
                m
            };
            let pdf = Bsdf::ward_pdf8(*pd, lobes, wo, &wi, gauss);
            let f = Bsdf::ward_eval8(&rho, rho_s, lobes, wo, &wi, gauss);
            let cos_over_pdf = wi[2] / pdf;
            for k in 0..3 {
                weight[k] = wardm.blend(f[k] * cos_over_pdf, weight[k]);
            }
            bsdf_pdf = wardm.blend(pdf, bsdf_pdf);
            ok &= pdf.cmp_gt(zero) | !wardm;
        }
        if let Some(y) = y.filter(|_| self.mirror != 0) {
            // `Bsdf::sample` (the mirror): always a direction, its weight already in `rho`.
            let reflected = vec(&y, ward_row::WO);
            for k in 0..3 {
                wi[k] = mirrorm.blend(reflected[k], wi[k]);
            }
            ok |= mirrorm;
        }
        let wi_world: [f32x8; 3] =
            std::array::from_fn(|k| fr[0][k] * wi[0] + fr[1][k] * wi[1] + fr[2][k] * wi[2]);
        let mut go = live & ok & !dot(&ng, &wi_world).cmp_le(zero);
        for k in 0..3 {
            beta[k] *= weight[k];
        }
        let beta_max = beta[0].max(beta[1].max(beta[2]));
        let finite = beta
            .iter()
            .fold(go, |m, c| m & c.abs().cmp_lt(splat(f32::INFINITY)));
        go = finite & !beta_max.cmp_le(zero);
        // Russian roulette.
        let q = (one - beta_max).max(splat(0.05));
        let rr = x[row::ROULETTE].cmp_gt(zero);
        go &= !(rr & x[row::U_RR].cmp_lt(q));
        let keep = one - q;
        for c in beta.iter_mut() {
            *c = rr.blend(*c / keep, *c);
        }
        let next_o = offset_origin(&p, &ng, &wi_world);
        if R::KEEPS {
            // `Bsdf::sample`'s density for the mirror lanes is the chance of choosing the
            // mirror, 1 (their `diffuse_prob` is 0).
            let pdf = mirrorm.blend(one, bsdf_pdf).to_array();
            let rr = rr.blend(one / keep, one).to_array();
            let wi = wi.map(|c| c.to_array());
            let mut mask = go.move_mask() as u32;
            while mask != 0 {
                let j = mask.trailing_zeros() as usize;
                mask &= mask - 1;
                let wi = Vec3::new(wi[0][j], wi[1][j], wi[2][j]);
                let delta = self.mirror >> j & 1 != 0;
                lanes[self.lane[j]].rec.scattered(wi, pdf[j], delta, rr[j]);
            }
        }

        let go = go.move_mask();
        let (l, beta) = (l.map(|c| c.to_array()), beta.map(|c| c.to_array()));
        let (next_o, next_d) = (next_o.map(|c| c.to_array()), wi_world.map(|c| c.to_array()));
        let bsdf_pdf = bsdf_pdf.to_array();
        // Every lane's state is written back, then the ended paths are finished: a branch per
        // lane on whether its path goes on mispredicted often (an ended path's other fields
        // are never read again).
        for j in 0..self.n {
            let lane = &mut lanes[self.lane[j]];
            lane.st.l = Vec3::new(l[0][j], l[1][j], l[2][j]);
            lane.st.beta = Vec3::new(beta[0][j], beta[1][j], beta[2][j]);
            lane.st.prev_pdf = (self.mirror >> j & 1 == 0).then_some(bsdf_pdf[j]);
            lane.st.ray = Ray::new(
                Vec3::new(next_o[0][j], next_o[1][j], next_o[2][j]),
                Vec3::new(next_d[0][j], next_d[1][j], next_d[2][j]),
            );
        }
        let mut ended = !go & ((1 << self.n) - 1);
        while ended != 0 {
            let j = ended.trailing_zeros() as usize;
            ended &= ended - 1;
            finish(self.lane[j], &mut lanes[self.lane[j]]);
        }
    }
}

/// A pixel's value from its `spp` samples, summed in the order given; non-finite samples are
/// dropped (and would be a bug).
pub(super) fn pixel_mean(samples: impl IntoIterator<Item = Rgb>, spp: u32) -> Rgb {
    let mut sum = Rgb::ZERO;
    for l in samples {
        if l.is_finite() {
            sum += l;
        }
    }
    sum / spp as f32
}
