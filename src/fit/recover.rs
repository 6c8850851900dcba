//! The global loop of the recovery (§4.1, Figure 1 of the notes): every global iteration
//! re-renders what each fitted group sees with *all* current parameters (so light bounced off a
//! surface whose BRDF changed reaches the others), refits each group on its fresh cache and lets
//! the hierarchy decide its level; then one final render gives the synthetic image.
//!
//! Groups are visited in turn and each one's new parameters enter the scene at once
//! (Gauss–Seidel), so a group's cache already sees the groups refitted before it in the same
//! iteration. Measured against updating all groups at the end of the iteration (Jacobi) on the
//! bench's diffuse figure6 (Mitsuba photo): worst ρ error after iterations 0, 1, 2 went from
//! 0.23, 0.11, 0.024 to 0.12, 0.017, 0.006 (≤ 0.01 at 0.62 s instead of 1.11 s), 9 → 8
//! iterations; the demo 15 → 12 iterations, recovery 31.5 → 27.7 s, same accuracy.

use super::cache::{build, choose_pixels, CacheOptions};
use super::hierarchy::{Event, GroupState, HierarchyOptions, Status};
use super::params::GroupParams;
use crate::io::image::Image;
use crate::math::sampler::hash_seed;
use crate::math::Rgb;
use crate::photo::{GroupPixelStats, Photo, UsableMask};
use crate::render::film::{progress_bar, render, RenderOptions};
use crate::render::PathTracer;
use crate::scene::Scene;
use serde::{Deserialize, Serialize};
use std::time::Instant;

#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct RecoverOptions {
    pub cache: CacheOptions,
    pub hierarchy: HierarchyOptions,
    /// At most this many global iterations.
    pub max_iterations: u32,
    /// Stop once every group is confirmed and no ρ moved by more than this (α: relative).
    pub tolerance: f32,
    /// Groups may climb the hierarchy only after an iteration in which no level changed and no
    /// parameter moved by more than this.
    pub settle: f32,
    /// Do not stop before every confirmed group has averaged this many independent fits.
    pub min_average: u32,
    /// Diffuse reflectance given to groups with no usable pixels when `unseen.enabled` is false
    /// (the notes: white).
    pub default_rho_d: f32,
    /// Groups with no usable pixels: their ρd estimated from the light they reflect
    /// ([`super::unseen`]).
    #[serde(default)]
    pub unseen: super::unseen::UnseenOptions,
    /// Cached pixels per group in the first global iteration; the number doubles every
    /// iteration up to `cache.max_pixels`. The first iterations fit against a scene still far
    /// from its fixed point (every group starts grey), so precision there is wasted time; the
    /// run does not stop before the full number is reached. 0: `cache.max_pixels` throughout.
    #[serde(default)]
    pub first_pixels: usize,
    /// Samples per pixel of the final render.
    pub final_spp: u32,
    pub seed: u64,
    pub progress: bool,
}

impl Default for RecoverOptions {
    fn default() -> Self {
        RecoverOptions {
            cache: CacheOptions::default(),
            hierarchy: HierarchyOptions::default(),
            max_iterations: 16,
            tolerance: 5e-3,
            settle: 0.03,
            min_average: 4,
            default_rho_d: 1.0,
            unseen: Default::default(),
            first_pixels: 1500,
            final_spp: 64,
            seed: 0,
            progress: true,
        }
    }
}

/// Cached pixels per group in global iteration `it` (see `RecoverOptions::first_pixels`).
pub fn pixel_budget(opts: &RecoverOptions, it: u32) -> usize {
    if opts.first_pixels == 0 {
        return opts.cache.max_pixels;
    }
    opts.first_pixels
        .saturating_mul(1usize << it.min(30))
        .min(opts.cache.max_pixels)
}

/// One line of the log: a group's event in a global iteration.
#[derive(Clone, Debug, Serialize)]
pub struct LogLine {
    pub iteration: u32,
    pub group: String,
    #[serde(flatten)]
    pub event: Event,
    pub params: std::collections::BTreeMap<&'static str, super::params::Value>,
    /// Time spent on this group in this iteration (cache build and fits).
    pub seconds: f64,
    /// Seconds since the recovery started when the line was written (across a resume: the
    /// interrupted run's time up to its checkpoint plus the resumed run's), so that the
    /// parameters can be plotted against time (`bench/compare.py`).
    pub elapsed: f64,
}

/// The state of a recovery after a global iteration: enough to continue it exactly (the caches'
/// seeds derive from the iteration number, so a resumed run draws the same samples).
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Checkpoint {
    pub version: u32,
    /// A hash of the scene file, the photo and the options: a checkpoint only resumes the run
    /// that wrote it.
    pub fingerprint: u64,
    pub next_iteration: u32,
    pub states: Vec<GroupState>,
    pub settled: bool,
    pub cache_builds: u32,
    pub objective_evals: u64,
    /// Length of log.jsonl when the checkpoint was taken (the caller truncates to it).
    pub log_bytes: u64,
    /// The log's `elapsed` when the checkpoint was taken.
    #[serde(default)]
    pub elapsed: f64,
    /// The unseen groups' recent estimates (`unseen::History`), so a resumed run averages the
    /// same ones.
    #[serde(default)]
    pub unseen_history: super::unseen::History,
}

pub const CHECKPOINT_VERSION: u32 = 2;

/// A hash identifying a run: scene text, photo pixels, mask and options.
pub fn fingerprint(
    scene_text: &str,
    photo: &Photo,
    mask: &UsableMask,
    opts: &RecoverOptions,
) -> u64 {
    use crate::math::sampler::mix64;
    let mut h = hash_seed(&[CHECKPOINT_VERSION as u64]);
    for b in scene_text.bytes() {
        h = mix64(h ^ b as u64);
    }
    for c in &photo.image.data {
        h = mix64(
            h ^ ((c.x.to_bits() as u64) << 32 | c.y.to_bits() as u64)
                ^ (c.z.to_bits() as u64).rotate_left(17),
        );
    }
    for &g in &mask.group {
        h = mix64(h ^ g as u64);
    }
    let o = serde_json::to_string(opts).expect("options serialise");
    for b in o.bytes() {
        h = mix64(h ^ b as u64);
    }
    h
}

/// Everything a recovery produced.
pub struct Recovery {
    pub groups: Vec<GroupState>,
    pub pixel_stats: Vec<GroupPixelStats>,
    /// The unseen groups' estimates after the last global iteration (empty without such groups).
    pub unseen: Vec<super::unseen::UnseenEstimate>,
    /// The scene with the recovered materials.
    pub scene: Scene,
    pub synthetic: Image,
    /// Per-group ε and noise floor of the final render against the photo (usable pixels).
    pub final_error: Vec<Option<(f32, f32)>>,
    pub mask: UsableMask,
    pub iterations: u32,
    pub cache_builds: u32,
    pub objective_evals: u64,
    pub total_s: f64,
    pub final_render_s: f64,
}

/// Applies each group's current parameters to its objects.
fn apply(scene: &mut Scene, states: &[GroupState]) {
    for obj in scene.objects.iter_mut() {
        let st = &states[obj.group];
        if matches!(
            st.status,
            Status::Analysing | Status::Confirmed | Status::Default
        ) {
            obj.material = st.params.material(st.level);
        }
    }
}

/// Recovers the materials of `scene`'s non-fixed groups from `photo`, using the usable pixels
/// of `mask` (see `photo::prepare`; `scene.camera` must be the camera the mask was made with).
/// `log` receives every event as it happens. Fails (naming the group) if a fit diverges: see
/// [`recover_resumable`].
pub fn recover(
    scene: &Scene,
    photo: &Photo,
    mask: &UsableMask,
    opts: &RecoverOptions,
    log: impl FnMut(&LogLine),
) -> Result<Recovery, String> {
    recover_resumable(scene, photo, mask, opts, None, log, |_| {})
}

/// [`recover`], starting from `resume` if given, and handing a [`Checkpoint`] to `checkpoint`
/// after every global iteration (its `fingerprint` and `log_bytes` are the caller's to fill).
///
/// A fit whose error or parameters are not finite (NaN or infinite values reached it, e.g. a
/// photo whose values overflow when summed) stops the recovery at once with an error naming the
/// group and the iteration: nothing is checkpointed for that iteration, so the last checkpoint
/// stays the state before it. The parameters themselves are always clamped inside their
/// physical bounds ([`GroupParams::clamped`]), so only the error can carry a NaN forward.
pub fn recover_resumable(
    scene: &Scene,
    photo: &Photo,
    mask: &UsableMask,
    opts: &RecoverOptions,
    resume: Option<&Checkpoint>,
    mut log: impl FnMut(&LogLine),
    mut checkpoint: impl FnMut(&Checkpoint),
) -> Result<Recovery, String> {
    let t0 = Instant::now();
    let variant = scene.render.ward_variant;
    let mask = mask.clone();

    let mut states: Vec<GroupState> = scene
        .groups
        .iter()
        .enumerate()
        .map(|(g, grp)| {
            let objs: Vec<_> = grp.objects.iter().map(|&o| &scene.objects[o]).collect();
            if objs.iter().all(|o| o.is_emitter()) {
                GroupState::new(
                    &grp.name,
                    Status::Light,
                    GroupParams::from_material(&objs[0].material),
                )
            } else if grp.fixed {
                GroupState::new(
                    &grp.name,
                    Status::Fixed,
                    GroupParams::from_material(&objs[0].material),
                )
            } else if mask.stats[g].usable == 0 && opts.unseen.enabled {
                // Grey until the first estimate, after global iteration 0 (unseen.rs).
                let mut s = GroupState::new(&grp.name, Status::Default, GroupParams::default());
                s.note = Some(format!(
                    "no usable pixels ({} visible): ρd estimated from the light it reflects",
                    mask.stats[g].visible
                ));
                s
            } else if mask.stats[g].usable == 0 {
                let mut s = GroupState::new(
                    &grp.name,
                    Status::Default,
                    GroupParams {
                        rho_d: Rgb::splat(opts.default_rho_d),
                        ..Default::default()
                    },
                );
                s.note = Some(format!(
                    "no usable pixels ({} visible): given the default diffuse reflectance {}",
                    mask.stats[g].visible, opts.default_rho_d
                ));
                tracing::warn!("group '{}': {}", grp.name, s.note.as_ref().unwrap());
                s
            } else {
                GroupState::new(&grp.name, Status::Analysing, GroupParams::default())
            }
        })
        .collect();

    let (mut iterations, mut cache_builds, mut evals) = (0u32, 0u32, 0u64);
    // Whether the previous iteration left the scene nearly unchanged (see `GroupState::step`).
    let mut settled = false;
    let mut start = 0;
    // Time before this call: that of the interrupted run, when resuming.
    let mut elapsed_before = 0.0;
    let mut unseen_history = super::unseen::History::default();
    if let Some(c) = resume {
        elapsed_before = c.elapsed;
        // A checkpoint is the run's own, but it was read from disk: refuse, rather than carry
        // on with, parameters a fit could not have produced.
        if let Some(s) = c
            .states
            .iter()
            .find(|s| s.is_fitted() && (!s.params.in_bounds() || !s.error.is_finite()))
        {
            return Err(format!(
                "cannot resume: the checkpoint holds parameters outside their physical bounds \
                 for group '{}' ({:?})",
                s.name, s.params
            ));
        }
        states = c.states.clone();
        unseen_history = c.unseen_history.clone();
        settled = c.settled;
        cache_builds = c.cache_builds;
        evals = c.objective_evals;
        start = c.next_iteration;
        iterations = c.next_iteration;
    }
    let mut current = scene.clone();
    apply(&mut current, &states);
    let photo_px = &photo.image.data;
    let w = scene.camera.width as usize;
    // The pixels of every group's cache at a given pixel budget.
    let choose_all = |cap: usize| -> Vec<_> {
        let cache_opts = CacheOptions {
            max_pixels: cap,
            ..opts.cache.clone()
        };
        (0..scene.groups.len())
            .map(|g| choose_pixels(&mask.pixels_of(g), w, &cache_opts))
            .collect()
    };
    let mut cap = pixel_budget(opts, start);
    let mut pixel_lists = choose_all(cap);

    let pb = progress_bar(opts.max_iterations as u64, "recover", opts.progress);
    pb.inc(start as u64);
    let mut finished = resume.is_some_and(|c| c.next_iteration >= opts.max_iterations);
    let mut unseen = Vec::new();
    for it in start..opts.max_iterations {
        if finished {
            break;
        }
        let budget = pixel_budget(opts, it);
        if budget != cap {
            cap = budget;
            pixel_lists = choose_all(cap);
        }
        let levels_before: Vec<_> = states.iter().map(|s| s.level).collect();
        iterations = it + 1;
        let before: Vec<GroupParams> = states.iter().map(|s| s.params).collect();
        // Groups try higher levels only once the previous iteration changed no level and moved
        // no parameter much; at most one moves per iteration: the one furthest above its
        // threshold.
        let climber = if settled {
            (0..states.len())
                .filter_map(|g| states[g].climb_priority(&opts.hierarchy).map(|p| (g, p)))
                .max_by(|a, b| a.1.total_cmp(&b.1))
                .map(|(g, _)| g)
        } else {
            None
        };
        for g in 0..states.len() {
            if !states[g].is_fitted() {
                continue;
            }
            let tg = Instant::now();
            let (px, tiles, n_tiles) = &pixel_lists[g];
            // Gauss–Seidel: each group's cache sees the groups fitted before it in this
            // iteration with their new parameters (`apply` below), not last iteration's.
            let pt = PathTracer::new(&current);
            let cache = build(
                &current,
                &pt,
                g,
                px,
                tiles,
                *n_tiles,
                photo_px,
                states[g].cache_needs(settled),
                &opts.cache,
                hash_seed(&[opts.seed, it as u64, g as u64]),
            );
            cache_builds += 1;
            let events = states[g].step(
                &cache,
                variant,
                &opts.hierarchy,
                settled,
                climber == Some(g),
            );
            let secs = tg.elapsed().as_secs_f64();
            for e in events {
                if let Event::Fit { evals: n, .. } = e {
                    evals += n as u64;
                }
                log(&LogLine {
                    iteration: it,
                    group: states[g].name.clone(),
                    params: states[g]
                        .params
                        .named(states[g].level)
                        .into_iter()
                        .collect(),
                    event: e,
                    seconds: secs,
                    elapsed: elapsed_before + t0.elapsed().as_secs_f64(),
                });
            }
            if let Some(what) = states[g].non_finite() {
                return Err(format!(
                    "group '{}': the fit diverged in global iteration {it} ({what}); recovery \
                     stopped{}. Check the photo for extreme values and the scene for \
                     degenerate geometry near this group",
                    states[g].name,
                    if it > 0 {
                        format!(", the checkpoint of iteration {} is intact", it - 1)
                    } else {
                        String::new()
                    }
                ));
            }
            apply(&mut current, &states);
        }
        // Hook (issue 26): unseen groups' ρd re-estimated against the refitted seen groups.
        let (estimates, unseen_moved) = super::unseen::update(
            &mut current,
            &mut states,
            photo,
            &mask,
            &opts.unseen,
            &mut unseen_history,
            hash_seed(&[opts.seed, it as u64, u64::MAX]),
        );
        unseen = estimates;
        pb.inc(1);
        let moved = states
            .iter()
            .zip(&before)
            .filter(|(s, _)| s.is_fitted())
            .map(|(s, b)| {
                let dr = (s.params.rho_d - b.rho_d)
                    .abs()
                    .max_element()
                    .max((s.params.rho_s - b.rho_s).abs().max_element());
                let da = ((s.params.alpha_x - b.alpha_x) / b.alpha_x)
                    .abs()
                    .max(((s.params.alpha_y - b.alpha_y) / b.alpha_y).abs());
                if s.level.is_ward() {
                    dr.max(da)
                } else {
                    dr
                }
            })
            .fold(unseen_moved, f32::max);
        let level_changed = states
            .iter()
            .zip(&levels_before)
            .any(|(s, l)| s.level != *l);
        if level_changed {
            // Fits made before a group changed its model saw a different scene: start every
            // group's average afresh.
            for s in states.iter_mut() {
                s.average = None;
            }
        }
        settled = !level_changed && moved < opts.settle;
        let all_confirmed = states.iter().all(|s| {
            s.status != Status::Analysing
                && (s.status != Status::Confirmed
                    || s.average.is_some_and(|a| a.1 >= opts.min_average))
        });
        finished = all_confirmed && moved < opts.tolerance && cap >= opts.cache.max_pixels;
        checkpoint(&Checkpoint {
            version: CHECKPOINT_VERSION,
            fingerprint: 0,
            // A finished run resumes straight to its final render.
            next_iteration: if finished {
                opts.max_iterations
            } else {
                it + 1
            },
            states: states.clone(),
            settled,
            cache_builds,
            objective_evals: evals,
            log_bytes: 0,
            elapsed: elapsed_before + t0.elapsed().as_secs_f64(),
            unseen_history: unseen_history.clone(),
        });
    }
    pb.finish_and_clear();

    // The final render, as two half-sample images with different seeds: their mean is the
    // synthetic image, their difference the noise floor.
    let tf = Instant::now();
    let half = (opts.final_spp / 2).max(1);
    let a = render(
        &current,
        &current.camera,
        &RenderOptions {
            spp: half,
            seed: hash_seed(&[opts.seed, 101]),
            progress: opts.progress,
        },
    );
    let b = render(
        &current,
        &current.camera,
        &RenderOptions {
            spp: half,
            seed: hash_seed(&[opts.seed, 202]),
            progress: opts.progress,
        },
    );
    let final_render_s = tf.elapsed().as_secs_f64();
    let mut synthetic = a.clone();
    for (s, bb) in synthetic.data.iter_mut().zip(&b.data) {
        *s = 0.5 * (*s + *bb);
    }
    let final_error = (0..states.len())
        .map(|g| image_error(&mask, g, &synthetic, &a, &b, &photo.image))
        .collect();
    Ok(Recovery {
        groups: states,
        pixel_stats: mask.stats.clone(),
        unseen,
        scene: current,
        synthetic,
        final_error,
        mask,
        iterations,
        cache_builds,
        objective_evals: evals,
        total_s: t0.elapsed().as_secs_f64(),
        final_render_s,
    })
}

/// ε of group `g` between a rendered image and the photo over its usable pixels, aggregated
/// over 4×4-pixel tiles (as on the cache), and the noise floor from the two half renders.
pub fn image_error(
    mask: &UsableMask,
    g: usize,
    syn: &Image,
    a: &Image,
    b: &Image,
    photo: &Image,
) -> Option<(f32, f32)> {
    use std::collections::BTreeMap;
    let mut tiles: BTreeMap<(usize, usize), [Rgb; 4]> = BTreeMap::new();
    for (i, &grp) in mask.group.iter().enumerate() {
        if grp != g as i32 {
            continue;
        }
        let key = ((i / mask.width) / 4, (i % mask.width) / 4);
        let t = tiles.entry(key).or_insert([Rgb::ZERO; 4]);
        t[0] += syn.data[i];
        t[1] += photo.data[i];
        t[2] += a.data[i];
        t[3] += b.data[i];
    }
    let sum = |c: Rgb| c.x + c.y + c.z;
    let total: f32 = tiles.values().map(|t| sum(t[1])).sum();
    if tiles.is_empty() || !(total > 0.0) {
        return None;
    }
    let e: f32 = tiles.values().map(|t| sum((t[0] - t[1]).abs())).sum();
    let n: f32 = tiles.values().map(|t| sum((t[2] - t[3]).abs())).sum();
    Some((e / total, 0.5 * n / total))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fit::cache::{CacheOptions, CachePixel, GroupCache};
    use crate::fit::hierarchy::HierarchyOptions;
    use crate::fit::level::Level;
    use crate::photo::usable_pixels;
    use crate::render::aov::index_buffers;
    use crate::scene::WardVariant;

    const SCENE: &str = r#"
[camera]
width = 32
height = 24
eye = [0.0, 2.0, 2.0]
target = [0.0, 0.0, 0.0]
fov_y_deg = 45.0

[[object]]
name = "floor"
group = "floor"
shape = "quad"
corner = [-1.0, 0.0, 1.0]
edge_u = [2.0, 0.0, 0.0]
edge_v = [0.0, 0.0, -2.0]

[[object]]
name = "lamp"
group = "lamp"
shape = "quad"
corner = [-0.2, 1.5, -0.2]
edge_u = [0.4, 0.0, 0.0]
edge_v = [0.0, 0.0, 0.4]
emission = 5.0
"#;

    /// A photo whose values are finite (so valid) but overflow f32 once summed over a tile:
    /// every fit's ε is NaN. The recovery must stop at once naming the group, write no
    /// checkpoint for the iteration, and never hand out non-finite parameters.
    #[test]
    fn a_diverging_fit_stops_the_recovery_naming_the_group() {
        let scene =
            crate::scene::load::parse_scene(SCENE, std::path::Path::new("t/scene.toml")).unwrap();
        let (w, h) = (32, 24);
        let photo = Photo::from_linear(Image {
            width: w,
            height: h,
            data: vec![Rgb::splat(f32::MAX); w * h],
        });
        let mask = usable_pixels(
            &index_buffers(&scene, &scene.camera),
            &photo,
            scene.groups.len(),
            &Default::default(),
        );
        assert!(mask.stats[0].usable > 0);
        let opts = RecoverOptions {
            progress: false,
            max_iterations: 4,
            final_spp: 2,
            cache: CacheOptions {
                light_samples: 4,
                indirect_samples: 4,
                max_pixels: 64,
                ..Default::default()
            },
            ..Default::default()
        };
        let (mut checkpoints, mut logged) = (0, 0);
        let e = recover_resumable(
            &scene,
            &photo,
            &mask,
            &opts,
            None,
            |_| logged += 1,
            |_| checkpoints += 1,
        )
        .err()
        .expect("the recovery must fail");
        assert!(e.contains("group 'floor'") && e.contains("diverged"), "{e}");
        assert!(e.contains("iteration 0") && e.contains("ε"), "{e}");
        assert_eq!(checkpoints, 0, "no checkpoint of the diverged iteration");
        assert!(logged > 0, "the diverged fit is logged");
    }

    /// Every level fitted to a cache holding NaN and infinite values keeps its parameters in
    /// their physical bounds (0 ≤ ρd, ρs; ρd + ρs ≤ 1; α in [ALPHA_MIN, ALPHA_MAX]), and the
    /// group reports the non-finite error rather than hiding it.
    #[test]
    fn fits_on_poisoned_caches_stay_in_bounds_and_report_non_finite_errors() {
        use crate::fit::cache::Sample;
        use crate::fit::params::{ALPHA_MAX, ALPHA_MIN};
        use crate::math::Vec3;
        let good = |i: u32, photo: Rgb| CachePixel {
            pixel: i,
            photo,
            d: Rgb::splat(0.4),
            d_half: [Rgb::splat(0.4); 2],
            mirror: Rgb::splat(0.2),
            mirror_half: [Rgb::splat(0.2); 2],
            start: 2 * i,
            mid: 2 * i + 1,
            end: 2 * i + 2,
            tile: i % 4,
        };
        let sample = Sample::new(
            Vec3::new(0.1, 0.2, 0.97).normalize(),
            Vec3::new(-0.1, -0.2, 0.97).normalize(),
            Rgb::splat(0.5),
        );
        for poison in [f32::NAN, f32::INFINITY, f32::MAX] {
            let mut pixels: Vec<CachePixel> = (0..16).map(|i| good(i, Rgb::splat(0.25))).collect();
            pixels[3].photo = Rgb::new(poison, 0.2, 0.2);
            pixels[5].d_half[1] = Rgb::splat(poison);
            pixels[7].mirror = Rgb::splat(poison);
            let cache = GroupCache {
                pixels,
                samples: vec![sample; 32],
                tiles: 4,
                stray: 0,
            };
            let mut any_bad = false;
            for level in Level::FITTED {
                let mut st = GroupState::new("g", Status::Analysing, GroupParams::default());
                st.level = level;
                st.step(
                    &cache,
                    WardVariant::Ward1992,
                    &HierarchyOptions::default(),
                    true,
                    true,
                );
                let p = st.params;
                assert!(p.in_bounds(), "{poison} {level:?}: {p:?}");
                for c in 0..3 {
                    assert!(
                        p.rho_d[c] >= 0.0 && p.rho_s[c] >= 0.0,
                        "{poison} {level:?}: {p:?}"
                    );
                    assert!(
                        p.rho_d[c] + p.rho_s[c] <= 1.0 + 1e-6,
                        "{poison} {level:?}: {p:?}"
                    );
                }
                assert!(
                    (ALPHA_MIN..=ALPHA_MAX).contains(&p.alpha_x)
                        && (ALPHA_MIN..=ALPHA_MAX).contains(&p.alpha_y)
                        && p.theta.is_finite(),
                    "{poison} {level:?}: {p:?}"
                );
                any_bad |= st.non_finite().is_some();
            }
            assert!(
                any_bad || poison.is_finite(),
                "{poison}: a poisoned cache must show as a non-finite error"
            );
        }
    }
}
