//! `matfit export gltf`: the .glb read back with the `gltf` crate (which validates the JSON and
//! the binary chunk) carries matfit's triangles, materials, textures and camera.
//! With `MATFIT_GLTF_VALIDATOR` set to a node script that runs the Khronos glTF-Validator
//! (`tools/gltf_validate.js`; docs/USAGE.md, "export"), the files are also checked by the reference validator.

use crate::common::{root, run};
use glam::{Mat3, Quat, Vec2, Vec3};
use matfit::scene::{load_scene, Material, Scene};
use std::path::{Path, PathBuf};

/// Runs `matfit export gltf` on a bundled scene; returns (scene, .glb bytes, stderr).
fn export(scene: &str, dir: &Path) -> (Scene, Vec<u8>, String) {
    let scene_path = root().join("scenes").join(scene).join("scene.toml");
    let out = dir.join(format!("{scene}.glb"));
    let (code, stdout, stderr) = run(
        &[
            "export",
            "gltf",
            scene_path.to_str().unwrap(),
            "-o",
            out.to_str().unwrap(),
        ],
        dir,
    );
    assert_eq!(code, 0, "{stdout}\n{stderr}");
    assert!(stdout.contains("wrote"), "{stdout}");
    validate_with_khronos(&out);
    (
        load_scene(&scene_path).unwrap(),
        std::fs::read(&out).unwrap(),
        stderr,
    )
}

/// The Khronos validator's verdict, when `MATFIT_GLTF_VALIDATOR` names its node script: it must
/// report no error and no warning.
fn validate_with_khronos(glb: &Path) {
    let Some(script) = std::env::var_os("MATFIT_GLTF_VALIDATOR") else {
        return;
    };
    let out = std::process::Command::new("node")
        .arg(PathBuf::from(script))
        .arg(glb)
        .output()
        .expect("runs node");
    let text =
        String::from_utf8_lossy(&out.stdout).into_owned() + &String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{}: {text}", glb.display());
    assert!(
        text.contains("errors 0") && text.contains("warnings 0"),
        "{}: {text}",
        glb.display()
    );
}

/// Per node name: world-space triangles of its mesh.
fn triangles(doc: &gltf::Gltf, blob: &[u8]) -> Vec<(String, Vec<[Vec3; 3]>)> {
    doc.nodes()
        .filter_map(|n| {
            let mesh = n.mesh()?;
            assert_eq!(
                n.transform().matrix(),
                glam::Mat4::IDENTITY.to_cols_array_2d()
            );
            let mut tris = Vec::new();
            for prim in mesh.primitives() {
                let r = prim.reader(|_| Some(blob));
                let p: Vec<Vec3> = r.read_positions().unwrap().map(Vec3::from).collect();
                let idx: Vec<u32> = r.read_indices().unwrap().into_u32().collect();
                for t in idx.chunks(3) {
                    tris.push([p[t[0] as usize], p[t[1] as usize], p[t[2] as usize]]);
                }
            }
            Some((n.name().unwrap().to_string(), tris))
        })
        .collect()
}

fn area(t: &[Vec3; 3]) -> f64 {
    0.5 * (t[1] - t[0]).cross(t[2] - t[0]).length() as f64
}

/// The material of the node named `name`.
fn material_of<'a>(doc: &'a gltf::Gltf, name: &str) -> gltf::Material<'a> {
    let node = doc.nodes().find(|n| n.name() == Some(name)).unwrap();
    node.mesh().unwrap().primitives().next().unwrap().material()
}

/// The extension object `ext` of a material, from the raw JSON.
fn extension(json: &serde_json::Value, material: usize, ext: &str) -> serde_json::Value {
    json["materials"][material]["extensions"][ext].clone()
}

fn json_of(glb: &[u8]) -> serde_json::Value {
    let g = gltf::binary::Glb::from_slice(glb).unwrap();
    serde_json::from_slice(&g.json).unwrap()
}

#[test]
fn figure6_gltf_has_matfit_triangles_camera_materials_and_light() {
    let dir = tempfile::tempdir().unwrap();
    let (scene, bytes, stderr) = export("figure6", dir.path());
    let doc = gltf::Gltf::from_slice(&bytes).expect("valid glTF");
    let blob = doc.blob.as_deref().unwrap();

    // Geometry: every object's triangles, the same positions and order as matfit's.
    let meshes = triangles(&doc, blob);
    assert_eq!(meshes.len(), scene.objects.len());
    let g = &scene.geometry;
    for (obj, (name, tris)) in scene.objects.iter().zip(&meshes) {
        assert_eq!(name, &obj.name);
        assert_eq!(tris.len(), obj.tri_range.len(), "{name}");
        for (t, tri) in tris.iter().zip(&g.tris[obj.tri_range.start as usize..]) {
            assert_eq!(*t, tri.v.map(|i| g.positions[i as usize]), "{name}");
        }
        let a: f64 = tris.iter().map(area).sum();
        assert!(
            (a - obj.area as f64).abs() < 1e-4 * obj.area as f64,
            "{name}"
        );
    }
    // Total area per group.
    for grp in &scene.groups {
        let want: f64 = grp
            .objects
            .iter()
            .map(|&o| scene.objects[o].area as f64)
            .sum();
        let got: f64 = grp
            .objects
            .iter()
            .map(|&o| meshes[o].1.iter().map(area).sum::<f64>())
            .sum();
        assert!((got - want).abs() < 1e-4 * want, "{}", grp.name);
    }

    // One material per group; the back wall's two objects share one.
    assert_eq!(doc.materials().count(), scene.groups.len());
    assert_eq!(
        material_of(&doc, "back_wall").index(),
        material_of(&doc, "front_wall").index()
    );
    let json = json_of(&bytes);
    // Diffuse: base colour ρd, no specular lobe.
    let right = material_of(&doc, "right_wall");
    let pbr = right.pbr_metallic_roughness();
    assert_eq!(pbr.base_color_factor(), [0.69, 0.0, 0.95, 1.0]);
    assert_eq!((pbr.metallic_factor(), pbr.roughness_factor()), (0.0, 1.0));
    assert_eq!(right.name(), Some("right_wall"));
    assert!(right.double_sided());
    let spec = extension(&json, right.index().unwrap(), "KHR_materials_specular");
    assert_eq!(spec["specularFactor"], 0.0);

    // The anisotropic Ward floor: ρd 0.1, ρs 0.9, αx 0.07, αy 0.11, θ 0.
    let floor = material_of(&doc, "floor");
    let fi = floor.index().unwrap();
    let pbr = floor.pbr_metallic_roughness();
    let r = pbr.roughness_factor();
    assert!((r * r - 0.07).abs() < 1e-6, "α_b = r² = min α: {r}");
    // base × (1 − max F0) = ρd
    assert!((pbr.base_color_factor()[0] * (1.0 - 0.9) - 0.1).abs() < 1e-5);
    let spec = extension(&json, fi, "KHR_materials_specular");
    let f0 = spec["specularColorFactor"][0].as_f64().unwrap() * 0.04;
    assert!((f0 - 0.9).abs() < 1e-5, "F0 = ρs: {spec}");
    let aniso = extension(&json, fi, "KHR_materials_anisotropy");
    let s = aniso["anisotropyStrength"].as_f64().unwrap() as f32;
    let at = r * r + s * s * (1.0 - r * r);
    assert!(
        (at - 0.11).abs() < 1e-5,
        "α_t = mix(r², 1, s²) = max α: {at}"
    );
    // αy > αx: glTF's direction is the bitangent, θ + 90°.
    let rot = aniso["anisotropyRotation"].as_f64().unwrap() as f32;
    assert!((rot - std::f32::consts::FRAC_PI_2).abs() < 1e-6);
    // TANGENT = the scene's tangent (+x), w = +1 (bitangent N × T).
    let node = doc.nodes().find(|n| n.name() == Some("floor")).unwrap();
    let prim = node.mesh().unwrap().primitives().next().unwrap();
    let reader = prim.reader(|_| Some(blob));
    let tangents: Vec<[f32; 4]> = reader.read_tangents().expect("TANGENT").collect();
    let normals: Vec<[f32; 3]> = reader.read_normals().unwrap().collect();
    for (t, n) in tangents.iter().zip(&normals) {
        assert_eq!(*t, [1.0, 0.0, 0.0, 1.0]);
        assert!((Vec3::from(*n) - Vec3::Y).length() < 1e-6);
    }
    assert!(
        stderr.contains("material 'floor': Ward (ward1992)"),
        "{stderr}"
    );

    // The light: emissive radiance 30 = factor × strength, single-sided, with its warning.
    let light = material_of(&doc, "light");
    let e = extension(
        &json,
        light.index().unwrap(),
        "KHR_materials_emissive_strength",
    );
    let strength = e["emissiveStrength"].as_f64().unwrap() as f32;
    let radiance = Vec3::from(light.emissive_factor()) * strength;
    assert!((radiance - Vec3::splat(30.0)).length() < 1e-4, "{radiance}");
    assert!(!light.double_sided());
    assert!(stderr.contains("glTF has no area lights"), "{stderr}");
    let used: Vec<&str> = doc.extensions_used().collect();
    for ext in [
        "KHR_materials_anisotropy",
        "KHR_materials_emissive_strength",
        "KHR_materials_specular",
    ] {
        assert!(used.contains(&ext), "{used:?}");
    }

    // The camera: the ray through pixel corners and a centre is matfit's.
    let cam_node = doc.nodes().find(|n| n.camera().is_some()).unwrap();
    let camera = cam_node.camera().unwrap();
    let gltf::camera::Projection::Perspective(p) = camera.projection() else {
        panic!("a perspective camera");
    };
    let (t, q, s) = cam_node.transform().decomposed();
    assert_eq!(s, [1.0; 3]);
    let (eye, q) = (Vec3::from(t), Quat::from_array(q));
    let c = &scene.camera;
    assert!((eye - c.eye()).length() < 1e-6);
    let aspect = p.aspect_ratio().unwrap();
    assert!((aspect - 512.0 / 384.0).abs() < 1e-6);
    let tan = (0.5 * p.yfov()).tan();
    for (x, y) in [
        (0.0, 0.0),
        (512.0, 0.0),
        (0.0, 384.0),
        (512.0, 384.0),
        (256.5, 100.5),
    ] {
        let (u, v) = (2.0 * x / 512.0 - 1.0, 1.0 - 2.0 * y / 384.0);
        let d = (q * Vec3::new(u * aspect * tan, v * tan, -1.0)).normalize();
        let want = c.ray(Vec2::new(x, y)).d;
        assert!(
            (d - want).length() < 1e-5,
            "pixel ({x}, {y}): {d} vs {want}"
        );
    }
    // The clipping planes cut nothing of the scene.
    let zfar = p.zfar().unwrap();
    let b = scene.geometry.bvh.bounds();
    assert!(zfar > (b.max - b.min).length() && p.znear() > 0.0 && p.znear() < 0.2);
}

#[test]
fn poster_gltf_embeds_the_textures_in_srgb() {
    let dir = tempfile::tempdir().unwrap();
    let (scene, bytes, _) = export("poster", dir.path());
    let doc = gltf::Gltf::from_slice(&bytes).expect("valid glTF");
    let blob = doc.blob.as_deref().unwrap();
    let json = json_of(&bytes);
    // One material per distinct texture: the six books differ, so the group has six.
    let textured: Vec<_> = scene
        .objects
        .iter()
        .filter(|o| matches!(o.material, Material::Textured { .. }))
        .collect();
    assert_eq!(textured.len(), 8);
    assert_eq!(doc.textures().count(), 8);
    assert_eq!(doc.images().count(), 8);
    assert_eq!(material_of(&doc, "book3").name(), Some("books/book3"));
    for obj in textured {
        let Material::Textured {
            texture,
            scale,
            varnish,
        } = &obj.material
        else {
            unreachable!()
        };
        let m = material_of(&doc, &obj.name);
        let info = m
            .pbr_metallic_roughness()
            .base_color_texture()
            .unwrap_or_else(|| panic!("{}: a base colour texture", obj.name));
        assert_eq!(info.tex_coord(), 0);
        let gltf::image::Source::View { view, mime_type } = info.texture().source().source() else {
            panic!("embedded");
        };
        assert_eq!(mime_type, "image/png");
        let png = &blob[view.offset()..view.offset() + view.length()];
        let img = image::load_from_memory(png).unwrap().to_rgb8();
        assert_eq!(
            (img.width() as usize, img.height() as usize),
            (texture.width, texture.height),
            "{}",
            obj.name
        );
        // The texels decode (sRGB) to scale × texture / (1 − max ρs of the varnish).
        let keep = 1.0 - varnish.map_or(0.0, |v| v.rho_s.max_element());
        let decode = |c: u8| matfit::io::image::srgb_decode(c as f32 / 255.0);
        let n = img.pixels().len() as f64;
        let mean: Vec<f64> = (0..3)
            .map(|k| img.pixels().map(|p| decode(p.0[k]) as f64).sum::<f64>() / n)
            .collect();
        let want = (0..3).map(|k| {
            texture.texels.iter().map(|t| t[k] as f64).sum::<f64>() / n * (scale[k] / keep) as f64
        });
        for (k, w) in want.enumerate() {
            assert!(
                (mean[k] - w).abs() < 2e-3,
                "{} channel {k}: {} vs {w}",
                obj.name,
                mean[k]
            );
        }
        // Mesh UVs with v flipped (glTF's v runs down the image).
        let node = doc
            .nodes()
            .find(|n| n.name() == Some(obj.name.as_str()))
            .unwrap();
        let prim = node.mesh().unwrap().primitives().next().unwrap();
        let uvs: Vec<[f32; 2]> = prim
            .reader(|_| Some(blob))
            .read_tex_coords(0)
            .unwrap()
            .into_f32()
            .collect();
        let g = &scene.geometry;
        let idx: Vec<u32> = prim
            .reader(|_| Some(blob))
            .read_indices()
            .unwrap()
            .into_u32()
            .collect();
        for (t, tri) in idx.chunks(3).zip(&g.tris[obj.tri_range.start as usize..]) {
            for k in 0..3 {
                let want = g.uvs[tri.v[k] as usize];
                assert_eq!(uvs[t[k] as usize], [want.x, 1.0 - want.y]);
            }
        }
    }
    // The desk's varnish: ρs 0.1, α 0.08, isotropic.
    let desk = material_of(&doc, "desk");
    let r = desk.pbr_metallic_roughness().roughness_factor();
    assert!((r * r - 0.08).abs() < 1e-6);
    assert!(json["materials"][desk.index().unwrap()]["extensions"]
        .get("KHR_materials_anisotropy")
        .is_none());
}

#[test]
fn facing_mirrors_gltf_are_metallic_mirrors() {
    let dir = tempfile::tempdir().unwrap();
    let (scene, bytes, stderr) = export("facing-mirrors", dir.path());
    let doc = gltf::Gltf::from_slice(&bytes).expect("valid glTF");
    for (name, rho_s) in [("mirror_left", 0.85), ("mirror_right", 0.7)] {
        let pbr = material_of(&doc, name).pbr_metallic_roughness();
        assert_eq!(pbr.base_color_factor(), [rho_s, rho_s, rho_s, 1.0]);
        assert_eq!((pbr.metallic_factor(), pbr.roughness_factor()), (1.0, 0.0));
        assert!(
            stderr.contains(&format!("material '{name}': mirror: glTF's specular")),
            "{stderr}"
        );
    }
    let tris: usize = triangles(&doc, doc.blob.as_deref().unwrap())
        .iter()
        .map(|(_, t)| t.len())
        .sum();
    assert_eq!(tris, scene.triangle_count());
}

#[test]
fn gltf_output_must_be_a_glb_file() {
    let dir = tempfile::tempdir().unwrap();
    let scene = root().join("scenes/figure6/scene.toml");
    let (code, _, stderr) = run(
        &["export", "gltf", scene.to_str().unwrap(), "-o", "out.gltf"],
        dir.path(),
    );
    assert_ne!(code, 0);
    assert!(stderr.contains("must end in .glb"), "{stderr}");
    let (code, _, stderr) = run(
        &[
            "export",
            "gltf",
            scene.to_str().unwrap(),
            "-o",
            "missing/out.glb",
        ],
        dir.path(),
    );
    assert_ne!(code, 0);
    assert!(stderr.contains("does not exist"), "{stderr}");
}

/// A calibrated camera with an off-centre principal point cannot be exact: said so; a centred
/// one with a roll gives matfit's rays.
#[test]
fn calibrated_cameras_map_to_gltf_nodes() {
    let dir = tempfile::tempdir().unwrap();
    let text = std::fs::read_to_string(root().join("scenes/figure6/scene.toml")).unwrap();
    let start = text.find("[camera]").unwrap();
    let end = start + text[start..].find("[[object]]").unwrap();
    let r = Mat3::from_rotation_z(0.3) * Mat3::from_rotation_x(0.35);
    let rows = |m: Mat3| {
        (0..3)
            .map(|i| format!("{:?}", m.row(i).to_array()))
            .collect::<Vec<_>>()
            .join(", ")
    };
    let eye = Vec3::new(0.2, 1.5, -0.5);
    // R here maps world to the OpenCV camera (x right, y down, z forward); the camera looks
    // down −z in world space, so R includes a flip of y and z.
    let r = Mat3::from_diagonal(Vec3::new(1.0, -1.0, -1.0)) * r;
    let t = -(r * eye);
    for (cx, warn) in [(255.5, false), (240.0, true)] {
        let camera = format!(
            "[camera]\nwidth = 512\nheight = 384\nfx = 500.0\nfy = 500.0\ncx = {cx}\ncy = 191.5\n\
             rotation = [{}]\ntranslation = {:?}\n\n",
            rows(r),
            t.to_array()
        );
        let file = dir.path().join("cal.toml");
        std::fs::write(&file, format!("{}{camera}{}", &text[..start], &text[end..])).unwrap();
        let out = dir.path().join("cal.glb");
        let (code, stdout, stderr) = run(
            &[
                "export",
                "gltf",
                file.to_str().unwrap(),
                "-o",
                out.to_str().unwrap(),
            ],
            dir.path(),
        );
        assert_eq!(code, 0, "{stdout}\n{stderr}");
        assert_eq!(stderr.contains("principal point"), warn, "{stderr}");
        let scene = load_scene(&file).unwrap();
        let doc = gltf::Gltf::from_slice(&std::fs::read(&out).unwrap()).unwrap();
        let node = doc.nodes().find(|n| n.camera().is_some()).unwrap();
        let camera = node.camera().unwrap();
        let gltf::camera::Projection::Perspective(p) = camera.projection() else {
            panic!()
        };
        let (_, q, _) = node.transform().decomposed();
        let q = Quat::from_array(q);
        let tan = (0.5 * p.yfov()).tan();
        let a = p.aspect_ratio().unwrap();
        for (x, y) in [(0.0, 0.0), (512.0, 384.0), (100.0, 300.0)] {
            let (u, v) = (2.0 * x / 512.0 - 1.0, 1.0 - 2.0 * y / 384.0);
            let d = (q * Vec3::new(u * a * tan, v * tan, -1.0)).normalize();
            let want = scene.camera.ray(Vec2::new(x, y)).d;
            // Off-centre: 16 px at 500 px focal length is ~0.03 rad off; centred: exact.
            let err = (d - want).length();
            assert_eq!(err > 1e-3, warn, "({x}, {y}): {d} vs {want}");
            if !warn {
                assert!(err < 1e-5);
            }
        }
    }
}

#[test]
fn sunroom_lights_are_khr_lights_punctual_aimed_along_their_nodes_minus_z() {
    let dir = tempfile::tempdir().unwrap();
    let (scene, bytes, stderr) = export("sunroom", dir.path());
    assert!(stderr.contains("KHR_lights_punctual"), "{stderr}");
    let json = json_of(&bytes);
    assert!(json["extensionsUsed"]
        .as_array()
        .unwrap()
        .contains(&serde_json::json!("KHR_lights_punctual")));
    let lights = json["extensions"]["KHR_lights_punctual"]["lights"]
        .as_array()
        .unwrap();
    assert_eq!(lights.len(), scene.punctual_lights.len());
    for l in &scene.punctual_lights {
        let node = json["nodes"]
            .as_array()
            .unwrap()
            .iter()
            .find(|n| n["name"] == l.name.as_str())
            .unwrap();
        let k = node["extensions"]["KHR_lights_punctual"]["light"]
            .as_u64()
            .unwrap() as usize;
        let f = |v: &serde_json::Value| v.as_f64().unwrap() as f32;
        let q = node["rotation"].as_array().unwrap();
        let aim = Quat::from_xyzw(f(&q[0]), f(&q[1]), f(&q[2]), f(&q[3])) * Vec3::NEG_Z;
        let (kind, direction, power) = match l.kind {
            matfit::scene::Punctual::Directional {
                direction,
                irradiance,
                ..
            } => ("directional", direction, irradiance),
            matfit::scene::Punctual::Spot {
                direction,
                intensity,
                position,
                cutoff,
                ..
            } => {
                let t = node["translation"].as_array().unwrap();
                let t = Vec3::new(f(&t[0]), f(&t[1]), f(&t[2]));
                assert!((t - position).length() < 1e-6);
                assert!((f(&lights[k]["spot"]["outerConeAngle"]) - cutoff).abs() < 1e-6);
                ("spot", direction, intensity)
            }
            matfit::scene::Punctual::Point { .. } => unreachable!("sunroom has no point light"),
        };
        assert_eq!(lights[k]["type"], kind);
        assert!((aim - direction).length() < 1e-5, "{aim} vs {direction}");
        // color × intensity = 683 lm/W × the light's RGB.
        let c = lights[k]["color"].as_array().unwrap();
        for ch in 0..3 {
            let lm = f(&c[ch]) * f(&lights[k]["intensity"]);
            assert!((lm / 683.0 - power[ch]).abs() < 1e-4, "{lm} vs {power}");
        }
    }
}
