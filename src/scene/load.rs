//! Scene loading: TOML → checked [`Scene`]. Every error names the scene file and the line, key or
//! object at fault; nothing here panics on bad input.

use super::camera_spec::build_camera;
use super::context::{line_of, with_suggestion, Ctx};
use super::error::SceneError;
use super::schema::{Color, MaterialSpec, ObjectSpec, SceneFile, ShapeKind};
use super::texture::Texture;
use super::{
    Geometry, Group, Material, Object, PunctualLight, RenderSettings, RhoBound, Scene, Tri,
};
use crate::geometry::{shapes, Bvh, TriangleMesh};
use crate::math::{Mat3, Rgb, Vec2, Vec3};
use glam::{Affine3A, EulerRot, Quat};
use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// Reads and checks a scene file. Relative paths inside it are relative to its folder.
pub fn load_scene(path: &Path) -> Result<Scene, SceneError> {
    let bytes = std::fs::read(path).map_err(|error| SceneError::Io {
        path: path.to_owned(),
        error,
    })?;
    if let Some(kind) = image_kind(&bytes) {
        return Err(SceneError::Scene {
            path: path.to_owned(),
            message: format!(
                "this is {kind} image, not a scene file (TOML text); the scene file comes \
                 first, the photo after it: `matfit recover SCENE.toml PHOTO -o OUT`"
            ),
        });
    }
    let text = String::from_utf8(bytes).map_err(|e| SceneError::Scene {
        path: path.to_owned(),
        message: format!(
            "not a scene file: a scene file is TOML text (UTF-8), and byte {} is not text",
            e.utf8_error().valid_up_to()
        ),
    })?;
    parse_scene(&text, path)
}

/// The image format whose signature `bytes` start with ("a PNG", …), if any: a photo given
/// where the scene belongs.
fn image_kind(bytes: &[u8]) -> Option<&'static str> {
    let signatures: [(&[u8], &str); 9] = [
        (b"\x89PNG", "a PNG"),
        (b"\xFF\xD8\xFF", "a JPEG"),
        (b"\x76\x2F\x31\x01", "an OpenEXR"),
        (b"#?RADIANCE", "a Radiance HDR"),
        (b"#?RGBE", "a Radiance HDR"),
        (b"PF\n", "a PFM"),
        (b"Pf\n", "a PFM"),
        (b"II*\0", "a TIFF"),
        (b"MM\0*", "a TIFF"),
    ];
    signatures
        .iter()
        .find(|(sig, _)| bytes.starts_with(sig))
        .map(|(_, kind)| *kind)
}

/// Parses scene text as if it were the file at `path`.
pub fn parse_scene(text: &str, path: &Path) -> Result<Scene, SceneError> {
    let file: SceneFile = toml::from_str(text).map_err(|e| SceneError::Toml {
        path: path.to_owned(),
        message: with_suggestion(&e.to_string()),
    })?;
    build_scene(file, text, path)
}

/// Checks and builds a parsed scene file; `text` and `path` are what errors point into.
pub(super) fn build_scene(file: SceneFile, text: &str, path: &Path) -> Result<Scene, SceneError> {
    let mut scene = build_objects(file, text, path)?;
    scene.views = super::view::build_views(&scene.source, &scene, text, path)?;
    let dir = path.parent().map(Path::to_path_buf).unwrap_or_default();
    check_camera_sees_geometry(&scene, &Ctx { path, text, dir })?;
    Ok(scene)
}

/// [`build_scene`] without the check that the camera sees something: for objects checked on
/// their own (an edit's added objects, which may well be out of view).
pub(super) fn build_objects(file: SceneFile, text: &str, path: &Path) -> Result<Scene, SceneError> {
    let dir = path.parent().map(Path::to_path_buf).unwrap_or_default();
    let cx = Ctx { path, text, dir };
    let camera = build_camera(&file, &cx)?;
    let render = build_render(&file, &cx)?;

    // Groups: declared ones first (with their options), then those objects name.
    let mut groups: Vec<Group> = Vec::new();
    let mut group_ix: HashMap<String, usize> = HashMap::new();
    for g in &file.groups {
        let name = g.name.get_ref();
        if name.trim().is_empty() {
            return Err(cx.at(g.name.span().start, "a group has an empty name".into()));
        }
        if group_ix.contains_key(name) {
            return Err(cx.at(
                g.name.span().start,
                format!("group '{name}' is declared twice"),
            ));
        }
        group_ix.insert(name.clone(), groups.len());
        groups.push(Group {
            name: name.clone(),
            objects: Vec::new(),
            fixed: g.fixed,
        });
    }
    if file.objects.is_empty() {
        return Err(cx.whole("the scene has no objects (add [[object]] tables)".into()));
    }

    let mut objects = Vec::new();
    let mut meshes = Vec::new();
    let mut seen: HashMap<&str, usize> = HashMap::new();
    for spec in &file.objects {
        let name = spec.name.get_ref();
        let off = spec.name.span().start;
        if name.trim().is_empty() {
            return Err(cx.at(off, "an object has an empty name".into()));
        }
        if let Some(prev) = seen.insert(name.as_str(), off) {
            return Err(cx.at(
                off,
                format!(
                    "object '{name}' is defined twice (first at line {})",
                    line_of(text, prev)
                ),
            ));
        }
        let Some(gname) = &spec.group else {
            return Err(cx.at(
                off,
                format!("object '{name}' is in no group: add `group = \"...\"`"),
            ));
        };
        let g = *group_ix.entry(gname.get_ref().clone()).or_insert_with(|| {
            groups.push(Group {
                name: gname.get_ref().clone(),
                objects: Vec::new(),
                fixed: false,
            });
            groups.len() - 1
        });
        let mut mesh = build_shape(spec, &cx)?;
        if let Some(t) = &spec.transform {
            mesh.transform(&transform_of(t));
        }
        // Problems of the mesh itself point at its `file` (or, for built-in shapes, `shape`) line.
        let shape_off = spec
            .file
            .as_ref()
            .map_or(spec.shape.span().start, |f| f.span().start);
        mesh.validate()
            .map_err(|p| cx.at(shape_off, format!("object '{name}': {p}")))?;
        let area = mesh.area();
        let emission = match &spec.emission {
            None => Rgb::ZERO,
            Some(e) => {
                let c = Rgb::from(e.get_ref().0);
                if !c.is_finite() || c.min_element() < 0.0 {
                    return Err(cx.at(
                        e.span().start,
                        format!(
                            "object '{name}': emission must be finite and non-negative, got {:?}",
                            e.get_ref().0
                        ),
                    ));
                }
                if c.max_element() > 0.0 && !(area > 0.0) {
                    return Err(cx.at(off, format!("light '{name}' has zero area")));
                }
                c
            }
        };
        let material = match &spec.material {
            Some(m) => build_material(m.get_ref(), &cx)
                .map_err(|msg| cx.at(m.span().start, format!("object '{name}': {msg}")))?,
            None if emission.max_element() > 0.0 => Material::Black,
            None => Material::Diffuse {
                rho_d: Rgb::splat(0.5),
            },
        };
        let tangent = match spec.tangent {
            Some(t) => {
                let t = Vec3::from(t);
                if !t.is_finite() || t.length_squared() == 0.0 {
                    return Err(cx.at(
                        off,
                        format!("object '{name}': tangent must be a non-zero finite vector"),
                    ));
                }
                Some(t.normalize())
            }
            None => None,
        };
        groups[g].objects.push(objects.len());
        objects.push(Object {
            name: name.clone(),
            group: g,
            material,
            emission,
            tangent,
            tri_range: 0..0,
            area,
            line: line_of(text, off),
        });
        meshes.push(mesh);
    }
    if let Some(g) = groups.iter().find(|g| g.objects.is_empty()) {
        return Err(cx.whole(format!(
            "group '{}' is declared but no object is in it",
            g.name
        )));
    }

    let mut punctual_lights: Vec<PunctualLight> = Vec::new();
    for spec in &file.lights {
        let name = spec.name.get_ref();
        let off = spec.name.span().start;
        if name.trim().is_empty() {
            return Err(cx.at(off, "a light has an empty name".into()));
        }
        if seen.contains_key(name.as_str()) || punctual_lights.iter().any(|l| &l.name == name) {
            return Err(cx.at(
                off,
                format!("'{name}' names two things (lights and objects share one set of names)"),
            ));
        }
        let kind = super::light::build(spec).map_err(|m| {
            let k = super::light::kind_name(*spec.kind.get_ref());
            cx.at(off, format!("{k} light '{name}': {m}"))
        })?;
        punctual_lights.push(PunctualLight {
            name: name.clone(),
            kind,
            line: line_of(text, off),
        });
    }

    let environment = match &file.environment {
        None => None,
        Some(e) => {
            let spec = e.get_ref();
            let path = cx.dir.join(&spec.file);
            let image = crate::io::image::read_linear(&path)
                .map_err(|m| cx.at(e.span().start, format!("[environment]: {m}")))?;
            let rot = transform_of(&super::schema::TransformSpec {
                rotate_deg: spec.rotate_deg,
                ..Default::default()
            });
            let env = super::environment::Environment::new(
                image,
                spec.scale.unwrap_or(1.0),
                Mat3::from(rot.matrix3),
            )
            .map_err(|m| {
                cx.at(
                    e.span().start,
                    format!("[environment] {}: {m}", path.display()),
                )
            })?;
            Some(Arc::new(env))
        }
    };

    let stray_light = match &file.stray_light {
        None => Rgb::ZERO,
        Some(s) => {
            let r = s.get_ref().radiance;
            if !r.iter().all(|v| v.is_finite() && *v >= 0.0) {
                return Err(cx.at(
                    s.span().start,
                    format!("[stray_light] radiance {r:?}: must be finite and not negative"),
                ));
            }
            Rgb::from_array(r)
        }
    };

    let geometry = build_geometry(&mut objects, meshes);
    map_atlas_textures(&mut objects, &groups, &geometry, &file, &cx)?;
    let scene = Scene {
        path: path.to_owned(),
        camera,
        render,
        groups,
        objects,
        punctual_lights,
        environment,
        stray_light,
        geometry: Arc::new(geometry),
        source: file,
        views: Vec::new(),
        view: None,
    };
    Ok(scene)
}

/// Gives every texture with `mapping = "atlas"` its group's atlas, which needs the geometry,
/// and checks that the image has the atlas's size (a texture written for another model, or
/// another texel size, would land on the wrong points).
fn map_atlas_textures(
    objects: &mut [Object],
    groups: &[Group],
    geometry: &Geometry,
    file: &SceneFile,
    cx: &Ctx,
) -> Result<(), SceneError> {
    use super::atlas::Atlas;
    use super::texture::Mapping;
    let mut built: HashMap<(usize, u32), Arc<Atlas>> = HashMap::new();
    for (i, spec) in file.objects.iter().enumerate() {
        let Some(m) = &spec.material else { continue };
        let MaterialSpec::Textured {
            mapping: Some(mapping),
            texel_size: Some(texel),
            ..
        } = m.get_ref()
        else {
            continue;
        };
        if mapping != "atlas" {
            continue;
        }
        let g = objects[i].group;
        let atlas = built
            .entry((g, texel.to_bits()))
            .or_insert_with(|| {
                Arc::new(Atlas::build(
                    geometry,
                    &groups[g].objects,
                    objects.len(),
                    *texel,
                ))
            })
            .clone();
        let (Material::Textured { texture, .. } | Material::TexturedPlastic { texture, .. }) =
            &mut objects[i].material
        else {
            continue;
        };
        if (texture.width, texture.height) != (atlas.width, atlas.height) || atlas.texel != *texel {
            return Err(cx.at(
                m.span().start,
                format!(
                    "object '{}': texture '{}' is {}×{} texels, but the atlas of group '{}' at \
                     texel_size {} is {}×{}: the texture was made for another model or texel size",
                    objects[i].name,
                    texture.path.display(),
                    texture.width,
                    texture.height,
                    groups[g].name,
                    texel,
                    atlas.width,
                    atlas.height
                ),
            ));
        }
        let mut t = (**texture).clone();
        t.mapping = Mapping::Atlas(atlas);
        *texture = Arc::new(t);
    }
    Ok(())
}

fn build_render(file: &SceneFile, cx: &Ctx) -> Result<RenderSettings, SceneError> {
    let mut r = RenderSettings::default();
    if let Some(spec) = &file.render {
        if let Some(spp) = spec.spp {
            if spp == 0 {
                return Err(cx.whole("[render] spp must be at least 1".into()));
            }
            r.spp = spp;
        }
        if let Some(d) = spec.max_depth {
            r.max_depth = d;
        }
        if let Some(d) = spec.rr_depth {
            r.rr_depth = d;
        }
        if let Some(s) = spec.seed {
            r.seed = s;
        }
        if let Some(v) = spec.ward_variant {
            r.ward_variant = v;
        }
    }
    Ok(r)
}

fn build_shape(spec: &ObjectSpec, cx: &Ctx) -> Result<TriangleMesh, SceneError> {
    let name = spec.name.get_ref();
    let off = spec.shape.span().start;
    let need = |v: Option<[f32; 3]>, key: &str| -> Result<Vec3, SceneError> {
        let v = v.ok_or_else(|| {
            cx.at(
                off,
                format!(
                    "object '{name}': shape '{:?}' needs `{key}`",
                    spec.shape.get_ref()
                )
                .to_lowercase(),
            )
        })?;
        if !v.iter().all(|x| x.is_finite()) {
            return Err(cx.at(
                off,
                format!("object '{name}': `{key}` has a NaN or infinite value"),
            ));
        }
        Ok(Vec3::from(v))
    };
    Ok(match spec.shape.get_ref() {
        ShapeKind::Quad => {
            let (c, u, v) = (
                need(spec.corner, "corner")?,
                need(spec.edge_u, "edge_u")?,
                need(spec.edge_v, "edge_v")?,
            );
            shapes::quad(c, u, v)
        }
        ShapeKind::Box => {
            let (lo, hi) = (need(spec.min, "min")?, need(spec.max, "max")?);
            if !(hi.cmpgt(lo).all()) {
                return Err(cx.at(
                    off,
                    format!("object '{name}': box `max` must exceed `min` on every axis"),
                ));
            }
            shapes::cuboid(lo, hi)
        }
        ShapeKind::Sphere => {
            let c = need(spec.center, "center")?;
            let r = spec.radius.ok_or_else(|| {
                cx.at(
                    off,
                    format!("object '{name}': shape 'sphere' needs `radius`"),
                )
            })?;
            if !(r > 0.0 && r.is_finite()) {
                return Err(cx.at(
                    off,
                    format!("object '{name}': sphere radius must be positive, got {r}"),
                ));
            }
            let segments = spec.segments.unwrap_or(64);
            if !(8..=1024).contains(&segments) {
                return Err(cx.at(
                    off,
                    format!(
                        "object '{name}': sphere `segments` must be between 8 and 1024, got {segments}"
                    ),
                ));
            }
            shapes::sphere(c, r, segments)
        }
        ShapeKind::Mesh => {
            let file = spec
                .file
                .as_ref()
                .ok_or_else(|| cx.at(off, format!("object '{name}': shape 'mesh' needs `file`")))?;
            let p = cx.dir.join(file.get_ref());
            super::meshio::load_mesh(&p)
                .map_err(|msg| cx.at(file.span().start, format!("object '{name}': {msg}")))?
        }
    })
}

fn transform_of(t: &super::schema::TransformSpec) -> Affine3A {
    let s = t.scale.map(|c| Vec3::from(c.0)).unwrap_or(Vec3::ONE);
    let r = t
        .rotate_deg
        .map(|[x, y, z]| {
            Quat::from_euler(
                EulerRot::ZYX,
                z.to_radians(),
                y.to_radians(),
                x.to_radians(),
            )
        })
        .unwrap_or(Quat::IDENTITY);
    let tr = t.translate.map(Vec3::from).unwrap_or(Vec3::ZERO);
    Affine3A::from_scale_rotation_translation(s, r, tr)
}

fn color(c: &Color, key: &str) -> Result<Rgb, String> {
    let v = Rgb::from(c.0);
    if !v.is_finite() || v.min_element() < 0.0 {
        return Err(format!(
            "`{key}` must be finite and non-negative, got {:?}",
            c.0
        ));
    }
    Ok(v)
}

/// Checks that a surface reflects at most the light it receives: its model's bound on ρd and ρs
/// per channel ([`Material::rho_bound`]), with a little slack for decimal values such as
/// 0.1 + 0.9 in f32. A texture's texels are not checked, only a uniform ρd.
fn energy(m: &Material) -> Result<(), String> {
    let rho_d = match m {
        Material::Textured { .. } | Material::TexturedPlastic { .. } => Rgb::ZERO,
        _ => m.rho_d(),
    };
    let (rho_s, bound) = (m.rho_s(), m.rho_bound());
    let reach = |c: usize| bound.reach(rho_d[c] as f64, rho_s[c] as f64);
    if let Some(c) = (0..3).find(|&c| reach(c) > 1.0 + 1e-6) {
        let what = match (bound, rho_d == Rgb::ZERO, rho_s == Rgb::ZERO) {
            (_, _, true) => "`rho_d`",
            (_, true, _) => "`rho_s`",
            (RhoBound::Sum, ..) => "`rho_d` + `rho_s`",
            (RhoBound::Each, ..) => "each of `rho_d` and `rho_s` (under the coat)",
        };
        return Err(format!(
            "{what} must be at most 1 in every channel, got {} in the {} channel: the surface \
             would reflect more light than it receives",
            reach(c) as f32,
            ["red", "green", "blue"][c]
        ));
    }
    Ok(())
}

/// A Ward lobe's (αx, αy, θ in radians) from a material table's keys: `alpha` (isotropic) or
/// `alpha_x` and `alpha_y`, with an optional `theta_deg`.
fn lobe(
    alpha: Option<f32>,
    alpha_x: Option<f32>,
    alpha_y: Option<f32>,
    theta_deg: Option<f32>,
    what: &str,
) -> Result<(f32, f32, f32), String> {
    let alpha_ok = |a: f32, key: &str| {
        if a > 0.0 && a.is_finite() {
            Ok(a)
        } else {
            Err(format!("`{key}` must be positive, got {a}"))
        }
    };
    let (ax, ay) = match (alpha, alpha_x, alpha_y) {
        (Some(a), None, None) => (alpha_ok(a, "alpha")?, alpha_ok(a, "alpha")?),
        (None, Some(x), Some(y)) => (alpha_ok(x, "alpha_x")?, alpha_ok(y, "alpha_y")?),
        _ => {
            return Err(format!(
                "{what} takes either `alpha` (isotropic) or both `alpha_x` and `alpha_y`"
            ))
        }
    };
    let theta = theta_deg.unwrap_or(0.0);
    if !theta.is_finite() {
        return Err("`theta_deg` must be finite".into());
    }
    Ok((ax, ay, theta.to_radians()))
}

/// Turns a material table into a material; the message says what is wrong.
fn build_material(m: &MaterialSpec, cx_dir: &Ctx) -> Result<Material, String> {
    build_material_in(m, &cx_dir.dir)
}

/// Same, resolving texture paths against `dir`.
pub fn build_material_in(m: &MaterialSpec, dir: &Path) -> Result<Material, String> {
    let m = build_unchecked(m, dir)?;
    energy(&m)?;
    Ok(m)
}

/// [`build_material_in`] but for the bound on the reflectances.
fn build_unchecked(m: &MaterialSpec, dir: &Path) -> Result<Material, String> {
    Ok(match m {
        MaterialSpec::Diffuse { rho_d } => {
            let rho_d = color(rho_d, "rho_d")?;
            Material::Diffuse { rho_d }
        }
        MaterialSpec::Mirror { rho_s } => {
            let rho_s = color(rho_s, "rho_s")?;
            Material::Mirror { rho_s }
        }
        MaterialSpec::DiffuseMirror { rho_d, rho_s } => {
            let (rho_d, rho_s) = (color(rho_d, "rho_d")?, color(rho_s, "rho_s")?);
            Material::DiffuseMirror { rho_d, rho_s }
        }
        MaterialSpec::Ward {
            rho_d,
            rho_s,
            alpha,
            alpha_x,
            alpha_y,
            theta_deg,
        } => {
            let (ax, ay, theta) = lobe(*alpha, *alpha_x, *alpha_y, *theta_deg, "a ward material")?;
            let (rho_d, rho_s) = (color(rho_d, "rho_d")?, color(rho_s, "rho_s")?);
            Material::Ward {
                rho_d,
                rho_s,
                alpha_x: ax,
                alpha_y: ay,
                theta,
            }
        }
        MaterialSpec::Microfacet {
            rho_d,
            rho_s,
            alpha,
            alpha_x,
            alpha_y,
            theta_deg,
            distribution,
        } => {
            let (ax, ay, theta) = lobe(
                *alpha,
                *alpha_x,
                *alpha_y,
                *theta_deg,
                "a microfacet material",
            )?;
            let (rho_d, rho_s) = (color(rho_d, "rho_d")?, color(rho_s, "rho_s")?);
            Material::Microfacet {
                rho_d,
                rho_s,
                alpha_x: ax,
                alpha_y: ay,
                theta,
                distribution: *distribution,
            }
        }
        MaterialSpec::Plastic {
            rho_d,
            rho_s,
            alpha,
            eta,
            distribution,
        } => {
            let (alpha, _, _) = lobe(Some(*alpha), None, None, None, "a plastic material")?;
            let eta = eta.unwrap_or(super::material::DEFAULT_ETA);
            if !(eta.is_finite() && eta > 1.0) {
                return Err(format!("`eta` must be a number > 1, got {eta}"));
            }
            let (rho_d, rho_s) = (color(rho_d, "rho_d")?, color(rho_s, "rho_s")?);
            Material::Plastic {
                rho_d,
                rho_s,
                alpha,
                eta,
                distribution: *distribution,
            }
        }
        MaterialSpec::Textured {
            texture,
            scale,
            mapping,
            texel_size,
            rho_s,
            alpha,
            alpha_x,
            alpha_y,
            theta_deg,
            eta,
            distribution,
        } => {
            // A coat instead of a varnish: the plastic's keys, checked as there.
            let coat = match (eta, rho_s) {
                (Some(eta), Some(rho_s)) => {
                    if alpha_x.is_some() || alpha_y.is_some() || theta_deg.is_some() {
                        return Err(
                            "a textured material's coat (`eta`) is isotropic: `alpha` only".into(),
                        );
                    }
                    let Some(a) = alpha else {
                        return Err("a textured material's coat (`eta`) needs `alpha`".into());
                    };
                    let (a, _, _) = lobe(Some(*a), None, None, None, "a coat")?;
                    if !(eta.is_finite() && *eta > 1.0) {
                        return Err(format!("`eta` must be a number > 1, got {eta}"));
                    }
                    let rho_s = color(rho_s, "rho_s")?;
                    Some((rho_s, a, *eta, distribution.unwrap_or_default()))
                }
                (Some(_), None) => {
                    return Err("a textured material's `eta` goes with `rho_s` (the coat's)".into())
                }
                (None, _) if distribution.is_some() => {
                    return Err("a textured material's `distribution` goes with `eta`".into())
                }
                (None, _) => None,
            };
            let varnish = match rho_s {
                _ if coat.is_some() => None,
                Some(rho_s) => {
                    let (alpha_x, alpha_y, theta) =
                        lobe(*alpha, *alpha_x, *alpha_y, *theta_deg, "a varnish")?;
                    let rho_s = color(rho_s, "rho_s")?;
                    Some(crate::scene::Varnish {
                        rho_s,
                        alpha_x,
                        alpha_y,
                        theta,
                    })
                }
                None if alpha.is_some() || alpha_x.is_some() || alpha_y.is_some() => {
                    return Err(
                        "a textured material's `alpha` goes with `rho_s` (the varnish's lobe)"
                            .into(),
                    )
                }
                None => None,
            };
            match (mapping.as_deref(), texel_size) {
                (None | Some("uv"), None) => {}
                (Some("atlas"), Some(t)) if t.is_finite() && *t > 0.0 => {}
                (Some("atlas"), Some(t)) => {
                    return Err(format!("`texel_size` must be positive, got {t}"))
                }
                (Some("atlas"), None) => {
                    return Err(
                        "`mapping = \"atlas\"` needs `texel_size` (world units per texel)".into(),
                    )
                }
                (None | Some("uv"), Some(_)) => {
                    return Err("`texel_size` goes with `mapping = \"atlas\"` only".into())
                }
                (Some(m), _) => {
                    return Err(format!(
                        "`mapping` must be \"uv\" or \"atlas\", got \"{m}\""
                    ))
                }
            }
            let p = dir.join(texture);
            let img = crate::io::image::read_linear(&p).map_err(|e| format!("texture: {e}"))?;
            let texture = Arc::new(Texture {
                width: img.width,
                height: img.height,
                texels: img.data,
                path: PathBuf::from(texture),
                mapping: super::texture::Mapping::Uv,
            });
            let scale = match scale {
                Some(s) => color(s, "scale")?,
                None => Rgb::ONE,
            };
            if let Some((rho_s, alpha, eta, distribution)) = coat {
                return Ok(Material::TexturedPlastic {
                    texture,
                    scale,
                    rho_s,
                    alpha,
                    eta,
                    distribution,
                });
            }
            Material::Textured {
                texture,
                scale,
                varnish,
            }
        }
        MaterialSpec::Black => Material::Black,
    })
}

fn build_geometry(objects: &mut [Object], meshes: Vec<TriangleMesh>) -> Geometry {
    let mut g = Geometry {
        positions: Vec::new(),
        normals: Vec::new(),
        uvs: Vec::new(),
        tris: Vec::new(),
        faces: Vec::new(),
        bvh: Bvh::build(&[]),
    };
    for (oi, (obj, mut m)) in objects.iter_mut().zip(meshes).enumerate() {
        let base = g.positions.len() as u32;
        let first = g.tris.len() as u32;
        if m.normals.is_none() {
            // Flat shading: one vertex per triangle corner so each carries its face normal.
            let mut flat = TriangleMesh::default();
            let mut uvs = Vec::new();
            for (i, tri) in m.indices.iter().enumerate() {
                let [a, b, c] = m.triangle(i);
                let n = (b - a).cross(c - a).normalize();
                let k = flat.positions.len() as u32;
                flat.positions.extend([a, b, c]);
                flat.indices.push([k, k + 1, k + 2]);
                flat.normals.get_or_insert_with(Vec::new).extend([n, n, n]);
                if let Some(uv) = &m.uvs {
                    uvs.extend(tri.map(|j| uv[j as usize]));
                }
            }
            flat.uvs = m.uvs.is_some().then_some(uvs);
            m = flat;
        }
        g.positions.extend_from_slice(&m.positions);
        g.normals.extend_from_slice(m.normals.as_ref().unwrap());
        match &m.uvs {
            Some(uv) => g.uvs.extend_from_slice(uv),
            None => g
                .uvs
                .extend(std::iter::repeat_n(Vec2::ZERO, m.positions.len())),
        }
        g.tris.extend(m.indices.iter().map(|t| Tri {
            v: [t[0] + base, t[1] + base, t[2] + base],
            object: oi as u32,
        }));
        obj.tri_range = first..g.tris.len() as u32;
    }
    let tri_pos: Vec<[Vec3; 3]> = g
        .tris
        .iter()
        .map(|t| t.v.map(|i| g.positions[i as usize]))
        .collect();
    g.bvh = Bvh::build(&tri_pos);
    let tangents: Vec<Option<Vec3>> = objects.iter().map(|o| o.tangent).collect();
    g.compute_faces(&tangents);
    g
}

fn check_camera_sees_geometry(scene: &Scene, cx: &Ctx) -> Result<(), SceneError> {
    let cam = &scene.camera;
    // A coarse grid first; if it misses, a fine one (up to a ray per pixel), so that a small
    // object alone in the view is not taken for nothing.
    let sees = |nx: u32, ny: u32| {
        (0..ny).any(|j| {
            (0..nx).any(|i| {
                let film = Vec2::new(
                    (i as f32 + 0.5) / nx as f32 * cam.width as f32,
                    (j as f32 + 0.5) / ny as f32 * cam.height as f32,
                );
                scene.intersect(&cam.ray(film), f32::INFINITY).is_some()
            })
        })
    };
    if sees(24, 24) || sees(cam.width.min(256), cam.height.min(256)) {
        return Ok(());
    }
    let v = |v: Vec3| format!("[{:.3}, {:.3}, {:.3}]", v.x, v.y, v.z);
    let b = scene.geometry.bvh.bounds();
    Err(cx.whole(format!(
        "the camera at {} sees no geometry (scene bounds {} to {}): check [camera] (eye, target \
         or rotation) and the objects' positions",
        v(cam.eye()),
        v(b.min),
        v(b.max)
    )))
}

/// The geometry of bare meshes, one object each (group 0, black), for tests of what reads it.
#[cfg(test)]
pub(crate) fn build_geometry_for_tests(meshes: Vec<TriangleMesh>) -> Geometry {
    let mut objects: Vec<Object> = (0..meshes.len())
        .map(|i| Object {
            name: format!("o{i}"),
            group: 0,
            material: Material::Black,
            emission: Rgb::ZERO,
            tangent: None,
            tri_range: 0..0,
            area: 0.0,
            line: 0,
        })
        .collect();
    build_geometry(&mut objects, meshes)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A small object alone in the view falls between the coarse grid's rays: the scene loads.
    #[test]
    fn a_small_object_alone_in_view_is_seen() {
        let text = r#"
[camera]
width = 512
height = 384
eye = [0.0, 0.0, 10.0]
target = [0.0, 0.0, 0.0]
fov_y_deg = 45.0

[[object]]
name = "chip"
group = "chip"
shape = "quad"
corner = [-0.025, -0.025, 0.0]
edge_u = [0.05, 0.0, 0.0]
edge_v = [0.0, 0.05, 0.0]
"#;
        parse_scene(text, Path::new("chip.toml")).unwrap();
        let away = text.replace("target = [0.0, 0.0, 0.0]", "target = [0.0, 0.0, 20.0]");
        let e = parse_scene(&away, Path::new("chip.toml")).err().unwrap();
        assert!(e.to_string().contains("sees no geometry"), "{e}");
    }

    /// A plastic's base is bounded alone under its coat: ρd 0.9 under ρs 0.3 loads as given,
    /// where the same reflectances on a microfacet material (sharing the light) are refused.
    #[test]
    fn a_plastic_may_reflect_more_than_one_less_its_coat() {
        let text = |material: &str| {
            format!(
                r#"
[camera]
width = 64
height = 48
eye = [0.0, 0.0, 10.0]
target = [0.0, 0.0, 0.0]
fov_y_deg = 45.0

[[object]]
name = "tile"
group = "tile"
shape = "quad"
corner = [-1.0, -1.0, 0.0]
edge_u = [2.0, 0.0, 0.0]
edge_v = [0.0, 2.0, 0.0]
material = {{ type = "{material}", rho_d = 0.9, rho_s = 0.3, alpha = 0.1 }}
"#
            )
        };
        let sc = parse_scene(&text("plastic"), Path::new("tile.toml")).unwrap();
        assert_eq!(sc.objects[0].material.rho_d(), Rgb::splat(0.9));
        let e = parse_scene(&text("microfacet"), Path::new("tile.toml")).err().unwrap();
        assert!(e.to_string().contains("`rho_d` + `rho_s` must be at most 1"), "{e}");
        let over = text("plastic").replace("rho_d = 0.9", "rho_d = 1.1");
        let e = parse_scene(&over, Path::new("tile.toml")).err().unwrap();
        assert!(e.to_string().contains("each of `rho_d` and `rho_s`"), "{e}");
    }

    #[test]
    fn suggestion_picks_nearest_key() {
        let m = with_suggestion(
            "unknown field `fovy_deg`, expected one of `width`, `fov_y_deg`, `eye`",
        );
        assert!(m.contains("did you mean `fov_y_deg`?"), "{m}");
        let m = with_suggestion("unknown variant `quadd`, expected one of `quad`, `box`");
        assert!(m.contains("did you mean `quad`?"), "{m}");
    }
}
