//! The climb-scheduling rules of the hierarchy, across groups: when the scene has *settled*
//! enough for any group to try higher levels, and *whose turn* it is to move. The per-group
//! state machine that obeys them is `hierarchy.rs`; the loop that asks them is `recovery.rs`.
//!
//! A group must not climb to explain light that a neighbour's stale model is missing, so groups
//! try higher levels only after an iteration that changed no level and in which every group's
//! parameters either stopped moving or move only within their own noise; except a group whose
//! error no neighbour's stale model could explain ([`gross`]), which climbs at once. The first to move is
//! the one that has waited longest for its turn, then the one furthest above its level's
//! threshold; others move in the same iteration only if no group moving lights them, nor they
//! it, by more than [`INDEPENDENT`] of its light (they cannot be explaining each other's
//! missing light). Turns rotate, so no group holds them; and when the iterations run out, every
//! group still analysing is decided (`GroupState::decide_at_end`).

use super::group::{GroupState, Motion, Status};
use super::level::HierarchyOptions;
use super::level::Level;

/// Whether the scene has settled after a global iteration: no group changed level, and every
/// fitted group's parameters are steady (moved less than the settle tolerance) or jittering
/// (their moves stopped shrinking: a weakly determined group must not block the others; see
/// [`GroupState::record_move`]).
pub fn settled(level_changed: bool, motions: &[Motion]) -> bool {
    !level_changed && motions.iter().all(|&m| m != Motion::Converging)
}

/// Whether a group, fitted `iterations_at_level` times at its current level before this
/// iteration, has seen its level's interreflections settle and may try the levels above.
pub fn has_settled_at_level(iterations_at_level: u32) -> bool {
    iterations_at_level >= 1
}

/// How much a group wants to climb this iteration, if it does: analysing, settled at its level
/// and above the level's threshold. Its priority is ε / threshold.
pub fn climb_priority(state: &GroupState, opts: &HierarchyOptions) -> Option<f32> {
    let thr = opts.thresholds.of(state.level);
    (state.status == Status::Analysing
        && has_settled_at_level(state.iterations_at_level)
        && state.error >= thr)
        .then(|| state.error / thr)
}

/// Two groups may climb in the same iteration when neither receives more than this share of
/// its cached light by way of the other (`GroupState::lit_by`).
pub const INDEPENDENT: f32 = 0.02;

/// Whether groups `a` and `b` light each other by at most [`INDEPENDENT`] of their light, both
/// ways. Unknown (no cache yet) counts as dependent.
fn independent(states: &[GroupState], a: usize, b: usize) -> bool {
    let share = |g: usize, h: usize| states[g].lit_by.get(h).copied();
    matches!((share(a, b), share(b, a)), (Some(x), Some(y)) if x <= INDEPENDENT && y <= INDEPENDENT)
}

/// How far above its level's threshold a group's error must be for [`gross`].
pub const GROSS: f32 = 10.0;

/// Whether group `g` misses its photo by more than its neighbours' stale models could explain,
/// so that it need not wait for the scene to settle before it climbs: it is analysing, has been
/// fitted at its level, its ε is at least [`GROSS`] times its level's threshold, and at least
/// twice the share of its cached light that came by way of the other groups (`lit_by`). Were
/// every other group's light wrong by 100%, g's tiles would be off by at most that share;
/// what remains is g's own model. (figure6's Ward floor fitted diffuse: ε 0.88, 42% of its light
/// by way of the others.) Before its first cache nothing is known: false.
pub fn gross(states: &[GroupState], g: usize, opts: &HierarchyOptions) -> bool {
    let s = &states[g];
    let others: f32 = (s.lit_by.iter().enumerate())
        .filter(|&(h, _)| h != g)
        .map(|(_, &x)| x)
        .sum();
    opts.gross_climbs
        && s.status == Status::Analysing
        && has_settled_at_level(s.iterations_at_level)
        && !s.lit_by.is_empty()
        && s.error >= GROSS * opts.thresholds.of(s.level)
        && s.error >= 2.0 * others
}

/// The groups that may move to a higher level this iteration. Until the scene has settled, the
/// [`gross`] ones. Then among those with a [`climb_priority`] the one that has waited longest
/// since it found a better level (`GroupState::waiting`), then the highest priority (the later
/// group on ties); then, in the same order, every other one independent of all those already
/// chosen. The waiting count makes turns rotate: one group that keeps finding better levels
/// cannot hold the turn while another waits.
pub fn climbers(states: &[GroupState], settled: bool, opts: &HierarchyOptions) -> Vec<usize> {
    if !settled {
        return (0..states.len())
            .filter(|&g| gross(states, g, opts))
            .collect();
    }
    let mut candidates: Vec<(usize, u32, f32)> = (0..states.len())
        .filter_map(|g| climb_priority(&states[g], opts).map(|p| (g, states[g].waiting, p)))
        .collect();
    // Best first: longest waiting, then highest priority, then the later group.
    candidates.sort_by(|a, b| b.1.cmp(&a.1).then(b.2.total_cmp(&a.2)).then(b.0.cmp(&a.0)));
    let mut chosen: Vec<usize> = Vec::new();
    for (g, _, _) in candidates {
        if chosen.iter().all(|&c| independent(states, g, c)) {
            chosen.push(g);
        }
    }
    chosen
}

/// Whether group `g`, not among the iteration's [`climbers`], may take a turn they leave
/// unused. The climbers are chosen before their climbs, and a climb may find nothing to move
/// to, or a texture, which needs no turn; a group whose climb earned a level would otherwise
/// wait behind them, possibly until the iterations run out. The turn keeps two groups that
/// light each other from changing their light at once; that holds as long as `g` is
/// independent of every group that `moved` this iteration so far and of every climber that
/// has not yet had its turn (`climbers_ahead`, which keep theirs; the recovery visits the
/// climbers first, so there is none). Only once the scene has settled: before, only the gross
/// groups climb.
pub fn takes_unused_turn(
    states: &[GroupState],
    g: usize,
    climbers_ahead: &[usize],
    moved: &[usize],
) -> bool {
    (climbers_ahead.iter().chain(moved)).all(|&c| c != g && independent(states, g, c))
}

/// What the schedule allows one group in a global iteration.
#[derive(Clone, Debug, Default)]
pub struct Turn {
    /// The group may try the levels above its own: the scene has settled, or it is [`gross`].
    pub may_climb: bool,
    /// It is its turn: it may also move to a level it found (otherwise it waits).
    pub may_move: bool,
    /// The group it must wait for before it may try level 7 ([`texture_waits_for`]).
    pub texture_waits_for: Option<String>,
    /// The run is in its last [`CLOSING`] iterations: no move to a uniform level now.
    pub closing: bool,
}

/// The last iterations of a run, in which no group moves to a uniform level. A move is checked
/// on the caches after it: a confirmed level is demoted when two caches in a row find a simpler
/// one as good, and its parameters are the mean of its fits. A move in the last two iterations
/// is checked by neither, and its one or two fits would become the answer. A texture still may:
/// it keeps its group's mean reflectance, so the light its neighbours see, and its trial pools
/// the evidence of the earlier ones. Where a group found a level too late, `decided` says so
/// and that more iterations would let it move.
pub const CLOSING: u32 = 2;

/// How many climbs a group's texture waits for its neighbours at most ([`texture_waits_for`])
/// at one level. A neighbour whose own faint print sits at the texture test's threshold is
/// reopened and confirmed again from cache to cache, so waiting for it need never end: on the
/// test interior the wood floor (12,000 pixels, detail z 39) waited behind the ±10% wallpaper
/// until the iterations ran out and ended diffuse. Going ahead after one wait costs little: a
/// texture that took a neighbour's reflection for its own is re-asked when that neighbour
/// changes level (`texture_sources_changed`).
pub const TEXTURE_WAITS: u32 = 1;

/// The group, if any, whose light `g` must see modelled before `g` may try level 7.
///
/// A texture is the last resort of the hierarchy: it takes whatever light the group's uniform
/// models miss, texel by texel, and holds it as reflectance. Tried while a group that lights it
/// is still analysing above its threshold, it takes that group's missing light too (a glossy
/// floor beside a mirror still modelled diffuse holds the lights' images in the mirror as
/// texels, and its lobe is lost). So `g` waits for any group that gives it more than
/// [`INDEPENDENT`] of its light and is analysing with ε at or above its threshold, unless that
/// group is itself waiting for a texture (two textured neighbours would otherwise wait for each
/// other); and for any such group without a lobe or mirror whose uniform level leaves a print
/// (`detail.rs`), which it would otherwise take for its own. The first such group, by index.
///
/// The recovery loop asks this only of a group whose texture would be fitted from more pixels
/// than a uniform level's cache holds (`CacheOptions::max_pixels`): waiting costs iterations
/// (the group settles at its best uniform level first, its neighbour climbs later), while a
/// texture tried too early on a small group is undone cheaply by the recheck
/// (`GroupState::untexture`).
pub fn texture_waits_for(
    states: &[GroupState],
    g: usize,
    opts: &HierarchyOptions,
) -> Option<usize> {
    if states[g].texture_waits >= TEXTURE_WAITS {
        return None;
    }
    let lit_by = &states[g].lit_by;
    (0..states.len()).find(|&h| {
        let s = &states[h];
        // A neighbour whose print is not yet modelled sends its pattern into this group's
        // residual (a glossy floor reflecting a papered wall): this group's texture would
        // take the reflection for its own. Only a neighbour without a lobe or mirror: its
        // print is its own (a diffuse surface's light blurs any pattern it receives), so two
        // groups never wait for each other's print, even while that neighbour itself waits.
        let unmodelled_print = !s.level.has_lobe()
            && !s.level.is_mirror()
            && s.level != Level::Textured
            && s.detail
                .is_some_and(|d| d.is_texture(opts.thresholds.texture_detail));
        let analysing = s.status == Status::Analysing
            && s.error >= opts.thresholds.of(s.level)
            && !s.texture_waiting;
        h != g && lit_by.get(h).is_some_and(|&x| x > INDEPENDENT) && (analysing || unmodelled_print)
    })
}

/// Whether a textured group must ask Algorithm 1's gate again: a group that gives it more than
/// [`INDEPENDENT`] of its light (`lit_by`, from its latest cache) is at another level `now` than
/// `then`, when its texture was taken or last re-asked (`GroupState::texture_sources`). The
/// shares are today's, not those from before the change: a mirror modelled diffuse gives a
/// floor little light, a specular one sends it the lights' images. Nothing is known (false)
/// while `then` does not cover the scene's groups.
pub fn texture_sources_changed(then: &[Level], lit_by: &[f32], now: &[Level]) -> bool {
    then.len() == now.len()
        && (lit_by.iter().zip(now).zip(then)).any(|((&x, a), b)| x > INDEPENDENT && a != b)
}

/// The first of [`climbers`]: the group whose turn it is.
pub fn climb_turn(states: &[GroupState], settled: bool, opts: &HierarchyOptions) -> Option<usize> {
    climbers(states, settled, opts).first().copied()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fit::level::Level;
    use crate::fit::params::GroupParams;

    fn group(status: Status, level: Level, error: f32, its: u32) -> GroupState {
        let mut s = GroupState::new("g", status, GroupParams::default());
        s.level = level;
        s.error = error;
        s.iterations_at_level = its;
        s
    }

    #[test]
    fn only_the_worst_settled_analysing_group_may_climb_and_only_once_settled() {
        let opts = HierarchyOptions::default(); // diffuse 2%, isotropic 1%
        let states = [
            group(Status::Analysing, Level::Diffuse, 0.05, 3), // 2.5× its threshold
            group(Status::Analysing, Level::Isotropic, 0.03, 2), // 3×: the worst
            group(Status::Analysing, Level::Diffuse, 0.09, 0), // not yet fitted at its level
            group(Status::Confirmed, Level::Diffuse, 0.50, 5), // decided
            group(Status::Analysing, Level::Diffuse, 0.01, 4), // below its threshold
        ];
        assert_eq!(climb_turn(&states, true, &opts), Some(1));
        assert_eq!(climb_turn(&states, false, &opts), None);
        assert_eq!(climb_priority(&states[2], &opts), None);
        assert_eq!(climb_priority(&states[3], &opts), None);
        assert_eq!(climb_priority(&states[4], &opts), None);
        use Motion::*;
        assert!(settled(false, &[Steady, Jittering, Steady]));
        assert!(!settled(true, &[Steady]) && !settled(false, &[Steady, Converging]));
    }

    /// A group waits for a texture on a group that lights it by more than [`INDEPENDENT`] and
    /// is analysing above its threshold, and on no other: not on one that lights it less, nor
    /// one that is decided or within its threshold, nor one itself waiting for a texture.
    #[test]
    fn a_texture_waits_only_for_an_analysing_neighbour_that_lights_it() {
        let opts = HierarchyOptions::default(); // diffuse threshold 2%
        let mut states = vec![
            group(Status::Analysing, Level::Anisotropic, 0.2, 3), // the would-be texture
            group(Status::Analysing, Level::Diffuse, 0.2, 3),     // lights it 1%
            group(Status::Confirmed, Level::Diffuse, 0.2, 3),     // decided
            group(Status::Analysing, Level::Diffuse, 0.01, 3),    // within its threshold
            group(Status::Analysing, Level::Diffuse, 0.2, 3),     // lights it 5%
        ];
        states[0].lit_by = vec![0.0, 0.01, 0.3, 0.3, 0.05];
        assert_eq!(texture_waits_for(&states, 0, &opts), Some(4));
        states[4].texture_waiting = true;
        assert_eq!(texture_waits_for(&states, 0, &opts), None);
        states[4].texture_waiting = false;
        states[4].lit_by = vec![0.05, 0.0, 0.0, 0.0, 0.0];
        states[0].texture_waiting = true;
        assert_eq!(texture_waits_for(&states, 4, &opts), None);
        // Having waited once at its level, it goes ahead.
        states[0].texture_waiting = false;
        states[0].texture_waits = TEXTURE_WAITS;
        assert_eq!(texture_waits_for(&states, 0, &opts), None);
        states[0].texture_waits = 0;
        // Before its first cache a group knows nothing of its light, and waits for no one.
        states[0].lit_by.clear();
        assert_eq!(texture_waits_for(&states, 0, &opts), None);
    }

    /// A textured group is re-asked when a group that lights it by more than 2% today has
    /// changed level since its texture, however little it lit it before: not for a change in a
    /// group that lights it little, nor before its first snapshot of the levels.
    #[test]
    fn a_texture_is_reasked_when_a_group_that_lights_it_now_changed_level() {
        use Level::*;
        let then = [Textured, Diffuse, Diffuse, Diffuse];
        // The mirror (1) turned specular and now gives 6%; the wall (2) climbed but gives 1%.
        let now = [Textured, Specular, Isotropic, Diffuse];
        assert!(texture_sources_changed(
            &then,
            &[0.0, 0.06, 0.01, 0.3],
            &now
        ));
        assert!(!texture_sources_changed(
            &then,
            &[0.0, 0.01, 0.01, 0.3],
            &now
        ));
        assert!(!texture_sources_changed(
            &then,
            &[0.0, 0.06, 0.01, 0.3],
            &then
        ));
        assert!(!texture_sources_changed(&[], &[0.0, 0.06, 0.01, 0.3], &now));
    }

    /// Two groups that keep finding a better level: the worse one (higher ε / threshold) climbs
    /// first, then the one that waited, then turns alternate; no group holds the turn.
    #[test]
    fn climbing_turns_rotate_between_waiting_groups() {
        let opts = HierarchyOptions::default();
        let mut states = [
            group(Status::Analysing, Level::Diffuse, 0.3, 3), // 15 thresholds above
            group(Status::Analysing, Level::Diffuse, 0.05, 3), // 2.5 thresholds above
        ];
        let mut turns = Vec::new();
        for _ in 0..4 {
            let g = climb_turn(&states, true, &opts).expect("a climber");
            turns.push(g);
            // The chosen group moves (its wait ends), the other is deferred.
            states[g].waiting = 0;
            states[1 - g].waiting += 1;
        }
        assert_eq!(turns, [0, 1, 0, 1]);
    }

    /// Groups that light each other take turns; a group that neither lights nor is lit by the
    /// one whose turn it is climbs in the same iteration.
    #[test]
    fn groups_that_do_not_light_each_other_climb_together() {
        let opts = HierarchyOptions::default();
        let mut states = [
            group(Status::Analysing, Level::Diffuse, 0.3, 3),
            group(Status::Analysing, Level::Diffuse, 0.2, 3),
            group(Status::Analysing, Level::Diffuse, 0.1, 3),
        ];
        // 0 and 1 light each other (10%); 2 gets 1% from each and gives each 0.5%.
        states[0].lit_by = vec![0.0, 0.10, 0.005];
        states[1].lit_by = vec![0.10, 0.0, 0.005];
        states[2].lit_by = vec![0.01, 0.01, 0.0];
        assert_eq!(climbers(&states, true, &opts), [0, 2]);
        // 2 now gets 5% of its light from 0: it waits for its own turn.
        states[2].lit_by[0] = 0.05;
        assert_eq!(climbers(&states, true, &opts), [0]);
        // Without a cache yet, nothing is known: one climber.
        states[2].lit_by.clear();
        assert_eq!(climbers(&states, true, &opts), [0]);
        // Unsettled, only a gross group climbs: 0 (ε 0.3, 10.5% of its light from the others).
        assert_eq!(climbers(&states, false, &opts), [0]);
        states[0].lit_by[1] = 0.2;
        assert!(climbers(&states, false, &opts).is_empty());
    }

    /// A turn the climbers leave unused passes on, to a group independent of every group
    /// that moved so far and of every climber still to come; never to one that either lights.
    #[test]
    fn a_turn_left_unused_passes_to_an_independent_group() {
        let opts = HierarchyOptions::default();
        let mut states = [
            group(Status::Analysing, Level::Diffuse, 0.3, 3),
            group(Status::Analysing, Level::Diffuse, 0.2, 3),
            group(Status::Analysing, Level::Diffuse, 0.1, 3),
            group(Status::Analysing, Level::Diffuse, 0.1, 3),
        ];
        // 1 lights 0 and 2; 3 lights 2; 0 and 3 are independent of each other.
        states[0].lit_by = vec![0.0, 0.10, 0.0, 0.0];
        states[1].lit_by = vec![0.10, 0.0, 0.10, 0.0];
        states[2].lit_by = vec![0.0, 0.10, 0.0, 0.10];
        states[3].lit_by = vec![0.0, 0.0, 0.10, 0.0];
        assert_eq!(climbers(&states, true, &opts), [0, 3]);
        // 1 and 2, not climbers, step in order; 0 before them found no level (its turn is
        // unused), 3 after them keeps its own.
        assert!(!takes_unused_turn(&states, 1, &[], &[0]), "0 moved and 1 lights it");
        assert!(takes_unused_turn(&states, 1, &[3], &[]), "0 did not move");
        assert!(!takes_unused_turn(&states, 2, &[3], &[]), "3, still to come, lights 2");
        assert!(!takes_unused_turn(&states, 2, &[], &[1]), "1 took the turn and lights 2");
        assert!(!takes_unused_turn(&states, 0, &[], &[0]), "a group is not its own neighbour");
        // Without a cache, nothing is known: dependent.
        states[1].lit_by.clear();
        assert!(!takes_unused_turn(&states, 1, &[3], &[]));
    }

    /// Before the scene settles, a group climbs only if its ε is at least `GROSS` thresholds
    /// and twice the share of its light that came by way of the others: not a group whose
    /// neighbours could explain its error, nor one just above its threshold, nor one decided
    /// or not yet fitted at its level, nor one without a cache.
    #[test]
    fn a_group_its_neighbours_cannot_explain_climbs_before_the_scene_settles() {
        // Diffuse threshold 2%. Group g's shares: `own` from itself, `others` split between the
        // next two groups.
        let opts = HierarchyOptions::default();
        let lit = |g: usize, own: f32, others: f32| {
            let mut v = vec![0.0; 6];
            v[g] = own;
            v[(g + 1) % 6] = others / 2.0;
            v[(g + 2) % 6] = others / 2.0;
            v
        };
        let mut states = vec![
            group(Status::Analysing, Level::Diffuse, 0.88, 1), // 42% via the others
            group(Status::Analysing, Level::Diffuse, 0.30, 3), // 20% via the others
            group(Status::Analysing, Level::Diffuse, 0.15, 3), // 7.5 thresholds
            group(Status::Confirmed, Level::Diffuse, 0.90, 3),
            group(Status::Analysing, Level::Diffuse, 0.90, 0), // not yet fitted here
            group(Status::Analysing, Level::Diffuse, 0.90, 3), // no cache
        ];
        for (g, (own, others)) in [(0.1, 0.42), (0.0, 0.2), (0.0, 0.01), (0.0, 0.0), (0.0, 0.0)]
            .into_iter()
            .enumerate()
        {
            states[g].lit_by = lit(g, own, others);
        }
        assert!(gross(&states, 0, &opts));
        assert!((1..6).all(|g| !gross(&states, g, &opts)));
        assert_eq!(climbers(&states, false, &opts), [0]);
        // g's own share does not count: its model is what is being fitted.
        states[0].lit_by = lit(0, 0.5, 0.42);
        assert!(gross(&states, 0, &opts));
        states[0].lit_by = lit(0, 0.1, 0.45);
        assert!(!gross(&states, 0, &opts));
        // Settled, the usual rule: everyone with a priority, the worst first.
        assert_eq!(climbers(&states, true, &opts)[0], 5);
    }
}
