//! What the fitter asks of the renderer for its incident-radiance cache (`fit::cache`): the
//! radiance arriving along indirect rays that leave a surface, traced by the path tracer as it
//! traces its own paths (eight at a time, `batch.rs`), so that the cache sees the light a render
//! of the same scene sees. Light samples, their visibility and density are `Lights`' own
//! functions; the cache composes them with its mixture of directions, whose MIS weights belong
//! to its estimator, not to the renderer.

use super::batch::{trace_jobs, Job};
use super::integrator::{PathTracer, Touched};
use crate::geometry::{Hit, Ray};
use crate::math::{Rgb, Sampler};

/// An indirect ray leaving a surface: where it lands (already intersected by the caller,
/// `Scene::intersect_hit`), and the sampler its path goes on drawing from.
#[derive(Clone)]
pub struct IndirectRay {
    pub ray: Ray,
    pub hit: Option<Hit>,
    pub sampler: Sampler,
}

impl IndirectRay {
    /// Makes `lane` this ray's path: one segment so far, emission at its first hit left out.
    /// The lane's fields are written in place (`PathState::restart`), not through a new `Job`.
    #[inline(always)]
    pub(super) fn start<R>(self, lane: &mut Job<R>) {
        lane.st.restart(self.ray, 1, false);
        lane.hit = self.hit;
        lane.traced = true;
        lane.sampler = self.sampler;
    }
}

/// The radiance arriving back along each ray, in order, and where its path went: the path's
/// one segment so far is the ray, and emission at its first hit is left out (the caller
/// weights it against light sampling). Each value is `PathTracer::trace(ray, sampler, 1,
/// false)`'s to the bit.
pub fn indirect_radiance(pt: &PathTracer, rays: Vec<IndirectRay>) -> Vec<(Rgb, Touched)> {
    let mut radiance = vec![(Rgb::ZERO, Touched::default()); rays.len()];
    let mut rays = rays.into_iter();
    let next = |lane: &mut Job| rays.next().map(|r| r.start(lane)).is_some();
    trace_jobs(pt, next, |i, st| radiance[i] = (st.l, st.touched));
    radiance
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::math::Vec3;
    use crate::scene::load::parse_scene;

    /// A grey floor, a back wall and a glossy (Ward) side wall, open above and in front, lit by
    /// the sun, an area light facing the side wall and a stray light: `{wall}` and `{stray}` set
    /// the back wall's ρd and the stray radiance.
    const ROOM: &str = r#"
[render]
spp = 1
seed = 1
[camera]
width = 8
height = 8
eye = [0.0, 1.0, 2.0]
target = [0.0, 0.5, -1.0]
up = [0.0, 1.0, 0.0]
fov_y_deg = 60.0
[[object]]
name = "floor"
group = "floor"
shape = "quad"
corner = [-2.0, 0.0, 1.0]
edge_u = [4.0, 0.0, 0.0]
edge_v = [0.0, 0.0, -3.0]
material = { type = "diffuse", rho_d = 0.5 }
[[object]]
name = "wall"
group = "wall"
shape = "quad"
corner = [-2.0, 0.0, -2.0]
edge_u = [4.0, 0.0, 0.0]
edge_v = [0.0, 2.0, 0.0]
material = { type = "diffuse", rho_d = {wall} }
[[object]]
name = "side"
group = "side"
shape = "quad"
corner = [-2.0, 0.0, 1.0]
edge_u = [0.0, 0.0, -3.0]
edge_v = [0.0, 2.0, 0.0]
tangent = [0.0, 1.0, 0.0]
material = { type = "ward", rho_d = 0.3, rho_s = 0.4, alpha_x = 0.1, alpha_y = 0.3, theta_deg = 0.0 }
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
radiance = [{stray}, {stray}, {stray}]
"#;

    fn room(wall: f32, stray: f32) -> crate::scene::Scene {
        let text = ROOM
            .replace("{wall}", &wall.to_string())
            .replace("{stray}", &stray.to_string());
        parse_scene(&text, std::path::Path::new("room.toml")).unwrap()
    }

    /// Rays leaving the floor in directions spread over the hemisphere, their paths drawing
    /// from samplers of `seed` (the rooms of this module's and `replay`'s tests share a floor).
    pub(crate) fn rays(scene: &crate::scene::Scene, n: u64, seed: u64) -> Vec<IndirectRay> {
        (0..n)
            .map(|i| {
                let (u, v) = ((i % 50) as f32 / 50.0, (i / 50 % 80) as f32 / 80.0);
                let o = Vec3::new(-1.5 + 3.0 * u, 1e-3, 0.5 - 2.0 * v);
                let (phi, z) = (
                    2.0 * std::f32::consts::PI * (i as f32 * 0.618).fract(),
                    0.05 + 0.45 * v,
                );
                let r = (1.0 - z * z).sqrt();
                let ray = Ray::new(o, Vec3::new(r * phi.cos(), z, r * phi.sin()));
                // Sample 0 of stream i: a sampler's values are set by `start_sample`.
                let mut sampler = Sampler::new(seed, i);
                sampler.start_sample(0);
                IndirectRay {
                    hit: scene.intersect_hit(&ray, f32::INFINITY),
                    ray,
                    sampler,
                }
            })
            .collect()
    }

    /// Traced again where only the back wall's ρd (or only the stray light) changed, a path
    /// `Touched` says never arrived at the wall (or never left the room) comes back the same to
    /// the bit; the others include paths that change, so the test can tell (about 1300 for the
    /// wall, 100 for the stray light: most paths that leave the room do so on their first
    /// segment, whose light the caller takes).
    #[test]
    fn a_path_that_touched_nothing_that_moved_comes_back_the_same() {
        let base = room(0.6, 0.3);
        let traced = indirect_radiance(&PathTracer::new(&base), rays(&base, 4000, 11));
        for (moved, what) in [
            (room(0.2, 0.3), "the wall"),
            (room(0.6, 1.3), "the stray light"),
        ] {
            let again = indirect_radiance(&PathTracer::new(&moved), rays(&moved, 4000, 11));
            let wall = base.group_index("wall").unwrap();
            let (mut same, mut changed) = (0, 0);
            for ((l, t), (m, _)) in traced.iter().zip(&again) {
                let touched = match what {
                    "the wall" => t.group(wall),
                    _ => t.escaped(),
                };
                if !touched {
                    assert_eq!(
                        l.to_array().map(f32::to_bits),
                        m.to_array().map(f32::to_bits)
                    );
                    same += 1;
                } else if l != m {
                    changed += 1;
                }
            }
            assert!(
                same > 400 && changed > 50,
                "{what}: {same} untouched, {changed} changed"
            );
        }
    }
}
