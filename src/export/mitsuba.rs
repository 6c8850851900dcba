//! Export to Mitsuba 3: `DIR/scene.xml` (scene format version 3.0.0) and one binary
//! little-endian PLY per object in `DIR/meshes/`.
//!
//! The PLYs hold the triangles *exactly as matfit loaded them*: world-space positions (every
//! transform applied), the shading normals and UVs of `Scene::geometry`, and matfit's vertex
//! order, so that Mitsuba intersects the same triangles and sees the same front sides (a
//! one-sided area light emits along the wound normal in both renderers). The XML carries no
//! transforms.
//!
//! How each part maps (and where it cannot be exact — those cases are warnings):
//! - **Camera.** `perspective` with `fov_axis = "y"` (matfit's field of view is vertical; Mitsuba's
//!   default axis is x), `to_world` a `lookat` from the eye along the third row of R (forward), with
//!   up = −(second row of R) since matfit's camera y points down. An off-centre principal point
//!   (calibrated cameras) becomes `principal_point_offset_x/y`, which Mitsuba measures as a
//!   fraction of the film size with the opposite sign of the shift on the film:
//!   offset_x = ½ − cx/width, offset_y = ½ − cy/height (cx, cy in matfit's continuous film
//!   coordinates; checked with Mitsuba 3.9.1's `sample_ray`). Mitsuba has square pixels only:
//!   fx ≠ fy is a warning and fy wins. Near/far clipping planes are set from the scene's bounds so
//!   that they cut nothing. An orthographic camera becomes an `orthographic` sensor whose
//!   `to_world` scales the film's local square to its extent ([`write_orthographic_sensor`]).
//! - **Film.** `hdrfilm`, the same width and height, `rfilter = box` (matfit's pixel filter),
//!   `pixel_format = rgb`. **Sampler** `independent` with the scene's spp.
//! - **Integrator.** `path` with `max_depth` and `rr_depth` = the scene's (same meanings:
//!   segments of a path; the same roulette) and `hide_emitters = false`.
//! - **BSDFs**, each wrapped in `twosided` (matfit's surfaces reflect on both sides):
//!   diffuse → `diffuse`; mirror → `conductor` with `material = "none"` (a 100% mirror) and
//!   `specular_reflectance` = ρs; diffuse + mirror → `blendbsdf` of weight w of
//!   `diffuse`(ρd/(1−w)) and `conductor`(ρs/w), which is exactly ρd·Lambert + ρs·mirror when both
//!   stay ≤ 1, i.e. when max ρd + max ρs ≤ 1 (w = max ρs / (max ρd + max ρs)); otherwise a warning
//!   and the blend is clamped. A texture → `diffuse` with a `bitmap` reflectance: the texels ×
//!   the material's scale in `textures/*.exr` (linear, `raw`, bilinear like matfit's lookup;
//!   `repeat` over mesh UVs, `clamp` over an atlas), and the object's PLY carries the texture's
//!   coordinates in Mitsuba's convention (v from the image's top row; matfit's runs up; an
//!   atlas's chart positions for recovered textures). A varnish is the Ward blend below with
//!   the bitmap as its diffuse part. Black → `diffuse` 0 (Mitsuba would otherwise give a shape
//!   its default 50% grey).
//! - **Ward** has no Mitsuba form; it becomes the same blend with the mirror replaced by a
//!   `roughconductor` (`material = "none"`) *fitted* to the Ward lobe over the directions this
//!   scene uses ([`super::standin`]): Beckmann or GGX, α (or αu, αv), and a weight k on ρs.
//!   What the fit leaves is stated per group, in a warning and in the file's header. Mitsuba
//!   orients αu along the mesh's dp/du: an anisotropic Ward object's PLY gets, per triangle, UVs
//!   u = s·p, v = t·p in matfit's shading frame (the object's tangent, else dp/du, rotated by
//!   θ), so that dp/du = s.
//! - **Emitters.** `area` with rgb `radiance` = the object's emission, one-sided like matfit's.

use super::standin::StandIn;
use super::ExportReport;
use crate::math::{Rgb, Vec2, Vec3};
use crate::render::bsdf::WardLobe;
use crate::scene::texture::{Mapping, Texture};
use crate::scene::{Distribution, Material, Punctual, PunctualLight, Scene, Varnish};
use std::fmt::Write as _;
use std::path::Path;
use std::sync::Arc;

/// Writes `dir/scene.xml` and `dir/meshes/*.ply` for `scene`. `dir` is created if needed.
pub fn export(scene: &Scene, dir: &Path) -> Result<ExportReport, String> {
    let mut report = ExportReport::default();
    let meshes = dir.join("meshes");
    std::fs::create_dir_all(&meshes)
        .map_err(|e| format!("cannot create {}: {e}", meshes.display()))?;

    let mut xml = String::new();
    xml.push_str("<scene version=\"3.0.0\">\n");
    write_integrator(&mut xml, scene);
    write_sensor(&mut xml, scene, &mut report.warnings);

    // A group's BSDF, when all its objects have the same one (textures differ: their means), is
    // defined once with the group's name as id and referenced by its shapes, so that `matfit
    // import mitsuba` (which groups shapes by BSDF id) gives every object back its group. A
    // shape named like its group goes without an id (Mitsuba's ids are one namespace); the
    // importer names such a shape after its BSDF.
    // Each object's BSDF and its warnings, computed once.
    let mut bsdfs: Vec<(String, Vec<String>)> = vec![Default::default(); scene.objects.len()];
    let mut shared: Vec<Option<String>> = vec![None; scene.groups.len()];
    let mut textures = TextureFiles::default();
    let mut fits = StandIns::default();
    for (g, group) in scene.groups.iter().enumerate() {
        let objs: Vec<usize> = (0..scene.objects.len())
            .filter(|&oi| scene.objects[oi].group == g)
            .collect();
        for &oi in &objs {
            let mut warnings = Vec::new();
            let bsdf = object_bsdf(scene, oi, &objs, &mut fits, &mut textures, &mut warnings);
            bsdfs[oi] = (bsdf, warnings);
        }
        let id = mitsuba_id(&group.name, 'g');
        let taken = scene
            .objects
            .iter()
            .any(|o| o.group != g && mitsuba_id(&o.name, 'o') == id);
        if objs.is_empty() || taken || objs.iter().any(|&oi| bsdfs[oi].0 != bsdfs[objs[0]].0) {
            continue;
        }
        let (bsdf, warnings) = &bsdfs[objs[0]];
        report.warnings.extend(warnings.iter().cloned());
        let _ = writeln!(
            xml,
            "\n    <!-- group '{}' -->\n    <bsdf type=\"twosided\" id=\"{}\">\n{}    </bsdf>",
            escape_comment(&group.name),
            escape(&id),
            indent(bsdf, 8)
        );
        shared[g] = Some(id);
    }

    let mut ply_files = Vec::new();
    for (oi, obj) in scene.objects.iter().enumerate() {
        let file = format!("meshes/{oi:03}_{}.ply", file_stem(&obj.name));
        let bytes = match &obj.material {
            Material::Ward {
                alpha_x,
                alpha_y,
                theta,
                ..
            }
            | Material::Microfacet {
                alpha_x,
                alpha_y,
                theta,
                ..
            } if alpha_x != alpha_y => object_ply_with(scene, oi, Some(*theta)),
            Material::Textured { .. } | Material::TexturedPlastic { .. } => {
                textured_ply(scene, oi)
            }
            _ => object_ply(scene, oi),
        };
        let path = dir.join(&file);
        crate::io::atomic::write_atomic(&path, &bytes)
            .map_err(|e| format!("cannot write {}: {e}", path.display()))?;
        ply_files.push(path);

        let group = &scene.groups[obj.group].name;
        let _ = writeln!(
            xml,
            "\n    <!-- object '{}', group '{}' -->",
            escape_comment(&obj.name),
            escape_comment(group)
        );
        let id = mitsuba_id(&obj.name, 'o');
        if shared[obj.group].as_ref() == Some(&id) {
            xml.push_str("    <shape type=\"ply\">\n");
        } else {
            let _ = writeln!(xml, "    <shape type=\"ply\" id=\"{}\">", escape(&id));
        }
        let _ = writeln!(xml, "        <string name=\"filename\" value=\"{file}\"/>");
        match &shared[obj.group] {
            Some(gid) => {
                let _ = writeln!(xml, "        <ref id=\"{}\"/>", escape(gid));
            }
            None => {
                let (bsdf, warnings) = &bsdfs[oi];
                report.warnings.extend(warnings.iter().cloned());
                let _ = writeln!(
                    xml,
                    "        <bsdf type=\"twosided\">\n{}        </bsdf>",
                    indent(bsdf, 12)
                );
            }
        }
        if obj.is_emitter() {
            let _ = writeln!(
                xml,
                "        <emitter type=\"area\">\n            {}\n        </emitter>",
                rgb("radiance", obj.emission)
            );
        }
        xml.push_str("    </shape>\n");
    }
    for l in &scene.punctual_lights {
        write_punctual(&mut xml, l, &mut report.warnings);
    }
    if scene.stray_light.max_element() > 0.0 {
        // Mitsuba's constant emitter is sampled too; the radiance it adds is the same.
        let _ = writeln!(
            xml,
            "\n    <emitter type=\"constant\">\n        {}\n    </emitter>",
            rgb("radiance", scene.stray_light)
        );
    }
    if let Some(e) = &scene.environment {
        // The map as matfit read it (linear EXR), so that Mitsuba reads the same radiance.
        let path = dir.join("environment.exr");
        e.image().write(&path)?;
        report.files.push(path);
        let r = e.to_world();
        let m = |i: usize, j: usize| r.col(j)[i];
        let _ = writeln!(
            xml,
            "\n    <emitter type=\"envmap\">\n        <string name=\"filename\" value=\"environment.exr\"/>\n        \
             <float name=\"scale\" value=\"{}\"/>\n        <transform name=\"to_world\">\n            \
             <matrix value=\"{} {} {} 0 {} {} {} 0 {} {} {} 0 0 0 0 1\"/>\n        </transform>\n    </emitter>",
            e.scale,
            m(0, 0), m(0, 1), m(0, 2),
            m(1, 0), m(1, 1), m(1, 2),
            m(2, 0), m(2, 1), m(2, 2)
        );
    }
    xml.push_str("</scene>\n");
    let xml = header(scene, &report.warnings) + &xml;
    let texture_files = textures.write(dir)?;

    let xml_path = dir.join("scene.xml");
    crate::io::atomic::write_atomic(&xml_path, xml.as_bytes())
        .map_err(|e| format!("cannot write {}: {e}", xml_path.display()))?;
    report.files.push(xml_path);
    report.files.extend(ply_files);
    report.files.extend(texture_files);
    Ok(report)
}

/// A `[[light]]` as the Mitsuba 3 emitter of the same meaning (`scene::light`).
fn write_punctual(xml: &mut String, l: &PunctualLight, warnings: &mut Vec<String>) {
    let id = escape(&mitsuba_id(&l.name, 'l'));
    let _ = writeln!(xml, "\n    <!-- light '{}' -->", escape_comment(&l.name));
    match l.kind {
        Punctual::Directional {
            direction,
            irradiance,
            angle,
        } => {
            if angle > 0.0 {
                warnings.push(format!(
                    "light '{}': Mitsuba's directional light is parallel; its {:.3}° angular \
                     size is dropped (the same irradiance, sharp shadows)",
                    l.name,
                    angle.to_degrees()
                ));
            }
            let _ = writeln!(
                xml,
                "    <emitter type=\"directional\" id=\"{id}\">\n        <vector name=\"direction\" \
                 value=\"{}\"/>\n        {}\n    </emitter>",
                triple(direction),
                rgb("irradiance", irradiance)
            );
        }
        Punctual::Point {
            position,
            intensity,
        } => {
            let _ = writeln!(
                xml,
                "    <emitter type=\"point\" id=\"{id}\">\n        <point name=\"position\" \
                 value=\"{}\"/>\n        {}\n    </emitter>",
                triple(position),
                rgb("intensity", intensity)
            );
        }
        Punctual::Spot {
            position,
            direction,
            intensity,
            cutoff,
            beam_width,
        } => {
            // The falloff is symmetric about the axis, so any `up` off the axis will do.
            let up = if direction.y.abs() < 0.9 {
                Vec3::Y
            } else {
                Vec3::X
            };
            let _ = writeln!(
                xml,
                "    <emitter type=\"spot\" id=\"{id}\">\n        <transform name=\"to_world\">\n            \
                 <lookat origin=\"{}\" target=\"{}\" up=\"{}\"/>\n        </transform>\n        {}\n        \
                 <float name=\"cutoff_angle\" value=\"{}\"/>\n        <float name=\"beam_width\" \
                 value=\"{}\"/>\n    </emitter>",
                triple(position),
                triple(position + direction),
                triple(up),
                rgb("intensity", intensity),
                cutoff.to_degrees(),
                beam_width.to_degrees()
            );
        }
    }
}

/// Mitsuba reserves ids that start with an underscore: such a name gets `prefix` in front.
fn mitsuba_id(name: &str, prefix: char) -> String {
    if name.starts_with('_') {
        format!("{prefix}{name}")
    } else {
        name.to_string()
    }
}

/// The XML declaration and the comment that says what wrote the file and lists every
/// approximation (`warnings`), or that there is none.
fn header(scene: &Scene, warnings: &[String]) -> String {
    let mut h = format!(
        "<?xml version=\"1.0\" encoding=\"utf-8\"?>\n<!-- Exported by matfit {} from {}. Geometry \
         in world space (meshes/*.ply).\n",
        env!("CARGO_PKG_VERSION"),
        scene.path.display().to_string().replace("--", "- -")
    );
    if warnings.is_empty() {
        h.push_str("     Approximations: none. -->\n");
    } else {
        h.push_str("     Approximations:\n");
        for w in warnings {
            // A comment holds any text but "--".
            let w = w.replace(['\n', '\r'], " ").replace("--", "- -");
            let _ = writeln!(h, "     - {w}");
        }
        h.push_str("-->\n");
    }
    h
}

/// The stand-ins fitted so far, by group and lobe: a group's objects usually share one.
#[derive(Default)]
struct StandIns(Vec<(LobeKey, Option<StandIn>)>);

/// A group and the bits of its lobe's αx, αy and θ.
type LobeKey = (usize, [u32; 3]);

/// Object `oi`'s BSDF element (without `twosided`); a Ward lobe's stand-in (a Ward material's
/// or a texture's varnish) is fitted over the camera's view of all of `group` (its group's
/// objects), so that the group shares one BSDF.
fn object_bsdf(
    scene: &Scene,
    oi: usize,
    group: &[usize],
    fits: &mut StandIns,
    textures: &mut TextureFiles,
    warnings: &mut Vec<String>,
) -> String {
    let obj = &scene.objects[oi];
    let lobe = match &obj.material {
        Material::Ward {
            alpha_x,
            alpha_y,
            theta,
            ..
        }
        | Material::Textured {
            varnish:
                Some(Varnish {
                    alpha_x,
                    alpha_y,
                    theta,
                    ..
                }),
            ..
        } => Some((*alpha_x, *alpha_y, *theta)),
        _ => None,
    };
    bsdf_xml(
        &obj.material,
        &obj.name,
        || {
            let (alpha_x, alpha_y, theta) = lobe?;
            let key = (obj.group, [alpha_x, alpha_y, theta].map(f32::to_bits));
            if let Some((_, s)) = fits.0.iter().find(|(k, _)| *k == key) {
                return *s;
            }
            let variant = scene.render.ward_variant;
            let ward = WardLobe {
                alpha_x,
                alpha_y,
                variant,
            };
            let s = super::standin::fit_ward(scene, group, ward, theta);
            fits.0.push((key, s));
            s
        },
        textures,
        warnings,
    )
}

/// The texture files an export writes: one EXR per texture and factor, under `textures/`.
#[derive(Default)]
struct TextureFiles {
    files: Vec<TextureFile>,
}

struct TextureFile {
    name: String,
    texture: Arc<Texture>,
    factor: Rgb,
    /// Texels clamped to 1 (a blend's diffuse part).
    clamp: bool,
}

impl TextureFiles {
    /// The file (relative to the scene's folder) that holds `texture` × `factor` (at most 1
    /// where `clamp`), linear.
    fn file(&mut self, texture: &Arc<Texture>, factor: Rgb, clamp: bool) -> String {
        if let Some(f) = self
            .files
            .iter()
            .find(|f| Arc::ptr_eq(&f.texture, texture) && f.factor == factor && f.clamp == clamp)
        {
            return f.name.clone();
        }
        let stem = texture
            .path
            .file_stem()
            .map(|s| file_stem(&s.to_string_lossy()))
            .unwrap_or_default();
        let name = format!("textures/{:03}_{stem}.exr", self.files.len());
        self.files.push(TextureFile {
            name: name.clone(),
            texture: texture.clone(),
            factor,
            clamp,
        });
        name
    }

    /// Writes every file into `dir`; returns their paths.
    fn write(&self, dir: &Path) -> Result<Vec<std::path::PathBuf>, String> {
        let mut paths = Vec::new();
        for f in &self.files {
            let mut image = super::texture_image(&f.texture, f.factor);
            if f.clamp {
                image.data.iter_mut().for_each(|c| *c = c.min(Rgb::ONE));
            }
            let path = dir.join(&f.name);
            if let Some(parent) = path.parent() {
                std::fs::create_dir_all(parent)
                    .map_err(|e| format!("cannot create {}: {e}", parent.display()))?;
            }
            image.write(&path)?;
            paths.push(path);
        }
        Ok(paths)
    }
}

/// Mitsuba's Lambert BSDF whose reflectance is the `bitmap` `file`: linear (`raw`), bilinear as
/// matfit's lookup; repeating over mesh UVs, clamped in an atlas (whose charts must not bleed
/// into each other across the texture's border).
fn bitmap_diffuse(file: &str, mapping: &Mapping) -> String {
    format!(
        "<bsdf type=\"diffuse\">\n    {}\n</bsdf>\n",
        bitmap_texture("reflectance", file, mapping)
    )
}

/// A linear (`raw`) bitmap texture named `name`, filtered bilinearly, repeated over UVs or
/// clamped over an atlas.
fn bitmap_texture(name: &str, file: &str, mapping: &Mapping) -> String {
    let wrap = match mapping {
        Mapping::Uv => "repeat",
        Mapping::Atlas(_) => "clamp",
    };
    format!(
        "<texture type=\"bitmap\" name=\"{name}\">\n        \
         <string name=\"filename\" value=\"{}\"/>\n        \
         <boolean name=\"raw\" value=\"true\"/>\n        \
         <string name=\"filter_type\" value=\"bilinear\"/>\n        \
         <string name=\"wrap_mode\" value=\"{wrap}\"/>\n    </texture>",
        escape(file)
    )
}

/// Mitsuba's `roughplastic`, exactly matfit's plastic (`render::bsdf::plastic`): `diffuse` the
/// base's `diffuse_reflectance` element, ρs the coat's F0 × `specular_reflectance`.
fn rough_plastic(
    distribution: crate::scene::Distribution,
    alpha: f32,
    eta: f32,
    diffuse: &str,
    rho_s: Rgb,
) -> String {
    let f0 = crate::render::bsdf::plastic::fresnel_dielectric(1.0, eta);
    format!(
        "<bsdf type=\"roughplastic\">\n    <string name=\"distribution\" value=\"{}\"/>\n    \
         <float name=\"alpha\" value=\"{alpha}\"/>\n    <float name=\"int_ior\" value=\"{eta}\"/>\n    \
         <float name=\"ext_ior\" value=\"1\"/>\n    {diffuse}\n    {}\n</bsdf>\n",
        distribution.name(),
        rgb("specular_reflectance", rho_s / f0)
    )
}

fn write_integrator(xml: &mut String, scene: &Scene) {
    let _ = writeln!(
        xml,
        "    <integrator type=\"path\">\n        \
         <integer name=\"max_depth\" value=\"{}\"/>\n        \
         <integer name=\"rr_depth\" value=\"{}\"/>\n        \
         <boolean name=\"hide_emitters\" value=\"false\"/>\n    </integrator>",
        scene.render.max_depth, scene.render.rr_depth
    );
}

fn write_sensor(xml: &mut String, scene: &Scene, warnings: &mut Vec<String>) {
    let cam = &scene.camera;
    let eye = cam.eye();
    if cam.is_orthographic() {
        return write_orthographic_sensor(xml, scene);
    }
    if cam.distortion.is_some() {
        warnings.push(
            "the camera's lens distortion is not exported: Mitsuba's perspective sensor is a \
             pinhole, so its image is the undistorted one"
                .into(),
        );
    }
    let forward = cam.r.row(2);
    let up = -cam.r.row(1);
    if ((cam.fx - cam.fy) / cam.fy).abs() > 1e-4 {
        warnings.push(format!(
            "camera: fx {} ≠ fy {} but Mitsuba has square pixels; exported with fy's vertical \
             field of view",
            cam.fx, cam.fy
        ));
    }
    // Clipping planes that cut nothing: far beyond the farthest corner of the scene, near a tiny
    // fraction of that (Mitsuba starts camera rays at the near plane).
    let far = super::far_clip(scene, eye);
    let near = far * 1e-6;
    let off_x = 0.5 - cam.cx / cam.width as f32;
    let off_y = 0.5 - cam.cy / cam.height as f32;
    let _ = writeln!(xml, "    <sensor type=\"perspective\">");
    let _ = writeln!(xml, "        <string name=\"fov_axis\" value=\"y\"/>");
    let _ = writeln!(
        xml,
        "        <float name=\"fov\" value=\"{}\"/>",
        cam.fov_y_deg().unwrap_or_default()
    );
    if off_x.abs() > 1e-7 || off_y.abs() > 1e-7 {
        let _ = writeln!(
            xml,
            "        <float name=\"principal_point_offset_x\" value=\"{off_x}\"/>\n        \
             <float name=\"principal_point_offset_y\" value=\"{off_y}\"/>"
        );
    }
    let _ = writeln!(
        xml,
        "        <float name=\"near_clip\" value=\"{near}\"/>\n        \
         <float name=\"far_clip\" value=\"{far}\"/>"
    );
    let target = eye + forward;
    let _ = writeln!(
        xml,
        "        <transform name=\"to_world\">\n            \
         <lookat origin=\"{}\" target=\"{}\" up=\"{}\"/>\n        </transform>",
        triple(eye),
        triple(target),
        triple(up)
    );
    write_sampler_and_film(xml, scene);
}

/// Mitsuba's `orthographic` sensor sees local [−1, 1] × [−1/aspect, 1/aspect] on its z = 0
/// plane, looking along +z, with film u = 0 at local +x (Mitsuba 3.9.1's `sample_ray`:
/// a `scale(2, 1.5, 1)` then `lookat` on a 200×100 film put pixel (0, 0)'s corner at local
/// (2, 0.75)). So `to_world` = lookat ∘ scale(width / 2fx, width / 2fy, 1), the lookat from
/// the film's centre: fx ≠ fy and an off-centre principal point are exact.
fn write_orthographic_sensor(xml: &mut String, scene: &Scene) {
    let cam = &scene.camera;
    let (w, h) = (cam.width as f32, cam.height as f32);
    let centre = cam.ray(Vec2::new(0.5 * w, 0.5 * h)).o;
    let forward = cam.r.row(2);
    let up = -cam.r.row(1);
    // Mitsuba starts the rays at the near plane, matfit at the film plane: the sensor goes
    // `near` behind the film plane (and the importer adds it back).
    let far = super::far_clip(scene, centre);
    let near = far * 1e-6;
    let origin = centre - forward * near;
    let _ = writeln!(
        xml,
        "    <sensor type=\"orthographic\">\n        \
         <float name=\"near_clip\" value=\"{near}\"/>\n        \
         <float name=\"far_clip\" value=\"{far}\"/>"
    );
    let _ = writeln!(
        xml,
        "        <transform name=\"to_world\">\n            \
         <scale x=\"{}\" y=\"{}\"/>\n            \
         <lookat origin=\"{}\" target=\"{}\" up=\"{}\"/>\n        </transform>",
        0.5 * w / cam.fx,
        0.5 * w / cam.fy,
        triple(origin),
        triple(origin + forward),
        triple(up)
    );
    write_sampler_and_film(xml, scene);
}

fn write_sampler_and_film(xml: &mut String, scene: &Scene) {
    let cam = &scene.camera;
    let _ = writeln!(
        xml,
        "        <sampler type=\"independent\">\n            \
         <integer name=\"sample_count\" value=\"{}\"/>\n        </sampler>",
        scene.render.spp
    );
    let _ = writeln!(
        xml,
        "        <film type=\"hdrfilm\">\n            \
         <integer name=\"width\" value=\"{}\"/>\n            \
         <integer name=\"height\" value=\"{}\"/>\n            \
         <string name=\"pixel_format\" value=\"rgb\"/>\n            \
         <rfilter type=\"box\"/>\n        </film>\n    </sensor>",
        cam.width, cam.height
    );
}

/// The (one-sided) BSDF element of a material, without the `twosided` wrapper. `stand_in`
/// (the fitted microfacet lobe, [`super::standin`]) is called for Ward lobes only.
fn bsdf_xml(
    m: &Material,
    name: &str,
    stand_in: impl FnOnce() -> Option<StandIn>,
    textures: &mut TextureFiles,
    warnings: &mut Vec<String>,
) -> String {
    let mirror = |c: Rgb| {
        format!(
            "<bsdf type=\"conductor\">\n    <string name=\"material\" value=\"none\"/>\n    {}\n</bsdf>\n",
            rgb("specular_reflectance", c)
        )
    };
    match m {
        Material::Diffuse { rho_d } => diffuse(*rho_d),
        Material::Mirror { rho_s } => mirror(*rho_s),
        Material::DiffuseMirror { rho_d, rho_s } => {
            blend(*rho_d, *rho_s, mirror, name, "diffuse_mirror", warnings)
        }
        Material::Ward {
            rho_d,
            rho_s,
            alpha_x,
            alpha_y,
            ..
        } => {
            let s = ward_stand_in(stand_in, *alpha_x, *alpha_y, name, "Ward", warnings);
            let lobe = |c: Rgb| rough_conductor(s.distribution.name(), s.alpha_x, s.alpha_y, c);
            blend(*rho_d, *rho_s * s.k, lobe, name, "ward", warnings)
        }
        Material::Microfacet {
            rho_d,
            rho_s,
            alpha_x,
            alpha_y,
            distribution,
            ..
        } => {
            // Exact: matfit's lobe is this plugin's value (`render::bsdf::microfacet`).
            let lobe = |c: Rgb| rough_conductor(distribution.name(), *alpha_x, *alpha_y, c);
            blend(*rho_d, *rho_s, lobe, name, "microfacet", warnings)
        }
        Material::Plastic {
            rho_d,
            rho_s,
            alpha,
            eta,
            distribution,
        } => {
            // Exact: `render::bsdf::plastic` is this plugin.
            rough_plastic(
                *distribution,
                *alpha,
                *eta,
                &rgb("diffuse_reflectance", *rho_d),
                *rho_s,
            )
        }
        Material::Textured {
            texture,
            scale,
            varnish,
        } => {
            // Mitsuba's bitmap has no scale: the factor is baked into the file.
            let mut bitmap = |f: Rgb, clamp: bool| {
                bitmap_diffuse(&textures.file(texture, f, clamp), &texture.mapping)
            };
            let Some(v) = varnish else {
                return bitmap(*scale, false);
            };
            if v.alpha_x != v.alpha_y {
                warnings.push(format!(
                    "object '{name}': Mitsuba orients an anisotropic lobe along the UVs' dp/du, \
                     which here are the texture's: the varnish's direction (θ) is not carried"
                ));
            }
            let s = ward_stand_in(
                stand_in,
                v.alpha_x,
                v.alpha_y,
                name,
                "the varnish, a Ward lobe,",
                warnings,
            );
            let lobe = |c: Rgb| rough_conductor(s.distribution.name(), s.alpha_x, s.alpha_y, c);
            let d = texture
                .texels
                .iter()
                .map(|&t| (t * *scale).max_element())
                .fold(0.0, f32::max);
            let diffuse_part = |f: f32| bitmap(*scale * f, true);
            blend_with(
                d,
                diffuse_part,
                v.rho_s * s.k,
                lobe,
                name,
                "textured",
                warnings,
            )
        }
        Material::TexturedPlastic {
            texture,
            scale,
            rho_s,
            alpha,
            eta,
            distribution,
        } => {
            // Exact, as for a plastic; Mitsuba's bitmap has no scale: baked into the file.
            let file = textures.file(texture, *scale, false);
            rough_plastic(
                *distribution,
                *alpha,
                *eta,
                &bitmap_texture("diffuse_reflectance", &file, &texture.mapping),
                *rho_s,
            )
        }
        Material::Black => diffuse(Rgb::ZERO),
    }
}

/// A perfectly conducting `roughconductor` of specular reflectance `c` (roughness: `alpha`
/// where isotropic, else `alpha_u` and `alpha_v`).
fn rough_conductor(distribution: &str, alpha_x: f32, alpha_y: f32, c: Rgb) -> String {
    let alphas = if alpha_x == alpha_y {
        format!("<float name=\"alpha\" value=\"{alpha_x}\"/>")
    } else {
        format!(
            "<float name=\"alpha_u\" value=\"{alpha_x}\"/>\n    \
             <float name=\"alpha_v\" value=\"{alpha_y}\"/>"
        )
    };
    format!(
        "<bsdf type=\"roughconductor\">\n    <string name=\"material\" value=\"none\"/>\n    \
         <string name=\"distribution\" value=\"{distribution}\"/>\n    {alphas}\n    {}\n</bsdf>\n",
        rgb("specular_reflectance", c)
    )
}

/// `Lambert(ρd) + lobe(ρs)` as a Mitsuba `blendbsdf`: (1 − w)·diffuse(ρd/(1 − w)) + w·lobe(ρs/w)
/// with w = max ρs / (max ρd + max ρs), exact while both components stay ≤ 1, i.e. while
/// max ρd + max ρs ≤ 1; beyond that a warning and the components are clamped.
fn blend(
    rho_d: Rgb,
    rho_s: Rgb,
    lobe: impl Fn(Rgb) -> String,
    name: &str,
    kind: &str,
    warnings: &mut Vec<String>,
) -> String {
    let part = |f: f32| diffuse((rho_d * f).min(Rgb::ONE));
    blend_with(rho_d.max_element(), part, rho_s, lobe, name, kind, warnings)
}

/// [`blend`] with any diffuse part (a texture): `diffuse(f)` is the Lambert part of ρd × f,
/// clamped to 1, and `d` is ρd's largest channel anywhere.
fn blend_with(
    d: f32,
    diffuse: impl FnOnce(f32) -> String,
    rho_s: Rgb,
    lobe: impl Fn(Rgb) -> String,
    name: &str,
    kind: &str,
    warnings: &mut Vec<String>,
) -> String {
    let s = rho_s.max_element();
    if s <= 0.0 {
        return diffuse(1.0);
    }
    if d <= 0.0 {
        return lobe(rho_s);
    }
    if d + s > 1.0 {
        warnings.push(format!(
            "object '{name}': {kind} with max ρd + max ρs = {:.4} > 1 has no exact Mitsuba \
             blendbsdf; the blend's components are clamped to 1",
            d + s
        ));
    }
    let w = s / (d + s);
    let b = (rho_s / w).min(Rgb::ONE);
    format!(
        "<bsdf type=\"blendbsdf\">\n    <float name=\"weight\" value=\"{w}\"/>\n{}{}</bsdf>\n",
        indent(&diffuse(1.0 / (1.0 - w)), 4),
        indent(&lobe(b), 4)
    )
}

/// The microfacet lobe standing for a Ward lobe of roughness (`alpha_x`, `alpha_y`) (fitted by
/// `stand_in`, else, where the camera does not see the object, Beckmann with Ward's α and
/// k = 1), with the warning that says what it is and what it leaves.
fn ward_stand_in(
    stand_in: impl FnOnce() -> Option<StandIn>,
    alpha_x: f32,
    alpha_y: f32,
    name: &str,
    what: &str,
    warnings: &mut Vec<String>,
) -> StandIn {
    let alphas = |x: f32, y: f32| {
        if x == y {
            format!("α {x:.4}")
        } else {
            format!("αu {x:.4}, αv {y:.4}")
        }
    };
    let Some(s) = stand_in() else {
        warnings.push(format!(
            "object '{name}': {what} has no Mitsuba equivalent; exported as ρd·Lambert + \
             ρs·Beckmann microfacet (roughconductor, {}), not fitted: the camera does not see \
             the object, so its error is not known",
            alphas(alpha_x, alpha_y)
        ));
        return StandIn {
            distribution: Distribution::Beckmann,
            alpha_x,
            alpha_y,
            k: 1.0,
            lobe_error: f32::NAN,
            error: f32::NAN,
            bias: f32::NAN,
            naive_error: f32::NAN,
            views: 0,
            bounced: 0,
        };
    };
    warnings.push(format!(
        "object '{name}': {what} has no Mitsuba equivalent; exported as ρd·Lambert + \
         k·ρs·{} microfacet (roughconductor, {}, k = {:.3}; Ward's {}), fitted to the lobe over \
         {} camera views of its group and {} through diffuse bounces: it differs from Ward \
         by {:.1}% of the lobe's radiance (L1) and {:.1}% of all the group reflects there (mean \
         {:+.1}%); Beckmann with Ward's α would leave {:.1}% of the lobe. Views other than this \
         camera's may differ more",
        match s.distribution {
            Distribution::Ggx => "GGX",
            Distribution::Beckmann => "Beckmann",
        },
        alphas(s.alpha_x, s.alpha_y),
        s.k,
        alphas(alpha_x, alpha_y),
        s.views,
        s.bounced,
        100.0 * s.lobe_error,
        100.0 * s.error,
        // Rounded first, so that a mean of −0.01% reads 0.0%, not −0.0%.
        (1000.0 * s.bias).round() / 10.0 + 0.0,
        100.0 * s.naive_error,
    ));
    s
}

/// Binary little-endian PLY of object `oi`'s triangles: positions, normals, uvs, matfit's vertex
/// order. Only the vertices its triangles use are written.
pub fn object_ply(scene: &Scene, oi: usize) -> Vec<u8> {
    object_ply_with(scene, oi, None)
}

/// [`object_ply`], or with `anisotropy = Some(θ)` every triangle's own three vertices with UVs
/// (s·p, t·p) in matfit's shading frame rotated by θ, so that Mitsuba's dp/du is that frame's s.
fn object_ply_with(scene: &Scene, oi: usize, anisotropy: Option<f32>) -> Vec<u8> {
    let g = &*scene.geometry;
    let obj = &scene.objects[oi];
    let range = obj.tri_range.start as usize..obj.tri_range.end as usize;
    let tris = &g.tris[range.clone()];
    // Compact the vertices: old index → new index (with a UV of their own if anisotropic).
    let mut remap = std::collections::HashMap::new();
    let mut verts: Vec<(u32, Option<Vec2>)> = Vec::new();
    let faces: Vec<[u32; 3]> = tris
        .iter()
        .zip(range)
        .map(|(t, ti)| match anisotropy {
            None => t.v.map(|i| {
                *remap.entry(i).or_insert_with(|| {
                    verts.push((i, None));
                    verts.len() as u32 - 1
                })
            }),
            Some(theta) => {
                let face = &g.faces[ti];
                let frame = face
                    .frame
                    .unwrap_or_else(|| {
                        let t = obj.tangent.unwrap_or(face.dpdu);
                        if t == Vec3::ZERO {
                            crate::math::Frame::from_normal(face.ng)
                        } else {
                            crate::math::Frame::from_normal_tangent(face.ng, t)
                        }
                    })
                    .rotated(theta);
                t.v.map(|i| {
                    let p = g.positions[i as usize];
                    verts.push((i, Some(Vec2::new(p.dot(frame.s), p.dot(frame.t)))));
                    verts.len() as u32 - 1
                })
            }
        })
        .collect();
    let verts: Vec<PlyVertex> = (verts.iter())
        .map(|&(i, uv)| PlyVertex {
            p: g.positions[i as usize],
            n: g.normals[i as usize],
            uv: uv.unwrap_or(g.uvs[i as usize]),
        })
        .collect();
    ply_bytes(&obj.name, &verts, &faces)
}

/// Object `oi`'s PLY with its texture's coordinates in Mitsuba's convention, v down from the
/// image's top row (Mitsuba's PLY loader keeps v as stored; matfit's v runs up), or an atlas's
/// position in it; vertices are duplicated on an atlas's chart seams.
fn textured_ply(scene: &Scene, oi: usize) -> Vec<u8> {
    let m = super::gltf::object_mesh(scene, oi, false);
    let uv = |k: usize| m.uvs.as_ref().map_or(Vec2::ZERO, |u| u[k]);
    let verts: Vec<PlyVertex> = (0..m.positions.len())
        .map(|k| PlyVertex {
            p: m.positions[k],
            n: m.normals[k],
            uv: uv(k),
        })
        .collect();
    ply_bytes(&scene.objects[oi].name, &verts, &m.indices)
}

struct PlyVertex {
    p: Vec3,
    n: Vec3,
    uv: Vec2,
}

/// A binary little-endian PLY of triangles.
fn ply_bytes(name: &str, verts: &[PlyVertex], faces: &[[u32; 3]]) -> Vec<u8> {
    let mut out = format!(
        "ply\nformat binary_little_endian 1.0\ncomment matfit export: object '{}'\n\
         element vertex {}\nproperty float x\nproperty float y\nproperty float z\n\
         property float nx\nproperty float ny\nproperty float nz\n\
         property float u\nproperty float v\n\
         element face {}\nproperty list uchar int vertex_indices\nend_header\n",
        name.replace(['\n', '\r'], " "),
        verts.len(),
        faces.len()
    )
    .into_bytes();
    out.reserve(verts.len() * 32 + faces.len() * 13);
    for PlyVertex { p, n, uv } in verts {
        for x in [p.x, p.y, p.z, n.x, n.y, n.z, uv.x, uv.y] {
            out.extend_from_slice(&x.to_le_bytes());
        }
    }
    for f in faces {
        out.push(3);
        for i in f {
            out.extend_from_slice(&(*i as i32).to_le_bytes());
        }
    }
    out
}

/// Mitsuba's Lambert BSDF of reflectance `c`.
fn diffuse(c: Rgb) -> String {
    format!(
        "<bsdf type=\"diffuse\">\n    {}\n</bsdf>\n",
        rgb("reflectance", c)
    )
}

fn rgb(name: &str, c: Rgb) -> String {
    format!("<rgb name=\"{name}\" value=\"{}, {}, {}\"/>", c.x, c.y, c.z)
}

fn triple(v: Vec3) -> String {
    format!("{}, {}, {}", v.x, v.y, v.z)
}

fn indent(s: &str, n: usize) -> String {
    let pad = " ".repeat(n);
    s.lines().map(|l| format!("{pad}{l}\n")).collect()
}

/// A file-name-safe version of an object name.
fn file_stem(name: &str) -> String {
    name.chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '-' || c == '_' {
                c
            } else {
                '_'
            }
        })
        .collect()
}

/// Escapes text for an XML attribute value.
fn escape(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
        .replace('\'', "&apos;")
}

/// Text safe inside an XML comment (no "--").
fn escape_comment(s: &str) -> String {
    escape(s).replace("--", "- -")
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The value of the first `<tag name="key" value="...">` after `from` in `s`.
    fn values(s: &str, key: &str) -> Vec<Vec<f32>> {
        s.match_indices(&format!("name=\"{key}\" value=\""))
            .map(|(i, m)| {
                let rest = &s[i + m.len()..];
                rest[..rest.find('"').unwrap()]
                    .split(',')
                    .map(|x| x.trim().parse().unwrap())
                    .collect()
            })
            .collect()
    }

    #[test]
    fn diffuse_mirror_blend_is_exactly_the_sum() {
        let rho_d = Rgb::new(0.5, 0.2, 0.1);
        let rho_s = Rgb::new(0.3, 0.4, 0.2);
        let mut warnings = Vec::new();
        let x = bsdf_xml(
            &Material::DiffuseMirror { rho_d, rho_s },
            "t",
            || None,
            &mut TextureFiles::default(),
            &mut warnings,
        );
        assert!(warnings.is_empty(), "{warnings:?}");
        let w = values(&x, "weight")[0][0];
        let a = Rgb::from_slice(&values(&x, "reflectance")[0]);
        let b = Rgb::from_slice(&values(&x, "specular_reflectance")[0]);
        assert!(x.contains("value=\"none\""));
        // blend(w) = (1 − w)·diffuse(a) + w·conductor(b) must be ρd·Lambert + ρs·mirror.
        assert!(
            ((1.0 - w) * a - rho_d).abs().max_element() < 1e-6,
            "{w} {a}"
        );
        assert!((w * b - rho_s).abs().max_element() < 1e-6, "{w} {b}");
        assert!(a.max_element() <= 1.0 && b.max_element() <= 1.0);
        // Beyond max ρd + max ρs = 1 there is no exact blend: said so.
        bsdf_xml(
            &Material::DiffuseMirror {
                rho_d: Rgb::splat(0.6),
                rho_s: Rgb::splat(0.6),
            },
            "u",
            || None,
            &mut TextureFiles::default(),
            &mut warnings,
        );
        assert_eq!(warnings.len(), 1);
    }

    #[test]
    fn ward_is_the_diffuse_blend_with_a_beckmann_lobe_of_the_same_alphas() {
        let mut warnings = Vec::new();
        let x = bsdf_xml(
            &Material::Ward {
                rho_d: Rgb::splat(0.1),
                rho_s: Rgb::new(0.9, 0.8, 0.7),
                alpha_x: 0.07,
                alpha_y: 0.11,
                theta: 0.3,
            },
            "floor",
            || {
                Some(StandIn {
                    distribution: Distribution::Beckmann,
                    alpha_x: 0.07,
                    alpha_y: 0.11,
                    k: 0.5,
                    lobe_error: 0.01,
                    error: 0.005,
                    bias: 0.0,
                    naive_error: 0.1,
                    views: 100,
                    bounced: 100,
                })
            },
            &mut TextureFiles::default(),
            &mut warnings,
        );
        assert_eq!(warnings.len(), 1, "{warnings:?}");
        assert!(
            x.contains("roughconductor") && x.contains("beckmann"),
            "{x}"
        );
        assert_eq!(values(&x, "alpha_u")[0][0], 0.07);
        assert_eq!(values(&x, "alpha_v")[0][0], 0.11);
        let w = values(&x, "weight")[0][0];
        let a = Rgb::from_slice(&values(&x, "reflectance")[0]);
        let b = Rgb::from_slice(&values(&x, "specular_reflectance")[0]);
        assert!(((1.0 - w) * a - Rgb::splat(0.1)).abs().max_element() < 1e-6);
        assert!((w * b - 0.5 * Rgb::new(0.9, 0.8, 0.7)).abs().max_element() < 1e-6);
    }

    /// The microfacet lobe is Mitsuba's GGX roughconductor itself: no scale, no warning.
    #[test]
    fn microfacet_is_the_diffuse_blend_with_the_same_ggx_lobe() {
        let mut warnings = Vec::new();
        let x = bsdf_xml(
            &Material::Microfacet {
                rho_d: Rgb::splat(0.1),
                rho_s: Rgb::new(0.6, 0.5, 0.4),
                alpha_x: 0.2,
                alpha_y: 0.2,
                theta: 0.0,
                distribution: crate::scene::Distribution::Ggx,
            },
            "block",
            || panic!("no Ward scale for a microfacet lobe"),
            &mut TextureFiles::default(),
            &mut warnings,
        );
        assert!(warnings.is_empty(), "{warnings:?}");
        assert!(x.contains("roughconductor") && x.contains("\"ggx\""), "{x}");
        assert_eq!(values(&x, "alpha")[0][0], 0.2);
        let w = values(&x, "weight")[0][0];
        let a = Rgb::from_slice(&values(&x, "reflectance")[0]);
        let b = Rgb::from_slice(&values(&x, "specular_reflectance")[0]);
        assert!(((1.0 - w) * a - Rgb::splat(0.1)).abs().max_element() < 1e-6);
        assert!((w * b - Rgb::new(0.6, 0.5, 0.4)).abs().max_element() < 1e-6);
    }

    /// The plastic is Mitsuba's GGX roughplastic itself: specular_reflectance = ρs / F0.
    #[test]
    fn plastic_is_roughplastic_with_the_coats_f0_divided_out() {
        let mut warnings = Vec::new();
        let x = bsdf_xml(
            &Material::Plastic {
                rho_d: Rgb::new(0.7, 0.05, 0.05),
                rho_s: Rgb::splat(0.02),
                alpha: 0.1,
                eta: 1.5,
                distribution: crate::scene::Distribution::Ggx,
            },
            "block",
            || panic!("no Ward scale for a plastic"),
            &mut TextureFiles::default(),
            &mut warnings,
        );
        assert!(warnings.is_empty(), "{warnings:?}");
        assert!(x.contains("roughplastic") && x.contains("\"ggx\""), "{x}");
        assert_eq!(values(&x, "alpha")[0][0], 0.1);
        assert_eq!(values(&x, "int_ior")[0][0], 1.5);
        assert_eq!(values(&x, "diffuse_reflectance")[0], vec![0.7, 0.05, 0.05]);
        assert!(
            (values(&x, "specular_reflectance")[0][0] - 0.5).abs() < 1e-5,
            "{x}"
        );
    }

    /// Mitsuba's αu runs along dp/du: the anisotropic PLY's UVs must make dp/du matfit's tangent
    /// rotated by θ, on every triangle of a box (six frames).
    #[test]
    fn anisotropic_uvs_put_dpdu_along_the_rotated_tangent() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("s.toml");
        std::fs::write(
            &path,
            "[camera]\nwidth = 8\nheight = 8\neye = [0, 0, 5]\ntarget = [0, 0, 0]\n\
             up = [0, 1, 0]\nfov_y_deg = 40\n\
             [[object]]\nname = \"b\"\ngroup = \"b\"\nshape = \"box\"\nmin = [-1, -1, -1]\n\
             max = [1, 1, 1]\ntangent = [1, 1, 0]\nmaterial = { type = \"ward\", rho_d = 0.1, \
             rho_s = 0.5, alpha_x = 0.1, alpha_y = 0.3, theta_deg = 30 }\n",
        )
        .unwrap();
        let scene = crate::scene::load_scene(&path).unwrap();
        let ply = object_ply_with(&scene, 0, Some(30f32.to_radians()));
        let header_end = ply.windows(11).position(|w| w == b"end_header\n").unwrap() + 11;
        let f = |k: usize| f32::from_le_bytes(ply[header_end + 4 * k..][..4].try_into().unwrap());
        let g = &*scene.geometry;
        let range = scene.objects[0].tri_range.clone();
        assert_eq!(range.len(), 12);
        for (n, ti) in range.enumerate() {
            // Vertex 3n + k: 8 floats x y z nx ny nz u v.
            let v = |k: usize| {
                let b = (3 * n + k) * 8;
                (
                    Vec3::new(f(b), f(b + 1), f(b + 2)),
                    Vec2::new(f(b + 6), f(b + 7)),
                )
            };
            let ((p0, uv0), (p1, uv1), (p2, uv2)) = (v(0), v(1), v(2));
            let (d1, d2) = (uv1 - uv0, uv2 - uv0);
            let det = d1.x * d2.y - d1.y * d2.x;
            let dpdu = ((p1 - p0) * d2.y - (p2 - p0) * d1.y) / det;
            let want = g.faces[ti as usize]
                .frame
                .unwrap()
                .rotated(30f32.to_radians())
                .s;
            assert!(
                (dpdu - want).length() < 1e-4,
                "triangle {ti}: {dpdu} vs {want}"
            );
        }
    }
}
