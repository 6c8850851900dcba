//! The parameter registry: every fitted parameter with its name, bounds and the levels that
//! use it. The fitter, the log, results.json and the exporters all read parameters through
//! [`GroupParams::named`] rather than knowing the fields (after Mitsuba 3's `traverse`).

use super::level::Level;
use crate::math::Rgb;
use crate::scene::Material;
use serde::{Deserialize, Serialize};

/// Lower and upper bounds of the Ward roughness.
pub const ALPHA_MIN: f32 = 0.005;
pub const ALPHA_MAX: f32 = 1.0;

/// One registered parameter.
pub struct ParamInfo {
    pub name: &'static str,
    pub min: f32,
    pub max: f32,
    /// Levels whose model has this parameter free.
    pub levels: &'static [Level],
}

pub const REGISTRY: [ParamInfo; 5] = [
    ParamInfo {
        name: "rho_d",
        min: 0.0,
        max: 1.0,
        levels: &[
            Level::Diffuse,
            Level::DiffuseSpecular,
            Level::Isotropic,
            Level::Anisotropic,
        ],
    },
    ParamInfo {
        name: "rho_s",
        min: 0.0,
        max: 1.0,
        levels: &[
            Level::Specular,
            Level::DiffuseSpecular,
            Level::Isotropic,
            Level::Anisotropic,
        ],
    },
    ParamInfo {
        name: "alpha_x",
        min: ALPHA_MIN,
        max: ALPHA_MAX,
        levels: &[Level::Isotropic, Level::Anisotropic],
    },
    ParamInfo {
        name: "alpha_y",
        min: ALPHA_MIN,
        max: ALPHA_MAX,
        levels: &[Level::Anisotropic],
    },
    ParamInfo {
        name: "theta_deg",
        min: -90.0,
        max: 90.0,
        levels: &[Level::Anisotropic],
    },
];

/// The reflectance parameters of one group. Which of them mean anything depends on the level.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct GroupParams {
    pub rho_d: Rgb,
    pub rho_s: Rgb,
    pub alpha_x: f32,
    pub alpha_y: f32,
    /// Radians.
    pub theta: f32,
}

impl Default for GroupParams {
    fn default() -> Self {
        GroupParams {
            rho_d: Rgb::splat(0.5),
            rho_s: Rgb::ZERO,
            alpha_x: 0.1,
            alpha_y: 0.1,
            theta: 0.0,
        }
    }
}

/// A parameter's value: a colour or a number.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
#[serde(untagged)]
pub enum Value {
    Rgb([f32; 3]),
    Scalar(f32),
}

impl GroupParams {
    /// The free parameters of `level`, by registry name (θ in degrees).
    pub fn named(&self, level: Level) -> Vec<(&'static str, Value)> {
        REGISTRY
            .iter()
            .filter(|p| p.levels.contains(&level))
            .map(|p| {
                let v = match p.name {
                    "rho_d" => Value::Rgb(self.rho_d.to_array()),
                    "rho_s" => Value::Rgb(self.rho_s.to_array()),
                    "alpha_x" => Value::Scalar(self.alpha_x),
                    "alpha_y" => Value::Scalar(self.alpha_y),
                    _ => Value::Scalar(self.theta.to_degrees()),
                };
                (p.name, v)
            })
            .collect()
    }

    /// The parameters equivalent to a scene material (θ in radians; α left at the default where
    /// the material has no lobe).
    pub fn from_material(m: &Material) -> GroupParams {
        let mut p = GroupParams {
            rho_d: m.rho_d(),
            rho_s: m.rho_s(),
            ..Default::default()
        };
        if let Material::Ward {
            alpha_x,
            alpha_y,
            theta,
            ..
        } = m
        {
            p.alpha_x = *alpha_x;
            p.alpha_y = *alpha_y;
            p.theta = *theta;
        }
        p
    }

    /// The material a group at `level` with these parameters has.
    pub fn material(&self, level: Level) -> Material {
        match level {
            Level::Diffuse | Level::Textured => Material::Diffuse { rho_d: self.rho_d },
            Level::PerfectSpecular => Material::Mirror { rho_s: Rgb::ONE },
            Level::Specular => Material::Mirror { rho_s: self.rho_s },
            Level::DiffuseSpecular => Material::DiffuseMirror {
                rho_d: self.rho_d,
                rho_s: self.rho_s,
            },
            Level::Isotropic => Material::Ward {
                rho_d: self.rho_d,
                rho_s: self.rho_s,
                alpha_x: self.alpha_x,
                alpha_y: self.alpha_x,
                theta: 0.0,
            },
            Level::Anisotropic => Material::Ward {
                rho_d: self.rho_d,
                rho_s: self.rho_s,
                alpha_x: self.alpha_x,
                alpha_y: self.alpha_y,
                theta: self.theta,
            },
        }
    }

    /// Brings the parameters inside their physical bounds: 0 ≤ ρd, ρs; ρd + ρs ≤ 1 per channel;
    /// α in [ALPHA_MIN, ALPHA_MAX]; θ in (−90°, 90°]. NaNs become the bounds' safe values.
    pub fn clamped(mut self) -> GroupParams {
        let fix = |v: f32| {
            if v.is_finite() {
                v.clamp(0.0, 1.0)
            } else {
                0.0
            }
        };
        self.rho_d = Rgb::new(fix(self.rho_d.x), fix(self.rho_d.y), fix(self.rho_d.z));
        self.rho_s = Rgb::new(fix(self.rho_s.x), fix(self.rho_s.y), fix(self.rho_s.z));
        for c in 0..3 {
            let sum = self.rho_d[c] + self.rho_s[c];
            if sum > 1.0 {
                self.rho_d[c] /= sum;
                self.rho_s[c] /= sum;
            }
        }
        let fa = |a: f32| {
            if a.is_finite() {
                a.clamp(ALPHA_MIN, ALPHA_MAX)
            } else {
                0.1
            }
        };
        self.alpha_x = fa(self.alpha_x);
        self.alpha_y = fa(self.alpha_y);
        if !self.theta.is_finite() {
            self.theta = 0.0;
        }
        self
    }

    /// Whether the parameters are inside the bounds [`GroupParams::clamped`] enforces (with a
    /// rounding slack of 1e-5 on ρd + ρs ≤ 1), all finite.
    pub fn in_bounds(&self) -> bool {
        let unit = |v: f32| (0.0..=1.0).contains(&v);
        (0..3).all(|c| {
            unit(self.rho_d[c])
                && unit(self.rho_s[c])
                && self.rho_d[c] + self.rho_s[c] <= 1.0 + 1e-5
        }) && (ALPHA_MIN..=ALPHA_MAX).contains(&self.alpha_x)
            && (ALPHA_MIN..=ALPHA_MAX).contains(&self.alpha_y)
            && self.theta.is_finite()
    }

    /// The canonical form of an anisotropic lobe: (αx, αy, θ) and (αy, αx, θ + 90°) are the
    /// same BRDF, and θ is defined modulo 180°. The canonical θ lies in (−45°, 45°].
    pub fn canonical(mut self) -> GroupParams {
        use std::f32::consts::{FRAC_PI_2, FRAC_PI_4, PI};
        let mut t = (self.theta + FRAC_PI_2).rem_euclid(PI) - FRAC_PI_2; // (−90°, 90°]
        if t > FRAC_PI_4 {
            t -= FRAC_PI_2;
            std::mem::swap(&mut self.alpha_x, &mut self.alpha_y);
        } else if t <= -FRAC_PI_4 {
            t += FRAC_PI_2;
            std::mem::swap(&mut self.alpha_x, &mut self.alpha_y);
        }
        self.theta = t;
        self
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn clamping_keeps_physical_bounds_and_canonical_form_is_the_same_lobe() {
        let p = GroupParams {
            rho_d: Rgb::new(0.8, f32::NAN, -0.2),
            rho_s: Rgb::new(0.6, 0.1, 0.3),
            alpha_x: 0.0,
            alpha_y: f32::INFINITY,
            theta: f32::NAN,
        }
        .clamped();
        for c in 0..3 {
            assert!(
                p.rho_d[c] >= 0.0 && p.rho_s[c] >= 0.0 && p.rho_d[c] + p.rho_s[c] <= 1.0 + 1e-6
            );
        }
        assert!(p.alpha_x >= ALPHA_MIN && p.alpha_y <= ALPHA_MAX && p.theta == 0.0);
        assert!(p.in_bounds() && GroupParams::default().in_bounds());
        let over = GroupParams {
            rho_d: Rgb::new(0.7, 0.1, 0.1),
            rho_s: Rgb::new(0.4, 0.1, 0.1),
            ..Default::default()
        };
        assert!(!over.in_bounds() && over.clamped().in_bounds());
        assert!(!GroupParams {
            alpha_x: 0.0,
            ..Default::default()
        }
        .in_bounds());
        let q = GroupParams {
            alpha_x: 0.11,
            alpha_y: 0.07,
            theta: 91f32.to_radians(),
            ..p
        }
        .canonical();
        assert!((q.alpha_x - 0.07).abs() < 1e-6 && (q.alpha_y - 0.11).abs() < 1e-6);
        assert!(
            (q.theta.to_degrees() - 1.0).abs() < 1e-3,
            "{}",
            q.theta.to_degrees()
        );
    }
}
