//! Directional, point and spot lights (`[[light]]`) against analytic answers, through the
//! renderer and the binary. A Lambert floor of reflectance ρ lit by one of them reflects
//! L = ρ/π · E cos θ (directional, irradiance E), ρ/π · I cos θ / d² (point), and the spot's
//! falloff (linear in angle from the beam to the cutoff, Mitsuba 3's) times the latter.

use crate::common::{diffuse, from_f32, run, write, SceneToml};
use matfit::math::{Rgb, Vec2, Vec3};
use matfit::render::film::{render, RenderOptions};
use matfit::scene::load::parse_scene;
use std::path::Path;

const RHO: [f32; 3] = [0.2, 0.5, 0.8];

/// A camera looking down at a large Lambert floor (y = 0), `extra` appended (lights, blockers).
fn floor_scene(extra: &str) -> matfit::scene::Scene {
    let text = SceneToml::compact()
        .render(&[("max_depth", "8")])
        .camera(24, 18, [0.0, 3.0, 0.5], [0.0; 3], 50.0)
        .floor_sized(20.0, &diffuse(&from_f32(RHO)))
        .raw(extra)
        .to_toml();
    parse_scene(&text, Path::new("inline.toml")).unwrap()
}

fn rendered(sc: &matfit::scene::Scene, spp: u32) -> matfit::io::image::Image {
    render(
        sc,
        &sc.camera,
        &RenderOptions {
            spp,
            seed: 1,
            progress: false,
        },
    )
}

/// The mean over pixel (x, y) of `radiance(floor point)`, on a 12×12 grid of film positions.
fn pixel_mean(
    sc: &matfit::scene::Scene,
    x: usize,
    y: usize,
    radiance: impl Fn(Vec3) -> f32,
) -> f32 {
    let n = 12;
    let mut sum = 0.0;
    for j in 0..n {
        for i in 0..n {
            let film = Vec2::new(
                x as f32 + (i as f32 + 0.5) / n as f32,
                y as f32 + (j as f32 + 0.5) / n as f32,
            );
            let ray = sc.camera.ray(film);
            let t = -ray.o.y / ray.d.y;
            sum += radiance(ray.o + ray.d * t);
        }
    }
    sum / (n * n) as f32
}

#[test]
fn a_directional_light_gives_rho_over_pi_e_cos() {
    // Every floor point gets the same light: each pixel is exact, not an estimate.
    let sc = floor_scene(
        "[[light]]\nname = \"sun\"\ntype = \"directional\"\ndirection = [0.6, -1.0, 0.3]\nirradiance = [2.0, 3.0, 4.0]\n",
    );
    let img = rendered(&sc, 2);
    let cos = 1.0 / Vec3::new(0.6, -1.0, 0.3).length();
    let e = Rgb::new(2.0, 3.0, 4.0);
    let want = Rgb::from(RHO) * e * (cos / std::f32::consts::PI);
    for (i, c) in img.data.iter().enumerate() {
        let rel = ((*c - want) / want).abs().max_element();
        assert!(rel < 1e-5, "pixel {i}: {c} vs {want}");
    }
}

#[test]
fn point_and_spot_lights_fall_off_as_the_inverse_square_and_the_cone() {
    let (p, i) = (Vec3::new(0.3, 1.2, -0.2), 2.5f32);
    let point = floor_scene(&format!(
        "[[light]]\nname = \"bulb\"\ntype = \"point\"\nposition = [{}, {}, {}]\nintensity = {i}\n",
        p.x, p.y, p.z
    ));
    // A spot aimed straight down, cutoff 30°, beam 20°: its edge crosses the view.
    let spot = floor_scene(&format!(
        "[[light]]\nname = \"spot\"\ntype = \"spot\"\nposition = [{}, {}, {}]\ndirection = [0, -1, 0]\nintensity = {i}\ncutoff_deg = 30\nbeam_width_deg = 20\n",
        p.x, p.y, p.z
    ));
    let point_l = |q: Vec3| {
        let d = p - q;
        RHO[1] / std::f32::consts::PI * i * (d.y / d.length()) / d.length_squared()
    };
    let falloff = |q: Vec3| {
        let angle = (-(q - p).normalize().y).acos().to_degrees();
        ((30.0 - angle) / 10.0).clamp(0.0, 1.0)
    };
    let (ip, is) = (rendered(&point, 64), rendered(&spot, 64));
    let (mut inside, mut outside, mut edge) = (0, 0, 0);
    for y in 0..18 {
        for x in 0..24 {
            let want = pixel_mean(&point, x, y, point_l);
            let got = ip.get(x, y).y;
            assert!(
                (got - want).abs() < 2e-3 * want,
                "point light, pixel ({x}, {y}): {got} vs {want}"
            );
            let want = pixel_mean(&spot, x, y, |q| point_l(q) * falloff(q));
            let got = is.get(x, y).y;
            assert!(
                (got - want).abs() < 2e-3 * point_l(Vec3::ZERO),
                "spot light, pixel ({x}, {y}): {got} vs {want}"
            );
            match want {
                0.0 => outside += 1,
                w if (w - pixel_mean(&point, x, y, point_l)).abs() < 1e-6 => inside += 1,
                _ => edge += 1,
            }
        }
    }
    // The view holds the beam, the ramp and the dark outside.
    assert!(
        inside >= 10 && outside > 20 && edge > 20,
        "{inside} {outside} {edge}"
    );
}

#[test]
fn a_blocker_casts_the_directional_lights_shadow() {
    // A black box floats above the floor; the sun's shadow is its outline moved along the
    // light's direction. Pixels wholly inside the shadow are black, wholly outside lit.
    let dir = Vec3::new(1.5, -1.0, 0.0).normalize();
    let sc = floor_scene(&format!(
        "[[object]]\nname = \"box\"\ngroup = \"box\"\nshape = \"box\"\nmin = [-0.4, 0.5, -0.4]\nmax = [0.4, 0.7, 0.4]\nmaterial = {{ type = \"black\" }}\n\
         [[light]]\nname = \"sun\"\ntype = \"directional\"\ndirection = [{}, {}, {}]\nirradiance = 3\n",
        dir.x, dir.y, dir.z
    ));
    let img = rendered(&sc, 16);
    // Floor point q is in shadow if q − dir·t, t > 0, passes through the box (slab test).
    let shadowed = |q: Vec3| {
        let (lo, hi) = (Vec3::new(-0.4, 0.5, -0.4), Vec3::new(0.4, 0.7, 0.4));
        let d = -dir;
        let (mut t0, mut t1) = (0.0f32, f32::INFINITY);
        for k in 0..3 {
            if d[k].abs() < 1e-9 {
                if q[k] < lo[k] || q[k] > hi[k] {
                    return false;
                }
                continue;
            }
            let (a, b) = ((lo[k] - q[k]) / d[k], (hi[k] - q[k]) / d[k]);
            t0 = t0.max(a.min(b));
            t1 = t1.min(a.max(b));
        }
        t0 <= t1
    };
    let lit = RHO[1] / std::f32::consts::PI * 3.0 * dir.y.abs();
    let (mut dark, mut bright) = (0, 0);
    for y in 0..18 {
        for x in 0..24 {
            let frac = pixel_mean(&sc, x, y, |q| f32::from(u8::from(shadowed(q))));
            // What the camera sees of the box itself is black too; skip those pixels.
            let sees_box = (0..36).any(|k| {
                let film = Vec2::new(
                    x as f32 + (k % 6) as f32 / 5.0,
                    y as f32 + (k / 6) as f32 / 5.0,
                );
                let hit = sc.intersect(&sc.camera.ray(film), f32::INFINITY).unwrap();
                sc.objects[hit.object as usize].name == "box"
            });
            if sees_box {
                continue;
            }
            let got = img.get(x, y).y;
            if frac == 1.0 {
                dark += 1;
                assert_eq!(got, 0.0, "pixel ({x}, {y}) is in the shadow");
            } else if frac == 0.0 {
                bright += 1;
                assert!(
                    (got - lit).abs() < 1e-5 * lit,
                    "pixel ({x}, {y}): {got} vs {lit}"
                );
            }
        }
    }
    assert!(
        dark >= 4 && bright > 100,
        "{dark} shadowed, {bright} lit pixels"
    );
}

#[test]
fn lights_are_checked_listed_and_exported_through_the_binary() {
    let dir = tempfile::tempdir().unwrap();
    let base = SceneToml::compact()
        .camera_above(32, 24)
        .floor("")
        .to_toml();
    // A scene lit only by a punctual light is a scene with light.
    let ok = write(
        dir.path(),
        "ok.toml",
        &format!("{base}[[light]]\nname = \"sun\"\ntype = \"directional\"\ndirection = [0, -1, 0]\nirradiance = 2\n\
                  [[light]]\nname = \"spot\"\ntype = \"spot\"\nposition = [0, 2, 0]\ntarget = [0, 0, 0]\nintensity = 3\n"),
    );
    let (code, out, err) = run(&["info", ok.to_str().unwrap()], dir.path());
    assert_eq!(code, 0, "{err}");
    assert!(out.contains("light sun: directional"), "{out}");
    assert!(out.contains("cutoff 20°"), "{out}");
    // A key of another kind of light is named, with the line.
    let bad = write(
        dir.path(),
        "bad.toml",
        &format!("{base}[[light]]\nname = \"sun\"\ntype = \"directional\"\nposition = [0, 1, 0]\nirradiance = 2\n"),
    );
    let (code, _, err) = run(
        &["render", bad.to_str().unwrap(), "-o", "x.png"],
        dir.path(),
    );
    assert_eq!(code, 2, "{err}");
    assert!(
        err.contains("bad.toml:16") && err.contains("takes no `position`"),
        "{err}"
    );
    // Export to Mitsuba and import back: the same lights.
    let (code, _, err) = run(&["export", "mitsuba", "ok.toml", "-o", "mts"], dir.path());
    assert_eq!(code, 0, "{err}");
    let (code, _, err) = run(
        &["import", "mitsuba", "mts/scene.xml", "-o", "back.toml"],
        dir.path(),
    );
    assert_eq!(code, 0, "{err}");
    let a = matfit::scene::load_scene(&ok).unwrap();
    let b = matfit::scene::load_scene(&dir.path().join("back.toml")).unwrap();
    assert_eq!(a.punctual_lights.len(), b.punctual_lights.len());
    for (la, lb) in a.punctual_lights.iter().zip(&b.punctual_lights) {
        assert_eq!(la.name, lb.name);
        let (x, y) = (format!("{:?}", la.kind), format!("{:?}", lb.kind));
        let nums = |s: &str| -> Vec<f32> {
            s.split(|c: char| !(c.is_ascii_digit() || c == '.' || c == '-' || c == 'e'))
                .filter_map(|t| t.parse().ok())
                .collect()
        };
        let (nx, ny) = (nums(&x), nums(&y));
        assert_eq!(nx.len(), ny.len(), "{x} vs {y}");
        assert!(
            nx.iter().zip(&ny).all(|(p, q)| (p - q).abs() < 1e-5),
            "{x} vs {y}"
        );
    }
}

/// A bundled scene at half size (256×192 → 128×96) copied with its other files into `dir`, its
/// photo rendered by matfit with the true materials (256 spp) and recovered blind through the
/// binary. Returns the true scene and results.json.
fn recover_half_size(name: &str, dir: &Path) -> (matfit::scene::Scene, serde_json::Value) {
    let src = crate::common::root().join("scenes").join(name);
    for f in std::fs::read_dir(&src).unwrap() {
        let f = f.unwrap().path();
        std::fs::copy(&f, dir.join(f.file_name().unwrap())).unwrap();
    }
    let text = std::fs::read_to_string(src.join("scene.toml"))
        .unwrap()
        .replace("width = 256\n", "width = 128\n")
        .replace("height = 192\n", "height = 96\n");
    let scene = write(dir, "scene.toml", &text);
    let s = scene.to_str().unwrap();
    let (code, _, err) = run(&["render", s, "--spp", "256", "-o", "photo.exr"], dir);
    assert_eq!(code, 0, "{err}");
    let (code, out, err) = run(&["recover", s, "photo.exr", "-o", "out"], dir);
    assert_eq!(code, 0, "{out}{err}");
    let json = crate::common::results(&dir.join("out"));
    (parse_scene(&text, &scene).unwrap(), json)
}

#[test]
fn a_room_lit_only_by_the_sun_and_a_spot_is_recovered_through_the_binary() {
    // scenes/sunroom: no area light.
    let dir = tempfile::tempdir().unwrap();
    let (truth, json) = recover_half_size("sunroom", dir.path());
    for g in json["groups"].as_array().unwrap() {
        let name = g["name"].as_str().unwrap();
        let o = truth.objects.iter().find(|o| o.name == name).unwrap();
        let got = |k: &str| -> Vec<f32> {
            g["params"][k]
                .as_array()
                .unwrap()
                .iter()
                .map(|x| x.as_f64().unwrap() as f32)
                .collect()
        };
        let close = |k: &str, want: Rgb| {
            let v = got(k);
            assert!(
                (0..3).all(|c| (v[c] - want[c]).abs() < 0.01),
                "{name} {k}: {v:?} vs {want}"
            );
        };
        match o.material {
            matfit::scene::Material::Diffuse { rho_d } => close("rho_d", rho_d),
            matfit::scene::Material::Ward {
                rho_d,
                rho_s,
                alpha_x,
                ..
            } => {
                close("rho_d", rho_d);
                close("rho_s", rho_s);
                let a = g["params"]["alpha_x"].as_f64().unwrap() as f32;
                assert!(
                    (a / alpha_x - 1.0).abs() < 0.05,
                    "{name} α {a} vs {alpha_x}"
                );
                assert_eq!(g["level"], "isotropic", "{g}");
            }
            _ => unreachable!("sunroom has diffuse and Ward groups"),
        }
    }
}

#[test]
fn a_uniform_environment_lights_a_floor_to_rho_times_its_radiance() {
    // A constant map of radiance c (times `scale`): an unoccluded Lambert floor receives π·c·s
    // and reflects ρ·c·s; rays that miss everything see c·s.
    let dir = tempfile::tempdir().unwrap();
    let mut map = matfit::io::image::Image::new(6, 4);
    map.data.fill(Rgb::new(0.5, 1.0, 2.0));
    map.write(&dir.path().join("sky.pfm")).unwrap();
    let text = &SceneToml::open_floor()
        .raw("[environment]\nfile = \"sky.pfm\"\nscale = 1.5\nrotate_deg = [10, 40, 0]\n")
        .to_toml();
    let path = write(dir.path(), "scene.toml", text);
    let sc = matfit::scene::load_scene(&path).unwrap();
    let img = rendered(&sc, 64);
    let c = Rgb::new(0.5, 1.0, 2.0) * 1.5;
    let (mut floor, mut n_floor, mut sky) = (Rgb::ZERO, 0, 0);
    for y in 0..18 {
        for x in 0..24 {
            let hits = crate::common::film_hits(&sc, x, y);
            let got = img.get(x, y);
            if hits == 0 {
                sky += 1;
                assert!((got - c).abs().max_element() < 1e-5, "({x}, {y}): {got}");
            } else if hits == 16 {
                floor += got;
                n_floor += 1;
            }
        }
    }
    let floor = floor / n_floor as f32;
    let want = Rgb::from(RHO) * c;
    assert!(
        ((floor - want) / want).abs().max_element() < 0.01,
        "floor {floor} vs ρ·c {want}"
    );
    assert!(
        sky > 20 && n_floor > 100,
        "{sky} sky, {n_floor} floor pixels"
    );
}

#[test]
fn a_room_lit_by_an_hdr_sky_is_recovered_and_its_envmap_round_trips_through_mitsuba() {
    let dir = tempfile::tempdir().unwrap();
    let (truth, json) = recover_half_size("skyroom", dir.path());
    let s = dir.path().join("scene.toml");
    let s = s.to_str().unwrap();
    for g in json["groups"].as_array().unwrap() {
        let name = g["name"].as_str().unwrap();
        let o = truth.objects.iter().find(|o| o.name == name).unwrap();
        let want = match o.material {
            matfit::scene::Material::Diffuse { rho_d } => rho_d,
            matfit::scene::Material::Ward { .. } => {
                // At this size the sky-lit ball's lobe is not pinned down (it may end
                // diffuse + mirror): it must at least be glossy.
                let rho_s = g["params"]["rho_s"][1].as_f64().unwrap();
                assert!(rho_s > 0.05, "{name}: {g}");
                continue;
            }
            _ => unreachable!(),
        };
        let v = &g["params"]["rho_d"];
        for c in 0..3 {
            let got = v[c].as_f64().unwrap() as f32;
            assert!((got - want[c]).abs() < 0.01, "{name}: {v} vs {want}");
        }
    }
    // Export to Mitsuba and import back: the same environment, to rounding.
    let (code, _, err) = run(&["export", "mitsuba", s, "-o", "mts"], dir.path());
    assert_eq!(code, 0, "{err}");
    let (code, _, err) = run(
        &["import", "mitsuba", "mts/scene.xml", "-o", "back.toml"],
        dir.path(),
    );
    assert_eq!(code, 0, "{err}");
    let back = matfit::scene::load_scene(&dir.path().join("back.toml")).unwrap();
    let (a, b) = (
        truth.environment.as_ref().unwrap(),
        back.environment.as_ref().unwrap(),
    );
    for k in 0..50 {
        let t = k as f32 * 0.7;
        let d = Vec3::new(
            t.sin() * (0.3 * t).cos(),
            (0.3 * t).sin(),
            t.cos() * (0.3 * t).cos(),
        )
        .normalize();
        let (x, y) = (a.radiance(d), b.radiance(d));
        assert!(
            (x - y).abs().max_element() <= 1e-3 * x.max_element().max(1.0),
            "{d}: {x} vs {y}"
        );
    }
}

#[test]
fn a_sun_with_an_angular_size_gives_the_same_irradiance_and_soft_shadows() {
    // A directional light 15° wide: the floor still receives E cos θ (the disc's radiance is
    // E / (π sin²7.5°)), and the shadow of a black slab has a penumbra that the parallel light
    // lacks.
    let dir = Vec3::new(0.5, -1.0, 0.2).normalize();
    let light = |angle: &str| {
        format!(
            "[[object]]\nname = \"slab\"\ngroup = \"slab\"\nshape = \"box\"\nmin = [-0.3, 1.5, -0.3]\nmax = [0.3, 1.52, 0.3]\nmaterial = {{ type = \"black\" }}\n\
             [[light]]\nname = \"sun\"\ntype = \"directional\"\ndirection = [{}, {}, {}]\nirradiance = 3\n{angle}",
            dir.x, dir.y, dir.z
        )
    };
    let sharp = floor_scene(&light(""));
    let soft = floor_scene(&light("angle_deg = 15\n"));
    let (a, b) = (rendered(&sharp, 64), rendered(&soft, 64));
    let lit = RHO[1] / std::f32::consts::PI * 3.0 * dir.y.abs();
    let (mut sum, mut n, mut penumbra_sharp, mut penumbra_soft) = (0.0f64, 0, 0, 0);
    // Pixels that see some of the slab are partly black in both: left out.
    let sees_slab = |i: usize| {
        (0..16).any(|k| {
            let film = Vec2::new(
                (i % 24) as f32 + (k % 4) as f32 / 3.0,
                (i / 24) as f32 + (k / 4) as f32 / 3.0,
            );
            let hit = sharp.intersect(&sharp.camera.ray(film), f32::INFINITY);
            hit.is_some_and(|h| sharp.objects[h.object as usize].name == "slab")
        })
    };
    for (i, (pa, pb)) in a.data.iter().zip(&b.data).enumerate() {
        if sees_slab(i) {
            continue;
        }
        // Far from the shadow both see the whole sun.
        if (pa.y - lit).abs() < 1e-5 * lit {
            sum += pb.y as f64;
            n += 1;
        }
        let partial = |v: f32| v > 0.05 * lit && v < 0.95 * lit;
        penumbra_sharp += usize::from(partial(pa.y));
        penumbra_soft += usize::from(partial(pb.y));
    }
    let mean = (sum / n as f64) as f32;
    assert!(n > 200, "{n}");
    assert!(
        (mean - lit).abs() < 0.01 * lit,
        "lit floor {mean} vs E cos θ ρ/π {lit}"
    );
    // The penumbra: pixels partly lit. The sharp shadow has them only where a pixel straddles
    // its edge.
    assert!(
        penumbra_soft > 2 * penumbra_sharp && penumbra_soft > 30,
        "partly lit pixels: {penumbra_sharp} sharp, {penumbra_soft} soft"
    );
}

/// OpenCV's distortion of normalised coordinates, as its documentation writes the model.
fn opencv_distort(k: [f32; 5], x: f32, y: f32) -> (f32, f32) {
    let r2 = x * x + y * y;
    let radial = 1.0 + k[0] * r2 + k[1] * r2 * r2 + k[4] * r2 * r2 * r2;
    (
        x * radial + 2.0 * k[2] * x * y + k[3] * (r2 + 2.0 * x * x),
        y * radial + k[2] * (r2 + 2.0 * y * y) + 2.0 * k[3] * x * y,
    )
}

#[test]
fn a_distorted_camera_sees_each_point_where_opencvs_model_puts_it() {
    // scenes/sunroom through a barrel-distorting lens (corners move ~15 px): the group seen at
    // pinhole pixel p is the one the distorted render shows at OpenCV's distort(p).
    let dir = tempfile::tempdir().unwrap();
    let k = [-0.25f32, 0.05, 0.002, -0.001, 0.0];
    let text =
        std::fs::read_to_string(crate::common::root().join("scenes/sunroom/scene.toml")).unwrap();
    let distorted = text.replace(
        "fov_y_deg = 45.0\n",
        &format!(
            "fov_y_deg = 45.0\ndistortion = [{}, {}, {}, {}, {}]\n",
            k[0], k[1], k[2], k[3], k[4]
        ),
    );
    assert_ne!(text, distorted);
    write(dir.path(), "pinhole.toml", &text);
    write(dir.path(), "lens.toml", &distorted);
    for name in ["pinhole", "lens"] {
        let (code, _, err) = run(
            &[
                "render",
                &format!("{name}.toml"),
                "--aov",
                "group",
                "-o",
                &format!("{name}.pfm"),
            ],
            dir.path(),
        );
        assert_eq!(code, 0, "{err}");
    }
    let read = |n: &str| matfit::io::image::read_linear(&dir.path().join(n)).unwrap();
    let (pin, lens) = (read("pinhole.pfm"), read("lens.pfm"));
    let cam = parse_scene(&text, Path::new("x.toml")).unwrap().camera;
    let (w, h) = (pin.width, pin.height);
    let id = |img: &matfit::io::image::Image, x: usize, y: usize| img.get(x, y).x;
    let (mut same, mut same_unmapped, mut n, mut moved) = (0, 0, 0, 0.0f32);
    for y in 1..h - 1 {
        for x in 1..w - 1 {
            let g = id(&pin, x, y);
            // Inside a group (no edge in the 5×5 neighbourhood), so a sub-pixel error cannot
            // change the answer.
            let interior = (y.saturating_sub(2)..(y + 3).min(h))
                .all(|j| (x.saturating_sub(2)..(x + 3).min(w)).all(|i| id(&pin, i, j) == g));
            if !interior {
                continue;
            }
            let (nx, ny) = (
                (x as f32 + 0.5 - cam.cx) / cam.fx,
                (y as f32 + 0.5 - cam.cy) / cam.fy,
            );
            let (dx, dy) = opencv_distort(k, nx, ny);
            let (px, py) = (dx * cam.fx + cam.cx, dy * cam.fy + cam.cy);
            if px < 0.0 || py < 0.0 || px >= w as f32 || py >= h as f32 {
                continue;
            }
            moved =
                moved.max(((px - x as f32 - 0.5).powi(2) + (py - y as f32 - 0.5).powi(2)).sqrt());
            n += 1;
            same += usize::from(id(&lens, px as usize, py as usize) == g);
            same_unmapped += usize::from(id(&lens, x, y) == g);
        }
    }
    assert!(moved > 10.0, "the lens moves points by up to {moved} px");
    assert!(same as f32 > 0.999 * n as f32, "{same} of {n} agree");
    // Read without the model, the distorted image disagrees where the lens moved things.
    assert!(
        same_unmapped < same - 100,
        "{same_unmapped} vs {same} of {n}"
    );
}

#[test]
fn a_photo_through_a_distorting_lens_is_recovered_with_the_lens_model_and_not_without() {
    let dir = tempfile::tempdir().unwrap();
    let text = std::fs::read_to_string(crate::common::root().join("scenes/sunroom/scene.toml"))
        .unwrap()
        .replace("width = 256\n", "width = 128\n")
        .replace("height = 192\n", "height = 96\n");
    let lens = text.replace(
        "fov_y_deg = 45.0\n",
        "fov_y_deg = 45.0\ndistortion = [-0.25, 0.05, 0.002, -0.001, 0.0]\n",
    );
    write(dir.path(), "pinhole.toml", &text);
    write(dir.path(), "lens.toml", &lens);
    let (code, _, err) = run(
        &["render", "lens.toml", "--spp", "256", "-o", "photo.exr"],
        dir.path(),
    );
    assert_eq!(code, 0, "{err}");
    let truth = parse_scene(&text, Path::new("x.toml")).unwrap();
    // The largest error of any ρd, and how many groups ended textured.
    let recovered = |scene: &str, out: &str| -> (f32, usize) {
        let (code, o, err) = run(&["recover", scene, "photo.exr", "-o", out], dir.path());
        assert_eq!(code, 0, "{o}{err}");
        let json = crate::common::results(&dir.path().join(out));
        let (mut worst, mut textured) = (0.0f32, 0);
        for g in json["groups"].as_array().unwrap() {
            if g["level"] == "textured" {
                textured += 1;
                continue;
            }
            let o = truth.objects.iter().find(|o| o.name == g["name"]).unwrap();
            let want = match o.material {
                matfit::scene::Material::Diffuse { rho_d } => rho_d,
                matfit::scene::Material::Ward { rho_d, .. } => rho_d,
                _ => unreachable!(),
            };
            for c in 0..3 {
                let got = g["params"]["rho_d"][c].as_f64().unwrap() as f32;
                worst = worst.max((got - want[c]).abs());
            }
        }
        (worst, textured)
    };
    let (worst, textured) = recovered("lens.toml", "with");
    assert!(
        worst < 0.01 && textured == 0,
        "with the lens: {worst}, {textured} textured"
    );
    // Without the lens model the outlines miss the photo's by up to ~8 px here: groups take
    // their neighbours' pixels and climb to textures to explain them.
    let (worst, textured) = recovered("pinhole.toml", "without");
    assert!(
        worst > 0.02 || textured > 0,
        "without: {worst}, {textured} textured"
    );
}

/// A Lambert sphere of reflectance ρ alone in the scene (nothing occludes it) against the
/// analytic irradiance, binned by the hit's normal n (16 bins of n·a over the pixels whose 4×4
/// sub-samples all hit): under a distant light of irradiance E along −l, L = ρ/π · E max(0, n·l);
/// under a sky of radiance a + b ω_y (equirectangular, 512×256), E(n) = π a + (2π/3) b n_y, so
/// L = ρ (a + (2/3) b n_y) (the irradiance of a linear radiance field: Ramamoorthi & Hanrahan
/// 2001, the l ≤ 1 bands). Every bin within 0.5%.
#[test]
fn a_lambert_sphere_matches_the_analytic_irradiance_of_a_sun_and_of_a_sky() {
    let dir = tempfile::tempdir().unwrap();
    let (a, b) = (1.0f32, 0.8f32);
    let (w, h) = (512, 256);
    let mut sky = matfit::io::image::Image::new(w, h);
    for y in 0..h {
        let theta = (y as f32 + 0.5) / h as f32 * std::f32::consts::PI;
        for x in 0..w {
            sky.set(x, y, Rgb::splat(a + b * theta.cos()));
        }
    }
    sky.write(&dir.path().join("sky.exr")).unwrap();
    let l = Vec3::new(-0.4, 0.7, 0.6).normalize();
    let sphere = |lights: &str| {
        SceneToml::compact()
            .render(&[("max_depth", "2")])
            .camera(64, 64, [0.0, 0.0, 4.0], [0.0; 3], 30.0)
            .sphere("ball", "ball", [0.0; 3], 1.0, Some(512), &diffuse(&[0.6]))
            .raw(lights)
            .to_toml()
    };
    let sun = format!(
        "[[light]]\nname = \"sun\"\ntype = \"directional\"\ndirection = [{}, {}, {}]\nirradiance = 3.0\n",
        -l.x, -l.y, -l.z
    );
    type Analytic = Box<dyn Fn(Vec3) -> f32>;
    let cases: [(String, u32, Vec3, Analytic); 2] = [
        (
            sun,
            4,
            l,
            Box::new(move |n: Vec3| 0.6 / std::f32::consts::PI * 3.0 * n.dot(l).max(0.0)),
        ),
        (
            "[environment]\nfile = \"sky.exr\"\n".to_string(),
            1024,
            Vec3::Y,
            Box::new(move |n: Vec3| 0.6 * (a + 2.0 / 3.0 * b * n.y)),
        ),
    ];
    for (lights, spp, axis, analytic) in cases {
        let path = write(dir.path(), "scene.toml", &sphere(&lights));
        let sc = matfit::scene::load_scene(&path).unwrap();
        let img = rendered(&sc, spp);
        let bins = 16;
        let (mut got, mut want, mut n) = (vec![0.0f64; bins], vec![0.0f64; bins], vec![0; bins]);
        for y in 0..64 {
            for x in 0..64 {
                // The pixel's mean analytic radiance over its 4×4 sub-samples, all on the ball.
                let mut sum = 0.0f32;
                let mut normal = Vec3::ZERO;
                let mut all = true;
                for k in 0..16 {
                    let film = Vec2::new(
                        x as f32 + (k % 4) as f32 / 4.0 + 0.125,
                        y as f32 + (k / 4) as f32 / 4.0 + 0.125,
                    );
                    match sc.intersect(&sc.camera.ray(film), f32::INFINITY) {
                        Some(hit) => {
                            let nrm = hit.p.normalize();
                            sum += analytic(nrm) / 16.0;
                            normal += nrm;
                        }
                        None => all = false,
                    }
                }
                let c = normal.normalize().dot(axis);
                // Away from the terminator, where the mesh's facets and the sphere differ most.
                if !all || c < 0.15 {
                    continue;
                }
                let bin = ((c * bins as f32) as usize).min(bins - 1);
                got[bin] += img.get(x, y).x as f64;
                want[bin] += sum as f64;
                n[bin] += 1;
            }
        }
        let mut checked = 0;
        for k in 0..bins {
            if n[k] < 8 {
                continue;
            }
            let rel = got[k] / want[k] - 1.0;
            assert!(
                rel.abs() < 0.005,
                "{}: bin {k} ({} px): {:.4} vs analytic {:.4} ({:+.2}%)",
                lights.lines().next().unwrap(),
                n[k],
                got[k] / n[k] as f64,
                want[k] / n[k] as f64,
                100.0 * rel
            );
            checked += 1;
        }
        assert!(checked >= 10, "{checked} bins checked");
    }
}
