//! The scene file's TOML schema, as serde types. Unknown keys are errors (with the nearest valid
//! key suggested by `load.rs`). Loading turns this into a [`crate::scene::Scene`]; `write.rs`
//! turns a scene back into it.
//!
//! ```toml
//! [render]                      # optional
//! spp = 64
//! max_depth = 8
//! rr_depth = 5                  # Russian roulette from this path segment on (Mitsuba's)
//! seed = 0
//! ward_variant = "ward1992"     # or "balanced"
//!
//! [camera]
//! width = 512
//! height = 384
//! eye = [0, 1, 3]               # look-at form ...
//! target = [0, 1, 0]
//! up = [0, 1, 0]
//! fov_y_deg = 40
//! # fx = 500, fy = 500, cx = 255.5, cy = 191.5      # ... or the calibrated (OpenCV) form:
//! # rotation = [[1,0,0],[0,-1,0],[0,0,-1]]         # world-to-camera R (rows)
//! # translation = [0, 1, 3]                         # world-to-camera t: x_cam = R x + t
//! # distortion = [-0.28, 0.09, 0.001, -0.0008, 0]   # OpenCV's k1, k2, p1, p2, k3 (optional)
//! # fisheye = [0.03, -0.01, 0, 0.001]              # or cv::fisheye's k1..k4
//! # projection = "orthographic"  # parallel rays from a film plane through `eye` (or the
//! # width_m = 2.5                # calibrated form's centre); the film's width in scene units
//! #                              # replaces fov_y_deg; calibrated: fx, fy in px per scene unit
//!
//! [[group]]                     # optional: groups named by objects exist anyway
//! name = "floor"
//! fixed = false
//!
//! [[object]]
//! name = "floor"
//! group = "floor"
//! shape = "quad"                # quad | box | sphere | mesh
//! corner = [-1, 0, 1]
//! edge_u = [2, 0, 0]
//! edge_v = [0, 0, -2]           # surfaces reflect on both sides; only an emitter has a front
//! tangent = [1, 0, 0]           # optional reference axis of the anisotropy angle
//! material = { type = "ward", rho_d = 0.1, rho_s = 0.9, alpha_x = 0.07, alpha_y = 0.11, theta_deg = 0 }
//! # or a microfacet lobe with the same keys (Mitsuba's roughconductor, material "none"), GGX
//! # unless distribution = "beckmann":
//! # material = { type = "microfacet", rho_d = 0.1, rho_s = 0.8, alpha = 0.2 }
//! # or a coated diffuse base (Mitsuba's roughplastic; rho_s at normal incidence, eta 1.49):
//! # material = { type = "plastic", rho_d = [0.7, 0.05, 0.05], rho_s = 0.039, alpha = 0.1 }
//! # emission = [10, 10, 10]     # makes the object an area light (front side, along edge_u × edge_v)
//!
//! [[object]]
//! name = "ball"
//! group = "ball"
//! shape = "sphere"
//! center = [0, 0.5, 0]
//! radius = 0.5
//! segments = 64                 # optional: triangles around (8-1024), half as many pole to pole
//! # a texture over the mesh's UVs (or `mapping = "atlas"`, `texel_size = 0.01`: the group's
//! # chart atlas, as `recover` writes it), optionally varnished with a uniform Ward lobe:
//! # material = { type = "textured", texture = "desk.png", rho_s = 0.06, alpha = 0.12 }
//!
//! [[light]]                     # lights that are not surfaces (`scene::light`)
//! name = "sun"
//! type = "directional"          # directional | point | spot
//! direction = [0.3, -1, -0.2]   # the way the light travels
//! irradiance = [3, 2.9, 2.6]    # W/m² per channel on a surface facing the light
//! angle_deg = 0.53              # optional: the source's angular diameter (soft shadows)
//! # type = "point": position = [0, 2, 0], intensity = 5 (W/sr per channel)
//! # type = "spot": position, target (or direction), intensity, cutoff_deg = 20,
//! #   beam_width_deg = 15 (full intensity inside, falling linearly in angle to 0 at the cutoff)
//!
//! [environment]                 # an HDR light probe, equirectangular (`scene::environment`)
//! file = "sky.exr"
//! scale = 1.0
//! rotate_deg = [0, 90, 0]       # about X, then Y, then Z
//!
//! [stray_light]                 # a constant environment: what every ray leaving the scene sees
//! radiance = [0.02, 0.02, 0.02] # W/(m² sr) per channel; `recover --stray-light` fits it
//! ```

use crate::scene::Distribution;
use serde::{Deserialize, Serialize};
use toml::Spanned;

#[derive(Clone, Debug, Deserialize, Serialize, Default)]
#[serde(deny_unknown_fields)]
pub struct SceneFile {
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub render: Option<RenderSpec>,
    pub camera: CameraSpec,
    #[serde(default, rename = "group", skip_serializing_if = "Vec::is_empty")]
    pub groups: Vec<GroupSpec>,
    #[serde(default, rename = "object")]
    pub objects: Vec<ObjectSpec>,
    #[serde(default, rename = "light", skip_serializing_if = "Vec::is_empty")]
    pub lights: Vec<LightSpec>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub environment: Option<Spanned<EnvironmentSpec>>,
    /// Light from outside the model that no light of the scene explains (`[stray_light]`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub stray_light: Option<Spanned<StrayLightSpec>>,
    /// The photos' views when several photos are fitted together (`scene::view`).
    #[serde(default, rename = "view", skip_serializing_if = "Vec::is_empty")]
    pub views: Vec<Spanned<ViewSpec>>,
}

/// One photo's view (`scene::view`): its camera and which of the scene's lights are on.
#[derive(Clone, Debug, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct ViewSpec {
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub name: Option<String>,
    /// A camera in either form; width and height default to `[camera]`'s. Absent: `[camera]`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub camera: Option<toml::Table>,
    /// The lights on (names of [[light]]s, of emitting objects or groups, or "environment").
    /// Absent: all of them.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub lights: Option<Vec<String>>,
}

/// An environment light (`scene::environment`): an equirectangular HDR light probe.
#[derive(Clone, Debug, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct EnvironmentSpec {
    /// EXR, HDR or PFM (linear radiance); an 8/16-bit image is read as sRGB.
    pub file: String,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub scale: Option<f32>,
    /// Rotation of the map into the scene, degrees about X, then Y, then Z (as a transform's).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rotate_deg: Option<[f32; 3]>,
}

/// Stray light (`Scene::stray_light`): a constant environment of this radiance, unoccluded
/// everywhere a ray leaves the scene, lighting shadows that no modelled light reaches.
#[derive(Clone, Debug, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct StrayLightSpec {
    pub radiance: [f32; 3],
}

#[derive(Clone, Debug, Deserialize, Serialize, Default, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct RenderSpec {
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub spp: Option<u32>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_depth: Option<u32>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rr_depth: Option<u32>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub seed: Option<u64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ward_variant: Option<crate::scene::WardVariant>,
}

#[derive(Clone, Debug, Deserialize, Serialize, Default, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct CameraSpec {
    pub width: u32,
    pub height: u32,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub eye: Option<[f32; 3]>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub target: Option<[f32; 3]>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub up: Option<[f32; 3]>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub fov_y_deg: Option<f32>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub fx: Option<f32>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub fy: Option<f32>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cx: Option<f32>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cy: Option<f32>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rotation: Option<[[f32; 3]; 3]>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub translation: Option<[f32; 3]>,
    /// OpenCV lens distortion (k1, k2, p1, p2, k3), in either form.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub distortion: Option<[f32; 5]>,
    /// Or OpenCV's fisheye model (k1, k2, k3, k4).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub fisheye: Option<[f32; 4]>,
    /// Perspective (the default) or orthographic.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub projection: Option<ProjectionKind>,
    /// An orthographic look-at camera's film width in scene units (its height from the aspect).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub width_m: Option<f32>,
}

#[derive(Clone, Copy, Debug, Deserialize, Serialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum ProjectionKind {
    Perspective,
    Orthographic,
}

#[derive(Clone, Debug, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct GroupSpec {
    pub name: Spanned<String>,
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub fixed: bool,
}

#[derive(Clone, Debug, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct ObjectSpec {
    pub name: Spanned<String>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub group: Option<Spanned<String>>,
    pub shape: Spanned<ShapeKind>,
    // quad
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub corner: Option<[f32; 3]>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub edge_u: Option<[f32; 3]>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub edge_v: Option<[f32; 3]>,
    // box
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub min: Option<[f32; 3]>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max: Option<[f32; 3]>,
    // sphere
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub center: Option<[f32; 3]>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub radius: Option<f32>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub segments: Option<u32>,
    // mesh
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub file: Option<Spanned<String>>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub transform: Option<TransformSpec>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub tangent: Option<[f32; 3]>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub material: Option<Spanned<MaterialSpec>>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub emission: Option<Spanned<Color>>,
}

/// A light that is not a surface (`scene::light`): which keys each type takes is checked by
/// `load.rs`, so that a missing or stray key is named with the light.
#[derive(Clone, Debug, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct LightSpec {
    pub name: Spanned<String>,
    #[serde(rename = "type")]
    pub kind: Spanned<LightKind>,
    /// directional: the way the light travels; spot: the beam's axis (or give `target`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub direction: Option<[f32; 3]>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub irradiance: Option<Color>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub position: Option<[f32; 3]>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub target: Option<[f32; 3]>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub intensity: Option<Color>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cutoff_deg: Option<f32>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub beam_width_deg: Option<f32>,
    /// directional: the source's angular diameter (the sun: 0.53°); 0 or absent: a delta.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub angle_deg: Option<f32>,
}

#[derive(Clone, Copy, Debug, Deserialize, Serialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum LightKind {
    Directional,
    Point,
    Spot,
}

#[derive(Clone, Copy, Debug, Deserialize, Serialize, PartialEq, Eq)]
#[serde(rename_all = "snake_case")]
pub enum ShapeKind {
    Quad,
    Box,
    Sphere,
    Mesh,
}

/// Applied in the order scale, rotate (X then Y then Z, degrees), translate.
#[derive(Clone, Debug, Deserialize, Serialize, Default, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct TransformSpec {
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub scale: Option<Color>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rotate_deg: Option<[f32; 3]>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub translate: Option<[f32; 3]>,
}

/// An RGB triple, written either as one number (grey) or as `[r, g, b]`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
#[serde(into = "ColorOut")]
pub struct Color(pub [f32; 3]);

#[derive(Serialize)]
#[serde(untagged)]
enum ColorOut {
    Grey(f32),
    Rgb([f32; 3]),
}

impl From<Color> for ColorOut {
    fn from(c: Color) -> ColorOut {
        let [r, g, b] = c.0;
        if r == g && g == b {
            ColorOut::Grey(r)
        } else {
            ColorOut::Rgb(c.0)
        }
    }
}

impl<'de> Deserialize<'de> for Color {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Color, D::Error> {
        struct V;
        impl<'de> serde::de::Visitor<'de> for V {
            type Value = Color;
            fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
                write!(f, "a number or an array of three numbers [r, g, b]")
            }
            fn visit_f64<E: serde::de::Error>(self, v: f64) -> Result<Color, E> {
                Ok(Color([v as f32; 3]))
            }
            fn visit_i64<E: serde::de::Error>(self, v: i64) -> Result<Color, E> {
                Ok(Color([v as f32; 3]))
            }
            fn visit_seq<A: serde::de::SeqAccess<'de>>(self, mut s: A) -> Result<Color, A::Error> {
                let mut c = [0.0f32; 3];
                for (i, slot) in c.iter_mut().enumerate() {
                    *slot = s
                        .next_element::<f32>()?
                        .ok_or_else(|| serde::de::Error::invalid_length(i, &self))?;
                }
                if s.next_element::<f32>()?.is_some() {
                    return Err(serde::de::Error::invalid_length(4, &self));
                }
                Ok(Color(c))
            }
        }
        d.deserialize_any(V)
    }
}

#[derive(Clone, Debug, Deserialize, Serialize, PartialEq)]
#[serde(tag = "type", rename_all = "snake_case", deny_unknown_fields)]
pub enum MaterialSpec {
    Diffuse {
        rho_d: Color,
    },
    Mirror {
        rho_s: Color,
    },
    DiffuseMirror {
        rho_d: Color,
        rho_s: Color,
    },
    Ward {
        #[serde(default = "zero_color")]
        rho_d: Color,
        rho_s: Color,
        #[serde(default, skip_serializing_if = "Option::is_none")]
        alpha: Option<f32>,
        #[serde(default, skip_serializing_if = "Option::is_none")]
        alpha_x: Option<f32>,
        #[serde(default, skip_serializing_if = "Option::is_none")]
        alpha_y: Option<f32>,
        #[serde(default, skip_serializing_if = "Option::is_none")]
        theta_deg: Option<f32>,
    },
    /// Lambert + a microfacet lobe (Mitsuba's `roughconductor`, `material = "none"`): the keys
    /// of a ward material, and `distribution` ("ggx", the default, or "beckmann").
    Microfacet {
        #[serde(default = "zero_color")]
        rho_d: Color,
        rho_s: Color,
        #[serde(default, skip_serializing_if = "Option::is_none")]
        alpha: Option<f32>,
        #[serde(default, skip_serializing_if = "Option::is_none")]
        alpha_x: Option<f32>,
        #[serde(default, skip_serializing_if = "Option::is_none")]
        alpha_y: Option<f32>,
        #[serde(default, skip_serializing_if = "Option::is_none")]
        theta_deg: Option<f32>,
        #[serde(default, skip_serializing_if = "is_ggx")]
        distribution: Distribution,
    },
    /// A diffuse base under a rough dielectric coat (Mitsuba's `roughplastic`): `rho_d`,
    /// `rho_s` (the coat's reflectance at normal incidence), `alpha`, optional `eta` (1.49) and
    /// `distribution` ("ggx", the default, or "beckmann").
    Plastic {
        rho_d: Color,
        rho_s: Color,
        alpha: f32,
        #[serde(default, skip_serializing_if = "Option::is_none")]
        eta: Option<f32>,
        #[serde(default, skip_serializing_if = "is_ggx")]
        distribution: Distribution,
    },
    Textured {
        texture: String,
        #[serde(default, skip_serializing_if = "Option::is_none")]
        scale: Option<Color>,
        /// "uv" (the mesh's UVs, the default) or "atlas": the group's chart atlas
        /// (`scene/atlas.rs`), rebuilt from the geometry at `texel_size` world units per texel.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        mapping: Option<String>,
        #[serde(default, skip_serializing_if = "Option::is_none")]
        texel_size: Option<f32>,
        /// An optional uniform Ward lobe on top of the texture (a varnish): `rho_s` with
        /// `alpha` or `alpha_x`/`alpha_y`/`theta_deg`, as in a ward material.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        rho_s: Option<Color>,
        #[serde(default, skip_serializing_if = "Option::is_none")]
        alpha: Option<f32>,
        #[serde(default, skip_serializing_if = "Option::is_none")]
        alpha_x: Option<f32>,
        #[serde(default, skip_serializing_if = "Option::is_none")]
        alpha_y: Option<f32>,
        #[serde(default, skip_serializing_if = "Option::is_none")]
        theta_deg: Option<f32>,
        /// With `eta`, the lobe is a rough dielectric coat instead, as in a plastic material:
        /// `rho_s` (the coat's reflectance at normal incidence), `alpha`, `eta` and
        /// `distribution` ("ggx", the default, or "beckmann").
        #[serde(default, skip_serializing_if = "Option::is_none")]
        eta: Option<f32>,
        #[serde(default, skip_serializing_if = "Option::is_none")]
        distribution: Option<Distribution>,
    },
    Black,
}

fn is_ggx(d: &Distribution) -> bool {
    *d == Distribution::Ggx
}

fn zero_color() -> Color {
    Color([0.0; 3])
}
