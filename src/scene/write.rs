//! Writes a scene back out as TOML: how `recover` saves the recovered scene so that
//! `matfit render` can use it. Materials come from the scene's objects; mesh and texture paths
//! are rewritten so that they still resolve from the new file's folder.

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
            let iso = alpha_x == alpha_y && *theta == 0.0;
            MaterialSpec::Ward {
                rho_d: c(*rho_d),
                rho_s: c(*rho_s),
                alpha: iso.then_some(*alpha_x),
                alpha_x: (!iso).then_some(*alpha_x),
                alpha_y: (!iso).then_some(*alpha_y),
                theta_deg: (!iso).then_some(theta.to_degrees()),
            }
        }
        Material::Textured { texture, scale } => MaterialSpec::Textured {
            texture: texture.path.to_string_lossy().into_owned(),
            scale: Some(c(*scale)),
        },
        Material::Black => MaterialSpec::Black,
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

fn relative(path: &Path, base: &Path) -> Option<PathBuf> {
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

/// The scene as a TOML document to be saved at `dest` (paths are rewritten for `dest`'s folder).
pub fn scene_to_toml(scene: &Scene, dest: &Path) -> String {
    let from_dir = scene.path.parent().unwrap_or(Path::new("."));
    let to_dir = dest.parent().unwrap_or(Path::new("."));
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
