//! Bad scene files: each gets a clear message naming the file and the line, key or object at
//! fault, and a non-zero exit, never a panic.

use crate::common::{run, small_scene, write};

/// (case, scene text, extra files, substrings the error must contain)
type Case = (
    &'static str,
    String,
    Vec<(&'static str, &'static [u8])>,
    Vec<&'static str>,
);

fn cases() -> Vec<Case> {
    let s = small_scene();
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
            vec!["scene.toml:9", "rotation is not a rotation matrix", "determinant +1 (it is 2"],
        ),
        (
            "orthographic camera with a field of view",
            s.replace("fov_y_deg = 45.0", "fov_y_deg = 45.0\nprojection = \"orthographic\""),
            vec![],
            vec!["scene.toml:7", "orthographic camera has no field of view", "width_m"],
        ),
        (
            "width_m on a perspective camera",
            s.replace("fov_y_deg = 45.0", "fov_y_deg = 45.0\nwidth_m = 2.0"),
            vec![],
            vec!["scene.toml:8", "width_m", "projection = \"orthographic\""],
        ),
        (
            "orthographic camera of no width",
            s.replace("fov_y_deg = 45.0", "projection = \"orthographic\"\nwidth_m = 0.0"),
            vec![],
            vec!["scene.toml:8", "width_m", "must be > 0"],
        ),
        (
            "orthographic camera with lens distortion",
            s.replace(
                "fov_y_deg = 45.0",
                "projection = \"orthographic\"\nwidth_m = 3.0\ndistortion = [0.1, 0.0, 0.0, 0.0, 0.0]",
            ),
            vec![],
            vec!["scene.toml:9", "distortion", "orthographic camera has no lens"],
        ),
        (
            "unknown projection",
            s.replace("fov_y_deg = 45.0", "fov_y_deg = 45.0\nprojection = \"orthogonal\""),
            vec![],
            vec!["scene.toml", "line 8", "orthogonal", "did you mean `orthographic`?"],
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
        // More bad inputs.
        (
            "NaN in the camera",
            s.replace("eye = [0.0, 2.0, 2.0]", "eye = [nan, 2.0, 2.0]"),
            vec![],
            vec!["scene.toml", "[camera] has a NaN or infinite value"],
        ),
        (
            "misspelt table with suggestion",
            s.replace("[camera]", "[camra]"),
            vec![],
            vec!["scene.toml", "line 2", "camra", "did you mean `camera`?"],
        ),
        (
            "camera beyond the pixel limit",
            s.replace("width = 64", "width = 65536").replace("height = 48", "height = 65536"),
            vec![],
            vec!["scene.toml", "65536×65536", "megapixels"],
        ),
        (
            "mesh in an unknown format",
            floor_mesh("floor.stl"),
            vec![("floor.stl", b"solid x\nendsolid x\n")],
            vec!["scene.toml:13", "object 'floor'", "unknown format '.stl'"],
        ),
        (
            "mesh face referring to a missing vertex",
            floor_mesh("oob.ply"),
            vec![(
                "oob.ply",
                b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\n\
                  element face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 0 1\n3 0 1 7\n",
            )],
            vec!["scene.toml:13", "object 'floor'", "triangle 0 refers to vertex 7"],
        ),
        (
            "PLY header with an impossible element count",
            floor_mesh("huge.ply"),
            vec![(
                "huge.ply",
                b"ply\nformat ascii 1.0\nelement vertex 99999999999999999999999\nproperty float x\nend_header\n",
            )],
            vec!["scene.toml:13", "object 'floor'", "huge.ply", "number too large"],
        ),
        (
            "corrupt glTF",
            floor_mesh("bad.gltf"),
            vec![("bad.gltf", b"{ \"asset\": ")],
            vec!["scene.toml:13", "object 'floor'", "bad.gltf", "not a readable glTF file"],
        ),
        (
            "mesh path is a folder",
            floor_mesh("meshes.obj/"),
            vec![("meshes.obj/", b"")],
            vec!["scene.toml:13", "object 'floor'", "is a folder"],
        ),
        (
            "transform with a NaN rotation",
            s.replacen(
                "edge_v = [0.0, 0.0, -2.0]",
                "edge_v = [0.0, 0.0, -2.0]\ntransform = { rotate_deg = [nan, 0.0, 0.0] }",
                1,
            ),
            vec![],
            vec!["scene.toml:12", "object 'floor'", "NaN"],
        ),
        (
            "transform scaling to nothing",
            s.replacen(
                "edge_v = [0.0, 0.0, -2.0]",
                "edge_v = [0.0, 0.0, -2.0]\ntransform = { scale = 0.0 }",
                1,
            ),
            vec![],
            vec!["scene.toml:12", "object 'floor'", "degenerate"],
        ),
        (
            "missing texture",
            s.replace(
                "{ type = \"diffuse\", rho_d = 0.5 }",
                "{ type = \"textured\", texture = \"nowhere.png\" }",
            ),
            vec![],
            vec!["scene.toml:16", "object 'floor'", "texture", "nowhere.png"],
        ),
        (
            "corrupt texture",
            s.replace(
                "{ type = \"diffuse\", rho_d = 0.5 }",
                "{ type = \"textured\", texture = \"t.png\" }",
            ),
            vec![("t.png", b"\x89PNG\r\n\x1a\n\x00\x00")],
            vec!["scene.toml:16", "object 'floor'", "t.png", "truncated or corrupt"],
        ),
        (
            "varnish lobe without its rho_s",
            s.replace(
                "{ type = \"diffuse\", rho_d = 0.5 }",
                "{ type = \"textured\", texture = \"t.png\", alpha = 0.1 }",
            ),
            vec![],
            vec!["scene.toml:16", "object 'floor'", "`alpha` goes with `rho_s`"],
        ),
        (
            "plastic coat without its rho_s",
            s.replace(
                "{ type = \"diffuse\", rho_d = 0.5 }",
                "{ type = \"textured\", texture = \"t.png\", alpha = 0.1, eta = 1.5 }",
            ),
            vec![],
            vec!["scene.toml:16", "object 'floor'", "`eta` goes with `rho_s`"],
        ),
        (
            "anisotropic plastic coat",
            s.replace(
                "{ type = \"diffuse\", rho_d = 0.5 }",
                "{ type = \"textured\", texture = \"t.png\", rho_s = 0.04, alpha_x = 0.1, \
                 alpha_y = 0.2, eta = 1.5 }",
            ),
            vec![],
            vec!["scene.toml:16", "object 'floor'", "coat (`eta`) is isotropic"],
        ),
        (
            "distribution without a coat",
            s.replace(
                "{ type = \"diffuse\", rho_d = 0.5 }",
                "{ type = \"textured\", texture = \"t.png\", distribution = \"beckmann\" }",
            ),
            vec![],
            vec!["scene.toml:16", "object 'floor'", "`distribution` goes with `eta`"],
        ),
        (
            "NaN emission",
            s.replace("emission = 5.0", "emission = nan"),
            vec![],
            vec!["scene.toml:25", "object 'lamp'", "finite and non-negative"],
        ),
        (
            "sphere with a negative radius",
            format!("{s}\n[[object]]\nname = \"ball\"\ngroup = \"ball\"\nshape = \"sphere\"\ncenter = [0.0, 0.5, 0.0]\nradius = -0.3\n"),
            vec![],
            vec!["scene.toml:30", "object 'ball'", "radius must be positive"],
        ),
        (
            "sphere with too many segments",
            format!("{s}\n[[object]]\nname = \"ball\"\ngroup = \"ball\"\nshape = \"sphere\"\ncenter = [0.0, 0.5, 0.0]\nradius = 0.3\nsegments = 100000\n"),
            vec![],
            vec!["scene.toml:30", "object 'ball'", "between 8 and 1024"],
        ),
        (
            "surface reflecting more than it receives",
            s.replace(
                "type = \"diffuse\", rho_d = 0.5",
                "type = \"diffuse_mirror\", rho_d = 0.7, rho_s = [0.2, 0.5, 0.2]",
            ),
            vec![],
            vec!["scene.toml:16", "object 'floor'", "at most 1", "green channel"],
        ),
        (
            "ward with a negative roughness",
            s.replace(
                "type = \"diffuse\", rho_d = 0.5",
                "type = \"ward\", rho_d = 0.5, rho_s = 0.2, alpha = -0.1",
            ),
            vec![],
            vec!["scene.toml:16", "object 'floor'", "`alpha` must be positive"],
        ),
        (
            "zero samples per pixel",
            format!("[render]\nspp = 0\n{s}"),
            vec![],
            vec!["scene.toml", "spp must be at least 1"],
        ),
        (
            "shape named by another word",
            s.replacen("shape = \"quad\"", "shape = \"cube\"", 1),
            vec![],
            vec!["scene.toml", "cube", "did you mean `box`?"],
        ),
        (
            "camera key named by another word",
            s.replace("fov_y_deg = 45.0", "fov = 45.0"),
            vec![],
            vec!["scene.toml", "line 7", "did you mean `fov_y_deg`?"],
        ),
        (
            "camera eye at its target",
            s.replace("target = [0.0, 0.0, 0.0]", "target = [0.0, 2.0, 2.0]"),
            vec![],
            vec!["scene.toml:6", "eye and target are the same point"],
        ),
        (
            "camera field of view out of range",
            s.replace("fov_y_deg = 45.0", "fov_y_deg = 200.0"),
            vec![],
            vec!["scene.toml:7", "fov_y_deg", "(0, 180), got 200"],
        ),
        (
            "camera looking straight down with the default up",
            s.replace("eye = [0.0, 2.0, 2.0]", "eye = [0.0, 2.0, 0.0]"),
            vec![],
            vec!["scene.toml:6", "parallel to the default up", "give `up`"],
        ),
        (
            "camera up along the view",
            s.replace("fov_y_deg = 45.0", "fov_y_deg = 45.0\nup = [0.0, -1.0, -1.0]"),
            vec![],
            vec!["scene.toml:8", "up [0.0, -1.0, -1.0] is parallel to the view direction"],
        ),
        (
            "object with an empty name",
            s.replace("name = \"lamp\"", "name = \"  \""),
            vec![],
            vec!["scene.toml:19", "empty name"],
        ),
        (
            "declared group with no object",
            format!("{s}\n[[group]]\nname = \"ghost\"\n"),
            vec![],
            vec!["scene.toml", "group 'ghost' is declared but no object is in it"],
        ),
    ]
}

#[test]
fn every_bad_scene_gets_a_clear_error() {
    let mut failures = Vec::new();
    for (name, text, files, expect) in cases() {
        let dir = tempfile::tempdir().unwrap();
        write(dir.path(), "scene.toml", &text);
        for (f, bytes) in files {
            match f.strip_suffix('/') {
                Some(folder) => std::fs::create_dir(dir.path().join(folder)).unwrap(),
                None => std::fs::write(dir.path().join(f), bytes).unwrap(),
            }
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
fn scene_file_that_is_not_text_or_not_a_file() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("bin.toml"), b"[camera]\nwidth = \xff\xfe\n").unwrap();
    let (code, _, err) = run(&["info", "bin.toml"], dir.path());
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("bin.toml") && err.contains("UTF-8"), "{err}");
    std::fs::create_dir(dir.path().join("folder.toml")).unwrap();
    let (code, _, err) = run(&["info", "folder.toml"], dir.path());
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("cannot read scene file folder.toml"), "{err}");
}

#[test]
fn missing_scene_file_and_unwritable_output() {
    let dir = tempfile::tempdir().unwrap();
    let (code, _, err) = run(&["render", "absent.toml", "-o", "x.png"], dir.path());
    assert_eq!(code, 2);
    assert!(err.contains("absent.toml"), "{err}");
    write(dir.path(), "scene.toml", &small_scene());
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
