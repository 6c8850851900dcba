//! Lights that are not surfaces: directional (the sun, a lamp far away, a calibrated
//! photometric-stereo rig), point and spot lights. Each is a Dirac delta — in direction or in
//! position — so no ray ever hits one: they light the scene only through next-event estimation
//! (`render::lights`), and a camera never sees them. Their units are the ones a calibration
//! gives: a directional light's irradiance on a surface facing it (W/m² per channel, what a
//! light meter or a photometric-stereo calibration reports), a point or spot light's radiant
//! intensity (W/sr per channel). They mean what Mitsuba 3's `directional`, `point` and `spot`
//! emitters mean, so the export is exact.

use super::schema::{LightKind, LightSpec};
use crate::math::{Rgb, Vec3};

#[derive(Clone, Debug, PartialEq)]
pub struct PunctualLight {
    pub name: String,
    pub kind: Punctual,
    /// Line of the light's entry in the scene file (1-based), for messages.
    pub line: usize,
}

#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Punctual {
    /// Light travelling along `direction` (unit) from a source of angular diameter `angle`
    /// (radians; 0: parallel light, a delta; else a disc of uniform radiance
    /// E / (π sin²(angle/2)), which gives irradiance E on a surface facing it, and soft
    /// shadows).
    Directional {
        direction: Vec3,
        irradiance: Rgb,
        angle: f32,
    },
    /// Light from `position`, the same radiant intensity in every direction.
    Point { position: Vec3, intensity: Rgb },
    /// A point light limited to a cone around `direction` (unit): full intensity within
    /// `beam_width` of the axis, falling linearly in angle to zero at `cutoff` (radians), as
    /// Mitsuba 3's `spot`.
    Spot {
        position: Vec3,
        direction: Vec3,
        intensity: Rgb,
        cutoff: f32,
        beam_width: f32,
    },
}

impl Punctual {
    /// Mitsuba 3's defaults: a 20° cutoff and a beam of three quarters of it.
    pub const DEFAULT_CUTOFF_DEG: f32 = 20.0;

    /// The spot's falloff towards unit direction `d` (from the light), 1 for other lights.
    pub fn falloff(&self, d: Vec3) -> f32 {
        match *self {
            Punctual::Spot {
                direction,
                cutoff,
                beam_width,
                ..
            } => {
                let cos = direction.dot(d);
                if cos <= cutoff.cos() {
                    0.0
                } else if cos >= beam_width.cos() {
                    1.0
                } else {
                    (cutoff - cos.clamp(-1.0, 1.0).acos()) / (cutoff - beam_width)
                }
            }
            _ => 1.0,
        }
    }
}

fn unit(v: [f32; 3], key: &str) -> Result<Vec3, String> {
    let v = Vec3::from(v);
    if !v.is_finite() || v.length_squared() == 0.0 {
        return Err(format!("`{key}` must be a non-zero finite vector, got {v}"));
    }
    Ok(v.normalize())
}

fn point(v: Option<[f32; 3]>, key: &str) -> Result<Vec3, String> {
    let v = Vec3::from(v.ok_or_else(|| format!("needs `{key}`"))?);
    if !v.is_finite() {
        return Err(format!("`{key}` must be finite, got {v}"));
    }
    Ok(v)
}

fn power(c: Option<Rgb>, key: &str) -> Result<Rgb, String> {
    let c = c.ok_or_else(|| format!("needs `{key}` (a number or [r, g, b])"))?;
    if !c.is_finite() || c.min_element() < 0.0 {
        return Err(format!("`{key}` must be finite and non-negative, got {c}"));
    }
    Ok(c)
}

/// The light of a `[[light]]` table, or what is wrong with it (the caller adds the name and
/// line).
pub fn build(spec: &LightSpec) -> Result<Punctual, String> {
    let kind = *spec.kind.get_ref();
    // Keys of another type of light are errors rather than ignored: a `position` on a
    // directional light means the user expected it to matter.
    let given = [
        ("direction", spec.direction.is_some()),
        ("irradiance", spec.irradiance.is_some()),
        ("position", spec.position.is_some()),
        ("target", spec.target.is_some()),
        ("intensity", spec.intensity.is_some()),
        ("cutoff_deg", spec.cutoff_deg.is_some()),
        ("beam_width_deg", spec.beam_width_deg.is_some()),
        ("angle_deg", spec.angle_deg.is_some()),
    ];
    let allowed: &[&str] = match kind {
        LightKind::Directional => &["direction", "irradiance", "angle_deg"],
        LightKind::Point => &["position", "intensity"],
        LightKind::Spot => &[
            "position",
            "direction",
            "target",
            "intensity",
            "cutoff_deg",
            "beam_width_deg",
        ],
    };
    if let Some((k, _)) = given.iter().find(|(k, g)| *g && !allowed.contains(k)) {
        return Err(format!(
            "a {} light takes no `{k}` (its keys: {})",
            kind_name(kind),
            allowed.join(", ")
        ));
    }
    let rgb = |c: &Option<super::schema::Color>| c.map(|c| Rgb::from(c.0));
    Ok(match kind {
        LightKind::Directional => Punctual::Directional {
            direction: unit(
                spec.direction
                    .ok_or("needs `direction` (the way the light travels)")?,
                "direction",
            )?,
            irradiance: power(rgb(&spec.irradiance), "irradiance")?,
            angle: match spec.angle_deg.unwrap_or(0.0) {
                a if (0.0..=45.0).contains(&a) => a.to_radians(),
                a => return Err(format!("`angle_deg` must be in [0, 45], got {a}")),
            },
        },
        LightKind::Point => Punctual::Point {
            position: point(spec.position, "position")?,
            intensity: power(rgb(&spec.intensity), "intensity")?,
        },
        LightKind::Spot => {
            let position = point(spec.position, "position")?;
            let direction = match (spec.direction, spec.target) {
                (Some(d), None) => unit(d, "direction")?,
                (None, Some(t)) => {
                    unit((Vec3::from(t) - position).to_array(), "target − position")?
                }
                _ => return Err("needs either `direction` or `target` (not both)".into()),
            };
            let cutoff = spec.cutoff_deg.unwrap_or(Punctual::DEFAULT_CUTOFF_DEG);
            if !(cutoff > 0.0 && cutoff <= 90.0) {
                return Err(format!("`cutoff_deg` must be in (0, 90], got {cutoff}"));
            }
            let beam = spec.beam_width_deg.unwrap_or(0.75 * cutoff);
            if !(beam > 0.0 && beam < cutoff) {
                return Err(format!(
                    "`beam_width_deg` must be in (0, cutoff_deg = {cutoff}), got {beam}"
                ));
            }
            Punctual::Spot {
                position,
                direction,
                intensity: power(rgb(&spec.intensity), "intensity")?,
                cutoff: cutoff.to_radians(),
                beam_width: beam.to_radians(),
            }
        }
    })
}

pub fn kind_name(kind: LightKind) -> &'static str {
    match kind {
        LightKind::Directional => "directional",
        LightKind::Point => "point",
        LightKind::Spot => "spot",
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use toml::Spanned;

    fn spec(text: &str) -> Result<Punctual, String> {
        #[derive(serde::Deserialize)]
        struct F {
            light: LightSpec,
        }
        let f: F = toml::from_str(&format!("[light]\nname = \"l\"\n{text}")).unwrap();
        let _: &Spanned<String> = &f.light.name;
        build(&f.light)
    }

    #[test]
    fn keys_are_checked_per_type() {
        let d = spec("type = \"directional\"\ndirection = [0, -2, 0]\nirradiance = 3").unwrap();
        assert_eq!(
            d,
            Punctual::Directional {
                direction: Vec3::new(0.0, -1.0, 0.0),
                irradiance: Rgb::splat(3.0),
                angle: 0.0
            }
        );
        let e = spec("type = \"directional\"\nposition = [0, 1, 0]\nirradiance = 3").unwrap_err();
        assert!(e.contains("takes no `position`"), "{e}");
        let e = spec("type = \"point\"\nposition = [0, 1, 0]").unwrap_err();
        assert!(e.contains("needs `intensity`"), "{e}");
        let e = spec("type = \"directional\"\ndirection = [0, 0, 0]\nirradiance = 1").unwrap_err();
        assert!(e.contains("non-zero"), "{e}");
        let e = spec("type = \"spot\"\nposition = [0, 1, 0]\ntarget = [0, 0, 0]\nintensity = 1\ncutoff_deg = 10\nbeam_width_deg = 12").unwrap_err();
        assert!(e.contains("beam_width_deg"), "{e}");
    }

    #[test]
    fn spot_falloff_is_mitsubas() {
        let s = spec("type = \"spot\"\nposition = [0, 1, 0]\ntarget = [0, 0, 0]\nintensity = 1")
            .unwrap();
        let at = |deg: f32| {
            let r = deg.to_radians();
            s.falloff(Vec3::new(r.sin(), -r.cos(), 0.0))
        };
        // Defaults: cutoff 20°, beam 15°; linear in angle between.
        assert_eq!(at(0.0), 1.0);
        assert_eq!(at(14.9), 1.0);
        assert!((at(17.5) - 0.5).abs() < 1e-3, "{}", at(17.5));
        assert_eq!(at(20.5), 0.0);
    }
}
