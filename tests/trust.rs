//! Trust on real inputs: a Mitsuba hand-off that states what it approximates, error bars and
//! status words that say what is known, a recovered.toml that says what it is, and messages
//! that keep their meaning.

use crate::common::{root, run, small_scene, write, QUICK};
use std::path::Path;

/// The comment that opens an exported scene.xml.
fn xml_header(dir: &Path) -> String {
    let xml = std::fs::read_to_string(dir.join("scene.xml")).unwrap();
    let start = xml.find("<!--").expect("a header comment");
    let end = start + xml[start..].find("-->").unwrap();
    xml[start..end].to_string()
}

/// Writes `scene` as `dir/scene.toml` and renders its photo, `dir/photo.exr`, at `spp`.
fn scene_and_photo(dir: &Path, scene: &str, spp: u32) {
    write(dir, "scene.toml", scene);
    let spp = spp.to_string();
    let (code, _, err) = run(
        &["render", "scene.toml", "-o", "photo.exr", "--spp", &spp],
        dir,
    );
    assert_eq!(code, 0, "{err}");
}

/// figure6's Ward floor goes to Mitsuba as a microfacet lobe fitted to it, whose remaining
/// error is printed and listed in the file; a scene without Ward says it approximates nothing.
#[test]
fn the_mitsuba_export_fits_ward_and_lists_every_approximation() {
    let d = tempfile::tempdir().unwrap();
    let dir = d.path();
    let scene = root().join("scenes/figure6/scene.toml");
    let (code, _, err) = run(
        &["export", "mitsuba", scene.to_str().unwrap(), "-o", "mi"],
        dir,
    );
    assert_eq!(code, 0, "{err}");
    let warnings: Vec<&str> = err
        .lines()
        .filter_map(|l| l.strip_prefix("warning: "))
        .collect();
    let floor = warnings
        .iter()
        .find(|w| w.starts_with("object 'floor': Ward has no Mitsuba equivalent"))
        .unwrap_or_else(|| panic!("{err}"));
    assert!(floor.contains("fitted to the lobe"), "{floor}");
    // The remaining error, stated in numbers, below what Ward's own α leaves.
    let pct = |after: &str| -> f64 {
        let s = &floor[floor.find(after).unwrap() + after.len()..];
        s[..s.find('%').unwrap()].trim().parse().unwrap()
    };
    let (lobe, naive) = (pct("differs from Ward by "), pct("would leave "));
    eprintln!("{floor}");
    assert!(lobe <= naive, "{floor}");
    let header = xml_header(&dir.join("mi"));
    assert!(header.contains("Approximations:\n"), "{header}");
    for w in &warnings {
        let w = w.replace("--", "- -");
        assert!(header.contains(&format!("- {w}")), "{w} not in\n{header}");
    }
    let xml = std::fs::read_to_string(dir.join("mi/scene.xml")).unwrap();
    assert!(xml.contains("roughconductor"), "{xml}");

    write(dir, "small.toml", &small_scene());
    let (code, _, err) = run(&["export", "mitsuba", "small.toml", "-o", "mi2"], dir);
    assert_eq!(code, 0, "{err}");
    assert!(!err.contains("warning"), "{err}");
    assert!(
        xml_header(&dir.join("mi2")).contains("Approximations: none."),
        "{}",
        xml_header(&dir.join("mi2"))
    );
}

/// The small room with a glossy Ward floor under the lamp, whose highlight the camera sees.
fn glossy_room() -> String {
    small_scene().replace(
        "material = { type = \"diffuse\", rho_d = 0.5 }",
        "material = { type = \"ward\", rho_d = 0.25, rho_s = 0.5, alpha = 0.1 }",
    )
}

/// `recover --exportable mitsuba` keeps to the models Mitsuba has: no Ward level, and the
/// export of its result approximates nothing. Without it, the same photo takes a Ward level.
#[test]
fn recover_exportable_mitsuba_uses_no_ward_level() {
    let d = tempfile::tempdir().unwrap();
    let dir = d.path();
    scene_and_photo(dir, &glossy_room(), 64);
    let fit = [
        "--max-iterations",
        "8",
        "--light-samples",
        "8",
        "--indirect-samples",
        "8",
        "--final-spp",
        "4",
    ];
    let level = |out: &str, extra: &[&str]| -> String {
        let mut args = vec!["recover", "scene.toml", "photo.exr", "-o", out];
        args.extend(fit);
        args.extend(extra);
        let (code, _, err) = run(&args, dir);
        assert_eq!(code, 0, "{err}");
        let res = crate::common::results(&dir.join(out));
        crate::common::result_group(&res, "floor")["level"]
            .as_str()
            .unwrap()
            .to_string()
    };
    let free = level("free", &[]);
    let kept = level("kept", &["--exportable", "mitsuba"]);
    eprintln!("floor: {free} without --exportable, {kept} with it");
    assert!(
        ["isotropic", "anisotropic"].contains(&free.as_str()),
        "the photo should take a Ward level without the flag: {free}"
    );
    assert!(
        !["isotropic", "anisotropic"].contains(&kept.as_str()),
        "{kept}"
    );
    let (code, _, err) = run(
        &["export", "mitsuba", "kept/recovered.toml", "-o", "mi"],
        dir,
    );
    assert_eq!(code, 0, "{err}");
    let header = xml_header(&dir.join("mi"));
    assert!(header.contains("Approximations: none."), "{header}\n{err}");
}

/// A room whose ceiling no pixel sees, lit by a lamp facing the floor and one facing the
/// ceiling: the ceiling's ρd is estimated from the light it sends to the floor.
const UNSEEN_ROOM: &str = r#"
[camera]
width = 64
height = 48
eye = [0.0, 1.2, 2.0]
target = [0.0, 0.0, 0.0]
fov_y_deg = 40.0

[[object]]
name = "floor"
group = "floor"
shape = "quad"
corner = [-2.0, 0.0, 2.0]
edge_u = [4.0, 0.0, 0.0]
edge_v = [0.0, 0.0, -4.0]
material = { type = "diffuse", rho_d = 0.5 }

[[object]]
name = "ceiling"
group = "ceiling"
shape = "quad"
corner = [-2.0, 2.5, -2.0]
edge_u = [4.0, 0.0, 0.0]
edge_v = [0.0, 0.0, 4.0]
material = { type = "diffuse", rho_d = 0.7 }

[[object]]
name = "down"
group = "lamps"
shape = "quad"
corner = [-0.2, 1.5, -0.2]
edge_u = [0.4, 0.0, 0.0]
edge_v = [0.0, 0.0, 0.4]
emission = 3.0

[[object]]
name = "up"
group = "lamps"
shape = "quad"
corner = [-0.2, 1.6, 0.2]
edge_u = [0.4, 0.0, 0.0]
edge_v = [0.0, 0.0, -0.4]
emission = 10.0
"#;

/// results.json gives no capped or sentinel 1σ: a σ is a number in [0, 1) or null with
/// `determined: false`; the unseen group's status says how its ρd was found, in results.json,
/// the terminal's table and the report alike.
#[test]
fn unseen_sigmas_and_status_words_say_what_is_known() {
    let d = tempfile::tempdir().unwrap();
    let dir = d.path();
    scene_and_photo(dir, UNSEEN_ROOM, 64);
    let mut args = vec!["recover", "scene.toml", "photo.exr", "-o", "out"];
    args.extend(QUICK);
    let (code, out, err) = run(&args, dir);
    assert_eq!(code, 0, "{err}");
    let res = crate::common::results(&dir.join("out"));
    let ceiling = crate::common::result_group(&res, "ceiling");
    let unseen = &ceiling["unseen"];
    let sigma = unseen["sigma"].as_array().unwrap();
    for s in sigma {
        assert!(
            s.is_null() || s.as_f64().is_some_and(|x| (0.0..1.0).contains(&x)),
            "{ceiling}"
        );
    }
    assert_eq!(
        unseen["determined"].as_bool().unwrap(),
        sigma.iter().all(|s| !s.is_null()),
        "{ceiling}"
    );
    let word = match unseen["rule"].as_str().unwrap() {
        "estimated" => "estimated",
        _ => "default",
    };
    eprintln!("ceiling: {ceiling}");
    assert_eq!(ceiling["status"], word, "{ceiling}");
    let row = out
        .lines()
        .find(|l| l.starts_with("ceiling "))
        .unwrap_or_else(|| panic!("{out}"));
    assert!(row.contains(&format!(" {word} ")), "{row}");
    let html = std::fs::read_to_string(dir.join("out/report.html")).unwrap();
    assert!(html.contains(&format!("<td>{word}</td>")), "report status");
    assert!(!html.contains("<td>Default</td>"));
    assert!(!res.to_string().contains("-1.0"), "{res}");
}

/// recovered.toml says what made it, from what and when, without the input's opening comments.
#[test]
fn recovered_toml_says_what_it_is() {
    let d = tempfile::tempdir().unwrap();
    let dir = d.path();
    let text = format!(
        "# the small room, with the true materials\n{}",
        small_scene()
    );
    scene_and_photo(dir, &text, 16);
    let mut args = vec!["recover", "scene.toml", "photo.exr", "-o", "out"];
    args.extend(QUICK);
    let (code, _, err) = run(&args, dir);
    assert_eq!(code, 0, "{err}");
    let rec = std::fs::read_to_string(dir.join("out/recovered.toml")).unwrap();
    let header: Vec<&str> = rec.lines().take_while(|l| l.starts_with('#')).collect();
    let header = header.join("\n");
    assert!(!rec.contains("true materials"), "{rec}");
    assert!(
        header.starts_with(&format!(
            "# Recovered by matfit {}",
            env!("CARGO_PKG_VERSION")
        )),
        "{rec}"
    );
    assert!(header.contains("Photo: photo.exr"), "{header}");
    assert!(header.contains("Scene: scene.toml"), "{header}");
    assert!(
        header.contains("Camera: the scene's, as given."),
        "{header}"
    );
    // Today's UTC date, as `date -u` would give it.
    let days = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .unwrap()
        .as_secs()
        / 86_400;
    let year = 1970 + days * 400 / 146_097;
    assert!(header.contains(&format!(" on {year}-")), "{header}");
    // It is a scene `render` reads.
    let (code, _, err) = run(
        &[
            "render",
            "out/recovered.toml",
            "-o",
            "again.exr",
            "--spp",
            "1",
        ],
        dir,
    );
    assert_eq!(code, 0, "{err}");
}

/// Messages: a photo where the scene belongs, a resume into nothing, an old report beside a
/// new run's log, and an inverted ignore mask.
#[test]
fn messages_say_what_went_wrong() {
    let d = tempfile::tempdir().unwrap();
    let dir = d.path();
    write(dir, "scene.toml", &small_scene());
    let (code, _, err) = run(
        &["render", "scene.toml", "-o", "photo.png", "--spp", "4"],
        dir,
    );
    assert_eq!(code, 0, "{err}");

    // The photo first: named as an image, with the right order.
    let (code, _, err) = run(&["recover", "photo.png", "scene.toml", "-o", "out"], dir);
    assert_eq!(code, 2, "{err}");
    assert!(
        err.contains("photo.png: this is a PNG image, not a scene file"),
        "{err}"
    );
    assert!(!err.contains("UTF-8"), "{err}");

    // --resume into a folder that does not exist: an error, and no folder made.
    let mut args = vec![
        "recover",
        "scene.toml",
        "photo.png",
        "-o",
        "none",
        "--resume",
    ];
    args.extend(QUICK);
    let (code, _, err) = run(&args, dir);
    assert_eq!(code, 2, "{err}");
    assert!(
        err.contains("cannot resume") && err.contains("does not exist"),
        "{err}"
    );
    assert!(!dir.join("none").exists());

    // A run into an old output starts by removing the old results: here the next run fails
    // before it writes any (a mask that ignores everything), and no old report is left.
    let mut args = vec!["recover", "scene.toml", "photo.png", "-o", "out"];
    args.extend(QUICK);
    let (code, _, err) = run(&args, dir);
    assert_eq!(code, 0, "{err}");
    assert!(dir.join("out/report.html").exists());
    // An object mask (white on the floor, what to keep) given as the ignore mask.
    let img = image::RgbImage::from_pixel(64, 48, image::Rgb([255, 255, 255]));
    img.save(dir.join("keep.png")).unwrap();
    let mut args = vec![
        "recover",
        "scene.toml",
        "photo.png",
        "-o",
        "out",
        "--ignore-mask",
        "keep.png",
    ];
    args.extend(QUICK);
    let (code, _, err) = run(&args, dir);
    assert_eq!(code, 2, "{err}");
    assert!(
        err.contains("no usable pixel") && err.contains("Is it inverted?"),
        "{err}"
    );
    for old in [
        "report.html",
        "results.json",
        "recovered.toml",
        "checkpoint.json",
    ] {
        assert!(!dir.join("out").join(old).exists(), "old {old} left");
    }
}

/// One warning style: the library's warnings read `warning: …` like the command's, and the
/// repeat at the end keeps the group's name.
#[test]
fn warnings_have_one_style_and_keep_the_group() {
    let d = tempfile::tempdir().unwrap();
    let dir = d.path();
    scene_and_photo(dir, UNSEEN_ROOM, 16);
    let mut args = vec!["recover", "scene.toml", "photo.exr", "-o", "out"];
    args.extend(QUICK);
    let (code, _, err) = run(&args, dir);
    assert_eq!(code, 0, "{err}");
    assert!(!err.contains(" WARN "), "{err}");
    assert!(!err.contains("matfit::"), "{err}");
    // The ceiling's warning, first and repeated, names it.
    let named = err
        .lines()
        .filter(|l| l.starts_with("warning: group 'ceiling': no usable pixels"))
        .count();
    assert!(named >= 2, "{err}");
    assert!(
        !err.lines()
            .any(|l| l.starts_with("warning: no usable pixels")),
        "{err}"
    );
}

/// A composite counts the pixels its edit changed beyond the renders' Monte Carlo noise: those
/// an added ball covers and its shadow, not the whole noisy floor.
#[test]
fn a_composite_counts_changes_beyond_the_noise() {
    let d = tempfile::tempdir().unwrap();
    let dir = d.path();
    write(dir, "scene.toml", &small_scene());
    let (code, _, err) = run(
        &[
            "render",
            "scene.toml",
            "-o",
            "photo.exr",
            "--spp",
            "16",
            "--seed",
            "9",
        ],
        dir,
    );
    assert_eq!(code, 0, "{err}");
    let (code, out, err) = run(
        &[
            "composite",
            "scene.toml",
            "photo.exr",
            "-o",
            "c.exr",
            "--spp",
            "16",
            "--add",
            "{ name = \"ball\", group = \"ball\", shape = \"sphere\", center = [0.4, 0.15, 0.4], \
             radius = 0.15, material = { type = \"diffuse\", rho_d = 0.5 } }",
        ],
        dir,
    );
    assert_eq!(code, 0, "{err}");
    let line = out
        .lines()
        .find(|l| l.contains("pixels changed beyond the Monte Carlo noise"))
        .unwrap_or_else(|| panic!("{out}"));
    let num = |before: &str| -> f64 {
        let head = &line[..line.find(before).unwrap()];
        head.rsplit([' ', ':'])
            .find(|w| !w.is_empty())
            .unwrap()
            .parse()
            .unwrap()
    };
    let (changed, covered) = (
        num(" pixels changed beyond"),
        num(" covered by added objects"),
    );
    eprintln!("{line}");
    assert!(
        changed >= covered && changed < 3.0 * covered + 100.0,
        "{line}"
    );
}

/// A photo 2.5× brighter than its exposure says (the error of a JPEG shot without one) is not
/// "confirmed" into confident nonsense: the groups it cannot explain say "not explained", and
/// the run's verdict, in the terminal, results.json and the report, names the exposure. The
/// same photo with its true exposure is explained.
#[test]
fn a_wrongly_exposed_photo_is_not_explained_and_the_verdict_says_why() {
    let d = tempfile::tempdir().unwrap();
    let dir = d.path();
    scene_and_photo(dir, &small_scene(), 64);
    let recover = |exposure: &str, out: &str| {
        let mut args = vec!["recover", "scene.toml", "photo.exr", "-o", out];
        // QUICK, but a final render whose noise floor leaves the verdict something to judge.
        let k = QUICK.iter().position(|&a| a == "--final-spp").unwrap();
        args.extend(
            QUICK
                .iter()
                .enumerate()
                .map(|(i, &a)| if i == k + 1 { "16" } else { a }),
        );
        args.extend(["--exposure", exposure]);
        let (code, stdout, err) = run(&args, dir);
        assert_eq!(code, 0, "{err}");
        (crate::common::results(&dir.join(out)), stdout)
    };
    let (res, stdout) = recover("0.4", "over");
    let verdict = &res["verdict"];
    eprintln!("{verdict}");
    assert_eq!(verdict["explained"], false, "{verdict}");
    assert_eq!(verdict["causes"][0]["cause"], "exposure", "{verdict}");
    let named = verdict["not_explained"].as_array().unwrap();
    assert!(!named.is_empty());
    for g in named {
        let g = crate::common::result_group(&res, g.as_str().unwrap());
        assert_eq!(g["status"], "not explained", "{g}");
    }
    assert!(stdout.contains("verdict: NOT EXPLAINED"), "{stdout}");
    assert!(stdout.contains("not explained"), "{stdout}");
    let html = std::fs::read_to_string(dir.join("over/report.html")).unwrap();
    assert!(html.contains("id=\"verdict\"") && html.contains("NOT EXPLAINED"));
    let (res, stdout) = recover("1", "right");
    assert_eq!(res["verdict"]["explained"], true, "{}", res["verdict"]);
    assert!(
        stdout.contains("verdict: every fitted group is explained"),
        "{stdout}"
    );
}

/// The case as a user meets it: an 8-bit sRGB JPEG shot 2.5× brighter than a good exposure
/// (one that puts the 99th percentile at 0.9), no exposure given. Its highlights clip; the run
/// is not explained, the verdict names the exposure first and says how many pixels were
/// clipped and left out of every fit, and no group is "confirmed" at an error many times its
/// noise floor. The well-exposed JPEG, its exposure given, is explained: 8 bits and the sRGB
/// curve alone raise no alarm.
#[test]
fn an_over_exposed_jpeg_without_an_exposure_is_not_explained() {
    let d = tempfile::tempdir().unwrap();
    let dir = d.path();
    scene_and_photo(dir, &small_scene(), 64);
    let linear = matfit::io::image::read_linear(&dir.join("photo.exr")).unwrap();
    let mut lum: Vec<f32> = linear.data.iter().map(|c| c.max_element()).collect();
    lum.sort_by(f32::total_cmp);
    let good = 0.9 / lum[lum.len() * 99 / 100];
    let jpeg = |name: &str, k: f32| -> f64 {
        let mut img = linear.clone();
        for c in &mut img.data {
            *c *= k;
        }
        img.write(&dir.join(name)).unwrap();
        img.data.iter().filter(|c| c.max_element() > 1.0).count() as f64 / img.data.len() as f64
    };
    let recover = |photo: &str, out: &str, exposure: Option<String>| {
        let mut args = vec!["recover", "scene.toml", photo, "-o", out];
        args.extend(QUICK);
        if let Some(e) = &exposure {
            args.extend(["--exposure", e.as_str()]);
        }
        let (code, stdout, err) = run(&args, dir);
        assert_eq!(code, 0, "{err}");
        (crate::common::results(&dir.join(out)), stdout)
    };

    let clipped = jpeg("over.jpg", 2.5 * good);
    assert!(clipped > 0.005, "the test needs clipped pixels: {clipped}");
    let (res, stdout) = recover("over.jpg", "over", None);
    let verdict = &res["verdict"];
    eprintln!("{verdict}\n{stdout}");
    assert_eq!(verdict["explained"], false, "{verdict}");
    assert_eq!(verdict["causes"][0]["cause"], "exposure", "{verdict}");
    let share = verdict["clipped_share"].as_f64().unwrap();
    assert!(
        share >= 0.5 * clipped && share <= 1.5 * clipped + 0.01,
        "clipped share {share} vs {clipped} of pixels over 1"
    );
    assert!(stdout.contains("verdict: NOT EXPLAINED"), "{stdout}");
    assert!(stdout.contains("clipped"), "{stdout}");
    for g in res["groups"].as_array().unwrap() {
        if let (Some(e), Some(nf)) = (g["error"].as_f64(), g["noise_floor"].as_f64()) {
            if e > 5.0 * nf + 0.03 {
                assert_ne!(g["status"], "confirmed", "{g}");
            }
        }
    }

    jpeg("right.jpg", good);
    let (res, stdout) = recover("right.jpg", "right", Some(good.to_string()));
    assert_eq!(
        res["verdict"]["explained"], true,
        "{}\n{stdout}",
        res["verdict"]
    );
}

/// A ceiling lamp written with its edges swapped faces the ceiling a centimetre above it and
/// lights the room only through it: warned like a lamp facing away, naming the object; the
/// same lamp facing down is not.
#[test]
fn a_light_facing_a_surface_a_centimetre_away_is_warned_of() {
    use crate::common::{diffuse, emission, SceneToml};
    let room = |lamp_faces_up: bool| {
        let (u, v) = ([0.4, 0.0, 0.0], [0.0, 0.0, 0.4]);
        let (u, v) = if lamp_faces_up { (v, u) } else { (u, v) };
        // Seen from inside the room, the ceiling and the floor in view.
        SceneToml::spaced()
            .camera(64, 48, [0.0, 0.8, 1.8], [0.0, 1.1, 0.0], 70.0)
            .floor(&diffuse(&[0.5]))
            .quad(
                "ceiling",
                "ceiling",
                [-1.0, 1.51, -1.0],
                [2.0, 0.0, 0.0],
                [0.0, 0.0, 2.0],
                &diffuse(&[0.8]),
            )
            .quad("lamp", "lamp", [-0.2, 1.5, -0.2], u, v, &emission(&[5.0]))
            .to_toml()
    };
    let d = tempfile::tempdir().unwrap();
    let dir = d.path();
    for (up, name) in [(true, "up.toml"), (false, "down.toml")] {
        write(dir, name, &room(up));
        let (code, _, err) = run(&["render", name, "-o", "x.exr", "--spp", "1"], dir);
        assert_eq!(code, 0, "{err}");
        let warned = err.lines().any(|l| {
            l.starts_with("warning: ") && l.contains("'lamp'") && l.contains("faces a surface")
        });
        assert_eq!(warned, up, "{name}: {err}");
    }
}
