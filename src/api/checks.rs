//! Checks made before long work: the scene's lights, the photo's exposure and brightness, and
//! the output folder. What they find goes to the caller's [`Observer`]; what stops the work is
//! an [`Error`].

use crate::error::{Error, Result};
use super::Observer;
use crate::prepare::{PhotoArgs, PreparedPhoto};
use crate::scene::lint::{group_name_warnings, lighting, Lighting};
use crate::scene::Scene;
use std::path::Path;

/// A number with at most `digits` decimals and no trailing zeros (1.6, not 1.5999999).
pub fn num(x: f32, digits: usize) -> String {
    let s = format!("{x:.digits$}");
    let s = if s.contains('.') {
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        s
    };
    if s == "-0" {
        "0".into()
    } else {
        s
    }
}

/// Warns of group names that look like typos; returns what the view says about the lights.
pub fn scene_warnings(sc: &Scene, obs: &dyn Observer) -> Lighting {
    for w in group_name_warnings(sc) {
        obs.warning(&w);
    }
    lighting(sc)
}

fn object_at(sc: &Scene, o: usize) -> String {
    format!(
        "{}:{}: light '{}'",
        sc.path.display(),
        sc.objects[o].line,
        sc.objects[o].name
    )
}

/// One line: how many pixels the user's ignore mask `mask` takes, and from which groups.
pub fn masked_summary(sc: &Scene, mask: &Path, p: &PreparedPhoto) -> String {
    let total = p.photo.ignored.iter().filter(|&&m| m).count();
    let per_group: Vec<String> = p
        .mask
        .stats
        .iter()
        .enumerate()
        .filter(|(_, st)| st.user > 0)
        .map(|(g, st)| format!("{} {}", sc.groups[g].name, st.user))
        .collect();
    format!(
        "{}: {total} pixels masked by the user{}",
        mask.display(),
        if per_group.is_empty() {
            String::new()
        } else {
            format!(" ({})", per_group.join(", "))
        }
    )
}

/// Refuses a fit with nothing to fit: no pixel of any group that reflects light is usable in
/// any photo. With an ignore mask, that is most often the mask's polarity (a mask of what to
/// keep given as what to ignore): said so.
pub fn some_usable(
    scenes: &[Scene],
    photos: &[std::path::PathBuf],
    prepared: &[PreparedPhoto],
    ignore_mask: Option<&Path>,
) -> Result<()> {
    let bail = |m: String| Err(Error::recover(m));
    let reflects = |sc: &Scene, g: usize| {
        !sc.groups[g]
            .objects
            .iter()
            .any(|&o| sc.objects[o].is_emitter())
    };
    let any = scenes.iter().zip(prepared).any(|(sc, p)| {
        (p.mask.stats.iter().enumerate()).any(|(g, st)| st.usable > 0 && reflects(sc, g))
    });
    if any || scenes.is_empty() || !(0..scenes[0].groups.len()).any(|g| reflects(&scenes[0], g)) {
        return Ok(());
    }
    let p = &prepared[0];
    let visible: usize = (p.mask.stats.iter().enumerate())
        .filter(|(g, _)| reflects(&scenes[0], *g))
        .map(|(_, st)| st.visible)
        .sum();
    let photo = photos[0].display();
    if let Some(m) = ignore_mask {
        let ignored = p.photo.ignored.iter().filter(|&&x| x).count();
        let share = 100.0 * ignored as f64 / p.photo.ignored.len().max(1) as f64;
        let user: usize = p.mask.stats.iter().map(|st| st.user).sum();
        return bail(format!(
            "{photo}: no usable pixel is left to fit: the ignore mask {} ignores {share:.0}% of \
             the photo, {user} of the {visible} pixels where the model's surfaces are seen. \
             Is it inverted? --ignore-mask marks what to IGNORE (white, or opaque alpha); a mask \
             of the object to keep must be inverted first (e.g. `magick {} -negate \
             ignore.png`)",
            m.display(),
            m.display()
        ));
    }
    bail(format!(
        "{photo}: no usable pixel is left to fit ({visible} pixels show the model's surfaces, \
         none of them usable): see `matfit inspect` for why each was rejected"
    ))
}

/// Refuses a scene whose render would be black (no light, or every light facing away from
/// what the camera sees); warns of each light that faces away while others do not.
pub fn require_light(sc: &Scene, l: &Lighting, obs: &dyn Observer) -> Result<()> {
    if l.none() {
        return Err(Error::scene(format!(
            "{}: no object emits light and there is no [[light]] (give a light an `emission = \
             [r, g, b]`, add a directional, point or spot [[light]] or an [environment]): the image \
             would be black",
            sc.path.display()
        ))
        .at(&sc.path, None));
    }
    let hint = "its front side is along the surface normal (edge_u × edge_v for a quad: swap \
                edge_u and edge_v to turn it)";
    if l.dark() {
        let names: Vec<String> = l.facing_away.iter().map(|&o| object_at(sc, o)).collect();
        return Err(Error::scene(format!(
            "{} face{} away from every surface the camera sees, so nothing in view is lit: {hint}",
            names.join(", "),
            if names.len() == 1 { "s" } else { "" }
        ))
        .at(&sc.path, Some(sc.objects[l.facing_away[0]].line)));
    }
    for &o in &l.facing_away {
        obs.warning(&format!(
            "{} faces away from every surface the camera sees and lights nothing in view: {hint}",
            object_at(sc, o)
        ));
    }
    for &(o, d) in &l.near_surface {
        obs.warning(&format!(
            "{} faces a surface {d:.3} scene units in front of it and lights the scene only              through that surface: {hint}",
            object_at(sc, o)
        ));
    }
    Ok(())
}

/// The photo is an 8/16-bit file (judged by its name, before it is read).
fn is_ldr(photo: &Path) -> bool {
    let ext = photo
        .extension()
        .and_then(|e| e.to_str())
        .unwrap_or("")
        .to_ascii_lowercase();
    matches!(ext.as_str(), "png" | "jpg" | "jpeg" | "tif" | "tiff")
}

/// Warns when an 8/16-bit photo comes with no way to know its exposure: k = 1 then means the
/// file's codes are radiances, which a camera's JPEG almost never is.
pub fn exposure_warning(photo: &Path, args: &PhotoArgs, l: &Lighting, obs: &dyn Observer) {
    if !is_ldr(photo)
        || args.exposure.is_some()
        || args.grey_card.is_some()
        || args.exposure_from_lights
    {
        return;
    }
    let light = if l.in_view.is_empty() {
        String::new()
    } else {
        " (a light is in view: --exposure-from-lights can calibrate from it)".into()
    };
    obs.warning(&format!(
        "{}: an 8/16-bit photo and no --exposure, --grey-card or --exposure-from-lights: the \
         exposure is taken as 1 (photo = radiance), which a camera's file rarely is{light}",
        photo.display()
    ));
}

/// Says how the exposure was set; warns when some group is far brighter in the photo than any
/// light of the scene could make a surface (reflected radiance never exceeds the brightest
/// emitted radiance when no material reflects more than it receives): a wrong exposure.
pub fn exposure_report(
    sc: &Scene,
    photo: &Path,
    args: &PhotoArgs,
    p: &PreparedPhoto,
    obs: &dyn Observer,
) {
    obs.message(&match &p.calibration {
        Some(c) => format!(
            "exposure k = {:.6} calibrated from {} (per channel {:.6}, {:.6}, {:.6})",
            c.factor, c.source, c.per_channel[0], c.per_channel[1], c.per_channel[2]
        ),
        None => format!(
            "exposure k = {} ({})",
            p.photo.exposure,
            if args.exposure.is_some() {
                "given"
            } else {
                "default, not given"
            }
        ),
    });
    // The bound below holds for area lights alone (a punctual light has no radiance; an
    // environment's is not checked here).
    if !sc.punctual_lights.is_empty() || sc.environment.is_some() {
        return;
    }
    let Some((brightest, lmax)) = sc
        .objects
        .iter()
        .filter(|o| o.is_emitter())
        .map(|o| (o.name.as_str(), o.emission.max_element()))
        .max_by(|a, b| a.1.total_cmp(&b.1))
    else {
        return;
    };
    let usable = p.mask.pixels_by_group(sc.groups.len());
    for (grp, px) in sc.groups.iter().zip(&usable) {
        if grp.objects.iter().any(|&o| sc.objects[o].is_emitter()) {
            continue;
        }
        let mut l: Vec<f32> = px
            .iter()
            .map(|&i| p.photo.image.data[i].max_element())
            .collect();
        if l.len() < 16 {
            continue;
        }
        let mid = l.len() / 2;
        let median = *l.select_nth_unstable_by(mid, f32::total_cmp).1;
        if median > 1.5 * lmax {
            obs.warning(&format!(
                "{}: group '{}' is {:.0}× brighter in the photo (median {}) than the brightest \
                 light ('{brightest}', radiance {}) could make any surface: is the exposure \
                 right? (--exposure K, --grey-card GROUP=RHO or --exposure-from-lights)",
                photo.display(),
                grp.name,
                median / lmax,
                num(median, 4),
                num(lmax, 4),
            ));
        }
    }
}

/// Files a command of matfit writes into its output folder: a folder holding any of them is a
/// matfit output and may be written again.
pub const OUTPUT_MARKS: &[&str] = &[
    "results.json",
    "checkpoint.json",
    "log.jsonl",
    "recovered.toml",
    "outlines.png",
    "usable.png",
    "scene.xml",
    "photo.stamp",
    "recovery",
];

/// `recover --resume` continues a run in `dir`: the folder and its checkpoint must be there
/// (creating an empty folder would only end in "no checkpoint" after the photo's preparation).
pub fn resumable(dir: &Path) -> Result<()> {
    if !dir.is_dir() {
        return Err(Error::recover(format!(
            "cannot resume: {} does not exist, so there is no checkpoint.json to resume from \
             (run without --resume to start)",
            dir.display()
        )));
    }
    if !dir.join("checkpoint.json").is_file() {
        return Err(Error::recover(format!(
            "cannot resume: {} holds no checkpoint.json (run without --resume to start afresh)",
            dir.display()
        )));
    }
    Ok(())
}

/// What a finished `recover` writes besides its log (`report::write_outputs`), and its
/// checkpoint.
const RESULT_FILES: &[&str] = &[
    "results.json",
    "report.html",
    "recovered.toml",
    "synthetic.exr",
    "synthetic.png",
    "error.exr",
    "error.png",
    "checkpoint.json",
];

/// A new `recover` into an old output: the old run's results go first, so that a run stopped
/// before its end leaves its own log alone rather than beside another run's report (and an
/// old checkpoint, whose log offset no longer matches, cannot be resumed from).
pub fn remove_old_results(dir: &Path) -> Result<()> {
    // Only from a matfit output: a folder written into with --force keeps what it holds.
    if !OUTPUT_MARKS.iter().any(|m| dir.join(m).exists()) {
        return Ok(());
    }
    for name in RESULT_FILES {
        let p = dir.join(name);
        match std::fs::remove_file(&p) {
            Ok(()) => {}
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
            Err(e) => {
                return Err(Error::io(format!(
                    "cannot remove the old {}: {e}",
                    p.display()
                )))
            }
        }
    }
    Ok(())
}
