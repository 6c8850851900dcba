//! One global iteration of the recovery, in its phases: the pixels each group's cache uses
//! ([`RecoveryLoop::choose_budget`]), then per fitted group in turn its cache
//! ([`RecoveryLoop::group_cache`]) and its fit and the hierarchy's decision
//! ([`RecoveryLoop::fit_group`]); then the photos' exposures ([`RecoveryLoop::update_exposures`]),
//! the unseen groups and the stray light ([`RecoveryLoop::update_unseen`]), and whether the scene
//! settled or converged ([`RecoveryLoop::settle`]).

use super::options::{pixel_budget, LogLine, RecoverError};
use super::run::{apply, ggx_samples, grey_card_factor, mirror_scale, texture_of, RecoveryLoop};
use super::run::{METAL_INDIRECT, TEXTURED_SAMPLES};
use crate::fit::cache::build::UnseenProbe;
use crate::fit::cache::{
    build, choose_pixels, CacheOptions, CacheRequest, GroupCache, Primary, PseudoTextures,
    STRAY_LIGHT,
};
use crate::fit::event::Event;
use crate::fit::group::{Motion, Status};
use crate::fit::level::Level;
use crate::fit::params::{largest_move, GroupParams};
use crate::fit::unseen::GroupShares;
use crate::fit::views::ExposureSums;
use crate::fit::{pseudo, schedule, unseen};
use crate::math::sampler::hash_seed;
use crate::math::Rgb;
use crate::photo::Photo;
use crate::render::PathTracer;
use crate::scene::Scene;
use std::time::Instant;

/// What one global iteration decides before it visits the groups.
struct Plan {
    it: u32,
    /// Each group's level and parameters as the iteration found them.
    levels_before: Vec<Level>,
    before: Vec<GroupParams>,
    /// The groups that may climb before the scene settles, and whose turn it is to move once
    /// it has (`schedule::climbers`).
    climbers: Vec<usize>,
    /// The order the groups are visited in: once the scene has settled, the climbers first,
    /// so that a turn one of them leaves unused can pass on to any later group
    /// (`schedule::takes_unused_turn`); then the others by index.
    order: Vec<usize>,
    /// The groups that changed to a level other than the texture so far this iteration:
    /// those a turn left unused must not light.
    moved: Vec<usize>,
    /// Unseen groups whose light every cache tracks (the stray light last).
    tracked: Vec<usize>,
    /// Whether no group may try level 7 yet (the stray light is not determined).
    hold_textures: bool,
}

/// What the unseen groups' phase found: how far their estimates moved, and how far they drifted
/// from what the averaged fits saw (`unseen::Estimates`).
struct UnseenMoves {
    moved: f32,
    drift: f32,
}

impl RecoveryLoop<'_> {
    /// One global iteration: every fitted group's cache rebuilt and refitted in turn, `log`
    /// receiving each event as it happens. A fit whose error or parameters are not finite stops
    /// the recovery with an error naming the group and the iteration (the state is then that of
    /// the failed iteration; the last checkpoint is the one to resume from).
    pub fn iterate(&mut self, log: &mut dyn FnMut(&LogLine)) -> Result<(), RecoverError> {
        let mut plan = self.plan();
        let mut shares = Vec::new();
        let mut sums = ExposureSums::new(self.exposures.len());
        for g in plan.order.clone() {
            if !self.states[g].is_fitted() {
                continue;
            }
            let tg = Instant::now();
            let cache = self.group_cache(g, &plan, log);
            let cache_secs = tg.elapsed().as_secs_f64();
            self.fit_group(g, cache, &mut plan, (tg, cache_secs), &mut shares, &mut sums, log)?;
        }
        let exposure_moved = self.update_exposures(&sums, plan.it);
        let unseen = self.update_unseen(&plan, &shares, log);
        self.settle(&plan, exposure_moved, unseen, log);
        Ok(())
    }

    /// The iteration's pixel budget (it doubles as the iterations go: `pixel_budget`), the
    /// groups that may climb, and the unseen groups every cache tracks.
    fn plan(&mut self) -> Plan {
        let (opts, it) = (self.opts, self.next);
        let budget = pixel_budget(opts, it);
        if budget != self.cap {
            self.cap = budget;
            self.choose_all(budget);
        }
        let levels_before: Vec<_> = self.states.iter().map(|s| s.level).collect();
        self.iterations = it + 1;
        let before: Vec<GroupParams> = self.states.iter().map(|s| s.params).collect();
        let climbers = schedule::climbers(&self.states, self.settled, &opts.hierarchy);
        let first: &[usize] = if self.settled { &climbers } else { &[] };
        let order: Vec<usize> = (first.iter().copied())
            .chain((0..self.states.len()).filter(|g| !first.contains(g)))
            .collect();
        // Unseen groups whose light every cache tracks, and the seen groups' shares of it.
        let mut tracked = if opts.unseen.enabled {
            unseen::unseen_groups(&self.states)
        } else {
            Vec::new()
        };
        // The stray light is tracked as one more unknown, last.
        if opts.stray_light {
            tracked.push(STRAY_LIGHT);
        }
        // While an open scene's stray light is not yet determined, no group tries level 7: a
        // texture takes the stray light's shape texel by texel and would hide it for good (a
        // textured group says nothing of it). Until half the iterations at most.
        let hold_textures = opts.stray_light
            && it < opts.max_iterations / 2
            && self.stray.as_ref().is_none_or(|s| s.open && !s.estimated);
        Plan {
            it,
            levels_before,
            before,
            order,
            climbers,
            moved: Vec::new(),
            tracked,
            hold_textures,
        }
    }

    /// Whether group `g` may try the levels above its own this iteration: once the scene has
    /// settled every group may; before, only a gross one (`schedule::climbers`).
    fn may_climb(&self, g: usize, plan: &Plan) -> bool {
        self.settled || plan.climbers.contains(&g)
    }

    /// Group `g`'s cache for this iteration, traced through the current scene: in the first
    /// photo, in every further photo through its view, and for a textured group in the confirmed
    /// mirrors that show it.
    fn group_cache(&mut self, g: usize, plan: &Plan, log: &mut dyn FnMut(&LogLine)) -> GroupCache {
        let (opts, it) = (self.opts, plan.it);
        let variant = self.scene.render.ward_variant;
        let textured = self.states[g].level == Level::Textured;
        if textured && self.pixel_lists[g].0.len() < self.texture_pixels()[g].len() {
            let cache_opts = CacheOptions {
                max_pixels: self.cap,
                ..opts.cache.clone()
            };
            // Textured: `choose` takes the texture's pixels, not these.
            self.pixel_lists[g] =
                self.choose(g, &cache_opts, self.scene.camera.width as usize, &[]);
            for k in 0..self.extra.len() {
                // Level 7 keeps every usable pixel of the view.
                let usable = self.extra[k].mask.pixels_of(g);
                self.extra[k].pixel_lists[g] = self.choose_in_view(k, g, &cache_opts, &usable);
            }
        }
        let level = self.states[g].level;
        let factor = match level {
            Level::Textured => TEXTURED_SAMPLES,
            Level::Microfacet | Level::Plastic => ggx_samples(self.states[g].params.alpha_x),
            Level::AnisotropicMicrofacet => {
                let p = &self.states[g].params;
                ggx_samples(p.alpha_x.min(p.alpha_y))
            }
            _ => 1,
        };
        let indirect = if level.is_microfacet() {
            factor * METAL_INDIRECT
        } else {
            factor
        };
        let cache_opts = CacheOptions {
            light_samples: opts.cache.light_samples * factor,
            indirect_samples: opts.cache.indirect_samples * indirect,
            ..opts.cache.clone()
        };
        let (px, tiles, n_tiles) = &self.pixel_lists[g];
        let atlas = self.atlases[g].as_deref();
        let needs = self.states[g].cache_needs(self.may_climb(g, plan));
        // §5.1: the groups still being analysed, as the mirror radiance may read them (one
        // photo only: the pseudo-textures read the photo's pixels).
        let analysing: Vec<bool> = self
            .states
            .iter()
            .enumerate()
            .map(|(i, s)| i != g && s.is_fitted() && s.status == Status::Analysing)
            .collect();
        let pseudo = (opts.pseudo_textures
            && self.extra.is_empty()
            && needs.mirror
            && analysing.contains(&true))
        .then(|| PseudoTextures {
            groups: analysing,
            usable: &self.mask.group,
            photo: self.photo_in_cache_units(),
        });
        let tracked = &plan.tracked;
        let probe: Vec<bool> = tracked
            .iter()
            .map(|&u| {
                u == STRAY_LIGHT
                    || unseen::worth_probing(&self.states[g], needs, u, &self.states[u])
            })
            .collect();
        let view_cache = |current: &Scene,
                          primary: Primary,
                          (px, tiles, n_tiles): (&[usize], &[u32], usize),
                          photo: &Photo,
                          pseudo: Option<&PseudoTextures>,
                          seed: u64| {
            let pt = PathTracer::new(current);
            let moved: Vec<(Scene, Rgb)> = tracked
                .iter()
                .map(|&u| match u {
                    STRAY_LIGHT => unseen::moved_stray(current),
                    u => unseen::moved_scene(current, &self.states[u]),
                })
                .collect();
            let moved_pt: Vec<Option<PathTracer>> = moved
                .iter()
                .zip(&probe)
                .map(|((s, _), &p)| p.then(|| PathTracer::new(s)))
                .collect();
            let probes: Vec<UnseenProbe> = tracked
                .iter()
                .zip(&moved)
                .zip(&moved_pt)
                .map(|((&group, (_, step)), pt)| UnseenProbe {
                    group,
                    moved: pt.as_ref(),
                    step: *step,
                })
                .collect();
            let req = CacheRequest {
                group: g,
                primary,
                pixels: px,
                tiles,
                n_tiles,
                photo: &photo.image.data,
                needs,
                atlas,
                unseen: &probes,
                pseudo,
                opts: &cache_opts,
                seed,
            };
            build(current, &pt, &req)
        };
        let mut cache = view_cache(
            &self.current,
            Primary::Camera,
            (px, tiles, *n_tiles),
            self.photo,
            pseudo.as_ref(),
            hash_seed(&[opts.seed, it as u64, g as u64]),
        );
        let reads_photo = pseudo.is_some();
        // The photo in the recovered scene's units (x / 1 is x: one photo without a grey
        // card is unchanged to the bit).
        let e0 = self.exposures[0];
        for p in cache.pixels.iter_mut() {
            p.photo /= e0;
        }
        let mut builds = 1;
        for (k, v) in self.extra.iter().enumerate() {
            let seed = hash_seed(&[opts.seed, it as u64, g as u64, k as u64 + 1]);
            let (px, tiles, n) = &v.pixel_lists[g];
            let c = view_cache(
                &v.current,
                Primary::Camera,
                (px, tiles, *n),
                v.photo,
                None,
                seed,
            );
            cache.append(c, self.exposures[k + 1]);
            builds += 1;
        }
        // A textured group is also fitted from its image in the confirmed mirrors (one photo
        // only, and not while §5.1 reads the photo for this group).
        if textured && opts.mirror_views && self.extra.is_empty() && !reads_photo {
            let w = self.scene.camera.width as usize;
            let all = CacheOptions {
                max_pixels: usize::MAX,
                ..opts.cache.clone()
            };
            for (m, rho_s, pixels) in self.mirror_view_pixels(g) {
                let (px, tiles, n) = choose_pixels(&pixels, w, &all);
                let seed = hash_seed(&[opts.seed, it as u64, g as u64, 0x6d69_7272, m as u64]);
                let mut c = view_cache(
                    &self.current,
                    Primary::Mirror(m),
                    (&px, &tiles, n),
                    self.photo,
                    None,
                    seed,
                );
                builds += 1;
                for p in c.pixels.iter_mut() {
                    p.photo = p.photo / e0 / rho_s;
                }
                let st = &self.states[g];
                let Some(model) = st
                    .texture
                    .as_ref()
                    .and_then(|t| crate::fit::texture::textured_model(&c, t, &st.params, variant))
                else {
                    continue;
                };
                let (scale, used) = mirror_scale(&c, &model);
                let event = Event::MirrorView {
                    mirror: self.states[m].name.clone(),
                    pixels: c.pixels.len(),
                    scale: [scale.x, scale.y, scale.z],
                    used,
                };
                log(&self.line(it, g, event, 0.0));
                if used {
                    for p in c.pixels.iter_mut() {
                        p.photo *= scale;
                    }
                    cache.append(c, 1.0);
                }
            }
        }
        self.cache_builds += builds;
        cache
    }

    /// Group `g` fitted on its fresh `cache` and stepped through the hierarchy (§5.1's
    /// hypotheses first, for a mirror); its shares of the unseen groups' light and its part of
    /// the photos' exposure sums collected; its new parameters put into the scene at once
    /// (Gauss–Seidel: the next groups' caches see them). `tg`: when its turn began, and how
    /// long its cache took.
    #[allow(clippy::too_many_arguments)]
    fn fit_group(
        &mut self,
        g: usize,
        mut cache: GroupCache,
        plan: &mut Plan,
        (tg, cache_secs): (Instant, f64),
        shares: &mut Vec<GroupShares>,
        sums: &mut ExposureSums,
        log: &mut dyn FnMut(&LogLine),
    ) -> Result<(), RecoverError> {
        let (opts, it) = (self.opts, plan.it);
        let variant = self.scene.render.ward_variant;
        let atlas = self.atlases[g].as_deref();
        let mut read = cache.pseudo.take().filter(|r| r.share >= pseudo::MIN_SHARE);
        let mut took = false;
        if let Some(r) = read.as_mut() {
            if let Some((event, take)) = pseudo::choose(&mut cache, r, &self.states, g, variant) {
                took = take;
                log(&self.line(it, g, event, 0.0));
            }
        }
        // A held group waits as for a neighbour: it is neither textured nor confirmed at a
        // uniform level that Algorithm 1's gate says is not enough.
        let held = plan.hold_textures.then(|| STRAY_LIGHT.to_string());
        let closing = it + opts.closing >= opts.max_iterations;
        let turn = schedule::Turn {
            may_climb: self.may_climb(g, plan),
            may_move: plan.climbers.contains(&g)
                || self.settled && {
                    let at = plan.order.iter().position(|&h| h == g).unwrap_or(0);
                    let ahead: Vec<usize> = (plan.order[at..].iter().copied())
                        .filter(|c| plan.climbers.contains(c))
                        .collect();
                    schedule::takes_unused_turn(&self.states, g, &ahead, &plan.moved)
                },
            // The neighbours first: the texture's pixels need the index buffers.
            texture_waits_for: held.or_else(|| {
                schedule::texture_waits_for(&self.states, g, &opts.hierarchy)
                    .filter(|_| self.texture_pixels()[g].len() > opts.cache.max_pixels)
                    .map(|h| self.states[h].name.clone())
            }),
            closing,
        };
        let st = &mut self.states[g];
        let level_before = st.level;
        let events = st.step(&cache, atlas, variant, &opts.hierarchy, &turn);
        if let (true, Some(r)) = (took, read.as_mut()) {
            // The unseen groups' derivatives are those of the rendered mirror radiance.
            cache.swap_mirror(r);
        }
        if !self.extra.is_empty() && self.states[g].level != Level::Textured {
            let st = &self.states[g];
            let model = crate::fit::texture::uniform_model(&cache, st.level, &st.params, variant);
            sums.add(&cache, &model, &self.exposures);
        }
        shares.extend(unseen::shares(&cache, g, &self.states[g], variant));
        self.states[g].lit_by = cache.light_from.clone();
        self.states[g].open = cache.open;
        self.note_texture_sources(g);
        if self.states[g].level != level_before {
            if self.states[g].level != Level::Textured {
                plan.moved.push(g);
            }
            for (h, st) in self.states.iter_mut().enumerate() {
                if h != g
                    && st.level == Level::Textured
                    && st.lit_by.get(g).is_some_and(|&x| x > schedule::INDEPENDENT)
                {
                    st.recheck_texture = true;
                }
            }
        }
        let secs = tg.elapsed().as_secs_f64();
        for e in events {
            if let Event::Fit { evals: n, .. } = e {
                self.evals += n as u64;
            }
            log(&LogLine {
                cache_seconds: Some(cache_secs),
                ..self.line(it, g, e, secs)
            });
        }
        if let Some(what) = self.states[g].non_finite() {
            return Err(RecoverError::Diverged {
                group: self.states[g].name.clone(),
                iteration: it,
                what,
            });
        }
        // Gauss–Seidel: the next groups' caches see this group's new parameters.
        self.textures[g] = texture_of(self.scene, &self.states[g], self.atlases[g].as_ref());
        apply(&mut self.current, &self.states, &self.textures);
        for v in self.extra.iter_mut() {
            apply(&mut v.current, &self.states, &self.textures);
        }
        Ok(())
    }

    /// Each photo's exposure factor against the refitted materials (several photos), and the
    /// grey card's, rendered with them. Returns the largest relative change of a factor.
    fn update_exposures(&mut self, sums: &ExposureSums, it: u32) -> f32 {
        let mut exposure_moved = 0.0f32;
        if !self.extra.is_empty() {
            self.residuals = sums.residuals(&self.exposures);
            if let Some(e) = sums.exposures() {
                exposure_moved = e
                    .iter()
                    .zip(&self.exposures)
                    .fold(0.0f32, |m, (a, b)| m.max((a / b - 1.0).abs()));
                self.exposures = e;
            }
        }
        // The grey card rendered with the refitted materials: the first photo's factor is
        // what it says, and the others keep their ratios to it.
        if let Some(card) = &self.opts.grey_card {
            match grey_card_factor(&self.current, self.photo, &self.mask, card) {
                Ok(f) => {
                    let scale = f / self.exposures[0];
                    tracing::debug!("iteration {it}: grey card factor {f}");
                    exposure_moved = exposure_moved.max((scale - 1.0).abs());
                    self.exposures.iter_mut().for_each(|e| *e *= scale);
                    self.photo_scaled.take();
                }
                Err(e) => tracing::warn!("{e}; the exposure stays as calibrated before the fit"),
            }
        }
        exposure_moved
    }

    /// The unseen groups' ρd (and the stray light) re-estimated against the refitted seen
    /// groups, except in the last `min_average` iterations (once as many have moved them): the
    /// fits made there all see the same values, so the averages that end the run hold
    /// `min_average` fits even if the estimate moved late, not only the last one.
    fn update_unseen(
        &mut self,
        plan: &Plan,
        shares: &[GroupShares],
        log: &mut dyn FnMut(&LogLine),
    ) -> UnseenMoves {
        let (opts, it) = (self.opts, plan.it);
        let n = opts.max_iterations;
        let m = opts.min_average;
        let frozen = it + 1 >= n || (it + m >= n && it >= m);
        let unseen::Estimates {
            groups: estimates,
            stray,
            moved,
            drift,
        } = unseen::update(
            &mut self.current,
            &mut self.states,
            shares,
            &plan.tracked,
            &opts.unseen,
            &mut self.unseen_history,
            frozen,
        );
        self.unseen = estimates;
        if let Some(s) = stray {
            log(&LogLine {
                iteration: it,
                group: "stray_light".into(),
                event: Event::StrayLight(s.clone()),
                params: Default::default(),
                distribution: None,
                seconds: 0.0,
                cache_seconds: None,
                elapsed: self.elapsed(),
            });
            self.set_stray_light(self.current.stray_light);
            self.stray = Some(s);
        }
        for v in self.extra.iter_mut() {
            apply(&mut v.current, &self.states, &self.textures);
        }
        UnseenMoves { moved, drift }
    }

    /// How far every group moved in the iteration; whether the averages restart, the scene
    /// settled, and the recovery converged.
    fn settle(
        &mut self,
        plan: &Plan,
        exposure_moved: f32,
        unseen: UnseenMoves,
        log: &mut dyn FnMut(&LogLine),
    ) {
        let (opts, it) = (self.opts, plan.it);
        let UnseenMoves {
            moved: unseen_moved,
            drift: unseen_drift,
        } = unseen;
        let moves: Vec<Option<f32>> = self
            .states
            .iter()
            .zip(&plan.before)
            .map(|(s, b)| {
                s.is_fitted()
                    .then(|| largest_move([(s.level, &s.params, b)]))
            })
            .collect();
        let moved = moves
            .iter()
            .flatten()
            .fold(unseen_moved.max(exposure_moved), |a, &b| a.max(b));
        let mut motions = Vec::new();
        for (g, m) in moves.iter().enumerate() {
            let Some(m) = *m else { continue };
            let motion = self.states[g].record_move(m, opts.settle);
            match motion {
                Motion::Jittering => log(&self.line(it, g, Event::Jitter { moved: m }, 0.0)),
                Motion::Converging => log(&self.line(it, g, Event::Converging { moved: m }, 0.0)),
                Motion::Steady => {}
            }
            // Only its own: the light it sends the others barely changes on the way.
            if self.states[g].restarts_its_average(motion, opts.settle) {
                self.states[g].restart_average();
            }
            motions.push(motion);
        }
        let level_changed = self
            .states
            .iter()
            .zip(&plan.levels_before)
            .any(|(s, l)| s.level != *l);
        // Fits made before a group changed its model saw a different scene; so did the averaged
        // fits once the unseen groups' ρd (or the stray light) is more than twice the tolerance,
        // in the seen light, away from the mean of the values they saw. (That mean, not the last
        // iteration's value: the estimate's own noise from one iteration to the next does not
        // restart them, a slow drift does; and not the value when they started: an average
        // of fits along a slow drift is biased by the distance from its mean.) Either starts
        // every group's average afresh; a new model also the record of how its parameters
        // converge.
        if level_changed || unseen_drift > 2.0 * opts.tolerance {
            for s in self.states.iter_mut() {
                s.restart_average();
                if level_changed {
                    s.moves.clear();
                }
            }
            self.unseen_history.restart_drift();
            if level_changed {
                self.unseen_history.restart_steps();
            }
        }
        tracing::debug!(
            "iteration {it}: moved {moved:.4} (unseen {unseen_moved:.4}, drift {unseen_drift:.4})"
        );
        self.settled = schedule::settled(level_changed, &motions);
        let all_confirmed = self.states.iter().all(|s| {
            s.status != Status::Analysing
                && (s.status != Status::Confirmed
                    || s.average.is_some_and(|a| a.1 >= opts.min_average))
        });
        self.converged =
            all_confirmed && moved < opts.tolerance && self.cap >= opts.cache.max_pixels;
        self.next = it + 1;
    }
}
