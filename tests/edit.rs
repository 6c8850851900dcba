//! Using the recovered scene (§7 of the notes). Edits given as `matfit render` flags
//! or as an edit file render exactly the scene written by hand with those edits; unknown names
//! are errors that suggest the nearest one; `matfit composite` puts a new object into the photo
//! by differential rendering, with its shadow and its reflection on the photographed surfaces.

use crate::common::{diffuse, material, root, run, write, SceneToml};
use matfit::io::image::{read_linear, Image};
use matfit::math::{Rgb, Vec2, Vec3};
use matfit::scene::load_scene;
use std::path::Path;

/// The small room at 48 × 36 pixels with a red block on the floor.
fn base() -> String {
    SceneToml::spaced()
        .render(&[("spp", "8"), ("seed", "3")])
        .camera_above(48, 36)
        .floor(&diffuse(&[0.5]))
        .cuboid(
            "block",
            "blocks",
            [0.2, 0.0, -0.6],
            [0.6, 0.4, -0.2],
            &diffuse(&[0.7, 0.2, 0.1]),
        )
        .lamp(5.0)
        .to_toml()
}

/// [`base`] with the edits of [`FLAGS`] written by hand.
fn edited() -> String {
    SceneToml::spaced()
        .render(&[("spp", "8"), ("seed", "3")])
        .camera(48, 36, [1.0, 2.0, 2.5], [0.0, 0.2, 0.0], 50.0)
        .quad(
            "floor",
            "floor",
            [-1.0, 0.1, 1.0],
            [2.0, 0.0, 0.0],
            [0.0, 0.0, -2.0],
            &diffuse(&[0.2, 0.4, 0.6]),
        )
        .lamp(10.0)
        .sphere(
            "ball",
            "ball",
            [0.0, 0.4, 0.0],
            0.3,
            None,
            &material(r#"{ type = "ward", rho_d = 0.3, rho_s = 0.2, alpha = 0.1 }"#),
        )
        .to_toml()
}

const FLAGS: [&str; 16] = [
    "--remove",
    "blocks",
    "--move",
    "floor=0,0.1,0",
    "--scale-light",
    "lamp=2",
    "--material",
    "floor={ type = \"diffuse\", rho_d = [0.2, 0.4, 0.6] }",
    "--add",
    "{ name = \"ball\", group = \"ball\", shape = \"sphere\", center = [0, 0.4, 0], radius = 0.3, \
     material = { type = \"ward\", rho_d = 0.3, rho_s = 0.2, alpha = 0.1 } }",
    "--look-from",
    "1,2,2.5",
    "--look-at",
    "0,0.2,0",
    "--fov",
    "50",
];

/// The same edits as an edit file.
const EDIT_FILE: &str = r#"
remove = ["blocks"]

[camera]
eye = [1.0, 2.0, 2.5]
target = [0.0, 0.2, 0.0]
fov_y_deg = 50.0

[[object]]
name = "ball"
group = "ball"
shape = "sphere"
center = [0.0, 0.4, 0.0]
radius = 0.3
material = { type = "ward", rho_d = 0.3, rho_s = 0.2, alpha = 0.1 }

[[material]]
group = "floor"
material = { type = "diffuse", rho_d = [0.2, 0.4, 0.6] }

[[move]]
object = "floor"
translate = [0.0, 0.1, 0.0]

[[light]]
object = "lamp"
scale = 2.0
"#;

fn render(dir: &Path, scene: &str, out: &str, extra: &[&str]) -> Image {
    let mut args = vec!["render", scene, "-o", out];
    args.extend(extra);
    let (code, _, err) = run(&args, dir);
    assert_eq!(code, 0, "{err}");
    read_linear(&dir.join(out)).unwrap()
}

#[test]
fn edits_by_flags_or_file_render_the_hand_edited_scene_to_the_bit() {
    let d = tempfile::tempdir().unwrap();
    let dir = d.path();
    write(dir, "scene.toml", &base());
    write(dir, "edited.toml", &edited());
    write(dir, "edit.toml", EDIT_FILE);
    let truth = render(dir, "edited.toml", "truth.exr", &[]);
    let by_flags = render(dir, "scene.toml", "flags.exr", &FLAGS);
    let by_file = render(dir, "scene.toml", "file.exr", &["--edit", "edit.toml"]);
    let plain = render(dir, "scene.toml", "plain.exr", &[]);
    assert!(truth.mean().max_element() > 0.01, "the edited scene is lit");
    assert_eq!(
        by_flags.data, truth.data,
        "flags = the scene edited by hand"
    );
    assert_eq!(
        by_file.data, truth.data,
        "edit file = the scene edited by hand"
    );
    assert_ne!(plain.data, truth.data);
}

#[test]
fn unknown_names_and_bad_edits_are_errors_that_say_what_to_write() {
    let d = tempfile::tempdir().unwrap();
    let dir = d.path();
    write(dir, "scene.toml", &base());
    let fails = |args: &[&str]| {
        let mut a = vec!["render", "scene.toml", "-o", "x.exr"];
        a.extend(args);
        let (code, _, err) = run(&a, dir);
        assert_eq!(code, 2, "{args:?}: {err}");
        assert!(!dir.join("x.exr").exists(), "nothing written on an error");
        err
    };
    let e = fails(&["--remove", "blok"]);
    assert!(
        e.contains("'blok'") && e.contains("did you mean 'block'"),
        "{e}"
    );
    let e = fails(&["--move", "florr=0,1,0"]);
    assert!(e.contains("did you mean 'floor'"), "{e}");
    let e = fails(&["--scale-light", "floor=2"]);
    assert!(e.contains("not a light"), "{e}");
    let e = fails(&["--look-from", "1,2,3"]);
    assert!(e.contains("--look-at"), "{e}");
    let e = fails(&["--move", "floor=0,1"]);
    assert!(e.contains("3 comma-separated"), "{e}");
    // An edit file's error points at its own line; an unknown key suggests the right one.
    write(
        dir,
        "bad.toml",
        "\n[[object]]\nname = \"b\"\ngroup = \"b\"\nshape = \"sphere\"\ncenter = [0, 0, 0]\nradius = -1\n",
    );
    let e = fails(&["--edit", "bad.toml"]);
    assert!(e.contains("bad.toml:"), "{e}");
    write(
        dir,
        "typo.toml",
        "[[move]]\nobject = \"floor\"\ntranslat = [0, 1, 0]\n",
    );
    let e = fails(&["--edit", "typo.toml"]);
    assert!(e.contains("translate"), "{e}");
}

/// figure6 at 160×120: the photo, the scene edited with a ball on the floor (the truth), and
/// the composite of that ball into the photo.
struct Figure6Ar {
    photo: Image,
    truth: Image,
    composite: Image,
    scene: matfit::scene::Scene,
}

const BALL_CENTER: [f32; 3] = [0.15, 0.3, -2.7];
const BALL_RADIUS: f32 = 0.3;

fn figure6_small(dir: &Path) {
    let text = std::fs::read_to_string(root().join("scenes/figure6/scene.toml")).unwrap();
    let text = text
        .replace("width = 512", "width = 160")
        .replace("height = 384", "height = 120");
    assert!(text.contains("width = 160") && text.contains("spp = 256"));
    write(dir, "scene.toml", &text);
}

/// The photo of figure6 (its true materials, 64 spp, seed 5), with a patch on the left wall
/// brightened by 30%: a detail of the real room that the model lacks (a poster nobody
/// modelled), which the composite must keep.
fn composite_ball(dir: &Path) -> Figure6Ar {
    figure6_small(dir);
    write(
        dir,
        "ball.toml",
        &format!(
            "[[object]]\nname = \"ball\"\ngroup = \"ball\"\nshape = \"sphere\"\n\
             center = {BALL_CENTER:?}\nradius = {BALL_RADIUS}\n\
             material = {{ type = \"ward\", rho_d = [0.05, 0.2, 0.6], rho_s = 0.3, alpha = 0.1 }}\n"
        ),
    );
    let mut photo = render(dir, "scene.toml", "photo.exr", &["--seed", "5"]);
    for y in 40..60 {
        for x in 4..14 {
            let c = photo.get(x, y);
            photo.set(x, y, c * 1.3);
        }
    }
    photo.write(&dir.join("photo.exr")).unwrap();
    let truth = render(
        dir,
        "scene.toml",
        "truth.exr",
        &["--edit", "ball.toml", "--seed", "9"],
    );
    // The scene stands for the recovered one (its materials are the truth): differential
    // rendering must then reproduce the truth where the ball changes the room.
    let (code, out, err) = run(
        &[
            "composite",
            "scene.toml",
            "photo.exr",
            "--edit",
            "ball.toml",
            "-o",
            "composite.exr",
        ],
        dir,
    );
    assert_eq!(code, 0, "{err}");
    assert!(out.contains("exposure 1 (default"), "{out}");
    Figure6Ar {
        photo,
        truth,
        composite: read_linear(&dir.join("composite.exr")).unwrap(),
        scene: load_scene(&dir.join("scene.toml")).unwrap(),
    }
}

/// The distance along `r` to the ball, if it hits.
fn hits_ball(o: Vec3, d: Vec3) -> Option<f32> {
    let c = Vec3::from(BALL_CENTER);
    let oc = o - c;
    let b = oc.dot(d);
    let disc = b * b - (oc.length_squared() - BALL_RADIUS * BALL_RADIUS);
    if disc < 0.0 {
        return None;
    }
    let t = -b - disc.sqrt();
    (t > 1e-4).then_some(t)
}

fn region_mean(img: &Image, pixels: &[usize]) -> Rgb {
    pixels
        .iter()
        .map(|&i| img.data[i])
        .fold(Rgb::ZERO, |a, c| a + c)
        / pixels.len() as f32
}

fn rel(a: Rgb, b: Rgb) -> f32 {
    (a - b).abs().element_sum() / b.element_sum()
}

#[test]
fn a_ball_composited_on_the_figure6_floor_casts_its_shadow_and_shows_in_the_floor() {
    let d = tempfile::tempdir().unwrap();
    let ar = composite_ball(d.path());
    let sc = &ar.scene;
    let cam = &sc.camera;
    let floor = sc.objects.iter().position(|o| o.name == "floor").unwrap() as u32;
    // The light's corners (scenes/figure6: corner [-0.5, 2.99, -6.6], edges 1 × 0.8).
    let corners = [
        Vec3::new(-0.5, 2.99, -6.6),
        Vec3::new(0.5, 2.99, -6.6),
        Vec3::new(-0.5, 2.99, -5.8),
        Vec3::new(0.5, 2.99, -5.8),
    ];
    let (mut umbra, mut reflection, mut far) = (vec![], vec![], vec![]);
    let (w, h) = (cam.width as usize, cam.height as usize);
    for y in 0..h {
        for x in 0..w {
            let ray = cam.ray(Vec2::new(x as f32 + 0.5, y as f32 + 0.5));
            let Some(hit) = sc.intersect(&ray, f32::INFINITY) else {
                continue;
            };
            if hits_ball(ray.o, ray.d).is_some_and(|t| t < hit.t + 0.5) {
                continue;
            }
            let i = y * w + x;
            if hit.object != floor {
                if hit.p.y > 1.3 && hit.p.z < -6.9 {
                    far.push(i); // the back wall above the blocks
                }
                continue;
            }
            let p = hit.p + Vec3::Y * 1e-3;
            let blocked = corners
                .iter()
                .filter(|&&c| hits_ball(p, (c - p).normalize()).is_some())
                .count();
            let mirror = ray.d - 2.0 * ray.d.dot(Vec3::Y) * Vec3::Y;
            if hits_ball(p, mirror).is_some() {
                reflection.push(i);
            } else if blocked == 4 {
                umbra.push(i);
            }
        }
    }
    eprintln!(
        "umbra {} reflection {} far {}",
        umbra.len(),
        reflection.len(),
        far.len()
    );
    assert!(umbra.len() >= 30, "umbra pixels: {}", umbra.len());
    assert!(
        reflection.len() >= 30,
        "reflection pixels: {}",
        reflection.len()
    );
    assert!(far.len() >= 200, "far pixels: {}", far.len());
    let m = |img: &Image, px: &[usize]| region_mean(img, px);

    // The shadow: the floor under the ball loses its direct light in the composite, as in the
    // truth, not in the photo.
    let (photo, comp, truth) = (
        m(&ar.photo, &umbra),
        m(&ar.composite, &umbra),
        m(&ar.truth, &umbra),
    );
    eprintln!("umbra: photo {photo:?} composite {comp:?} truth {truth:?}");
    assert!(
        comp.element_sum() < 0.7 * photo.element_sum(),
        "shadow falls"
    );
    assert!(rel(comp, truth) < 0.08, "shadow as deep as the truth's");

    // The reflection: floor pixels that see the ball along their mirror direction showed the
    // light's highlight in the photo; the ball's dark underside now hides it, as in the truth.
    // (The photo's Monte Carlo noise there is of the highlight's scale: compared in its units.)
    let (photo, comp, truth) = (
        m(&ar.photo, &reflection),
        m(&ar.composite, &reflection),
        m(&ar.truth, &reflection),
    );
    eprintln!("reflection: photo {photo:?} composite {comp:?} truth {truth:?}");
    assert!(
        comp.element_sum() < 0.1 * photo.element_sum(),
        "the ball hides the highlight"
    );
    assert!(
        (comp - truth).abs().element_sum() < 0.01 * photo.element_sum(),
        "as the truth shows it"
    );

    // Far from the ball, the composite is the photo.
    let (photo, comp) = (m(&ar.photo, &far), m(&ar.composite, &far));
    assert!(rel(comp, photo) < 0.005, "{comp:?} vs {photo:?}");
    // The photo's own detail (the brightened patch) survives; a plain render lacks it.
    let patch: Vec<usize> = (40..60)
        .flat_map(|y| (4..14).map(move |x| y * w + x))
        .collect();
    let (photo, comp, truth) = (
        m(&ar.photo, &patch),
        m(&ar.composite, &patch),
        m(&ar.truth, &patch),
    );
    assert!(rel(comp, photo) < 0.01, "{comp:?} vs {photo:?}");
    assert!(rel(truth, photo) > 0.15, "{truth:?} vs {photo:?}");
}

#[test]
fn a_removed_block_shows_what_was_behind_it_and_composite_refuses_a_new_camera() {
    let d = tempfile::tempdir().unwrap();
    let dir = d.path();
    figure6_small(dir);
    let photo = render(
        dir,
        "scene.toml",
        "photo.exr",
        &["--seed", "5", "--spp", "64"],
    );
    let truth = render(
        dir,
        "scene.toml",
        "truth.exr",
        &["--remove", "small_block", "--seed", "9", "--spp", "64"],
    );
    let (code, _, err) = run(
        &[
            "composite",
            "scene.toml",
            "photo.exr",
            "--remove",
            "small_block",
            "--spp",
            "64",
            "-o",
            "composite.exr",
        ],
        dir,
    );
    assert_eq!(code, 0, "{err}");
    let comp = read_linear(&dir.join("composite.exr")).unwrap();
    // The block's pixels, from the group index buffer of the unedited scene.
    let (code, _, err) = run(
        &["render", "scene.toml", "-o", "groups.exr", "--aov", "group"],
        dir,
    );
    assert_eq!(code, 0, "{err}");
    let sc = load_scene(&dir.join("scene.toml")).unwrap();
    let g = sc.group_index("small_block").unwrap() as f32;
    let ids = read_linear(&dir.join("groups.exr")).unwrap();
    let block: Vec<usize> = (0..ids.data.len())
        .filter(|&i| ids.data[i].x == g)
        .collect();
    assert!(block.len() > 100, "{}", block.len());
    let (p, c, t) = (
        region_mean(&photo, &block),
        region_mean(&comp, &block),
        region_mean(&truth, &block),
    );
    eprintln!("block: photo {p:?} composite {c:?} truth {t:?}");
    assert!(rel(c, p) > 0.3, "the block is gone");
    assert!(rel(c, t) < 0.05, "what was behind it shows");

    let (code, _, err) = run(
        &[
            "composite",
            "scene.toml",
            "photo.exr",
            "--look-from",
            "0,1,0",
            "--look-at",
            "0,0,-3",
            "-o",
            "c2.png",
        ],
        dir,
    );
    assert_eq!(code, 2);
    assert!(err.contains("photo's camera"), "{err}");
}
