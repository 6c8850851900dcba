//! How the terminal shows numbers: rounded vectors, colours, materials, and the table of
//! recovered materials that ends `recover`.

use matfit::fit::Status;
use matfit::fit::{Level, Recovery};
use matfit::math::{Rgb, Vec3};
use matfit::scene::{Material, Scene};

/// A number with at most `digits` decimals and no trailing zeros (1.6, not 1.5999999).
pub fn num(x: f32, digits: usize) -> String {
    let s = format!("{x:.digits$}");
    let s = if s.contains('.') {
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        s
    };
    if s == "-0" {
        "0".into()
    } else {
        s
    }
}

/// `(x, y, z)` rounded to 4 decimals.
pub fn vec3(v: Vec3) -> String {
    format!("({}, {}, {})", num(v.x, 4), num(v.y, 4), num(v.z, 4))
}

/// One number for a grey colour, `(r, g, b)` otherwise; 3 decimals.
pub fn rgb(c: Rgb) -> String {
    if c.x == c.y && c.y == c.z {
        num(c.x, 3)
    } else {
        format!("({}, {}, {})", num(c.x, 3), num(c.y, 3), num(c.z, 3))
    }
}

/// A microfacet distribution's name in a table.
fn distribution_label(d: matfit::scene::Distribution) -> &'static str {
    match d {
        matfit::scene::Distribution::Ggx => "GGX",
        matfit::scene::Distribution::Beckmann => "Beckmann",
    }
}

/// A material as the scene file would write it, on one line.
pub fn material(m: &Material) -> String {
    match m {
        Material::Diffuse { rho_d } => format!("diffuse ρd {}", rgb(*rho_d)),
        Material::Mirror { rho_s } => format!("mirror ρs {}", rgb(*rho_s)),
        Material::DiffuseMirror { rho_d, rho_s } => {
            format!("diffuse + mirror ρd {} ρs {}", rgb(*rho_d), rgb(*rho_s))
        }
        Material::Ward {
            rho_d,
            rho_s,
            alpha_x,
            alpha_y,
            theta,
        } => format!(
            "ward ρd {} ρs {} {}",
            rgb(*rho_d),
            rgb(*rho_s),
            alpha(*alpha_x, *alpha_y, *theta)
        ),
        Material::Microfacet {
            rho_d,
            rho_s,
            alpha_x,
            alpha_y,
            theta,
            distribution,
        } => format!(
            "microfacet ({}) ρd {} ρs {} {}",
            distribution_label(*distribution),
            rgb(*rho_d),
            rgb(*rho_s),
            alpha(*alpha_x, *alpha_y, *theta)
        ),
        Material::Plastic {
            rho_d,
            rho_s,
            alpha,
            distribution,
            ..
        } => format!(
            "plastic ({} coat) ρd {} ρs {} α {}",
            distribution_label(*distribution),
            rgb(*rho_d),
            rgb(*rho_s),
            num(*alpha, 4)
        ),
        Material::Textured {
            texture,
            scale,
            varnish,
        } => {
            let t = format!("textured {} × {}", texture.path.display(), rgb(*scale));
            match varnish {
                Some(v) => format!(
                    "{t} + ward ρs {} {}",
                    rgb(v.rho_s),
                    alpha(v.alpha_x, v.alpha_y, v.theta)
                ),
                None => t,
            }
        }
        Material::TexturedPlastic {
            texture,
            scale,
            rho_s,
            alpha,
            distribution,
            ..
        } => format!(
            "textured {} × {} under a plastic ({} coat) ρs {} α {}",
            texture.path.display(),
            rgb(*scale),
            distribution_label(*distribution),
            rgb(*rho_s),
            num(*alpha, 4)
        ),
        Material::Black => "black".into(),
    }
}

fn alpha(ax: f32, ay: f32, theta: f32) -> String {
    if ax == ay && theta == 0.0 {
        format!("α {}", num(ax, 4))
    } else {
        format!(
            "αx {} αy {} θ {}°",
            num(ax, 4),
            num(ay, 4),
            num(theta.to_degrees(), 1)
        )
    }
}

/// (ρd, ρs, lobe) columns of a material; "-" where it has none.
fn columns(m: &Material) -> (String, String, String) {
    let dash = || "-".to_string();
    match m {
        Material::Diffuse { rho_d } => (rgb(*rho_d), dash(), dash()),
        Material::Mirror { rho_s } => (dash(), rgb(*rho_s), dash()),
        Material::DiffuseMirror { rho_d, rho_s } => (rgb(*rho_d), rgb(*rho_s), dash()),
        Material::Ward {
            rho_d,
            rho_s,
            alpha_x,
            alpha_y,
            theta,
        } => (rgb(*rho_d), rgb(*rho_s), alpha(*alpha_x, *alpha_y, *theta)),
        Material::Microfacet {
            rho_d,
            rho_s,
            alpha_x,
            alpha_y,
            theta,
            distribution,
        } => (
            rgb(*rho_d),
            rgb(*rho_s),
            format!(
                "{} {}",
                alpha(*alpha_x, *alpha_y, *theta),
                distribution.name()
            ),
        ),
        Material::Plastic {
            rho_d,
            rho_s,
            alpha: a,
            ..
        } => (rgb(*rho_d), rgb(*rho_s), alpha(*a, *a, 0.0)),
        Material::Textured { scale, varnish, .. } => match varnish {
            Some(v) => (
                format!("texture × {}", rgb(*scale)),
                rgb(v.rho_s),
                alpha(v.alpha_x, v.alpha_y, v.theta),
            ),
            None => (format!("texture × {}", rgb(*scale)), dash(), dash()),
        },
        Material::TexturedPlastic {
            scale,
            rho_s,
            alpha: a,
            ..
        } => (
            format!("texture × {}", rgb(*scale)),
            rgb(*rho_s),
            alpha(*a, *a, 0.0),
        ),
        Material::Black => (dash(), dash(), dash()),
    }
}

/// The table of recovered materials: one row per group with its level, status, parameters
/// (as the recovered scene holds them, fixed groups included) and ε of the final render.
pub fn recovered(rec: &Recovery) -> String {
    let sc: &Scene = &rec.scene;
    let rows: Vec<[String; 9]> = rec
        .groups
        .iter()
        .enumerate()
        .map(|(g, st)| {
            let m = sc.groups[g]
                .objects
                .first()
                .map(|&o| sc.objects[o].material.clone())
                .unwrap_or(Material::Black);
            let (rd, rs, lobe) = if st.status == Status::Light {
                ("-".into(), "-".into(), "-".into())
            } else {
                columns(&m)
            };
            let level = match st.status {
                // A fixed group keeps the scene's material: show its kind, not a fitted level.
                Status::Fixed | Status::Light => "-".to_string(),
                _ => st.level.name().to_string(),
            };
            let (e, n) = match rec.final_error.get(g).copied().flatten() {
                Some((e, n)) if st.status != Status::Light => {
                    (format!("{:.2}%", 100.0 * e), format!("{:.2}%", 100.0 * n))
                }
                _ => ("-".into(), "-".into()),
            };
            let sigma = match (&st.sigma, st.status) {
                (Some(sd), Status::Analysing | Status::Confirmed) => uncertainty(st, sd),
                _ => "-".into(),
            };
            [
                st.name.clone(),
                level,
                matfit::report::group_status(
                    st,
                    rec.final_error.get(g).copied().flatten(),
                    rec.unseen.iter().find(|u| u.group == g),
                )
                .to_string(),
                rd,
                rs,
                lobe,
                sigma,
                e,
                n,
            ]
        })
        .collect();
    let head = [
        "group", "level", "status", "ρd", "ρs", "lobe", "1σ", "ε", "noise",
    ];
    let mut w = head.map(|h| h.chars().count());
    for r in &rows {
        for (i, c) in r.iter().enumerate() {
            w[i] = w[i].max(c.chars().count());
        }
    }
    let line = |cells: &[String]| {
        let mut s = String::new();
        for (i, c) in cells.iter().enumerate() {
            let pad = w[i] - c.chars().count();
            // Numbers of the last two columns right-aligned, text left-aligned.
            if i >= 7 {
                s.push_str(&" ".repeat(pad));
                s.push_str(c);
            } else {
                s.push_str(c);
                if i + 1 < cells.len() {
                    s.push_str(&" ".repeat(pad));
                }
            }
            if i + 1 < cells.len() {
                s.push_str("  ");
            }
        }
        s.trim_end().to_string() + "\n"
    };
    let mut out = line(&head.map(String::from));
    for r in &rows {
        out.push_str(&line(r));
    }
    out.push_str(
        "ε: Σ|synthetic − photo| / Σ photo over the group's usable pixels and channels, final \
         render (as report.html and results.json `error`); noise: the same ε between two \
         independent halves of the render's samples, the floor below which ε cannot go. 1σ: \
         the largest standard uncertainty of the group's reflectances (any channel) and of its \
         roughness (relative); every parameter's is in results.json `sigma`.\n",
    );
    if rec
        .groups
        .iter()
        .any(|st| st.is_fitted() && st.level == Level::Plastic)
    {
        use matfit::render::bsdf::plastic::{fresnel_dielectric, DEFAULT_ETA};
        out.push_str(&format!(
            "plastic: a diffuse base under a rough dielectric coat (GGX or Beckmann, whichever \
             fits better) whose index of refraction \
             is not fitted but taken as η = {DEFAULT_ETA} (acrylic); its ρs is the coat's \
             reflectance at normal incidence (F0 = {:.4} for that η; a ρs away from it is a coat \
             reflecting more or less than clean acrylic).\n",
            fresnel_dielectric(1.0, DEFAULT_ETA)
        ));
    }
    out
}

/// The 1σ column: the largest σ of ρd and ρs over the channels, and α's relative σ.
fn uncertainty(st: &matfit::fit::GroupState, sd: &matfit::fit::GroupParams) -> String {
    let rho = sd.rho_d.max_element().max(sd.rho_s.max_element());
    let mut out = format!("ρ {rho:.3}");
    if st.level.has_lobe() {
        let rel = (sd.alpha_x / st.params.alpha_x).max(sd.alpha_y / st.params.alpha_y);
        out += &format!(", α {:.1}%", 100.0 * rel);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn numbers_are_rounded_without_float_noise() {
        assert_eq!(num(1.599_999_9, 4), "1.6");
        assert_eq!(num(-0.000_01, 4), "0");
        assert_eq!(num(-0.200_000_02, 4), "-0.2");
        assert_eq!(num(3.0, 4), "3");
        assert_eq!(
            vec3(Vec3::new(-0.0, 1.599_999_9, -0.200_000_02)),
            "(0, 1.6, -0.2)"
        );
    }
}
