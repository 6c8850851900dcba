//! What `recover` writes: the recovered scene, results.json, images, and the HTML report.
//! Every file is written atomically.

pub mod html;
pub mod plots;
pub mod verdict;

use crate::fit::params::Value;
use crate::fit::Status;
use crate::fit::{GroupParams, Level, Recovery};
use crate::io::atomic::write_atomic;
use crate::io::image::Image;
use crate::math::Rgb;
use crate::photo::Photo;
use crate::scene::Material;
use serde::Serialize;
use std::collections::BTreeMap;
use std::path::Path;

#[derive(Serialize)]
pub struct GroupResult {
    pub name: String,
    pub level: &'static str,
    pub level_number: u8,
    /// [`status_word`]: "estimated" for an unseen group the photo determined; "not explained"
    /// for a fitted group whose final ε is far above its noise floor (`verdict::explained`).
    pub status: &'static str,
    /// ε of the final render against the photo (usable pixels, 4×4 tiles); absent without pixels.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub error: Option<f32>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub noise_floor: Option<f32>,
    /// ε and noise floor on the cache at the last fit (what the hierarchy decided on).
    pub fit_error: f32,
    pub fit_noise_floor: f32,
    /// The photo's own noise in ε's units on that cache (`fit::error::photo_noise`): the part
    /// of `fit_error` that is neither the cache's noise nor misfit.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub fit_photo_noise: Option<f32>,
    pub visible_pixels: usize,
    pub usable_pixels: usize,
    pub rejected_pixels: usize,
    /// How many pixels the group kept and why it lost the rest, in words.
    pub pixels_lost: String,
    /// The band width its mask used and whether the edge test applied.
    pub band_width: usize,
    pub edge_test: bool,
    pub params: BTreeMap<&'static str, Value>,
    /// The microfacet levels' and the plastic's distribution ("ggx" or "beckmann"), chosen by
    /// the fit.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub distribution: Option<&'static str>,
    /// The 1σ of each parameter in `params` (same units: `fit/uncertainty.rs`); absent where
    /// not fitted or not computable, null ("not determined") where the photo does not
    /// constrain a parameter or its 1σ spans its whole range ([`Sigma::of`]).
    #[serde(skip_serializing_if = "BTreeMap::is_empty")]
    pub sigma: BTreeMap<&'static str, Sigma>,
    /// The material's directional-hemispherical albedo at incidence 0° and 60°, with its 1σ
    /// from `sigma` (`fit::uncertainty::albedo`): the reflectance every level's model has, to
    /// compare groups fitted at different levels, or with another system's albedo. A textured
    /// group's is its mean texel's.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub albedo: Option<AlbedoResult>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub note: Option<String>,
    /// For a group with no usable pixels: which rule gave its ρd, its 1σ and the remedy.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub unseen: Option<UnseenResult>,
    /// For a textured group (level 7): its texture files and how much of it the photo saw.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub texture: Option<TextureResult>,
}

#[derive(Serialize)]
pub struct AlbedoResult {
    /// Per channel, light arriving along the normal, and at 60° (averaged over the azimuth).
    pub normal: [f32; 3],
    pub at_60deg: [f32; 3],
    /// Their 1σ; null where a parameter they depend on is not determined (or for a group
    /// given, not fitted).
    pub sigma_normal: [Option<f32>; 3],
    pub sigma_60deg: [Option<f32>; 3],
}

impl From<crate::fit::uncertainty::Albedo> for AlbedoResult {
    fn from(a: crate::fit::uncertainty::Albedo) -> Self {
        AlbedoResult {
            normal: a.value[0].to_array(),
            at_60deg: a.value[1].to_array(),
            sigma_normal: a.sigma[0],
            sigma_60deg: a.sigma[1],
        }
    }
}

#[derive(Serialize)]
pub struct TextureResult {
    /// Linear reflectance (EXR) and its sRGB preview, relative to the output folder.
    pub file: String,
    pub preview: String,
    pub width: usize,
    pub height: usize,
    /// World units per texel: one photo pixel at the group's median footprint.
    pub texel_size: f32,
    /// Texels inside the atlas's charts, and how many of them the photo saw; the others were
    /// filled by pull–push from the seen texels of their chart.
    pub texels: usize,
    pub texels_seen: usize,
    /// Of the unseen texels, those filled from a repeating print of their chart's seen
    /// texels (`fit::periodic`) rather than from their neighbours and their object's mean.
    pub texels_repeated: usize,
    /// The smoothness penalty's weight the texture was solved with, chosen by cross-validation
    /// on the photo's pixels (`fit::texture::choose_smoothing`).
    pub smoothing: f32,
    /// The uniform lobe on top of the texture: "none", or the Ward level it came from.
    pub lobe: &'static str,
}

#[derive(Serialize)]
pub struct Timing {
    pub total_s: f64,
    /// Everything before the final render (the inverse problem's cost).
    pub fit_s: f64,
    pub final_render_s: f64,
    /// The final render's samples per pixel and the side in pixels of its error's tiles.
    pub final_spp: u32,
    pub error_tile_px: usize,
}

/// What a recovery was run on and with: enough to run it again.
#[derive(Clone, Debug, Serialize)]
pub struct Inputs {
    /// matfit's version.
    pub matfit: String,
    pub scene: String,
    pub photo: String,
    /// The factor the photo's values were divided by, and how it was found ("given",
    /// "calibrated", "default").
    pub exposure: f32,
    pub exposure_rule: String,
    /// The mean image motion (pixels) of the model's edges under the pose correction found
    /// (None: registration off, `--camera-is-calibrated`).
    pub registration_px: Option<[f32; 2]>,
    /// Every photo, in the order of the scene's views, when several were fitted together (the
    /// exposure and registration above are then the first photo's).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub photos: Vec<String>,
    /// The pose correction: rotation (degrees), camera centre's move (scene units), image
    /// motion (px) and whether it was applied.
    pub registration: Option<crate::prepare::pose::Pose>,
    /// The user's mask of pixels to ignore (`--ignore-mask`), if one was given.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub ignore_mask: Option<String>,
    pub options: crate::fit::RecoverOptions,
}

#[derive(Serialize)]
pub struct Results {
    /// None when the caller did not say (the library's own tests).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub inputs: Option<Inputs>,
    pub groups: Vec<GroupResult>,
    pub timing: Timing,
    pub iterations: u32,
    pub cache_builds: u32,
    pub objective_evals: u64,
    pub ward_variant: &'static str,
    /// Per photo, when several were fitted together: its fitted exposure factor and residual.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub views: Vec<crate::fit::recovery::ViewFit>,
    /// The fitted stray light (`recover --stray-light`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub stray_light: Option<StrayResult>,
    /// Whether the recovered scene explains the photo, and if not the likely causes
    /// (`verdict.rs`; None where the photo was not at hand).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub verdict: Option<verdict::Verdict>,
}

/// An unseen group's estimate (`fit::unseen::UnseenEstimate`) as results.json states it.
#[derive(Serialize)]
pub struct UnseenResult {
    pub group: usize,
    pub rule: crate::fit::unseen::Rule,
    pub rho_d: [f32; 3],
    /// 1σ per channel; null where the photo does not determine it ([`determined_sigma`]).
    pub sigma: [Option<f32>; 3],
    /// Whether every channel's 1σ is determined.
    pub determined: bool,
    pub influence: f32,
    pub remedy: String,
}

/// The stray light's estimate (`fit::stray::StrayEstimate`) as results.json states it.
#[derive(Serialize)]
pub struct StrayResult {
    pub radiance: [f32; 3],
    /// 1σ per channel; null where the photo gave none.
    pub sigma: [Option<f32>; 3],
    pub estimated: bool,
    pub share: f32,
    pub open: bool,
}

/// A parameter's 1σ as results.json states it: per channel or one value, null where not
/// determined.
#[derive(Clone, Copy, Debug, Serialize, PartialEq)]
#[serde(untagged)]
pub enum Sigma {
    Rgb([Option<f32>; 3]),
    Scalar(Option<f32>),
}

impl Sigma {
    /// The 1σ `v` of parameter `name` as stated: a zero σ is a parameter the photo did not
    /// constrain (`uncertainty::sigma` pins it), not an exact value, and a reflectance σ of 1
    /// or an angle's of 180° spans the parameter's whole range; both are "not determined".
    pub fn of(name: &str, v: &Value) -> Sigma {
        let cap = match name {
            "rho_d" | "rho_s" => Some(1.0),
            "theta_deg" => Some(180.0),
            _ => None,
        };
        let stated = |s: f32| determined_sigma(s, cap).filter(|&s| s > 0.0);
        match v {
            Value::Rgb(c) => Sigma::Rgb(c.map(stated)),
            Value::Scalar(x) => Sigma::Scalar(stated(*x)),
        }
    }
}

/// A 1σ as the outputs state it: None where the fit has none to give. The unseen-group fit
/// marks a channel without an estimate with a negative σ and caps the others at 1, and a
/// reflectance σ of 1 spans all of [0, 1]: neither is an error bar.
pub fn determined_sigma(s: f32, cap: Option<f32>) -> Option<f32> {
    (s.is_finite() && s >= 0.0 && cap.is_none_or(|c| s < c)).then_some(s)
}

impl From<&crate::fit::unseen::UnseenEstimate> for UnseenResult {
    fn from(e: &crate::fit::unseen::UnseenEstimate) -> Self {
        let sigma = e.sigma.map(|s| determined_sigma(s, Some(1.0)));
        UnseenResult {
            group: e.group,
            rule: e.rule,
            rho_d: e.rho_d,
            sigma,
            determined: sigma.iter().all(Option::is_some),
            influence: e.influence,
            remedy: e.remedy.clone(),
        }
    }
}

impl From<&crate::fit::stray::StrayEstimate> for StrayResult {
    fn from(e: &crate::fit::stray::StrayEstimate) -> Self {
        StrayResult {
            radiance: e.radiance,
            sigma: e.sigma.map(|s| determined_sigma(s, None)),
            estimated: e.estimated,
            share: e.share,
            open: e.open,
        }
    }
}

/// A group's status in words, as results.json, report.html and the terminal's table say it:
/// an unseen group whose ρd the photo determined (`Rule::Estimated`) is "estimated"; one
/// given the stated scene default is "default".
/// The status of a fitted group whose final ε is far above its noise floor.
pub const NOT_EXPLAINED: &str = "not explained";

/// A group's status as the outputs state it: [`NOT_EXPLAINED`] for a fitted group whose final
/// ε (`final_error`: ε and noise floor) is far above its noise floor, else [`status_word`].
pub fn group_status(
    s: &crate::fit::GroupState,
    final_error: Option<(f32, f32)>,
    unseen: Option<&crate::fit::unseen::UnseenEstimate>,
) -> &'static str {
    match final_error {
        Some((e, n)) if s.is_fitted() && !verdict::explained(e, n) => NOT_EXPLAINED,
        _ => status_word(s.status, unseen),
    }
}

pub fn status_word(
    status: Status,
    unseen: Option<&crate::fit::unseen::UnseenEstimate>,
) -> &'static str {
    match status {
        Status::Analysing => "analysing",
        Status::Confirmed => "confirmed",
        Status::Default
            if unseen.is_some_and(|u| u.rule == crate::fit::unseen::Rule::Estimated) =>
        {
            "estimated"
        }
        Status::Default => "default",
        Status::Fixed => "fixed",
        Status::Light => "light",
    }
}

/// The material of group `g`'s first object in the recovered scene.
fn fixed_material(rec: &Recovery, g: usize) -> Option<&Material> {
    let o = *rec.scene.groups.get(g)?.objects.first()?;
    Some(&rec.scene.objects[o].material)
}

/// The hierarchy level whose model a material is.
fn level_of(m: &Material) -> Level {
    match m {
        Material::Mirror { .. } => Level::Specular,
        Material::DiffuseMirror { .. } => Level::DiffuseSpecular,
        Material::Ward {
            alpha_x,
            alpha_y,
            theta,
            ..
        } if alpha_x == alpha_y && *theta == 0.0 => Level::Isotropic,
        Material::Ward { .. } => Level::Anisotropic,
        Material::Microfacet {
            alpha_x,
            alpha_y,
            theta,
            ..
        } if alpha_x == alpha_y && *theta == 0.0 => Level::Microfacet,
        Material::Microfacet { .. } => Level::AnisotropicMicrofacet,
        Material::Plastic { .. } => Level::Plastic,
        Material::Textured { .. } | Material::TexturedPlastic { .. } => Level::Textured,
        Material::Diffuse { .. } | Material::Black => Level::Diffuse,
    }
}

pub fn results(rec: &Recovery) -> Results {
    let groups = rec
        .groups
        .iter()
        .enumerate()
        .map(|(g, s)| {
            let fe = rec.final_error[g];
            let st = &rec.pixel_stats[g];
            let unseen = rec.unseen.iter().find(|u| u.group == g);
            // A fixed group keeps the scene's material: report that, not the unused fit state.
            let (level, params) = match (s.status, fixed_material(rec, g)) {
                (Status::Fixed, Some(m)) => (level_of(m), GroupParams::from_material(m)),
                _ => (s.level, s.params),
            };
            let texture = texture_result(g, s);
            // A texture's parameters are its lobe's (ρd: the mean of its seen texels).
            let named_at = match s.status {
                Status::Fixed => level,
                _ => s.params_level(),
            };
            GroupResult {
                name: s.name.clone(),
                level: level.name(),
                level_number: level.number(),
                status: group_status(s, fe, unseen),
                error: fe.map(|e| e.0),
                noise_floor: fe.map(|e| e.1),
                fit_error: s.error,
                fit_noise_floor: s.noise_floor,
                fit_photo_noise: s.photo_noise,
                visible_pixels: st.visible,
                usable_pixels: st.usable,
                rejected_pixels: st.rejected,
                pixels_lost: st.why(),
                band_width: st.band_width,
                edge_test: st.edge_test,
                params: params.named(named_at).into_iter().collect(),
                distribution: named_at
                    .has_distribution()
                    .then(|| params.distribution.name()),
                sigma: match (s.status, &s.sigma) {
                    (Status::Analysing | Status::Confirmed, Some(sd)) => sd
                        .named(named_at)
                        .into_iter()
                        .map(|(k, v)| (k, Sigma::of(k, &v)))
                        .collect(),
                    _ => BTreeMap::new(),
                },
                albedo: group_albedo(rec, s, named_at, &params, unseen),
                note: s.note.clone(),
                unseen: unseen.map(UnseenResult::from),
                texture,
            }
        })
        .collect();
    Results {
        inputs: None,
        groups,
        timing: Timing {
            total_s: rec.total_s,
            fit_s: rec.fit_s,
            final_render_s: rec.final_render_s,
            final_spp: rec.final_spp,
            error_tile_px: rec.error_tile,
        },
        iterations: rec.iterations,
        cache_builds: rec.cache_builds,
        objective_evals: rec.objective_evals,
        ward_variant: rec.scene.render.ward_variant.name(),
        views: rec.views.clone(),
        stray_light: rec.stray_light.as_ref().map(StrayResult::from),
        verdict: None,
    }
}

/// [`GroupResult::albedo`]: with the fit's 1σ for a fitted group, the estimate's for an
/// unseen one (its reflectance only), none for a group given.
fn group_albedo(
    rec: &Recovery,
    s: &crate::fit::GroupState,
    level: Level,
    params: &GroupParams,
    unseen: Option<&crate::fit::unseen::UnseenEstimate>,
) -> Option<AlbedoResult> {
    let sigma = match (s.status, &s.sigma, unseen) {
        (Status::Analysing | Status::Confirmed, Some(sd), _) => Some(*sd),
        (_, _, Some(u)) => Some(GroupParams {
            rho_d: Rgb::from_array(u.sigma),
            ..GroupParams::default()
        }),
        _ => None,
    };
    let variant = rec.scene.render.ward_variant;
    let alternatives = match s.status {
        Status::Analysing | Status::Confirmed => &s.alternatives[..],
        _ => &[],
    };
    let a = crate::fit::uncertainty::albedo(level, params, sigma.as_ref(), alternatives, variant)?;
    Some(a.into())
}

/// The texture outputs of group `g`, if it ended at level 7.
fn texture_result(g: usize, s: &crate::fit::GroupState) -> Option<TextureResult> {
    let t = s.texture.as_ref().filter(|_| s.level == Level::Textured)?;
    let stem = crate::fit::recovery::texture_stem(g, &s.name);
    Some(TextureResult {
        file: format!("textures/{stem}.exr"),
        preview: format!("textures/{stem}.png"),
        width: t.width,
        height: t.height,
        texel_size: t.texel,
        texels: t.charted,
        texels_seen: t.seen_count(),
        texels_repeated: t.repeated,
        smoothing: t.smoothing,
        lobe: if t.base.is_ward() {
            t.base.name()
        } else {
            "none"
        },
    })
}

/// The recovered scene with its level-7 textures written under `dir/textures/` and referenced
/// by absolute paths (which `scene_to_toml` makes relative to `dir`).
fn with_written_textures(rec: &Recovery, dir: &Path) -> Result<crate::scene::Scene, String> {
    let mut scene = rec.scene.clone();
    let mut written = std::collections::BTreeSet::new();
    for obj in scene.objects.iter_mut() {
        let (Material::Textured { texture, .. } | Material::TexturedPlastic { texture, .. }) =
            &mut obj.material
        else {
            continue;
        };
        if !matches!(texture.mapping, crate::scene::texture::Mapping::Atlas(_))
            || texture.path.is_absolute()
        {
            continue;
        }
        let exr = dir.join(&texture.path);
        if written.insert(exr.clone()) {
            if let Some(parent) = exr.parent() {
                std::fs::create_dir_all(parent)
                    .map_err(|e| format!("cannot create {}: {e}", parent.display()))?;
            }
            let img = Image {
                width: texture.width,
                height: texture.height,
                data: texture.texels.clone(),
            };
            img.write(&exr)?;
            img.write(&exr.with_extension("png"))?;
        }
        let mut t = (**texture).clone();
        t.path = std::path::absolute(&exr).unwrap_or(exr);
        *texture = std::sync::Arc::new(t);
    }
    Ok(scene)
}

/// A false-colour ramp (black → blue → green → yellow → red → white) for t in [0, 1].
pub fn false_colour(t: f32) -> Rgb {
    let stops = [
        Rgb::new(0.0, 0.0, 0.0),
        Rgb::new(0.0, 0.05, 0.6),
        Rgb::new(0.0, 0.6, 0.1),
        Rgb::new(0.9, 0.85, 0.0),
        Rgb::new(0.9, 0.05, 0.0),
        Rgb::new(1.0, 1.0, 1.0),
    ];
    let t = if t.is_finite() {
        t.clamp(0.0, 1.0)
    } else {
        1.0
    } * (stops.len() - 1) as f32;
    let i = (t as usize).min(stops.len() - 2);
    let f = t - i as f32;
    stops[i] * (1.0 - f) + stops[i + 1] * f
}

/// Side in pixels of the error picture's tiles.
pub const MAP_TILE: usize = 8;

/// Full scale of the error picture: model error of 10% of the photo's radiance.
pub const ERROR_SCALE: f32 = 0.1;

/// |synthetic − photo| per channel, and the picture of the model's error (usable pixels only):
/// per group and `MAP_TILE`-pixel square of its usable pixels, the residual r = synthetic −
/// photo summed over the tile, less three times what the scatter of r within the tile explains
/// (√(n·var r) per channel: the noise of both images, pixel by pixel), over the tile's photo
/// radiance. Monte Carlo noise, in the final render or in the photo, then shows black and a
/// wrong model shows; false colour, full scale at `scale`.
pub fn error_images(rec: &Recovery, photo: &Photo, scale: f32) -> (Image, Image) {
    let (w, h) = (rec.synthetic.width, rec.synthetic.height);
    let tile_of = |i: usize| (i / w / MAP_TILE, (i % w) / MAP_TILE);
    let mut abs = Image::new(w, h);
    // Per (group, tile): Σ r, Σ r², Σ photo, pixel count.
    type Key = (i32, (usize, usize));
    let mut tiles: std::collections::HashMap<Key, (Rgb, Rgb, Rgb, f32)> = Default::default();
    for i in 0..w * h {
        let r = rec.synthetic.data[i] - photo.image.data[i];
        abs.data[i] = r.abs();
        let g = rec.mask.group[i];
        if g >= 0 {
            let t = tiles
                .entry((g, tile_of(i)))
                .or_insert((Rgb::ZERO, Rgb::ZERO, Rgb::ZERO, 0.0));
            t.0 += r;
            t.1 += r * r;
            t.2 += photo.image.data[i];
            t.3 += 1.0;
        }
    }
    let excess: std::collections::HashMap<Key, f32> = tiles
        .into_iter()
        .map(|(k, (sr, sr2, ph, n))| {
            let total = (ph.x + ph.y + ph.z).max(1e-12);
            let e = if n < 2.0 {
                0.0
            } else {
                let var = ((sr2 - sr * sr / n) / (n - 1.0)).max(Rgb::ZERO);
                let noise = (var * n).powf(0.5);
                let d = sr.abs() - noise * 3.0;
                d.max(Rgb::ZERO).element_sum() / total
            };
            (k, e)
        })
        .collect();
    let mut pic = Image::new(w, h);
    for i in 0..w * h {
        let g = rec.mask.group[i];
        pic.data[i] = if g >= 0 {
            let e = excess[&(g, tile_of(i))];
            // The picture is an sRGB preview: linearise the ramp so it shows as designed.
            let c = false_colour(e / scale);
            Rgb::new(c.x.powf(2.2), c.y.powf(2.2), c.z.powf(2.2))
        } else {
            Rgb::splat(0.02)
        };
    }
    (abs, pic)
}

/// Writes every output of a recovery into `dir` (which must exist).
pub fn write_outputs(
    dir: &Path,
    rec: &Recovery,
    photo: &Photo,
    inputs: Option<&Inputs>,
) -> Result<(), String> {
    let io = |p: &Path, e: std::io::Error| format!("cannot write {}: {e}", p.display());
    let scene_path = dir.join("recovered.toml");
    let scene = with_written_textures(rec, dir)?;
    let text = crate::scene::write::scene_to_toml(&scene, &scene_path);
    // A refined pose the fit ran with is the camera the materials belong to.
    let camera = inputs
        .filter(|i| i.photos.is_empty())
        .and_then(|i| i.registration.as_ref())
        .filter(|r| r.applied)
        .map(|r| &r.camera);
    let text = crate::scene::write::recovered_toml(&text, &recovered_header(inputs), camera);
    write_atomic(&scene_path, text.as_bytes()).map_err(|e| io(&scene_path, e))?;
    let mut res = results(rec);
    res.inputs = inputs.cloned();
    res.verdict = Some(verdict::verdict(rec, photo));
    let json = serde_json::to_string_pretty(&res).expect("results serialise");
    let rp = dir.join("results.json");
    write_atomic(&rp, json.as_bytes()).map_err(|e| io(&rp, e))?;
    rec.synthetic.write(&dir.join("synthetic.exr"))?;
    rec.synthetic.write(&dir.join("synthetic.png"))?;
    photo.image.write(&dir.join("photo.png"))?;
    let (abs, pic) = error_images(rec, photo, ERROR_SCALE);
    abs.write(&dir.join("error.exr"))?;
    pic.write(&dir.join("error.png"))?;
    // The plots come from the run's log, next to the outputs (absent: no plots).
    let log = std::fs::read_to_string(dir.join("log.jsonl")).unwrap_or_default();
    let plots: Vec<(String, String)> = plots::histories(&log)
        .into_iter()
        .filter_map(|(g, h)| plots::convergence_svg(&g, &h).map(|svg| (g, svg)))
        .collect();
    let page = html::report(&res, dir, &plots, ERROR_SCALE);
    let hp = dir.join("report.html");
    write_atomic(&hp, page.as_bytes()).map_err(|e| io(&hp, e))?;
    Ok(())
}

/// What recovered.toml says of itself: what made it, from what, when, and which camera it has.
fn recovered_header(inputs: Option<&Inputs>) -> String {
    let version = inputs.map_or(env!("CARGO_PKG_VERSION"), |i| i.matfit.as_str());
    let mut h = format!(
        "Recovered by matfit {version} (`matfit recover`) on {} (UTC): the materials fitted to \n\
         the photo; results.json and report.html beside this file say how well (ε, 1σ, status).\n",
        utc_date(std::time::SystemTime::now())
    );
    let Some(i) = inputs else {
        return h;
    };
    if i.photos.is_empty() {
        h += &format!("Photo: {}\n", i.photo);
    } else {
        h += &format!("Photos: {}\n", i.photos.join(", "));
    }
    h += &format!("Scene: {}\n", i.scene);
    match &i.registration {
        Some(r) if r.applied && i.photos.is_empty() => {
            h += &format!(
                "Camera: the scene's, refined to the photo and applied ({:.3}° rotation, centre \n\
                 moved {:.4} scene units, {:.2} px RMS image motion; results.json \n\
                 inputs.registration), in the calibrated form.\n",
                r.rotation_deg,
                r.translation.length(),
                r.rms_px
            )
        }
        Some(r) if r.applied => {
            h += "Camera: the scene's; the first photo's refined pose is in results.json \n\
                  inputs.registration.\n"
        }
        _ => h += "Camera: the scene's, as given.\n",
    }
    h
}

/// The UTC calendar date of `t`, YYYY-MM-DD (H. Hinnant's civil-from-days algorithm).
fn utc_date(t: std::time::SystemTime) -> String {
    let secs = t
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_secs()) as i64;
    let z = secs.div_euclid(86_400) + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = doy - (153 * mp + 2) / 5 + 1;
    let m = if mp < 10 { mp + 3 } else { mp - 9 };
    let y = yoe + era * 400 + i64::from(m <= 2);
    format!("{y:04}-{m:02}-{d:02}")
}

/// Adds a section of preformatted `text` under `title` to `dir/report.html`, after the
/// parameter table (the demo's true vs recovered values, which only it knows).
pub fn add_to_report(dir: &Path, title: &str, text: &str) -> Result<(), String> {
    let hp = dir.join("report.html");
    let page =
        std::fs::read_to_string(&hp).map_err(|e| format!("cannot read {}: {e}", hp.display()))?;
    let page = html::with_section(&page, title, text);
    write_atomic(&hp, page.as_bytes()).map_err(|e| format!("cannot write {}: {e}", hp.display()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn utc_dates() {
        let at = |s: u64| utc_date(std::time::UNIX_EPOCH + std::time::Duration::from_secs(s));
        assert_eq!(at(0), "1970-01-01");
        assert_eq!(at(951_782_400), "2000-02-29");
        assert_eq!(at(1_796_515_200 + 86_399), "2026-12-06");
    }

    #[test]
    fn caps_and_sentinels_are_no_error_bars() {
        assert_eq!(determined_sigma(0.004, Some(1.0)), Some(0.004));
        assert_eq!(determined_sigma(1.0, Some(1.0)), None);
        assert_eq!(determined_sigma(-1.0, None), None);
        assert_eq!(determined_sigma(2.0, None), Some(2.0));
    }
}
