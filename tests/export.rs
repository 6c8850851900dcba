//! `matfit export mitsuba`: the PLYs carry the scene's triangles exactly, the XML the camera,
//! filter, two-sided BSDFs and the lights (issue 3, cross-check against an independent renderer).

use crate::common::{root, run};
use matfit::scene::load_scene;

/// Parses a binary little-endian PLY as written by the exporter: (positions, faces).
fn read_ply(bytes: &[u8]) -> (Vec<[f32; 3]>, Vec<[u32; 3]>) {
    let end = b"end_header\n";
    let hdr_len = bytes
        .windows(end.len())
        .position(|w| w == end)
        .expect("a PLY header")
        + end.len();
    let header = std::str::from_utf8(&bytes[..hdr_len]).unwrap();
    assert!(
        header.contains("format binary_little_endian 1.0"),
        "{header}"
    );
    let count = |elem: &str| -> usize {
        header
            .lines()
            .find_map(|l| l.strip_prefix(&format!("element {elem} ")))
            .unwrap()
            .parse()
            .unwrap()
    };
    let props: Vec<&str> = header
        .lines()
        .filter_map(|l| l.strip_prefix("property float "))
        .collect();
    assert_eq!(props, ["x", "y", "z", "nx", "ny", "nz", "u", "v"]);
    let (nv, nf) = (count("vertex"), count("face"));
    let f32_at = |o: usize| f32::from_le_bytes(bytes[o..o + 4].try_into().unwrap());
    let positions = (0..nv)
        .map(|i| {
            let o = hdr_len + i * 32;
            [f32_at(o), f32_at(o + 4), f32_at(o + 8)]
        })
        .collect();
    let mut o = hdr_len + nv * 32;
    let mut faces = Vec::new();
    for _ in 0..nf {
        assert_eq!(bytes[o], 3, "triangles only");
        let idx =
            |k: usize| u32::from_le_bytes(bytes[o + 1 + 4 * k..o + 5 + 4 * k].try_into().unwrap());
        faces.push([idx(0), idx(1), idx(2)]);
        o += 13;
    }
    assert_eq!(o, bytes.len(), "no trailing bytes");
    (positions, faces)
}

fn area(p: &[[f32; 3]], f: &[u32; 3]) -> f64 {
    let v = |i: u32| glam::DVec3::from(p[i as usize].map(f64::from));
    0.5 * (v(f[1]) - v(f[0])).cross(v(f[2]) - v(f[0])).length()
}

#[test]
fn figure6_exports_the_same_triangles_camera_and_lights() {
    let scene_path = root().join("scenes/figure6/scene.toml");
    let scene = load_scene(&scene_path).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("mi");
    let (code, stdout, stderr) = run(
        &[
            "export",
            "mitsuba",
            scene_path.to_str().unwrap(),
            "-o",
            out.to_str().unwrap(),
        ],
        dir.path(),
    );
    assert_eq!(code, 0, "{stdout}\n{stderr}");
    // The anisotropic Ward floor cannot be carried over: the user is told.
    assert!(
        stderr.contains("warning: object 'floor': Ward has no Mitsuba equivalent"),
        "{stderr}"
    );

    let xml = std::fs::read_to_string(out.join("scene.xml")).unwrap();
    let mut triangles = 0;
    let mut total_area = 0.0;
    for (oi, obj) in scene.objects.iter().enumerate() {
        let file = format!("meshes/{oi:03}_{}.ply", obj.name);
        assert!(
            xml.contains(&format!("value=\"{file}\"")),
            "{file} in\n{xml}"
        );
        let (p, f) = read_ply(&std::fs::read(out.join(&file)).unwrap());
        assert_eq!(f.len(), obj.tri_range.len(), "{}", obj.name);
        // The same triangles in the same vertex order (so the same front sides).
        let g = &scene.geometry;
        for (face, tri) in f.iter().zip(&g.tris[obj.tri_range.start as usize..]) {
            for k in 0..3 {
                assert_eq!(
                    p[face[k] as usize],
                    g.positions[tri.v[k] as usize].to_array()
                );
            }
        }
        let a: f64 = f.iter().map(|t| area(&p, t)).sum();
        assert!(
            (a - obj.area as f64).abs() < 1e-4 * obj.area as f64,
            "{}: {a} vs {}",
            obj.name,
            obj.area
        );
        triangles += f.len();
        total_area += a;
    }
    assert_eq!(triangles, scene.triangle_count());
    let scene_area: f64 = scene.objects.iter().map(|o| o.area as f64).sum();
    assert!((total_area - scene_area).abs() < 1e-4 * scene_area);

    assert!(xml.contains("<scene version=\"3.0.0\">"));
    assert!(
        xml.contains("<string name=\"fov_axis\" value=\"y\"/>"),
        "{xml}"
    );
    assert!(xml.contains("<float name=\"fov\" value=\"40"), "{xml}");
    assert!(xml.contains("<rfilter type=\"box\"/>"));
    assert!(xml.contains("<integer name=\"max_depth\" value=\"8\"/>"));
    assert!(xml.contains("<integer name=\"rr_depth\" value=\"5\"/>"));
    // One two-sided BSDF per group, named like it, and every shape refers to its group's.
    assert_eq!(
        xml.matches("<bsdf type=\"twosided\" id=").count(),
        scene.groups.len(),
        "every BSDF is two-sided, one per group"
    );
    assert_eq!(xml.matches("<ref id=").count(), scene.objects.len());
    assert!(xml.contains("<ref id=\"back_wall\"/>") && xml.contains("id=\"front_wall\""));
    assert_eq!(xml.matches("<emitter type=\"area\">").count(), 1);
    assert!(
        xml.contains("<rgb name=\"radiance\" value=\"30, 30, 30\"/>"),
        "{xml}"
    );
    assert!(
        !xml.contains("principal_point_offset"),
        "a look-at camera is centred"
    );
}
