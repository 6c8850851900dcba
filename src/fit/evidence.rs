//! A climb's evidence pooled over the caches it was tried on.
//!
//! One cache decides a level badly where the photo barely tells two models apart: the gain's
//! noise is measured from the cache's two halves, a one-degree-of-freedom estimate that is as
//! likely to come out half its true size as twice it, and a group that waited for its turn was
//! judged again from scratch, its last cache alone deciding. So each climb keeps every tried
//! level's ε, its halves', its cross-half cost and its held-out ε on that cache ([`Trial`]),
//! and a level is judged against the one kept below it on every recent cache where both were
//! fitted ([`judge`]): the mean gain must clear the margin of the mean ε and `noise_factor`
//! times the mean gain's noise (from the halves of every cache), both halves' mean gains must
//! be positive, and at least half of the in-sample gain must remain on the held-back tiles,
//! summed over the caches. On one cache this is `fitter::lowers_error` and the held-out test as
//! they were. A climb that found a level lowering ε by the margin but not clear of its noise
//! does not confirm the group: it climbs again on a later cache, up to [`CLIMB_TRIALS`] times.

use super::fitter::LevelFit;
use super::level::Level;
use serde::{Deserialize, Serialize};

/// Climbs from one level pooled: a group whose climb found a level that lowered ε by the
/// margin but did not clear its noise is tried again, up to this many climbs in all, before
/// it is confirmed where it is.
pub const CLIMB_TRIALS: usize = 3;

/// One level's fit on one climb's cache.
#[derive(Clone, Copy, Debug, Serialize, Deserialize, PartialEq)]
pub struct Trial {
    pub level: Level,
    pub error: f32,
    pub halves: [f32; 2],
    /// The unbiased cross-half cost (`LevelFit::cost`; comparable within one cache).
    pub cost: f64,
    /// ε on held-back tiles, the reflectances fitted on the other half (None: a group too
    /// small to split, which the held-out test does not judge).
    pub held: Option<f32>,
}

impl Trial {
    pub fn of(fit: &LevelFit, held: Option<f32>) -> Trial {
        Trial {
            level: fit.level,
            error: fit.error,
            halves: fit.halves,
            cost: fit.cost,
            held,
        }
    }
}

/// The group's latest climbs (at most [`POOLED_CLIMBS`]), each the level it climbed from and
/// the levels fitted on its cache, that level's first. A climb's fits stay evidence after the
/// group moves: its cache does not depend on the group's own model, so a level the climbs from
/// below found no better than the one it moved to is not taken on the next cache alone.
#[derive(Clone, Debug, Default, Serialize, Deserialize, PartialEq)]
pub struct ClimbEvidence {
    pub climbs: Vec<(Level, Vec<Trial>)>,
}

/// The climbs a verdict pools at most, the latest: the scene around the group keeps settling,
/// and old caches saw it less settled.
pub const POOLED_CLIMBS: usize = 4;

/// A level judged against a simpler one over the climbs where both were fitted.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Verdict {
    /// It lowers ε by the margin, clear of the noise, on both halves.
    pub earned: bool,
    /// It lowers the unbiased cross-half cost, summed over the caches.
    pub lowers_cost: bool,
    /// At least half of its in-sample gain remains on held-back tiles.
    pub predicts: bool,
    /// The mean gain's noise.
    pub gain_noise: f32,
    /// The held-out ε of the simpler and of the tried level, the means over the climbs (None
    /// where a group too small to split was not judged).
    pub held: Option<[f32; 2]>,
    /// The climbs pooled.
    pub climbs: u32,
}

impl ClimbEvidence {
    pub fn is_empty(&self) -> bool {
        self.climbs.is_empty()
    }

    /// The climbs' trials, oldest first.
    pub fn trials(&self) -> impl Iterator<Item = &[Trial]> {
        self.climbs.iter().map(|(_, t)| t.as_slice())
    }

    /// How many of the climbs went up from `level`.
    pub fn climbs_from(&self, level: Level) -> usize {
        self.climbs.iter().filter(|(l, _)| *l == level).count()
    }

    /// Adds a climb's trials from `level`, forgetting the oldest beyond [`POOLED_CLIMBS`].
    pub fn add(&mut self, level: Level, trials: Vec<Trial>) {
        self.climbs.push((level, trials));
        if self.climbs.len() > POOLED_CLIMBS {
            self.climbs.remove(0);
        }
    }
}

/// `better` judged against `base` over `climbs` and the current climb's `current` trials (the
/// rule of `fitter::lowers_error` and of the held-out test on the means: on one climb the same
/// verdict).
pub fn judge<'a>(
    climbs: impl Iterator<Item = &'a [Trial]>,
    current: &'a [Trial],
    base: Level,
    better: Level,
    margin: f32,
    noise_factor: f32,
) -> Verdict {
    let pairs: Vec<(Trial, Trial)> = (climbs.chain(std::iter::once(current)))
        .filter_map(|c| {
            let a = c.iter().find(|t| t.level == base)?;
            let b = c.iter().find(|t| t.level == better)?;
            Some((*a, *b))
        })
        .collect();
    let n = pairs.len().max(1) as f32;
    let (mut gain, mut g0, mut g1, mut var, mut base_error) = (0.0f32, 0.0, 0.0, 0.0, 0.0);
    let (mut held_gain, mut held, mut judged) = (0.0f32, [0.0f32; 2], true);
    let mut cost_gain = 0.0f64;
    for (a, b) in &pairs {
        cost_gain += a.cost - b.cost;
        gain += a.error - b.error;
        let (h0, h1) = (a.halves[0] - b.halves[0], a.halves[1] - b.halves[1]);
        g0 += h0;
        g1 += h1;
        var += (0.5 * (h0 - h1)).powi(2);
        base_error += a.error;
        match (a.held, b.held) {
            (Some(x), Some(y)) => {
                held_gain += x - y;
                held[0] += x;
                held[1] += y;
            }
            _ => judged = false,
        }
    }
    let gain_noise = var.sqrt() / n;
    let (gain, base_error) = (gain / n, base_error / n);
    let earned = !pairs.is_empty()
        && gain > margin * base_error
        && gain > noise_factor * gain_noise
        && g0 > 0.0
        && g1 > 0.0;
    Verdict {
        earned,
        lowers_cost: cost_gain > 0.0,
        predicts: !judged || held_gain / n >= 0.5 * gain,
        gain_noise,
        held: judged.then(|| held.map(|h| h / n)),
        climbs: pairs.len() as u32,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn trial(level: Level, error: f32, halves: [f32; 2], held: f32) -> Trial {
        Trial {
            level,
            error,
            halves,
            cost: error as f64,
            held: Some(held),
        }
    }

    /// On one climb the verdict is `lowers_error`'s and the held-out test's.
    #[test]
    fn one_climb_is_judged_as_one_cache_is() {
        let base = trial(Level::Diffuse, 0.20, [0.21, 0.19], 0.21);
        let good = trial(Level::DiffuseSpecular, 0.15, [0.155, 0.145], 0.16);
        let v = judge(std::iter::empty(), &[base, good], Level::Diffuse, Level::DiffuseSpecular, 0.15, 3.0);
        // Gain 0.05 > 0.03 and > 3 × |0.055 − 0.045| / 2; held-out gain 0.05 ≥ 0.025.
        assert!(v.earned && v.predicts && v.climbs == 1, "{v:?}");
        assert!((v.gain_noise - 0.005).abs() < 1e-6, "{v:?}");
        // Halves that disagree: gain 0.05, noise |0.08 − 0.02| / 2 = 0.03.
        let noisy = trial(Level::DiffuseSpecular, 0.15, [0.13, 0.17], 0.16);
        let v = judge(std::iter::empty(), &[base, noisy], Level::Diffuse, Level::DiffuseSpecular, 0.15, 3.0);
        assert!(!v.earned && (v.gain_noise - 0.03).abs() < 1e-6, "{v:?}");
    }

    /// A gain each cache's noise hides clears it over three: the mean gain's noise falls as
    /// 1/√n. A gain that one cache shows and the others do not is not kept.
    #[test]
    fn a_steady_gain_clears_the_noise_pooled_a_lucky_one_does_not() {
        let climb = |g: f32, d: f32| {
            vec![
                trial(Level::Diffuse, 0.20, [0.20, 0.20], 0.20),
                trial(Level::DiffuseSpecular, 0.20 - g, [0.20 - g - d, 0.20 - g + d], 0.20 - g),
            ]
        };
        let (l0, l1) = (Level::Diffuse, Level::DiffuseSpecular);
        // Each: gain 0.045, noise 0.02 (z 2.25 < 3); three together: noise 0.0115, z 3.9.
        let one = judge(std::iter::empty(), &climb(0.045, 0.02), l0, l1, 0.15, 3.0);
        assert!(!one.earned, "{one:?}");
        let two = [climb(0.045, 0.02), climb(0.045, 0.02)];
        let three = judge(two.iter().map(|c| c.as_slice()), &climb(0.045, 0.02), l0, l1, 0.15, 3.0);
        assert!(three.earned && three.climbs == 3, "{three:?}");
        // One cache with a clear gain (z 10), two with none: the mean gain 0.0167 misses the
        // margin (0.03).
        let none = [climb(0.0, 0.005), climb(0.0, 0.005)];
        let lucky = judge(none.iter().map(|c| c.as_slice()), &climb(0.05, 0.005), l0, l1, 0.15, 3.0);
        assert!(!lucky.earned, "{lucky:?}");
    }

    /// Climbs where one of the two levels was not fitted are left out; the oldest climbs are
    /// forgotten beyond `POOLED_CLIMBS`, whatever level they went up from.
    #[test]
    fn only_climbs_that_fitted_both_levels_count() {
        let mut e = ClimbEvidence::default();
        e.add(Level::Diffuse, vec![trial(Level::Diffuse, 0.2, [0.2, 0.2], 0.2)]);
        let v = judge(
            e.trials(),
            &[
                trial(Level::Diffuse, 0.2, [0.2, 0.2], 0.2),
                trial(Level::Isotropic, 0.1, [0.1, 0.1], 0.1),
            ],
            Level::Diffuse,
            Level::Isotropic,
            0.15,
            3.0,
        );
        assert_eq!(v.climbs, 1);
        for _ in 0..POOLED_CLIMBS {
            e.add(Level::Isotropic, Vec::new());
        }
        assert_eq!((e.climbs.len(), e.climbs_from(Level::Diffuse)), (POOLED_CLIMBS, 0));
    }
}
