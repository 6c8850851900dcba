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
//!   that they cut nothing.
//! - **Film.** `hdrfilm`, the same width and height, `rfilter = box` (matfit's pixel filter),
//!   `pixel_format = rgb`. **Sampler** `independent` with the scene's spp.
//! - **Integrator.** `path` with `max_depth` and `rr_depth` = the scene's (same meanings:
//!   segments of a path; the same roulette) and `hide_emitters = false`.
//! - **BSDFs**, each wrapped in `twosided` (matfit's surfaces reflect on both sides):
//!   diffuse → `diffuse`; mirror → `conductor` with `material = "none"` (a 100% mirror) and
//!   `specular_reflectance` = ρs; diffuse + mirror → `blendbsdf` of weight w of
//!   `diffuse`(ρd/(1−w)) and `conductor`(ρs/w), which is exactly ρd·Lambert + ρs·mirror when both
//!   stay ≤ 1, i.e. when max ρd + max ρs ≤ 1 (w = max ρs / (max ρd + max ρs)); otherwise a warning
//!   and the blend is clamped. Ward has no Mitsuba equivalent (its `roughplastic` and
//!   `roughconductor` are microfacet models): a warning, exported as `diffuse` ρd. A texture is
//!   not exported: a warning, `diffuse` with the texture's mean × scale. Black → `diffuse` 0
//!   (Mitsuba would otherwise give a shape its default 50% grey).
//! - **Emitters.** `area` with rgb `radiance` = the object's emission, one-sided like matfit's.

use super::ExportReport;
use crate::math::{Rgb, Vec2, Vec3};
use crate::scene::{Material, Scene};
use std::fmt::Write as _;
use std::path::Path;

/// Writes `dir/scene.xml` and `dir/meshes/*.ply` for `scene`. `dir` is created if needed.
pub fn export(scene: &Scene, dir: &Path) -> Result<ExportReport, String> {
    let mut report = ExportReport::default();
    let meshes = dir.join("meshes");
    std::fs::create_dir_all(&meshes)
        .map_err(|e| format!("cannot create {}: {e}", meshes.display()))?;

    let mut xml = String::new();
    xml.push_str("<?xml version=\"1.0\" encoding=\"utf-8\"?>\n");
    let _ = writeln!(
        xml,
        "<!-- Exported by matfit {} from {}. Geometry in world space (meshes/*.ply). -->",
        env!("CARGO_PKG_VERSION"),
        escape(&scene.path.display().to_string())
    );
    xml.push_str("<scene version=\"3.0.0\">\n");
    write_integrator(&mut xml, scene);
    write_sensor(&mut xml, scene, &mut report.warnings);

    let mut ply_files = Vec::new();
    for (oi, obj) in scene.objects.iter().enumerate() {
        let file = format!("meshes/{oi:03}_{}.ply", file_stem(&obj.name));
        let bytes = object_ply(scene, oi);
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
        // Mitsuba reserves ids that start with an underscore.
        let id = if obj.name.starts_with('_') {
            format!("o{}", obj.name)
        } else {
            obj.name.clone()
        };
        let _ = writeln!(xml, "    <shape type=\"ply\" id=\"{}\">", escape(&id));
        let _ = writeln!(xml, "        <string name=\"filename\" value=\"{file}\"/>");
        let bsdf = bsdf_xml(&obj.material, &obj.name, &mut report.warnings);
        let _ = writeln!(
            xml,
            "        <bsdf type=\"twosided\">\n{}        </bsdf>",
            indent(&bsdf, 12)
        );
        if obj.is_emitter() {
            let _ = writeln!(
                xml,
                "        <emitter type=\"area\">\n            {}\n        </emitter>",
                rgb("radiance", obj.emission)
            );
        }
        xml.push_str("    </shape>\n");
    }
    xml.push_str("</scene>\n");

    let xml_path = dir.join("scene.xml");
    crate::io::atomic::write_atomic(&xml_path, xml.as_bytes())
        .map_err(|e| format!("cannot write {}: {e}", xml_path.display()))?;
    report.files.push(xml_path);
    report.files.extend(ply_files);
    Ok(report)
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
    let b = scene.geometry.bvh.bounds();
    let mut far = 0.0f32;
    for i in 0..8 {
        let corner = Vec3::new(
            if i & 1 == 0 { b.min.x } else { b.max.x },
            if i & 2 == 0 { b.min.y } else { b.max.y },
            if i & 4 == 0 { b.min.z } else { b.max.z },
        );
        far = far.max((corner - eye).length());
    }
    let far = (2.0 * far).max(1e-3);
    let near = far * 1e-6;
    let off_x = 0.5 - cam.cx / cam.width as f32;
    let off_y = 0.5 - cam.cy / cam.height as f32;
    let _ = writeln!(xml, "    <sensor type=\"perspective\">");
    let _ = writeln!(xml, "        <string name=\"fov_axis\" value=\"y\"/>");
    let _ = writeln!(
        xml,
        "        <float name=\"fov\" value=\"{}\"/>",
        cam.fov_y_deg()
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

/// The (one-sided) BSDF element of a material, without the `twosided` wrapper.
fn bsdf_xml(m: &Material, name: &str, warnings: &mut Vec<String>) -> String {
    let diffuse = |c: Rgb| {
        format!(
            "<bsdf type=\"diffuse\">\n    {}\n</bsdf>\n",
            rgb("reflectance", c)
        )
    };
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
            let (d, s) = (rho_d.max_element(), rho_s.max_element());
            if s <= 0.0 {
                return diffuse(*rho_d);
            }
            if d <= 0.0 {
                return mirror(*rho_s);
            }
            if d + s > 1.0 {
                warnings.push(format!(
                    "object '{name}': diffuse_mirror with max ρd + max ρs = {:.4} > 1 has no \
                     exact Mitsuba blendbsdf; the blend's components are clamped to 1",
                    d + s
                ));
            }
            // (1 − w)·diffuse(ρd/(1 − w)) + w·mirror(ρs/w) = ρd·Lambert + ρs·mirror.
            let w = s / (d + s);
            let a = (*rho_d / (1.0 - w)).min(Rgb::ONE);
            let b = (*rho_s / w).min(Rgb::ONE);
            format!(
                "<bsdf type=\"blendbsdf\">\n    <float name=\"weight\" value=\"{w}\"/>\n{}{}</bsdf>\n",
                indent(&diffuse(a), 4),
                indent(&mirror(b), 4)
            )
        }
        Material::Ward { rho_d, rho_s, .. } => {
            warnings.push(format!(
                "object '{name}': Ward has no Mitsuba equivalent; exported as diffuse ρd {:?} \
                 (the specular lobe ρs {:?} is dropped)",
                rho_d.to_array(),
                rho_s.to_array()
            ));
            diffuse(*rho_d)
        }
        Material::Textured { varnish, .. } => {
            let mean = m.rho_d();
            warnings.push(format!(
                "object '{name}': textures are not exported; diffuse with the texture's mean \
                 {:?}{}",
                mean.to_array(),
                if varnish.is_some() {
                    " (its varnish, a Ward lobe, is dropped)"
                } else {
                    ""
                }
            ));
            diffuse(mean)
        }
        Material::Black => diffuse(Rgb::ZERO),
    }
}

/// Binary little-endian PLY of object `oi`'s triangles: positions, normals, uvs, matfit's vertex
/// order. Only the vertices its triangles use are written.
pub fn object_ply(scene: &Scene, oi: usize) -> Vec<u8> {
    let g = &*scene.geometry;
    let tris =
        &g.tris[scene.objects[oi].tri_range.start as usize..][..scene.objects[oi].tri_range.len()];
    // Compact the vertices: old index → new index.
    let mut remap = std::collections::HashMap::new();
    let mut verts: Vec<u32> = Vec::new();
    let faces: Vec<[u32; 3]> = tris
        .iter()
        .map(|t| {
            t.v.map(|i| {
                *remap.entry(i).or_insert_with(|| {
                    verts.push(i);
                    verts.len() as u32 - 1
                })
            })
        })
        .collect();
    let mut out = format!(
        "ply\nformat binary_little_endian 1.0\ncomment matfit export: object '{}'\n\
         element vertex {}\nproperty float x\nproperty float y\nproperty float z\n\
         property float nx\nproperty float ny\nproperty float nz\n\
         property float u\nproperty float v\n\
         element face {}\nproperty list uchar int vertex_indices\nend_header\n",
        scene.objects[oi].name.replace(['\n', '\r'], " "),
        verts.len(),
        faces.len()
    )
    .into_bytes();
    out.reserve(verts.len() * 32 + faces.len() * 13);
    for &i in &verts {
        let (p, n, uv): (Vec3, Vec3, Vec2) = (
            g.positions[i as usize],
            g.normals[i as usize],
            g.uvs[i as usize],
        );
        for x in [p.x, p.y, p.z, n.x, n.y, n.z, uv.x, uv.y] {
            out.extend_from_slice(&x.to_le_bytes());
        }
    }
    for f in &faces {
        out.push(3);
        for i in f {
            out.extend_from_slice(&(*i as i32).to_le_bytes());
        }
    }
    out
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
            &mut warnings,
        );
        assert_eq!(warnings.len(), 1);
    }
}
