//! A simulated real capture: figure6 photographed through a distorting, vignetting
//! lens whose pose is not quite the model's, with a non-linear response, noise, and three 8-bit
//! brackets; merged by `matfit hdr`, recovered by `matfit recover` with the lens, the
//! vignetting and a grey card given, as a user of a real camera would.

use crate::common::{root, run, write};
use image::RgbImage;

/// The lens (OpenCV k1, k2, p1, p2, k3) and its vignetting (Lensfun a1, a2, a3).
const DISTORTION: &str = "[-0.12, 0.03, 0.0005, -0.0003, 0.0]";
const VIGNETTING: [f32; 3] = [-0.3, 0.05, 0.0];

/// figure6 at `w`×`h` with its lens and a grey card (fixed, ρ 0.18) on the back wall.
fn scene_text(w: u32, h: u32) -> String {
    let text = std::fs::read_to_string(root().join("scenes/figure6/scene.toml")).unwrap();
    text.replace("width = 512", &format!("width = {w}"))
        .replace("height = 384", &format!("height = {h}"))
        .replace(
            "fov_y_deg = 40.0\n",
            &format!("fov_y_deg = 40.0\ndistortion = {DISTORTION}\n"),
        )
        + r#"
[[group]]
name = "card"
fixed = true

[[object]]
name = "card"
group = "card"
shape = "quad"
corner = [-1.7, 0.9, -6.99]
edge_u = [0.8, 0.0, 0.0]
edge_v = [0.0, 0.8, 0.0]
material = { type = "diffuse", rho_d = 0.18 }
"#
}

/// The model a user has before the fit: figure6's geometry, lights and grey card, every other
/// material a placeholder (diffuse 0.5). The grey card's first calibration renders the card
/// with these, 23% off here; the fit renders it again with what it recovers.
fn placeholder_materials(text: &str) -> String {
    text.lines()
        .map(|l| {
            if l.starts_with("material = ") && !l.contains("0.18") {
                r#"material = { type = "diffuse", rho_d = 0.5 }"#
            } else {
                l
            }
        })
        .collect::<Vec<_>>()
        .join("\n")
}

/// An S-shaped camera response (as tests/photo_inputs.rs): linear → code in [0, 1].
fn camera_code(linear: f32) -> f32 {
    let u = linear.clamp(0.0, 1.0).powf(1.0 / 2.2);
    0.5 * u + 0.5 * (3.0 * u * u - 2.0 * u * u * u)
}

/// A standard normal draw from a counter (Box–Muller on a hash).
fn gauss(i: u64) -> f32 {
    let h = |x: u64| {
        let mut z = x.wrapping_add(0x9E37_79B9_7F4A_7C15);
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64
    };
    let (u1, u2) = (h(2 * i).max(1e-12), h(2 * i + 1));
    ((-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()) as f32
}

fn params(dir: &std::path::Path, out: &str) -> serde_json::Value {
    crate::common::results(&dir.join(out))
}

/// The truth is figure6's table; the capture differs from the model by its pose (`pose`: eye
/// moved 2 cm, view turned 1°, found by `--refine-pose`; or not), its lens and vignetting, a
/// response, 1% noise and 8 bits, and its exposure is found from the grey card in a model whose
/// other materials are placeholders. Every parameter is compared with the truth within twice
/// the tolerance of the clean photo (the radiance through the true camera, exposure known),
/// fitted with the same settings, both as medians over `seeds` runs (at 128×96 one run's ρ
/// scatters by 0.01–0.03 from seed to seed, and two seeds in six put a block 0.2 off) — and the exposure within 1% of the one that made the
/// brackets (1.5% with the pose off, below). With the pose off, the pose must be found within 0.1° and 1 cm: the refinement
/// against the placeholders alone (no quick fit) found 1.18° and a 3.3 cm lift, and the floor
/// came out ρd 0.074 for 0.1 and θ −4.8°.
fn capture_is_recovered(pose: bool, (width, height): (u32, u32), seeds: u64) {
    let d = tempfile::tempdir().unwrap();
    let keep = std::env::var_os("MATFIT_KEEP").map(std::path::PathBuf::from);
    let dir = keep.as_deref().unwrap_or(d.path());
    let text = scene_text(width, height);
    write(dir, "scene.toml", &text);
    write(dir, "model.toml", &placeholder_materials(&text));
    // The camera that took the photo.
    let (eye, target) = if pose {
        // 1° about the vertical through the eye, and 2 cm to the right.
        let (s, c) = 1f64.to_radians().sin_cos();
        let (tx, tz) = (0.0f64, -1.139693 + 0.2);
        (
            [0.02, 1.6, -0.2],
            [0.02 + c * tx - s * tz, 1.25798, -0.2 + s * tx + c * tz],
        )
    } else {
        ([0.0f64, 1.6, -0.2], [0.0f64, 1.25798, -1.139693])
    };
    write(
        dir,
        "taken.toml",
        &format!(
            "[camera]\neye = {eye:?}\ntarget = {target:?}\nfov_y_deg = 40.0\ndistortion = {DISTORTION}\n"
        ),
    );
    let (code, _, err) = run(
        &[
            "render",
            "scene.toml",
            "--edit",
            "taken.toml",
            "--spp",
            "256",
            "-o",
            "radiance.exr",
        ],
        dir,
    );
    assert_eq!(code, 0, "{err}");
    let img = matfit::io::image::read_linear(&dir.join("radiance.exr")).unwrap();
    let (w, h) = (img.width, img.height);
    // Vignetting about the image centre (the look-at camera's principal point), r = 1 at the
    // half-diagonal.
    let half_diag = 0.5 * ((w * w + h * h) as f32).sqrt();
    let v = |x: usize, y: usize| {
        let (dx, dy) = (
            x as f32 + 0.5 - 0.5 * w as f32,
            y as f32 + 0.5 - 0.5 * h as f32,
        );
        let r2 = (dx * dx + dy * dy) / (half_diag * half_diag);
        1.0 + r2 * (VIGNETTING[0] + r2 * (VIGNETTING[1] + r2 * VIGNETTING[2]))
    };
    // The middle exposure puts the 90th percentile of the luminance at 0.5.
    let mut lum: Vec<f32> = img.data.iter().map(|c| c.element_sum() / 3.0).collect();
    lum.sort_by(f32::total_cmp);
    let k = 0.5 / lum[lum.len() * 9 / 10];
    let mut linear = img.clone();
    for (i, c) in linear.data.iter_mut().enumerate() {
        *c *= v(i % w, i / w) * k;
    }
    linear.write(&dir.join("linear.exr")).unwrap();
    let times = [0.25f32, 1.0, 4.0];
    for (j, t) in times.iter().enumerate() {
        let mut b = RgbImage::new(w as u32, h as u32);
        for (i, (p, c)) in b.pixels_mut().zip(&img.data).enumerate() {
            let (x, y) = (i % w, i / w);
            let code = |ch: u64, lin: f32| {
                // 1% noise on the sensor's linear value, then the response and 8 bits.
                let n = 1.0 + 0.01 * gauss((j as u64 * 3 + ch) << 32 | i as u64);
                (camera_code(lin * v(x, y) * k * t * n) * 255.0).round() as u8
            };
            *p = image::Rgb([code(0, c.x), code(1, c.y), code(2, c.z)]);
        }
        b.save(dir.join(format!("b{j}.png"))).unwrap();
    }
    let (code, _, err) = run(
        &[
            "hdr",
            "b0.png",
            "b1.png",
            "b2.png",
            "--times",
            "1/4,1,4",
            "-o",
            "merged.exr",
        ],
        dir,
    );
    assert_eq!(code, 0, "{err}");
    let vig = format!("{},{},{}", VIGNETTING[0], VIGNETTING[1], VIGNETTING[2]);
    let recover = |photo: &str, out: &str, extra: &[&str]| {
        // `--model FILE` first in `extra`: another scene file than model.toml.
        let (model, extra) = match extra {
            ["--model", m, rest @ ..] => (*m, rest),
            _ => ("model.toml", extra),
        };
        let mut args = vec![
            "recover",
            model,
            photo,
            "-o",
            out,
            "--force",
            "--final-spp",
            "4",
        ];
        args.extend(extra);
        let (code, stdout, err) = run(&args, dir);
        assert_eq!(code, 0, "{stdout}\n{err}");
        (Fit::of(&params(dir, out)), stdout)
    };
    // The clean photo: the radiance through the camera that took it, exposure known.
    let through_taken = placeholder_materials(&text)
        .replace("eye = [0.0, 1.6, -0.2]", &format!("eye = {eye:?}"))
        .replace(
            "target = [0.0, 1.257980, -1.139693]",
            &format!("target = {target:?}"),
        );
    write(dir, "clean.toml", &through_taken);
    // Each recovery with `seeds` seeds; the parameters compared are the medians (the first
    // seed's run is the one whose exposure, pose and output are checked).
    let seeds: Vec<String> = (0..seeds).map(|s| s.to_string()).collect();
    let clean = Fit::median(seeds.iter().map(|seed| {
        let out = format!("clean{seed}");
        let args = [
            "--model",
            "clean.toml",
            "--exposure",
            "1",
            "--camera-is-calibrated",
            "--seed",
            seed,
        ];
        recover("radiance.exr", &out, &args).0
    }));
    let mut args = vec!["--vignetting", &vig, "--grey-card", "card=0.18"];
    if pose {
        args.push("--refine-pose");
    }
    let runs: Vec<(Fit, String)> = (seeds.iter())
        .map(|seed| {
            let out = if seed == "0" {
                "out".to_string()
            } else {
                format!("out{seed}")
            };
            let args = [&args[..], &["--seed", seed]].concat();
            recover("merged.exr", &out, &args)
        })
        .collect();
    let stdout = runs[0].1.clone();
    let got = Fit::median(runs.into_iter().map(|r| r.0));
    // The exposure: the brackets' merge over the radiance that made them (vignetted).
    let merged = matfit::io::image::read_linear(&dir.join("merged.exr")).unwrap();
    let (mut sm, mut sr) = (0.0f64, 0.0f64);
    for (i, (m, r)) in merged.data.iter().zip(&img.data).enumerate() {
        sm += m.element_sum() as f64;
        sr += (r.element_sum() * v(i % w, i / w)) as f64;
    }
    let k_true = sm / sr;
    let k = params(dir, "out")["inputs"]["exposure"].as_f64().unwrap();
    eprintln!("exposure {k:.4}, true {k_true:.4}\n{stdout}");
    // 1% through the right pose (128×96). At 256×192 the grey card's few pixels leave ±1%
    // whatever the pose: through the exact camera, given, these brackets gave +0.9%.
    let k_tol = if pose { 0.015 } else { 0.01 };
    assert!(
        (k / k_true - 1.0).abs() < k_tol,
        "exposure {k} for {k_true}\n{stdout}"
    );
    assert!(stdout.contains("recalibrated from grey card"), "{stdout}");
    let found = params(dir, "out")["inputs"]["registration"]["rotation_deg"]
        .as_f64()
        .unwrap();
    if pose {
        let moved = &params(dir, "out")["inputs"]["registration"]["translation"];
        let off: f64 = (0..3)
            .map(|i| moved[i].as_f64().unwrap() - [0.02, 0.0, 0.0][i])
            .map(|d| d * d)
            .sum::<f64>()
            .sqrt();
        assert!(
            (found - 1.0).abs() < 0.1 && off < 0.01,
            "camera turned by {found}° and moved by {moved}, not 1° and (0.02, 0, 0)"
        );
    }
    // Every group of figure6 is uniform: what the misregistration leaves along the blocks'
    // edges is not a print.
    let levels: Vec<String> = params(dir, "out")["groups"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|g| g["level"] == "textured")
        .map(|g| g["name"].to_string())
        .collect();
    assert!(levels.is_empty(), "textured: {levels:?}\n{stdout}");
    let truth = Fit::truth();
    // Each parameter within twice the clean photo's tolerance: its error on the clean photo
    // (128×96 pixels leave the blocks ±0.06), at least 0.01 for ρ, 4% for α, 2° for θ. The
    // reflectances are compared with the exposure's own error taken out (checked above: a k
    // 0.7% high makes every ρ 0.7% low), so that the figures judge the materials and the pose.
    let exposure_error = k / k_true;
    let mut report = String::new();
    let mut bad = Vec::new();
    for (k, (name, t)) in truth.0.iter().enumerate() {
        let c = clean.0[k].1;
        let g = if name.starts_with("ρ") {
            got.0[k].1 * exposure_error
        } else {
            got.0[k].1
        };
        let floor = if name.starts_with("α") {
            0.04 * t
        } else if name.starts_with("θ") {
            2.0
        } else {
            0.01
        };
        let tol = 2.0 * (c - t).abs().max(floor);
        report +=
            &format!("{name}: truth {t:.4}, clean {c:.4}, capture {g:.4} (tolerance {tol:.4}; ρ with the exposure error out)\n");
        if (g - t).abs() > tol {
            bad.push(name.clone());
        }
    }
    eprintln!("{report}");
    assert!(bad.is_empty(), "{bad:?}\n{report}\n{stdout}");
}

/// Every fitted parameter of figure6's seen groups, named (ρ per channel, the floor's lobe).
struct Fit(Vec<(String, f64)>);

impl Fit {
    const GROUPS: [(&'static str, [f64; 3]); 6] = [
        ("back_wall", [0.65, 0.65, 0.0]),
        ("left_wall", [0.66, 0.66, 0.66]),
        ("right_wall", [0.69, 0.0, 0.95]),
        ("big_block", [0.77, 0.0, 0.0]),
        ("small_block", [0.0, 0.76, 0.26]),
        ("floor", [0.1, 0.1, 0.1]),
    ];

    fn truth() -> Fit {
        let mut v = Vec::new();
        for (g, rho) in Fit::GROUPS {
            for (c, r) in rho.iter().enumerate() {
                v.push((format!("ρd {g} {c}"), *r));
            }
        }
        for c in 0..3 {
            v.push((format!("ρs floor {c}"), 0.9));
        }
        v.push(("αx floor".into(), 0.07));
        v.push(("αy floor".into(), 0.11));
        v.push(("θ floor".into(), 0.0));
        Fit(v)
    }

    /// Each parameter's median over `fits` (an odd number of them).
    fn median(fits: impl Iterator<Item = Fit>) -> Fit {
        let fits: Vec<Fit> = fits.collect();
        let mid = |k: usize| {
            let mut v: Vec<f64> = fits.iter().map(|f| f.0[k].1).collect();
            v.sort_by(f64::total_cmp);
            v[v.len() / 2]
        };
        Fit((0..fits[0].0.len())
            .map(|k| (fits[0].0[k].0.clone(), mid(k)))
            .collect())
    }

    fn of(res: &serde_json::Value) -> Fit {
        use crate::common::{json_rgb, result_group};
        let group = |name: &str| result_group(res, name)["params"].clone();
        let rgb = |p: &serde_json::Value, k: &str| json_rgb(&p[k]);
        let mut v = Vec::new();
        for (g, _) in Fit::GROUPS {
            for (c, r) in rgb(&group(g), "rho_d").into_iter().enumerate() {
                v.push((format!("ρd {g} {c}"), r));
            }
        }
        let floor = group("floor");
        for (c, r) in rgb(&floor, "rho_s").into_iter().enumerate() {
            v.push((format!("ρs floor {c}"), r));
        }
        let (ax, ay) = (
            floor["alpha_x"].as_f64().unwrap(),
            floor["alpha_y"].as_f64().unwrap_or(f64::NAN),
        );
        let theta = floor["theta_deg"].as_f64().unwrap_or(f64::NAN);
        // αx along the tangent at θ = 0 is the same lobe as αy there at θ = 90°.
        let (ax, ay, theta) = if (theta.rem_euclid(180.0) - 90.0).abs() < 45.0 {
            (ay, ax, theta - 90.0)
        } else {
            (ax, ay, theta)
        };
        v.push(("αx floor".into(), ax));
        v.push(("αy floor".into(), ay));
        v.push(("θ floor".into(), (theta + 90.0).rem_euclid(180.0) - 90.0));
        Fit(v)
    }
}

#[test]
fn a_simulated_capture_through_the_right_pose_is_recovered_from_its_brackets() {
    capture_is_recovered(false, (128, 96), 3);
}

/// At 128×96 the pose refinement trades the 1° turn for a 7 cm lift (1.7°; the blocks' edges
/// are a few pixels long), so this one is at 256×192 (about two minutes on two cores).
#[test]
fn a_simulated_capture_off_by_a_degree_and_2_cm_is_recovered_with_its_pose_refined() {
    capture_is_recovered(true, (256, 192), 1);
}

/// The same at figure6's own 512×384, for the absolute figures asked of a capture (ρ within 0.01, α 4%,
/// θ 2°), printed: `cargo test --profile ci --test tests capture::full -- --ignored
/// --nocapture` (several minutes).
#[test]
#[ignore]
fn full_size_capture_off_by_a_degree_and_2_cm() {
    capture_is_recovered(true, (512, 384), 1);
}
