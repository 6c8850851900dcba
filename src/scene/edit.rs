//! Edits of a scene (§7 of the notes: new viewpoints, new lighting, objects added and removed,
//! reflectances changed): an edit file in TOML, or the same edits given as `matfit render`
//! flags, applied to a scene file before it is loaded.
//!
//! ```toml
//! remove = ["small_block"]             # objects, groups (every object in them), or lights
//!
//! [camera]                             # replaces the scene's camera (either form); width and
//! eye = [0.5, 1.2, 3.0]                # height default to the scene's
//! target = [0, 0.4, 0]
//! fov_y_deg = 40
//!
//! [[object]]                           # added, as in a scene file; a light if it has emission
//! name = "ball"
//! group = "ball"
//! shape = "sphere"
//! center = [0.2, 0.25, 0.3]
//! radius = 0.25
//! material = { type = "diffuse", rho_d = [0.7, 0.1, 0.1] }
//!
//! [[material]]                         # a group's (or an object's) material, replaced
//! group = "back_wall"
//! material = { type = "diffuse", rho_d = 0.8 }
//!
//! [[move]]                             # an object (or every object of a group), translated
//! object = "big_block"
//! translate = [0.1, 0, -0.05]
//!
//! [[light]]                            # a light's emission, rescaled or replaced
//! object = "light"                     # an emitting object or group, or a [[light]] of the
//! scale = 0.5                          # scene (scale only); or emission = [10, 9, 8]
//! ```
//!
//! Edits apply in the order: remove, material, move, light, object, camera; several edit files
//! apply one after another. Names that match nothing are errors naming the nearest name. The
//! edits work on the scene file's schema ([`SceneFile`]), so the edited scene is loaded and
//! checked exactly as a written one; an added object's relative paths (meshes, textures) are
//! relative to its edit file's folder, and its errors point at the edit file's lines.

use super::camera_spec::{check_camera, edited_camera};
use super::error::SceneError;
use super::load::{build_objects, build_scene};
use super::schema::{Color, MaterialSpec, ObjectSpec, SceneFile, ShapeKind};
use super::Scene;
use serde::Deserialize;
use std::path::{Path, PathBuf};
use toml::Spanned;

/// One edit file (or the edits of a command line), as parsed.
#[derive(Clone, Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct EditFile {
    #[serde(default)]
    pub remove: Vec<String>,
    /// A whole camera table; width and height may be left out (the scene's are kept).
    #[serde(default)]
    pub camera: Option<toml::Table>,
    #[serde(default, rename = "object")]
    pub add: Vec<ObjectSpec>,
    #[serde(default, rename = "material")]
    pub materials: Vec<MaterialEdit>,
    #[serde(default, rename = "move")]
    pub moves: Vec<MoveEdit>,
    #[serde(default, rename = "light")]
    pub lights: Vec<LightEdit>,
}

#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MaterialEdit {
    /// A group, or one object.
    pub group: String,
    pub material: Spanned<MaterialSpec>,
}

#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MoveEdit {
    /// An object, or every object of a group.
    pub object: String,
    pub translate: [f32; 3],
}

#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LightEdit {
    /// An emissive object, or every emissive object of a group.
    pub object: String,
    /// Multiplies the emission (one number, or per channel).
    #[serde(default)]
    pub scale: Option<Color>,
    /// Replaces the emission (makes any object a light).
    #[serde(default)]
    pub emission: Option<Color>,
}

/// An edit with the text it was parsed from and where it came from (for messages and for
/// the relative paths of added objects).
#[derive(Clone, Debug)]
pub struct Edit {
    pub file: EditFile,
    pub text: String,
    /// The edit file, or a name for the command line's edits.
    pub path: PathBuf,
}

impl Edit {
    /// Reads an edit file.
    pub fn read(path: &Path) -> Result<Edit, SceneError> {
        let text = std::fs::read_to_string(path).map_err(|error| SceneError::Io {
            path: path.to_owned(),
            error,
        })?;
        Edit::parse(text, path)
    }

    /// Parses edit text as if it were the file at `path`.
    pub fn parse(text: String, path: &Path) -> Result<Edit, SceneError> {
        let file: EditFile = toml::from_str(&text).map_err(|e| SceneError::Toml {
            path: path.to_owned(),
            message: super::context::with_suggestion(&e.to_string()),
        })?;
        Ok(Edit {
            file,
            text,
            path: path.to_owned(),
        })
    }

    /// Whether the edit changes nothing.
    pub fn is_empty(&self) -> bool {
        let f = &self.file;
        f.remove.is_empty()
            && f.camera.is_none()
            && f.add.is_empty()
            && f.materials.is_empty()
            && f.moves.is_empty()
            && f.lights.is_empty()
    }

    /// Whether the edit adds objects or moves a camera (what `composite` must know).
    pub fn changes_camera(&self) -> bool {
        self.file.camera.is_some()
    }
}

/// Loads the scene file at `path` with `edits` applied in order.
pub fn load_edited(path: &Path, edits: &[Edit]) -> Result<Scene, SceneError> {
    let text = std::fs::read_to_string(path).map_err(|error| SceneError::Io {
        path: path.to_owned(),
        error,
    })?;
    let mut file: SceneFile = toml::from_str(&text).map_err(|e| SceneError::Toml {
        path: path.to_owned(),
        message: super::context::with_suggestion(&e.to_string()),
    })?;
    for e in edits {
        apply(&mut file, e)?;
    }
    build_scene(file, &text, path)
}

/// Applies one edit to a scene file's contents.
pub fn apply(scene: &mut SceneFile, edit: &Edit) -> Result<(), SceneError> {
    let f = &edit.file;
    let err = |message: String| SceneError::Scene {
        path: edit.path.clone(),
        message,
    };
    for name in &f.remove {
        if let Some(i) = scene.lights.iter().position(|l| l.name.get_ref() == name) {
            scene.lights.remove(i);
            continue;
        }
        let hit = resolve(scene, name).map_err(err)?;
        let mut i = 0;
        scene.objects.retain(|_| {
            i += 1;
            !hit.contains(&(i - 1))
        });
    }
    if scene.objects.is_empty() && !f.remove.is_empty() && f.add.is_empty() {
        return Err(err("the edit removes every object of the scene".into()));
    }
    for m in &f.materials {
        for i in resolve(scene, &m.group).map_err(err)? {
            scene.objects[i].material = Some(m.material.clone());
        }
    }
    for m in &f.moves {
        if let Some(bad) = m.translate.iter().find(|x| !x.is_finite()) {
            return Err(err(format!("move of '{}': translate has {bad}", m.object)));
        }
        for i in resolve(scene, &m.object).map_err(err)? {
            translate(&mut scene.objects[i], m.translate);
        }
    }
    for l in &f.lights {
        if let Some(p) = scene
            .lights
            .iter_mut()
            .find(|p| p.name.get_ref() == &l.object)
        {
            let Some(s) = l.scale else {
                return Err(err(format!(
                    "light '{}' is a {} light: give `scale` (its irradiance or intensity is \
                     multiplied), not `emission`",
                    l.object,
                    super::light::kind_name(*p.kind.get_ref())
                )));
            };
            for c in [&mut p.irradiance, &mut p.intensity].into_iter().flatten() {
                *c = Color(std::array::from_fn(|k| c.0[k] * s.0[k]));
            }
            continue;
        }
        let hit = resolve(scene, &l.object).map_err(err)?;
        match (&l.scale, &l.emission) {
            (Some(_), Some(_)) | (None, None) => {
                return Err(err(format!(
                    "light '{}': give either `scale` or `emission`",
                    l.object
                )))
            }
            (None, Some(e)) => {
                for &i in &hit {
                    let span = scene.objects[i].name.span();
                    scene.objects[i].emission = Some(Spanned::new(span, *e));
                }
            }
            (Some(s), None) => {
                let lights: Vec<usize> = hit
                    .into_iter()
                    .filter(|&i| scene.objects[i].emission.is_some())
                    .collect();
                if lights.is_empty() {
                    return Err(err(format!(
                        "'{}' is not a light (it has no emission): give `emission` to make it one",
                        l.object
                    )));
                }
                for i in lights {
                    let o = &mut scene.objects[i];
                    let e = o.emission.as_ref().expect("filtered");
                    let v = Color(std::array::from_fn(|k| e.get_ref().0[k] * s.0[k]));
                    o.emission = Some(Spanned::new(e.span(), v));
                }
            }
        }
    }
    let camera = match &f.camera {
        Some(table) => Some(edited_camera(table, &scene.camera).map_err(err)?),
        None => None,
    };
    if !f.add.is_empty() || camera.is_some() {
        // Checked on their own against the edit's text first, so that errors point at the
        // edit file's lines and relative paths resolve against its folder.
        let alone = SceneFile {
            render: None,
            camera: camera.clone().unwrap_or_else(|| scene.camera.clone()),
            groups: Vec::new(),
            objects: f.add.clone(),
            lights: Vec::new(),
            environment: None,
            stray_light: None,
            views: Vec::new(),
        };
        if f.add.is_empty() {
            check_camera(&alone, &edit.text, &edit.path)?;
        } else {
            build_objects(alone, &edit.text, &edit.path)?;
        }
    }
    let dir = edit.path.parent().unwrap_or(Path::new(""));
    for o in &f.add {
        let name = o.name.get_ref();
        if scene.objects.iter().any(|s| s.name.get_ref() == name) {
            return Err(err(format!(
                "the added object '{name}' has the name of an object of the scene: rename it"
            )));
        }
        let mut o = o.clone();
        absolute_paths(&mut o, dir);
        scene.objects.push(o);
    }
    if let Some(c) = camera {
        scene.camera = c;
    }
    Ok(())
}

/// The objects that `name` means: the object of that name, else every object of the group
/// of that name. An error names the nearest object or group.
fn resolve(scene: &SceneFile, name: &str) -> Result<Vec<usize>, String> {
    if let Some(i) = scene.objects.iter().position(|o| o.name.get_ref() == name) {
        return Ok(vec![i]);
    }
    let in_group: Vec<usize> = (0..scene.objects.len())
        .filter(|&i| {
            scene.objects[i]
                .group
                .as_ref()
                .is_some_and(|g| g.get_ref() == name)
        })
        .collect();
    if !in_group.is_empty() {
        return Ok(in_group);
    }
    let mut names: Vec<&str> = scene
        .objects
        .iter()
        .map(|o| o.name.get_ref().as_str())
        .collect();
    names.extend(
        scene
            .objects
            .iter()
            .filter_map(|o| o.group.as_ref().map(|g| g.get_ref().as_str())),
    );
    let nearest = names
        .iter()
        .map(|n| (strsim::damerau_levenshtein(name, n), *n))
        .min();
    Err(match nearest {
        Some((d, n)) if d <= 3.max(name.len() / 3) => {
            format!("no object or group is named '{name}' (did you mean '{n}'?)")
        }
        _ => {
            names.sort_unstable();
            names.dedup();
            format!(
                "no object or group is named '{name}'; the scene has: {}",
                names.join(", ")
            )
        }
    })
}

/// Moves an object by `t` in world space, whatever its shape. A transform applies scale,
/// rotation, then translation: where there is one (or for a mesh), adding to its translation
/// moves the object in world space; else the shape's own coordinates move.
fn translate(o: &mut ObjectSpec, t: [f32; 3]) {
    let add = |p: &mut Option<[f32; 3]>| {
        if let Some(p) = p {
            for k in 0..3 {
                p[k] += t[k];
            }
        }
    };
    if o.transform.is_some() || *o.shape.get_ref() == ShapeKind::Mesh {
        let tr = o.transform.get_or_insert_with(Default::default);
        let mut p = Some(tr.translate.unwrap_or([0.0; 3]));
        add(&mut p);
        tr.translate = p;
        return;
    }
    match o.shape.get_ref() {
        ShapeKind::Quad => add(&mut o.corner),
        ShapeKind::Box => {
            add(&mut o.min);
            add(&mut o.max);
        }
        ShapeKind::Sphere => add(&mut o.center),
        ShapeKind::Mesh => unreachable!("handled above"),
    }
}

/// Makes an added object's file references absolute (they are relative to its edit file).
fn absolute_paths(o: &mut ObjectSpec, dir: &Path) {
    let abs = |s: &str| -> String {
        let p = Path::new(s);
        if p.is_absolute() {
            s.to_string()
        } else {
            std::path::absolute(dir.join(p))
                .unwrap_or_else(|_| dir.join(p))
                .display()
                .to_string()
        }
    };
    if let Some(f) = &o.file {
        o.file = Some(Spanned::new(f.span(), abs(f.get_ref())));
    }
    if let Some(m) = &o.material {
        if let MaterialSpec::Textured { texture, .. } = m.get_ref() {
            let mut spec = m.get_ref().clone();
            if let MaterialSpec::Textured { texture: t, .. } = &mut spec {
                *t = abs(texture);
            }
            o.material = Some(Spanned::new(m.span(), spec));
        }
    }
}

/// The edits given as `matfit render` flags, as the edit text they stand for (so that they go
/// through the same parser and checks as an edit file).
#[derive(Clone, Debug, Default)]
pub struct EditFlags {
    pub remove: Vec<String>,
    /// NAME=dx,dy,dz
    pub moves: Vec<String>,
    /// NAME=K or NAME=r,g,b
    pub scale_lights: Vec<String>,
    /// GROUP={ type = "diffuse", rho_d = 0.5 } (an inline TOML table)
    pub materials: Vec<String>,
    /// An object as an inline TOML table: { name = "ball", group = "ball", shape = ... }
    pub add: Vec<String>,
    /// A look-at camera: eye, target, optional vertical field of view in degrees.
    pub look_from: Option<[f32; 3]>,
    pub look_at: Option<[f32; 3]>,
    pub fov_y_deg: Option<f32>,
}

impl EditFlags {
    /// The flags as one edit (None when there are none).
    pub fn to_edit(&self) -> Result<Option<Edit>, SceneError> {
        let path = PathBuf::from("(command-line edits)");
        let bad = |message: String| SceneError::Scene {
            path: path.clone(),
            message,
        };
        let q = |s: &str| toml::Value::String(s.to_string()).to_string();
        // Top-level keys first: a TOML table header ends the top level.
        let mut text = String::new();
        if !self.remove.is_empty() {
            let names: Vec<String> = self.remove.iter().map(|n| q(n)).collect();
            text += &format!("remove = [{}]\n", names.join(", "));
        }
        if !self.add.is_empty() {
            let mut tables = Vec::new();
            for a in &self.add {
                tables.push(inline_table(a).map_err(bad)?);
            }
            text += &format!("object = [{}]\n", tables.join(", "));
        }
        for m in &self.moves {
            let (name, v) = split_flag(m, "--move", "NAME=DX,DY,DZ").map_err(bad)?;
            let t = numbers(v, 3).map_err(|e| bad(format!("--move {m}: {e}")))?;
            text += &format!("[[move]]\nobject = {}\ntranslate = {t}\n", q(name));
        }
        for l in &self.scale_lights {
            let (name, v) = split_flag(l, "--scale-light", "NAME=K or NAME=R,G,B").map_err(bad)?;
            let k = numbers(v, 1)
                .or_else(|_| numbers(v, 3))
                .map_err(|e| bad(format!("--scale-light {l}: {e}")))?;
            let k = k.trim_start_matches('[').trim_end_matches(']');
            let k = if k.contains(',') {
                format!("[{k}]")
            } else {
                k.to_string()
            };
            text += &format!("[[light]]\nobject = {}\nscale = {k}\n", q(name));
        }
        for m in &self.materials {
            let (name, v) =
                split_flag(m, "--material", "GROUP={ type = \"diffuse\", rho_d = 0.5 }")
                    .map_err(bad)?;
            text += &format!(
                "[[material]]\ngroup = {}\nmaterial = {}\n",
                q(name),
                inline(v)
            );
        }
        match (self.look_from, self.look_at) {
            (Some(e), Some(t)) => {
                text += &format!("[camera]\neye = {e:?}\ntarget = {t:?}\n");
                text += &format!("fov_y_deg = {:?}\n", self.fov_y_deg.unwrap_or(40.0));
            }
            (None, None) if self.fov_y_deg.is_none() => {}
            _ => {
                return Err(bad(
                    "a new camera needs both --look-from and --look-at (and optionally --fov)"
                        .into(),
                ))
            }
        }
        if text.is_empty() {
            return Ok(None);
        }
        Edit::parse(text, &path).map(Some)
    }
}

fn split_flag<'a>(s: &'a str, flag: &str, form: &str) -> Result<(&'a str, &'a str), String> {
    match s.split_once('=') {
        Some((n, v)) if !n.trim().is_empty() && !v.trim().is_empty() => Ok((n.trim(), v.trim())),
        _ => Err(format!("{flag} '{s}': expected {form}")),
    }
}

/// "a,b,c" as a TOML array (or one number), checking there are `n` finite numbers.
fn numbers(v: &str, n: usize) -> Result<String, String> {
    let xs: Vec<f32> = v
        .split(',')
        .map(|x| x.trim().parse::<f32>())
        .collect::<Result<_, _>>()
        .map_err(|_| format!("'{v}' is not {n} comma-separated number(s)"))?;
    if xs.len() != n || xs.iter().any(|x| !x.is_finite()) {
        return Err(format!("'{v}' is not {n} comma-separated finite number(s)"));
    }
    Ok(if n == 1 {
        format!("{:?}", xs[0])
    } else {
        format!("{xs:?}")
    })
}

/// An inline table given with or without its braces.
fn inline(v: &str) -> String {
    let v = v.trim();
    if v.starts_with('{') {
        v.to_string()
    } else {
        format!("{{ {v} }}")
    }
}

/// An object given as an inline table (`{ a = 1, b = 2 }` or `a = 1, b = 2`), checked to be one.
fn inline_table(v: &str) -> Result<String, String> {
    let t = inline(v);
    let doc: toml::Table = toml::from_str(&format!("x = {t}"))
        .map_err(|e| format!("--add '{v}': not an inline table: {e}"))?;
    match doc.get("x") {
        Some(toml::Value::Table(_)) => Ok(t),
        _ => Err(format!("--add '{v}': not an inline table")),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const SCENE: &str = r#"
[camera]
width = 64
height = 48
eye = [0, 1, 3]
target = [0, 1, 0]
fov_y_deg = 40

[[object]]
name = "floor"
group = "floor"
shape = "quad"
corner = [-1, 0, 1]
edge_u = [2, 0, 0]
edge_v = [0, 0, -2]
material = { type = "diffuse", rho_d = 0.5 }

[[object]]
name = "block"
group = "blocks"
shape = "box"
min = [0, 0, 0]
max = [0.2, 0.2, 0.2]
material = { type = "diffuse", rho_d = 0.3 }

[[object]]
name = "light"
group = "light"
shape = "quad"
corner = [-0.2, 1.9, 0.2]
edge_u = [0.4, 0, 0]
edge_v = [0, 0, -0.4]
emission = [4, 4, 4]
"#;

    fn edited(edit: &str) -> Result<SceneFile, SceneError> {
        let mut f: SceneFile = toml::from_str(SCENE).unwrap();
        let e = Edit::parse(edit.to_string(), Path::new("edit.toml"))?;
        apply(&mut f, &e)?;
        Ok(f)
    }

    #[test]
    fn removes_by_object_and_group_and_names_the_nearest() {
        let f = edited("remove = [\"blocks\"]").unwrap();
        assert_eq!(f.objects.len(), 2);
        assert!(f.objects.iter().all(|o| o.name.get_ref() != "block"));
        let e = edited("remove = [\"blok\"]").unwrap_err().to_string();
        assert!(
            e.contains("'blok'") && e.contains("did you mean 'block'"),
            "{e}"
        );
    }

    #[test]
    fn moves_rescales_and_recolours() {
        let f = edited(
            "[[move]]\nobject = \"block\"\ntranslate = [1, 0, -1]\n\
             [[light]]\nobject = \"light\"\nscale = 0.5\n\
             [[material]]\ngroup = \"floor\"\nmaterial = { type = \"diffuse\", rho_d = 0.9 }\n",
        )
        .unwrap();
        let b = &f.objects[1];
        assert_eq!(b.min, Some([1.0, 0.0, -1.0]));
        assert_eq!(b.max, Some([1.2, 0.2, -0.8]));
        assert_eq!(
            f.objects[2].emission.as_ref().unwrap().get_ref().0,
            [2.0; 3]
        );
        assert_eq!(
            *f.objects[0].material.as_ref().unwrap().get_ref(),
            MaterialSpec::Diffuse {
                rho_d: Color([0.9; 3])
            }
        );
        let e = edited("[[light]]\nobject = \"floor\"\nscale = 2\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("not a light"), "{e}");
    }

    #[test]
    fn adds_objects_and_replaces_the_camera_keeping_its_size() {
        let f = edited(
            "[camera]\neye = [2, 1, 2]\ntarget = [0, 0, 0]\nfov_y_deg = 30\n\
             [[object]]\nname = \"ball\"\ngroup = \"ball\"\nshape = \"sphere\"\n\
             center = [0, 0.3, 0]\nradius = 0.3\n",
        )
        .unwrap();
        assert_eq!(f.objects.len(), 4);
        assert_eq!((f.camera.width, f.camera.height), (64, 48));
        assert_eq!(f.camera.eye, Some([2.0, 1.0, 2.0]));
        // A duplicate name and a bad added object are errors at the edit file's line.
        let e = edited(
            "[[object]]\nname = \"block\"\ngroup = \"x\"\nshape = \"sphere\"\ncenter = [0, 0, 0]\nradius = 1\n",
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("rename it"), "{e}");
        let e = edited(
            "\n\n[[object]]\nname = \"b\"\ngroup = \"x\"\nshape = \"sphere\"\ncenter = [0, 0, 0]\nradius = -1\n",
        )
        .unwrap_err()
        .to_string();
        assert!(e.starts_with("edit.toml:"), "{e}");
        // An added object the camera does not see (behind it) is a valid edit: a later edit of
        // the camera may look at it, and the whole edited scene is checked as one.
        let f = edited(
            "[[object]]\nname = \"behind\"\ngroup = \"x\"\nshape = \"sphere\"\n\
             center = [0, 0, 50]\nradius = 0.3\n",
        )
        .unwrap();
        assert_eq!(f.objects.len(), 4);
    }

    #[test]
    fn flags_become_the_same_edit() {
        let flags = EditFlags {
            remove: vec!["block".into()],
            moves: vec!["floor=0,0.5,0".into()],
            scale_lights: vec!["light=1,2,3".into()],
            materials: vec!["floor=type = \"diffuse\", rho_d = 0.2".into()],
            add: vec![
                "{ name = \"ball\", group = \"ball\", shape = \"sphere\", center = [0, 0.3, 0], radius = 0.3 }"
                    .into(),
            ],
            look_from: Some([1.0, 1.0, 1.0]),
            look_at: Some([0.0, 0.0, 0.0]),
            fov_y_deg: None,
        };
        let e = flags.to_edit().unwrap().unwrap();
        let mut f: SceneFile = toml::from_str(SCENE).unwrap();
        apply(&mut f, &e).unwrap();
        let names: Vec<&str> = f
            .objects
            .iter()
            .map(|o| o.name.get_ref().as_str())
            .collect();
        assert_eq!(names, ["floor", "light", "ball"]);
        assert_eq!(f.objects[0].corner, Some([-1.0, 0.5, 1.0]));
        assert_eq!(
            f.objects[1].emission.as_ref().unwrap().get_ref().0,
            [4.0, 8.0, 12.0]
        );
        assert_eq!(f.camera.fov_y_deg, Some(40.0));
        let bad = EditFlags {
            moves: vec!["floor=1,2".into()],
            ..Default::default()
        };
        assert!(bad
            .to_edit()
            .unwrap_err()
            .to_string()
            .contains("3 comma-separated"));
        assert!(EditFlags::default().to_edit().unwrap().is_none());
    }
}
