//! Pseudo-textures (§5.1 of the notes, "the problem of multiple specular reflections").
//!
//! A mirror's pixels show what it reflects, so its ρs is fitted against a render of those
//! objects. While one of them is still being analysed its material is wrong (a book still at the
//! diffuse level has no texture yet, a second mirror no ρs yet), and the mirror absorbs the error:
//! its ρs is biased or its ε is so high that it is taken for a texture. The notes' remedy: take
//! the analysed object B as a *pseudo-texture*, its radiance read straight from the photo with no
//! illumination computed, fit the mirror A against that, and keep whichever hypothesis fits best.
//!
//! Here, while A's cache is built, each mirror sample whose reflected ray first lands on a group
//! still being analysed is traced twice: rendered through the current scene (B as currently
//! modelled, "both specular with the stored properties" when B is a mirror too) and read from the
//! photo where the camera sees the same point ([`photo_radiance`]). A is fitted at its mirror
//! level against both ([`choose`]); the smaller error ε wins for this iteration and
//! `log.jsonl` records both errors (`hypotheses`). The notes' third hypothesis, "A
//! pseudo-textured and B specular", is B's own fit with A taken from the photo. As in the notes,
//! only the group being fitted is decided: B keeps being analysed. Reading B from the photo is
//! exact for a diffuse B (its radiance does not depend on the direction it is seen from) and
//! wrong for a mirror B (it shows something else to the camera than to A); the comparison of
//! the two hypotheses is what tells them apart. `recover --no-pseudo-textures` turns it off.

use super::cache::{GroupCache, PseudoMirror};
use super::event::Event;
use super::fitter::fit_level;
use super::group::GroupState;
use super::level::Level;
use crate::scene::WardVariant;

/// Below this share of a cache's mirror samples read from the photo, the two hypotheses cannot
/// differ by more than the noise: the rendered one is kept without comparing.
pub const MIN_SHARE: f32 = 0.01;

/// Chooses between the rendered and the pseudo-textured mirror radiance of `cache` for group
/// `group`: both fitted at its mirror level (ideal mirror ρs when it is not at one yet), the
/// smaller error ε kept (the notes' criterion). Leaves the chosen one in `cache` and returns
/// the event to log and whether the photo's was taken, the other radiance left in `pseudo`
/// (swap again to restore the rendered one); None, with the rendered one in `cache`, for a
/// group that is not being taken for a mirror.
pub fn choose(
    cache: &mut GroupCache,
    pseudo: &mut PseudoMirror,
    states: &[GroupState],
    group: usize,
    variant: WardVariant,
) -> Option<(Event, bool)> {
    let state = &states[group];
    let level = if state.level.is_mirror() {
        state.level
    } else {
        Level::Specular
    };
    let rendered = fit_level(cache, level, &state.params, variant);
    cache.swap_mirror(pseudo);
    let read = fit_level(cache, level, &state.params, variant);
    // A group that fits worse as a mirror either way than at its own level is not being taken
    // for one: nothing to decide (its first fit, error 0, has no level to compare with yet).
    if !state.level.is_mirror()
        && state.error > 0.0
        && rendered.error.min(read.error) >= state.error
    {
        cache.swap_mirror(pseudo);
        return None;
    }
    let take = read.error < rendered.error;
    if !take {
        cache.swap_mirror(pseudo);
    }
    let event = Event::Hypotheses {
        level,
        pseudo_textured: pseudo
            .groups
            .iter()
            .map(|&g| states[g].name.clone())
            .collect(),
        share: pseudo.share,
        error_rendered: rendered.error,
        error_pseudo: read.error,
        chose: if take { "pseudo_texture" } else { "rendered" }.to_string(),
    };
    Some((event, take))
}
