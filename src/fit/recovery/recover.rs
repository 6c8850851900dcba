//! The recovery's entry points: [`recover`] and [`recover_resumable`] run a [`RecoveryLoop`]
//! to the end, with a progress bar and a checkpoint after every global iteration.

use super::checkpoint::Checkpoint;
use super::options::{LogLine, PhotoView, RecoverError, RecoverOptions, Recovery};
use super::run::RecoveryLoop;
use crate::fit::event::Event;
use crate::photo::Photo;
use crate::prepare::UsableMask;
use crate::render::film::progress_bar;
use crate::scene::Scene;

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
) -> Result<Recovery, RecoverError> {
    recover_resumable(scene, photo, mask, &[], opts, None, log, |_| {})
}

/// [`recover`], starting from `resume` if given, and handing a [`Checkpoint`] to `checkpoint`
/// after every global iteration (its `fingerprint` and `log_bytes` are the caller's to fill).
///
/// A fit whose error or parameters are not finite (NaN or infinite values reached it, e.g. a
/// photo whose values overflow when summed) stops the recovery at once with an error naming the
/// group and the iteration: nothing is checkpointed for that iteration, so the last checkpoint
/// stays the state before it. The parameters themselves are always clamped inside their
/// physical bounds ([`GroupParams::clamped`]), so only the error can carry a NaN forward.
#[allow(clippy::too_many_arguments)]
pub fn recover_resumable(
    scene: &Scene,
    photo: &Photo,
    mask: &UsableMask,
    views: &[PhotoView],
    opts: &RecoverOptions,
    resume: Option<&Checkpoint>,
    mut log: impl FnMut(&LogLine),
    mut checkpoint: impl FnMut(&Checkpoint),
) -> Result<Recovery, RecoverError> {
    let mut run = match resume {
        Some(c) => RecoveryLoop::resume(scene, photo, mask, views, opts, c)?,
        None => RecoveryLoop::start(scene, photo, mask, views, opts),
    };
    // The bar advances once per group fitted (the iterations grow longer as the cache's pixel
    // budget doubles, so a bar per iteration stalled and then jumped); its message says which
    // iteration of at most how many, since a run that converges stops before the last.
    let fitted = run.fitted_groups().max(1) as u64;
    let pb = progress_bar(
        opts.max_iterations as u64 * fitted,
        "recover",
        opts.progress,
    );
    pb.inc(run.next_iteration() as u64 * fitted);
    while !run.converged() {
        pb.set_message(format!(
            "iteration {}/{}",
            run.next_iteration() + 1,
            opts.max_iterations
        ));
        run.iterate(&mut |l: &LogLine| {
            if matches!(l.event, Event::Fit { .. }) {
                pb.inc(1);
            }
            log(l)
        })?;
        checkpoint(&run.checkpoint());
    }
    run.decide_the_undecided(&mut log);
    pb.finish_and_clear();
    Ok(run.finish())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fit::cache::{CacheOptions, CachePixel, GroupCache};
    use crate::fit::group::GroupState;
    use crate::fit::group::Status;
    use crate::fit::level::HierarchyOptions;
    use crate::fit::level::Level;
    use crate::fit::params::GroupParams;
    use crate::fit::recovery::options::auto_final_spp;
    use crate::io::image::Image;
    use crate::math::Rgb;
    use crate::prepare::usable_pixels;
    use crate::render::aov::index_buffers;
    use crate::scene::WardVariant;

    #[test]
    fn the_final_renders_samples_shrink_with_the_image_to_a_floor() {
        let spp = |w: usize, h: usize| auto_final_spp(w * h);
        assert_eq!((spp(512, 384), spp(960, 540)), (64, 64));
        assert_eq!(
            (spp(1280, 720), spp(1920, 1080), spp(4000, 3000)),
            (36, 16, 16)
        );
        // Between the two bounds the image's samples stay at 2^25 (to the pixel's even spp).
        let n = 1280 * 720;
        assert!((n * spp(1280, 720) as usize).abs_diff(1 << 25) < 2 * n);
        assert_eq!(spp(0, 0), 64);
    }

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
            final_spp: Some(2),
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
            &[],
            &opts,
            None,
            |_| logged += 1,
            |_| checkpoints += 1,
        )
        .err()
        .expect("the recovery must fail");
        assert!(matches!(e, RecoverError::Diverged { iteration: 0, .. }));
        let e = e.to_string();
        assert!(e.contains("group 'floor'") && e.contains("diverged"), "{e}");
        assert!(e.contains("iteration 0") && e.contains("ε"), "{e}");
        assert_eq!(checkpoints, 0, "no checkpoint of the diverged iteration");
        assert!(logged > 0, "the diverged fit is logged");
    }

    /// Every level fitted to a cache holding NaN and infinite values keeps its parameters in
    /// their physical bounds (0 ≤ ρd, ρs; the level's bound on them; α in [ALPHA_MIN,
    /// ALPHA_MAX]), and the group reports the non-finite error rather than hiding it.
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
            normal: Vec3::ZERO,
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
                samples: vec![sample; 32].into(),
                tiles: 4,
                stray: 0,
                texels: None,
                width: 0,
                unseen: None,
                light_from: Vec::new(),
                open: 0.0,
                pseudo: None,
                views: Vec::new(),
            };
            let mut any_bad = false;
            for level in Level::FITTED {
                let mut st = GroupState::new("g", Status::Analysing, GroupParams::default());
                st.level = level;
                st.step(
                    &cache,
                    None,
                    WardVariant::Ward1992,
                    &HierarchyOptions::default(),
                    &crate::fit::schedule::Turn {
                        may_climb: true,
                        may_move: true,
                        texture_waits_for: None,
                        closing: false,
                    },
                );
                let p = st.params;
                assert!(p.in_bounds(st.level), "{poison} {level:?}: {p:?}");
                for c in 0..3 {
                    assert!(
                        p.rho_d[c] >= 0.0 && p.rho_s[c] >= 0.0,
                        "{poison} {level:?}: {p:?}"
                    );
                    let reach = (st.level.rho_bound()).reach(p.rho_d[c] as f64, p.rho_s[c] as f64);
                    assert!(reach <= 1.0 + 1e-6, "{poison} {level:?}: {p:?}");
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
