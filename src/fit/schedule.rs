//! The climb-scheduling rules of the hierarchy, across groups: when the scene has *settled*
//! enough for any group to try higher levels, and *whose turn* it is to move. The per-group
//! state machine that obeys them is `hierarchy.rs`; the loop that asks them is `recovery.rs`.
//!
//! A group must not climb to explain light that a neighbour's stale model is missing, so groups
//! try higher levels only after an iteration that changed no level and moved no parameter much,
//! and at most one group moves per iteration: the one furthest above its level's threshold.

use super::hierarchy::{GroupState, HierarchyOptions, Status};

/// Whether the scene has settled after a global iteration: no group changed level and no
/// fitted parameter moved by more than `settle` (`moved` as `params::largest_move` measures it).
pub fn settled(level_changed: bool, moved: f32, settle: f32) -> bool {
    !level_changed && moved < settle
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

/// The group that may move to a higher level this iteration, if any: none until the scene has
/// settled, then the one with the highest [`climb_priority`] (the first such on ties).
pub fn climb_turn(states: &[GroupState], settled: bool, opts: &HierarchyOptions) -> Option<usize> {
    if !settled {
        return None;
    }
    (0..states.len())
        .filter_map(|g| climb_priority(&states[g], opts).map(|p| (g, p)))
        .max_by(|a, b| a.1.total_cmp(&b.1))
        .map(|(g, _)| g)
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
        assert!(settled(false, 0.01, 0.03));
        assert!(!settled(true, 0.0, 0.03) && !settled(false, 0.03, 0.03));
    }
}
