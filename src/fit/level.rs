//! The hierarchy of reflectance models (docs/DESIGN.md, "The hierarchy"): every group starts
//! at level 1 and climbs while its error stays above the level's threshold.

use crate::scene::RhoBound;
use serde::{Deserialize, Serialize};

/// Levels compare in the order the hierarchy climbs them ([`Level::FITTED`]), which for
/// level 8 is not its number.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Level {
    /// 1: Lambert, ρd.
    Diffuse = 1,
    /// 2: ideal mirror with ρs = 1 (a hypothesis test, no free parameter).
    PerfectSpecular = 2,
    /// 3: ideal mirror, ρs.
    Specular = 3,
    /// 4: Lambert + ideal mirror, ρd and ρs.
    DiffuseSpecular = 4,
    /// 5: Lambert + isotropic Ward, ρd, ρs, α.
    Isotropic = 5,
    /// 6: Lambert + anisotropic Ward, ρd, ρs, αx, αy, θ.
    Anisotropic = 6,
    /// 7: a per-texel diffuse map (radiosity texture, §5.2), with the uniform Ward lobe of level
    /// 5 or 6 on top where one earned its place (`fit/texture.rs`).
    Textured = 7,
    /// 8 (beyond the notes): Lambert + an isotropic microfacet lobe, ρd, ρs, α, GGX or Beckmann
    /// (whichever fits better; `render::bsdf::microfacet`): GGX's wide-tailed highlight of most
    /// real glossy surfaces, which no Ward lobe makes, and Beckmann's Gaussian one with Smith's
    /// masking. Tried after the Ward levels and before the texture, the last resort.
    Microfacet = 8,
    /// 10 (beyond the notes): Lambert + an anisotropic microfacet lobe (GGX or Beckmann), ρd,
    /// ρs, αx, αy, θ: brushed metal. Tried right after level 8, as level 6 after level 5.
    AnisotropicMicrofacet = 10,
    /// 9 (beyond the notes): a diffuse base under a rough dielectric coat, ρd, ρs (at normal
    /// incidence), α, GGX or Beckmann as level 8 (`render::bsdf::plastic`): plastics, paint,
    /// lacquer, whose reflection rises towards grazing and whose diffuse light falls off faster
    /// than the cosine.
    Plastic = 9,
}

impl PartialOrd for Level {
    fn partial_cmp(&self, other: &Self) -> Option<std::cmp::Ordering> {
        Some(self.cmp(other))
    }
}

impl Ord for Level {
    fn cmp(&self, other: &Self) -> std::cmp::Ordering {
        self.rank().cmp(&other.rank())
    }
}

impl Level {
    pub const FITTED: [Level; 10] = [
        Level::Diffuse,
        Level::PerfectSpecular,
        Level::Specular,
        Level::DiffuseSpecular,
        Level::Isotropic,
        Level::Anisotropic,
        Level::Microfacet,
        Level::AnisotropicMicrofacet,
        Level::Plastic,
        Level::Textured,
    ];

    /// Its place in the climb ([`Level::FITTED`]).
    fn rank(self) -> usize {
        match self {
            Level::Diffuse => 0,
            Level::PerfectSpecular => 1,
            Level::Specular => 2,
            Level::DiffuseSpecular => 3,
            Level::Isotropic => 4,
            Level::Anisotropic => 5,
            Level::Microfacet => 6,
            Level::AnisotropicMicrofacet => 7,
            Level::Plastic => 8,
            Level::Textured => 9,
        }
    }

    pub fn number(self) -> u8 {
        self as u8
    }

    pub fn name(self) -> &'static str {
        match self {
            Level::Diffuse => "diffuse",
            Level::PerfectSpecular => "perfect_specular",
            Level::Specular => "specular",
            Level::DiffuseSpecular => "diffuse_specular",
            Level::Isotropic => "isotropic",
            Level::Anisotropic => "anisotropic",
            Level::Textured => "textured",
            Level::Microfacet => "microfacet",
            Level::AnisotropicMicrofacet => "anisotropic_microfacet",
            Level::Plastic => "plastic",
        }
    }

    /// The next level of the hierarchy among those the fitter tries.
    pub fn next(self) -> Option<Level> {
        let i = Level::FITTED.iter().position(|&l| l == self)?;
        Level::FITTED.get(i + 1).copied()
    }

    /// Whether the level's specular part is an ideal mirror (as opposed to a Ward lobe).
    pub fn is_mirror(self) -> bool {
        matches!(
            self,
            Level::PerfectSpecular | Level::Specular | Level::DiffuseSpecular
        )
    }

    pub fn is_ward(self) -> bool {
        matches!(self, Level::Isotropic | Level::Anisotropic)
    }

    /// Whether the level's specular part is a glossy lobe (Ward or microfacet) whose shape the
    /// cache's direction pairs determine.
    pub fn has_lobe(self) -> bool {
        self.is_ward() || self.is_microfacet() || self == Level::Plastic
    }

    /// Whether the level is Lambert + a microfacet lobe (8 or 10; not the coated level 9).
    pub fn is_microfacet(self) -> bool {
        matches!(self, Level::Microfacet | Level::AnisotropicMicrofacet)
    }

    /// Whether the level's lobe has a microfacet distribution to choose (8, 9 and 10).
    pub fn has_distribution(self) -> bool {
        self.is_microfacet() || self == Level::Plastic
    }

    /// The bound on the level's ρd and ρs ([`RhoBound`]): the coated level 9's each alone.
    pub fn rho_bound(self) -> RhoBound {
        RhoBound::of(self == Level::Plastic)
    }
}

/// Error thresholds per level: a group whose error falls below its level's threshold is
/// confirmed at that level.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct Thresholds {
    pub diffuse: f32,
    pub perfect_specular: f32,
    pub specular: f32,
    pub diffuse_specular: f32,
    pub isotropic: f32,
    pub anisotropic: f32,
    /// Level 7 confirms below this (a texture is a diffuse model: as level 1). A group reaches
    /// level 7 only when the anisotropic level (or the best lower one) stays above its own
    /// threshold: that is the texture threshold of Algorithm 1.
    #[serde(default = "textured_threshold")]
    pub textured: f32,
    /// As the glossy Ward levels' (levels 8, 9 and 10).
    #[serde(default = "microfacet_threshold")]
    pub microfacet: f32,
    /// The texture threshold of Algorithm 1, on what the error metric cannot see: a group whose
    /// best uniform model leaves texel-scale structure of at least this RMS fraction of its
    /// radiance (`detail.rs`) tries level 7 even when its ε is below its threshold (fine grain
    /// averages out in the error's tiles), and level 7 is tried only for such a group or one
    /// above `texture_error` (a mirror whose ε misses its threshold by noise is not a
    /// texture).
    #[serde(default = "texture_detail")]
    pub texture_detail: f32,
    /// The texture threshold of Algorithm 1 on ε itself: a group whose best uniform model
    /// misses by at least this much tries level 7 whatever its fine detail. Shelves of book
    /// spines, tiles: a texture of large flat patches whose edges the usable-pixel mask removes
    /// leaves no fine detail, only an ε no BRDF can lower.
    /// Far above what a mirror or a glossy lobe leaves when fitted at a neighbouring level.
    #[serde(default = "texture_error")]
    pub texture_error: f32,
}

fn texture_detail() -> f32 {
    0.02
}

fn texture_error() -> f32 {
    0.15
}

fn textured_threshold() -> f32 {
    0.02
}

fn microfacet_threshold() -> f32 {
    0.01
}

impl Default for Thresholds {
    /// 2% for the diffuse and mirror levels, 1% for the glossy ones: the notes' example switches
    /// from isotropic to anisotropic at 1%.
    fn default() -> Self {
        Thresholds {
            diffuse: 0.02,
            perfect_specular: 0.02,
            specular: 0.02,
            diffuse_specular: 0.02,
            isotropic: 0.01,
            anisotropic: 0.01,
            textured: textured_threshold(),
            microfacet: microfacet_threshold(),
            texture_detail: texture_detail(),
            texture_error: texture_error(),
        }
    }
}

impl Thresholds {
    pub fn of(&self, level: Level) -> f32 {
        match level {
            Level::Diffuse => self.diffuse,
            Level::PerfectSpecular => self.perfect_specular,
            Level::Specular => self.specular,
            Level::DiffuseSpecular => self.diffuse_specular,
            Level::Isotropic => self.isotropic,
            Level::Anisotropic => self.anisotropic,
            Level::Textured => self.textured,
            Level::Microfacet | Level::AnisotropicMicrofacet | Level::Plastic => self.microfacet,
        }
    }
}

#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct HierarchyOptions {
    pub thresholds: Thresholds,
    /// A higher level must lower ε by at least this fraction of the current ε...
    pub margin: f32,
    /// ...and by more than this many noise floors.
    pub noise_factor: f32,
    /// Whether levels 8, 9 and 10, the GGX lobes (microfacet, plastic, anisotropic), are tried (off: the
    /// hierarchy of the notes and the Ward lobes alone, for comparison).
    #[serde(default = "yes")]
    pub microfacet: bool,
    /// Whether levels 5 and 6, the Ward lobes, are tried (off: only models with an exact Mitsuba
    /// form, the microfacet lobes standing in from the first glossy level on).
    #[serde(default = "yes")]
    pub ward: bool,
    /// Whether a group whose error its neighbours' stale models cannot explain climbs before
    /// the scene settles (`schedule::gross`).
    #[serde(default = "yes")]
    pub gross_climbs: bool,
}

fn yes() -> bool {
    true
}

impl Default for HierarchyOptions {
    fn default() -> Self {
        HierarchyOptions {
            thresholds: Thresholds::default(),
            margin: 0.15,
            noise_factor: 3.0,
            microfacet: true,
            ward: true,
            gross_climbs: true,
        }
    }
}
