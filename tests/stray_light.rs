//! Stray light: `[stray_light]`, a constant environment of radiance S that every ray
//! leaving the scene sees, rendered against the analytic answer, carried through Mitsuba's
//! `constant` emitter both ways, and fitted with the materials by `recover --stray-light` on an
//! open room whose photo has it and whose model does not.

use crate::common::{result_group, results, root, run, small_scene, write, SceneToml};
use matfit::math::Rgb;
use matfit::render::film::{render, RenderOptions};
use matfit::scene::load::parse_scene;
use matfit::scene::{load_scene, Material};
use std::path::Path;

const S: [f32; 3] = [0.3, 0.6, 0.9];

/// A grey-blue floor seen from above, open to the sky, lit by the stray light alone.
fn floor() -> String {
    SceneToml::open_floor()
        .raw("[stray_light]\nradiance = [0.3, 0.6, 0.9]\n")
        .to_toml()
}

#[test]
fn a_stray_light_lights_an_open_floor_to_rho_times_its_radiance() {
    // An unoccluded Lambert floor under a constant environment S receives π S and reflects ρ S
    // (a cosine-sampled bounce weighs every direction alike: no noise); rays that miss see S.
    let dir = tempfile::tempdir().unwrap();
    let sc = parse_scene(&floor(), &dir.path().join("floor.toml")).unwrap();
    let img = render(
        &sc,
        &sc.camera,
        &RenderOptions {
            spp: 16,
            seed: 3,
            progress: false,
        },
    );
    let s = Rgb::from(S);
    let want = Rgb::new(0.2, 0.5, 0.8) * s;
    let (mut floor, mut sky) = (0, 0);
    for y in 0..18 {
        for x in 0..24 {
            let hits = crate::common::film_hits(&sc, x, y);
            let got = img.get(x, y);
            if hits == 0 {
                sky += 1;
                assert!((got - s).abs().max_element() < 1e-5, "({x}, {y}): {got}");
            } else if hits == 16 {
                floor += 1;
                assert!(
                    ((got - want) / want).abs().max_element() < 1e-4,
                    "({x}, {y}): {got} vs ρ S {want}"
                );
            }
        }
    }
    assert!(sky > 20 && floor > 100, "{sky} sky, {floor} floor pixels");
}

#[test]
fn a_stray_light_goes_to_mitsuba_as_a_constant_emitter_and_comes_back() {
    let dir = tempfile::tempdir().unwrap();
    let scene = write(dir.path(), "floor.toml", &floor());
    let (code, out, err) = run(
        &["export", "mitsuba", scene.to_str().unwrap(), "-o", "mi"],
        dir.path(),
    );
    assert_eq!(code, 0, "{out}{err}");
    let xml = std::fs::read_to_string(dir.path().join("mi/scene.xml")).unwrap();
    assert!(
        xml.contains("<emitter type=\"constant\">")
            && xml.contains("<rgb name=\"radiance\" value=\"0.3, 0.6, 0.9\"/>"),
        "{xml}"
    );
    let (code, out, err) = run(
        &["import", "mitsuba", "mi/scene.xml", "-o", "back.toml"],
        dir.path(),
    );
    assert_eq!(code, 0, "{out}{err}");
    let back = load_scene(&dir.path().join("back.toml")).unwrap();
    assert_eq!(back.stray_light, Rgb::from(S));
}

#[test]
fn a_negative_stray_light_is_an_error_naming_its_line() {
    let dir = tempfile::tempdir().unwrap();
    let text = floor().replace("[0.3, 0.6, 0.9]", "[0.3, -0.6, 0.9]");
    let scene = write(dir.path(), "floor.toml", &text);
    let (code, _, err) = run(
        &["render", scene.to_str().unwrap(), "-o", "x.exr"],
        dir.path(),
    );
    assert_eq!(code, 2, "{err}");
    assert!(
        err.contains("[stray_light]")
            && err.contains("not negative")
            && err.contains("floor.toml:18:"),
        "{err}"
    );
}

/// scenes/sunroom at half size (128×96) as a model, and as the truth with a stray light of
/// (0.05, 0.05, 0.06) added.
pub fn sunroom_with_stray_light() -> (String, String) {
    let text = std::fs::read_to_string(root().join("scenes/sunroom/scene.toml"))
        .unwrap()
        .replace("width = 256\n", "width = 128\n")
        .replace("height = 192\n", "height = 96\n");
    let truth = format!("{text}\n[stray_light]\nradiance = [0.05, 0.05, 0.06]\n");
    (text, truth)
}

/// Renders `truth` (256 spp) as the photo in `d` and recovers `model` from it with
/// `--stray-light` and `extra` into `d/out`: the recovery's standard output.
fn render_and_recover_with_stray_light(
    d: &Path,
    truth: &Path,
    model: &Path,
    extra: &[&str],
) -> String {
    let (code, _, err) = run(
        &[
            "render",
            truth.to_str().unwrap(),
            "--spp",
            "256",
            "-o",
            "photo.exr",
        ],
        d,
    );
    assert_eq!(code, 0, "{err}");
    let mut args = vec![
        "recover",
        model.to_str().unwrap(),
        "photo.exr",
        "--stray-light",
    ];
    args.extend(extra);
    args.extend(["-o", "out"]);
    let (code, out, err) = run(&args, d);
    assert_eq!(code, 0, "{out}{err}");
    out
}

#[test]
fn a_stray_light_is_fitted_with_the_materials_through_the_binary() {
    // scenes/sunroom (open-topped) at half size. The photo has a stray light of 8% of the
    // seen light, which the model does not; fitted with it, every group is as if there were
    // none.
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let (text, truth) = sunroom_with_stray_light();
    let truth_path = write(d, "truth.toml", &truth);
    let model = write(d, "model.toml", &text);
    let out = render_and_recover_with_stray_light(d, &truth_path, &model, &[]);
    // The summary states the estimate (its value is checked in results.json below).
    assert!(out.contains("stray light (0.0"), "{out}");
    let json = results(&d.join("out"));
    let s = &json["stray_light"];
    let want = [0.05, 0.05, 0.06];
    for c in 0..3 {
        let got = s["radiance"][c].as_f64().unwrap();
        let sigma = s["sigma"][c].as_f64().unwrap();
        assert!(
            (got / want[c] - 1.0).abs() < 0.05 && sigma > 0.0 && sigma < 0.005,
            "stray light {s}"
        );
    }
    assert_eq!(s["estimated"], true, "{s}");
    // Every group as without stray light in the photo: the level of its truth, ρ within 0.01.
    let truth_scene = parse_scene(&truth, &truth_path).unwrap();
    for o in &truth_scene.objects {
        let g = result_group(&json, &o.name);
        let rgb = |k: &str| crate::common::json_rgb(&g["params"][k]);
        let close = |k: &str, want: Rgb| {
            let v = rgb(k);
            assert!(
                (0..3).all(|c| (v[c] as f32 - want[c]).abs() < 0.01),
                "{} {k}: {v:?} vs {want}",
                o.name
            );
        };
        match o.material {
            Material::Diffuse { rho_d } => {
                assert_eq!(g["level"], "diffuse", "{g}");
                close("rho_d", rho_d);
            }
            Material::Ward {
                rho_d,
                rho_s,
                alpha_x,
                ..
            } => {
                assert_eq!(g["level"], "isotropic", "{g}");
                close("rho_d", rho_d);
                close("rho_s", rho_s);
                let a = g["params"]["alpha_x"].as_f64().unwrap() as f32;
                assert!((a / alpha_x - 1.0).abs() < 0.03, "α {a} vs {alpha_x}");
            }
            _ => unreachable!("sunroom has diffuse and Ward groups"),
        }
    }
    // The recovered scene keeps the stray light.
    let rec = load_scene(&d.join("out/recovered.toml")).unwrap();
    let got = rec.stray_light;
    assert!((got.x / 0.05 - 1.0).abs() < 0.05, "recovered.toml: {got}");
}

/// The same with the ball a rough plastic, fitted where only the levels that export to Mitsuba
/// exactly are allowed (`--exportable mitsuba`: the ball must climb to plastic or microfacet,
/// levels 8–10): the stray light is estimated there as well as beside Ward.
#[test]
fn a_stray_light_is_fitted_beside_a_plastic_ball_through_the_binary() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let (text, truth) = sunroom_with_stray_light();
    let ward =
        "material = { type = \"ward\", rho_d = [0.3, 0.3, 0.1], rho_s = 0.15, alpha = 0.12 }";
    let plastic =
        "material = { type = \"plastic\", rho_d = [0.3, 0.3, 0.1], rho_s = 0.04, alpha = 0.12 }";
    assert!(truth.contains(ward));
    let truth_path = write(d, "truth.toml", &truth.replace(ward, plastic));
    let model = write(d, "model.toml", &text);
    render_and_recover_with_stray_light(d, &truth_path, &model, &["--exportable", "mitsuba"]);
    let json = results(&d.join("out"));
    let ball = result_group(&json, "ball");
    eprintln!("ball: {ball}\nstray light: {}", json["stray_light"]);
    assert_eq!(ball["level"], "plastic", "{ball}");
    let rho_d = crate::common::json_rgb(&ball["params"]["rho_d"]);
    let want_rho_d = [0.3, 0.3, 0.1];
    assert!(
        (0..3).all(|c| (rho_d[c] - want_rho_d[c]).abs() < 0.01),
        "ball ρd {rho_d:?}"
    );
    let alpha = ball["params"]["alpha_x"].as_f64().unwrap();
    assert!((alpha / 0.12 - 1.0).abs() < 0.05, "ball α {alpha}");
    let s = &json["stray_light"];
    assert_eq!(s["estimated"], true, "{s}");
    let want = [0.05, 0.05, 0.06];
    for c in 0..3 {
        let got = s["radiance"][c].as_f64().unwrap();
        let sigma = s["sigma"][c].as_f64().unwrap();
        assert!(
            (got / want[c] - 1.0).abs() < 0.05 && sigma > 0.0,
            "stray light {s}"
        );
    }
    // The diffuse groups as without stray light.
    let truth_scene = parse_scene(&truth, &truth_path).unwrap();
    for o in &truth_scene.objects {
        if let Material::Diffuse { rho_d } = o.material {
            let v = crate::common::json_rgb(&result_group(&json, &o.name)["params"]["rho_d"]);
            assert!(
                (0..3).all(|c| (v[c] as f32 - rho_d[c]).abs() < 0.015),
                "{} ρd {v:?} vs {rho_d}",
                o.name
            );
        }
    }
}

#[test]
fn three_photos_of_a_glossy_ball_share_one_stray_light() {
    // scenes/lightstage at 64×64: three photos, each under one distant light, all with the
    // same stray light (10% of the seen light). A texture could take the stray light's shape
    // texel by texel, so no group tries level 7 while it is undetermined, and the ball stays
    // the Ward lobe it is.
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let text = std::fs::read_to_string(root().join("scenes/lightstage/scene.toml"))
        .unwrap()
        .replace("width = 192", "width = 64")
        .replace("height = 192", "height = 64");
    let model = write(d, "model.toml", &text);
    let truth = write(
        d,
        "truth.toml",
        &format!("{text}\n[stray_light]\nradiance = [0.02, 0.02, 0.02]\n"),
    );
    for (view, name) in [("1", "a.exr"), ("10", "b.exr"), ("19", "c.exr")] {
        let args = [
            "render",
            truth.to_str().unwrap(),
            "--view",
            view,
            "--spp",
            "64",
            "-o",
            name,
        ];
        let (code, _, err) = run(&args, d);
        assert_eq!(code, 0, "{err}");
    }
    let (code, out, err) = run(
        &[
            "recover",
            model.to_str().unwrap(),
            "a.exr",
            "b.exr",
            "c.exr",
            "--views",
            "1,10,19",
            "--no-register",
            "--stray-light",
            "-o",
            "out",
        ],
        d,
    );
    assert_eq!(code, 0, "{out}{err}");
    let json = results(&d.join("out"));
    let s = &json["stray_light"];
    for c in 0..3 {
        let got = s["radiance"][c].as_f64().unwrap();
        assert!((got / 0.02 - 1.0).abs() < 0.03, "stray light {s}");
    }
    let g = result_group(&json, "ball");
    assert_eq!(g["level"], "isotropic", "{g}");
    let rho_d = crate::common::json_rgb(&g["params"]["rho_d"]);
    for (c, want) in [0.35, 0.2, 0.12].into_iter().enumerate() {
        assert!((rho_d[c] - want).abs() < 0.01, "ρd {rho_d:?}");
    }
    for v in json["views"].as_array().unwrap() {
        let k = v["exposure"].as_f64().unwrap();
        assert!((k - 1.0).abs() < 0.01, "{v}");
    }
}

#[test]
fn a_recovery_of_an_open_scene_says_what_it_assumes_of_the_outside() {
    // A floor under a lamp, open all round: without --stray-light the run warns, naming the
    // option (and the summary repeats it); with it there is no such warning.
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    write(d, "scene.toml", &small_scene());
    let (code, _, err) = run(&["render", "scene.toml", "--spp", "8", "-o", "p.exr"], d);
    assert_eq!(code, 0, "{err}");
    let quick = ["--max-iterations", "1", "--final-spp", "2"];
    let mut args = vec!["recover", "scene.toml", "p.exr", "-o", "a"];
    args.extend(quick);
    let (code, out, err) = run(&args, d);
    assert_eq!(code, 0, "{err}");
    let said = |s: &str| s.contains("the scene is open: ") && s.contains("--stray-light fits it");
    assert!(said(&err), "{out}\n{err}");
    args.push("--stray-light");
    args[4] = "b";
    let (code, out, err) = run(&args, d);
    assert_eq!(code, 0, "{err}");
    assert!(!said(&err) && !said(&out), "{out}\n{err}");
}

#[test]
fn inspect_measures_the_open_share_before_any_fit() {
    // `matfit inspect` says how much of what the seen surfaces face is no geometry, and warns
    // as a recovery would where the model lets no light in from there. A floor under the open
    // sky: every ray from it leaves, 100% exactly; with its stray light the model accounts for
    // that, without it the warning names the option. figure6, a closed room: 0%, no warning.
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let sun = "\n[[light]]\nname = \"sun\"\ntype = \"directional\"\n\
               direction = [0.3, -1.0, -0.2]\nirradiance = [2.0, 2.0, 2.0]\n";
    let lit = format!("{}{sun}", floor());
    let open = format!("{}{sun}", SceneToml::open_floor().to_toml());
    let figure6 = std::fs::read_to_string(root().join("scenes/figure6/scene.toml"))
        .unwrap()
        .replace("width = 512", "width = 64")
        .replace("height = 384", "height = 48");
    let warned =
        |s: &str| s.contains("warning: the scene is open: ") && s.contains("--stray-light");
    for (name, text, share, light, warns) in [
        (
            "lit",
            lit.as_str(),
            "100.0%",
            "the stray light (0.3, 0.6, 0.9)",
            false,
        ),
        ("open", open.as_str(), "100.0%", "none", true),
        ("closed", figure6.as_str(), "0.0%", "none", false),
    ] {
        let scene = format!("{name}.toml");
        write(d, &scene, text);
        let photo = format!("{name}.exr");
        let (code, _, err) = run(&["render", &scene, "--spp", "4", "-o", &photo], d);
        assert_eq!(code, 0, "{err}");
        let args = [
            "inspect",
            &scene,
            &photo,
            "--camera-is-calibrated",
            "-o",
            name,
        ];
        let (code, out, err) = run(&args, d);
        assert_eq!(code, 0, "{err}");
        let line = out
            .lines()
            .find(|l| l.starts_with("open share: "))
            .unwrap_or("");
        assert!(
            line.starts_with(&format!("open share: {share} ")),
            "{name}: {out}"
        );
        assert!(
            line.ends_with(&format!("light from outside the model: {light}")),
            "{name}: {line}"
        );
        assert_eq!(warned(&out), warns, "{name}: {out}");
    }
}
