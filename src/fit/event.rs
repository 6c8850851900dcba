//! What happened to a group in one global iteration: one [`Event`] per fit, level tried,
//! decision and hypothesis, written to `log.jsonl` and read back by the report.

use super::level::Level;
use serde::Serialize;

/// What happened to a group in one global iteration.
#[derive(Clone, Debug, Serialize, PartialEq)]
#[serde(tag = "event", rename_all = "snake_case")]
pub enum Event {
    /// The current level was fitted.
    Fit {
        level: Level,
        error: f32,
        noise_floor: f32,
        evals: u32,
    },
    /// A higher level was tried on the same cache.
    Tried {
        level: Level,
        error_before: f32,
        error_after: f32,
        noise_floor: f32,
        gain_noise: f32,
        /// ε of the lower and of the tried level on held-back pixels (each fitted on the other
        /// half of the group's tiles), when the in-sample gain earned a look at them.
        #[serde(skip_serializing_if = "Option::is_none")]
        held_out: Option<[f32; 2]>,
        kept: bool,
        /// How many caches the test pooled: this one and the earlier climbs' at the group's
        /// level (`evidence.rs`; the texture's trials, for level 7).
        caches: u32,
        /// Seconds spent fitting and judging this level on the cache (the log line's `seconds`
        /// is the group's whole turn: its cache build and every fit).
        #[serde(default)]
        fit_seconds: f32,
    },
    /// No level above the current one earned its place on the caches of the group's climbs
    /// so far, fewer than [`crate::fit::evidence::CONFIRMING_CLIMBS`]: it climbs again on the
    /// next cache, pooled with these, before it is confirmed.
    Inconclusive { level: Level, caches: u32 },
    /// The group moved to a new level.
    Moved { from: Level, to: Level },
    /// A higher level earned its place, but another group moves first this iteration.
    Deferred { to: Level },
    /// The run ended while the group was still analysing: it is confirmed at the best level
    /// it had found, and `reason` says why it had not decided earlier.
    Decided {
        level: Level,
        error: f32,
        reason: String,
    },
    /// The group's parameters still move by more than the settle tolerance, but no longer
    /// converge (their steps stopped shrinking): they move within their own noise and no
    /// longer hold the other groups back from climbing.
    Jitter { moved: f32 },
    /// The group's parameters moved by more than the settle tolerance, and clearly less than
    /// ever before at the level: they still converge, and the other groups wait for them
    /// before they try higher levels (`schedule::settled`).
    Converging { moved: f32 },
    /// The group's level is decided.
    Confirmed {
        level: Level,
        error: f32,
        below_threshold: bool,
    },
    /// A simpler level explained this cache as well as the confirmed one: the group keeps its
    /// level and its mean of earlier fits (this cache's fit does not join it), and is demoted
    /// if the next cache says the same ([`GroupState::doubted`]). For a textured group
    /// re-asked Algorithm 1's gate: its best uniform level passed the gate on this cache; it
    /// keeps its texture and is asked again on the next ([`GroupState::texture_doubt`]).
    Doubted {
        level: Level,
        lower: Level,
        error: f32,
        error_lower: f32,
    },
    /// A simpler level explains the photo as well as the current one on two caches in a row:
    /// the group goes back to it (the current level no longer earns its place).
    Demoted {
        from: Level,
        to: Level,
        error_before: f32,
        error_after: f32,
    },
    /// The level's fit on this cache ended above the simpler level `from`'s, which it contains
    /// ([`restart_from_nested`]): it was fitted again from `from`'s optimum, or the group's
    /// previous answer at the level explained the cache better (`previous_kept`).
    Restarted {
        level: Level,
        from: Level,
        error_before: f32,
        error_after: f32,
        previous_kept: bool,
    },
    /// Algorithm 1's gate held on the group's best uniform level, but level 7 was not tried:
    /// `behind`, which lights the group, is still analysing (`schedule::texture_waits_for`), or
    /// is the stray light, not yet determined (`recover --stray-light`). The group stays
    /// analysing at that level and climbs again later.
    TextureWaits {
        behind: String,
        level: Level,
        error: f32,
    },
    /// The textured group's smoothness weight was chosen by cross-validation
    /// (`texture::choose_smoothing`): the weight, and per weight tried its held-out error
    /// relative to the chosen one's.
    Smoothing {
        weight: f32,
        choices: Vec<f32>,
        held_out: Vec<f32>,
    },
    /// A textured group re-asked Algorithm 1's gate ([`GroupState::untexture`]) keeps its
    /// texture: its best uniform level, with that level's ε, noise floor and coherent detail.
    TextureKept {
        level: Level,
        error: f32,
        noise_floor: f32,
        detail: f32,
    },
    /// Algorithm 1's gate on the group's best uniform level, asked when its climb reaches level
    /// 7: `open` (it tries a texture) when its ε missed by the texture threshold beyond the
    /// noise (`gross`), or its residual holds texel-scale structure (`detail.rs`: RMS fraction
    /// `detail`, z-score `z`, and the share of the high-passed residual that registration and
    /// highlight misfit explained). Logged closed too: why a group kept a uniform model.
    TextureGate {
        open: bool,
        level: Level,
        gross: bool,
        detail: f32,
        z: f32,
        explained: f32,
    },
    /// A confirmed group's uniform level leaves texel-scale structure that only a texture
    /// explains (`detail.rs`): RMS fraction `detail`, z-score `z`, and the share of the
    /// high-passed residual that registration and highlight misfit explained. It analyses
    /// again, so its next climb tries level 7.
    Reopened {
        level: Level,
        detail: f32,
        z: f32,
        explained: f32,
    },
    /// §5.1 (`pseudo.rs`): the group's mirror level fitted with the groups it reflects that are
    /// still being analysed rendered, and read from the photo (pseudo-textures); the one with
    /// the smaller cost (`chose`: "rendered" or "pseudo_texture") is used in this iteration.
    Hypotheses {
        level: Level,
        pseudo_textured: Vec<String>,
        /// Share of the group's mirror samples read from the photo.
        share: f32,
        error_rendered: f32,
        error_pseudo: f32,
        chose: String,
    },
    /// The textured group's image in a confirmed mirror joined its cache (`used`), or
    /// was left out because its level disagreed with the model's by more than
    /// `recovery::MIRROR_SCALE_LIMIT`. `scale`: the factor that brought the photo's image
    /// (divided by the mirror's ρs) to the model's mean over those pixels.
    MirrorView {
        mirror: String,
        pixels: usize,
        scale: [f32; 3],
        used: bool,
    },
    /// The stray light's estimate after the iteration (`recover --stray-light`; its line's
    /// group is "stray_light").
    StrayLight(super::stray::StrayEstimate),
}
