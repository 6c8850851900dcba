//! The photo's inputs: a user mask of pixels to ignore, and LDR brackets merged into
//! one linear photo by `matfit hdr`. Both through the binary on a small scene: a coloured floor
//! with a grey card on it, lit by a quad light, rendered by `matfit render`.

use crate::common::{diffuse, from_f32, run, write, SceneToml, QUICK};
use matfit::io::image::{read_linear, Image};
use matfit::math::Rgb;
use matfit::photo::Response;
use std::path::Path;

/// The floor's true ρd.
const FLOOR: [f32; 3] = [0.6, 0.45, 0.3];

/// The small room with a floor of ρd [`FLOOR`] and a dark card on it.
fn scene() -> String {
    SceneToml::spaced()
        .camera_above(64, 48)
        .floor(&diffuse(&from_f32(FLOOR)))
        .quad(
            "card",
            "card",
            [-0.8, 0.01, -0.2],
            [0.5, 0.0, 0.0],
            [0.0, 0.0, -0.5],
            &diffuse(&[0.2]),
        )
        .lamp(5.0)
        .to_toml()
}

/// Writes the scene into `dir` and renders its photo (64 spp) to `dir/photo.exr`.
fn photo(dir: &Path) -> Image {
    write(dir, "scene.toml", &scene());
    let (code, _, err) = run(
        &["render", "scene.toml", "-o", "photo.exr", "--spp", "64"],
        dir,
    );
    assert_eq!(code, 0, "{err}");
    read_linear(&dir.join("photo.exr")).unwrap()
}

/// Quick recovery of `photo` into `dir/out` with `extra` options; the floor's ρd and what
/// `recover` printed.
fn recover_floor(dir: &Path, photo: &str, extra: &[&str]) -> (Rgb, String) {
    let mut args = vec!["recover", "scene.toml", photo, "-o", "out", "--force"];
    args.extend(QUICK);
    args.extend(extra);
    let (code, out, err) = run(&args, dir);
    assert_eq!(code, 0, "{err}");
    let json = crate::common::results(&dir.join("out"));
    let floor = crate::common::result_group(&json, "floor").clone();
    let rho = &floor["params"]["rho_d"];
    let c = |k: usize| rho[k].as_f64().unwrap() as f32;
    (Rgb::new(c(0), c(1), c(2)), format!("{out}\n{floor}"))
}

/// Largest error of the floor's ρd over channels.
fn floor_error(rho: Rgb) -> f32 {
    (rho - Rgb::from(FLOOR)).abs().max_element()
}

/// Tolerance of a quick recovery of a clean photo of this scene (`clean_photo_tolerance`).
const TOL: f32 = 0.01;

#[test]
fn clean_photo_tolerance() {
    let d = tempfile::tempdir().unwrap();
    photo(d.path());
    let (rho, out) = recover_floor(d.path(), "photo.exr", &[]);
    eprintln!("clean: floor ρd {rho:?}, error {:.4}", floor_error(rho));
    assert!(floor_error(rho) < TOL, "{out}");
}

/// An unmodelled bright object (a white box over a quarter of the floor) biases the floor's
/// ρd; painted into an ignore mask, the recovery is back within the clean photo's tolerance.
#[test]
fn an_ignore_mask_removes_an_unmodelled_object() {
    let d = tempfile::tempdir().unwrap();
    let dir = d.path();
    let mut img = photo(dir);
    let (w, h) = (img.width, img.height);
    let inside = |x: usize, y: usize| (36..52).contains(&x) && (24..40).contains(&y);
    let mut mask = image::GrayImage::new(w as u32, h as u32);
    for y in 0..h {
        for x in 0..w {
            if inside(x, y) {
                img.set(x, y, img.get(x, y) * 4.0);
                mask.put_pixel(x as u32, y as u32, image::Luma([255]));
            }
        }
    }
    img.write(&dir.join("box.exr")).unwrap();
    mask.save(dir.join("mask.png")).unwrap();
    let (biased, _) = recover_floor(dir, "box.exr", &[]);
    let (masked, out) = recover_floor(dir, "box.exr", &["--ignore-mask", "mask.png"]);
    eprintln!(
        "box: floor ρd {biased:?} (error {:.4}) unmasked, {masked:?} (error {:.4}) masked",
        floor_error(biased),
        floor_error(masked)
    );
    assert!(
        floor_error(biased) > 2.0 * TOL,
        "the box does not bias: {biased:?}"
    );
    assert!(floor_error(masked) < TOL, "{out}");
    assert!(
        out.contains("mask.png: 256 pixels masked by the user"),
        "{out}"
    );
    assert!(
        out.contains("\"pixels_lost\":\"256 masked by the user"),
        "{out}"
    );
    let results = std::fs::read_to_string(dir.join("out/results.json")).unwrap();
    assert!(
        results.contains("\"ignore_mask\": \"mask.png\""),
        "{results}"
    );
    let (code, out, err) = run(
        &[
            "inspect",
            "scene.toml",
            "box.exr",
            "-o",
            "check",
            "--ignore-mask",
            "mask.png",
        ],
        dir,
    );
    assert_eq!(code, 0, "{err}");
    assert!(out.contains("256 masked by the user (mask.png)"), "{out}");
    // A mask of another size: the file and both sizes named, exit code 2.
    image::GrayImage::new(32, 24)
        .save(dir.join("small.png"))
        .unwrap();
    let mut args = vec!["recover", "scene.toml", "box.exr", "-o", "out2"];
    args.extend(["--ignore-mask", "small.png"]);
    let (code, _, err) = run(&args, dir);
    assert_eq!(code, 2, "{err}");
    assert!(
        err.contains("small.png") && err.contains("32×24") && err.contains("64×48"),
        "{err}"
    );
}

/// The camera of the brackets: gamma 2.2 then a smoothstep blend (an S-curve), code in [0, 1].
fn camera_code(linear: f32) -> f32 {
    let u = linear.clamp(0.0, 1.0).powf(1.0 / 2.2);
    0.5 * u + 0.5 * (3.0 * u * u - 2.0 * u * u * u)
}

/// Three 8-bit brackets of the rendered photo 4× apart through an S-shaped response, merged by
/// `matfit hdr` with the response recovered from them, recovered by `matfit recover` with the
/// grey card: the floor within twice the clean photo's tolerance.
#[test]
fn brackets_merged_by_hdr_are_recovered_within_twice_the_clean_tolerance() {
    let d = tempfile::tempdir().unwrap();
    let dir = d.path();
    let img = photo(dir);
    // The middle exposure puts the median of the lit pixels at linear 0.18.
    let mut lum: Vec<f32> = img
        .data
        .iter()
        .map(|c| c.element_sum() / 3.0)
        .filter(|&l| l > 0.0)
        .collect();
    lum.sort_by(f32::total_cmp);
    let k = 0.18 / lum[lum.len() / 2];
    let times = [0.25f32, 1.0, 4.0];
    let mut names = Vec::new();
    for (j, t) in times.iter().enumerate() {
        let mut b = image::RgbImage::new(img.width as u32, img.height as u32);
        for (p, c) in b.pixels_mut().zip(&img.data) {
            let code = |v: f32| (camera_code(v * k * t) * 255.0).round() as u8;
            *p = image::Rgb([code(c.x), code(c.y), code(c.z)]);
        }
        let name = format!("b{j}.png");
        b.save(dir.join(&name)).unwrap();
        names.push(name);
    }
    let mut args: Vec<&str> = vec!["hdr"];
    args.extend(names.iter().map(|s| s.as_str()));
    args.extend([
        "--times",
        "1/4,1,4",
        "-o",
        "merged.exr",
        "--response-out",
        "curve.txt",
    ]);
    let (code, out, err) = run(&args, dir);
    assert_eq!(code, 0, "{err}");
    eprintln!("{out}{err}");
    // The background is black in every exposure: counted, and given 0.
    assert!(
        err.contains("have a channel black in every exposure"),
        "{err}"
    );
    assert!(
        out.contains("wrote merged.exr (64×48, 3 8-bit exposures"),
        "{out}"
    );
    // The recovered curve against the truth (both 1 at the middle code), codes 0.1–0.95.
    let table = Response::parse(&format!("table:{}", dir.join("curve.txt").display())).unwrap();
    let truth = |z: f32| {
        let (mut lo, mut hi) = (0.0f32, 1.0f32);
        for _ in 0..40 {
            let m = 0.5 * (lo + hi);
            if camera_code(m) < z {
                lo = m;
            } else {
                hi = m;
            }
        }
        0.5 * (lo + hi)
    };
    let curve = (26..=242)
        .map(|m| {
            let z = m as f32 / 255.0;
            (table.linearize(z) / (truth(z) / truth(127.0 / 255.0)) - 1.0).abs()
        })
        .fold(0.0, f32::max);
    let (clean, _) = recover_floor(dir, "photo.exr", &["--grey-card", "card=0.2"]);
    let (merged, rec) = recover_floor(dir, "merged.exr", &["--grey-card", "card=0.2"]);
    eprintln!(
        "hdr: curve error {curve:.4}; floor ρd {merged:?} (error {:.4}) from the merge, \
         {clean:?} (error {:.4}) from the clean photo, both with the grey card",
        floor_error(merged),
        floor_error(clean)
    );
    assert!(curve < 0.03, "curve error {curve}");
    assert!(floor_error(clean) < TOL, "{rec}");
    assert!(floor_error(merged) < 2.0 * TOL, "{rec}");
    // Counts that do not match, and a float image, are refused.
    let (code, _, err) = run(
        &["hdr", "b0.png", "b1.png", "--times", "1,2,3", "-o", "x.exr"],
        dir,
    );
    assert_eq!(code, 2);
    assert!(err.contains("2 images but 3 exposure times"), "{err}");
    let (code, _, err) = run(
        &[
            "hdr",
            "b0.png",
            "photo.exr",
            "--times",
            "1,2",
            "-o",
            "x.exr",
        ],
        dir,
    );
    assert_eq!(code, 2);
    assert!(err.contains("photo.exr: a float image"), "{err}");
}

#[test]
fn vignetting_is_divided_out_by_its_radial_model_or_a_flat_field() {
    // The photo through a lens that darkens the corners to 70% (Lensfun's model, r = 1 at the
    // half-diagonal); the same fall-off photographed on a white card is the flat field.
    let d = tempfile::tempdir().unwrap();
    let clean = photo(d.path());
    let a = [-0.35f32, 0.05, 0.0];
    let (w, h) = (clean.width, clean.height);
    let hd2 = 0.25 * (w * w + h * h) as f32;
    let v = |i: usize| {
        let (x, y) = (
            (i % w) as f32 + 0.5 - 0.5 * w as f32,
            (i / w) as f32 + 0.5 - 0.5 * h as f32,
        );
        let r2 = (x * x + y * y) / hd2;
        1.0 + a[0] * r2 + a[1] * r2 * r2
    };
    let (mut vignetted, mut flat) = (clean.clone(), Image::new(w, h));
    for i in 0..w * h {
        vignetted.data[i] *= v(i);
        flat.data[i] = Rgb::splat(0.8 * v(i));
    }
    vignetted.write(&d.path().join("vignetted.exr")).unwrap();
    flat.write(&d.path().join("flat.exr")).unwrap();
    let (rho, out) = recover_floor(d.path(), "vignetted.exr", &["--vignetting", "-0.35,0.05,0"]);
    let radial = floor_error(rho);
    assert!(radial < TOL, "radial model: {out}");
    let (rho, out) = recover_floor(d.path(), "vignetted.exr", &["--flat-field", "flat.exr"]);
    let flat_field = floor_error(rho);
    assert!(flat_field < TOL, "flat field: {out}");
    // Uncorrected, the floor comes out dark.
    let (rho, _) = recover_floor(d.path(), "vignetted.exr", &[]);
    let none = floor_error(rho);
    assert!(
        none > 1.5 * TOL && none > 3.0 * radial.max(flat_field),
        "uncorrected {none} vs radial {radial}, flat field {flat_field}: {rho:?}"
    );
}

#[test]
fn a_16_bit_tiff_read_as_linear_is_recovered_like_the_float_photo() {
    // A raw converter's linear 16-bit TIFF: codes = radiance × 65535 / 4 (the stated scale is
    // --exposure 0.25: photo = k × radiance with codes read as [0, 1]).
    let d = tempfile::tempdir().unwrap();
    let clean = photo(d.path());
    let (w, h) = (clean.width as u32, clean.height as u32);
    let codes: Vec<u16> = clean
        .data
        .iter()
        .flat_map(|c| c.to_array())
        .map(|x| (x * 0.25 * 65535.0).round().clamp(0.0, 65535.0) as u16)
        .collect();
    let tiff = image::ImageBuffer::<image::Rgb<u16>, Vec<u16>>::from_raw(w, h, codes).unwrap();
    tiff.save(d.path().join("photo.tif")).unwrap();
    let (rho, out) = recover_floor(
        d.path(),
        "photo.tif",
        &["--response", "linear", "--exposure", "0.25"],
    );
    assert!(floor_error(rho) < TOL, "16-bit TIFF: {out}");
}
