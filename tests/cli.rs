//! What a new user meets first. Each behaviour through the binary, checking the
//! message and the exit status.

use crate::common::{matfit, root, run, small_room, small_scene, write, QUICK};
use std::path::Path;
use std::process::Stdio;

fn render_photo(dir: &Path, name: &str) {
    let (code, _, err) = run(&["render", "scene.toml", "-o", name, "--spp", "16"], dir);
    assert_eq!(code, 0, "{err}");
}

/// `scene` written to `dir/scene.toml`, its 16-spp photo rendered, and a quick recovery of it
/// into `dir/out`, which must succeed; returns what it printed.
fn recover_quickly(dir: &Path, scene: &str) -> String {
    write(dir, "scene.toml", scene);
    render_photo(dir, "photo.exr");
    let mut args = vec!["recover", "scene.toml", "photo.exr", "-o", "out"];
    args.extend(QUICK);
    let (code, out, err) = run(&args, dir);
    assert_eq!(code, 0, "{err}");
    out
}

#[test]
fn a_closed_pipe_ends_quietly() {
    let scene = root().join("scenes/glossy/scene.toml");
    for _ in 0..5 {
        let mut child = matfit()
            .args(["info", scene.to_str().unwrap()])
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        // The reader goes away before matfit has written (it loads the scene first).
        drop(child.stdout.take());
        let out = child.wait_with_output().unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(0), "{err}");
        assert!(
            !err.contains("panicked") && !err.contains("Broken pipe"),
            "{err}"
        );
    }
}

#[test]
fn zero_samples_per_pixel_is_refused() {
    let d = tempfile::tempdir().unwrap();
    write(d.path(), "scene.toml", &small_scene());
    let (code, _, err) = run(
        &["render", "scene.toml", "-o", "x.png", "--spp", "0"],
        d.path(),
    );
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("--spp") && err.contains("'0'"), "{err}");
    assert!(!d.path().join("x.png").exists());
}

#[test]
fn render_says_what_it_wrote() {
    let d = tempfile::tempdir().unwrap();
    write(d.path(), "scene.toml", &small_scene());
    let (code, out, err) = run(
        &["render", "scene.toml", "-o", "x.png", "--spp", "2"],
        d.path(),
    );
    assert_eq!(code, 0, "{err}");
    assert!(out.starts_with("wrote x.png (64×48, 2 spp) in "), "{out}");
    assert!(out.trim_end().ends_with(" s"), "{out}");
}

#[test]
fn info_prints_rounded_vectors_materials_and_render_settings() {
    let d = tempfile::tempdir().unwrap();
    write(d.path(), "scene.toml", &small_scene());
    let (code, out, err) = run(&["info", "scene.toml"], d.path());
    assert_eq!(code, 0, "{err}");
    assert!(out.contains("eye (0, 2, 2)"), "{out}");
    assert!(!out.contains("Vec3"), "{out}");
    assert!(out.contains("render spp 64, max_depth"), "{out}");
    assert!(out.contains("group floor: floor; diffuse ρd 0.5"), "{out}");
    assert!(out.contains("light lamp: radiance 5, area 0.16"), "{out}");
    // The bundled scenes have no suspicious group names and lights that light the view.
    for s in ["figure6", "glossy", "cornell"] {
        let (code, _, err) = run(
            &["info", &format!("scenes/{s}/scene.toml")],
            &crate::common::root(),
        );
        assert_eq!(code, 0, "{s}: {err}");
        assert!(!err.contains("warning"), "{s}: {err}");
    }
}

#[test]
fn a_missing_scene_file_is_reported_once() {
    let d = tempfile::tempdir().unwrap();
    let (code, _, err) = run(&["info", "absent.toml"], d.path());
    assert_eq!(code, 2);
    assert_eq!(err.matches("No such file").count(), 1, "{err}");
    assert!(err.contains("cannot read scene file absent.toml"), "{err}");
}

#[test]
fn no_light_or_a_light_facing_away_stops_before_the_work() {
    let d = tempfile::tempdir().unwrap();
    let dir = d.path();
    write(dir, "scene.toml", &small_scene());
    render_photo(dir, "photo.exr");
    // The lamp is the last object: without its emission nothing emits.
    let dark = small_scene().replace("emission = 5.0", "");
    write(dir, "dark.toml", &dark);
    let (code, _, err) = run(&["render", "dark.toml", "-o", "x.exr"], dir);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("dark.toml: no object emits light"), "{err}");
    // edge_v reversed: the lamp's front side faces the ceiling-less sky.
    let away = small_scene().replace("edge_v = [0.0, 0.0, 0.4]", "edge_v = [0.0, 0.0, -0.4]");
    write(dir, "away.toml", &away);
    let (code, _, err) = run(&["render", "away.toml", "-o", "x.exr"], dir);
    assert_eq!(code, 2, "{err}");
    assert!(
        err.contains("away.toml:19: light 'lamp' faces away from every surface"),
        "{err}"
    );
    assert!(err.contains("swap edge_u and edge_v"), "{err}");
    let mut args = vec!["recover", "away.toml", "photo.exr", "-o", "out"];
    args.extend(QUICK);
    let (code, _, err) = run(&args, dir);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("light 'lamp' faces away"), "{err}");
    assert!(
        !dir.join("out").exists(),
        "refused before creating the output"
    );
    // The index buffers need no light.
    let (code, _, err) = run(
        &["render", "dark.toml", "-o", "g.exr", "--aov", "group"],
        dir,
    );
    assert_eq!(code, 0, "{err}");
}

#[test]
fn help_describes_arguments_defaults_and_the_workflow() {
    let d = tempfile::tempdir().unwrap();
    let (code, out, _) = run(&["--help"], d.path());
    assert_eq!(code, 0);
    assert!(out.contains("matfit inspect SCENE PHOTO"), "{out}");
    assert!(out.contains("matfit recover SCENE PHOTO"), "{out}");
    assert!(!out.contains("issue"), "{out}");
    for cmd in [
        "render",
        "recover",
        "inspect",
        "demo",
        "info",
        "export",
        "composite",
        "hdr",
    ] {
        let (code, out, _) = run(&[cmd, "--help"], d.path());
        assert_eq!(code, 0);
        assert!(!out.contains("::"), "{cmd}: a Rust path in:\n{out}");
        let usage = out.lines().find(|l| l.starts_with("Usage:")).unwrap_or("");
        if usage.contains("<SCENE>") {
            assert!(out.contains("Scene file (TOML)"), "{cmd}:\n{out}");
        }
        if usage.contains("<PHOTO>") {
            assert!(out.contains("Photograph of the scene"), "{cmd}:\n{out}");
        }
        // Every option that takes a value states its default (or that it has none to state).
        let opts: Vec<&str> = out.split("\n  -").skip(1).collect();
        for o in opts
            .iter()
            .chain(out.split("\n      --").skip(1).collect::<Vec<_>>().iter())
        {
            let takes_value = o.lines().next().is_some_and(|l| l.contains(" <"));
            let required = o.starts_with("o, --output") || o.starts_with("-output");
            let optional = o.contains("[default") || o.contains("Instead:") || o.contains("(e.g.");
            if takes_value && !required && !o.starts_with("-threads") && !o.starts_with("-scene <")
            {
                assert!(optional, "{cmd}: option without a default:\n{o}");
            }
        }
    }
    let (_, out, _) = run(&["recover", "--help"], d.path());
    assert!(
        out.contains("[default: 1, unless"),
        "exposure default: {out}"
    );
}

#[test]
fn exposure_default_is_stated_and_an_ldr_photo_without_one_is_warned() {
    let d = tempfile::tempdir().unwrap();
    let dir = d.path();
    write(dir, "scene.toml", &small_scene());
    render_photo(dir, "photo.png");
    let (code, out, err) = run(&["inspect", "scene.toml", "photo.png", "-o", "i1"], dir);
    assert_eq!(code, 0, "{err}");
    assert!(out.contains("exposure 1 (default, not given)"), "{out}");
    assert!(
        err.contains("warning: photo.png: an 8/16-bit photo and no --exposure"),
        "{err}"
    );
    let (code, out, err) = run(
        &[
            "inspect",
            "scene.toml",
            "photo.png",
            "-o",
            "i2",
            "--exposure",
            "1",
        ],
        dir,
    );
    assert_eq!(code, 0, "{err}");
    assert!(out.contains("exposure 1 (given)"), "{out}");
    assert!(!err.contains("warning"), "{err}");
}

/// Each registration states the rule it was held to: the pose refinement applies from 0.1 px
/// RMS, the film shift from half a pixel on either axis (it once quoted the pose's rule).
#[test]
fn inspect_states_each_registrations_own_rule() {
    let d = tempfile::tempdir().unwrap();
    let dir = d.path();
    write(dir, "scene.toml", &small_scene());
    render_photo(dir, "photo.exr");
    for (extra, found, rule) in [
        (
            None,
            "registration: camera turned by",
            "below 0.1 px RMS, not applied",
        ),
        (
            Some("--film-shift"),
            "registration: film shifted by (",
            "below 0.5 px on both axes, not applied",
        ),
    ] {
        let mut args = vec!["inspect", "scene.toml", "photo.exr", "-o", "i"];
        args.extend(extra);
        let (code, out, err) = run(&args, dir);
        assert_eq!(code, 0, "{err}");
        let line = out
            .lines()
            .find(|l| l.starts_with("registration:"))
            .unwrap_or_else(|| panic!("no registration line in:\n{out}"));
        assert!(line.starts_with(found), "{line}");
        // The photo is rendered through the scene's own camera: nothing to apply.
        assert!(line.ends_with(rule), "{line}");
        std::fs::remove_dir_all(dir.join("i")).unwrap();
    }
}

#[test]
fn recover_ends_with_the_table_and_repeats_warnings() {
    let d = tempfile::tempdir().unwrap();
    let dir = d.path();
    write(dir, "scene.toml", &small_scene());
    render_photo(dir, "photo.exr");
    // k = 1e-4: the floor (radiance about 0.04 under the lamp of radiance 5) divided by it is
    // far brighter than the lamp itself.
    let mut args = vec![
        "recover",
        "scene.toml",
        "photo.exr",
        "-o",
        "out",
        "--exposure",
        "0.0001",
    ];
    args.extend(QUICK);
    let (code, out, err) = run(&args, dir);
    assert_eq!(code, 0, "{err}");
    assert!(out.contains("exposure k = 0.0001 (given)"), "{out}");
    let head = out
        .lines()
        .find(|l| l.starts_with("group "))
        .expect("a table header");
    for col in ["level", "status", "ρd", "ρs", "lobe", "ε", "noise"] {
        assert!(head.contains(col), "{head}");
    }
    let row = out
        .lines()
        .find(|l| l.starts_with("floor "))
        .expect("a floor row");
    assert!(row.contains('%'), "{row}");
    assert!(out.contains("ε: Σ|synthetic − photo| / Σ photo"), "{out}");
    let warning = "photo.exr: group 'floor' is ";
    assert!(err.contains(warning), "{err}");
    assert!(err.contains("× brighter in the photo"), "{err}");
    assert!(
        err.contains("than the brightest light ('lamp', radiance 5)"),
        "{err}"
    );
    let repeated = err.split("(repeated):").nth(1).expect("warnings repeated");
    assert!(repeated.contains(warning), "{err}");
}

#[test]
fn a_folder_of_other_files_is_not_overwritten_without_force() {
    let d = tempfile::tempdir().unwrap();
    let dir = d.path();
    write(dir, "scene.toml", &small_scene());
    render_photo(dir, "photo.exr");
    write(dir, "mine/thesis.tex", "months of work");
    for cmd in [
        vec!["inspect", "scene.toml", "photo.exr", "-o", "mine"],
        vec!["export", "mitsuba", "scene.toml", "-o", "mine"],
        vec!["recover", "scene.toml", "photo.exr", "-o", "mine"],
    ] {
        let (code, _, err) = run(&cmd, dir);
        assert_eq!(code, 2, "{cmd:?}: {err}");
        assert!(
            err.contains(
                "mine is not empty (1 entry, e.g. 'thesis.tex') and is not a matfit output"
            ),
            "{err}"
        );
        assert!(err.contains("--force"), "{err}");
    }
    let (code, _, err) = run(
        &[
            "inspect",
            "scene.toml",
            "photo.exr",
            "-o",
            "mine",
            "--force",
        ],
        dir,
    );
    assert_eq!(code, 0, "{err}");
    assert!(err.contains("(--force)"), "{err}");
    // A matfit output may be written again, with a note.
    let (code, _, err) = run(&["inspect", "scene.toml", "photo.exr", "-o", "mine"], dir);
    assert_eq!(code, 0, "{err}");
    assert!(
        err.contains("note: writing over the matfit output in mine"),
        "{err}"
    );
    assert!(dir.join("mine/thesis.tex").exists());
}

#[test]
fn ctrl_c_on_recover_says_how_to_resume() {
    let d = tempfile::tempdir().unwrap();
    let dir = d.path();
    write(dir, "scene.toml", &small_scene());
    render_photo(dir, "photo.exr");
    let child = matfit()
        .args([
            "recover",
            "scene.toml",
            "photo.exr",
            "-o",
            "out",
            "--max-iterations",
            "64",
        ])
        .args(["--light-samples", "512", "--threads", "1"])
        .current_dir(dir)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let t = std::time::Instant::now();
    // Interrupted once the work has begun (its log is open), long before it can end.
    while !dir.join("out/log.jsonl").exists() && t.elapsed().as_secs() < 60 {
        std::thread::sleep(std::time::Duration::from_millis(50));
    }
    let pid = child.id().to_string();
    let killed = std::process::Command::new("kill")
        .args(["-INT", &pid])
        .status()
        .unwrap();
    assert!(killed.success());
    let out = child.wait_with_output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(130), "{err}");
    assert!(err.contains("interrupted"), "{err}");
    assert!(
        err.contains("recover scene.toml photo.exr -o out --max-iterations 64 --light-samples 512 --threads 1 --resume"),
        "{err}"
    );
}

#[test]
fn a_group_name_one_edit_from_another_is_warned() {
    let d = tempfile::tempdir().unwrap();
    let text = small_room()
        .quad(
            "rug",
            "flor",
            [-0.5, 0.01, 0.5],
            [1.0, 0.0, 0.0],
            [0.0, 0.0, -1.0],
            "",
        )
        .to_toml();
    write(d.path(), "scene.toml", &text);
    let (code, _, err) = run(&["info", "scene.toml"], d.path());
    assert_eq!(code, 0, "{err}");
    assert!(
        err.contains(
            "scene.toml:28: object 'rug' is in group 'flor', 1 edit away from group 'floor'"
        ),
        "{err}"
    );
    assert!(err.contains("a typo?"), "{err}");
}

#[test]
fn demo_table_is_aligned_for_long_names_and_explains_the_ratio() {
    let d = tempfile::tempdir().unwrap();
    let dir = d.path();
    let long = small_scene().replacen("group = \"floor\"", "group = \"a_very_long_floor_name\"", 1);
    write(dir, "scene.toml", &long);
    let mut args = vec![
        "demo",
        "--scene",
        "scene.toml",
        "-o",
        "demo",
        "--photo-spp",
        "4",
    ];
    args.extend(QUICK);
    let (code, out, err) = run(&args, dir);
    assert_eq!(code, 0, "{err}");
    let head = out
        .lines()
        .find(|l| l.starts_with("surface"))
        .expect("header");
    let col = head.find("true value").unwrap();
    let row = out
        .lines()
        .find(|l| l.starts_with("a_very_long_floor_name"))
        .expect("row");
    let next = out
        .lines()
        .skip_while(|l| !l.starts_with("a_very_long"))
        .nth(1)
        .unwrap();
    for l in [row, next] {
        assert_eq!(l.find('('), Some(col), "column moved:\n{head}\n{l}");
    }
    assert!(out.contains("(fitting time / final render time"), "{out}");
}

#[test]
fn outputs_keep_the_input_layout_and_fixed_groups_their_material() {
    let d = tempfile::tempdir().unwrap();
    let dir = d.path();
    let small = small_scene();
    let text = format!(
        "# the small room\n{small}\n[[object]]\nname = \"shelf\"\ngroup = \"shelf\"\n\
         shape = \"quad\"\ncorner = [-1.0, 0.0, -1.0]\nedge_u = [2.0, 0.0, 0.0]\n\
         edge_v = [0.0, 1.0, 0.0]\nmaterial = {{ type = \"mirror\", rho_s = 0.8 }}  # kept\n\n\
         [[group]]\nname = \"shelf\"\nfixed = true\n"
    );
    let out = recover_quickly(dir, &text);
    let shelf_row = out
        .lines()
        .find(|l| l.starts_with("shelf "))
        .expect("shelf row");
    assert!(
        shelf_row.contains("fixed") && shelf_row.contains("0.8"),
        "{shelf_row}"
    );
    let json = crate::common::results(&dir.join("out"));
    let shelf = crate::common::result_group(&json, "shelf");
    assert_eq!(shelf["status"], "fixed", "{shelf}");
    assert_eq!(shelf["level"], "specular", "{shelf}");
    let rho_s = shelf["params"]["rho_s"][0].as_f64().unwrap();
    assert!((rho_s - 0.8).abs() < 1e-6, "{shelf}");
    // recovered.toml: its own header for the input's opening comment, then the input's lines,
    // only the fitted materials changed ([camera] has the refined pose where one was applied).
    let rec = std::fs::read_to_string(dir.join("out/recovered.toml")).unwrap();
    let body = |t: &str| -> Vec<String> {
        let mut in_camera = false;
        t.lines()
            .skip_while(|l| l.is_empty() || l.starts_with('#'))
            .filter(|l| {
                if l.starts_with('[') {
                    in_camera = *l == "[camera]";
                }
                !in_camera
            })
            .map(String::from)
            .collect()
    };
    let (input, output) = (body(&text), body(&rec));
    assert_eq!(input.len(), output.len(), "{rec}");
    let changed: Vec<&String> = input
        .iter()
        .zip(&output)
        .filter(|(a, b)| a != b)
        .map(|(_, b)| b)
        .collect();
    assert_eq!(
        changed.len(),
        1,
        "only the floor's material changes:\n{rec}"
    );
    assert!(changed[0].starts_with("material = { type = "), "{rec}");
    assert!(rec.starts_with("# Recovered by matfit "), "{rec}");
    assert!(!rec.contains("# the small room"), "{rec}");
    assert!(
        rec.contains("material = { type = \"mirror\", rho_s = 0.8 }  # kept"),
        "{rec}"
    );
}

#[test]
fn the_report_is_one_file_with_pictures_plots_inputs_and_a_noise_free_error_map() {
    let d = tempfile::tempdir().unwrap();
    let dir = d.path();
    recover_quickly(dir, &small_scene());
    let html = std::fs::read_to_string(dir.join("out/report.html")).unwrap();
    // One file: the pictures embedded as PNGs, no links to them.
    use base64::Engine;
    let pngs: Vec<Vec<u8>> = html
        .split("src=\"data:image/png;base64,")
        .skip(1)
        .map(|s| {
            base64::engine::general_purpose::STANDARD
                .decode(s.split('"').next().unwrap())
                .expect("valid base64")
        })
        .collect();
    // Photo, synthetic, error map, and the slider's photo and synthetic.
    assert_eq!(pngs.len(), 5, "embedded pictures");
    assert!(pngs.iter().all(|b| b.starts_with(b"\x89PNG\r\n\x1a\n")));
    assert!(!html.contains("src=\"photo.png\""));
    // The error map's colour bar, and the fitted group's convergence plot with its two series
    // (the lamp has no fit, so no plot).
    assert!(html.contains("id=\"colour-bar\""));
    let plot = html
        .split("data-group=\"floor\">")
        .nth(1)
        .expect("a plot for the floor");
    let svg = plot.split("</svg>").next().unwrap();
    assert!(svg.trim_start().starts_with("<svg"), "{svg}");
    assert!(svg.matches("<polyline").count() >= 2, "{svg}");
    assert!(!html.contains("data-group=\"lamp\""));
    // The inputs, in the page and in results.json: enough to run it again.
    assert!(html.contains("id=\"inputs\""));
    let res = crate::common::results(&dir.join("out"));
    let inputs = &res["inputs"];
    assert_eq!(inputs["scene"], "scene.toml", "{inputs}");
    assert_eq!(inputs["photo"], "photo.exr", "{inputs}");
    assert_eq!(inputs["exposure_rule"], "default", "{inputs}");
    assert_eq!(inputs["options"]["max_iterations"], 2, "{inputs}");
    // The photo has 16 spp and the final render 2: per pixel, noise is tens of percent of the
    // radiance, while the floor's model (diffuse, as the truth) is right. The map shows model
    // error above the noise, so almost nothing is lit (the per-pixel map was mostly white).
    let map = matfit::io::image::read_linear(&dir.join("out/error.png")).unwrap();
    let lit = map.data.iter().filter(|c| c.max_element() > 0.05).count();
    eprintln!("error map: {lit} of {} pixels lit", map.data.len());
    assert!(
        lit * 100 < map.data.len() * 3,
        "{lit} of {} lit",
        map.data.len()
    );
}

/// Chromium, for the report's browser test: `MATFIT_CHROMIUM` (set by .ci/run, which installs
/// it), else `chromium` on the PATH.
fn chromium() -> Option<String> {
    let exe = std::env::var("MATFIT_CHROMIUM").unwrap_or_else(|_| "chromium".to_string());
    let ok = std::process::Command::new(&exe)
        .arg("--version")
        .output()
        .is_ok_and(|o| o.status.success());
    ok.then_some(exe)
}

#[test]
fn the_report_opens_in_a_browser_with_every_picture_and_plot() {
    let Some(exe) = chromium() else {
        // .ci/run installs it; a developer without it is told, not failed.
        eprintln!("SKIPPED: no chromium (set MATFIT_CHROMIUM or install Debian's chromium)");
        assert!(
            std::env::var_os("MATFIT_CHROMIUM").is_none(),
            "MATFIT_CHROMIUM is set but does not run"
        );
        return;
    };
    let d = tempfile::tempdir().unwrap();
    let dir = d.path();
    recover_quickly(dir, &small_scene());
    let page = format!("file://{}", dir.join("out/report.html").display());
    let browser = |extra: &[&str]| {
        let out = std::process::Command::new(&exe)
            .args([
                "--headless",
                "--no-sandbox",
                "--disable-gpu",
                "--virtual-time-budget=5000",
            ])
            .arg(format!("--user-data-dir={}", dir.join("profile").display()))
            .args(extra)
            .arg(&page)
            .output()
            .expect("chromium runs");
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        String::from_utf8_lossy(&out.stdout).into_owned()
    };
    // The DOM after the page's script ran: every picture decoded (the page counts them on
    // load), the plot drawn, the table there.
    let dom = browser(&["--dump-dom"]);
    let loaded = dom
        .split("data-images-loaded=\"")
        .nth(1)
        .and_then(|s| s.split('"').next())
        .expect("the page's load count");
    let (n, of) = loaded.split_once('/').unwrap();
    assert_eq!(n, of, "pictures decoded: {loaded}");
    assert!(n.parse::<usize>().unwrap() >= 4, "{loaded}");
    assert!(dom.contains("data-group=\"floor\"") && dom.contains("<polyline"));
    assert!(dom.contains("<th>group</th>") && dom.contains("<td>floor</td>"));
    // A screenshot: the page is drawn, not blank.
    let shot = dir.join("shot.png");
    browser(&[
        &format!("--screenshot={}", shot.display()),
        "--window-size=1000,800",
    ]);
    let img = matfit::io::image::read_linear(&shot).unwrap();
    let dark = img.data.iter().filter(|c| c.max_element() < 0.5).count();
    assert!(
        dark * 50 > img.data.len(),
        "the screenshot is nearly blank: {dark} dark pixels of {}",
        img.data.len()
    );
}
