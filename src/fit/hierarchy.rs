//! The per-group state machine of the hierarchical and iterative principles (§4.1 of the notes).
//!
//! ```text
//!            fit at level ℓ (iterative principle, every global iteration)
//!                 │
//!   ε < threshold(ℓ) ──────────────────────────────► Confirmed at ℓ (keeps being refined)
//!                 │ no
//!   first iteration at ℓ, the rest of the scene still moving, or another group's turn?
//!   (those rules across groups: `schedule.rs`)
//!       ── yes ──► wait (a group must not climb to explain light that a neighbour's stale
//!       model is missing: groups that light each other climb one at a time, the worst
//!       ε / threshold first)
//!                 │ no
//!   climb (hierarchical principle): try ℓ+1, ℓ+2, … 6 on the same cache, in order.
//!   A level is kept only if it lowers ε by a clear margin: by the fraction `margin` of the
//!   current ε, and by more than `noise_factor` times the noise of that gain. Both models are
//!   evaluated on the same samples, so the gain's noise is measured by evaluating it on each
//!   half of the samples alone: |gain₀ − gain₁| / 2; and it must lower the cross-half
//!   least-squares cost too, which Monte Carlo noise does not inflate (so a near-mirror Ward
//!   lobe cannot beat the mirror model merely by being evaluated with less noise). Both tests
//!   pool this cache with those of the group's earlier climbs at ℓ (`evidence.rs`). Climbing
//!   stops at the first kept level below its threshold; levels 8 and 10, which reshape a lobe,
//!   are skipped while no specular level has been kept.
//!        kept a higher level ──► move to it (Analysing; confirmed when its refit passes)
//!        none earned its place on 2 climbs' caches ──► Confirmed at ℓ, the simplest level with
//!        the lowest error (on fewer: inconclusive, climb again on the next cache)
//! ```
//! Every fit and every level tried becomes an [`Event`] for the log.

use super::cache::GroupCache;
use super::detail::{uniform_detail, Detail};
use super::event::Event;
use super::fitter::{
    assess, embed, fit_level, fit_level_above, fit_level_as, fit_on_tiles, lowers_error,
    refit_level, refit_reflectances, LevelFit,
};
use super::group::{GroupState, Status};
use super::level::{HierarchyOptions, Level};
use super::params::GroupParams;
use super::schedule::Turn;
use super::texture::{fit_textured, TextureState};
use crate::scene::atlas::Atlas;
use crate::scene::{Distribution, WardVariant};

/// A level contains the simpler levels it embeds ([`embed`]: anisotropic Ward with αx = αy and
/// θ = 0 is isotropic Ward), so its best fit on a cache is no worse than theirs in ε. A fit
/// that ends above one of them is a failed search, and the demotion check would judge the
/// level by it. The search descends the cross-half cost, which a lobe narrow beside the
/// spacing of the cache's directions can drive below zero with a few spiky samples (see
/// `objective::pooled`); ε keeps that noise and decides here. `fit` becomes the lowest ε of:
/// the level fitted again from the best such simpler fit (which it cannot end above,
/// [`fit_level_above`]), the same on the error's tiles ([`fit_on_tiles`]), and `previous`,
/// the group's answer at this level on earlier caches, assessed on this one. Returns the
/// event, when it did.
fn restart_from_nested(
    cache: &GroupCache,
    fit: &mut LevelFit,
    nested: &[LevelFit],
    previous: &GroupParams,
    variant: WardVariant,
) -> Option<Event> {
    let (lower, start) = (nested.iter())
        .filter(|f| f.error < fit.error)
        .filter_map(|f| Some((f, embed(f.level, &f.params, fit.level)?)))
        .min_by(|a, b| a.0.error.total_cmp(&b.0.error))?;
    let mut again = fit_level_above(
        cache,
        fit.level,
        &start,
        std::slice::from_ref(lower),
        variant,
    );
    if let Some(t) = fit_on_tiles(cache, fit.level, &start, variant) {
        let evals = again.evals + t.evals;
        if t.error < again.error {
            again = t;
        }
        again.evals = evals;
    }
    let kept = assess(cache, fit.level, previous, variant, again.evals + 1);
    let previous_kept = kept.error < again.error;
    let mut best = if previous_kept { kept } else { again };
    let event = Event::Restarted {
        level: fit.level,
        from: lower.level,
        error_before: fit.error,
        error_after: best.error,
        previous_kept,
    };
    best.evals += fit.evals;
    *fit = best;
    Some(event)
}

/// Algorithm 1's gate on a group's best uniform model: it tries a texture if it misses by the
/// texture threshold beyond its noise floor (gross: a small group's ε can reach the threshold
/// on its cache's noise alone), or leaves texel-scale structure that only a texture explains
/// ([`judged_detail`], this cache's with `earlier`, the same model's on the earlier caches;
/// [`detail_opens`]). Neither where the model is mostly reflection, which a texture would only
/// paint (`detail::reflection_holds_the_light`), nor on a group of fewer pixels than a texture
/// could be told from a per-pixel fit on (`detail::MIN_PIXELS`). Returns whether, the detail
/// judged, and whether gross.
fn texture_gate(
    cache: &GroupCache,
    best: &LevelFit,
    earlier: &[Detail],
    variant: WardVariant,
    opts: &HierarchyOptions,
) -> (bool, Detail, bool) {
    let parts = super::texture::uniform_parts(cache, best.level, &best.params, variant);
    let gross = best.error - best.noise_floor >= opts.thresholds.texture_error
        && cache.first_view().len() >= super::detail::MIN_PIXELS
        && !super::detail::reflection_holds_the_light(
            best.level,
            &best.params,
            &parts.model,
            &parts.spec,
        );
    let this = super::detail::parts_detail(cache, best.level, &best.params, &parts);
    let thr = opts.thresholds.texture_detail;
    let detail = judged_detail(this, earlier, best.error, best.noise_floor, thr);
    let opens = detail_opens(&detail, best.error, best.noise_floor, thr);
    (gross || opens, detail, gross)
}

/// Whether texel-scale structure `d` opens the gate (or reopens a confirmed group) for a
/// uniform fit of ε `error` over `noise_floor`: it is a texture's (`threshold`), and the fit
/// misses by more than its noise ([`DETAIL_GATE_NOISE`]) or the structure is twice as certain
/// as the gate asks elsewhere (z ≥ 2 × `detail::MIN_Z`).
fn detail_opens(d: &Detail, error: f32, noise_floor: f32, threshold: f32) -> bool {
    d.is_texture(threshold)
        && (error >= DETAIL_GATE_NOISE * noise_floor || d.z >= 2.0 * super::detail::MIN_Z)
}

/// How far above its noise floor a uniform fit's ε must be for structure of the usual
/// certainty to open the gate ([`detail_opens`]). At its noise floor the residual is mostly
/// the caches' noise, whose heavy tails (a few bright samples) the z-score's standard error
/// understates, and a texture fitted there takes that noise for a print. A real print seen
/// at the floor (one the tiled ε hardly sees) is far more certain than the usual bar.
const DETAIL_GATE_NOISE: f32 = 1.5;

/// The texel-scale structure a uniform model's texture decisions go by (the gate, a confirmed
/// group's reopening): `this` cache's, or, where that is no texture's, the structure pooled
/// with `earlier`, the same model's on earlier caches ([`Detail::pooled`]), provided the photo
/// shows more than noise there (ε at least [`POOLED_GATE_NOISE`] times the noise floor). A
/// small group's print (a staircase's wood) is certain on several caches before it is on one;
/// but where ε is its noise, what a uniform model leaves on every cache is the caches' own
/// correlated noise and misfit, which pooling would make look certain too.
fn judged_detail(
    this: Detail,
    earlier: &[Detail],
    error: f32,
    noise_floor: f32,
    threshold: f32,
) -> Detail {
    if this.is_texture(threshold) || earlier.is_empty() || error < POOLED_GATE_NOISE * noise_floor
    {
        return this;
    }
    let all: Vec<Detail> = earlier.iter().copied().chain([this]).collect();
    match Detail::pooled(&all) {
        Some(p) if p.is_texture(threshold) => p,
        _ => this,
    }
}

/// How far above its noise floor a group's ε must be for its texel-scale structure to be
/// judged pooled over its caches ([`judged_detail`]).
const POOLED_GATE_NOISE: f32 = 2.0;

/// The [`Event::Smoothing`] of a texture whose fit chose its smoothness weight.
fn smoothing_event(t: &TextureState) -> Option<Event> {
    (!t.held_out.is_empty()).then(|| Event::Smoothing {
        weight: t.smoothing,
        choices: super::texture::SMOOTHING_CHOICES.to_vec(),
        held_out: t.held_out.clone(),
    })
}

/// A texture that does not earn its place is tried again from the same level, its evidence
/// pooled with the earlier trials', up to this many trials in all.
const TEXTURE_TRIALS: u32 = 3;

/// What a climb found ([`GroupState::climb`]).
struct Climb {
    /// The best level's fit (the current level's if none earned its place) and its texture.
    best: LevelFit,
    texture: Option<TextureState>,
    /// Whether every level above the one kept was tried (or ruled out) on this cache.
    exhausted: bool,
    /// Whether a level not kept lowered ε by the margin (`conclude`).
    near_miss: bool,
    /// Level 7 was not tried because a group that lights this one is still analysing.
    texture_waits: bool,
    /// Level 7 was tried and did not earn its place, for good.
    texture_refused: bool,
    /// The texture trials' pooled evidence, this one included (None: no trial).
    texture_evidence: Option<(f32, f32, u32)>,
    /// The uniform levels above `best` tried and not kept that the photo could not tell from
    /// it ([`GroupState::alternatives`]).
    alternatives: Vec<(Level, GroupParams)>,
    /// The climbs' evidence, this climb's fits added ([`GroupState::climb_pool`]).
    pool: super::evidence::ClimbPool,
}

impl GroupState {
    /// Damps oscillation between global iterations. Groups that see each other (a wall and the
    /// glossy floor reflecting it) can make the fixed-point iteration of the notes alternate
    /// around its limit: ρ(t+1) − ρ(t) ≈ r (ρ(t) − ρ(t−1)) with r < 0. Where a channel's step
    /// reverses, take the secant (Aitken) estimate of the limit, ρ(t) + Δ / (1 − r), with r
    /// kept in [−0.9, 0]. Monotone steps are left alone: extrapolating them too makes a noisy
    /// scene (the glossy figure6's caustics) diverge.
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
            self.params = self.params.clamped(self.level);
        }
        self.last_step = Some((self.params.rho_d - old.rho_d, self.params.rho_s - old.rho_s));
    }

    /// The fit of the current level on the cache (level 7: the lobe, then the texture warm-
    /// started from the last one), and the new texture.
    ///
    /// Levels 8–10 fit each microfacet distribution on its own and add ε(GGX) − ε(Beckmann) to
    /// the group's [`GroupState::distribution_evidence`]; the fit returned is that of the
    /// distribution with the lower ε summed over every cache at the level, this one included.
    /// A distribution is chosen by the evidence of all the caches, never by the last alone: on
    /// a material that is neither, the two fit about as well, and a choice per cache flips
    /// between them (and between their very different α) from one iteration to the next.
    fn fit_current(
        &mut self,
        cache: &GroupCache,
        atlas: Option<&Atlas>,
        variant: WardVariant,
    ) -> (LevelFit, Option<TextureState>) {
        if self.level == Level::Textured {
            if let (Some(a), Some(t)) = (atlas, &self.texture) {
                if let Some(r) =
                    fit_textured(cache, a, t.base, &self.params, Some(t), variant, false)
                {
                    return (r.0, Some(r.1));
                }
            }
        }
        // After two fits at its level that descended every start, a race of the starts.
        let warm = self.iterations_at_level >= 2;
        if self.level.has_distribution() {
            let one = |d| fit_level_as(cache, self.level, &self.params, variant, d, warm);
            let (ggx, beckmann) = (one(Distribution::Ggx), one(Distribution::Beckmann));
            let d = (ggx.error - beckmann.error) as f64;
            let (sum, squares, n) = self.distribution_evidence.get_or_insert((0.0, 0.0, 0));
            (*sum, *squares, *n) = (*sum + d, *squares + d * d, *n + 1);
            let evals = ggx.evals + beckmann.evals;
            let mut fit = if *sum > 0.0 { beckmann } else { ggx };
            fit.evals = evals;
            return (fit, None);
        }
        let fit = if warm {
            refit_level(cache, self.level, &self.params, variant)
        } else {
            fit_level(cache, self.level, &self.params, variant)
        };
        (fit, None)
    }

    /// Whether a confirmed level `current` still lowers the error of the simpler `lower` on
    /// the same cache: by the margin, and on at least one half of the samples.
    fn holds(lower: &LevelFit, current: &LevelFit, opts: &HierarchyOptions) -> bool {
        let gain = lower.error - current.error;
        let mut halves = (0..2).map(|k| lower.halves[k] - current.halves[k]);
        gain > opts.margin * lower.error && halves.any(|g| g > 0.0)
    }

    /// Whether `better` lowers the error of `base` by a clear margin on the same cache.
    fn earns(base: &LevelFit, better: &LevelFit, opts: &HierarchyOptions) -> (bool, f32) {
        lowers_error(base, better, opts.margin, opts.noise_factor)
    }

    /// Whether `better` (a higher level that earned its place on the whole cache) also predicts
    /// pixels it was not fitted to, so that a wall cannot turn glossy to absorb a neighbour's
    /// error: both levels' reflectances are fitted on the even tiles and judged on the odd
    /// ones, then the other way round, and at least half of the in-sample gain must remain on
    /// the held-back pixels. Returns the verdict and the held-out ε of `base` and `better`. A
    /// group too small to split (a half with no pixel) is not judged.
    ///
    /// The lobes keep the shape the whole cache gave them: a narrow highlight on a small curved
    /// object covers a tile or two, and a half without it has nothing to place a lobe's width
    /// by, so a width searched there can predict the other half worse than a mirror does. A
    /// lobe that only absorbs an error on a few tiles still fails: the half without them gives
    /// it no amplitude.
    fn predicts(
        cache: &GroupCache,
        base: &LevelFit,
        better: &LevelFit,
        variant: WardVariant,
    ) -> (bool, [f32; 2]) {
        let halves = cache.split_tiles();
        if halves.iter().any(|h| h.pixels.is_empty()) {
            return (true, [base.error, better.error]);
        }
        let mut held = [0.0f32; 2];
        for k in 0..2 {
            let (fit_on, judge_on) = (&halves[k], &halves[1 - k]);
            let fb = refit_reflectances(fit_on, base.level, &base.params, variant);
            let fh = refit_reflectances(fit_on, better.level, &better.params, variant);
            held[0] += 0.5 * assess(judge_on, base.level, &fb.params, variant, 0).error;
            held[1] += 0.5 * assess(judge_on, better.level, &fh.params, variant, 0).error;
        }
        let gain = base.error - better.error;
        (held[0] - held[1] >= 0.5 * gain, held)
    }

    /// Ends the analysis of a group the run left undecided (the iterations ran out): it is
    /// confirmed at its current level, the best one it kept, and the event says why it had not
    /// decided. `None` if the group was not analysing.
    pub fn decide_at_end(&mut self, opts: &HierarchyOptions, iterations: u32) -> Option<Event> {
        if self.status != Status::Analysing {
            return None;
        }
        let thr = opts.thresholds.of(self.level);
        let reason = match self.pending {
            Some(l) => format!(
                "{} earned its place but was still waiting for its turn to climb after {iterations} \
                 iterations; more iterations (--max-iterations) would let it move",
                l.name()
            ),
            None if self.iterations_at_level < 2 => format!(
                "it reached {} only {} iteration(s) before the end; more iterations \
                 (--max-iterations) would let it confirm or climb",
                self.level.name(),
                self.iterations_at_level
            ),
            None if self.climb_pool.climbs > 0 => format!(
                "no level above it earned its place on the {} cache(s) it climbed on, fewer than \
                 the {} a refusal is pooled over; more iterations (--max-iterations) would let \
                 it confirm or climb",
                self.climb_pool.climbs,
                super::evidence::CONFIRMING_CLIMBS
            ),
            None => "the rest of the scene never settled long enough for it to try the higher \
                 levels"
                .to_string(),
        };
        self.status = Status::Confirmed;
        self.note = Some(format!(
            "decided at the end of the run: kept {} with ε {:.4} (threshold {:.4}): {reason}",
            self.level.name(),
            self.error,
            thr
        ));
        Some(Event::Decided {
            level: self.level,
            error: self.error,
            reason,
        })
    }

    /// One global iteration for this group, given its freshly built cache and what the
    /// schedule allows it (`schedule::Turn`: whether it may try the higher levels now, the
    /// rest of the scene having settled; whether it may also move to one, groups that light
    /// each other moving one at a time; whether it must wait before trying level 7).
    /// A try that finds no better level confirms the group; one that finds a better level
    /// without leave to move changes nothing and is tried again later.
    /// `atlas`: the group's texture atlas, for level 7 (None: the group cannot be textured).
    pub fn step(
        &mut self,
        cache: &GroupCache,
        atlas: Option<&Atlas>,
        variant: WardVariant,
        opts: &HierarchyOptions,
        turn: &Turn,
    ) -> Vec<Event> {
        let mut events = self.fit_and_climb(cache, atlas, variant, opts, turn);
        self.detail = (atlas.is_some() && self.level != Level::Textured)
            .then(|| uniform_detail(cache, self.level, &self.params, variant));
        if self.detail_pool.last().is_some_and(|(l, _)| *l != self.level) {
            self.detail_pool.clear();
        }
        if let Some(d) = self.detail {
            self.detail_pool.push((self.level, d));
        }
        events.extend(self.reopen(opts));
        // At the level it ends at (a climb fits the new level on this cache too).
        let fits = match (&self.average, self.status) {
            (Some(a), Status::Confirmed) => a.1,
            _ => 1,
        };
        self.sigma = super::uncertainty::sigma(cache, self.level, &self.params, variant, fits);
        self.photo_noise = (self.level != Level::Textured)
            .then(|| super::fitter::photo_noise(cache, self.level, &self.params, variant))
            .flatten();
        let scatter = self.fit_scatter();
        if let (Some(sd), Some((scatter, n)), Status::Confirmed) =
            (&mut self.sigma, scatter, self.status)
        {
            *sd = super::uncertainty::with_scatter(sd, &scatter, n);
        }
        events
    }

    /// Algorithm 1's gate asked again of a textured group, after a group that lights it changed
    /// level. The texture was chosen because every uniform model missed, but against the light
    /// of that group's old model: a glossy floor that climbed while the mirror beside it was
    /// still diffuse found no lobe for the highlights the mirror sends it and took a texture,
    /// which then kept them for good. The uniform levels are fitted as a climb would (each
    /// must earn its place over the one below); if the best now passes the gate (ε within the
    /// texture threshold beyond the noise, and no coherent detail) on two caches in a row, the
    /// second judged with the first's structure pooled, the group goes back to it and is
    /// analysed again from there; otherwise it says what kept the texture. After the first
    /// such cache it is doubted and asked again on the next: a faint print's structure sits
    /// near the gate's threshold on any one cache, and one cache must not undo a texture that
    /// several caches earned.
    fn untexture(
        &mut self,
        cache: &GroupCache,
        variant: WardVariant,
        opts: &HierarchyOptions,
    ) -> Option<Event> {
        cache.texels.as_ref()?;
        let mut best = fit_level(cache, Level::Diffuse, &self.params, variant);
        for level in [Level::Isotropic, Level::Anisotropic]
            .into_iter()
            .filter(|_| opts.ward)
        {
            let f = fit_level(cache, level, &best.params, variant);
            if Self::earns(&best, &f, opts).0 {
                best = f;
            }
        }
        let earlier: Vec<Detail> = self.texture_doubt.into_iter().collect();
        let (texture, detail, _) = texture_gate(cache, &best, &earlier, variant, opts);
        if texture {
            self.texture_doubt = None;
            return Some(Event::TextureKept {
                level: best.level,
                error: best.error,
                noise_floor: best.noise_floor,
                detail: detail.rms,
            });
        }
        if self.texture_doubt.is_none() {
            // Closed, the judged structure is this cache's own.
            self.texture_doubt = Some(detail);
            self.recheck_texture = true;
            return Some(Event::Doubted {
                level: self.level,
                lower: best.level,
                error: self.error,
                error_lower: best.error,
            });
        }
        self.texture_doubt = None;
        Some(self.demote(&best))
    }

    /// The structure its uniform `level` left on the earlier caches, if that is its level.
    fn detail_at(&self, level: Level) -> Vec<Detail> {
        (self.detail_pool.iter())
            .filter(|&&(l, _)| l == level)
            .map(|&(_, d)| d)
            .collect()
    }

    /// A confirmed group at a uniform level whose model leaves texel-scale structure that only
    /// a texture explains analyses again, so that its next climb tries level 7: a group
    /// confirmed early (its ε under the threshold before its cache could show the structure)
    /// is not kept from its texture. Not from a level whose texture was already refused.
    /// Decided as the gate decides ([`judged_detail`]: the latest cache's structure, or where
    /// ε is more than noise, the structure pooled over its caches at this level), so that a
    /// group the gate would turn away is not reopened again and again.
    fn reopen(&mut self, opts: &HierarchyOptions) -> Option<Event> {
        let (this, earlier) = self.detail_at(self.level).split_last().map(|(t, e)| (*t, e.to_vec()))?;
        let thr = opts.thresholds.texture_detail;
        let d = judged_detail(this, &earlier, self.error, self.noise_floor, thr);
        if self.status != Status::Confirmed
            || self.level == Level::Textured
            || self.texture_refused == Some(self.level)
            || !detail_opens(&d, self.error, self.noise_floor, thr)
        {
            return None;
        }
        self.status = Status::Analysing;
        self.note = None;
        Some(Event::Reopened {
            level: self.level,
            detail: d.rms,
            z: d.z,
            explained: d.explained,
        })
    }

    /// Goes back to the simpler level `f` fitted, to be analysed again from there.
    fn demote(&mut self, f: &LevelFit) -> Event {
        let event = Event::Demoted {
            from: self.level,
            to: f.level,
            error_before: self.error,
            error_after: f.error,
        };
        self.level = f.level;
        self.take(f);
        self.texture = None;
        self.doubted = None;
        self.texture_refused = None;
        self.pending_texture = None;
        self.texture_evidence = None;
        self.distribution_evidence = None;
        self.climb_pool = Default::default();
        self.iterations_at_level = 0;
        self.moves.clear();
        self.last_step = None;
        self.restart_average();
        self.status = Status::Analysing;
        // What was said of the level it left no longer holds.
        self.note = None;
        self.texture_waiting = false;
        event
    }

    /// [`GroupState::step`] but the parameters' σ.
    fn fit_and_climb(
        &mut self,
        cache: &GroupCache,
        atlas: Option<&Atlas>,
        variant: WardVariant,
        opts: &HierarchyOptions,
        turn: &Turn,
    ) -> Vec<Event> {
        let mut events = Vec::new();
        let Some(fit) = self.refit(cache, atlas, variant, opts, &mut events) else {
            return events;
        };
        if self.status != Status::Analysing {
            return events;
        }
        let thr = opts.thresholds.of(self.level);
        // Texel-scale structure the error's tiles average away (the texture threshold of
        // Algorithm 1).
        let textured_detail = atlas.is_some()
            && self.texture_refused != Some(self.level)
            && uniform_detail(cache, self.level, &fit.params, variant)
                .is_texture(opts.thresholds.texture_detail);
        if fit.error < thr && !textured_detail {
            self.status = Status::Confirmed;
            events.push(Event::Confirmed {
                level: self.level,
                error: fit.error,
                below_threshold: true,
            });
            return events;
        }
        // The count includes this iteration's fit; the rule is on those before it.
        if !turn.may_climb || !super::schedule::has_settled_at_level(self.iterations_at_level - 1) {
            return events;
        }
        let climb = self.climb(fit, cache, atlas, variant, opts, turn, &mut events);
        self.conclude(climb, thr, opts, turn, &mut events);
        events
    }

    /// The iterative principle: the current level refitted on this cache (level 7: its texture
    /// too), restarted from a simpler level it contains where its search ended above it, and
    /// checked against the simpler levels of a confirmed group (two caches in a row that a
    /// simpler level explains as well demote it). Takes the fit into the group's parameters
    /// (into its mean once confirmed, damped while analysing) and returns it; None when the
    /// group's turn ends here (doubted, demoted, or confirmed above level 1).
    fn refit(
        &mut self,
        cache: &GroupCache,
        atlas: Option<&Atlas>,
        variant: WardVariant,
        opts: &HierarchyOptions,
        events: &mut Vec<Event>,
    ) -> Option<LevelFit> {
        let (mut fit, texture) = self.fit_current(cache, atlas, variant);
        events.push(Event::Fit {
            level: self.level,
            error: fit.error,
            noise_floor: fit.noise_floor,
            evals: fit.evals,
        });
        let old = self.params;
        // A confirmed group's simpler levels on this cache, for the demotion check below.
        let demotable = self.status == Status::Confirmed
            && self.level != Level::Diffuse
            && self.level != Level::Textured;
        let nested: Vec<LevelFit> = if demotable {
            let needs = self.cache_needs_for(self.level, false);
            (Level::FITTED.iter().copied())
                .filter(|&l| l < self.level && (opts.ward || !l.is_ward()))
                .filter(|&l| {
                    (!l.has_lobe() || needs.lobe_samples) && (!l.is_mirror() || needs.mirror)
                })
                .map(|l| fit_level(cache, l, &old, variant))
                .collect()
        } else {
            Vec::new()
        };
        if let Some(e) = restart_from_nested(cache, &mut fit, &nested, &old, variant) {
            events.push(e);
        }
        // Demotion check: does a simpler level (available in this cache) do as well? The
        // level keeps its place while it lowers ε by the margin and on at least one half of
        // the samples: a climb's noise test asks for evidence of a gain, and one noisy cache
        // would otherwise undo a level that the photo showed on the ones before. So it goes
        // back only when two caches in a row say so; a cache that says so once is an outlier
        // (its fit, often a search that ended near the simpler level, stays out of the mean).
        if let Some(lower) = nested.iter().find(|f| !Self::holds(f, &fit, opts)) {
            if self.doubted.is_some() {
                self.take(&fit);
                events.push(self.demote(lower));
            } else {
                self.iterations_at_level += 1;
                self.doubted = Some(lower.level);
                self.error = fit.error;
                self.noise_floor = fit.noise_floor;
                events.push(Event::Doubted {
                    level: self.level,
                    lower: lower.level,
                    error: fit.error,
                    error_lower: lower.error,
                });
            }
            return None;
        }
        self.doubted = None;
        self.take(&fit);
        if self.status == Status::Confirmed {
            self.accumulate(cache.pixels.len().max(1) as f32);
        } else if texture.is_some() {
            // A texture's mean ρd moves with its texels: nothing to damp.
        } else if self.iterations_at_level > 0 {
            self.damp(&old);
        } else {
            self.last_step = None;
        }
        if let Some(new) = texture {
            events.extend(smoothing_event(&new));
            self.take_texture(new);
        }
        self.iterations_at_level += 1;
        if self.level == Level::Textured && std::mem::take(&mut self.recheck_texture) {
            if let Some(e) = self.untexture(cache, variant, opts) {
                let demoted = matches!(e, Event::Demoted { .. });
                events.push(e);
                if demoted {
                    return None;
                }
            }
        }
        if demotable {
            return None;
        }
        Some(fit)
    }

    /// The hierarchical principle: the levels above the current one tried in order on the same
    /// cache, each kept only where it earns its place over the best so far (and, but for the
    /// texture, predicts held-back tiles); level 7 only through Algorithm 1's gate.
    #[allow(clippy::too_many_arguments)]
    fn climb(
        &self,
        fit: LevelFit,
        cache: &GroupCache,
        atlas: Option<&Atlas>,
        variant: WardVariant,
        opts: &HierarchyOptions,
        turn: &Turn,
        events: &mut Vec<Event>,
    ) -> Climb {
        let mut pool = self.climb_pool.clone();
        pool.record(&fit);
        let mut best = fit.clone();
        let mut tried = vec![fit];
        // Per fit in `tried`, the noise of its gain over the level kept below it (0: the
        // current level's own fit).
        let mut tried_noise = vec![0.0f32];
        let mut level = self.level;
        let mut texture = None;
        // Whether every level above the one kept was tried (or ruled out) on this cache.
        let mut exhausted = true;
        // The lowest ε of the levels tried and not kept (not the texture's).
        let mut rejected = f32::INFINITY;
        // Level 7 was not tried because a group that lights this one is still analysing.
        let mut texture_waits = false;
        // Level 7 was tried and did not earn its place, for good; the trials' pooled evidence.
        let mut texture_refused = false;
        let mut texture_evidence = None;
        while let Some(next) = level.next() {
            let started = std::time::Instant::now();
            // Levels 8 and 10 reshape a lobe: a group on which no specular level earned its
            // place has none to reshape (a wall whose ε is its noise would only fit the noise).
            // Without the Ward levels, level 8 is the first lobe a group can take.
            let no_lobe = next.is_microfacet()
                && best.level == Level::Diffuse
                && (opts.ward || next != Level::Microfacet);
            let no_ward = next.is_ward() && !opts.ward;
            if ((next.is_microfacet() || next == Level::Plastic) && !opts.microfacet)
                || no_lobe
                || no_ward
            {
                level = next;
                continue;
            }
            if next == Level::Textured {
                let (open, d, gross) =
                    texture_gate(cache, &best, &self.detail_at(best.level), variant, opts);
                events.push(Event::TextureGate {
                    open,
                    level: best.level,
                    gross,
                    detail: d.rms,
                    z: d.z,
                    explained: d.explained,
                });
                if !open {
                    break;
                }
                if let Some(behind) = &turn.texture_waits_for {
                    texture_waits = true;
                    exhausted = false;
                    events.push(Event::TextureWaits {
                        behind: behind.clone(),
                        level: best.level,
                        error: best.error,
                    });
                    break;
                }
                // Algorithm 1 of the notes: every uniform model failed its threshold. A
                // per-texel model cannot be judged on held-out tiles (their texels are not
                // fitted); its gain must clear the margin and the noise like any other.
                //
                // The varnish. In one photo a bare texture can always mimic a highlight, so the
                // two cannot be told apart by ε on the texture level: the evidence for a lobe is
                // that a uniform Ward level earned its place, held-out tiles included. The
                // texture is then varnished with that lobe (refitted under the texture), unless
                // the bare texture fits significantly better (the lobe was the uniform model's
                // way to imitate the texture: a poster's "anisotropic" lobe).
                let Some(a) = atlas else { break };
                // A trial set aside for its turn starts from its texture.
                let fit = |base| {
                    let pending = self.pending_texture.as_ref().filter(|t| t.base == base);
                    super::texture::fit_textured(
                        cache,
                        a,
                        base,
                        &best.params,
                        pending,
                        variant,
                        true,
                    )
                };
                let Some(bare) = fit(Level::Diffuse) else {
                    break;
                };
                let (f, t) = match best.level.is_ward().then(|| fit(best.level)).flatten() {
                    Some(varnished) if !Self::earns(&varnished.0, &bare.0, opts).0 => varnished,
                    _ => bare,
                };
                // Pooled with the earlier trials from this level: a faint print's gain can
                // sit just under its noise on one cache and clear it on two together.
                let (single, gain_noise) = Self::earns(&best, &f, opts);
                let gain = best.error - f.error;
                let (g, v, n) = self.texture_evidence.unwrap_or((0.0, 0.0, 0));
                let pooled = (g + gain, v + gain_noise * gain_noise, n + 1);
                let kept = single
                    || gain > opts.margin * best.error
                        && pooled.0 > opts.noise_factor * pooled.1.sqrt();
                texture_evidence = Some(pooled);
                events.push(Event::Tried {
                    level: next,
                    error_before: best.error,
                    error_after: f.error,
                    noise_floor: f.noise_floor,
                    gain_noise,
                    held_out: None,
                    kept,
                    caches: pooled.2,
                    fit_seconds: started.elapsed().as_secs_f32(),
                });
                if kept {
                    best = f;
                    texture = Some(t);
                } else if gain <= opts.margin * best.error || pooled.2 >= TEXTURE_TRIALS {
                    texture_refused = true;
                }
                break;
            }
            let last = tried.last().expect("the current level's fit");
            let start = GroupParams {
                alpha_x: last.params.alpha_x,
                alpha_y: last.params.alpha_y,
                theta: last.params.theta,
                distribution: last.params.distribution,
                ..best.params
            };
            let f = fit_level_above(cache, next, &start, &tried, variant);
            // Judged on this cache pooled with the earlier climbs' at this level
            // (`evidence.rs`): one cache's noise no longer decides.
            pool.record(&f);
            let p = pool
                .gain(best.level, next)
                .expect("both levels fitted on this cache");
            let (mut earned, gain_noise) = (p.clear(opts.margin, opts.noise_factor), p.noise);
            // Level 10 searches its shape on a plain cost on tiles (`objective::pooled`; only
            // its last few steps subtract the noise), which trades the cache's noise for bias
            // and so can lower ε as no unbiased fit does: it must also lower the unbiased
            // cross-half cost, or it only fits the noise.
            if next == Level::AnisotropicMicrofacet && p.cost <= 0.0 {
                earned = false;
            }
            let (kept, held_out) = if earned {
                let (_, held) = Self::predicts(cache, &best, &f, variant);
                pool.record_held(best.level, next, held);
                let ok = pool.predicts(best.level, next).unwrap_or(true);
                (ok, Some(held))
            } else {
                (false, None)
            };
            events.push(Event::Tried {
                level: next,
                error_before: best.error,
                error_after: f.error,
                noise_floor: f.noise_floor,
                gain_noise,
                held_out,
                kept,
                caches: p.caches,
                fit_seconds: started.elapsed().as_secs_f32(),
            });
            level = next;
            if kept {
                best = f.clone();
                // Below its threshold, unless it leaves the structure only a texture explains.
                let detail = || {
                    atlas.is_some()
                        && uniform_detail(cache, next, &f.params, variant)
                            .is_texture(opts.thresholds.texture_detail)
                };
                if f.error < opts.thresholds.of(next) && !detail() {
                    exhausted = level.next().is_none();
                    break;
                }
            } else {
                rejected = rejected.min(f.error);
            }
            tried.push(f);
            tried_noise.push(gain_noise);
        }
        // A level that lowered ε by the margin but failed another test (its gain's noise, level
        // 10's unbiased cost, the held-out tiles) is a near miss, which a later climb on a
        // settled cache may pass.
        let near_miss = rejected < (1.0 - opts.margin) * best.error;
        // Levels above the kept one that the photo cannot tell from it: those that fit at
        // least as well, and those that fit worse by no more than the margin the kept level's
        // test demands of a gain (`noise_factor` times the gain's noise), for the test that
        // would reject them cannot reject them either.
        let alternatives = (tried.iter().zip(&tried_noise))
            .filter(|(f, _)| f.level.number() > best.level.number() && f.level != Level::Textured)
            .filter(|(f, &n)| f.error <= best.error + opts.noise_factor * n)
            .map(|(f, _)| (f.level, f.params))
            .collect();
        Climb {
            best,
            texture,
            exhausted,
            near_miss,
            texture_waits,
            texture_refused,
            texture_evidence,
            alternatives,
            pool,
        }
    }

    /// The climb's outcome: the group moves to the best level it found (or waits for its turn
    /// to move), or, where none earned its place, is confirmed at its own.
    fn conclude(
        &mut self,
        climb: Climb,
        thr: f32,
        opts: &HierarchyOptions,
        turn: &Turn,
        events: &mut Vec<Event>,
    ) {
        let Climb {
            best,
            texture,
            exhausted,
            near_miss,
            texture_waits,
            texture_refused,
            texture_evidence,
            alternatives,
            mut pool,
        } = climb;
        pool.finish_climb();
        self.climb_pool = pool;
        self.alternatives = alternatives;
        self.texture_waiting = texture_waits;
        self.texture_waits += u32::from(texture_waits);
        if texture_evidence.is_some() {
            self.texture_evidence = texture_evidence;
        }
        if texture_refused {
            self.texture_refused = Some(self.level);
            self.pending_texture = None;
        }
        // A texture does not wait for the turn: the turn keeps two groups that light each other
        // from changing their light at once, and a texture keeps its group's mean reflectance
        // (its neighbours see nearly the same light), while the neighbours whose missing light
        // it could take have been waited for already (`Turn::texture_waits_for`). Among many
        // groups that light each other the turn came too rarely for a printed wall to get it.
        // In the run's last iterations no group moves to a uniform level
        // (`schedule::CLOSING`).
        let waits = (!turn.may_move || turn.closing) && best.level != Level::Textured;
        if best.level != self.level && waits {
            self.waiting += 1;
            self.pending = Some(best.level);
            if texture.is_some() {
                self.pending_texture = texture;
            }
            events.push(Event::Deferred { to: best.level });
        } else if best.level != self.level {
            self.waiting = 0;
            self.pending = None;
            events.push(Event::Moved {
                from: self.level,
                to: best.level,
            });
            self.level = best.level;
            self.take(&best);
            if let Some(t) = &texture {
                events.extend(smoothing_event(t));
            }
            self.texture = texture;
            self.pending_texture = None;
            self.texture_refused = None;
            self.texture_waits = 0;
            self.texture_evidence = None;
            self.distribution_evidence = None;
            self.climb_pool = Default::default();
            self.iterations_at_level = 0;
            self.moves.clear();
            self.last_step = None;
            // Every level above was tried on this cache, in a settled scene, and none earned
            // its place or came near it: a second climb once the move has settled would try
            // the same levels against nearly the same light. (A texture still converges texel
            // by texel; a confirmed mirror lends its ρs to the textures it shows, so its ρs
            // must settle first.)
            if exhausted && !near_miss && !matches!(self.level, Level::Textured | Level::Specular) {
                self.status = Status::Confirmed;
                self.note = Some(format!(
                    "no level above {} lowered the error by a clear margin in the climb that moved it there; kept with fit ε {:.4} above its threshold {:.4}",
                    self.level.name(),
                    self.error,
                    opts.thresholds.of(self.level)
                ));
                events.push(Event::Confirmed {
                    level: self.level,
                    error: self.error,
                    below_threshold: false,
                });
            }
        } else if !texture_waits && self.climb_pool.climbs < super::evidence::CONFIRMING_CLIMBS {
            self.waiting = 0;
            self.pending = None;
            events.push(Event::Inconclusive {
                level: self.level,
                caches: self.climb_pool.climbs,
            });
        } else if !texture_waits {
            self.status = Status::Confirmed;
            self.waiting = 0;
            self.pending = None;
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
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fit::cache::{synthetic_cache, synthetic_diffuse as diffuse, CachePixel};
    use crate::math::{Rgb, Vec3};

    /// A group analysing at level 1, settled there (two iterations), stepped once on `c` with
    /// its turn to climb: its state, the events and the levels its climb tried.
    fn climb(
        name: &str,
        c: &GroupCache,
        opts: &HierarchyOptions,
    ) -> (GroupState, Vec<Event>, Vec<Level>) {
        climb_in(name, c, opts, false)
    }

    /// [`climb`], in a run's closing iterations if `closing`.
    fn climb_in(
        name: &str,
        c: &GroupCache,
        opts: &HierarchyOptions,
        closing: bool,
    ) -> (GroupState, Vec<Event>, Vec<Level>) {
        let mut st = GroupState::new(name, Status::Analysing, GroupParams::default());
        st.iterations_at_level = 2;
        let turn = Turn {
            may_climb: true,
            may_move: true,
            texture_waits_for: None,
            closing,
        };
        let events = st.step(c, None, WardVariant::Ward1992, opts, &turn);
        let tried = events
            .iter()
            .filter_map(|e| match e {
                Event::Tried { level, .. } => Some(*level),
                _ => None,
            })
            .collect();
        (st, events, tried)
    }

    /// Ward lobe per unit ρs for the synthetic photos (the renderer's own lobe).
    fn ward(wo: Vec3, wi: Vec3, a: f32) -> f32 {
        let lobe = crate::render::bsdf::WardLobe {
            alpha_x: a,
            alpha_y: a,
            variant: WardVariant::Ward1992,
        };
        lobe.eval(wo, wi)
    }

    /// The held-out test (`predicts`): a Ward lobe on every tile of a group (a property of its
    /// material) predicts the tiles it was not fitted to and is kept; gloss on alternate tiles
    /// only (light a stale neighbour misses on part of a wall, not the wall's material) does
    /// not: fitted on the glossy tiles the lobe predicts the others worse than Lambert does.
    #[test]
    fn a_level_is_kept_only_if_it_predicts_held_back_pixels() {
        let v = WardVariant::Ward1992;
        let make = |all_tiles: bool| {
            synthetic_cache(
                480,
                48,
                24,
                7,
                move |p: &CachePixel, s: &[(Vec3, Vec3, Rgb)]| {
                    let lobe: Rgb = s
                        .iter()
                        .map(|&(wo, wi, c)| c * ward(wo, wi, 0.2))
                        .fold(Rgb::ZERO, |a, b| a + b);
                    if all_tiles {
                        0.5 * diffuse(s) + 0.3 * lobe
                    } else if p.tile.is_multiple_of(2) {
                        0.1 * diffuse(s) + 0.8 * lobe
                    } else {
                        0.1 * diffuse(s)
                    }
                },
            )
        };
        let fits = |c: &GroupCache| {
            let f0 = fit_level(c, Level::Diffuse, &GroupParams::default(), v);
            let f1 = fit_level_above(
                c,
                Level::Isotropic,
                &GroupParams::default(),
                std::slice::from_ref(&f0),
                v,
            );
            (f0, f1)
        };
        let (c, opts) = (make(true), HierarchyOptions::default());
        let (f0, f1) = fits(&c);
        let (ok, held) = GroupState::predicts(&c, &f0, &f1, v);
        assert!(
            ok && held[0] - held[1] >= 0.5 * (f0.error - f1.error),
            "{held:?} {} {}",
            f0.error,
            f1.error
        );
        let (st, events, _) = climb("sphere", &c, &opts);
        assert_eq!(st.level, Level::Isotropic, "{events:?}");
        assert!(events.iter().any(|e| matches!(
            e,
            Event::Tried {
                level: Level::Isotropic,
                held_out: Some(_),
                kept: true,
                ..
            }
        )));
        let c = make(false);
        let (f0, f1) = fits(&c);
        assert!(f1.error < f0.error);
        let (ok, held) = GroupState::predicts(&c, &f0, &f1, v);
        assert!(!ok && held[1] > held[0], "{held:?}");
    }

    /// Anisotropic Ward contains isotropic Ward: an anisotropic fit that ended above the
    /// isotropic one is a failed search (here a lobe far too bright and turned), which the demotion
    /// check must not take for the photo's verdict. The restart from the isotropic fit, the
    /// group's previous answer where it explains the cache, or else the search on the error's
    /// tiles finds the lobe (αy/αx = 3, θ = 0). A fit no worse than the simpler one is left
    /// alone.
    #[test]
    fn a_fit_worse_than_a_level_it_contains_is_restarted() {
        let v = WardVariant::Ward1992;
        let lobe = crate::render::bsdf::WardLobe {
            alpha_x: 0.12,
            alpha_y: 0.36,
            variant: v,
        };
        let c = synthetic_cache(480, 256, 24, 3, |_, s: &[(Vec3, Vec3, Rgb)]| {
            let spec = (s.iter()).fold(Rgb::ZERO, |a, &(wo, wi, c)| a + c * lobe.eval(wo, wi));
            0.3 * diffuse(s) + 0.4 * spec
        });
        let truth = GroupParams {
            rho_d: Rgb::splat(0.3),
            rho_s: Rgb::splat(0.4),
            alpha_x: 0.12,
            alpha_y: 0.36,
            ..GroupParams::default()
        };
        let turned = GroupParams {
            rho_s: Rgb::splat(0.8),
            alpha_x: 0.36,
            alpha_y: 0.12,
            ..truth
        };
        let iso = fit_level(&c, Level::Isotropic, &GroupParams::default(), v);
        let failed = assess(&c, Level::Anisotropic, &turned, v, 0);
        assert!(
            failed.error > iso.error,
            "{} vs {}",
            failed.error,
            iso.error
        );
        let nested = std::slice::from_ref(&iso);

        let mut fit = failed.clone();
        let event = restart_from_nested(&c, &mut fit, nested, &truth, v);
        let Some(Event::Restarted {
            from: Level::Isotropic,
            previous_kept,
            ..
        }) = event
        else {
            panic!("{event:?}");
        };
        assert_eq!(fit.level, Level::Anisotropic);
        let at_truth = assess(&c, Level::Anisotropic, &truth, v, 0).error;
        assert!(at_truth < 0.7 * iso.error, "{at_truth} vs {}", iso.error);
        // The previous answer is kept unless the restarted search fits better still.
        assert!(fit.error <= at_truth, "{} vs {at_truth}", fit.error);
        assert_eq!(previous_kept, fit.error == at_truth);
        let aligned = |p: GroupParams| {
            let turn = p.theta.rem_euclid(std::f32::consts::PI);
            turn.min(std::f32::consts::PI - turn) < 0.1 && p.alpha_y > 1.5 * p.alpha_x
        };
        assert!(aligned(fit.params), "{:?}", fit.params);

        let mut refit = failed.clone();
        let event = restart_from_nested(&c, &mut refit, nested, &turned, v);
        assert!(
            matches!(
                event,
                Some(Event::Restarted {
                    previous_kept: false,
                    ..
                })
            ),
            "{event:?}"
        );
        assert_eq!(refit.level, Level::Anisotropic);
        assert!(
            refit.error < 0.7 * iso.error,
            "{} vs {}",
            refit.error,
            iso.error
        );
        assert!(aligned(refit.params), "{:?}", refit.params);

        let mut good = fit.clone();
        assert_eq!(restart_from_nested(&c, &mut good, nested, &turned, v), None);
        assert_eq!(good.error, fit.error);
    }

    /// A confirmed level keeps its place on a cache where its gain is clear but noisy (the
    /// halves disagree by more than a climb accepts), and loses it where the gain is below
    /// the margin or both halves prefer the simpler level.
    #[test]
    fn a_confirmed_level_holds_on_a_noisy_gain_and_not_on_a_small_one() {
        let opts = HierarchyOptions::default();
        let fit = |level, error: f32, halves| LevelFit {
            level,
            params: GroupParams::default(),
            error,
            noise_floor: 0.0,
            halves,
            cost: 0.0,
            evals: 0,
        };
        let iso = fit(Level::Isotropic, 0.059, [0.059, 0.059]);
        // 28% lower, but the halves' gains differ by more than a third of it.
        let noisy = fit(Level::Anisotropic, 0.043, [0.030, 0.056]);
        assert!(!GroupState::earns(&iso, &noisy, &opts).0);
        assert!(GroupState::holds(&iso, &noisy, &opts));
        let small = fit(Level::Anisotropic, 0.053, [0.052, 0.054]);
        assert!(!GroupState::holds(&iso, &small, &opts));
        let worse_on_both = fit(Level::Anisotropic, 0.043, [0.060, 0.061]);
        assert!(!GroupState::holds(&iso, &worse_on_both, &opts));
    }

    /// A confirmed level goes back to a simpler one only when two caches in a row find that
    /// one as good: after one such cache it keeps its level and its mean (that cache's fit
    /// stays out of it), and a cache on which it holds again clears the doubt.
    #[test]
    fn a_confirmed_level_is_demoted_only_by_two_caches_in_a_row() {
        let opts = HierarchyOptions::default();
        let v = WardVariant::Ward1992;
        let matte = |seed| synthetic_cache(480, 64, 24, seed, |_, s| 0.5 * diffuse(s));
        let glossy = |seed| {
            synthetic_cache(480, 64, 24, seed, |_, s: &[(Vec3, Vec3, Rgb)]| {
                let lobe = (s.iter()).fold(Rgb::ZERO, |a, &(wo, wi, c)| a + c * ward(wo, wi, 0.2));
                0.5 * diffuse(s) + 0.3 * lobe
            })
        };
        let confirmed = GroupParams {
            rho_d: Rgb::splat(0.5),
            rho_s: Rgb::splat(0.3),
            alpha_x: 0.2,
            alpha_y: 0.2,
            ..GroupParams::default()
        };
        let mut st = GroupState::new("desk", Status::Confirmed, confirmed);
        st.level = Level::Isotropic;
        let turn = Turn {
            may_climb: true,
            may_move: true,
            texture_waits_for: None,
            closing: false,
        };
        let step = |st: &mut GroupState, c: &GroupCache| st.step(c, None, v, &opts, &turn);
        let doubted = |e: &[Event]| e.iter().any(|e| matches!(e, Event::Doubted { .. }));
        let demoted = |e: &[Event]| e.iter().any(|e| matches!(e, Event::Demoted { .. }));

        let e = step(&mut st, &matte(1));
        assert!(doubted(&e) && !demoted(&e), "{e:?}");
        assert_eq!(
            (st.level, st.status, st.params),
            (Level::Isotropic, Status::Confirmed, confirmed)
        );
        let e = step(&mut st, &glossy(2));
        assert!(!doubted(&e) && !demoted(&e), "{e:?}");
        assert_eq!((st.level, st.doubted), (Level::Isotropic, None));
        let e = step(&mut st, &matte(3));
        assert!(doubted(&e) && !demoted(&e), "{e:?}");
        let e = step(&mut st, &matte(4));
        assert!(demoted(&e), "{e:?}");
        assert_eq!(
            (st.level, st.status, st.doubted),
            (Level::Diffuse, Status::Analysing, None)
        );
    }

    /// A Lambert surface seen with few samples (ε well above the diffuse threshold, all of it
    /// noise) climbs through the mirror, Ward and plastic levels, but not through 8 and 10: with
    /// no lobe kept there is none to reshape.
    #[test]
    fn a_group_with_no_lobe_skips_the_levels_that_reshape_one() {
        let c = synthetic_cache(480, 4, 24, 11, |_, s| 0.5 * diffuse(s));
        let opts = HierarchyOptions::default();
        let (st, events, tried) = climb("wall", &c, &opts);
        assert!(st.error > opts.thresholds.diffuse, "{events:?}");
        assert_eq!(st.level, Level::Diffuse, "{events:?}");
        assert!(
            tried.contains(&Level::Anisotropic) && tried.contains(&Level::Plastic),
            "{tried:?}"
        );
        assert!(!tried.iter().any(|l| l.is_microfacet()), "{tried:?}");
    }

    /// A group whose reflectance changes from tile to tile (no uniform level comes within the
    /// texture threshold) passes Algorithm 1's gate. Told to wait for a neighbour, it does not
    /// try level 7 and is not confirmed: it stays analysing, marked as waiting, and holds no
    /// one back. Not told to wait, the same climb ends it (here without an atlas, nothing
    /// earns its place: inconclusive, to be confirmed by the next cache's climb).
    #[test]
    fn a_group_that_waits_for_a_neighbour_does_not_try_a_texture() {
        let patchy = synthetic_cache(480, 16, 24, 5, |p, s| {
            if p.tile % 2 == 0 {
                0.1 * diffuse(s)
            } else {
                0.8 * diffuse(s)
            }
        });
        let opts = HierarchyOptions::default();
        let step = |waits: Option<&str>| {
            let mut st = GroupState::new("poster", Status::Analysing, GroupParams::default());
            st.iterations_at_level = 2;
            let turn = Turn {
                may_climb: true,
                may_move: true,
                texture_waits_for: waits.map(str::to_string),
                closing: false,
            };
            let events = st.step(&patchy, None, WardVariant::Ward1992, &opts, &turn);
            (st, events)
        };
        let (st, events) = step(Some("mirror"));
        assert!(
            st.error - st.noise_floor >= opts.thresholds.texture_error,
            "{events:?}"
        );
        assert!(
            events.iter().any(|e| matches!(e,
                Event::TextureWaits { behind, .. } if behind == "mirror")),
            "{events:?}"
        );
        assert_eq!(st.status, Status::Analysing, "{events:?}");
        assert!(st.texture_waiting);
        let (st, events) = step(None);
        assert!(!events
            .iter()
            .any(|e| matches!(e, Event::TextureWaits { .. })));
        assert!(events.iter().any(|e| matches!(e, Event::Inconclusive { .. })));
        assert!(!st.texture_waiting);
    }

    /// Texel-scale structure of the usual certainty (5% RMS, z 5) reopens a confirmed group
    /// whose ε is twice its noise floor, and not one whose ε is its noise floor; structure
    /// twice as certain (z 10) reopens both.
    #[test]
    fn structure_at_the_noise_floor_reopens_a_group_only_if_twice_as_certain() {
        let opts = HierarchyOptions::default();
        let reopens = |error: f32, z: f32| {
            let print = Detail {
                rms: 0.05,
                z,
                explained: 0.5,
            };
            assert!(print.is_texture(opts.thresholds.texture_detail));
            let mut st = GroupState::new("plastic", Status::Confirmed, GroupParams::default());
            st.detail_pool = vec![(Level::Diffuse, print)];
            (st.error, st.noise_floor) = (error, 0.05);
            st.reopen(&opts).is_some()
        };
        assert!(reopens(0.1, 5.0));
        assert!(!reopens(0.05, 5.0));
        assert!(reopens(0.05, 10.0));
    }

    /// A group of fewer pixels than a texture can be told from a per-pixel fit on does not try
    /// one, however far its uniform levels miss: the same patchy group with 12 pixels, gross,
    /// keeps the gate shut.
    #[test]
    fn a_group_of_a_few_pixels_is_never_textured() {
        let patchy = |n| {
            synthetic_cache(n, 16, n.min(24), 5, |p, s| {
                if p.tile % 2 == 0 {
                    0.1 * diffuse(s)
                } else {
                    0.8 * diffuse(s)
                }
            })
        };
        let opts = HierarchyOptions::default();
        let turn = Turn {
            may_climb: true,
            may_move: true,
            texture_waits_for: Some("mirror".to_string()),
            closing: false,
        };
        let gate = |n: usize| {
            let mut st = GroupState::new("handle", Status::Analysing, GroupParams::default());
            st.iterations_at_level = 2;
            let events = st.step(&patchy(n), None, WardVariant::Ward1992, &opts, &turn);
            assert!(
                st.error - st.noise_floor >= opts.thresholds.texture_error,
                "{n}: {events:?}"
            );
            events
                .iter()
                .find_map(|e| match e {
                    Event::TextureGate { open, gross, .. } => Some((*open, *gross)),
                    _ => None,
                })
                .expect("the gate was asked")
        };
        assert_eq!(gate(480), (true, true));
        assert_eq!(gate(12), (false, false));
    }

    /// A climb that tried every level above the one it moved to (none earned its place) ends
    /// the analysis there: the group is confirmed in the same step. One that stopped at a level
    /// below its threshold did not try the levels above it, and the group goes on analysing.
    #[test]
    fn a_move_is_confirmed_only_when_every_level_above_was_tried() {
        let opts = HierarchyOptions::default();
        let glossy = |samples: usize, seed: u64| {
            synthetic_cache(480, samples, 24, seed, |_, s: &[(Vec3, Vec3, Rgb)]| {
                let lobe: Rgb = s
                    .iter()
                    .map(|&(wo, wi, c)| c * ward(wo, wi, 0.2))
                    .fold(Rgb::ZERO, |a, b| a + b);
                0.5 * diffuse(s) + 0.4 * lobe
            })
        };
        // Few samples: the Ward level's ε stays above its threshold on the noise.
        let (st, events, tried) = climb("block", &glossy(32, 11), &opts);
        assert!(st.level.is_ward(), "{events:?}");
        assert!(st.error >= opts.thresholds.of(st.level), "{events:?}");
        assert!(tried.contains(&Level::Plastic), "{tried:?}");
        assert_eq!(st.status, Status::Confirmed, "{events:?}");
        let moved = events.iter().position(|e| matches!(e, Event::Moved { .. }));
        let confirmed = events
            .iter()
            .position(|e| matches!(e, Event::Confirmed { .. }));
        assert!(moved.is_some() && confirmed > moved, "{events:?}");
        // Many: the first Ward level meets its threshold and the climb stops there.
        let (st, events, tried) = climb("block", &glossy(384, 7), &opts);
        assert_eq!(st.level, Level::Isotropic, "{events:?}");
        assert!(st.error < opts.thresholds.of(st.level), "{events:?}");
        assert!(!tried.contains(&Level::Plastic), "{tried:?}");
        assert_eq!(st.status, Status::Analysing, "{events:?}");
    }

    /// In a run's last iterations (`schedule::CLOSING`) a climb that finds a better uniform
    /// level does not move there, even in its turn: the group waits with the level pending, and
    /// is decided at the end with a reason that says so. Before them, the same climb moves.
    #[test]
    fn no_group_moves_in_the_closing_iterations() {
        let opts = HierarchyOptions::default();
        let c = synthetic_cache(480, 384, 24, 7, |_, s: &[(Vec3, Vec3, Rgb)]| {
            let lobe: Rgb = (s.iter())
                .map(|&(wo, wi, c)| c * ward(wo, wi, 0.2))
                .fold(Rgb::ZERO, |a, b| a + b);
            0.5 * diffuse(s) + 0.4 * lobe
        });
        let (open, events, _) = climb("block", &c, &opts);
        assert_eq!(open.level, Level::Isotropic, "{events:?}");
        let (mut st, events, _) = climb_in("block", &c, &opts, true);
        assert_eq!(st.level, Level::Diffuse, "{events:?}");
        assert!(events.iter().any(|e| matches!(e, Event::Deferred { to: Level::Isotropic })));
        let decided = st.decide_at_end(&opts, 16);
        let Some(Event::Decided { reason, .. }) = decided else {
            panic!("{decided:?}");
        };
        assert!(reason.contains("isotropic") && reason.contains("--max-iterations"), "{reason}");
    }

    /// A mirror is not confirmed at its move, even by a climb that tried every level above:
    /// a confirmed mirror lends its ρs to the textures it shows, so the ρs must settle first.
    #[test]
    fn a_mirror_is_not_confirmed_at_its_move() {
        let opts = HierarchyOptions::default();
        // ρs 0.8 with ±15% of tile-to-tile scatter no lobe explains: ε stays above the
        // specular threshold, and no level above lowers it.
        let cache = synthetic_cache(480, 32, 24, 5, |p: &CachePixel, _| {
            p.mirror * (0.8 * (1.0 + 0.15 * (p.tile as f32 * 12.9898).sin()))
        });
        let (st, events, tried) = climb("mirror", &cache, &opts);
        assert_eq!(st.level, Level::Specular, "{events:?}");
        assert!(st.error >= opts.thresholds.of(st.level), "{events:?}");
        assert!(tried.contains(&Level::Plastic), "{tried:?}");
        assert_eq!(st.status, Status::Analysing, "{events:?}");
    }

    /// A climb that finds no level above is inconclusive: the group is confirmed only by a
    /// second climb on another cache, pooled with the first (`evidence::CONFIRMING_CLIMBS`).
    /// The levels that climb tried and did not keep are the kept level's alternatives (its
    /// albedo's model uncertainty) exactly when the gain test could not reject them either:
    /// they fitted no worse than the kept level by more than `noise_factor` times their gain's
    /// noise. A forced coat (plastic) on a matte wall fits slightly worse and is one of them.
    #[test]
    fn alternatives_are_the_levels_the_gain_test_cannot_tell_apart() {
        let opts = HierarchyOptions::default();
        // A matte wall with ±8% tile-to-tile scatter no model explains: ε stays above the
        // diffuse threshold and no level above earns its place.
        let wall = |seed: u64| {
            synthetic_cache(240, 16, 24, seed, |p: &CachePixel, s| {
                diffuse(s) * (0.5 * (1.0 + 0.08 * (p.tile as f32 * 12.9898).sin()))
            })
        };
        let (mut st, events, _) = climb("wall", &wall(1), &opts);
        assert_eq!((st.level, st.status), (Level::Diffuse, Status::Analysing), "{events:?}");
        assert!(events.iter().any(|e| matches!(e, Event::Inconclusive { caches: 1, .. })));
        let turn = Turn {
            may_climb: true,
            may_move: true,
            texture_waits_for: None,
            closing: false,
        };
        let events = st.step(&wall(2), None, WardVariant::Ward1992, &opts, &turn);
        let tried: Vec<Level> = (events.iter())
            .filter_map(|e| match e {
                Event::Tried { level, caches, .. } => {
                    assert_eq!(*caches, 2, "{events:?}");
                    Some(*level)
                }
                _ => None,
            })
            .collect();
        assert_eq!((st.level, st.status), (Level::Diffuse, Status::Confirmed), "{events:?}");
        assert!(tried.contains(&Level::Plastic), "{tried:?}");
        let mut expected = Vec::new();
        let mut worse = 0;
        for e in &events {
            if let Event::Tried {
                level,
                error_before,
                error_after,
                gain_noise,
                kept: false,
                ..
            } = *e
            {
                assert_eq!(error_before, st.error, "{events:?}");
                if error_after <= error_before + opts.noise_factor * gain_noise {
                    expected.push(level);
                    worse += usize::from(error_after > error_before);
                }
            }
        }
        let got: Vec<Level> = st.alternatives.iter().map(|a| a.0).collect();
        assert_eq!(got, expected, "{events:?}");
        assert!(worse >= 1, "no alternative fitted worse than the kept level: {events:?}");
    }

    /// A group still analysing when the iterations run out is confirmed at its level, and the
    /// event says which better level was still waiting.
    #[test]
    fn a_run_ends_with_every_group_decided() {
        let opts = HierarchyOptions::default();
        let mut st = GroupState::new("block", Status::Analysing, GroupParams::default());
        st.iterations_at_level = 5;
        st.pending = Some(Level::Isotropic);
        st.error = 0.09;
        match st.decide_at_end(&opts, 16) {
            Some(Event::Decided { level, reason, .. }) => {
                assert_eq!(level, Level::Diffuse);
                assert!(reason.contains("isotropic") && reason.contains("max-iterations"));
            }
            e => panic!("{e:?}"),
        }
        assert_eq!(st.status, Status::Confirmed);
        assert!(st.note.as_ref().unwrap().contains("decided at the end"));
        assert!(st.decide_at_end(&opts, 16).is_none());
    }
}
