//! Writes a scene back out as TOML: how `recover` saves the recovered scene so that
//! `matfit render` can use it. Materials come from the scene's objects; mesh and texture paths
//! are rewritten so that they still resolve from the new file's folder. When the scene's file
//! is still what was loaded, it is edited in place (toml_edit: comments, key order and inline
//! arrays kept, only materials and paths changed), so that the two files can be diffed.

use super::schema::{Color, MaterialSpec, SceneFile};
use super::{Material, Scene};
use std::path::{Path, PathBuf};
use toml::Spanned;

/// The schema form of a material.
pub fn material_spec(m: &Material) -> MaterialSpec {
    let c = |v: crate::math::Rgb| Color(v.to_array());
    match m {
        Material::Diffuse { rho_d } => MaterialSpec::Diffuse { rho_d: c(*rho_d) },
        Material::Mirror { rho_s } => MaterialSpec::Mirror { rho_s: c(*rho_s) },
        Material::DiffuseMirror { rho_d, rho_s } => MaterialSpec::DiffuseMirror {
            rho_d: c(*rho_d),
            rho_s: c(*rho_s),
        },
        Material::Ward {
            rho_d,
            rho_s,
            alpha_x,
            alpha_y,
            theta,
        } => {
            let [alpha, alpha_x, alpha_y, theta_deg] = lobe_keys(*alpha_x, *alpha_y, *theta);
            MaterialSpec::Ward {
                rho_d: c(*rho_d),
                rho_s: c(*rho_s),
                alpha,
                alpha_x,
                alpha_y,
                theta_deg,
            }
        }
        Material::Microfacet {
            rho_d,
            rho_s,
            alpha_x,
            alpha_y,
            theta,
            distribution,
        } => {
            let [alpha, alpha_x, alpha_y, theta_deg] = lobe_keys(*alpha_x, *alpha_y, *theta);
            MaterialSpec::Microfacet {
                rho_d: c(*rho_d),
                rho_s: c(*rho_s),
                alpha,
                alpha_x,
                alpha_y,
                theta_deg,
                distribution: *distribution,
            }
        }
        Material::Plastic {
            rho_d,
            rho_s,
            alpha,
            eta,
            distribution,
        } => MaterialSpec::Plastic {
            rho_d: c(*rho_d),
            rho_s: c(*rho_s),
            alpha: *alpha,
            // Written even at the default: a recovered η is an assumption the reader should see.
            eta: Some(*eta),
            distribution: *distribution,
        },
        Material::Textured {
            texture,
            scale,
            varnish,
        } => {
            let atlas = match &texture.mapping {
                super::texture::Mapping::Atlas(a) => Some(a.texel),
                super::texture::Mapping::Uv => None,
            };
            let [alpha, alpha_x, alpha_y, theta_deg] = match varnish {
                Some(v) => lobe_keys(v.alpha_x, v.alpha_y, v.theta),
                None => [None; 4],
            };
            MaterialSpec::Textured {
                texture: texture.path.to_string_lossy().into_owned(),
                scale: Some(c(*scale)),
                mapping: atlas.map(|_| "atlas".to_string()),
                texel_size: atlas,
                rho_s: varnish.map(|v| c(v.rho_s)),
                alpha,
                alpha_x,
                alpha_y,
                theta_deg,
                eta: None,
                distribution: None,
            }
        }
        Material::TexturedPlastic {
            texture,
            scale,
            rho_s,
            alpha,
            eta,
            distribution,
        } => {
            let atlas = match &texture.mapping {
                super::texture::Mapping::Atlas(a) => Some(a.texel),
                super::texture::Mapping::Uv => None,
            };
            MaterialSpec::Textured {
                texture: texture.path.to_string_lossy().into_owned(),
                scale: Some(c(*scale)),
                mapping: atlas.map(|_| "atlas".to_string()),
                texel_size: atlas,
                rho_s: Some(c(*rho_s)),
                alpha: Some(*alpha),
                alpha_x: None,
                alpha_y: None,
                theta_deg: None,
                eta: Some(*eta),
                distribution: Some(*distribution),
            }
        }
        Material::Black => MaterialSpec::Black,
    }
}

/// A Ward lobe's keys (`alpha`, `alpha_x`, `alpha_y`, `theta_deg`): `alpha` alone where it is
/// isotropic, the other three where it is not.
fn lobe_keys(alpha_x: f32, alpha_y: f32, theta: f32) -> [Option<f32>; 4] {
    if alpha_x == alpha_y && theta == 0.0 {
        [Some(alpha_x), None, None, None]
    } else {
        [None, Some(alpha_x), Some(alpha_y), Some(theta.to_degrees())]
    }
}

/// A path written in a scene at `from_dir`, made to resolve from `to_dir`.
fn rebase(p: &str, from_dir: &Path, to_dir: &Path) -> String {
    let abs = std::path::absolute(from_dir.join(p)).unwrap_or_else(|_| from_dir.join(p));
    let to = std::path::absolute(to_dir).unwrap_or_else(|_| to_dir.to_path_buf());
    relative(&abs, &to)
        .unwrap_or(abs)
        .to_string_lossy()
        .into_owned()
}

/// `path` relative to the folder `base` (both absolute), if they share a root.
pub(crate) fn relative(path: &Path, base: &Path) -> Option<PathBuf> {
    let p: Vec<_> = path.components().collect();
    let b: Vec<_> = base.components().collect();
    let common = p.iter().zip(&b).take_while(|(a, b)| a == b).count();
    if common == 0 {
        return None;
    }
    let mut out = PathBuf::new();
    for _ in common..b.len() {
        out.push("..");
    }
    for c in &p[common..] {
        out.push(c);
    }
    Some(out)
}

/// The scene as a TOML document to be saved at `dest` (paths are rewritten for `dest`'s folder):
/// the scene's own file with its materials replaced where it can, else written anew.
pub fn scene_to_toml(scene: &Scene, dest: &Path) -> String {
    let from_dir = scene.path.parent().unwrap_or(Path::new("."));
    let to_dir = dest.parent().unwrap_or(Path::new("."));
    std::fs::read_to_string(&scene.path)
        .ok()
        .and_then(|text| edit_source(scene, &text, from_dir, to_dir))
        .unwrap_or_else(|| fresh_toml(scene, from_dir, to_dir))
}

/// The recovered scene's file: `toml` (from [`scene_to_toml`]) without the comments that opened
/// the source file (they described the input, e.g. "with the true materials"), under `header`
/// (lines to be written as comments), and with `camera`'s pose in `[camera]`'s calibrated form
/// when given (a refined pose the fit was run with).
pub fn recovered_toml(toml: &str, header: &str, camera: Option<&super::Camera>) -> String {
    let body = toml
        .lines()
        .skip_while(|l| {
            let t = l.trim_start();
            t.is_empty() || t.starts_with('#')
        })
        .collect::<Vec<_>>()
        .join("\n");
    let body = camera.and_then(|c| with_camera(&body, c)).unwrap_or(body);
    let mut out: String = header
        .lines()
        .map(|l| format!("# {}\n", l.trim_end()))
        .collect();
    out.push('\n');
    out.push_str(body.trim_end());
    out.push('\n');
    out
}

/// `text` with `[camera]`'s pose and intrinsics replaced by `c`'s, in the calibrated form
/// (cx, cy in OpenCV's convention: pixel centres at integers); the lens and projection stay.
fn with_camera(text: &str, c: &super::Camera) -> Option<String> {
    let mut doc: toml_edit::DocumentMut = text.parse().ok()?;
    let t = doc.get_mut("camera")?.as_table_like_mut()?;
    for k in [
        "eye",
        "target",
        "up",
        "fov_y_deg",
        "width_m",
        "fx",
        "fy",
        "cx",
        "cy",
        "rotation",
        "translation",
    ] {
        t.remove(k);
    }
    // The f32's shortest decimal form (57.941124, not 57.941123962402344).
    let num = |x: f32| x.to_string().parse::<f64>().unwrap_or(f64::from(x));
    let arr = |v: [f32; 3]| {
        let mut a = toml_edit::Array::new();
        for x in v {
            a.push(num(x));
        }
        a
    };
    t.insert("fx", toml_edit::value(num(c.fx)));
    t.insert("fy", toml_edit::value(num(c.fy)));
    t.insert("cx", toml_edit::value(num(c.cx - 0.5)));
    t.insert("cy", toml_edit::value(num(c.cy - 0.5)));
    let mut rows = toml_edit::Array::new();
    for i in 0..3 {
        rows.push(arr(c.r.row(i).to_array()));
    }
    t.insert("rotation", toml_edit::value(rows));
    t.insert("translation", toml_edit::value(arr(c.t.to_array())));
    Some(doc.to_string())
}

/// A material as an inline table: `{ type = "ward", rho_d = [0.1, 0.1, 0.1], ... }`.
fn inline_material(m: &MaterialSpec) -> Option<toml_edit::Value> {
    #[derive(serde::Serialize)]
    struct Wrap<'a> {
        material: &'a MaterialSpec,
    }
    let text = toml::to_string(&Wrap { material: m }).ok()?;
    let doc: toml_edit::DocumentMut = text.parse().ok()?;
    let mut v = doc.get("material")?.clone().into_value().ok()?;
    if let Some(t) = v.as_inline_table_mut() {
        t.fmt();
    }
    Some(v)
}

/// `text` (the scene's file) with each object's material set to the scene's and its paths
/// rebased; None when the file no longer matches the scene or has a layout this does not edit.
fn edit_source(scene: &Scene, text: &str, from_dir: &Path, to_dir: &Path) -> Option<String> {
    let file: SceneFile = toml::from_str(text).ok()?;
    // The file changed since it was loaded: it does not describe this scene.
    if toml::to_string(&file).ok()? != toml::to_string(&scene.source).ok()? {
        return None;
    }
    let mut doc: toml_edit::DocumentMut = text.parse().ok()?;
    let objects = doc.get_mut("object")?.as_array_of_tables_mut()?;
    if objects.len() != scene.objects.len() {
        return None;
    }
    for ((t, obj), spec) in objects.iter_mut().zip(&scene.objects).zip(&file.objects) {
        if let Some(v) = t.get_mut("file").and_then(|i| i.as_value_mut()) {
            let rebased = rebase(v.as_str()?, from_dir, to_dir);
            let decor = v.decor().clone();
            *v = rebased.into();
            *v.decor_mut() = decor;
        }
        // An emitter given no material reflects nothing: nothing to write.
        if spec.material.is_none() && matches!(obj.material, Material::Black) {
            continue;
        }
        let mut m = material_spec(&obj.material);
        // Unchanged (a fixed group): the user's line stays, unless a texture path needs rebasing.
        let textured = matches!(m, MaterialSpec::Textured { .. });
        if !textured && spec.material.as_ref().map(|s| s.get_ref()) == Some(&m) {
            continue;
        }
        if let MaterialSpec::Textured { texture, .. } = &mut m {
            *texture = rebase(texture, from_dir, to_dir);
        }
        let mut new = inline_material(&m)?;
        match t.get_mut("material").and_then(|i| i.as_value_mut()) {
            Some(v) => {
                *new.decor_mut() = v.decor().clone();
                *v = new;
            }
            None => {
                t.insert("material", toml_edit::Item::Value(new));
            }
        }
    }
    // A fitted stray light replaces the file's (or is added after everything else).
    let given = file.stray_light.as_ref().map(|s| s.get_ref().radiance);
    let now = stray_light_spec(scene).map(|s| s.get_ref().radiance);
    if given != now {
        match now {
            Some(r) => {
                let mut t = toml_edit::Table::new();
                let mut a = toml_edit::Array::new();
                for v in r {
                    a.push(v as f64);
                }
                t.insert("radiance", toml_edit::value(a));
                doc.insert("stray_light", toml_edit::Item::Table(t));
            }
            None => {
                doc.remove("stray_light");
            }
        }
    }
    Some(doc.to_string())
}

/// The scene's stray light as written: None when there is none.
fn stray_light_spec(scene: &Scene) -> Option<Spanned<super::schema::StrayLightSpec>> {
    (scene.stray_light.max_element() > 0.0).then(|| {
        Spanned::new(
            0..0,
            super::schema::StrayLightSpec {
                radiance: scene.stray_light.to_array(),
            },
        )
    })
}

/// The scene written from its schema form (comments and layout of the source are lost).
fn fresh_toml(scene: &Scene, from_dir: &Path, to_dir: &Path) -> String {
    let mut file: SceneFile = scene.source.clone();
    for (spec, obj) in file.objects.iter_mut().zip(&scene.objects) {
        if let Some(f) = &spec.file {
            spec.file = Some(Spanned::new(0..0, rebase(f.get_ref(), from_dir, to_dir)));
        }
        let mut m = material_spec(&obj.material);
        if let MaterialSpec::Textured { texture, .. } = &mut m {
            *texture = rebase(texture, from_dir, to_dir);
        }
        spec.material = Some(Spanned::new(0..0, m));
    }
    file.stray_light = stray_light_spec(scene);
    // The render settings in force (including the Ward variant) are written explicitly.
    let r = &scene.render;
    file.render = Some(super::schema::RenderSpec {
        spp: Some(r.spp),
        max_depth: Some(r.max_depth),
        rr_depth: Some(r.rr_depth),
        seed: Some(r.seed),
        ward_variant: Some(r.ward_variant),
    });
    toml::to_string_pretty(&file).expect("scene serialises")
}

#[cfg(test)]
mod tests {
    use super::*;

    const SCENE: &str = r#"# my room
[camera]
width = 32
height = 24
eye = [0.0, 2.0, 2.0]   # where I stood
target = [0.0, 0.0, 0.0]
fov_y_deg = 45.0

[[object]]
name = "floor"
group = "floor"
shape = "quad"
corner = [-1.0, 0.0, 1.0]
edge_u = [2.0, 0.0, 0.0]
edge_v = [0.0, 0.0, -2.0]
material = { type = "diffuse", rho_d = 0.5 } # a guess

[[object]]
name = "lamp"
group = "lamp"
shape = "quad"
corner = [-0.2, 1.5, -0.2]
edge_u = [0.4, 0.0, 0.0]
edge_v = [0.0, 0.0, 0.4]
emission = 5.0
"#;

    /// Only the material line differs: comments, inline arrays and key order stay.
    #[test]
    fn the_source_is_edited_in_place() {
        let d = tempfile::tempdir().unwrap();
        let path = d.path().join("scene.toml");
        std::fs::write(&path, SCENE).unwrap();
        let mut scene = crate::scene::load_scene(&path).unwrap();
        scene.objects[0].material = Material::Ward {
            rho_d: crate::math::Rgb::new(0.25, 0.5, 0.125),
            rho_s: crate::math::Rgb::splat(0.25),
            alpha_x: 0.125,
            alpha_y: 0.125,
            theta: 0.0,
        };
        let out = scene_to_toml(&scene, &d.path().join("out").join("recovered.toml"));
        let changed: Vec<(&str, &str)> = SCENE
            .lines()
            .zip(out.lines())
            .filter(|(a, b)| a != b)
            .collect();
        assert_eq!(SCENE.lines().count(), out.lines().count(), "{out}");
        assert_eq!(changed.len(), 1, "{out}");
        assert_eq!(
            changed[0].1,
            "material = { type = \"ward\", rho_d = [0.25, 0.5, 0.125], rho_s = 0.25, alpha = 0.125 } # a guess"
        );
        // And it loads again, with the new material.
        let back = crate::scene::load::parse_scene(&out, &d.path().join("recovered.toml")).unwrap();
        assert!(matches!(back.objects[0].material, Material::Ward { .. }));
    }

    /// A file changed since it was loaded is not taken for the scene: written anew.
    #[test]
    fn a_changed_source_is_not_edited() {
        let d = tempfile::tempdir().unwrap();
        let path = d.path().join("scene.toml");
        std::fs::write(&path, SCENE).unwrap();
        let scene = crate::scene::load_scene(&path).unwrap();
        std::fs::write(&path, SCENE.replace("rho_d = 0.5", "rho_d = 0.7")).unwrap();
        let out = scene_to_toml(&scene, &d.path().join("recovered.toml"));
        assert!(!out.contains("# my room"), "{out}");
        assert!(crate::scene::load::parse_scene(&out, &path).is_ok());
    }
}
