//! Levels 8, 9 and 10, the microfacet lobes. First figure6 with a diffuse floor (ρd 0.5), its small
//! block a rough green metal (Lambert 0 + GGX ρs (0.2, 0.7, 0.3), α 0.2: Mitsuba's
//! `roughconductor` with `material = "none"`) and its big block a red plastic (ρd (0.7, 0.05,
//! 0.05) under a GGX coat of IOR 1.49, α 0.1: Mitsuba's `roughplastic`), the photo rendered by
//! matfit at half size and recovered blind. The blocks must end at their levels with their
//! parameters, every other group diffuse, and where the climb tried the GGX levels the best Ward
//! lobes on the same cache must leave clearly larger errors. bench/nonward.py does the same from
//! Mitsuba's photos and scores the predictions.

use crate::recover::{run_keeping_photo, scaled, truth};
use matfit::fit::Event;
use matfit::fit::{Level, RecoverOptions};
use matfit::math::Rgb;
use matfit::render::bsdf::plastic::{fresnel_dielectric, DEFAULT_ETA};
use matfit::scene::{Distribution, Material, Scene};

/// Gives every object of `group` the material `m`; returns the group's index.
fn set_material(scene: &mut Scene, group: &str, m: Material) -> usize {
    let g = scene.group_index(group).unwrap();
    for &o in &scene.groups[g].objects.clone() {
        scene.objects[o].material = m.clone();
    }
    g
}

#[test]
fn a_rough_metal_and_a_plastic_are_recovered_at_the_ggx_levels() {
    let mut scene = scaled("scenes/figure6/scene.toml", 0.5);
    let (metal_s, metal_a) = (Rgb::new(0.2, 0.7, 0.3), 0.2f32);
    let (plastic_d, plastic_a) = (Rgb::new(0.7, 0.05, 0.05), 0.1f32);
    let f0 = fresnel_dielectric(1.0, DEFAULT_ETA);
    let mut set = |group: &str, m: Material| set_material(&mut scene, group, m);
    set(
        "floor",
        Material::Diffuse {
            rho_d: Rgb::splat(0.5),
        },
    );
    let metal = set(
        "small_block",
        Material::Microfacet {
            rho_d: Rgb::ZERO,
            rho_s: metal_s,
            alpha_x: metal_a,
            alpha_y: metal_a,
            theta: 0.0,
            distribution: Distribution::Ggx,
        },
    );
    let plastic = set(
        "big_block",
        Material::Plastic {
            rho_d: plastic_d,
            rho_s: Rgb::splat(f0),
            alpha: plastic_a,
            eta: DEFAULT_ETA,
            distribution: Distribution::Ggx,
        },
    );
    let (rec, _, log) = run_keeping_photo(&scene, 256, RecoverOptions::default());
    let mut table = String::new();
    for s in rec.groups.iter().filter(|s| s.is_fitted()) {
        table += &format!(
            "{:<12} {:<12} ε {:.4} ρd {:?} ρs {:?} α {:.4}\n",
            s.name,
            s.level.name(),
            s.error,
            s.params.rho_d.to_array(),
            s.params.rho_s.to_array(),
            s.params.alpha_x
        );
    }
    eprintln!("{table}");
    let m = &rec.groups[metal];
    assert_eq!(m.level, Level::Microfacet, "{table}");
    assert_eq!(m.params.distribution, Distribution::Ggx, "{table}");
    assert!((m.params.alpha_x / metal_a - 1.0).abs() < 0.05, "{table}");
    assert!(
        (m.params.rho_s - metal_s).abs().max_element() < 0.03,
        "{table}"
    );
    assert!(m.params.rho_d.max_element() < 0.03, "{table}");
    let p = &rec.groups[plastic];
    assert_eq!(p.level, Level::Plastic, "{table}");
    assert!(
        (p.params.rho_d - plastic_d).abs().max_element() < 0.03,
        "{table}"
    );
    assert!(
        (p.params.rho_s - Rgb::splat(f0)).abs().max_element() < 0.01,
        "{table}"
    );
    assert!((p.params.alpha_x / plastic_a - 1.0).abs() < 0.2, "{table}");
    for s in rec.groups.iter().filter(|s| s.is_fitted()) {
        if s.name != "small_block" && s.name != "big_block" {
            assert!(matches!(truth(&scene, &s.name), Material::Diffuse { .. }));
            assert_eq!(s.level, Level::Diffuse, "{}\n{table}", s.name);
        }
    }
    // What the GGX levels buy: on the cache where the climb tried them, the best Ward (or
    // mirror) models leave clearly larger errors.
    for (g, level) in [(metal, Level::Microfacet), (plastic, Level::Plastic)] {
        let name = &rec.groups[g].name;
        let (ward, with) = climb_errors(&log, name, level);
        eprintln!("climb of {name}: best Ward or mirror ε {ward:.4}, {level:?} {with:.4}");
        assert!(ward > 1.5 * with, "{name}: {ward} vs {with}\n{table}");
    }
}

/// In the last climb of `group` that tried `level` (its tries after the fit that began it, all
/// on that fit's cache): the lowest ε of the Ward and mirror levels it tried, and the ε of
/// `level`.
fn climb_errors(log: &[(String, Event)], group: &str, level: Level) -> (f32, f32) {
    let mut climb: Vec<(Level, f32)> = Vec::new();
    let mut found = None;
    for (_, e) in log.iter().filter(|(g, _)| g == group) {
        match e {
            Event::Fit { .. } => climb.clear(),
            Event::Tried {
                level: l,
                error_after,
                ..
            } => {
                climb.push((*l, *error_after));
                if *l == level {
                    found = Some(climb.clone());
                }
            }
            _ => {}
        }
    }
    let tries = found.expect("the level was tried");
    let ward = tries
        .iter()
        .filter(|t| t.0 < Level::Microfacet)
        .map(|t| t.1)
        .fold(f32::INFINITY, f32::min);
    (ward, tries.last().expect("the level's try").1)
}

/// Level 10 and the Beckmann distribution: figure6 with a diffuse floor and big block, its
/// small block a brushed Beckmann metal (Lambert 0 + Beckmann ρs (0.9, 0.6, 0.2), αx 0.1 along
/// the tangent, αy 0.3: Mitsuba's `roughconductor` with `distribution = "beckmann"`,
/// `alpha_u` ≠ `alpha_v`), the photo rendered by matfit at half size and recovered blind. The
/// block must climb to level 10 with Beckmann's distribution and its shape, and every other
/// group stay diffuse.
#[test]
fn a_brushed_beckmann_metal_is_recovered_at_level_10() {
    let mut scene = scaled("scenes/figure6/scene.toml", 0.5);
    let (rho_s, ax, ay) = (Rgb::new(0.9, 0.6, 0.2), 0.1f32, 0.3f32);
    let mut set = |group: &str, m: Material| set_material(&mut scene, group, m);
    set(
        "floor",
        Material::Diffuse {
            rho_d: Rgb::splat(0.5),
        },
    );
    set(
        "big_block",
        Material::Diffuse {
            rho_d: Rgb::new(0.7, 0.2, 0.1),
        },
    );
    let metal = set(
        "small_block",
        Material::Microfacet {
            rho_d: Rgb::ZERO,
            rho_s,
            alpha_x: ax,
            alpha_y: ay,
            theta: 0.0,
            distribution: Distribution::Beckmann,
        },
    );
    let rec = run_keeping_photo(&scene, 256, RecoverOptions::default()).0;
    let mut table = String::new();
    for s in rec.groups.iter().filter(|s| s.is_fitted()) {
        table += &format!(
            "{:<12} {:<22} ε {:.4} ρd {:?} ρs {:?} α ({:.4}, {:.4}) θ {:.1}° {:?}\n",
            s.name,
            s.level.name(),
            s.error,
            s.params.rho_d.to_array(),
            s.params.rho_s.to_array(),
            s.params.alpha_x,
            s.params.alpha_y,
            s.params.theta.to_degrees(),
            s.params.distribution
        );
    }
    eprintln!("{table}");
    let m = &rec.groups[metal];
    assert_eq!(m.level, Level::AnisotropicMicrofacet, "{table}");
    assert_eq!(m.params.distribution, Distribution::Beckmann, "{table}");
    assert!((m.params.alpha_x / ax - 1.0).abs() < 0.05, "{table}");
    assert!((m.params.alpha_y / ay - 1.0).abs() < 0.05, "{table}");
    assert!(m.params.theta.to_degrees().abs() < 5.0, "{table}");
    assert!(
        (m.params.rho_s - rho_s).abs().max_element() < 0.05,
        "{table}"
    );
    assert!(m.params.rho_d.max_element() < 0.05, "{table}");
    for s in rec.groups.iter().filter(|s| s.is_fitted()) {
        if s.name != "small_block" {
            assert_eq!(s.level, Level::Diffuse, "{}\n{table}", s.name);
        }
    }
}

/// The same brushed metal through the command line at another seed (photo and recovery 1),
/// where level 10's first try lowers ε by 43% but fails its unbiased-cost guard: the group must
/// not be confirmed at level 8 in that climb (a near miss), and a later climb reaches level 10.
#[test]
fn a_brushed_metal_that_misses_level_10_once_still_reaches_it() {
    use crate::common::{result_group, results, run, write};
    let d = tempfile::tempdir().unwrap();
    let text = std::fs::read_to_string(crate::common::root().join("scenes/figure6/scene.toml"))
        .unwrap()
        .replace("width = 512", "width = 256")
        .replace("height = 384", "height = 192")
        .replace(
            "material = { type = \"ward\", rho_d = 0.1, rho_s = 0.9, alpha_x = 0.07, alpha_y = 0.11, theta_deg = 0.0 }",
            "material = { type = \"diffuse\", rho_d = 0.5 }",
        )
        .replace(
            "rho_d = [0.77, 0.0, 0.0]",
            "rho_d = [0.7, 0.2, 0.1]",
        )
        .replace(
            "material = { type = \"diffuse\", rho_d = [0.0, 0.76, 0.26] }",
            "material = { type = \"microfacet\", rho_d = 0.0, rho_s = [0.9, 0.6, 0.2], alpha_x = 0.1, alpha_y = 0.3, theta_deg = 0.0, distribution = \"beckmann\" }",
        );
    assert!(text.contains("beckmann") && text.contains("rho_d = 0.5 }"));
    write(d.path(), "scene.toml", &text);
    let render = [
        "render",
        "scene.toml",
        "-o",
        "photo.exr",
        "--spp",
        "256",
        "--seed",
        "1",
    ];
    let (code, _, err) = run(&render, d.path());
    assert_eq!(code, 0, "{err}");
    let recover = [
        "recover",
        "scene.toml",
        "photo.exr",
        "-o",
        "out",
        "--exposure",
        "1",
        "--seed",
        "1",
    ];
    let (code, out, err) = run(&recover, d.path());
    assert_eq!(code, 0, "{err}");
    let res = results(&d.path().join("out"));
    let metal = result_group(&res, "small_block");
    assert_eq!(metal["level"], "anisotropic_microfacet", "{out}");
    let p = &metal["params"];
    let (ax, ay) = (
        p["alpha_x"].as_f64().unwrap(),
        p["alpha_y"].as_f64().unwrap(),
    );
    assert!(
        (ax / 0.1 - 1.0).abs() < 0.15 && (ay / 0.3 - 1.0).abs() < 0.15,
        "{out}"
    );
}
