//! Checks of a loaded scene that do not stop it from loading but would make a command's work
//! useless or suspicious: group names that look like typos, and lights that nothing in view
//! can receive light from. Commands run them before the long work.

use super::Scene;
use crate::math::Vec3;

/// What the camera's view says about the scene's lights.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Lighting {
    /// Emitting objects (indices into `scene.objects`).
    pub emitters: Vec<usize>,
    /// Emitters whose front side (along the surface normal, edge_u × edge_v for a quad) faces
    /// away from every surface point the camera sees: they light nothing in the picture.
    pub facing_away: Vec<usize>,
    /// Emitters whose front side meets a surface within [`NEAR_SURFACE`] of the scene's size
    /// over most of their area (a ceiling lamp written with its edges swapped, facing the
    /// ceiling a centimetre away: it lights the room only through that surface), with the
    /// median distance.
    pub near_surface: Vec<(usize, f32)>,
    /// Emitters the camera sees directly.
    pub in_view: Vec<usize>,
    /// Punctual lights (`[[light]]`) and the environment, which are not checked for what they
    /// light.
    pub punctual: usize,
}

impl Lighting {
    /// Whether the scene has no light at all.
    pub fn none(&self) -> bool {
        self.emitters.is_empty() && self.punctual == 0
    }

    /// True when no light can light anything the camera sees: a render would be black.
    pub fn dark(&self) -> bool {
        self.punctual == 0 && self.emitters.len() == self.facing_away.len()
    }
}

/// A light's front side "meets a surface" when the nearest surface along its normal is closer
/// than this fraction of the scene's bounding-box diagonal (3.5 cm in a room 5 m across) over
/// at least [`NEAR_SHARE`] of the points tried on it.
pub const NEAR_SURFACE: f32 = 0.005;
pub const NEAR_SHARE: f32 = 0.9;

/// Points the camera sees on a `nx`×`ny` grid of the film: (point, normal on the camera's
/// side, object).
fn visible_points(scene: &Scene, nx: u32, ny: u32) -> Vec<(Vec3, Vec3, usize)> {
    scene
        .camera_grid_hits(nx, ny)
        .into_iter()
        .map(|(_, ray, h)| {
            let n = if h.ng.dot(ray.d) < 0.0 { h.ng } else { -h.ng };
            (h.p, n, h.object as usize)
        })
        .collect()
}

/// Which emitters can light what the camera sees. Geometric only (occlusion is not tested):
/// it finds a light put in backwards, not one hidden behind a wall.
pub fn lighting(scene: &Scene) -> Lighting {
    let g = &scene.geometry;
    let pts = visible_points(scene, 48, 36);
    let (lo, hi) = g.positions.iter().fold(
        (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)),
        |(lo, hi), &p| (lo.min(p), hi.max(p)),
    );
    let near = NEAR_SURFACE * (hi - lo).length().max(1e-6);
    let mut out = Lighting {
        punctual: scene.punctual_lights.len() + usize::from(scene.environment.is_some()),
        ..Lighting::default()
    };
    for (e, obj) in scene.objects.iter().enumerate() {
        if !obj.is_emitter() {
            continue;
        }
        out.emitters.push(e);
        if pts.iter().any(|&(_, _, o)| o == e) {
            out.in_view.push(e);
        }
        // At most ~256 triangles of a big emitting mesh: a light that faces some surface
        // does so over much of its area.
        let n_tris = obj.tri_range.len().max(1);
        let step = n_tris.div_ceil(256);
        let lights_something = obj.tri_range.clone().step_by(step).any(|t| {
            let tri = &g.tris[t as usize];
            let ng = g.faces[t as usize].ng;
            let v = tri.v.map(|i| g.positions[i as usize]);
            let centroid = (v[0] + v[1] + v[2]) / 3.0;
            [centroid, v[0], v[1], v[2]].iter().any(|&q| {
                pts.iter()
                    .any(|&(p, n, o)| o != e && ng.dot(p - q) > 0.0 && n.dot(q - p) > 0.0)
            })
        });
        if !lights_something {
            out.facing_away.push(e);
        } else if let Some(d) = front_blocked(scene, obj.tri_range.clone(), step, near) {
            out.near_surface.push((e, d));
        }
    }
    out
}

/// The median distance to the nearest surface in front of the triangles `tris` (every `step`-th)
/// when at least [`NEAR_SHARE`] of them meet one within `near`.
fn front_blocked(
    scene: &Scene,
    tris: std::ops::Range<u32>,
    step: usize,
    near: f32,
) -> Option<f32> {
    let g = &scene.geometry;
    let mut d: Vec<f32> = tris
        .step_by(step)
        .map(|t| {
            let tri = &g.tris[t as usize];
            let ng = g.faces[t as usize].ng;
            let v = tri.v.map(|i| g.positions[i as usize]);
            let centroid = (v[0] + v[1] + v[2]) / 3.0;
            let ray = crate::geometry::Ray::new(centroid + ng * (1e-4 * near), ng);
            scene.intersect(&ray, near).map_or(f32::INFINITY, |h| h.t)
        })
        .collect();
    let n = d.len();
    let hits = d.iter().filter(|x| x.is_finite()).count();
    if n == 0 || (hits as f32) < NEAR_SHARE * n as f32 {
        return None;
    }
    d.sort_by(f32::total_cmp);
    Some(d[n / 2])
}

/// One message per group name that looks like a typo of another: one edit away from it, or a
/// group of a single object whose name is close to another group's. Names the object and line.
pub fn group_name_warnings(scene: &Scene) -> Vec<String> {
    let mut out = Vec::new();
    let groups = &scene.groups;
    for (a, ga) in groups.iter().enumerate() {
        for (b, gb) in groups.iter().enumerate() {
            if a == b {
                continue;
            }
            if numbered_series(&ga.name, &gb.name) {
                continue;
            }
            let d = strsim::damerau_levenshtein(&ga.name, &gb.name);
            let (na, nb) = (ga.objects.len(), gb.objects.len());
            // The suspect is the smaller group (the later one on a tie, so each pair warns once).
            let suspect = na < nb || (na == nb && a > b);
            let close = d == 1
                || (na == 1 && d == 2 && ga.name.chars().count().min(gb.name.chars().count()) >= 5);
            if !(suspect && close) {
                continue;
            }
            let Some(&o) = ga.objects.first() else {
                continue;
            };
            let obj = &scene.objects[o];
            out.push(format!(
                "{}:{}: object '{}' is in group '{}', {} edit{} away from group '{}' ({} object{}): \
                 a typo? A new group gets its own material",
                scene.path.display(),
                obj.line,
                obj.name,
                ga.name,
                d,
                if d == 1 { "" } else { "s" },
                gb.name,
                nb,
                if nb == 1 { "" } else { "s" },
            ));
        }
    }
    out
}

/// Whether two names are members of a numbered series ("desk_1", "desk_2"; "books9",
/// "books10"): the same stem, each with a number after it. A room's furniture is named so, and
/// each pair would otherwise look one edit from a typo: 46 such groups gave 1,000 warnings.
/// So are a name and the same name numbered ("WhitePaint", "WhitePaint2"), as exporters name a
/// second material of one look, once the name is more than an initial or two.
fn numbered_series(a: &str, b: &str) -> bool {
    match (numbered_stem(a), numbered_stem(b)) {
        (Some(x), Some(y)) => x == y,
        (Some(x), None) => x == b && b.chars().count() >= 3,
        (None, Some(y)) => y == a && a.chars().count() >= 3,
        (None, None) => false,
    }
}

/// The name without its trailing number, if it ends in one.
fn numbered_stem(s: &str) -> Option<&str> {
    let t = s.trim_end_matches(|c: char| c.is_ascii_digit());
    (t.len() < s.len()).then_some(t)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scene_with_groups(names: &[&str]) -> Scene {
        let mut text = String::from(
            "[camera]\nwidth = 8\nheight = 8\nfov_y_deg = 40\n\
             eye = [0, 0, 3]\ntarget = [0, 0, 0]\n",
        );
        for (i, g) in names.iter().enumerate() {
            text += &format!(
                "[[object]]\nname = \"o{i}\"\ngroup = \"{g}\"\nshape = \"sphere\"\n\
                 center = [{i}, 0, 0]\nradius = 0.1\n"
            );
        }
        super::super::load::parse_scene(&text, std::path::Path::new("scene.toml")).unwrap()
    }

    #[test]
    fn a_numbered_series_of_groups_is_not_a_typo_but_a_misspelling_is() {
        let series = scene_with_groups(&[
            "desk_1",
            "desk_2",
            "desk_10",
            "books9",
            "books10",
            "WhitePaint",
            "WhitePaint2",
        ]);
        assert_eq!(group_name_warnings(&series), Vec::<String>::new());
        let typo = scene_with_groups(&["floor", "flor", "desk_1", "desk_x"]);
        let w = group_name_warnings(&typo);
        assert_eq!(w.len(), 2, "{w:?}");
        assert!(
            w[0].contains("group 'flor', 1 edit away from group 'floor'"),
            "{w:?}"
        );
        assert!(
            w[1].contains("'desk_x'") && w[1].contains("'desk_1'"),
            "{w:?}"
        );
        assert!(numbered_series("a2", "a13") && !numbered_series("a", "a1"));
        assert!(numbered_series("WhitePaint", "WhitePaint2") && numbered_series("rug7", "rug"));
        assert!(!numbered_series("desk_1", "dusk_2") && !numbered_series("7", "x7"));
    }
}
