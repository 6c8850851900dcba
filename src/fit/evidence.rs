//! The evidence of several caches for a climb's decisions (`hierarchy.rs`): each level's fit on
//! each of the last [`POOLED_CLIMBS`] climbs' caches at the group's current level, so that a
//! higher level is kept, or refused, by what those caches say together, not by the one that
//! came last.
//!
//! One cache's test (`fitter::lowers_error`) asks of the gain g = ε(lower) − ε(higher) that it
//! clear the margin and `noise_factor` times its noise, |g₀ − g₁| / 2 from the cache's two
//! halves of samples. On a material that neither model is (a measured BRDF, a painted ball
//! whose coat is between a lobe and a mirror) g sits near that bar, and each cache's noise
//! decides: the same photo gave plastic, diffuse or isotropic by the seed. Pooled over the n
//! caches both levels were fitted on, the gain is the mean of the per-cache gains, judged
//! against the larger of the pooled halves' noise (|Σg₀ − Σg₁| / 2n) and the gains' own scatter
//! from cache to cache (their standard deviation / √n), which also holds whatever moved between
//! the caches (the group's parameters converging, a neighbour's light). With one cache the test
//! is the single cache's, exactly.

use super::fitter::LevelFit;
use super::level::Level;
use serde::{Deserialize, Serialize};

/// How many climbs' caches at a level are pooled: older ones saw a scene that has moved on.
pub const POOLED_CLIMBS: u32 = 3;

/// A climb that finds no level above the group's own earning its place confirms the group
/// there only once this many climbs' caches, pooled, say so (`Event::Inconclusive` before):
/// a refusal is a decision too, and one cache's noise made it as often as a move.
pub const CONFIRMING_CLIMBS: u32 = 2;

/// One level's fit on one climb's cache.
#[derive(Clone, Copy, Debug, Serialize, Deserialize, PartialEq)]
struct Entry {
    climb: u32,
    level: Level,
    error: f32,
    halves: [f32; 2],
    cost: f64,
}

/// Held-out ε of a lower and a higher level on one climb's cache (`GroupState::predicts`).
#[derive(Clone, Copy, Debug, Serialize, Deserialize, PartialEq)]
struct Held {
    climb: u32,
    lower: Level,
    higher: Level,
    held: [f32; 2],
}

/// The climbs' evidence at a group's current level (emptied when the level changes).
#[derive(Clone, Debug, Default, Serialize, Deserialize, PartialEq)]
pub struct ClimbPool {
    /// Climbs at the current level so far, the one under way not included.
    pub climbs: u32,
    fits: Vec<Entry>,
    held: Vec<Held>,
}

/// A higher level's gain over a lower one, pooled over the caches both were fitted on.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PooledGain {
    pub caches: u32,
    /// Mean gain in ε, and the lower level's mean ε.
    pub gain: f32,
    pub lower_error: f32,
    /// Mean gain on each half of the samples.
    pub halves: [f32; 2],
    /// The mean gain's noise: the larger of the halves' and the caches' scatter (module doc).
    pub noise: f32,
    /// Mean gain in the cross-half cost (`LevelFit::cost`).
    pub cost: f64,
}

impl PooledGain {
    /// Whether the gain is clear: by the fraction `margin` of the lower level's ε, by
    /// `noise_factor` times its noise, and on each half of the samples
    /// (`fitter::lowers_error`, pooled).
    pub fn clear(&self, margin: f32, noise_factor: f32) -> bool {
        self.gain > margin * self.lower_error
            && self.gain > noise_factor * self.noise
            && self.halves[0] > 0.0
            && self.halves[1] > 0.0
    }
}

impl ClimbPool {
    pub fn is_empty(&self) -> bool {
        self.climbs == 0 && self.fits.is_empty()
    }

    /// Records level `f.level`'s fit on the cache of climb `self.climbs` (the one under way).
    pub fn record(&mut self, f: &LevelFit) {
        let climb = self.climbs;
        self.fits
            .retain(|e| !(e.climb == climb && e.level == f.level));
        self.fits.push(Entry {
            climb,
            level: f.level,
            error: f.error,
            halves: f.halves,
            cost: f.cost,
        });
    }

    /// Records the held-out ε of `lower` and `higher` on the cache of the climb under way.
    pub fn record_held(&mut self, lower: Level, higher: Level, held: [f32; 2]) {
        let climb = self.climbs;
        self.held
            .retain(|h| !(h.climb == climb && h.lower == lower && h.higher == higher));
        self.held.push(Held {
            climb,
            lower,
            higher,
            held,
        });
    }

    /// Ends the climb under way: the next one pools with it and the [`POOLED_CLIMBS`] − 1
    /// before it.
    pub fn finish_climb(&mut self) {
        self.climbs += 1;
        let oldest = self.climbs.saturating_sub(POOLED_CLIMBS - 1);
        self.fits.retain(|e| e.climb >= oldest);
        self.held.retain(|h| h.climb >= oldest);
    }

    fn fit(&self, climb: u32, level: Level) -> Option<&Entry> {
        self.fits
            .iter()
            .find(|e| e.climb == climb && e.level == level)
    }

    /// `higher`'s gain over `lower`, pooled over the climbs' caches both were fitted on (None:
    /// none).
    pub fn gain(&self, lower: Level, higher: Level) -> Option<PooledGain> {
        let pairs: Vec<(&Entry, &Entry)> = (self.fits.iter())
            .filter(|e| e.level == lower)
            .filter_map(|l| Some((l, self.fit(l.climb, higher)?)))
            .collect();
        if pairs.is_empty() {
            return None;
        }
        let n = pairs.len() as f32;
        let gains: Vec<f32> = pairs.iter().map(|(l, h)| l.error - h.error).collect();
        let gain = gains.iter().sum::<f32>() / n;
        let half = |k: usize| pairs.iter().map(|(l, h)| l.halves[k] - h.halves[k]).sum::<f32>() / n;
        let halves = [half(0), half(1)];
        let scatter = if pairs.len() > 1 {
            let var = gains.iter().map(|g| (g - gain).powi(2)).sum::<f32>() / (n - 1.0);
            (var / n).sqrt()
        } else {
            0.0
        };
        Some(PooledGain {
            caches: pairs.len() as u32,
            gain,
            lower_error: pairs.iter().map(|(l, _)| l.error).sum::<f32>() / n,
            halves,
            noise: (0.5 * (halves[0] - halves[1]).abs()).max(scatter),
            cost: pairs.iter().map(|(l, h)| l.cost - h.cost).sum::<f64>() / n as f64,
        })
    }

    /// Whether `higher` predicts held-back pixels better than `lower` by at least half its
    /// in-sample gain, summed over the climbs' caches where both were judged on them
    /// (`GroupState::predicts`, pooled). None: never judged.
    pub fn predicts(&self, lower: Level, higher: Level) -> Option<bool> {
        let (mut held, mut gain, mut any) = (0.0f32, 0.0f32, false);
        for h in (self.held.iter()).filter(|h| h.lower == lower && h.higher == higher) {
            let (Some(l), Some(u)) = (self.fit(h.climb, lower), self.fit(h.climb, higher)) else {
                continue;
            };
            held += h.held[0] - h.held[1];
            gain += l.error - u.error;
            any = true;
        }
        any.then_some(held >= 0.5 * gain)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fit::params::GroupParams;

    fn fit(level: Level, error: f32, halves: [f32; 2]) -> LevelFit {
        LevelFit {
            level,
            params: GroupParams::default(),
            error,
            noise_floor: 0.0,
            halves,
            cost: error as f64,
            evals: 1,
        }
    }

    /// With one cache the pooled test is the cache's own (`fitter::lowers_error`).
    #[test]
    fn one_cache_is_judged_as_before() {
        let (lower, higher) = (
            fit(Level::Diffuse, 0.050, [0.051, 0.049]),
            fit(Level::Isotropic, 0.040, [0.043, 0.037]),
        );
        let mut pool = ClimbPool::default();
        pool.record(&lower);
        pool.record(&higher);
        let p = pool.gain(Level::Diffuse, Level::Isotropic).unwrap();
        let (single, noise) = crate::fit::fitter::lowers_error(&lower, &higher, 0.05, 2.0);
        assert_eq!(p.caches, 1);
        assert!((p.noise - noise).abs() < 1e-7 && (p.gain - 0.010).abs() < 1e-7);
        assert_eq!(p.clear(0.05, 2.0), single);
        assert!(pool.gain(Level::Diffuse, Level::Anisotropic).is_none());
    }

    /// A gain that one cache shows just under its noise is clear on three caches that agree,
    /// and not on three that disagree (the scatter from cache to cache is its noise); caches
    /// older than [`POOLED_CLIMBS`] climbs are forgotten.
    #[test]
    fn caches_that_agree_add_up_and_caches_that_disagree_do_not() {
        // Gain g whose halves differ by ±0.008 (sign s): one cache's noise is 0.004, its bar
        // 2 × 0.004 = 0.008; independent caches' halves differ each their own way.
        let climb = |pool: &mut ClimbPool, g: f32, s: f32| {
            pool.record(&fit(Level::Diffuse, 0.050, [0.050, 0.050]));
            pool.record(&fit(
                Level::Plastic,
                0.050 - g,
                [0.050 - g + 0.004 * s, 0.050 - g - 0.004 * s],
            ));
            let p = pool.gain(Level::Diffuse, Level::Plastic).unwrap();
            pool.finish_climb();
            p
        };
        let mut agree = ClimbPool::default();
        let first = climb(&mut agree, 0.007, 1.0);
        assert!(!first.clear(0.05, 2.0), "one cache: under its noise");
        climb(&mut agree, 0.007, -1.0);
        let p = climb(&mut agree, 0.007, 1.0);
        assert_eq!(p.caches, 3);
        assert!(p.clear(0.05, 2.0), "three caches that agree: {p:?}");
        // A fourth climb forgets the first: still three caches.
        assert_eq!(climb(&mut agree, 0.007, -1.0).caches, 3);

        let mut disagree = ClimbPool::default();
        climb(&mut disagree, 0.020, 1.0);
        climb(&mut disagree, -0.004, -1.0);
        let p = climb(&mut disagree, 0.005, 1.0);
        assert!((p.gain - 0.007).abs() < 1e-6);
        assert!(!p.clear(0.05, 2.0), "the same mean gain, scattered: {p:?}");
    }

    /// The held-out verdict is pooled over the caches where the pair was judged.
    #[test]
    fn held_out_evidence_is_pooled() {
        let mut pool = ClimbPool::default();
        for held_gain in [0.002, 0.009] {
            pool.record(&fit(Level::Diffuse, 0.05, [0.05, 0.05]));
            pool.record(&fit(Level::Isotropic, 0.04, [0.04, 0.04]));
            pool.record_held(Level::Diffuse, Level::Isotropic, [0.05, 0.05 - held_gain]);
            if held_gain < 0.005 {
                assert_eq!(pool.predicts(Level::Diffuse, Level::Isotropic), Some(false));
            }
            pool.finish_climb();
        }
        // 0.011 held out of 0.020 in sample: more than half.
        assert_eq!(pool.predicts(Level::Diffuse, Level::Isotropic), Some(true));
        assert_eq!(pool.predicts(Level::Diffuse, Level::Plastic), None);
    }
}
