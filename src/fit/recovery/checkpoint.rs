//! Checkpoints: the state of a recovery after a global iteration, enough to continue it exactly
//! (the caches' seeds derive from the iteration number, so a resumed run draws the same samples
//! and ends with the same result as an uninterrupted one).

use super::options::RecoverOptions;
use crate::fit::group::GroupState;
use crate::math::sampler::{hash_seed, mix64};
use crate::photo::Photo;
use crate::prepare::UsableMask;
use serde::{Deserialize, Serialize};

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
    pub unseen_history: crate::fit::unseen::History,
    /// Each photo's fitted exposure factor (several photos only; `fit/views.rs`).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub exposures: Vec<f32>,
    /// The stray light's last estimate (`recover --stray-light`; None without it).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub stray_light: Option<crate::fit::stray::StrayEstimate>,
}

pub const CHECKPOINT_VERSION: u32 = 2;

impl Checkpoint {
    /// The first fitted group whose state no fit could have produced (parameters outside their
    /// physical bounds, or a non-finite error), if any: a checkpoint is the run's own, but it
    /// was read from disk.
    pub fn implausible_group(&self) -> Option<&GroupState> {
        self.states
            .iter()
            .find(|s| s.is_fitted() && (!s.params.in_bounds(s.level) || !s.error.is_finite()))
    }
}

/// A hash identifying a run: scene text, photo pixels, mask and options.
pub fn fingerprint(
    scene_text: &str,
    photo: &Photo,
    mask: &UsableMask,
    opts: &RecoverOptions,
) -> u64 {
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
