//! The path tracer against analytic answers (the kind pbrt-v4's integrators_test keeps).

use crate::common::{diffuse, emission, mirror, run, small_scene, vec3, write, SceneToml};
use matfit::math::Rgb;
use matfit::render::film::{render, RenderOptions};
use matfit::scene::load::parse_scene;
use std::path::Path;

fn scene(text: &str) -> matfit::scene::Scene {
    parse_scene(text, Path::new("inline.toml")).unwrap()
}

/// Six inward-facing quads of a cube [-1, 1]³, each with `material` and `emission`.
fn enclosure(material: &str, emission: &str) -> String {
    let faces = [
        (
            "px",
            "[1.0, -1.0, -1.0]",
            "[0.0, 0.0, 2.0]",
            "[0.0, 2.0, 0.0]",
        ),
        (
            "nx",
            "[-1.0, -1.0, -1.0]",
            "[0.0, 2.0, 0.0]",
            "[0.0, 0.0, 2.0]",
        ),
        (
            "py",
            "[-1.0, 1.0, -1.0]",
            "[2.0, 0.0, 0.0]",
            "[0.0, 0.0, 2.0]",
        ),
        (
            "ny",
            "[-1.0, -1.0, -1.0]",
            "[0.0, 0.0, 2.0]",
            "[2.0, 0.0, 0.0]",
        ),
        (
            "pz",
            "[-1.0, -1.0, 1.0]",
            "[0.0, 2.0, 0.0]",
            "[2.0, 0.0, 0.0]",
        ),
        (
            "nz",
            "[-1.0, -1.0, -1.0]",
            "[2.0, 0.0, 0.0]",
            "[0.0, 2.0, 0.0]",
        ),
    ];
    faces
        .iter()
        .map(|(n, c, u, v)| {
            format!(
                "[[object]]\nname = \"{n}\"\ngroup = \"walls\"\nshape = \"quad\"\ncorner = {c}\nedge_u = {u}\nedge_v = {v}\n\
                 material = {material}\nemission = {emission}\n"
            )
        })
        .collect()
}

/// The white furnace: every wall of a closed cube emits Le = 0.5 and reflects ρ = 0.5, so
/// L = Le Σ ρᵏ = Le / (1 − ρ) = 1 everywhere. Rendered at 16×16, 256 spp, with `render_extra`
/// added to the `[render]` table. Returns the scene and the image.
fn furnace(render_extra: &str, seed: u64) -> (matfit::scene::Scene, matfit::io::image::Image) {
    let text = format!(
        "[render]\nmax_depth = 1000\n{render_extra}\n[camera]\nwidth = 16\nheight = 16\neye = [0.1, 0.2, 0.3]\ntarget = [0.5, -0.4, -1.0]\nfov_y_deg = 90.0\n{}",
        enclosure("{ type = \"diffuse\", rho_d = 0.5 }", "0.5")
    );
    let sc = scene(&text);
    let img = render(
        &sc,
        &sc.camera,
        &RenderOptions {
            spp: 256,
            seed,
            progress: false,
        },
    );
    (sc, img)
}

#[test]
fn white_furnace_converges_to_le_over_one_minus_rho() {
    // Inward-facing check: the camera sees the walls' front sides.
    let (_, img) = furnace("", 3);
    let mean = img.mean();
    assert!(
        (mean - Rgb::ONE).abs().max_element() < 0.01,
        "furnace mean {mean}"
    );
    let worst = img
        .data
        .iter()
        .map(|c| (c.x - 1.0).abs())
        .fold(0.0, f32::max);
    assert!(worst < 0.1, "worst pixel off by {worst}");
}

#[test]
fn russian_roulette_from_the_first_segment_stays_unbiased() {
    // The furnace with roulette on every segment (rr_depth = 1; the default is 5): paths end
    // after ~2 segments instead of ~6, and the mean must still be Le / (1 − ρ) = 1.
    let (sc, img) = furnace("rr_depth = 1", 4);
    assert_eq!(sc.render.rr_depth, 1);
    let mean = img.mean();
    assert!(
        (mean - Rgb::ONE).abs().max_element() < 0.01,
        "furnace mean with roulette from segment 1: {mean}"
    );
}

/// Form factor from a differential area to a parallel rectangle a × b at height c, with the
/// area under one corner (Howell's catalogue, C-11).
fn form_factor_corner(a: f64, b: f64, c: f64) -> f64 {
    let (x, y) = (a / c, b / c);
    let (sx, sy) = ((1.0 + x * x).sqrt(), (1.0 + y * y).sqrt());
    (x / sx * (y / sx).atan() + y / sy * (x / sy).atan()) / (2.0 * std::f64::consts::PI)
}

/// A Lambert floor (ρ 0.5) under a 0.8 × 0.6 quad light at height 0.5, seen straight down
/// through a 0.5° field of view, direct light only.
fn floor_under_a_lamp() -> String {
    SceneToml::compact()
        .render(&[("max_depth", "2")])
        .table(
            "[camera]",
            &[
                ("width", "3"),
                ("height", "3"),
                ("eye", &vec3([0.0, 0.25, 0.0])),
                ("target", &vec3([0.0; 3])),
                ("up", &vec3([0.0, 0.0, -1.0])),
                ("fov_y_deg", "0.5"),
            ],
        )
        .floor_sized(5.0, &diffuse(&[0.5]))
        .quad(
            "lamp",
            "lamp",
            [-0.4, 0.5, -0.3],
            [0.8, 0.0, 0.0],
            [0.0, 0.0, 0.6],
            &emission(&[3.0]),
        )
        .to_toml()
}

/// A mirror floor of reflectance (0.7, 0.5, 0.3) seen at 45°, reflecting an emitter of
/// radiance 2.
fn mirror_floor() -> String {
    SceneToml::compact()
        .render(&[("max_depth", "3")])
        .camera(5, 5, [0.0, 1.0, 1.0], [0.0; 3], 2.0)
        .floor_sized(2.0, &mirror(&[0.7, 0.5, 0.3]))
        .quad(
            "lamp",
            "lamp",
            [-1.0, -1.0, -2.0],
            [2.0, 0.0, 0.0],
            [0.0, 4.0, 2.0],
            &emission(&[2.0]),
        )
        .to_toml()
}

#[test]
fn lambert_plane_under_a_quad_light_matches_the_form_factor() {
    // Floor ρ = 0.5 at y = 0; emitter 0.8 × 0.6 at height 0.5, centred above the origin, facing
    // down, radiance 3. Direct light only. Radiance of the floor at the origin:
    // L = ρ/π · E = ρ · Le · F, with F = 4 F_corner(0.4, 0.3, 0.5) by symmetry.
    let text = &floor_under_a_lamp();
    let sc = scene(text);
    let img = render(
        &sc,
        &sc.camera,
        &RenderOptions {
            spp: 16384,
            seed: 5,
            progress: false,
        },
    );
    let l = img.get(1, 1).x as f64;
    let expected = 0.5 * 3.0 * 4.0 * form_factor_corner(0.4, 0.3, 0.5);
    let rel = (l - expected).abs() / expected;
    assert!(
        rel < 0.005,
        "floor radiance {l:.5} vs analytic {expected:.5} ({:.3}%)",
        rel * 100.0
    );
}

#[test]
fn mirror_shows_the_emitter_times_rho_s() {
    // A mirror floor of reflectance (0.7, 0.5, 0.3) seen at 45° reflects an emitter of radiance 2.
    let text = &mirror_floor();
    let sc = scene(text);
    let img = render(
        &sc,
        &sc.camera,
        &RenderOptions {
            spp: 16,
            seed: 1,
            progress: false,
        },
    );
    let c = img.get(2, 2);
    assert!(
        (c - Rgb::new(1.4, 1.0, 0.6)).abs().max_element() < 1e-4,
        "mirror pixel {c}"
    );
}

#[test]
fn same_seed_gives_bit_identical_images_on_one_and_two_threads() {
    let dir = tempfile::tempdir().unwrap();
    write(dir.path(), "scene.toml", &small_scene());
    let mut outputs = Vec::new();
    for threads in ["1", "2"] {
        let out = format!("t{threads}.pfm");
        let (code, _, err) = run(
            &[
                "--threads",
                threads,
                "render",
                "scene.toml",
                "-o",
                &out,
                "--spp",
                "8",
                "--seed",
                "9",
            ],
            dir.path(),
        );
        assert_eq!(code, 0, "{err}");
        outputs.push(std::fs::read(dir.path().join(out)).unwrap());
    }
    assert_eq!(outputs[0], outputs[1]);
    let (code, _, _) = run(
        &[
            "render",
            "scene.toml",
            "-o",
            "s2.pfm",
            "--spp",
            "8",
            "--seed",
            "10",
        ],
        dir.path(),
    );
    assert_eq!(code, 0);
    assert_ne!(
        std::fs::read(dir.path().join("s2.pfm")).unwrap(),
        outputs[0],
        "another seed, another image"
    );
}

/// A bundled scene at a quarter of its resolution, with another Ward normalisation.
fn quarter(name: &str, variant: &str) -> (String, std::path::PathBuf) {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../scenes")
        .join(name)
        .join("scene.toml");
    let text = std::fs::read_to_string(&path).unwrap();
    let text = text
        .lines()
        .map(|l| match l.split_once(" = ") {
            Some((key @ ("width" | "height"), v)) => {
                format!("{key} = {}", v.parse::<u32>().unwrap() / 4)
            }
            Some(("ward_variant", _)) => String::new(),
            _ if l == "[render]" => format!("[render]\nward_variant = \"{variant}\""),
            _ => l.to_string(),
        })
        .collect::<Vec<_>>()
        .join("\n");
    (text, path)
}

#[test]
fn eight_path_batches_give_the_one_path_integrators_pixels_to_the_bit() {
    // `film::render` traces eight paths at a time (`render::batch`), with Lambert, Ward and
    // ideal-mirror vertices on SIMD lanes; `film::render_pixel` traces one path at a time.
    // Every material kind (Lambert, mirror, Lambert + mirror, isotropic and anisotropic Ward, a
    // texture), both Ward normalisations, and area, directional, point and spot lights, on the
    // bundled scenes at a quarter of their resolution: the same pixels.
    let dir = tempfile::tempdir().unwrap();
    let checker = image::RgbImage::from_fn(8, 8, |x, y| {
        if (x + y) % 2 == 0 {
            image::Rgb([230, 200, 40])
        } else {
            image::Rgb([20, 90, 160])
        }
    });
    checker.save(dir.path().join("checker.png")).unwrap();
    let (cornell, cornell_path) = quarter("cornell", "ward1992");
    let first_diffuse = cornell.find("material = { type = \"diffuse\"").unwrap();
    let end = first_diffuse + cornell[first_diffuse..].find('\n').unwrap();
    let textured = format!(
        "{}material = {{ type = \"textured\", texture = \"{}\" }}{}",
        &cornell[..first_diffuse],
        dir.path().join("checker.png").display(),
        &cornell[end..]
    );
    // Punctual lights: the sunroom's sun and spot alone, and glossy's area lights with a point
    // light and a spot added (the area light first, then each punctual light, in order).
    let (glossy, glossy_path) = quarter("glossy", "balanced");
    let glossy_punctual = format!(
        "{glossy}\n[[light]]\nname = \"bulb\"\ntype = \"point\"\nposition = [0.3, 2.0, -1.5]\n\
         intensity = [2.0, 1.5, 1.0]\n\
         [[light]]\nname = \"spot\"\ntype = \"spot\"\nposition = [-1.0, 2.5, -1.0]\n\
         target = [0.0, 0.5, -3.5]\nintensity = [3.0, 3.0, 3.5]\ncutoff_deg = 30\n"
    );
    // figure6 at 9 spp: a camera packet's slot then keeps its pixel's sampler from one packet
    // to the next (`render_pixels`), which 3 spp never does.
    for (name, text, spp) in [
        ("figure6", quarter("figure6", "ward1992"), 9),
        ("glossy", quarter("glossy", "balanced"), 3),
        ("cornell, textured", (textured, cornell_path), 3),
        ("sunroom", quarter("sunroom", "ward1992"), 9),
        ("glossy, punctual", (glossy_punctual, glossy_path), 3),
    ] {
        let sc = parse_scene(&text.0, &text.1).unwrap();
        let seed = 17;
        let opts = RenderOptions {
            spp,
            seed,
            progress: false,
        };
        // `render`, and `render_image` (next-event estimation through planar mirrors too,
        // which glossy has), against the one-path integrator with the same lights.
        let plain = render(&sc, &sc.camera, &opts);
        let imaged =
            matfit::render::film::render_image(&sc, &sc.camera, &opts, |_| {}, &|| false).unwrap();
        let tracers = [
            (plain, matfit::render::PathTracer::new(&sc)),
            (
                imaged,
                matfit::render::PathTracer::new(&sc).with_mirror_lights(),
            ),
        ];
        let w = sc.camera.width as usize;
        let mut lit = 0;
        for (img, pt) in &tracers {
            for (i, px) in img.data.iter().enumerate() {
                let (x, y) = (i % w, i / w);
                let one = matfit::render::film::render_pixel(pt, &sc.camera, x, y, spp, seed);
                assert_eq!(
                    px.to_array().map(f32::to_bits),
                    one.to_array().map(f32::to_bits),
                    "{name}: pixel ({x}, {y}): {px} vs {one}"
                );
                lit += usize::from(px.max_element() > 0.0);
            }
        }
        assert!(
            lit > tracers[0].0.data.len(),
            "{name}: a dark image tests little"
        );
    }
}

#[test]
fn a_render_of_some_pixels_gives_them_the_whole_renders_values_to_the_bit() {
    // `film::render_where` renders runs of the marked pixels of a row; each must come out as
    // in the whole image (a pixel's sampler is keyed by its index), the rest black. The mask has
    // lone pixels, runs, whole rows and runs that end at the row's end.
    let (text, path) = quarter("figure6", "ward1992");
    let sc = parse_scene(&text, &path).unwrap();
    let opts = RenderOptions {
        spp: 9,
        seed: 23,
        progress: false,
    };
    let (w, h) = (sc.camera.width as usize, sc.camera.height as usize);
    let wanted: Vec<bool> = (0..w * h)
        .map(|i| {
            let (x, y) = (i % w, i / w);
            (x * 7 + y * 13) % 11 == 0 || (y % 5 == 1 && x % 17 < 6) || y == h / 2 || x + 3 >= w
        })
        .collect();
    let whole = render(&sc, &sc.camera, &opts);
    let some = matfit::render::film::render_where(&sc, &sc.camera, &opts, &wanted);
    let mut lit = 0;
    for (i, (a, b)) in whole.data.iter().zip(&some.data).enumerate() {
        let expect = if wanted[i] { *a } else { Rgb::ZERO };
        assert_eq!(
            b.to_array().map(f32::to_bits),
            expect.to_array().map(f32::to_bits),
            "pixel ({}, {}), wanted {}",
            i % w,
            i / w,
            wanted[i]
        );
        lit += usize::from(wanted[i] && a.max_element() > 0.0);
    }
    assert!(
        lit > w * h / 10,
        "too few lit marked pixels ({lit}) to test"
    );
}
