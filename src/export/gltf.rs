//! Export to glTF 2.0: one binary `.glb` (JSON chunk + binary chunk, textures embedded as PNG),
//! for taking a recovered scene into Blender, three.js or any glTF viewer.
//!
//! **Geometry.** One mesh (one triangle primitive) and one node with no transform per object:
//! world-space positions *exactly as matfit loaded them* (as the Mitsuba exporter's PLYs),
//! matfit's vertex order (so the same front sides), its unit shading normals, TEXCOORD_0 where
//! the object has UVs or an atlas texture, TANGENT where the material is anisotropic. glTF's v
//! runs down the image, matfit's up: v_gltf = 1 − v.
//!
//! **Camera.** A perspective camera node (or an orthographic one, exact:
//! `orthographic_camera_json`). glTF cameras look down −Z with +Y up and +X right;
//! matfit's rows of R are right, down, forward (OpenCV), so the node's rotation (camera to world)
//! has columns (right, −down, −forward) = Rᵀ·diag(1, −1, −1), a proper rotation, and its
//! translation is the eye. yfov = 2·atan(height / 2fy), aspectRatio = width / height. zfar is
//! twice the distance to the farthest corner of the scene's bounds, znear half the distance to
//! the nearest triangle: nothing is clipped and depth buffers keep their precision. glTF has
//! square pixels and a centred principal point: fx ≠ fy (fy wins) and an off-centre principal
//! point (calibrated cameras) are warnings.
//!
//! **Materials**, one per group (one per distinct material where a group's objects differ, e.g.
//! one texture per book), all `doubleSided` (matfit's surfaces reflect on both sides). glTF's
//! metallic-roughness model is a GGX lobe with Schlick Fresnel over a Lambert base (glTF 2.0
//! Appendix B); `KHR_materials_specular` (specularFactor 0 removes the lobe, specularColorFactor
//! scales F0 = 0.04·specularColorFactor, clamped to 1) and the base's weight 1 − max F0 at
//! normal incidence (`fresnel_mix`) give:
//! - diffuse ρd → baseColor ρd, metallic 0, roughness 1, specularFactor 0: exactly Lambert.
//!   Black the same with ρd = 0.
//! - mirror ρs → metallic 1, roughness 0, baseColor ρs: exact at normal incidence; glTF's
//!   Fresnel rises to 1 at grazing incidence (a warning when ρs < 1).
//! - diffuse + mirror → metallic 0, roughness 0, specularColorFactor ρs/0.04 (F0 = ρs) and
//!   baseColor ρd/(1 − max ρs), so that both albedos are matfit's at normal incidence; the same
//!   Fresnel warning, and a warning when the base colour clips at 1.
//! - Ward (ρd, ρs, αx, αy, θ) → as diffuse + mirror with GGX roughness. Ward's exponent
//!   tan²δ(cos²φ/αx² + sin²φ/αy²) is Beckmann's, and Beckmann's and GGX's distributions of the
//!   same αx, αy have the same peak, 1/(π αx αy), so α_GGX = α_Ward keeps the highlight's peak;
//!   GGX is narrower at the top (half maximum at tan δ = 0.64α, Beckmann's at 0.83α) and has
//!   longer tails. glTF's roughness r has α = r². Isotropic: r = √α. Anisotropic:
//!   `KHR_materials_anisotropy`, whose
//!   roughness along its direction is α_t = mix(r², 1, strength²) and across it α_b = r²
//!   (extension spec, "Anisotropy"); so r = √min(αx, αy),
//!   strength = √((max − min)/(1 − min)), and the direction, counter-clockwise from TANGENT
//!   towards the bitangent N × T (TANGENT.w = +1), is matfit's θ (which rotates the tangent
//!   towards n × tangent, `Frame::rotated`), plus π/2 when αy > αx. TANGENT is the object's
//!   tangent, else the mean dp/du of the vertex's triangles, made orthogonal to the normal, as
//!   the renderer's shading frame. A warning for every Ward material: GGX is not Ward (tails,
//!   Fresnel, the variant's normalisation); α > 1 is clamped.
//! - textured (ρd(u, v) = scale·texture, optional Ward varnish) → baseColorTexture, an 8-bit
//!   sRGB PNG (glTF base colour textures are sRGB-encoded; matfit's texels are linear
//!   reflectance) of scale·texture/(1 − max ρs), and the varnish as a Ward lobe above. Clipping
//!   at 1 is a warning. Mesh-UV textures repeat (sampler REPEAT, as matfit's lookup); atlas
//!   textures (`scene/atlas.rs`) get UVs = atlas position / atlas size, per chart (vertices on
//!   chart seams are duplicated), CLAMP_TO_EDGE, and a one-texel border around every chart copied
//!   from its edge, so that bilinear filtering reads what matfit's clamped lookup reads.
//!
//! **Lights.** `[[light]]`s (directional, point, spot) are KHR_lights_punctual lights.
//! glTF has no area lights (KHR_lights_punctual has points, spots and directional
//! lights only, which would change the light's size and so the shadows and highlights). An
//! emitter keeps its mesh: emissiveFactor = L/max L and `KHR_materials_emissive_strength` = max L,
//! so their product is matfit's radiance L. Emission is one-sided in matfit (the wound normal's
//! side): emitters' materials are single-sided, so the back does not glow where renderers honour
//! it. A warning: only renderers that light a scene by emissive surfaces (path tracers such as
//! Cycles) carry the light; rasterisers show the lamp but not its light.
//!
//! **File.** The JSON is built with serde_json and checked by the gltf crate's validation
//! (`gltf::Gltf::from_slice`) before it is written: gltf-json 1.4's typed structs have no
//! KHR_materials_anisotropy, and the other two extensions would need feature flags on the `gltf`
//! dependency the mesh loader uses. The container is `gltf::binary::Glb` (it pads the chunks).

use super::ExportReport;
use crate::math::{Frame, Mat3, Rgb, Vec2, Vec3};
use crate::scene::texture::{Mapping, Texture};
use crate::scene::{Material, Punctual, PunctualLight, Scene, WardVariant};
use serde_json::{json, Map, Value};
use std::collections::HashMap;
use std::f32::consts::FRAC_PI_2;
use std::path::Path;
use std::sync::Arc;

/// F0 of glTF's dielectric (ior 1.5): ((1.5 − 1)/(1.5 + 1))².
const DIELECTRIC_F0: f32 = 0.04;

/// Writes `path` (a `.glb`) for `scene`.
pub fn export(scene: &Scene, path: &Path) -> Result<ExportReport, String> {
    let (bytes, warnings) = glb(scene)?;
    crate::io::atomic::write_atomic(path, &bytes)
        .map_err(|e| format!("cannot write {}: {e}", path.display()))?;
    Ok(ExportReport {
        files: vec![path.to_path_buf()],
        warnings,
    })
}

/// The `.glb` file of `scene` and the export's warnings.
pub fn glb(scene: &Scene) -> Result<(Vec<u8>, Vec<String>), String> {
    let mut warnings = Vec::new();
    let mut bin = Bin::default();
    let mut ext_used: Vec<String> = Vec::new();
    let mut materials: Vec<Value> = Vec::new();
    let mut material_group: Vec<usize> = Vec::new();
    let mut images: Vec<Value> = Vec::new();
    let mut image_of: HashMap<(usize, [u32; 3]), usize> = HashMap::new();
    let mut samplers: Vec<Value> = Vec::new();
    let mut textures: Vec<Value> = Vec::new();
    let mut meshes = Vec::new();
    let mut nodes = Vec::new();

    for (oi, obj) in scene.objects.iter().enumerate() {
        let group = &scene.groups[obj.group];
        let mut w = Vec::new();
        let spec = material_spec(&obj.material, scene.render.ward_variant, &mut w);
        // The base colour texture, once per texture and baked factor.
        let texture = match (&obj.material, spec.texture_factor) {
            (
                Material::Textured { texture, .. } | Material::TexturedPlastic { texture, .. },
                Some(factor),
            ) => {
                let key = (
                    Arc::as_ptr(texture) as usize,
                    factor.to_array().map(f32::to_bits),
                );
                let ti = match image_of.get(&key) {
                    Some(&ti) => ti,
                    None => {
                        let (png, clipped) = texture_png(texture, factor)?;
                        if clipped > 0 {
                            w.push(format!(
                                "{clipped} texels of the texture {} exceed reflectance 1 once \
                                 scaled for glTF's base colour (×{:?}): clipped to 1",
                                texture.path.display(),
                                factor.to_array()
                            ));
                        }
                        let view = bin.view(&png, None);
                        images.push(json!({"bufferView": view, "mimeType": "image/png"}));
                        let atlas = matches!(texture.mapping, Mapping::Atlas(_));
                        // 33071 CLAMP_TO_EDGE, 10497 REPEAT; 9729 LINEAR (matfit's bilinear
                        // lookup, no mipmaps: they would mix an atlas's charts).
                        let wrap = if atlas { 33071 } else { 10497 };
                        samplers.push(json!({"magFilter": 9729, "minFilter": 9729,
                                             "wrapS": wrap, "wrapT": wrap}));
                        textures.push(json!({"source": images.len() - 1,
                                             "sampler": samplers.len() - 1}));
                        image_of.insert(key, textures.len() - 1);
                        textures.len() - 1
                    }
                };
                Some(ti)
            }
            _ => None,
        };
        let mat = material_json(&spec, texture, obj.emission, &mut ext_used);
        // One material per group, unless its objects differ.
        let mi = match (0..materials.len())
            .find(|&m| material_group[m] == obj.group && strip_name(&materials[m]) == mat)
        {
            Some(m) => m,
            None => {
                let distinct = group
                    .objects
                    .iter()
                    .any(|&o| !same_material(&scene.objects[o], obj));
                let name = if distinct {
                    format!("{}/{}", group.name, obj.name)
                } else {
                    group.name.clone()
                };
                for m in w {
                    warnings.push(format!("material '{name}': {m}"));
                }
                if obj.is_emitter() {
                    warnings.push(format!(
                        "material '{name}': glTF has no area lights; object '{}' emits as an \
                         emissive surface (radiance {:?}), which path tracers light the scene \
                         with and rasterisers do not",
                        obj.name,
                        obj.emission.to_array()
                    ));
                }
                let mut m = mat;
                m["name"] = json!(name);
                materials.push(m);
                material_group.push(obj.group);
                materials.len() - 1
            }
        };

        let mesh = object_mesh(scene, oi, spec.anisotropic);
        let mut attributes = Map::new();
        attributes.insert(
            "POSITION".into(),
            bin.floats(flat3(&mesh.positions), 3, true).into(),
        );
        attributes.insert(
            "NORMAL".into(),
            bin.floats(flat3(&mesh.normals), 3, false).into(),
        );
        if let Some(uvs) = &mesh.uvs {
            let f: Vec<f32> = uvs.iter().flat_map(|u| [u.x, u.y]).collect();
            attributes.insert("TEXCOORD_0".into(), bin.floats(f, 2, false).into());
        }
        if let Some(t) = &mesh.tangents {
            let f: Vec<f32> = t.iter().flat_map(|t| [t.x, t.y, t.z, 1.0]).collect();
            attributes.insert("TANGENT".into(), bin.floats(f, 4, false).into());
        }
        let indices = bin.indices(&mesh.indices);
        meshes.push(json!({
            "name": obj.name,
            "primitives": [{"attributes": attributes, "indices": indices,
                            "material": mi, "mode": 4}],
        }));
        nodes.push(json!({"name": obj.name, "mesh": meshes.len() - 1}));
    }

    let (camera, camera_node) = camera_json(scene, &mut warnings);
    nodes.push(camera_node);
    let mut lights = Vec::new();
    for l in &scene.punctual_lights {
        let (light, node) = punctual_json(l, lights.len());
        lights.push(light);
        nodes.push(node);
    }
    if scene.environment.is_some() {
        warnings.push(
            "the [environment] light is not written: core glTF has no environment light (give \
             the viewer the same HDR map as its sky)"
                .into(),
        );
    }
    if scene.stray_light.max_element() > 0.0 {
        let [r, g, b] = scene.stray_light.to_array();
        warnings.push(format!(
            "the [stray_light] ({r}, {g}, {b}) is not written: core glTF has no constant \
             environment (give the viewer a uniform sky of that radiance)"
        ));
    }
    if !lights.is_empty() {
        ext_used.push("KHR_lights_punctual".into());
        warnings.push(format!(
            "{} light(s) written as KHR_lights_punctual with intensity = 683 lm/W × the largest \
             channel (glTF's units are photometric) and color = RGB / that channel; spot lights' \
             falloff between inner and outer cone is each viewer's own",
            lights.len()
        ));
    }

    let mut root = json!({
        "asset": {
            "version": "2.0",
            "generator": format!("matfit {}", env!("CARGO_PKG_VERSION")),
        },
        "scene": 0,
        "scenes": [{"name": scene_name(&scene.path),
                    "nodes": (0..nodes.len()).collect::<Vec<_>>()}],
        "nodes": nodes,
        "cameras": [camera],
        "meshes": meshes,
        "materials": materials,
        "accessors": bin.accessors,
        "bufferViews": bin.views,
        "buffers": [{"byteLength": bin.bytes.len()}],
    });
    if !lights.is_empty() {
        root["extensions"] = json!({"KHR_lights_punctual": {"lights": lights}});
    }
    if !textures.is_empty() {
        root["images"] = json!(images);
        root["samplers"] = json!(samplers);
        root["textures"] = json!(textures);
    }
    if !ext_used.is_empty() {
        ext_used.sort();
        ext_used.dedup();
        root["extensionsUsed"] = json!(ext_used);
    }
    tidy(&mut root);
    let json = serde_json::to_vec(&root).map_err(|e| e.to_string())?;
    let length = 12 + 8 + json.len().next_multiple_of(4) + 8 + bin.bytes.len().next_multiple_of(4);
    let glb = gltf::binary::Glb {
        header: gltf::binary::Header {
            magic: *b"glTF",
            version: 2,
            length: u32::try_from(length).map_err(|_| "the scene exceeds glTF's 4 GiB")?,
        },
        json: json.into(),
        bin: Some(bin.bytes.into()),
    };
    let bytes = glb.to_vec().map_err(|e| e.to_string())?;
    // The gltf crate's validation (indices, accessor bounds, the chunks) before anyone sees it.
    gltf::Gltf::from_slice(&bytes).map_err(|e| format!("internal error: invalid glTF: {e}"))?;
    Ok((bytes, warnings))
}

/// Writes every float as the shortest decimal that reads back as the same f32 (0.65, not
/// 0.6499999761581421): all of them come from f32, and people read these files.
fn tidy(v: &mut Value) {
    match v {
        Value::Number(n) if n.is_f64() => {
            let x = n.as_f64().unwrap_or(0.0) as f32;
            if let Some(m) = x
                .to_string()
                .parse::<f64>()
                .ok()
                .and_then(serde_json::Number::from_f64)
            {
                *n = m;
            }
        }
        Value::Array(a) => a.iter_mut().for_each(tidy),
        Value::Object(o) => o.values_mut().for_each(tidy),
        _ => {}
    }
}

/// The scene file's folder and name ("figure6/scene.toml"): enough to recognise it, without the
/// exporting machine's full path.
fn scene_name(path: &Path) -> String {
    let parts: Vec<_> = path.components().rev().take(2).collect();
    parts
        .iter()
        .rev()
        .map(|c| c.as_os_str().to_string_lossy())
        .collect::<Vec<_>>()
        .join("/")
}

/// The binary chunk: buffer views and accessors into one buffer.
#[derive(Default)]
struct Bin {
    bytes: Vec<u8>,
    views: Vec<Value>,
    accessors: Vec<Value>,
}

impl Bin {
    /// A buffer view of `data` (4-byte aligned, as vertex attributes need); `target` 34962 for
    /// vertex attributes, 34963 for indices, none for images.
    fn view(&mut self, data: &[u8], target: Option<u32>) -> usize {
        self.bytes.resize(self.bytes.len().next_multiple_of(4), 0);
        let mut v = json!({"buffer": 0, "byteOffset": self.bytes.len(), "byteLength": data.len()});
        if let Some(t) = target {
            v["target"] = json!(t);
        }
        self.bytes.extend_from_slice(data);
        self.views.push(v);
        self.views.len() - 1
    }

    /// A float accessor of `n`-vectors (min/max given for positions, where glTF requires them).
    fn floats(&mut self, data: Vec<f32>, n: usize, bounds: bool) -> usize {
        let bytes: Vec<u8> = data.iter().flat_map(|x| x.to_le_bytes()).collect();
        let view = self.view(&bytes, Some(34962));
        let count = data.len() / n;
        let kind = ["", "SCALAR", "VEC2", "VEC3", "VEC4"][n];
        let mut a = json!({"bufferView": view, "componentType": 5126, "count": count,
                           "type": kind});
        if bounds {
            let mut lo = vec![f32::MAX; n];
            let mut hi = vec![f32::MIN; n];
            for v in data.chunks(n) {
                for k in 0..n {
                    lo[k] = lo[k].min(v[k]);
                    hi[k] = hi[k].max(v[k]);
                }
            }
            a["min"] = json!(lo);
            a["max"] = json!(hi);
        }
        self.accessors.push(a);
        self.accessors.len() - 1
    }

    fn indices(&mut self, idx: &[[u32; 3]]) -> usize {
        let bytes: Vec<u8> = idx.iter().flatten().flat_map(|i| i.to_le_bytes()).collect();
        let view = self.view(&bytes, Some(34963));
        self.accessors
            .push(json!({"bufferView": view, "componentType": 5125,
                                   "count": idx.len() * 3, "type": "SCALAR"}));
        self.accessors.len() - 1
    }
}

fn flat3(v: &[Vec3]) -> Vec<f32> {
    v.iter().flat_map(|p| p.to_array()).collect()
}

/// glTF's parameters for one matfit material (before textures and emission are attached).
#[derive(Clone, Debug, PartialEq)]
pub struct Spec {
    pub base_color: Rgb,
    /// Multiplies a textured material's texels (scale and the base's Fresnel compensation).
    pub texture_factor: Option<Rgb>,
    pub metallic: f32,
    pub roughness: f32,
    /// KHR_materials_specular: (specularFactor, specularColorFactor); None: glTF's default.
    pub specular: Option<(f32, Rgb)>,
    /// KHR_materials_anisotropy: (anisotropyStrength, anisotropyRotation).
    pub anisotropy: Option<(f32, f32)>,
    /// Whether the mesh needs TANGENT.
    pub anisotropic: bool,
}

/// The mapping of the module comment. `warnings` gets one message per approximation.
pub fn material_spec(m: &Material, variant: WardVariant, warnings: &mut Vec<String>) -> Spec {
    let lambert = |rho_d: Rgb| Spec {
        base_color: rho_d,
        texture_factor: None,
        metallic: 0.0,
        roughness: 1.0,
        specular: Some((0.0, Rgb::ONE)),
        anisotropy: None,
        anisotropic: false,
    };
    match m {
        Material::Diffuse { rho_d } => lambert(*rho_d),
        Material::Black => lambert(Rgb::ZERO),
        Material::Mirror { rho_s } => {
            if rho_s.min_element() < 1.0 {
                warnings.push(fresnel_warning("mirror", *rho_s));
            }
            Spec {
                base_color: rho_s.min(Rgb::ONE),
                metallic: 1.0,
                roughness: 0.0,
                specular: None,
                ..lambert(Rgb::ZERO)
            }
        }
        Material::DiffuseMirror { rho_d, rho_s } => {
            warnings.push(fresnel_warning("diffuse + mirror", *rho_s));
            layered(*rho_d, *rho_s, 0.0, None, warnings)
        }
        Material::Ward {
            rho_d,
            rho_s,
            alpha_x,
            alpha_y,
            theta,
        } => {
            let (r, aniso) = ward_roughness(*alpha_x, *alpha_y, *theta, warnings);
            warnings.push(ward_warning(variant, *rho_s, *alpha_x, *alpha_y, r, aniso));
            layered(*rho_d, *rho_s, r, aniso, warnings)
        }
        Material::Microfacet {
            rho_d,
            rho_s,
            alpha_x,
            alpha_y,
            theta,
            distribution,
        } => {
            // glTF's lobe is GGX itself: only its Fresnel differs (a perfect conductor's F = 1).
            let (r, aniso) = ward_roughness(*alpha_x, *alpha_y, *theta, warnings);
            warnings.push(fresnel_warning("microfacet", *rho_s));
            if *distribution != crate::scene::Distribution::Ggx {
                warnings.push(format!(
                    "a {} microfacet lobe is exported as glTF's GGX of the same α (a narrower \
                     core and a wider halo)",
                    distribution.name()
                ));
            }
            layered(*rho_d, *rho_s, r, aniso, warnings)
        }
        Material::Plastic {
            rho_d,
            rho_s,
            alpha,
            distribution,
            ..
        } => {
            let (r, aniso) = coat_roughness(*alpha, *distribution, warnings);
            layered(*rho_d, *rho_s, r, aniso, warnings)
        }
        Material::Textured { scale, varnish, .. } => match varnish {
            None => Spec {
                texture_factor: Some(*scale),
                ..lambert(Rgb::ONE)
            },
            Some(v) => {
                let (r, aniso) = ward_roughness(v.alpha_x, v.alpha_y, v.theta, warnings);
                warnings.push(ward_warning(
                    variant, v.rho_s, v.alpha_x, v.alpha_y, r, aniso,
                ));
                // The base's compensation goes into the texels with the scale (clipping there
                // is counted per texel).
                let mut s = layered(Rgb::ZERO, v.rho_s, r, aniso, warnings);
                s.texture_factor = Some(*scale * base_compensation(v.rho_s, warnings));
                s.base_color = Rgb::ONE;
                s
            }
        },
        Material::TexturedPlastic {
            scale,
            rho_s,
            alpha,
            distribution,
            ..
        } => {
            // As a plastic, with the base's compensation in the texels as for a varnish.
            let (r, aniso) = coat_roughness(*alpha, *distribution, warnings);
            let mut s = layered(Rgb::ZERO, *rho_s, r, aniso, warnings);
            s.texture_factor = Some(*scale * base_compensation(*rho_s, warnings));
            s.base_color = Rgb::ONE;
            s
        }
    }
}

/// 1 / (1 − max ρs): what undoes glTF's weight of the base under a lobe of F0 = ρs (at normal
/// incidence). 1 when ρs leaves the base no weight at all (a warning: the diffuse term is lost).
fn base_compensation(rho_s: Rgb, warnings: &mut Vec<String>) -> f32 {
    let keep = 1.0 - rho_s.max_element().min(1.0);
    if keep < 1e-3 {
        warnings.push(format!(
            "ρs {:?} leaves glTF's base no weight: the diffuse term is lost",
            rho_s.to_array()
        ));
        return 1.0;
    }
    1.0 / keep
}

/// A plastic's coat as glTF's dielectric lobe, a GGX coat with Schlick's Fresnel from F0 = ρs:
/// its roughness, and a warning when the coat's distribution is not GGX.
fn coat_roughness(
    alpha: f32,
    distribution: crate::scene::Distribution,
    warnings: &mut Vec<String>,
) -> (f32, Option<(f32, f32)>) {
    let roughness = ward_roughness(alpha, alpha, 0.0, warnings);
    if distribution != crate::scene::Distribution::Ggx {
        warnings.push(format!(
            "a {} plastic coat is exported as glTF's GGX coat of the same α (a narrower core and \
             a wider halo)",
            distribution.name()
        ));
    }
    roughness
}

/// Lambert ρd under a GGX lobe of F0 = ρs, the base compensated for glTF's 1 − max F0.
fn layered(
    rho_d: Rgb,
    rho_s: Rgb,
    roughness: f32,
    anisotropy: Option<(f32, f32)>,
    warnings: &mut Vec<String>,
) -> Spec {
    if rho_s.max_element() > 1.0 {
        warnings.push(format!(
            "ρs {:?} exceeds glTF's largest F0, 1: clamped",
            rho_s.to_array()
        ));
    }
    let base = if rho_d.max_element() > 0.0 {
        rho_d * base_compensation(rho_s, warnings)
    } else {
        Rgb::ZERO
    };
    if base.max_element() > 1.0 + 1e-6 {
        warnings.push(format!(
            "the base colour ρd/(1 − max ρs) = {:?} clips at 1 (glTF weights the base by \
             1 − max F0)",
            base.to_array()
        ));
    }
    Spec {
        base_color: base.min(Rgb::ONE),
        texture_factor: None,
        metallic: 0.0,
        roughness,
        specular: Some((1.0, rho_s.min(Rgb::ONE) / DIELECTRIC_F0)),
        anisotropy,
        anisotropic: anisotropy.is_some(),
    }
}

/// glTF roughness and (strength, rotation) of KHR_materials_anisotropy for Ward's αx, αy, θ.
pub fn ward_roughness(
    alpha_x: f32,
    alpha_y: f32,
    theta: f32,
    warnings: &mut Vec<String>,
) -> (f32, Option<(f32, f32)>) {
    if alpha_x.max(alpha_y) > 1.0 {
        warnings.push(format!(
            "Ward α ({alpha_x}, {alpha_y}) beyond glTF's largest, 1: clamped"
        ));
    }
    let (lo, hi) = (
        alpha_x.min(alpha_y).clamp(0.0, 1.0),
        alpha_x.max(alpha_y).clamp(0.0, 1.0),
    );
    let r = lo.sqrt();
    if hi - lo <= 1e-4 * hi || lo >= 1.0 {
        return (r, None);
    }
    let strength = ((hi - lo) / (1.0 - lo)).sqrt();
    let rotation = if alpha_y > alpha_x {
        theta + FRAC_PI_2
    } else {
        theta
    };
    (r, Some((strength, rotation)))
}

fn fresnel_warning(what: &str, rho_s: Rgb) -> String {
    format!(
        "{what}: glTF's specular reflectance is ρs {:?} at normal incidence and rises to 1 at \
         grazing incidence (Schlick's Fresnel); matfit's is ρs at every angle",
        rho_s.to_array()
    )
}

fn ward_warning(
    variant: WardVariant,
    rho_s: Rgb,
    alpha_x: f32,
    alpha_y: f32,
    r: f32,
    aniso: Option<(f32, f32)>,
) -> String {
    format!(
        "Ward ({}) ρs {:?}, αx {alpha_x}, αy {alpha_y} approximated by glTF's GGX lobe: \
         roughness {r:.4} (α = r², the same peak){}, F0 = ρs rising to 1 at grazing incidence; \
         GGX's highlight is narrower at the top and has longer tails than Ward's",
        variant.name(),
        rho_s.to_array(),
        match aniso {
            Some((s, rot)) =>
                format!(", KHR_materials_anisotropy strength {s:.4} rotation {rot:.4}"),
            None => String::new(),
        }
    )
}

/// The glTF material object of `spec`, with its base colour texture and emission.
fn material_json(
    spec: &Spec,
    texture: Option<usize>,
    emission: Rgb,
    ext_used: &mut Vec<String>,
) -> Value {
    let c = spec.base_color;
    let mut pbr = json!({
        "baseColorFactor": [c.x, c.y, c.z, 1.0],
        "metallicFactor": spec.metallic,
        "roughnessFactor": spec.roughness,
    });
    if let Some(t) = texture {
        pbr["baseColorTexture"] = json!({"index": t, "texCoord": 0});
    }
    let mut m = json!({"pbrMetallicRoughness": pbr, "doubleSided": true});
    let mut ext = Map::new();
    if let Some((factor, color)) = spec.specular {
        ext.insert(
            "KHR_materials_specular".into(),
            json!({"specularFactor": factor, "specularColorFactor": color.to_array()}),
        );
    }
    if let Some((strength, rotation)) = spec.anisotropy {
        ext.insert(
            "KHR_materials_anisotropy".into(),
            json!({"anisotropyStrength": strength, "anisotropyRotation": rotation}),
        );
    }
    let peak = emission.max_element();
    if peak > 0.0 {
        m["emissiveFactor"] = json!((emission / peak).to_array());
        if peak != 1.0 {
            ext.insert(
                "KHR_materials_emissive_strength".into(),
                json!({"emissiveStrength": peak}),
            );
        }
        m["doubleSided"] = json!(false);
    }
    if !ext.is_empty() {
        ext_used.extend(ext.keys().cloned());
        m["extensions"] = Value::Object(ext);
    }
    m
}

fn strip_name(m: &Value) -> Value {
    let mut m = m.clone();
    if let Some(o) = m.as_object_mut() {
        o.remove("name");
    }
    m
}

/// Whether two objects would get the same glTF material.
fn same_material(a: &crate::scene::Object, b: &crate::scene::Object) -> bool {
    let same = match (&a.material, &b.material) {
        (
            Material::Textured {
                texture: ta,
                scale: sa,
                varnish: va,
            },
            Material::Textured {
                texture: tb,
                scale: sb,
                varnish: vb,
            },
        ) => Arc::ptr_eq(ta, tb) && sa == sb && va == vb,
        (
            Material::TexturedPlastic {
                texture: ta,
                scale: sa,
                rho_s: ra,
                alpha: aa,
                eta: ea,
                distribution: da,
            },
            Material::TexturedPlastic {
                texture: tb,
                scale: sb,
                rho_s: rb,
                alpha: ab,
                eta: eb,
                distribution: db,
            },
        ) => Arc::ptr_eq(ta, tb) && (sa, ra, aa, ea, da) == (sb, rb, ab, eb, db),
        (Material::Textured { .. } | Material::TexturedPlastic { .. }, _)
        | (_, Material::Textured { .. } | Material::TexturedPlastic { .. }) => false,
        (x, y) => format!("{x:?}") == format!("{y:?}"),
    };
    same && a.emission == b.emission
}

/// An object's triangles as glTF wants them: compacted vertices, per-vertex attributes.
pub struct ObjectMesh {
    pub positions: Vec<Vec3>,
    pub normals: Vec<Vec3>,
    pub uvs: Option<Vec<Vec2>>,
    pub tangents: Option<Vec<Vec3>>,
    pub indices: Vec<[u32; 3]>,
}

/// The mesh of object `oi`: its vertices (duplicated on an atlas's chart seams, where one
/// position has two UVs), matfit's triangle order and winding.
pub fn object_mesh(scene: &Scene, oi: usize, tangents: bool) -> ObjectMesh {
    let g = &*scene.geometry;
    let obj = &scene.objects[oi];
    let range = obj.tri_range.start as usize..obj.tri_range.end as usize;
    let atlas = match &obj.material {
        Material::Textured { texture, .. } | Material::TexturedPlastic { texture, .. } => {
            match &texture.mapping {
                Mapping::Atlas(a) => Some((a.clone(), texture.width, texture.height)),
                Mapping::Uv => None,
            }
        }
        _ => None,
    };
    let has_uvs = atlas.is_some()
        || range
            .clone()
            .any(|t| g.tris[t].v.iter().any(|&i| g.uvs[i as usize] != Vec2::ZERO));

    let mut remap: HashMap<(u32, [u32; 2]), u32> = HashMap::new();
    let mut verts: Vec<(u32, Vec2)> = Vec::new();
    let mut indices = Vec::with_capacity(range.len());
    for t in range.clone() {
        let tri = g.tris[t];
        let ng = g.faces[t].ng;
        let idx = tri.v.map(|i| {
            let uv = match &atlas {
                Some((a, w, h)) => {
                    let [x, y] = a
                        .position(oi as u32, g.positions[i as usize], ng)
                        .unwrap_or([0.0, 0.0]);
                    Vec2::new(x / *w as f32, y / *h as f32)
                }
                None => Vec2::new(g.uvs[i as usize].x, 1.0 - g.uvs[i as usize].y),
            };
            *remap
                .entry((i, uv.to_array().map(f32::to_bits)))
                .or_insert_with(|| {
                    verts.push((i, uv));
                    verts.len() as u32 - 1
                })
        });
        indices.push(idx);
    }
    // Unit normals (glTF requires them): the geometric normal of a triangle that uses the
    // vertex where the source's normal degenerates.
    let mut fallback = vec![Vec3::ZERO; verts.len()];
    let mut dpdu = vec![Vec3::ZERO; verts.len()];
    for (t, idx) in range.clone().zip(&indices) {
        for &k in idx {
            fallback[k as usize] = g.faces[t].ng;
            dpdu[k as usize] += g.faces[t].dpdu.normalize_or_zero();
        }
    }
    let normals: Vec<Vec3> = verts
        .iter()
        .zip(&fallback)
        .map(|(&(i, _), &ng)| {
            let n = g.normals[i as usize].normalize_or_zero();
            if n == Vec3::ZERO || !n.is_finite() {
                ng
            } else {
                n
            }
        })
        .collect();
    let tangents = tangents.then(|| {
        normals
            .iter()
            .zip(&dpdu)
            .map(|(&n, &d)| {
                let f = match obj.tangent {
                    Some(t) => Frame::from_normal_tangent(n, t),
                    None if d != Vec3::ZERO => Frame::from_normal_tangent(n, d),
                    None => Frame::from_normal(n),
                };
                f.s
            })
            .collect()
    });
    ObjectMesh {
        positions: verts
            .iter()
            .map(|&(i, _)| g.positions[i as usize])
            .collect(),
        normals,
        uvs: has_uvs.then(|| verts.iter().map(|&(_, uv)| uv).collect()),
        tangents,
        indices,
    }
}

/// An 8-bit sRGB PNG of factor × texels, and how many texels clipped at 1. An atlas gets a
/// one-texel border around each chart copied from the chart's edge (see the module comment).
pub fn texture_png(texture: &Texture, factor: Rgb) -> Result<(Vec<u8>, usize), String> {
    let img = super::texture_image(texture, factor);
    let clipped = img
        .data
        .iter()
        .filter(|c| c.max_element() > 1.0 + 1e-6)
        .count();
    let mut png = std::io::Cursor::new(Vec::new());
    img.to_srgb8()
        .write_to(&mut png, image::ImageFormat::Png)
        .map_err(|e| format!("cannot encode a texture as PNG: {e}"))?;
    Ok((png.into_inner(), clipped))
}

/// The glTF camera and its node (see the module comment).
fn camera_json(scene: &Scene, warnings: &mut Vec<String>) -> (Value, Value) {
    let cam = &scene.camera;
    if cam.is_orthographic() {
        return orthographic_camera_json(scene);
    }
    let eye = cam.eye();
    if cam.distortion.is_some() {
        warnings.push(
            "the camera's lens distortion is not exported: a glTF camera is a pinhole".into(),
        );
    }
    if ((cam.fx - cam.fy) / cam.fy).abs() > 1e-4 {
        warnings.push(format!(
            "camera: fx {} ≠ fy {} but glTF cameras have square pixels; exported with fy's \
             vertical field of view",
            cam.fx, cam.fy
        ));
    }
    let (dx, dy) = (
        cam.cx - 0.5 * cam.width as f32,
        cam.cy - 0.5 * cam.height as f32,
    );
    if dx.abs() > 1e-3 || dy.abs() > 1e-3 {
        warnings.push(format!(
            "camera: the principal point is ({dx:.3}, {dy:.3}) pixels off the image centre, \
             which glTF cameras cannot express; exported centred (the image shifts by that much)"
        ));
    }
    let far = super::far_clip(scene, eye);
    let g = &*scene.geometry;
    let nearest = g
        .tris
        .iter()
        .map(|t| {
            let [a, b, c] = t.v.map(|i| g.positions[i as usize]);
            point_triangle_distance(eye, a, b, c)
        })
        .fold(f32::INFINITY, f32::min);
    let near = (0.5 * nearest).clamp(far * 1e-6, far * 0.5);
    let rot = camera_rotation(cam.r);
    let q = glam::Quat::from_mat3(&rot).normalize();
    let camera = json!({
        "type": "perspective",
        "name": "camera",
        "perspective": {
            "yfov": 2.0 * (0.5 * cam.height as f32 / cam.fy).atan(),
            "aspectRatio": cam.width as f32 / cam.height as f32,
            "znear": near,
            "zfar": far,
        },
    });
    let node = json!({
        "name": "camera",
        "camera": 0,
        "rotation": q.to_array(),
        "translation": eye.to_array(),
    });
    (camera, node)
}

/// An orthographic camera: glTF's `xmag`, `ymag` are half the film's width and height in scene
/// units (glTF 2.0 §5.12), the node at the film's centre, so that fx ≠ fy and an off-centre
/// principal point are exact.
fn orthographic_camera_json(scene: &Scene) -> (Value, Value) {
    let cam = &scene.camera;
    let (w, h) = (cam.width as f32, cam.height as f32);
    let centre = cam.ray(Vec2::new(0.5 * w, 0.5 * h)).o;
    let size = Vec2::new(w / cam.fx, h / cam.fy);
    let far = super::far_clip(scene, centre);
    let q = glam::Quat::from_mat3(&camera_rotation(cam.r)).normalize();
    let camera = json!({
        "type": "orthographic",
        "name": "camera",
        "orthographic": { "xmag": 0.5 * size.x, "ymag": 0.5 * size.y, "znear": 0.0, "zfar": far },
    });
    let node = json!({
        "name": "camera",
        "camera": 0,
        "rotation": q.to_array(),
        "translation": centre.to_array(),
    });
    (camera, node)
}

/// A `[[light]]` as a KHR_lights_punctual light (index `k`) and the node that places it: the
/// light shines along the node's −z.
fn punctual_json(l: &PunctualLight, k: usize) -> (Value, Value) {
    // 683 lm/W: the luminous efficacy at 555 nm, the SI definition of the candela.
    let power = |c: Rgb| {
        let m = c.max_element();
        let color = if m > 0.0 { c / m } else { Rgb::ONE };
        (color.to_array(), 683.0 * m)
    };
    let aim = |d: Vec3| {
        glam::Quat::from_rotation_arc(Vec3::NEG_Z, d)
            .normalize()
            .to_array()
    };
    let (light, rotation, translation) = match l.kind {
        Punctual::Directional {
            direction,
            irradiance,
            ..
        } => {
            let (color, intensity) = power(irradiance);
            (
                json!({"type": "directional", "color": color, "intensity": intensity}),
                Some(aim(direction)),
                None,
            )
        }
        Punctual::Point {
            position,
            intensity,
        } => {
            let (color, intensity) = power(intensity);
            (
                json!({"type": "point", "color": color, "intensity": intensity}),
                None,
                Some(position.to_array()),
            )
        }
        Punctual::Spot {
            position,
            direction,
            intensity,
            cutoff,
            beam_width,
        } => {
            let (color, intensity) = power(intensity);
            (
                json!({"type": "spot", "color": color, "intensity": intensity,
                       "spot": {"innerConeAngle": beam_width, "outerConeAngle": cutoff}}),
                Some(aim(direction)),
                Some(position.to_array()),
            )
        }
    };
    let mut light = light;
    light["name"] = json!(l.name);
    let mut node = json!({"name": l.name, "extensions": {"KHR_lights_punctual": {"light": k}}});
    if let Some(r) = rotation {
        node["rotation"] = json!(r);
    }
    if let Some(t) = translation {
        node["translation"] = json!(t);
    }
    (light, node)
}

/// Camera-to-world rotation of a glTF camera (x right, y up, looking down −z) from matfit's
/// world-to-camera R (rows right, down, forward): columns (right, −down, −forward).
pub fn camera_rotation(r: Mat3) -> Mat3 {
    Mat3::from_cols(r.row(0), -r.row(1), -r.row(2))
}

/// The distance from `p` to the triangle (a, b, c).
fn point_triangle_distance(p: Vec3, a: Vec3, b: Vec3, c: Vec3) -> f32 {
    let segment = |a: Vec3, b: Vec3| {
        let d = b - a;
        let t = if d.length_squared() > 0.0 {
            ((p - a).dot(d) / d.length_squared()).clamp(0.0, 1.0)
        } else {
            0.0
        };
        (p - (a + d * t)).length()
    };
    let n = (b - a).cross(c - a);
    let inside = n != Vec3::ZERO
        && (b - a).cross(p - a).dot(n) >= 0.0
        && (c - b).cross(p - b).dot(n) >= 0.0
        && (a - c).cross(p - c).dot(n) >= 0.0;
    if inside {
        (p - a).dot(n).abs() / n.length()
    } else {
        segment(a, b).min(segment(b, c)).min(segment(c, a))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::Camera;

    #[test]
    fn ward_anisotropy_reproduces_both_alphas_and_the_direction() {
        // The extension: α_t = mix(r², 1, s²) along the direction, α_b = r² across it.
        for (ax, ay, theta) in [(0.07, 0.11, 0.0), (0.2, 0.05, 0.3), (0.3, 0.3, 1.0)] {
            let mut w = Vec::new();
            let (r, aniso) = ward_roughness(ax, ay, theta, &mut w);
            assert!(w.is_empty(), "{w:?}");
            let ab = r * r;
            let Some((s, rot)) = aniso else {
                assert_eq!(ax, ay);
                assert!((ab - ax).abs() < 1e-6);
                continue;
            };
            let at = ab * (1.0 - s * s) + s * s;
            assert!((at - ax.max(ay)).abs() < 1e-6 && (ab - ax.min(ay)).abs() < 1e-6);
            // The direction of the larger α, in matfit's frame, is where glTF stretches.
            let frame = Frame::from_normal_tangent(Vec3::Z, Vec3::X);
            let dir = frame.s * rot.cos() + frame.n.cross(frame.s) * rot.sin();
            let ward = frame.rotated(theta);
            let want = if ax >= ay { ward.s } else { ward.t };
            assert!((dir - want).length() < 1e-5, "{dir} vs {want}");
        }
        let mut w = Vec::new();
        ward_roughness(1.5, 0.2, 0.0, &mut w);
        assert_eq!(w.len(), 1, "α > 1 is said to be clamped");
    }

    #[test]
    fn factors_map_as_stated() {
        let mut w = Vec::new();
        let v = WardVariant::Ward1992;
        let d = material_spec(
            &Material::Diffuse {
                rho_d: Rgb::new(0.5, 0.2, 0.1),
            },
            v,
            &mut w,
        );
        assert_eq!(d.base_color, Rgb::new(0.5, 0.2, 0.1));
        assert_eq!((d.metallic, d.roughness), (0.0, 1.0));
        assert_eq!(d.specular.unwrap().0, 0.0, "no specular lobe: Lambert");
        assert!(w.is_empty());

        let m = material_spec(
            &Material::Mirror {
                rho_s: Rgb::splat(0.8),
            },
            v,
            &mut w,
        );
        assert_eq!(
            (m.metallic, m.roughness, m.base_color),
            (1.0, 0.0, Rgb::splat(0.8))
        );
        assert_eq!(w.len(), 1, "Fresnel at grazing incidence is said");

        // Diffuse + mirror: F0 = ρs and the base's weight 1 − max ρs compensated.
        let (rho_d, rho_s) = (Rgb::new(0.3, 0.2, 0.1), Rgb::new(0.4, 0.5, 0.2));
        let dm = material_spec(&Material::DiffuseMirror { rho_d, rho_s }, v, &mut w);
        let (_, color) = dm.specular.unwrap();
        assert!((color * DIELECTRIC_F0 - rho_s).abs().max_element() < 1e-6);
        assert!((dm.base_color * (1.0 - 0.5) - rho_d).abs().max_element() < 1e-6);
        assert_eq!((dm.metallic, dm.roughness), (0.0, 0.0));

        // Figure 6's floor: ρd 0.1 under ρs 0.9 is a white base at weight 0.1.
        w.clear();
        let ward = material_spec(
            &Material::Ward {
                rho_d: Rgb::splat(0.1),
                rho_s: Rgb::splat(0.9),
                alpha_x: 0.07,
                alpha_y: 0.11,
                theta: 0.0,
            },
            v,
            &mut w,
        );
        assert!((ward.base_color - Rgb::ONE).abs().max_element() < 1e-5);
        assert!((ward.roughness - 0.07f32.sqrt()).abs() < 1e-6);
        assert!(ward.anisotropic && ward.anisotropy.unwrap().1 == FRAC_PI_2);
        assert_eq!(w.len(), 1, "{w:?}");
        assert!(w[0].contains("ward1992"), "{w:?}");
    }

    #[test]
    fn an_orthographic_camera_node_gives_matfit_rays() {
        let eye = Vec3::new(1.0, 2.0, 3.0);
        let cam = Camera::orthographic_look_at(320, 200, eye, Vec3::ZERO, Vec3::Y, 2.5).unwrap();
        let path =
            std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/figure6/scene.toml");
        let mut scene = crate::scene::load_scene(&path).unwrap();
        scene.camera = cam.clone();
        let (c, node) = orthographic_camera_json(&scene);
        let f = |v: &Value| v.as_f64().unwrap() as f32;
        let (xmag, ymag) = (f(&c["orthographic"]["xmag"]), f(&c["orthographic"]["ymag"]));
        assert!((xmag - 1.25).abs() < 1e-6 && (ymag - 1.25 * 200.0 / 320.0).abs() < 1e-6);
        let q = node["rotation"]
            .as_array()
            .unwrap()
            .iter()
            .map(f)
            .collect::<Vec<_>>();
        let q = glam::Quat::from_array([q[0], q[1], q[2], q[3]]);
        let t = node["translation"]
            .as_array()
            .unwrap()
            .iter()
            .map(f)
            .collect::<Vec<_>>();
        for (x, y) in [(0.0, 0.0), (320.0, 0.0), (0.0, 200.0), (100.5, 33.25)] {
            // glTF: NDC x right, y up; the ray through NDC (u, v) starts at (u·xmag, v·ymag, 0)
            // and runs along −z.
            let (u, v) = (2.0 * x / 320.0 - 1.0, 1.0 - 2.0 * y / 200.0);
            let o = Vec3::new(t[0], t[1], t[2]) + q * Vec3::new(u * xmag, v * ymag, 0.0);
            let want = cam.ray(Vec2::new(x, y));
            assert!(
                (o - want.o).length() < 1e-5,
                "({x}, {y}): {o} vs {}",
                want.o
            );
            assert!((q * -Vec3::Z - want.d).length() < 1e-5);
        }
    }

    #[test]
    fn the_camera_node_gives_matfit_rays() {
        // A calibrated camera with a rotation that is not a look-at's (roll), centred.
        let la = Camera::look_at(
            320,
            200,
            Vec3::new(1.0, 2.0, 3.0),
            Vec3::new(-0.5, 0.3, -1.0),
            Vec3::new(0.3, 1.0, 0.1),
            50.0,
        )
        .unwrap();
        let roll = Mat3::from_rotation_z(0.4);
        let r = roll * la.r;
        let eye = la.eye();
        let cam = Camera::calibrated(320, 200, la.fy, la.fy, 159.5, 99.5, r, -(r * eye)).unwrap();
        let rot = camera_rotation(cam.r);
        assert!((rot.determinant() - 1.0).abs() < 1e-5);
        let q = glam::Quat::from_mat3(&rot);
        let yfov = 2.0 * (0.5 * 200.0 / cam.fy).atan();
        let aspect = 320.0 / 200.0;
        for (x, y) in [(0.0, 0.0), (320.0, 0.0), (0.0, 200.0), (100.5, 33.25)] {
            // glTF: NDC x right, y up; the ray through NDC (u, v) is (u·a·tan, v·tan, −1).
            let (u, v) = (2.0 * x / 320.0 - 1.0, 1.0 - 2.0 * y / 200.0);
            let t = (0.5 * yfov).tan();
            let d = (q * Vec3::new(u * aspect * t, v * t, -1.0)).normalize();
            let want = cam.ray(Vec2::new(x, y)).d;
            assert!((d - want).length() < 1e-5, "({x}, {y}): {d} vs {want}");
        }
    }

    /// An atlas texture read through the exported UVs, bilinearly as a glTF renderer does,
    /// gives matfit's clamped atlas lookup (up to 8-bit sRGB quantisation), on seams too.
    #[test]
    fn atlas_uvs_and_borders_reproduce_matfit_lookups() {
        use crate::scene::atlas::Atlas;
        let path =
            std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes/figure6/scene.toml");
        let mut scene = crate::scene::load_scene(&path).unwrap();
        let oi = scene
            .objects
            .iter()
            .position(|o| o.name == "big_block")
            .unwrap();
        let atlas = Atlas::build(&scene.geometry, &[oi], scene.objects.len(), 0.05);
        let mut rng = crate::math::sampler::TestRng(7);
        let texels: Vec<Rgb> = (0..atlas.width * atlas.height)
            .map(|_| Rgb::new(rng.f32(), rng.f32(), rng.f32()))
            .collect();
        let texture = Arc::new(Texture {
            width: atlas.width,
            height: atlas.height,
            texels: texels.clone(),
            path: "atlas.png".into(),
            mapping: Mapping::Atlas(Arc::new(atlas.clone())),
        });
        scene.objects[oi].material = Material::Textured {
            texture: texture.clone(),
            scale: Rgb::ONE,
            varnish: None,
        };
        let mesh = object_mesh(&scene, oi, false);
        let (png, clipped) = texture_png(&texture, Rgb::ONE).unwrap();
        assert_eq!(clipped, 0);
        let img = image::load_from_memory(&png).unwrap().to_rgb8();
        let (w, h) = (atlas.width as i64, atlas.height as i64);
        let texel = |x: i64, y: i64| {
            let p = img
                .get_pixel(x.clamp(0, w - 1) as u32, y.clamp(0, h - 1) as u32)
                .0;
            Rgb::from_array(p.map(|c| crate::io::image::srgb_decode(c as f32 / 255.0)))
        };
        // glTF's bilinear filter: texel centres at (i + ½)/W.
        let sample = |uv: Vec2| {
            let (x, y) = (uv.x * w as f32 - 0.5, uv.y * h as f32 - 0.5);
            let (x0, y0) = (x.floor(), y.floor());
            let (fx, fy) = (x - x0, y - y0);
            let (x0, y0) = (x0 as i64, y0 as i64);
            let top = texel(x0, y0) * (1.0 - fx) + texel(x0 + 1, y0) * fx;
            let bottom = texel(x0, y0 + 1) * (1.0 - fx) + texel(x0 + 1, y0 + 1) * fx;
            top * (1.0 - fy) + bottom * fy
        };
        let g = &*scene.geometry;
        let tris = scene.objects[oi].tri_range.clone();
        assert_eq!(mesh.indices.len(), tris.len());
        let mut worst = 0.0f32;
        for (t, idx) in (tris.start as usize..tris.end as usize).zip(&mesh.indices) {
            let [a, b, c] = g.tris[t].v.map(|i| g.positions[i as usize]);
            let uv = idx.map(|k| mesh.uvs.as_ref().unwrap()[k as usize]);
            // Corners (on the chart's edges: the borders matter) and inner points.
            for bary in [
                [1.0, 0.0, 0.0],
                [0.0, 1.0, 0.0],
                [0.0, 0.0, 1.0],
                [0.2, 0.3, 0.5],
                [0.6, 0.3, 0.1],
            ] {
                let p = a * bary[0] + b * bary[1] + c * bary[2];
                let q = uv[0] * bary[0] + uv[1] * bary[1] + uv[2] * bary[2];
                let want = atlas.lookup(&texels, oi as u32, p, g.faces[t].ng);
                worst = worst.max((sample(q) - want).abs().max_element());
            }
        }
        assert!(worst < 5e-3, "largest difference {worst}");
    }

    #[test]
    fn distance_to_a_triangle() {
        let (a, b, c) = (Vec3::ZERO, Vec3::X, Vec3::Y);
        let d = |p| point_triangle_distance(p, a, b, c);
        assert!((d(Vec3::new(0.2, 0.2, 3.0)) - 3.0).abs() < 1e-6);
        assert!((d(Vec3::new(2.0, 0.0, 0.0)) - 1.0).abs() < 1e-6);
        assert!((d(Vec3::new(1.0, 1.0, 0.0)) - 0.5f32.sqrt()).abs() < 1e-6);
    }
}
