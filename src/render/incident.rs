//! What the fitter asks of the renderer for its incident-radiance cache (`fit::cache`): the
//! radiance arriving along indirect rays that leave a surface, traced by the path tracer as it
//! traces its own paths (eight at a time, `batch.rs`), so that the cache sees the light a render
//! of the same scene sees. Light samples, their visibility and density are `Lights`' own
//! functions; the cache composes them with its mixture of directions, whose MIS weights belong
//! to its estimator, not to the renderer.

use super::batch::{trace_jobs, Job};
use super::integrator::{PathState, PathTracer};
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

/// The radiance arriving back along each ray, in order: the path's one segment so far is the
/// ray, and emission at its first hit is left out (the caller weights it against light
/// sampling). Each value is `PathTracer::trace(ray, sampler, 1, false)`'s to the bit.
pub fn indirect_radiance(pt: &PathTracer, rays: Vec<IndirectRay>) -> Vec<Rgb> {
    let mut radiance = vec![Rgb::ZERO; rays.len()];
    let mut rays = rays.into_iter();
    let next = |lane: &mut Job| {
        rays.next()
            .map(|r| {
                *lane = Job {
                    st: PathState::new(r.ray, 1, false),
                    hit: r.hit,
                    traced: true,
                    sampler: r.sampler,
                }
            })
            .is_some()
    };
    trace_jobs(pt, next, |i, l| radiance[i] = l);
    radiance
}
