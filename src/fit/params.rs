//! The parameter registry: one row per fitted parameter with its name, bounds, scale, the
//! levels whose model has it free, and its accessor (after Mitsuba 3's `traverse`). Clamping,
//! the bounds check, the solver's bounds for the lobe shape, the convergence test
//! ([`largest_move`]), the averaging of independent fits, the log, results.json and the report
//! read parameters through these rows rather than knowing the fields: a new parameter is a field
//! of [`GroupParams`] and a row of [`REGISTRY`].

use super::level::Level;
use crate::math::Rgb;
use crate::scene::{Distribution, Material};
use serde::{Deserialize, Serialize};

/// Lower and upper bounds of the lobes' roughness (Ward and microfacet).
pub const ALPHA_MIN: f32 = 0.005;
pub const ALPHA_MAX: f32 = 1.0;

/// How a parameter is fitted and compared: its own value, or its logarithm (a scale parameter
/// such as roughness, whose changes are relative).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Scale {
    Linear,
    Log,
}

/// One registered parameter.
pub struct ParamInfo {
    /// Its key in the log, results.json and the report.
    pub name: &'static str,
    /// Bounds of every channel, in fitting units (radians for angles).
    pub min: f32,
    pub max: f32,
    /// Where a non-finite value is reset to by clamping.
    pub fallback: f32,
    pub scale: Scale,
    /// Levels whose model has this parameter free.
    pub levels: &'static [Level],
    /// Whether its change between global iterations counts in the convergence test.
    pub watched: bool,
    /// Its channels (three for a colour, one for a number), in fitting units.
    pub get: fn(&GroupParams) -> &[f32],
    pub get_mut: fn(&mut GroupParams) -> &mut [f32],
    /// Fitting units to the units it is reported in.
    pub shown: fn(f32) -> f32,
}

impl ParamInfo {
    /// The bounds in the units the solver works in (the logarithm for [`Scale::Log`]).
    pub fn solver_bounds(&self) -> (f64, f64) {
        match self.scale {
            Scale::Linear => (self.min as f64, self.max as f64),
            Scale::Log => ((self.min as f64).ln(), (self.max as f64).ln()),
        }
    }

    /// Whether `level`'s model has this parameter free.
    pub fn free_at(&self, level: Level) -> bool {
        self.levels.contains(&level)
    }

    /// A channel value brought inside the bounds, or the fallback if it is not finite.
    pub fn clamp(&self, v: f32) -> f32 {
        if v.is_finite() {
            v.clamp(self.min, self.max)
        } else {
            self.fallback
        }
    }

    /// Whether a channel value is finite and inside the bounds.
    pub fn contains(&self, v: f32) -> bool {
        v.is_finite() && (self.min..=self.max).contains(&v)
    }
}

fn same(v: f32) -> f32 {
    v
}

/// The levels with a glossy lobe: their ρd, ρs and α are free.
const LOBE_LEVELS: &[Level] = &[
    Level::Isotropic,
    Level::Anisotropic,
    Level::Microfacet,
    Level::AnisotropicMicrofacet,
    Level::Plastic,
];

pub const REGISTRY: [ParamInfo; 5] = [
    ParamInfo {
        name: "rho_d",
        min: 0.0,
        max: 1.0,
        fallback: 0.0,
        scale: Scale::Linear,
        levels: &[
            Level::Diffuse,
            Level::DiffuseSpecular,
            Level::Isotropic,
            Level::Anisotropic,
            Level::Microfacet,
            Level::AnisotropicMicrofacet,
            Level::Plastic,
        ],
        watched: true,
        get: |p| p.rho_d.as_ref(),
        get_mut: |p| p.rho_d.as_mut(),
        shown: same,
    },
    ParamInfo {
        name: "rho_s",
        min: 0.0,
        max: 1.0,
        fallback: 0.0,
        scale: Scale::Linear,
        levels: &[
            Level::Specular,
            Level::DiffuseSpecular,
            Level::Isotropic,
            Level::Anisotropic,
            Level::Microfacet,
            Level::AnisotropicMicrofacet,
            Level::Plastic,
        ],
        watched: true,
        get: |p| p.rho_s.as_ref(),
        get_mut: |p| p.rho_s.as_mut(),
        shown: same,
    },
    ParamInfo {
        name: "alpha_x",
        min: ALPHA_MIN,
        max: ALPHA_MAX,
        fallback: 0.1,
        scale: Scale::Log,
        levels: LOBE_LEVELS,
        watched: true,
        get: |p| std::slice::from_ref(&p.alpha_x),
        get_mut: |p| std::slice::from_mut(&mut p.alpha_x),
        shown: same,
    },
    ParamInfo {
        name: "alpha_y",
        min: ALPHA_MIN,
        max: ALPHA_MAX,
        fallback: 0.1,
        scale: Scale::Log,
        levels: &[Level::Anisotropic, Level::AnisotropicMicrofacet],
        watched: true,
        get: |p| std::slice::from_ref(&p.alpha_y),
        get_mut: |p| std::slice::from_mut(&mut p.alpha_y),
        shown: same,
    },
    // Any angle: `GroupParams::canonical` folds it into (−45°, 45°]. Not watched: a nearly
    // isotropic lobe leaves it free to wander without changing the image.
    ParamInfo {
        name: "theta_deg",
        min: f32::NEG_INFINITY,
        max: f32::INFINITY,
        fallback: 0.0,
        scale: Scale::Linear,
        levels: &[Level::Anisotropic, Level::AnisotropicMicrofacet],
        watched: false,
        get: |p| std::slice::from_ref(&p.theta),
        get_mut: |p| std::slice::from_mut(&mut p.theta),
        shown: f32::to_degrees,
    },
];

/// The registry row named `name`.
pub fn param(name: &str) -> &'static ParamInfo {
    REGISTRY
        .iter()
        .find(|p| p.name == name)
        .expect("a registered parameter")
}

/// The largest change of a watched parameter free at the level, over groups and channels,
/// between `before` and `after`: absolute for a linear parameter, relative for a logarithmic
/// one. `params` pairs each group's level with its parameters after and before.
pub fn largest_move<'a>(
    params: impl IntoIterator<Item = (Level, &'a GroupParams, &'a GroupParams)>,
) -> f32 {
    let mut moved = 0.0f32;
    for (level, after, before) in params {
        for row in REGISTRY.iter().filter(|r| r.watched && r.free_at(level)) {
            for (a, b) in (row.get)(after).iter().zip((row.get)(before)) {
                let d = match row.scale {
                    Scale::Linear => (a - b).abs(),
                    Scale::Log => ((a - b) / b).abs(),
                };
                moved = moved.max(d);
            }
        }
    }
    moved
}

/// The reflectance parameters of one group. Which of them mean anything depends on the level.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct GroupParams {
    pub rho_d: Rgb,
    pub rho_s: Rgb,
    pub alpha_x: f32,
    pub alpha_y: f32,
    /// Radians.
    pub theta: f32,
    /// The microfacet levels' distribution (GGX elsewhere).
    #[serde(default)]
    pub distribution: Distribution,
}

impl Default for GroupParams {
    fn default() -> Self {
        GroupParams {
            rho_d: Rgb::splat(0.5),
            rho_s: Rgb::ZERO,
            alpha_x: 0.1,
            alpha_y: 0.1,
            theta: 0.0,
            distribution: Distribution::Ggx,
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
    /// The free parameters of `level`, by registry name, in the units they are reported in.
    pub fn named(&self, level: Level) -> Vec<(&'static str, Value)> {
        REGISTRY
            .iter()
            .filter(|p| p.free_at(level))
            .map(|p| {
                let v = match (p.get)(self) {
                    &[r, g, b] => Value::Rgb([(p.shown)(r), (p.shown)(g), (p.shown)(b)]),
                    channels => Value::Scalar((p.shown)(channels[0])),
                };
                (p.name, v)
            })
            .collect()
    }

    /// The running sums of [`GroupParams::add_to_mean`] before the first fit.
    pub fn zero_sums() -> GroupParams {
        GroupParams {
            rho_d: Rgb::ZERO,
            rho_s: Rgb::ZERO,
            alpha_x: 0.0,
            alpha_y: 0.0,
            theta: 0.0,
            distribution: Distribution::Ggx,
        }
    }

    /// Adds these parameters, with weight `weight`, to the weighted running `sums` (each
    /// parameter on its scale: roughness in the log domain, as it is fitted), and returns the
    /// mean of the sums over the total weight `total` (this weight included), clamped at
    /// `level`.
    pub fn add_to_mean(
        &self,
        sums: &mut GroupParams,
        weight: f32,
        total: f32,
        level: Level,
    ) -> GroupParams {
        sums.distribution = self.distribution;
        for row in &REGISTRY {
            let sum = (row.get_mut)(sums);
            for (s, &v) in sum.iter_mut().zip((row.get)(self)) {
                *s += match row.scale {
                    Scale::Linear => v * weight,
                    Scale::Log => v.ln() * weight,
                };
            }
        }
        sums.mean_of_sums(total, level)
    }

    /// Adds the squares of these parameters (on the scales of [`GroupParams::add_to_mean`]),
    /// with weight `weight`, to the running `squares`.
    pub fn add_squares(&self, squares: &mut GroupParams, weight: f32) {
        for row in &REGISTRY {
            let sum = (row.get_mut)(squares);
            for (s, &v) in sum.iter_mut().zip((row.get)(self)) {
                let x = match row.scale {
                    Scale::Linear => v,
                    Scale::Log => v.ln(),
                };
                *s += x * x * weight;
            }
        }
    }

    /// The scatter (standard deviation) of single fits about their weighted mean, from the
    /// running `sums` and `squares` of total weight `total`, in the parameters' own units
    /// (roughness: its mean times the scatter of ln α). `self` is the mean.
    pub fn scatter(&self, sums: &GroupParams, squares: &GroupParams, total: f32) -> GroupParams {
        let mut out = GroupParams::zero_sums();
        for row in &REGISTRY {
            let (s, q, m) = ((row.get)(sums), (row.get)(squares), (row.get)(self));
            for (k, o) in (row.get_mut)(&mut out).iter_mut().enumerate() {
                let mean = s[k] / total;
                let sd = (q[k] / total - mean * mean).max(0.0).sqrt();
                *o = match row.scale {
                    Scale::Linear => sd,
                    Scale::Log => m[k] * sd,
                };
            }
        }
        out
    }

    /// The mean of these running sums ([`GroupParams::add_to_mean`]) of total weight `total`,
    /// clamped at `level`.
    pub fn mean_of_sums(&self, total: f32, level: Level) -> GroupParams {
        let mut mean = *self;
        for row in &REGISTRY {
            for (m, &s) in (row.get_mut)(&mut mean).iter_mut().zip((row.get)(self)) {
                *m = match row.scale {
                    Scale::Linear => s / total,
                    Scale::Log => (s / total).exp(),
                };
            }
        }
        mean.clamped(level)
    }

    /// The parameters equivalent to a scene material (θ in radians; α left at the default where
    /// the material has no lobe).
    pub fn from_material(m: &Material) -> GroupParams {
        let mut p = GroupParams {
            rho_d: m.rho_d(),
            rho_s: m.rho_s(),
            ..Default::default()
        };
        let lobe = match m {
            Material::Ward {
                alpha_x,
                alpha_y,
                theta,
                ..
            }
            | Material::Microfacet {
                alpha_x,
                alpha_y,
                theta,
                ..
            } => Some((*alpha_x, *alpha_y, *theta)),
            Material::Textured {
                varnish: Some(v), ..
            } => Some((v.alpha_x, v.alpha_y, v.theta)),
            Material::Plastic { alpha, .. } | Material::TexturedPlastic { alpha, .. } => {
                Some((*alpha, *alpha, 0.0))
            }
            _ => None,
        };
        if let Some((ax, ay, theta)) = lobe {
            p.alpha_x = ax;
            p.alpha_y = ay;
            p.theta = theta;
        }
        if let Material::Microfacet { distribution, .. } = m {
            p.distribution = *distribution;
        }
        p
    }

    /// Level 7's material: the texture, with the lobe of the texture's `base` level on top (a
    /// varnish when the base is a Ward level, none when it is diffuse).
    pub fn textured(
        &self,
        texture: std::sync::Arc<crate::scene::texture::Texture>,
        base: Level,
    ) -> Material {
        let varnish = match base {
            Level::Isotropic => Some((self.alpha_x, self.alpha_x, 0.0)),
            Level::Anisotropic => Some((self.alpha_x, self.alpha_y, self.theta)),
            _ => None,
        };
        Material::Textured {
            texture,
            scale: Rgb::ONE,
            varnish: varnish.map(|(alpha_x, alpha_y, theta)| crate::scene::Varnish {
                rho_s: self.rho_s,
                alpha_x,
                alpha_y,
                theta,
            }),
        }
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
            Level::Microfacet => Material::Microfacet {
                rho_d: self.rho_d,
                rho_s: self.rho_s,
                alpha_x: self.alpha_x,
                alpha_y: self.alpha_x,
                theta: 0.0,
                distribution: self.distribution,
            },
            Level::AnisotropicMicrofacet => Material::Microfacet {
                rho_d: self.rho_d,
                rho_s: self.rho_s,
                alpha_x: self.alpha_x,
                alpha_y: self.alpha_y,
                theta: self.theta,
                distribution: self.distribution,
            },
            Level::Plastic => Material::Plastic {
                rho_d: self.rho_d,
                rho_s: self.rho_s,
                alpha: self.alpha_x,
                eta: crate::render::bsdf::plastic::DEFAULT_ETA,
                distribution: self.distribution,
            },
        }
    }

    /// Brings the parameters inside their physical bounds at `level`: every channel inside its
    /// registry row's bounds (a non-finite one to the row's fallback), then the level's bound on
    /// ρd and ρs per channel ([`Level::rho_bound`]).
    pub fn clamped(mut self, level: Level) -> GroupParams {
        for row in &REGISTRY {
            for v in (row.get_mut)(&mut self) {
                *v = row.clamp(*v);
            }
        }
        for c in 0..3 {
            (self.rho_d[c], self.rho_s[c]) = level.rho_bound().clamp(self.rho_d[c], self.rho_s[c]);
        }
        self
    }

    /// Whether the parameters are inside the bounds [`GroupParams::clamped`] enforces at `level`
    /// (with a rounding slack of 1e-5 on the bound on ρd and ρs), all finite.
    pub fn in_bounds(&self, level: Level) -> bool {
        REGISTRY
            .iter()
            .all(|row| (row.get)(self).iter().all(|&v| row.contains(v)))
            && (0..3).all(|c| {
                let reach = level.rho_bound().reach(self.rho_d[c] as f64, self.rho_s[c] as f64);
                reach <= 1.0 + 1e-5
            })
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
            distribution: Distribution::Ggx,
        }
        .clamped(Level::Isotropic);
        for c in 0..3 {
            assert!(
                p.rho_d[c] >= 0.0 && p.rho_s[c] >= 0.0 && p.rho_d[c] + p.rho_s[c] <= 1.0 + 1e-6
            );
        }
        assert!(p.alpha_x >= ALPHA_MIN && p.alpha_y <= ALPHA_MAX && p.theta == 0.0);
        let l = Level::Isotropic;
        assert!(p.in_bounds(l) && GroupParams::default().in_bounds(l));
        let over = GroupParams {
            rho_d: Rgb::new(0.7, 0.1, 0.1),
            rho_s: Rgb::new(0.4, 0.1, 0.1),
            ..Default::default()
        };
        assert!(!over.in_bounds(l) && over.clamped(l).in_bounds(l));
        assert!(!GroupParams {
            alpha_x: 0.0,
            ..Default::default()
        }
        .in_bounds(l));
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

    /// A plastic's base under its coat is bounded alone (ρd 0.9 under ρs 0.3 is a plastic, and
    /// stays as it is), where a lobe beside a diffuse term shares the light with it.
    #[test]
    fn a_plastic_is_bounded_by_each_reflectance_and_the_others_by_their_sum() {
        let p = GroupParams {
            rho_d: Rgb::new(0.9, 0.5, 0.2),
            rho_s: Rgb::splat(0.3),
            ..Default::default()
        };
        assert!(p.in_bounds(Level::Plastic));
        assert_eq!(p.clamped(Level::Plastic), p);
        assert!(!p.in_bounds(Level::Microfacet));
        let q = p.clamped(Level::Microfacet);
        assert!((q.rho_d.x - 0.75).abs() < 1e-6 && (q.rho_s.x - 0.25).abs() < 1e-6, "{q:?}");
        let over = GroupParams {
            rho_d: Rgb::splat(1.2),
            ..p
        };
        assert!(!over.in_bounds(Level::Plastic));
        assert_eq!(over.clamped(Level::Plastic).rho_d, Rgb::ONE);
        // The mean of plastics' fits is clamped as a plastic.
        let mut sums = GroupParams::zero_sums();
        let m = p.add_to_mean(&mut sums, 1.0, 1.0, Level::Plastic);
        assert!((m.rho_d - p.rho_d).abs().max_element() < 1e-6, "{m:?}");
    }

    #[test]
    fn the_registry_averages_moves_and_names_each_parameter_on_its_scale() {
        let a = GroupParams {
            rho_d: Rgb::new(0.2, 0.4, 0.6),
            rho_s: Rgb::splat(0.1),
            alpha_x: 0.04,
            alpha_y: 0.1,
            theta: 0.3,
            distribution: Distribution::Ggx,
        };
        let b = GroupParams {
            rho_d: Rgb::new(0.4, 0.4, 0.2),
            alpha_x: 0.16,
            theta: 0.1,
            ..a
        };
        // Equal weights: ρ and θ arithmetic means, α the geometric mean.
        let mut sums = GroupParams::zero_sums();
        a.add_to_mean(&mut sums, 2.0, 2.0, Level::Isotropic);
        let m = b.add_to_mean(&mut sums, 2.0, 4.0, Level::Isotropic);
        assert!((m.rho_d - Rgb::new(0.3, 0.4, 0.4)).abs().max_element() < 1e-6);
        assert!((m.alpha_x - 0.08).abs() < 1e-6 && (m.alpha_y - 0.1).abs() < 1e-6);
        assert!((m.theta - 0.2).abs() < 1e-6);
        // Moves: ρ absolute (0.4), α relative (3.0) only where the level has a lobe, θ never.
        let moved = |level| largest_move([(level, &b, &a)]);
        assert!((moved(Level::Diffuse) - 0.4).abs() < 1e-6);
        assert!((moved(Level::Isotropic) - 3.0).abs() < 1e-6);
        let turned = GroupParams { theta: 1.0, ..a };
        assert_eq!(largest_move([(Level::Anisotropic, &turned, &a)]), 0.0);
        // Names: the level's free parameters, θ in degrees.
        let names: Vec<_> = a.named(Level::Anisotropic);
        assert_eq!(
            names.iter().map(|n| n.0).collect::<Vec<_>>(),
            ["rho_d", "rho_s", "alpha_x", "alpha_y", "theta_deg"]
        );
        assert_eq!(names[4].1, Value::Scalar(0.3f32.to_degrees()));
        assert_eq!(a.named(Level::Specular).len(), 1);
        assert_eq!(param("alpha_x").solver_bounds().1, 0.0);
    }
}
