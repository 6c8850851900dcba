//! What a recovery takes and gives: [`RecoverOptions`], the log's [`LogLine`], the
//! [`Recovery`], and why one stops without a result ([`RecoverError`]).

use crate::fit::cache::CacheOptions;
use crate::fit::event::Event;
use crate::fit::group::GroupState;
use crate::fit::level::HierarchyOptions;
use crate::fit::params::GroupParams;
use crate::io::image::Image;
use crate::math::Rgb;
use crate::photo::Photo;
use crate::prepare::{GroupPixelStats, UsableMask};
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
    /// No group moves to a uniform level in this many last iterations
    /// ([`crate::fit::schedule::CLOSING`]); 0 for the quick fits that shade the model for the
    /// pose's refinement, whose materials are not an answer.
    #[serde(default = "closing")]
    pub closing: u32,
    /// Diffuse reflectance given to groups with no usable pixels when `unseen.enabled` is false
    /// (the notes: white).
    pub default_rho_d: f32,
    /// Groups with no usable pixels: their ρd estimated from the light they reflect
    /// ([`super::unseen`]).
    #[serde(default)]
    pub unseen: crate::fit::unseen::UnseenOptions,
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
    /// A textured group is also fitted from its image in the confirmed ideal mirrors
    /// (`recovery/iterate.rs`, `cache::Primary::Mirror`).
    #[serde(default = "yes")]
    pub mirror_views: bool,
    /// Fit a stray light (a constant environment, `Scene::stray_light`) with the
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

fn closing() -> u32 {
    crate::fit::schedule::CLOSING
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
            closing: closing(),
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
    pub params: std::collections::BTreeMap<&'static str, crate::fit::params::Value>,
    /// The distribution of the parameters' lobe at levels 8–10.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub distribution: Option<&'static str>,
    /// Time spent on this group in this iteration (cache build and fits).
    pub seconds: f64,
    /// Of `seconds`, the time its cache took to build (lines of a group's turn in an
    /// iteration; absent on the others).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub cache_seconds: Option<f64>,
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
    pub unseen: Vec<crate::fit::unseen::UnseenEstimate>,
    /// The stray light's estimate after the last global iteration (`stray_light` on).
    pub stray_light: Option<crate::fit::stray::StrayEstimate>,
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
