//! The state of one group as the recovery carries it from one global iteration to the next:
//! its level, status, parameters and the running means of its fits. The decisions that change
//! it (fit, climb, confirm, demote) are the hierarchy's (`hierarchy.rs`); the rules across
//! groups are the schedule's (`schedule.rs`).

use super::cache::CacheNeeds;
use super::fitter::LevelFit;
use super::level::Level;
use super::params::GroupParams;
use super::texture::TextureState;
use serde::{Deserialize, Serialize};

/// Where a group stands in the hierarchy.
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

/// How a group's parameters moved in a global iteration (see [`GroupState::record_move`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Motion {
    Steady,
    Jittering,
    Converging,
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
    /// The same of the fits that chose the other microfacet distribution (levels 8–10): the
    /// runner-up, which takes over from `average` once its total weight is the greater.
    #[serde(default)]
    pub runner_up: Option<(GroupParams, u32, f32)>,
    /// The weighted sums of squares of the fits in `average` and in `runner_up` (same scales):
    /// the scatter of single fits across caches, which the parameters' 1σ includes.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub squares: Option<(GroupParams, GroupParams)>,
    /// Global iterations since this group last found a higher level that earned its place
    /// but had to wait for another group's turn (0: not waiting). The longest waiting group
    /// climbs first, so no group holds the turn (see `schedule::climbers`).
    #[serde(default)]
    pub waiting: u32,
    /// The higher level it is waiting for.
    #[serde(default)]
    pub pending: Option<Level>,
    /// How far its parameters moved in each global iteration at its current level (largest
    /// ρ change or relative α change): whether it is still converging or only jittering.
    #[serde(default)]
    pub moves: Vec<f32>,
    /// Level 7's texture (and the level of the lobe on top of it).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub texture: Option<super::texture::TextureState>,
    /// Per group of the scene, the share of this group's light that last bounced there
    /// (`GroupCache::light_from` of its latest cache): which groups' models its fit depends on
    /// (`schedule::climbers`). Empty before its first cache.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub lit_by: Vec<f32>,
    /// The open share of its pixels' hemisphere (`GroupCache::open` of its latest cache).
    #[serde(default)]
    pub open: f32,
    /// The 1σ of its parameters at its level, from its latest cache (`uncertainty.rs`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sigma: Option<GroupParams>,
    /// The photo's own noise in ε's units on its latest cache, at its level
    /// (`objective::photo_noise`): what ε holds beyond the noise floor without any misfit.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub photo_noise: Option<f32>,
    /// Set (by the recovery loop) when a group that lights this textured group changed level:
    /// its next step asks Algorithm 1's gate again ([`GroupState::untexture`]).
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub recheck_texture: bool,
    /// The structure its best uniform model left when a re-ask of Algorithm 1's gate
    /// ([`GroupState::untexture`]) last found no texture: the next re-ask, on the next cache,
    /// pools it, and demotes the texture only if it finds none either. None once the gate
    /// kept the texture.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub texture_doubt: Option<super::detail::Detail>,
    /// Per group of the scene, its level when this group's texture was taken or last re-asked
    /// (empty when not textured): the recovery loop re-asks the gate when a group that gives
    /// this one more than 2% of its light is now at another level, measured on this group's
    /// latest cache, so also a mirror that gave it little light while it was modelled diffuse.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub texture_sources: Vec<Level>,
    /// Its last climb found that only a texture would do, but a group that lights it was still
    /// analysing (`schedule::texture_waits_for`): it waits, and holds no other group back.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub texture_waiting: bool,
    /// The climbs at its current level in which its texture waited so
    /// (`schedule::TEXTURE_WAITS`).
    #[serde(default)]
    pub texture_waits: u32,
    /// The simpler level that explained the last cache as well as the confirmed one
    /// ([`Event::Doubted`]); None once the level held again.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub doubted: Option<Level>,
    /// The uniform level from which a texture was last tried and not kept: its residual's
    /// structure is not re-asked until the group is at another level.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub texture_refused: Option<Level>,
    /// A texture that earned its place in a climb the group could not move on (another group's
    /// turn): its next trial starts from it rather than from nothing.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pending_texture: Option<TextureState>,
    /// The texture trials from the current level so far, pooled: the sum of their gains in ε,
    /// the sum of their gains' noise variances, and their count (`hierarchy.rs`, `climb`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub texture_evidence: Option<(f32, f32, u32)>,
    /// The fits of its last climb at levels above the one it kept that did not earn their
    /// place and fitted its cache no worse than the kept level by more than the gain test's
    /// own margin (`noise_factor` times the gain's noise): models its photo could not tell
    /// from its own. Only a trial worse beyond that margin is rejected by the photo. Its
    /// albedo's 1σ holds their spread (`uncertainty::albedo`).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub alternatives: Vec<(Level, GroupParams)>,
    /// Levels 8–10: the evidence between the two microfacet distributions pooled over the
    /// caches at the current level, as the sum of ε(GGX) − ε(Beckmann), its sum of squares and
    /// the count (`hierarchy.rs`, `fit_current`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub distribution_evidence: Option<(f64, f64, u32)>,
    /// Every level's fit on the caches of its climbs at the current level
    /// (`evidence::ClimbPool`): a higher level is kept or refused by their pooled evidence.
    #[serde(default, skip_serializing_if = "super::evidence::ClimbPool::is_empty")]
    pub climb_pool: super::evidence::ClimbPool,
    /// The texel-scale structure its uniform level left on its latest cache (`detail.rs`;
    /// None when textured, without an atlas, or not yet measured).
    #[serde(skip)]
    pub detail: Option<super::detail::Detail>,
    /// The texel-scale structure of every cache since the group reached its level, and that
    /// level: what a confirmed group's reopening is decided on (`hierarchy.rs`, `reopen`).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub detail_pool: Vec<(Level, super::detail::Detail)>,
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
            runner_up: None,
            squares: None,
            waiting: 0,
            pending: None,
            moves: Vec::new(),
            texture: None,
            lit_by: Vec::new(),
            open: 0.0,
            sigma: None,
            photo_noise: None,
            recheck_texture: false,
            texture_doubt: None,
            texture_sources: Vec::new(),
            texture_waiting: false,
            texture_waits: 0,
            doubted: None,
            texture_refused: None,
            pending_texture: None,
            texture_evidence: None,
            alternatives: Vec::new(),
            distribution_evidence: None,
            climb_pool: Default::default(),
            detail: None,
            detail_pool: Vec::new(),
        }
    }

    /// Adds a confirmed fit of weight `weight` to the running mean and sets the parameters to the
    /// mean.
    /// The mean is over fits of one microfacet distribution, the one chosen by the greater
    /// weight of fits: the two can fit a photo about as well, and one iteration's cache may tip
    /// the choice the other way, which must neither restart the mean nor end the run on it.
    pub(crate) fn accumulate(&mut self, weight: f32) {
        let p = self.params;
        let squares = self
            .squares
            .get_or_insert((GroupParams::zero_sums(), GroupParams::zero_sums()));
        if self
            .average
            .is_some_and(|(sums, _, _)| sums.distribution != p.distribution)
        {
            std::mem::swap(&mut self.average, &mut self.runner_up);
            std::mem::swap(&mut squares.0, &mut squares.1);
        }
        let (sums, n, total) = self
            .average
            .get_or_insert((GroupParams::zero_sums(), 0, 0.0));
        *n += 1;
        *total += weight;
        self.params = p.add_to_mean(sums, weight, *total, self.level);
        p.add_squares(&mut squares.0, weight);
        if let (Some(a), Some(r)) = (&self.average, &self.runner_up) {
            if r.2 > a.2 {
                self.params = r.0.mean_of_sums(r.2, self.level);
                std::mem::swap(&mut self.average, &mut self.runner_up);
                std::mem::swap(&mut squares.0, &mut squares.1);
            }
        }
    }

    /// The scatter of the single fits in the group's mean, and their number; None before three.
    pub fn fit_scatter(&self) -> Option<(GroupParams, u32)> {
        let ((sums, n, total), (squares, _)) = (self.average?, self.squares?);
        (n >= 3 && total > 0.0).then(|| (self.params.scatter(&sums, &squares, total), n))
    }

    /// Starts its mean of confirmed fits afresh.
    pub fn restart_average(&mut self) {
        self.average = None;
        self.runner_up = None;
        self.squares = None;
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

    /// The level whose parameters describe the group: its own, or at level 7 the level of the
    /// lobe on top of its texture (ρd is then the texture's mean).
    pub fn params_level(&self) -> Level {
        match (&self.texture, self.level) {
            (Some(t), Level::Textured) => t.base,
            _ => self.level,
        }
    }

    /// Whether the group is fitted at all.
    pub fn is_fitted(&self) -> bool {
        matches!(self.status, Status::Analysing | Status::Confirmed)
    }

    /// What the group's cache must hold this iteration.
    pub fn cache_needs(&self, may_climb: bool) -> CacheNeeds {
        self.cache_needs_for(self.level, may_climb && self.status == Status::Analysing)
    }

    pub(crate) fn cache_needs_for(&self, level: Level, may_climb: bool) -> CacheNeeds {
        let textured = level == Level::Textured;
        let varnished = textured && self.texture.as_ref().is_some_and(|t| t.base.is_ward());
        CacheNeeds {
            lobe_samples: may_climb
                || level.has_lobe()
                || varnished
                || (textured && self.recheck_texture),
            mirror: may_climb || level.is_mirror(),
            mirror_fitted: level.is_mirror(),
            texels: may_climb || textured,
            // A climb's texture trial is solved as level 7's texture is, on its neighbourhood's
            // irradiance: on the rows as sampled each texel takes its pixel's noise, and a
            // faint print's trial loses to the uniform model it should beat.
            smoothed_irradiance: may_climb || textured,
        }
    }

    /// Takes a newly solved texture: once the group is confirmed, into the running mean of the
    /// textures since (each global iteration's cache is an independent estimate, as for the
    /// parameters' mean of `accumulate`), else as it is.
    pub(crate) fn take_texture(&mut self, new: TextureState) {
        let n = match (&self.average, self.status) {
            (Some(a), Status::Confirmed) => a.1,
            _ => 1,
        };
        match &mut self.texture {
            Some(t) if n > 1 && t.texels.len() == new.texels.len() => {
                let k = 1.0 / n as f32;
                for (m, x) in t.texels.iter_mut().zip(&new.texels) {
                    *m = *m * (1.0 - k) + *x * k;
                }
                for (s, x) in t.seen.iter_mut().zip(&new.seen) {
                    *s |= *x;
                }
                t.base = new.base;
                t.smoothing = new.smoothing;
                t.smoothing_settled = new.smoothing_settled;
            }
            _ => self.texture = Some(new),
        }
    }

    pub(crate) fn take(&mut self, f: &LevelFit) {
        self.params = f.params;
        self.error = f.error;
        self.noise_floor = f.noise_floor;
    }

    /// Records how far the group's parameters moved in this global iteration (largest ρ change,
    /// or relative α change at the Ward levels) and says whether that holds the scene back.
    /// A group is `Steady` once its move is below `settle`. One whose moves stopped shrinking
    /// (three or more at its level since it was last steady, this one not clearly below every
    /// earlier one: at least 0.7 of the smallest; or eight iterations at the level) is
    /// `Jittering`: it moves within its own noise (a lobe the photo hardly determines) and
    /// waiting would not settle it, so it must not block the other groups' climbs either.
    /// A confirmed group averaging two fits or more is `Jittering` too (below). Otherwise it is
    /// still `Converging`. The smallest of all, not of the last two: noise
    /// makes some moves smaller than the one before by chance, and a lobe whose α jumps about
    /// at random would then count as converging every few iterations, holding the scene back
    /// until its eight iterations ran out.
    pub fn record_move(&mut self, moved: f32, settle: f32) -> Motion {
        // Since it was last steady: a later disturbance (a neighbour's climb) starts anew.
        let since = self.moves.iter().rposition(|&m| m < settle).map_or(0, |k| k + 1);
        let n = self.moves.len() - since;
        let least = self.moves[since..].iter().copied().fold(f32::INFINITY, f32::min);
        // A confirmed group's parameters are the mean of its fits since it was confirmed: that
        // mean moves by (fit − mean)/count, less each time by construction, which is not
        // convergence. Its fits are draws of one scene (a neighbour's climb restarts the mean).
        let averaging = self.status == Status::Confirmed && self.average.is_some_and(|a| a.1 >= 2);
        let motion = if moved < settle {
            Motion::Steady
        } else if averaging || n >= 2 && moved >= 0.7 * least || self.iterations_at_level >= 8 {
            Motion::Jittering
        } else {
            Motion::Converging
        };
        self.moves.push(moved);
        motion
    }

    /// Whether its average of confirmed fits starts afresh after an iteration whose move was
    /// `motion` (just recorded): while it still converges and has never been steady at its
    /// level (a group confirmed at its move), its fits lie on the way to its value.
    pub fn restarts_its_average(&self, motion: Motion, settle: f32) -> bool {
        motion == Motion::Converging && self.moves.iter().all(|&m| m >= settle)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Parameters that keep moving by the same amount (a lobe the photo does not determine)
    /// stop holding the scene back after three iterations; shrinking moves do not.
    #[test]
    fn jittering_parameters_count_as_settled_converging_ones_do_not() {
        let mut st = GroupState::new("block", Status::Analysing, GroupParams::default());
        let m: Vec<Motion> = [0.5, 0.4, 0.45, 0.6, 0.5]
            .iter()
            .map(|&x| st.record_move(x, 0.03))
            .collect();
        assert_eq!(m[..2], [Motion::Converging, Motion::Converging]);
        assert!(m[2..].iter().all(|&x| x == Motion::Jittering), "{m:?}");
        // A lobe whose α jumps by chance to a move smaller than the two before it, but not
        // clearly below the smallest so far, still jitters.
        let mut st = GroupState::new("door", Status::Analysing, GroupParams::default());
        let m: Vec<Motion> = [0.125, 0.115, 0.316, 0.294, 0.103, 1.17]
            .iter()
            .map(|&x| st.record_move(x, 0.03))
            .collect();
        assert!(m[2..].iter().all(|&x| x == Motion::Jittering), "{m:?}");
        let mut st = GroupState::new("wall", Status::Analysing, GroupParams::default());
        let m: Vec<Motion> = [0.4, 0.2, 0.1, 0.05, 0.02]
            .iter()
            .map(|&x| st.record_move(x, 0.03))
            .collect();
        assert_eq!(
            m,
            [
                Motion::Converging,
                Motion::Converging,
                Motion::Converging,
                Motion::Converging,
                Motion::Steady
            ]
        );
    }

    /// A group that has converged ever since it reached its level restarts its average each
    /// iteration it still converges; once steady there, a later converging move does not
    /// restart it (the scene-wide restarts are `recovery.rs`'s), nor does jitter.
    #[test]
    fn only_a_group_still_reaching_its_level_restarts_its_average() {
        let settle = 0.03;
        let mut st = GroupState::new("floor", Status::Confirmed, GroupParams::default());
        let m = st.record_move(0.2, settle);
        assert_eq!(m, Motion::Converging);
        assert!(st.restarts_its_average(m, settle));
        let m = st.record_move(0.1, settle);
        assert!(st.restarts_its_average(m, settle));
        let m = st.record_move(0.01, settle);
        assert_eq!(m, Motion::Steady);
        assert!(!st.restarts_its_average(m, settle));
        // Steady once at its level: a converging move later is the scene's, not its own.
        for moved in [0.5, 0.4] {
            st.record_move(moved, settle);
        }
        let m = st.record_move(0.2, settle);
        assert_eq!(m, Motion::Converging);
        assert!(!st.restarts_its_average(m, settle));
        let mut st = GroupState::new("wall", Status::Confirmed, GroupParams::default());
        for moved in [0.1, 0.09] {
            st.record_move(moved, settle);
        }
        let m = st.record_move(0.08, settle);
        assert_eq!(m, Motion::Jittering);
        assert!(!st.restarts_its_average(m, settle));
    }

    /// A confirmed group's mean is over the fits of the distribution chosen by the greater
    /// weight: a fit that tips the other way joins the runner-up without moving the parameters
    /// or restarting the mean, and the runner-up leads once it outweighs.
    #[test]
    fn a_distribution_flip_joins_the_runner_up() {
        use crate::scene::Distribution::{Beckmann, Ggx};
        let mut st = GroupState::new("block", Status::Confirmed, GroupParams::default());
        let fit = |st: &mut GroupState, distribution, alpha: f32, weight: f32| {
            st.params = GroupParams {
                alpha_x: alpha,
                alpha_y: alpha,
                distribution,
                ..GroupParams::default()
            };
            st.accumulate(weight);
            (st.params.distribution, st.params.alpha_x)
        };
        for _ in 0..3 {
            fit(&mut st, Beckmann, 0.3, 100.0);
        }
        let (d, a) = fit(&mut st, Ggx, 0.2, 100.0);
        assert_eq!(d, Beckmann);
        assert!((a - 0.3).abs() < 1e-5, "{a}");
        assert_eq!(st.average.map(|a| a.1), Some(3));
        let (d, a) = fit(&mut st, Beckmann, 0.3, 100.0);
        assert_eq!((d, st.average.map(|a| a.1)), (Beckmann, Some(4)));
        assert!((a - 0.3).abs() < 1e-5, "{a}");
        // Four GGX fits (weight 460) outweigh four Beckmann fits (400).
        for _ in 0..2 {
            fit(&mut st, Ggx, 0.2, 120.0);
        }
        let (d, a) = fit(&mut st, Ggx, 0.22, 120.0);
        assert_eq!(d, Ggx);
        let want = ((340.0 * 0.2f32.ln() + 120.0 * 0.22f32.ln()) / 460.0).exp();
        assert!((a - want).abs() < 1e-4, "{a} vs {want}");
        assert_eq!(st.runner_up.map(|r| r.1), Some(4));
        st.restart_average();
        assert!(st.average.is_none() && st.runner_up.is_none());
    }
}
