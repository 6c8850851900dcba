//! The recovery's entry points and what they take and give: [`RecoverOptions`], the log's
//! [`LogLine`], the [`Recovery`]; [`recover`] and [`recover_resumable`] run a
//! [`RecoveryLoop`](super::recovery::RecoveryLoop) to the end.

use super::cache::CacheOptions;
pub use super::checkpoint::{fingerprint, Checkpoint, CHECKPOINT_VERSION};
use super::event::Event;
use super::group::GroupState;
use super::level::HierarchyOptions;
use super::params::GroupParams;
use super::recovery::RecoveryLoop;
use crate::io::image::Image;
use crate::math::Rgb;
use crate::photo::{GroupPixelStats, Photo, UsableMask};
use crate::render::film::progress_bar;
use crate::scene::Scene;
use serde::{Deserialize, Serialize};

/// Why a recovery stopped without a result.
#[derive(Debug, thiserror::Error)]
pub enum RecoverError {
    /// A fit's error or parameters were not finite (NaN or infinite values reached it).
    #[error(
        "group '{group}': the fit diverged in global iteration {iteration} ({what}); recovery \
         stopped{}. Check the photo for extreme values and the scene for degenerate geometry \
         near this group",
        intact_checkpoint(.iteration)
    )]
    Diverged {
        group: String,
        iteration: u32,
        /// What was not finite, with the values.
        what: String,
    },
    /// The checkpoint to resume from holds parameters no fit could have produced.
    #[error(
        "cannot resume: the checkpoint holds parameters outside their physical bounds for group \
         '{group}' ({params:?})"
    )]
    ImplausibleCheckpoint { group: String, params: GroupParams },
}

/// The note of a divergence message on the last good checkpoint.
fn intact_checkpoint(iteration: &u32) -> String {
    if *iteration > 0 {
        format!(", the checkpoint of iteration {} is intact", iteration - 1)
    } else {
        String::new()
    }
}

/// For callers that report errors as text (the command line).
impl From<RecoverError> for String {
    fn from(e: RecoverError) -> String {
        e.to_string()
    }
}

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
    /// §5.1 of the notes (`pseudo.rs`): a mirror is also fitted with the groups it reflects
    /// that are still being analysed read from the photo, and the better hypothesis is used.
    #[serde(default = "yes")]
    pub pseudo_textures: bool,
    /// Issue 25: a textured group is also fitted from its image in the confirmed ideal mirrors
    /// (`recovery.rs`, `cache::Primary::Mirror`).
    #[serde(default = "yes")]
    pub mirror_views: bool,
    /// Issue 23: fit a stray light (a constant environment, `Scene::stray_light`) with the
    /// materials, as one more unknown of the unseen groups' joint fit (`unseen.rs`).
    #[serde(default)]
    pub stray_light: bool,
    /// Samples per pixel of the final render (None: [`auto_final_spp`]).
    pub final_spp: Option<u32>,
    pub seed: u64,
    pub progress: bool,
    /// The grey card the first photo's exposure was calibrated from, if any. The calibration
    /// renders the card before any material is known; the loop renders it again with the
    /// refitted materials after every global iteration and rescales the photo to match.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub grey_card: Option<GreyCard>,
}

/// A group of known diffuse reflectance in the photo (`--grey-card GROUP=ρ`).
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct GreyCard {
    pub group: String,
    pub rho: Rgb,
}

fn yes() -> bool {
    true
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
            pseudo_textures: true,
            mirror_views: true,
            stray_light: false,
            final_spp: None,
            seed: 0,
            progress: true,
            grey_card: None,
        }
    }
}

/// Samples per pixel of the final render when none is asked for: 64 up to 2^19 pixels (960×540
/// and below); above, the same 2^25 samples spread over the image, but at least 16. Its error's
/// tiles grow as the spp falls (`error::block_side`), so 1920×1080 at 16 spp has as many tiles
/// as 960×540 at 64, each holding as many samples: its ε is as certain for a quarter of the
/// render. The synthetic image itself is noisier per pixel; `--final-spp` asks for more.
pub fn auto_final_spp(pixels: usize) -> u32 {
    let spp = (1u64 << 25) / pixels.max(1) as u64;
    spp.clamp(16, 64) as u32 & !1
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
    /// The distribution of the parameters' lobe at levels 8–10.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub distribution: Option<&'static str>,
    /// Time spent on this group in this iteration (cache build and fits).
    pub seconds: f64,
    /// Seconds since the recovery started when the line was written (across a resume: the
    /// interrupted run's time up to its checkpoint plus the resumed run's), so that the
    /// parameters can be plotted against time (`bench/compare.py`).
    pub elapsed: f64,
}

/// Everything a recovery produced.
pub struct Recovery {
    pub groups: Vec<GroupState>,
    pub pixel_stats: Vec<GroupPixelStats>,
    /// The unseen groups' estimates after the last global iteration (empty without such groups).
    pub unseen: Vec<super::unseen::UnseenEstimate>,
    /// The stray light's estimate after the last global iteration (`stray_light` on).
    pub stray_light: Option<super::stray::StrayEstimate>,
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
    /// The fitting's share of `total_s`: everything before the final render.
    pub fit_s: f64,
    pub final_render_s: f64,
    /// The final render's samples per pixel, and the side in pixels of its error's tiles
    /// (`error::block_side`).
    pub final_spp: u32,
    pub error_tile: usize,
    /// Per photo (the first included) when several were fitted together; else empty.
    pub views: Vec<ViewFit>,
    /// The first photo's exposure factor against the recovered scene, relative to the exposure
    /// already divided out of it: photo = factor × the recovered scene's radiance. 1 for one
    /// photo unless a grey card recalibrated it (`RecoverOptions::grey_card`).
    pub exposure_factor: f32,
}

/// A further photo of the scene, fitted together with the first (`scene::view`, `fit/views.rs`).
pub struct PhotoView<'a> {
    pub name: String,
    /// The scene as this photo's view sees it (its camera registered to the photo, its lights).
    pub scene: &'a Scene,
    pub photo: &'a Photo,
    pub mask: &'a UsableMask,
}

/// What the fit made of each photo when several were fitted together.
#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct ViewFit {
    pub name: String,
    /// The fitted factor k of photo = k × the recovered scene's radiance (their geometric mean
    /// is 1: the materials' scale is the photos' consensus).
    pub exposure: f32,
    /// Σ|photo/k − model| / Σ photo/k over the photo's cached pixels of the uniform groups, in
    /// the last iteration: how well the one set of materials explains this photo.
    pub residual: f32,
    /// Cached pixels of the photo in the last iteration.
    pub pixels: usize,
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
    use crate::fit::group::Status;
    use crate::fit::level::HierarchyOptions;
    use crate::fit::level::Level;
    use crate::math::Rgb;
    use crate::photo::usable_pixels;
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
                    },
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
