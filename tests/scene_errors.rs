//! Bad scene files: each gets a clear message naming the file and the line, key or object at
//! fault, and a non-zero exit, never a panic.

use crate::common::{run, write, SMALL_SCENE};

/// (case, scene text, extra files, substrings the error must contain)
type Case = (
    &'static str,
    String,
    Vec<(&'static str, &'static [u8])>,
    Vec<&'static str>,
);

fn cases() -> Vec<Case> {
    let s = SMALL_SCENE;
    let floor_mesh = |file: &str| {
        s.replace(
            "shape = \"quad\"\ncorner = [-1.0, 0.0, 1.0]",
            &format!("shape = \"mesh\"\nfile = \"{file}\"\ncorner = [-1.0, 0.0, 1.0]"),
        )
    };
    vec![
        ("malformed toml", s.replace("width = 64", "width = = 64"), vec![], vec!["scene.toml", "line 3"]),
        (
            "unknown key with suggestion",
            s.replace("fov_y_deg = 45.0", "fov_y_degs = 45.0"),
            vec![],
            vec!["scene.toml", "line 7", "fov_y_degs", "did you mean `fov_y_deg`?"],
        ),
        ("wrong type", s.replace("width = 64", "width = \"wide\""), vec![], vec!["scene.toml", "line 3", "width"]),
        (
            "unknown shape with suggestion",
            s.replacen("shape = \"quad\"", "shape = \"quadd\"", 1),
            vec![],
            vec!["scene.toml", "quadd", "did you mean `quad`?"],
        ),
        (
            "unknown material type",
            s.replace("type = \"diffuse\"", "type = \"difuse\""),
            vec![],
            vec!["scene.toml", "line 16", "difuse", "did you mean `diffuse`?"],
        ),
        (
            "missing mesh file",
            floor_mesh("nowhere.obj"),
            vec![],
            vec!["scene.toml:13", "object 'floor'", "nowhere.obj", "not found"],
        ),
        (
            "corrupt mesh file",
            floor_mesh("bad.ply"),
            vec![("bad.ply", b"ply\nformat ascii 1.0\nelement vertex 3\nend_he")],
            vec!["scene.toml:13", "object 'floor'", "bad.ply"],
        ),
        (
            "mesh with NaN vertex",
            floor_mesh("nan.obj"),
            vec![("nan.obj", b"v 0 0 0\nv 1 0 nan\nv 0 1 0\nf 1 2 3\n")],
            vec!["scene.toml:13", "object 'floor'", "NaN"],
        ),
        (
            "mesh of only degenerate triangles",
            floor_mesh("flat.obj"),
            vec![("flat.obj", b"v 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\n")],
            vec!["scene.toml:13", "object 'floor'", "degenerate"],
        ),
        (
            "mesh with no triangles",
            floor_mesh("empty.obj"),
            vec![("empty.obj", b"v 0 0 0\nv 1 0 0\n")],
            vec!["scene.toml:13", "object 'floor'", "no triangles"],
        ),
        (
            "duplicate object name",
            s.replace("name = \"lamp\"", "name = \"floor\""),
            vec![],
            vec!["scene.toml:19", "object 'floor' is defined twice", "line 10"],
        ),
        (
            "duplicate group declaration",
            format!("{s}\n[[group]]\nname = \"g\"\n[[group]]\nname = \"g\"\n"),
            vec![],
            vec!["scene.toml", "group 'g' is declared twice"],
        ),
        (
            "object in no group",
            s.replace("group = \"lamp\"\n", ""),
            vec![],
            vec!["scene.toml:19", "object 'lamp' is in no group"],
        ),
        (
            "camera sees no geometry",
            s.replace("target = [0.0, 0.0, 0.0]", "target = [0.0, 4.0, 4.0]"),
            vec![],
            vec!["scene.toml", "sees no geometry"],
        ),
        (
            "negative light radiance",
            s.replace("emission = 5.0", "emission = [5.0, -1.0, 5.0]"),
            vec![],
            vec!["scene.toml:25", "object 'lamp'", "non-negative"],
        ),
        (
            "light with zero area",
            s.replace("edge_u = [0.4, 0.0, 0.0]", "edge_u = [0.0, 0.0, 0.0]"),
            vec![],
            vec!["scene.toml:21", "lamp", "degenerate"],
        ),
        (
            "camera form incomplete",
            s.replace("fov_y_deg = 45.0", ""),
            vec![],
            vec!["scene.toml", "[camera] lacks fov_y_deg"],
        ),
        (
            "camera forms mixed",
            s.replace("fov_y_deg = 45.0", "fov_y_deg = 45.0\nfx = 100.0"),
            vec![],
            vec!["scene.toml", "mixes the look-at form"],
        ),
        (
            "calibrated camera with a non-rotation",
            s.replace(
                "eye = [0.0, 2.0, 2.0]\ntarget = [0.0, 0.0, 0.0]\nfov_y_deg = 45.0",
                "fx = 50.0\nfy = 50.0\ncx = 32.0\ncy = 24.0\nrotation = [[2.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]\ntranslation = [0.0, 0.0, 0.0]",
            ),
            vec![],
            vec!["scene.toml", "rotation matrix"],
        ),
        (
            "ward without alpha",
            s.replace("type = \"diffuse\", rho_d = 0.5", "type = \"ward\", rho_d = 0.5, rho_s = 0.2"),
            vec![],
            vec!["scene.toml:16", "object 'floor'", "alpha"],
        ),
        (
            "negative reflectance",
            s.replace("rho_d = 0.5", "rho_d = [0.5, -0.1, 0.5]"),
            vec![],
            vec!["scene.toml:16", "rho_d", "non-negative"],
        ),
        (
            "colour with two components",
            s.replace("rho_d = 0.5", "rho_d = [0.5, 0.5]"),
            vec![],
            vec!["scene.toml", "line 16", "three numbers"],
        ),
        ("zero-size camera", s.replace("width = 64", "width = 0"), vec![], vec!["scene.toml", "width and height"]),
        (
            "box with max below min",
            format!("{s}\n[[object]]\nname = \"b\"\ngroup = \"b\"\nshape = \"box\"\nmin = [0.0, 0.0, 0.0]\nmax = [1.0, -1.0, 1.0]\n"),
            vec![],
            vec!["scene.toml:30", "object 'b'", "max"],
        ),
        (
            "quad missing an edge",
            s.replace("edge_v = [0.0, 0.0, -2.0]\n", ""),
            vec![],
            vec!["scene.toml:12", "object 'floor'", "edge_v"],
        ),
        ("no objects", s[..s.find("[[object]]").unwrap()].to_string(), vec![], vec!["scene.toml", "no objects"]),
    ]
}

#[test]
fn every_bad_scene_gets_a_clear_error() {
    let mut failures = Vec::new();
    for (name, text, files, expect) in cases() {
        let dir = tempfile::tempdir().unwrap();
        write(dir.path(), "scene.toml", &text);
        for (f, bytes) in files {
            std::fs::write(dir.path().join(f), bytes).unwrap();
        }
        let (code, _, err) = run(&["info", "scene.toml"], dir.path());
        let missing: Vec<_> = expect.iter().filter(|e| !err.contains(*e)).collect();
        if code != 2 || !missing.is_empty() || err.contains("panicked") {
            failures.push(format!(
                "{name}: exit {code}, missing {missing:?} in:\n{err}"
            ));
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n\n"));
}

#[test]
fn missing_scene_file_and_unwritable_output() {
    let dir = tempfile::tempdir().unwrap();
    let (code, _, err) = run(&["render", "absent.toml", "-o", "x.png"], dir.path());
    assert_eq!(code, 2);
    assert!(err.contains("absent.toml"), "{err}");
    write(dir.path(), "scene.toml", SMALL_SCENE);
    let (code, _, err) = run(
        &[
            "render",
            "scene.toml",
            "-o",
            "no/such/dir/x.png",
            "--spp",
            "1",
        ],
        dir.path(),
    );
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("no/such/dir/x.png"), "{err}");
    let (code, _, err) = run(
        &["render", "scene.toml", "-o", "x.bmp", "--spp", "1"],
        dir.path(),
    );
    assert_eq!(code, 2);
    assert!(err.contains(".exr, .hdr, .pfm or .png"), "{err}");
}
