//! End-to-end recovery: the bundled scenes rendered by matfit with their true materials, then
//! recovered blind. Run at reduced resolution (a quarter of the pixels) to fit CI's time; the
//! tolerances are stated per test. The full-resolution figures are `matfit demo`'s (see the
//! README and bench/README.md).

use crate::common::root;
use matfit::fit::{recover, Level, RecoverOptions, Recovery};
use matfit::fit::{Event, Status};
use matfit::photo::Photo;
use matfit::prepare::usable_pixels;
use matfit::render::aov::index_buffers;
use matfit::render::film::{render, RenderOptions};
use matfit::scene::load::parse_scene;
use matfit::scene::{Material, Scene};

/// The bundled scene at `path` with its film scaled by `scale` (same field of view).
pub(crate) fn scaled(path: &str, scale: f32) -> Scene {
    let p = root().join(path);
    let text = std::fs::read_to_string(&p).unwrap();
    let sc = parse_scene(&text, &p).unwrap();
    let (w, h) = (sc.camera.width, sc.camera.height);
    let text = text
        .replace(
            &format!("width = {w}\n"),
            &format!("width = {}\n", (w as f32 * scale) as u32),
        )
        .replace(
            &format!("height = {h}\n"),
            &format!("height = {}\n", (h as f32 * scale) as u32),
        );
    parse_scene(&text, &p).unwrap()
}

/// Renders the photo with the true materials, recovers, returns the recovery and the log.
fn run(scene: &Scene, photo_spp: u32) -> (Recovery, Vec<(String, Event)>) {
    run_with(scene, photo_spp, RecoverOptions::default())
}

/// [`run`] with other recovery options (progress, seed and final spp as `run`'s).
fn run_with(
    scene: &Scene,
    photo_spp: u32,
    opts: RecoverOptions,
) -> (Recovery, Vec<(String, Event)>) {
    let (rec, _, log) = run_keeping_photo(scene, photo_spp, opts);
    (rec, log)
}

/// [`run_with`], also returning the photo (linear).
pub(crate) fn run_keeping_photo(
    scene: &Scene,
    photo_spp: u32,
    opts: RecoverOptions,
) -> (Recovery, matfit::io::image::Image, Vec<(String, Event)>) {
    let img = render(
        scene,
        &scene.camera,
        &RenderOptions {
            spp: photo_spp,
            seed: 77,
            progress: false,
        },
    );
    let photo = Photo::from_linear(img.clone());
    let mask = usable_pixels(
        &index_buffers(scene, &scene.camera),
        &photo,
        scene.groups.len(),
        &Default::default(),
    );
    let opts = RecoverOptions {
        progress: false,
        seed: 5,
        final_spp: Some(16),
        ..opts
    };
    let mut log = Vec::new();
    let rec = recover(scene, &photo, &mask, &opts, |l| {
        log.push((l.group.clone(), l.event.clone()))
    })
    .unwrap();
    (rec, img, log)
}

pub(crate) fn truth(scene: &Scene, group: &str) -> Material {
    let g = scene.group_index(group).unwrap();
    scene.objects[scene.groups[g].objects[0]].material.clone()
}

/// One line per fitted group: level, status, recovered vs true ρ (printed on failure).
fn table(scene: &Scene, rec: &Recovery) -> String {
    rec.groups
        .iter()
        .filter(|g| g.is_fitted())
        .map(|g| {
            let t = truth(scene, &g.name);
            format!(
                "{:<14} {:<17} {:?} ρd {:.4} (true {:.4}) ρs {:.4} (true {:.4}) αx {:.4} αy {:.4} θ {:.2}°\n",
                g.name,
                g.level.name(),
                g.status,
                g.params.rho_d,
                t.rho_d(),
                g.params.rho_s,
                t.rho_s(),
                g.params.alpha_x,
                g.params.alpha_y,
                g.params.theta.to_degrees()
            )
        })
        .collect()
}

pub(crate) fn state<'a>(rec: &'a Recovery, name: &str) -> &'a matfit::fit::GroupState {
    rec.groups.iter().find(|g| g.name == name).unwrap()
}

#[test]
fn figure6_is_recovered_blind() {
    // Tolerances at a quarter of the pixels and a 256-spp photo: ρ within 0.015, α within 4%,
    // θ within 1.5°. Measured here: worst ρ +0.0118 (big block), αx −1.1%, αy −0.2%, θ −0.4°.
    // (The full-resolution demo: ρ within 0.012, α exact to 4 digits, θ −0.6°; see the notes.)
    // As in the notes' experiment, the hidden ceiling gets white (footnote 5), which is its
    // truth here; with the ceiling estimated instead, see tests/unseen.rs.
    let scene = scaled("scenes/figure6/scene.toml", 0.5);
    let mut white = RecoverOptions::default();
    white.unseen.enabled = false;
    let (rec, log) = run_with(&scene, 256, white);
    eprintln!("{}", table(&scene, &rec));
    for name in [
        "left_wall",
        "right_wall",
        "back_wall",
        "big_block",
        "small_block",
        "floor",
    ] {
        let st = state(&rec, name);
        let t = truth(&scene, name);
        let dr = (st.params.rho_d - t.rho_d()).abs().max_element();
        let ds = (st.params.rho_s - t.rho_s()).abs().max_element();
        assert!(
            dr < 0.015 && ds < 0.015,
            "{name}: ρd {} vs {}, ρs {} vs {}",
            st.params.rho_d,
            t.rho_d(),
            st.params.rho_s,
            t.rho_s()
        );
        assert_eq!(st.status, Status::Confirmed, "{name}");
        let want = if name == "floor" {
            Level::Anisotropic
        } else {
            Level::Diffuse
        };
        assert_eq!(st.level, want, "{name}");
    }
    let floor = state(&rec, "floor").params;
    assert!(
        (floor.alpha_x / 0.07 - 1.0).abs() < 0.04,
        "αx {}",
        floor.alpha_x
    );
    assert!(
        (floor.alpha_y / 0.11 - 1.0).abs() < 0.04,
        "αy {}",
        floor.alpha_y
    );
    assert!(
        floor.theta.to_degrees().abs() < 1.5,
        "θ {}°",
        floor.theta.to_degrees()
    );
    assert_eq!(
        state(&rec, "ceiling").status,
        Status::Default,
        "the ceiling is out of view"
    );
    assert_eq!(state(&rec, "light").status, Status::Light);
    // The floor climbed the levels in order, each tried once, before settling.
    let tried: Vec<Level> = log
        .iter()
        .filter(|(g, _)| g == "floor")
        .filter_map(|(_, e)| {
            if let Event::Tried { level, .. } = e {
                Some(*level)
            } else {
                None
            }
        })
        .collect();
    let first: Vec<Level> = tried.iter().copied().take(5).collect();
    assert_eq!(
        first,
        vec![
            Level::PerfectSpecular,
            Level::Specular,
            Level::DiffuseSpecular,
            Level::Isotropic,
            Level::Anisotropic
        ],
        "climb order {tried:?}"
    );
}

#[test]
fn glossy_scene_groups_are_confirmed_at_their_own_levels() {
    // Every group at its own level; ρ within 0.03 and α within 5% at a quarter of the pixels.
    // Measured here: walls and floor within 0.002, mirror ρs −0.011, lacquer box ρd +0.015 /
    // ρs −0.020 (its mirror part is nearly collinear with its diffuse shading), sphere ρ within
    // 0.004 and α +1.1%. The target is 0.01 / 3%: not met yet for the mirror and the box.
    let scene = scaled("scenes/glossy/scene.toml", 0.5);
    let (rec, _) = run(&scene, 256);
    eprintln!("{}", table(&scene, &rec));
    for (name, level) in [
        ("mirror", Level::Specular),
        ("glossy_sphere", Level::Isotropic),
        ("lacquer_box", Level::DiffuseSpecular),
        ("floor", Level::Diffuse),
        ("walls", Level::Diffuse),
    ] {
        let st = state(&rec, name);
        assert_eq!((st.level, st.status), (level, Status::Confirmed), "{name}");
        let t = truth(&scene, name);
        let dr = (st.params.rho_d - t.rho_d()).abs().max_element();
        let ds = (st.params.rho_s - t.rho_s()).abs().max_element();
        assert!(
            dr < 0.03 && ds < 0.03,
            "{name}: ρd {} vs {}, ρs {} vs {}",
            st.params.rho_d,
            t.rho_d(),
            st.params.rho_s,
            t.rho_s()
        );
    }
    let a = state(&rec, "glossy_sphere").params.alpha_x;
    assert!((a / 0.15 - 1.0).abs() < 0.05, "α {a}");
}

/// A stall: a group whose parameters keep moving by more than the settle tolerance (here built
/// by a tolerance below the Monte Carlo jitter of every fit, 0.002, as a weakly determined lobe
/// does at the default one) would keep the scene from ever "settling", so that no group could
/// climb after the first ones (on the glossy scene the groups would stay diffuse and the run end
/// with them analysing). Parameters that stopped converging count as settled, so every group
/// reaches its own level and ends decided.
#[test]
fn jitter_above_the_settle_tolerance_does_not_stall_the_hierarchy() {
    let scene = scaled("scenes/glossy/scene.toml", 0.5);
    let (rec, log) = run_with(
        &scene,
        256,
        RecoverOptions {
            settle: 0.002,
            ..Default::default()
        },
    );
    eprintln!("{}", table(&scene, &rec));
    for g in &rec.groups {
        assert_ne!(g.status, Status::Analysing, "{} undecided", g.name);
    }
    for (name, level) in [
        ("mirror", Level::Specular),
        ("glossy_sphere", Level::Isotropic),
        ("lacquer_box", Level::DiffuseSpecular),
    ] {
        assert_eq!(state(&rec, name).level, level, "{name}");
    }
    assert!(
        log.iter().any(|(_, e)| matches!(e, Event::Jitter { .. })),
        "the jitter is logged"
    );
}
