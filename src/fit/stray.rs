//! The stray light's estimate (`recover --stray-light`), as the unseen groups' fit
//! (`unseen.rs`) gives it to the log, the checkpoint and the results.

use serde::{Deserialize, Serialize};

/// The stray light's estimate (`recover --stray-light`): a constant environment's radiance,
/// fitted like an unseen group's ρd from the light it adds to the seen groups' tiles (what it
/// adds has its own shape: it fills shadows and is strongest where a surface sees open sky).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct StrayEstimate {
    /// W/(m² sr) per channel, in the scene's units.
    pub radiance: [f32; 3],
    /// 1σ per channel (−1: no estimate from the photo in that channel).
    pub sigma: [f32; 3],
    /// Whether every channel was determined (1σ below `unseen::STRAY_MAX_SHARE` of the seen light);
    /// a channel that never was keeps its given value (0 unless the scene file gives one).
    pub estimated: bool,
    /// The share of the seen pixels' light it makes.
    pub share: f32,
    /// Whether any of its light reaches the seen tiles (false in a closed room).
    #[serde(default)]
    pub open: bool,
}

impl StrayEstimate {
    /// One line for the log and the summary.
    pub fn describe(&self) -> String {
        let [r, g, b] = self.radiance;
        let [sr, sg, sb] = self.sigma;
        let how = if self.estimated {
            format!("1σ ({sr:.1e}, {sg:.1e}, {sb:.1e})")
        } else {
            "not determined by the photo in some channel (kept as given there)".to_string()
        };
        format!(
            "stray light ({r:.4}, {g:.4}, {b:.4}) W/(m² sr), {how}, {:.1}% of the seen light",
            100.0 * self.share
        )
    }
}
