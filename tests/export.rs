//! `matfit export mitsuba`: the PLYs carry the scene's triangles exactly, the XML the camera,
//! filter, two-sided BSDFs and the lights (for the cross-check against an independent renderer).

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

/// Mitsuba's `bitmap` lookup as Mitsuba 3.9 does it (checked with its Python bindings): v = 0
/// is the image's top row, bilinear between texel centres, `repeat` or `clamp` at the border.
fn mitsuba_bitmap(img: &matfit::io::image::Image, uv: [f32; 2], repeat: bool) -> [f32; 3] {
    let (w, h) = (img.width as i64, img.height as i64);
    let (x, y) = (uv[0] * w as f32 - 0.5, uv[1] * h as f32 - 0.5);
    let (x0, y0) = (x.floor(), y.floor());
    let (ax, ay) = (x - x0, y - y0);
    let at = |i: i64, j: i64| {
        let (i, j) = if repeat {
            (i.rem_euclid(w), j.rem_euclid(h))
        } else {
            (i.clamp(0, w - 1), j.clamp(0, h - 1))
        };
        img.get(i as usize, j as usize).to_array()
    };
    let (i, j) = (x0 as i64, y0 as i64);
    let taps = [
        (at(i, j), (1.0 - ax) * (1.0 - ay)),
        (at(i + 1, j), ax * (1.0 - ay)),
        (at(i, j + 1), (1.0 - ax) * ay),
        (at(i + 1, j + 1), ax * ay),
    ];
    let mut out = [0.0f32; 3];
    for (c, wt) in taps {
        for k in 0..3 {
            out[k] += c[k] * wt;
        }
    }
    out
}

/// A texture leaves as a `bitmap` that Mitsuba reads, at every surface point the camera sees,
/// where matfit reads it: over a mesh's UVs (the poster, the book spines; a flipped v would
/// mirror them) and over a recovered texture's atlas (charts of boxes, no UVs of their own).
#[test]
fn textures_export_as_bitmaps_mitsuba_reads_where_matfit_does() {
    use matfit::math::Rgb;
    use matfit::scene::atlas::Atlas;
    use matfit::scene::texture::{Mapping, Texture};
    use matfit::scene::Material;
    use std::sync::Arc;

    let mut scene = load_scene(&root().join("scenes/poster/scene.toml")).unwrap();
    // The books as a recovery writes them: one atlas over the group, texels of no symmetry.
    let books = scene.group_index("books").unwrap();
    let objs: Vec<usize> = (0..scene.objects.len())
        .filter(|&o| scene.objects[o].group == books)
        .collect();
    let atlas = Arc::new(Atlas::build(
        &scene.geometry,
        &objs,
        scene.objects.len(),
        0.01,
    ));
    let n = atlas.width * atlas.height;
    let texture = Arc::new(Texture {
        width: atlas.width,
        height: atlas.height,
        texels: (0..n)
            .map(|i| {
                let h = |k: usize| ((i * 7919 + k * 104_729) % 1000) as f32 / 1000.0;
                Rgb::new(h(1), h(2), h(3))
            })
            .collect(),
        path: "books.exr".into(),
        mapping: Mapping::Atlas(atlas),
    });
    for &o in &objs {
        scene.objects[o].material = Material::Textured {
            texture: texture.clone(),
            scale: Rgb::new(0.9, 0.8, 0.7),
            varnish: None,
        };
    }
    let dir = tempfile::tempdir().unwrap();
    let report = matfit::export::mitsuba::export(&scene, dir.path()).unwrap();
    // The desk's varnish is the only approximation.
    assert_eq!(report.warnings.len(), 1, "{:?}", report.warnings);
    assert!(
        report.warnings[0].contains("varnish"),
        "{}",
        report.warnings[0]
    );

    // Each shape's PLY and the bitmap (file, wrap) of its BSDF, inline or by reference.
    let xml = std::fs::read_to_string(dir.path().join("scene.xml")).unwrap();
    let doc = roxmltree::Document::parse(&xml).unwrap();
    let string = |n: roxmltree::Node, name: &str| {
        n.children()
            .find(|c| c.has_tag_name("string") && c.attribute("name") == Some(name))
            .and_then(|c| c.attribute("value"))
            .map(str::to_string)
    };
    // (file, repeat, the diffuse part's weight 1 − w in a varnish's blendbsdf).
    let bitmap_of = |n: roxmltree::Node| {
        n.descendants()
            .find(|c| c.has_tag_name("texture"))
            .map(|t| {
                assert_eq!(t.attribute("type"), Some("bitmap"));
                let weight = t
                    .ancestors()
                    .find(|a| a.attribute("type") == Some("blendbsdf"))
                    .map_or(1.0, |b| {
                        let w = b.children().find(|c| c.has_tag_name("float")).unwrap();
                        1.0 - w.attribute("value").unwrap().parse::<f32>().unwrap()
                    });
                (
                    string(t, "filename").unwrap(),
                    string(t, "wrap_mode").unwrap() == "repeat",
                    weight,
                )
            })
    };
    let bsdfs: std::collections::HashMap<String, (String, bool, f32)> = doc
        .root_element()
        .children()
        .filter(|c| c.has_tag_name("bsdf"))
        .filter_map(|b| Some((b.attribute("id")?.to_string(), bitmap_of(b)?)))
        .collect();
    let mut shapes = std::collections::HashMap::new();
    for s in doc
        .root_element()
        .children()
        .filter(|c| c.has_tag_name("shape"))
    {
        let ply = string(s, "filename").unwrap();
        let oi: usize = ply["meshes/".len()..][..3].parse().unwrap();
        let bitmap = match s.children().find(|c| c.has_tag_name("ref")) {
            Some(r) => bsdfs.get(r.attribute("id").unwrap()).cloned(),
            None => bitmap_of(s),
        };
        if let Some(b) = bitmap {
            shapes.insert(oi, (ply, b));
        }
    }
    let textured: Vec<usize> = (0..scene.objects.len())
        .filter(|&o| matches!(scene.objects[o].material, Material::Textured { .. }))
        .collect();
    assert_eq!(shapes.len(), textured.len(), "{shapes:?}");

    let (mut hits, mut worst, mut sum) = (0usize, 0.0f32, 0.0f64);
    let mut per_object = vec![0usize; scene.objects.len()];
    let mut files = std::collections::HashMap::new();
    for (_, _, hit) in scene.camera_grid_hits(240, 180) {
        let oi = hit.object as usize;
        let Some((ply, (image, repeat, weight))) = shapes.get(&oi) else {
            continue;
        };
        let Material::Textured { texture, scale, .. } = &scene.objects[oi].material else {
            unreachable!()
        };
        let want = texture.at(&hit) * *scale;
        // The hit's barycentrics in its PLY face (the PLY keeps matfit's triangle order).
        let (p, f, uv, img) = files.entry(oi).or_insert_with(|| {
            let bytes = std::fs::read(dir.path().join(ply)).unwrap();
            let (p, f) = read_ply(&bytes);
            let img = matfit::io::image::read_linear(&dir.path().join(image)).unwrap();
            (p, f, read_ply_uv(&bytes), img)
        });
        let face = f[hit.prim as usize - scene.objects[oi].tri_range.start as usize];
        let v = |k: usize| glam::Vec3::from(p[face[k] as usize]);
        let (e1, e2, d) = (v(1) - v(0), v(2) - v(0), hit.p - v(0));
        let (d11, d12, d22) = (e1.dot(e1), e1.dot(e2), e2.dot(e2));
        let (d1, d2) = (d.dot(e1), d.dot(e2));
        let den = d11 * d22 - d12 * d12;
        let (b1, b2) = ((d22 * d1 - d12 * d2) / den, (d11 * d2 - d12 * d1) / den);
        let at = |k: usize| uv[face[k] as usize];
        let uvh = [0, 1].map(|c| (1.0 - b1 - b2) * at(0)[c] + b1 * at(1)[c] + b2 * at(2)[c]);
        let got = mitsuba_bitmap(img, uvh, *repeat).map(|c| c * weight);
        let err = (0..3)
            .map(|k| (got[k] - want.to_array()[k]).abs())
            .fold(0.0, f32::max);
        worst = worst.max(err);
        sum += err as f64;
        hits += 1;
        per_object[oi] += 1;
    }
    // Every textured object is seen, the poster and the books many times.
    for &o in &textured {
        assert!(
            per_object[o] > 20,
            "{}: {}",
            scene.objects[o].name,
            per_object[o]
        );
    }
    let mean = sum / hits as f64;
    eprintln!("{hits} hits: mean |Δ| {mean:.2e}, largest {worst:.2e}");
    // Rounding only (bilinear weights from the UVs instead of the chart's projection); a texel
    // off, a flipped v or a chart blending into its neighbour would be 0.01-0.5.
    assert!(mean < 1e-5, "mean {mean}");
    assert!(worst < 1e-3, "largest {worst}");
}

/// The vertices' (u, v) of a PLY as written by the exporter ([`read_ply`]'s layout).
fn read_ply_uv(bytes: &[u8]) -> Vec<[f32; 2]> {
    let (p, _) = read_ply(bytes);
    let end = b"end_header\n";
    let hdr_len = bytes.windows(end.len()).position(|w| w == end).unwrap() + end.len();
    let f32_at = |o: usize| f32::from_le_bytes(bytes[o..o + 4].try_into().unwrap());
    (0..p.len())
        .map(|i| [f32_at(hdr_len + i * 32 + 24), f32_at(hdr_len + i * 32 + 28)])
        .collect()
}
