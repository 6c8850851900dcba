//! The per-group state machine of the hierarchical and iterative principles (§4.1 of the notes).
//!
//! ```text
//!            fit at level ℓ (iterative principle, every global iteration)
//!                 │
//!   ε < threshold(ℓ) ──────────────────────────────► Confirmed at ℓ (keeps being refined)
//!                 │ no
//!   first iteration at ℓ, the rest of the scene still moving, or another group's turn?
//!       ── yes ──► wait (a group must not climb to explain light that a neighbour's stale
//!       model is missing: one group climbs at a time, the worst ε / threshold first)
//!                 │ no
//!   climb (hierarchical principle): try ℓ+1, ℓ+2, … 6 on the same cache, in order.
//!   A level is kept only if it lowers ε by a clear margin: by the fraction `margin` of the
//!   current ε, and by more than `noise_factor` times the noise of that gain. Both models are
//!   evaluated on the same samples, so the gain's noise is measured by evaluating it on each
//!   half of the samples alone: |gain₀ − gain₁| / 2; and it must lower the cross-half
//!   least-squares cost too, which Monte Carlo noise does not inflate (so a near-mirror Ward
//!   lobe cannot beat the mirror model merely by being evaluated with less noise). Climbing
//!   stops at the first kept level below its threshold.
//!        kept a higher level ──► move to it (Analysing; confirmed when its refit passes)
//!        none earned its place ──► Confirmed at ℓ, the simplest level with the lowest error
//! ```
//! Every fit and every level tried becomes an [`Event`] for the log.

use super::cache::{CacheNeeds, GroupCache};
use super::fitter::{fit_level, LevelFit};
use super::level::{Level, Thresholds};
use super::params::GroupParams;
use crate::scene::WardVariant;
use serde::{Deserialize, Serialize};

#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Status {
    /// Still climbing the hierarchy.
    Analysing,
    /// Its level is decided; its parameters are still refined at each global iteration.
    Confirmed,
    /// No usable pixels: it got the stated default.
    Default,
    /// Marked fixed in the scene: its material is kept.
    Fixed,
    /// An emitter: its emission is known, it is not fitted.
    Light,
}

#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct HierarchyOptions {
    pub thresholds: Thresholds,
    /// A higher level must lower ε by at least this fraction of the current ε...
    pub margin: f32,
    /// ...and by more than this many noise floors.
    pub noise_factor: f32,
}

impl Default for HierarchyOptions {
    fn default() -> Self {
        HierarchyOptions {
            thresholds: Thresholds::default(),
            margin: 0.15,
            noise_factor: 3.0,
        }
    }
}

/// The state of one group.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct GroupState {
    pub name: String,
    pub level: Level,
    pub status: Status,
    pub params: GroupParams,
    /// ε and noise floor of the last fit (on the cache).
    pub error: f32,
    pub noise_floor: f32,
    /// Global iterations spent at the current level.
    pub iterations_at_level: u32,
    pub note: Option<String>,
    /// The last change of ρd and ρs made by a refit at the same level (for damping).
    #[serde(default)]
    pub last_step: Option<(crate::math::Rgb, crate::math::Rgb)>,
    /// Sum and count of the fits since the group was confirmed at its level. Each global
    /// iteration draws a fresh cache, so these are independent estimates; their mean is the
    /// group's parameters (Monte Carlo noise shrinks as 1/√count).
    #[serde(default)]
    /// Running sum of confirmed fits, each weighted by its cache's pixel count (its precision),
    /// with the number of fits and the total weight.
    pub average: Option<(GroupParams, u32, f32)>,
}

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
        kept: bool,
    },
    /// The group moved to a new level.
    Moved { from: Level, to: Level },
    /// A higher level earned its place, but another group moves first this iteration.
    Deferred { to: Level },
    /// The group's level is decided.
    Confirmed {
        level: Level,
        error: f32,
        below_threshold: bool,
    },
    /// A simpler level explains the photo as well as the current one on today's cache: the
    /// group goes back to it (the current level no longer earns its place).
    Demoted {
        from: Level,
        to: Level,
        error_before: f32,
        error_after: f32,
    },
}

impl GroupState {
    pub fn new(name: &str, status: Status, params: GroupParams) -> GroupState {
        GroupState {
            name: name.to_string(),
            level: Level::Diffuse,
            status,
            params,
            error: 0.0,
            noise_floor: 0.0,
            iterations_at_level: 0,
            note: None,
            last_step: None,
            average: None,
        }
    }

    /// Adds a confirmed fit of weight `weight` to the running mean and sets the parameters to the
    /// mean.
    fn accumulate(&mut self, weight: f32) {
        let p = self.params;
        let (sum, n, wsum) = self.average.get_or_insert((
            GroupParams {
                rho_d: crate::math::Rgb::ZERO,
                rho_s: crate::math::Rgb::ZERO,
                alpha_x: 0.0,
                alpha_y: 0.0,
                theta: 0.0,
            },
            0,
            0.0,
        ));
        sum.rho_d += p.rho_d * weight;
        sum.rho_s += p.rho_s * weight;
        sum.alpha_x += p.alpha_x.ln() * weight;
        sum.alpha_y += p.alpha_y.ln() * weight;
        sum.theta += p.theta * weight;
        *n += 1;
        *wsum += weight;
        let k = *wsum;
        // Roughness is averaged in the log domain (it is fitted in ln α).
        self.params = GroupParams {
            rho_d: sum.rho_d / k,
            rho_s: sum.rho_s / k,
            alpha_x: (sum.alpha_x / k).exp(),
            alpha_y: (sum.alpha_y / k).exp(),
            theta: sum.theta / k,
        }
        .clamped();
    }

    /// What is not finite about the group's last fit (its error, noise floor or a parameter),
    /// if anything: a diverged fit, which `recover` must not carry on with.
    pub fn non_finite(&self) -> Option<String> {
        let p = &self.params;
        let checks = [
            ("error ε", self.error.is_finite()),
            ("noise floor", self.noise_floor.is_finite()),
            ("rho_d", p.rho_d.is_finite()),
            ("rho_s", p.rho_s.is_finite()),
            ("alpha_x", p.alpha_x.is_finite()),
            ("alpha_y", p.alpha_y.is_finite()),
            ("theta", p.theta.is_finite()),
        ];
        let bad: Vec<&str> = checks.iter().filter(|c| !c.1).map(|c| c.0).collect();
        (!bad.is_empty()).then(|| {
            format!(
                "{} not finite: ε {}, ρd {:?}, ρs {:?}, αx {}, αy {}",
                bad.join(", "),
                self.error,
                p.rho_d.to_array(),
                p.rho_s.to_array(),
                p.alpha_x,
                p.alpha_y
            )
        })
    }

    /// Whether the group is fitted at all.
    pub fn is_fitted(&self) -> bool {
        matches!(self.status, Status::Analysing | Status::Confirmed)
    }

    /// What the group's cache must hold this iteration.
    pub fn cache_needs(&self, may_climb: bool) -> CacheNeeds {
        self.cache_needs_for(self.level, may_climb && self.status == Status::Analysing)
    }

    fn cache_needs_for(&self, level: Level, may_climb: bool) -> CacheNeeds {
        CacheNeeds {
            lobe_samples: may_climb || level.is_ward(),
            mirror: may_climb || level.is_mirror(),
        }
    }

    /// Damps oscillation between global iterations. Groups that see each other (a wall and the
    /// glossy floor reflecting it) can make the fixed-point iteration of the notes alternate
    /// around its limit: ρ(t+1) − ρ(t) ≈ r (ρ(t) − ρ(t−1)) with r < 0. Where a channel's step
    /// reverses, take the secant (Aitken) estimate of the limit, ρ(t) + Δ / (1 − r), with r
    /// kept in [−0.9, 0]. Monotone steps are left alone: extrapolating them too (r ≤ 0.7, for
    /// steps > 0.01) sped up the diffuse figure6 of `bench/` (worst ρ error after 4 iterations
    /// 0.0094 → 0.0056) but made the glossy figure6 diverge, where caustic noise moves the
    /// blocks by more than that.
    fn damp(&mut self, old: &GroupParams) {
        use crate::math::Rgb;
        let step = (self.params.rho_d - old.rho_d, self.params.rho_s - old.rho_s);
        if let Some((pd, ps)) = self.last_step {
            let fix = |new: &mut Rgb, old: Rgb, d: Rgb, prev: Rgb| {
                for c in 0..3 {
                    if d[c] * prev[c] < 0.0 && prev[c].abs() > 1e-6 {
                        let r = (d[c] / prev[c]).clamp(-0.9, 0.0);
                        new[c] = old[c] + d[c] / (1.0 - r);
                    }
                }
            };
            fix(&mut self.params.rho_d, old.rho_d, step.0, pd);
            fix(&mut self.params.rho_s, old.rho_s, step.1, ps);
            self.params = self.params.clamped();
        }
        self.last_step = Some((self.params.rho_d - old.rho_d, self.params.rho_s - old.rho_s));
    }

    fn take(&mut self, f: &LevelFit) {
        self.params = f.params;
        self.error = f.error;
        self.noise_floor = f.noise_floor;
    }

    /// Whether `better` lowers the error of `base` by a clear margin on the same cache.
    fn earns(base: &LevelFit, better: &LevelFit, opts: &HierarchyOptions) -> (bool, f32) {
        let gain = base.error - better.error;
        let g0 = base.halves[0] - better.halves[0];
        let g1 = base.halves[1] - better.halves[1];
        let gain_noise = 0.5 * (g0 - g1).abs();
        (
            gain > opts.margin * base.error
                && gain > opts.noise_factor * gain_noise
                && g0 > 0.0
                && g1 > 0.0,
            gain_noise,
        )
    }

    /// Whether this group wants to climb this iteration if allowed: analysing, fitted at its
    /// level before, and above the level's threshold. Its priority is ε / threshold.
    pub fn climb_priority(&self, opts: &HierarchyOptions) -> Option<f32> {
        let thr = opts.thresholds.of(self.level);
        (self.status == Status::Analysing && self.iterations_at_level >= 1 && self.error >= thr)
            .then(|| self.error / thr)
    }

    /// One global iteration for this group, given its freshly built cache. `may_climb`: whether
    /// the group may try the higher levels now (the rest of the scene has settled); `may_move`:
    /// whether it may also move to one (one group at a time, the worst first; see `recover.rs`).
    /// A try that finds no better level confirms the group; one that finds a better level
    /// without leave to move changes nothing and is tried again later.
    pub fn step(
        &mut self,
        cache: &GroupCache,
        variant: WardVariant,
        opts: &HierarchyOptions,
        may_climb: bool,
        may_move: bool,
    ) -> Vec<Event> {
        let mut events = Vec::new();
        let fit = fit_level(cache, self.level, &self.params, variant);
        events.push(Event::Fit {
            level: self.level,
            error: fit.error,
            noise_floor: fit.noise_floor,
            evals: fit.evals,
        });
        let old = self.params;
        self.take(&fit);
        if self.status == Status::Confirmed {
            self.accumulate(cache.pixels.len().max(1) as f32);
        } else if self.iterations_at_level > 0 {
            self.damp(&old);
        } else {
            self.last_step = None;
        }
        self.iterations_at_level += 1;
        if self.status == Status::Confirmed && self.level != Level::Diffuse {
            // Demotion check: does a simpler level (available in this cache) do as well?
            let needs = self.cache_needs_for(self.level, false);
            for lower in Level::FITTED.iter().copied().filter(|&l| l < self.level) {
                if (lower.is_ward() && !needs.lobe_samples) || (lower.is_mirror() && !needs.mirror)
                {
                    continue;
                }
                let f = fit_level(cache, lower, &self.params, variant);
                let current = LevelFit {
                    level: self.level,
                    params: self.params,
                    error: self.error,
                    noise_floor: self.noise_floor,
                    halves: fit.halves,
                    cost: fit.cost,
                    evals: 0,
                };
                if !Self::earns(&f, &current, opts).0 {
                    events.push(Event::Demoted {
                        from: self.level,
                        to: lower,
                        error_before: self.error,
                        error_after: f.error,
                    });
                    self.level = lower;
                    self.take(&f);
                    self.iterations_at_level = 0;
                    self.last_step = None;
                    self.average = None;
                    self.status = Status::Analysing;
                    break;
                }
            }
            return events;
        }
        if self.status != Status::Analysing {
            return events;
        }
        let thr = opts.thresholds.of(self.level);
        if fit.error < thr {
            self.status = Status::Confirmed;
            events.push(Event::Confirmed {
                level: self.level,
                error: fit.error,
                below_threshold: true,
            });
            return events;
        }
        if self.iterations_at_level < 2 || !may_climb {
            return events; // let the interreflections of this level settle first
        }
        // Climb on the same cache.
        let mut best = fit.clone();
        let mut last = fit;
        let mut level = self.level;
        while let Some(next) = level.next() {
            let start = GroupParams {
                alpha_x: last.params.alpha_x,
                alpha_y: last.params.alpha_y,
                theta: last.params.theta,
                ..best.params
            };
            let f = fit_level(cache, next, &start, variant);
            let (kept, gain_noise) = Self::earns(&best, &f, opts);
            events.push(Event::Tried {
                level: next,
                error_before: best.error,
                error_after: f.error,
                noise_floor: f.noise_floor,
                gain_noise,
                kept,
            });
            level = next;
            if kept {
                best = f.clone();
                if f.error < opts.thresholds.of(next) {
                    break;
                }
            }
            last = f;
        }
        if best.level != self.level && !may_move {
            events.push(Event::Deferred { to: best.level });
        } else if best.level != self.level {
            events.push(Event::Moved {
                from: self.level,
                to: best.level,
            });
            self.level = best.level;
            self.take(&best);
            self.iterations_at_level = 0;
            self.last_step = None;
        } else {
            self.status = Status::Confirmed;
            self.note = Some(format!(
                "no higher level lowered the error by a clear margin; kept {} with fit ε {:.4} above its threshold {:.4}",
                self.level.name(),
                self.error,
                thr
            ));
            events.push(Event::Confirmed {
                level: self.level,
                error: self.error,
                below_threshold: false,
            });
        }
        events
    }
}
