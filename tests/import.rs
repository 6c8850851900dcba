//! `matfit import mitsuba`: the inverse of the exporter (a round trip renders the
//! same image), a scene written in Mitsuba's own idiom imports as the same scene written by
//! hand, and bad input is an error naming the file and line.

use crate::common::{root, run, write};
use matfit::math::{Rgb, Vec2};
use matfit::render::aov::{aov_image, Aov};
use matfit::render::film::{render, RenderOptions};
use matfit::scene::{load_scene, Distribution, Material, Scene};
use std::path::Path;

/// `matfit import mitsuba XML -o OUT`, run in OUT's folder: (exit code, stdout, stderr).
fn run_import(xml: &Path, out: &Path) -> (i32, String, String) {
    run(
        &[
            "import",
            "mitsuba",
            xml.to_str().unwrap(),
            "-o",
            out.to_str().unwrap(),
        ],
        out.parent().unwrap(),
    )
}

/// `matfit import mitsuba XML -o OUT`, which must succeed; returns its stderr (the warnings).
fn import(xml: &Path, out: &Path) -> String {
    let (code, stdout, stderr) = run_import(xml, out);
    assert_eq!(code, 0, "{stdout}\n{stderr}");
    stderr
}

/// The two cameras shoot the same rays through the film (corners, centre, an odd point).
fn assert_same_camera(a: &Scene, b: &Scene, tol: f32) {
    let (ca, cb) = (&a.camera, &b.camera);
    assert_eq!((ca.width, ca.height), (cb.width, cb.height));
    let (w, h) = (ca.width as f32, ca.height as f32);
    for p in [
        (0.0, 0.0),
        (w, 0.0),
        (0.0, h),
        (w, h),
        (w / 2.0, h / 2.0),
        (0.37 * w, 0.81 * h),
    ] {
        let (ra, rb) = (ca.ray(Vec2::new(p.0, p.1)), cb.ray(Vec2::new(p.0, p.1)));
        // Origins to f32's precision at their magnitude (an orthographic film is hundreds of
        // units from a Cornell box's origin).
        assert!(
            (ra.o - rb.o).abs().max_element() < tol * ra.o.abs().max_element().max(1.0),
            "{:?} vs {:?}",
            ra.o,
            rb.o
        );
        assert!(
            (ra.d - rb.d).abs().max_element() < tol,
            "{p:?}: {:?} vs {:?}",
            ra.d,
            rb.d
        );
    }
}

/// Every object of `a` has a namesake in `b` with the same triangles (vertex for vertex, in
/// order) and the same emission.
fn assert_same_geometry(a: &Scene, b: &Scene, tol: f32) {
    assert_eq!(a.objects.len(), b.objects.len());
    for oa in &a.objects {
        let ob = b
            .objects
            .iter()
            .find(|o| o.name == oa.name)
            .unwrap_or_else(|| panic!("no object '{}' in {}", oa.name, b.path.display()));
        assert_eq!(oa.tri_range.len(), ob.tri_range.len(), "{}", oa.name);
        let (ga, gb) = (&a.geometry, &b.geometry);
        let bounds = ga.bvh.bounds();
        let scale = (bounds.max - bounds.min).length();
        for (ta, tb) in ga.tris[oa.tri_range.start as usize..][..oa.tri_range.len()]
            .iter()
            .zip(&gb.tris[ob.tri_range.start as usize..])
        {
            for k in 0..3 {
                let (pa, pb) = (
                    ga.positions[ta.v[k] as usize],
                    gb.positions[tb.v[k] as usize],
                );
                assert!(
                    (pa - pb).abs().max_element() <= tol * scale,
                    "{}: {pa} vs {pb}",
                    oa.name
                );
            }
        }
        assert!(
            (oa.emission - ob.emission).abs().max_element() <= 1e-6 * oa.emission.max_element(),
            "{}",
            oa.name
        );
    }
}

/// Mean radiance per object of `a` and `b` rendered with the same seed, over the pixels where
/// both see the object directly with the same object around them (3×3): a pixel on an outline
/// may see one object in one scene and its neighbour in the other.
fn object_means(a: &Scene, b: &Scene, spp: u32) -> Vec<(String, Rgb, Rgb, usize)> {
    let opts = RenderOptions {
        spp,
        seed: 7,
        progress: false,
    };
    let (ia, ib) = (render(a, &a.camera, &opts), render(b, &b.camera, &opts));
    let id = |sc: &Scene| -> Vec<i64> {
        aov_image(sc, &sc.camera, Aov::Object, false)
            .data
            .iter()
            .map(|c| c.x.round() as i64)
            .collect()
    };
    let (da, db) = (id(a), id(b));
    let (w, h) = (a.camera.width as usize, a.camera.height as usize);
    let mut sums = vec![(Rgb::ZERO, Rgb::ZERO, 0usize); a.objects.len()];
    for y in 1..h - 1 {
        for x in 1..w - 1 {
            let i = y * w + x;
            let o = da[i];
            let same = (0..9).all(|k| {
                let j = (y + k / 3 - 1) * w + (x + k % 3 - 1);
                da[j] == o && db[j] == o
            });
            if same && o >= 0 && (o as usize) < sums.len() {
                let s = &mut sums[o as usize];
                s.0 += ia.data[i];
                s.1 += ib.data[i];
                s.2 += 1;
            }
        }
    }
    a.objects
        .iter()
        .zip(sums)
        .filter(|(_, s)| s.2 > 0)
        .map(|(o, (sa, sb, n))| (o.name.clone(), sa / n as f32, sb / n as f32, n))
        .collect()
}

/// Exports `scene`, imports it back and checks the two agree; returns the imported scene.
fn round_trip(scene: &str) -> Scene {
    round_trip_warned(scene, &[])
}

/// [`round_trip`] where the import may warn with lines containing one of `allowed`.
fn round_trip_warned(scene: &str, allowed: &[&str]) -> Scene {
    let src = root().join(scene);
    let dir = tempfile::tempdir().unwrap();
    let mi = dir.path().join("mi");
    let (code, stdout, stderr) = run(
        &[
            "export",
            "mitsuba",
            src.to_str().unwrap(),
            "-o",
            mi.to_str().unwrap(),
        ],
        dir.path(),
    );
    assert_eq!(code, 0, "{stdout}\n{stderr}");
    // In a folder of its own, so that the mesh paths must be rewritten.
    std::fs::create_dir(dir.path().join("back")).unwrap();
    let out = dir.path().join("back").join("scene.toml");
    let warnings = import(&mi.join("scene.xml"), &out);
    let text = std::fs::read_to_string(&out).unwrap();
    assert!(
        text.starts_with("# Imported by `matfit import mitsuba`"),
        "{text}"
    );
    assert!(text.contains("file = \"../mi/meshes/000_"), "{text}");
    let mut original = load_scene(&src).unwrap();
    let back = load_scene(&out).unwrap();
    // The exporter's XML is in the imported subset: nothing is approximated on the way back.
    // Ward went out as a microfacet lobe fitted to it (src/export/standin.rs) and comes back as
    // that microfacet material, exactly: same ρd, its fitted α near Ward's, anisotropy along the
    // same axes (the exporter's UVs make dp/du the tangent), ρs scaled by the fitted k.
    assert!(
        !(warnings.lines())
            .any(|l| l.contains("warning") && !allowed.iter().any(|a| l.contains(a))),
        "{warnings}"
    );
    // Objects and groups keep their names (the exporter shares a group's BSDF by id), but for
    // a group whose objects have textures of their own (no BSDF to share).
    let own_textures = |g: usize| {
        let mut t =
            (original.objects.iter().filter(|o| o.group == g)).filter_map(|o| match &o.material {
                Material::Textured { texture, .. } => Some(texture),
                _ => None,
            });
        let first = t.next();
        first.is_some_and(|f| t.any(|x| !std::sync::Arc::ptr_eq(f, x)))
    };
    for (oa, ob) in original.objects.iter().zip(&back.objects) {
        assert_eq!(oa.name, ob.name);
        if own_textures(oa.group) {
            continue;
        }
        assert_eq!(
            original.groups[oa.group].name, back.groups[ob.group].name,
            "{}",
            oa.name
        );
    }
    for (oa, ob) in original.objects.iter_mut().zip(&back.objects) {
        if let Material::Ward {
            rho_s,
            alpha_x,
            alpha_y,
            ..
        } = &oa.material
        {
            let Material::Microfacet {
                rho_s: back_s,
                alpha_x: bx,
                alpha_y: by,
                ..
            } = &ob.material
            else {
                panic!(
                    "{}: {:?} came back as {:?}",
                    oa.name, oa.material, ob.material
                );
            };
            let near = |a: f32, b: f32| (0.3..3.0).contains(&(b / a));
            assert!(near(*alpha_x, *bx) && near(*alpha_y, *by), "{}", oa.name);
            let k = *back_s / *rho_s;
            assert!(
                k.max_element() - k.min_element() < 1e-5 && k.x > 0.05 && k.x < 3.0,
                "{}: k {k}",
                oa.name
            );
            oa.material = ob.material.clone();
        }
        // A texture's varnish (a Ward lobe) comes back as a Ward lobe of the stand-in's α and
        // its ρs scaled by the fitted k; the texture is a turned copy, compared by the render.
        if let (
            Material::Textured {
                varnish: Some(va), ..
            },
            Material::Textured {
                varnish: Some(vb), ..
            },
        ) = (&mut oa.material, &ob.material)
        {
            let near = |a: f32, b: f32| (0.3..3.0).contains(&(b / a));
            assert!(
                near(va.alpha_x, vb.alpha_x) && near(va.alpha_y, vb.alpha_y),
                "{}",
                oa.name
            );
            let k = vb.rho_s / va.rho_s;
            assert!(
                k.max_element() - k.min_element() < 1e-5 && k.x > 0.05 && k.x < 3.0,
                "{}: k {k}",
                oa.name
            );
            va.rho_s = vb.rho_s;
            (va.alpha_x, va.alpha_y) = (vb.alpha_x, vb.alpha_y);
        }
    }
    assert_same_camera(&original, &back, 1e-5);
    assert_same_geometry(&original, &back, 1e-6);
    assert_eq!(back.render.max_depth, original.render.max_depth);
    assert_eq!(back.render.rr_depth, original.render.rr_depth);
    assert_eq!(back.render.spp, original.render.spp);
    for (oa, ob) in original.objects.iter().zip(&back.objects) {
        let (a, b) = (&oa.material, &ob.material);
        // A texture's mean is an f32 sum over its texels, in another order once turned.
        let tol = match a {
            Material::Textured { .. } => 3e-4,
            _ => 1e-6,
        };
        let close = |a: Rgb, b: Rgb| (a - b).abs().max_element() < tol * a.max_element().max(1.0);
        assert!(
            close(a.rho_d(), b.rho_d()) && close(a.rho_s(), b.rho_s()),
            "{}: ρd {} ρs {} vs ρd {} ρs {}",
            oa.name,
            a.rho_d(),
            a.rho_s(),
            b.rho_d(),
            b.rho_s()
        );
    }
    // The same image, to rounding: every object's mean radiance, same seed, same samples.
    for (name, a, b, _) in object_means(&original, &back, 4) {
        let rel = ((a - b).abs() / a.max(Rgb::splat(1e-3))).max_element();
        assert!(rel < 1e-3, "{scene} {name}: {a} vs {b}");
    }
    back
}

#[test]
fn figure6_round_trips_through_mitsuba() {
    round_trip("scenes/figure6/scene.toml");
}

/// A microfacet material goes out as Mitsuba's GGX `roughconductor` (in a `blendbsdf` with a
/// diffuse part), a Beckmann plastic as a Beckmann `roughplastic`, and each comes back the same
/// material, with no warning.
#[test]
fn microfacet_materials_round_trip_through_mitsuba() {
    let text = std::fs::read_to_string(root().join("scenes/figure6/scene.toml")).unwrap();
    let text = text
        .replace(
            "material = { type = \"diffuse\", rho_d = [0.0, 0.76, 0.26] }",
            "material = { type = \"microfacet\", rho_s = [0.2, 0.7, 0.3], alpha = 0.2 }",
        )
        .replace(
            "material = { type = \"diffuse\", rho_d = [0.77, 0.0, 0.0] }",
            "material = { type = \"microfacet\", rho_d = [0.5, 0.1, 0.1], rho_s = 0.3, alpha = 0.08 }",
        )
        .replace(
            "material = { type = \"diffuse\", rho_d = 0.66 }",
            "material = { type = \"plastic\", rho_d = [0.6, 0.3, 0.1], rho_s = 0.05, alpha = 0.15, eta = 1.6, distribution = \"beckmann\" }",
        );
    let dir = tempfile::tempdir().unwrap();
    let src = write(dir.path(), "scene.toml", &text);
    let back = round_trip(src.to_str().unwrap());
    let material = |name: &str| {
        let g = back.group_index(name).unwrap();
        back.objects[back.groups[g].objects[0]].material.clone()
    };
    for (name, alpha) in [("small_block", 0.2), ("big_block", 0.08)] {
        let m = material(name);
        assert!(
            matches!(m, Material::Microfacet { alpha_x, alpha_y, .. }
                if alpha_x == alpha && alpha_y == alpha),
            "{name}: {m:?}"
        );
    }
    // The plastic went out as roughplastic (specular_reflectance = ρs / F0) and comes back as
    // itself, η and its Beckmann coat included.
    let m = material("left_wall");
    assert!(
        matches!(m, Material::Plastic { alpha, eta, distribution, .. }
            if alpha == 0.15 && (eta - 1.6).abs() < 1e-6 && distribution == Distribution::Beckmann),
        "{m:?}"
    );
}

#[test]
fn cornell_round_trips_through_mitsuba() {
    round_trip("scenes/cornell/scene.toml");
}

#[test]
fn facing_mirrors_round_trip_through_mitsuba() {
    round_trip("scenes/facing-mirrors/scene.toml");
}

/// Textures go out as Mitsuba bitmaps over PLY UVs (v down) and come back turned to matfit's
/// texture coordinates: the same image. The desk's varnish is the one approximation.
#[test]
fn textured_poster_round_trips_through_mitsuba() {
    let back = round_trip_warned("scenes/poster/scene.toml", &["textured Ward varnish"]);
    let textured = back
        .objects
        .iter()
        .filter(|o| matches!(o.material, Material::Textured { .. }))
        .count();
    assert_eq!(textured, 8, "the poster, six books and the desk");
}

/// Orthographic cameras go out as Mitsuba's `orthographic` sensor and come back the same: the
/// look-at form (square pixels) and a calibrated one with fx ≠ fy and an off-centre principal
/// point (its `to_world` scales x and y differently).
#[test]
fn orthographic_cameras_round_trip_through_mitsuba() {
    let text = std::fs::read_to_string(root().join("scenes/cornell/scene.toml")).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let meshes = root().join("scenes/cornell/meshes");
    let text = text.replace(
        "file = \"meshes/",
        &format!("file = \"{}/", meshes.display()),
    );
    let look_at = text.replace(
        "fov_y_deg = 39.3077",
        "projection = \"orthographic\"\nwidth_m = 600",
    );
    let calibrated = text.replace(
        "eye = [278.0, 273.0, -800.0]\ntarget = [278.0, 273.0, -799.0]\nup = [0.0, 1.0, 0.0]\nfov_y_deg = 39.3077",
        "projection = \"orthographic\"\nfx = 0.45\nfy = 0.4\ncx = 120.0\ncy = 140.0\n\
         rotation = [[-1, 0, 0], [0, -1, 0], [0, 0, 1]]\ntranslation = [278.0, 273.0, 800.0]",
    );
    assert_ne!(calibrated, text);
    for (name, text) in [("look_at", look_at), ("calibrated", calibrated)] {
        let src = write(dir.path(), &format!("{name}.toml"), &text);
        let back = round_trip(src.to_str().unwrap());
        assert!(back.camera.is_orthographic(), "{name}");
    }
}

/// A Cornell box written as Mitsuba users write them (rectangles and cubes placed by
/// transform chains, `<default>` parameters, BSDFs by reference, a horizontal field of view)
/// imports as the same scene written by hand (scenes/mitsuba-cbox/expected.toml).
#[test]
fn a_hand_written_mitsuba_scene_imports_as_its_matfit_twin() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("cbox.toml");
    let warnings = import(&root().join("scenes/mitsuba-cbox/scene.xml"), &out);
    assert!(!warnings.contains("warning"), "{warnings}");
    let got = load_scene(&out).unwrap();
    let want = load_scene(&root().join("scenes/mitsuba-cbox/expected.toml")).unwrap();
    assert_same_camera(&want, &got, 1e-5);
    assert_same_geometry(&want, &got, 1e-5);
    // Groups: shapes sharing a BSDF id share its group; the others are their own.
    for o in &want.objects {
        let g = &got.objects.iter().find(|x| x.name == o.name).unwrap();
        assert_eq!(
            got.groups[g.group].name, want.groups[o.group].name,
            "{}",
            o.name
        );
        assert!(
            (g.material.rho_d() - o.material.rho_d())
                .abs()
                .max_element()
                < 1e-6
        );
        assert!(matches!(
            (&g.material, &o.material),
            (Material::Diffuse { .. }, Material::Diffuse { .. })
                | (Material::Black, Material::Black)
        ));
    }
    assert_eq!(got.render.spp, 64);
    assert_eq!(got.render.max_depth, 6);
    // Per-group mean radiance, one seed in both: equal to within noise (here, to rounding).
    for (name, a, b, _) in object_means(&want, &got, 16) {
        let rel = ((a - b).abs() / a.max(Rgb::splat(1e-3))).max_element();
        assert!(rel < 2e-3, "{name}: {a} vs {b}");
    }
}

/// A `-D` parameter overrides a `<default>`.
#[test]
fn command_line_parameters_override_defaults() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("cbox.toml");
    let xml = root().join("scenes/mitsuba-cbox/scene.xml");
    let (code, _, stderr) = run(
        &[
            "import",
            "mitsuba",
            xml.to_str().unwrap(),
            "-o",
            out.to_str().unwrap(),
            "-D",
            "res_x=64",
            "-D",
            "spp=3",
        ],
        dir.path(),
    );
    assert_eq!(code, 0, "{stderr}");
    let sc = load_scene(&out).unwrap();
    assert_eq!(
        (sc.camera.width, sc.camera.height, sc.render.spp),
        (64, 192, 3)
    );
}

/// An XML scene around one shape element, written to `dir/scene.xml`.
fn xml_with(dir: &Path, body: &str) -> std::path::PathBuf {
    write(
        dir,
        "scene.xml",
        &format!(
            "<scene version=\"3.0.0\">\n<sensor type=\"perspective\">\n\
             <float name=\"fov\" value=\"40\"/>\n</sensor>\n{body}\n</scene>\n"
        ),
    )
}

fn import_fails(xml: &Path) -> String {
    let out = xml.with_file_name("out.toml");
    let (code, stdout, stderr) = run_import(xml, &out);
    assert_eq!(code, 2, "{stdout}\n{stderr}");
    assert!(!out.exists(), "nothing is written on an error");
    assert!(!stderr.contains("panicked"), "{stderr}");
    stderr
}

#[test]
fn bad_mitsuba_files_are_errors_naming_file_and_line() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();

    let missing = import_fails(&d.join("nowhere.xml"));
    assert!(
        missing.starts_with("error: cannot read Mitsuba scene"),
        "{missing}"
    );
    assert!(missing.contains("nowhere.xml"), "{missing}");

    let xml = xml_with(d, "<shape type=\"cylinder\"/>");
    let e = import_fails(&xml);
    assert!(
        e.contains(&format!(
            "error: {}:5: shape type 'cylinder' is not supported",
            xml.display()
        )),
        "{e}"
    );

    let xml = write(
        d,
        "scene.xml",
        "<scene version=\"3.0.0\">\n<shape type=\"cube\">\n</scene>\n",
    );
    let e = import_fails(&xml);
    assert!(
        e.contains(&format!("error: {}:3: malformed XML", xml.display())),
        "{e}"
    );

    let xml = xml_with(d, "<emitter type=\"projector\"/>");
    let e = import_fails(&xml);
    assert!(
        e.contains(":5: emitter type 'projector' cannot be imported"),
        "{e}"
    );

    let xml = xml_with(
        d,
        "<emitter type=\"constant\"/>\n<emitter type=\"constant\"/>",
    );
    let e = import_fails(&xml);
    assert!(
        e.contains(":6: a second constant emitter: matfit takes one"),
        "{e}"
    );

    let xml = xml_with(
        d,
        "<shape type=\"sphere\">\n<float name=\"radius\" value=\"$r\"/>\n</shape>",
    );
    let e = import_fails(&xml);
    assert!(e.contains(":6: parameter $r has no value"), "{e}");

    let xml = xml_with(
        d,
        "<shape type=\"ply\">\n<string name=\"filename\" value=\"gone.ply\"/>\n</shape>",
    );
    let e = import_fails(&xml);
    assert!(
        e.contains(":5: file ") && e.contains("gone.ply not found"),
        "{e}"
    );
}

/// What matfit cannot render exactly is imported as the nearest material, with a warning that
/// names the element's line, repeated in the file's header; exact BSDFs stay exact.
#[test]
fn approximations_are_warnings_listed_in_the_header() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    write(d, "meshes/tri.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n");
    let xml = write(
        d,
        "scene.xml",
        r#"<scene version="3.0.0">
<sensor type="perspective">
    <float name="fov" value="50"/>
    <transform name="to_world"><lookat origin="0, 0, 5" target="0, 0, 0" up="0, 1, 0"/></transform>
    <film type="hdrfilm"><integer name="width" value="32"/><integer name="height" value="32"/></film>
</sensor>
<bsdf type="roughplastic" id="plastic">
    <float name="alpha" value="0.2"/>
    <boolean name="nonlinear" value="true"/>
    <rgb name="diffuse_reflectance" value="0.5, 0.4, 0.3"/>
</bsdf>
<bsdf type="twosided" id="blend">
    <bsdf type="blendbsdf">
        <float name="weight" value="0.25"/>
        <bsdf type="diffuse"><rgb name="reflectance" value="0.4"/></bsdf>
        <bsdf type="conductor"><rgb name="specular_reflectance" value="0.8"/></bsdf>
    </bsdf>
</bsdf>
<shape type="rectangle" id="board"><ref id="plastic"/></shape>
<shape type="obj" id="tri">
    <string name="filename" value="meshes/tri.obj"/>
    <transform name="to_world"><scale value="2"/><translate z="1"/></transform>
    <ref id="blend"/>
</shape>
<shape type="sphere" id="gold">
    <float name="radius" value="0.1"/>
    <bsdf type="conductor"><string name="material" value="Au"/></bsdf>
</shape>
<shape type="rectangle" id="lamp">
    <transform name="to_world"><scale value="0.2"/><translate z="2"/></transform>
    <emitter type="area"><rgb name="radiance" value="5"/></emitter>
</shape>
</scene>
"#,
    );
    let out = d.join("out").join("scene.toml");
    std::fs::create_dir(d.join("out")).unwrap();
    let stderr = import(&xml, &out);
    let text = std::fs::read_to_string(&out).unwrap();
    for (line, what) in [
        (5, "no rfilter"),
        (7, "one-sided"),
        (27, "a mirror with ρs = Fresnel"),
        (27, "one-sided"),
    ] {
        let w = format!("{}:{line}: ", xml.display());
        assert!(
            stderr.lines().any(|l| l.contains(&w) && l.contains(what)),
            "{w}{what} in\n{stderr}"
        );
        assert!(
            text.lines()
                .any(|l| l.starts_with("# - ") && l.contains(&w) && l.contains(what)),
            "{what} in\n{text}"
        );
    }
    let sc = load_scene(&out).unwrap();
    let obj = |n: &str| sc.objects.iter().find(|o| o.name == n).unwrap();
    // Roughplastic (Mitsuba's default distribution, Beckmann; nonlinear): matfit's Beckmann
    // plastic with the same α and η = 1.49/1.000277, F0 = ((η − 1)/(η + 1))² ≈ 0.0387, and
    // the linear model's ρd = ρ (1 − F_int)/(1 − ρ F_int), one F_int for every channel.
    match &obj("board").material {
        Material::Plastic {
            rho_d,
            rho_s,
            alpha,
            eta,
            distribution,
        } => {
            assert_eq!(*distribution, Distribution::Beckmann);
            assert!((rho_s.x - 0.0387).abs() < 1e-3, "{rho_s}");
            let f_int = |got: f32, rho: f32| {
                let r = got / rho;
                (1.0 - r) / (1.0 - r * rho)
            };
            let (fx, fz) = (f_int(rho_d.x, 0.5), f_int(rho_d.z, 0.3));
            assert!(
                (0.3..0.8).contains(&fx) && (fx - fz).abs() < 1e-4,
                "{rho_d}"
            );
            assert_eq!(*alpha, 0.2);
            assert!((eta - 1.49 / 1.000277).abs() < 1e-6, "{eta}");
        }
        m => panic!("{m:?}"),
    }
    // The blend is exact: ρd = 0.75 · 0.4, ρs = 0.25 · 0.8; the mesh is placed by to_world
    // and referred to from the output's folder.
    match &obj("tri").material {
        Material::DiffuseMirror { rho_d, rho_s } => {
            assert!((rho_d.x - 0.3).abs() < 1e-6 && (rho_s.x - 0.2).abs() < 1e-6);
        }
        m => panic!("{m:?}"),
    }
    assert!(text.contains("file = \"../meshes/tri.obj\""), "{text}");
    let t = &obj("tri").tri_range;
    let p = |k: usize| sc.geometry.positions[sc.geometry.tris[t.start as usize].v[k] as usize];
    assert_eq!(p(1).to_array(), [2.0, 0.0, 1.0]);
    // Gold from the table; a shape without a BSDF has Mitsuba's default, diffuse 0.5.
    assert!((obj("gold").material.rho_s().y - 0.766).abs() < 1e-6);
    assert_eq!(obj("lamp").emission, Rgb::splat(5.0));
    assert!(matches!(obj("lamp").material, Material::Diffuse { .. }));
}

/// The published Mitsuba scene of the measured Cornell box (scenes/cornell/cbox.xml, byte for
/// byte from mitsuba-data): its measured spectra become the colours Mitsuba 3's own RGB
/// variant gives them (tools/cornell_rgb.md, column "Mitsuba 3.9.1 scalar_rgb itself",
/// measured by Mitsuba), its camera and meshes those of scenes/cornell/scene.toml, written by
/// hand from the same data.
#[test]
fn the_published_cornell_box_imports_with_mitsubas_own_colours() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("cbox.toml");
    let warnings = import(&root().join("scenes/cornell/cbox.xml"), &out);
    assert_eq!(
        warnings.matches("sampled spectrum").count(),
        6,
        "{warnings}"
    );
    assert!(warnings.contains("pixel filter is not a box"), "{warnings}");
    let got = load_scene(&out).unwrap();
    let hand = load_scene(&root().join("scenes/cornell/scene.toml")).unwrap();
    assert_same_camera(&hand, &got, 1e-5);
    assert_eq!(got.triangle_count(), hand.triangle_count());
    let (a, b) = (got.geometry.bvh.bounds(), hand.geometry.bvh.bounds());
    assert!(
        (a.min - b.min).abs().max_element() < 1e-3 && (a.max - b.max).abs().max_element() < 1e-3
    );
    let mitsuba = [
        ("white", Rgb::new(0.7350, 0.7356, 0.7363)),
        ("box", Rgb::new(0.7350, 0.7356, 0.7363)),
        ("red", Rgb::new(0.4913, 0.0492, 0.0509)),
        ("green", Rgb::new(0.0683, 0.3978, 0.0863)),
        ("light", Rgb::new(0.7764, 0.7798, 0.7760)),
    ];
    for (group, want) in mitsuba {
        let o = got
            .objects
            .iter()
            .find(|o| got.groups[o.group].name == group)
            .unwrap_or_else(|| panic!("no group {group}"));
        let rho = o.material.rho_d();
        assert!(
            (rho - want).abs().max_element() < 1.5e-3,
            "{group}: {rho} vs Mitsuba {want}"
        );
    }
    let light = got.objects.iter().find(|o| o.is_emitter()).unwrap();
    let want = Rgb::new(20.7108, 10.8546, 2.7712);
    assert!(
        ((light.emission - want) / want).abs().max_element() < 1e-3,
        "{} vs Mitsuba {want}",
        light.emission
    );
}

/// A constant `<spectrum>` on a light is equal-energy light, as Mitsuba 3's RGB variants load
/// it (Bitterli's scenes light rooms this way); the same on a reflectance stays grey.
#[test]
fn a_constant_spectrum_on_a_light_is_equal_energy_white() {
    let dir = tempfile::tempdir().unwrap();
    let xml = scene_with(
        dir.path(),
        "<shape type=\"rectangle\" id=\"lamp\">\
         <emitter type=\"area\"><spectrum name=\"radiance\" value=\"16.032\"/></emitter>\
         </shape>\n<shape type=\"rectangle\" id=\"card\"><bsdf type=\"diffuse\">\
         <spectrum name=\"reflectance\" value=\"0.4\"/></bsdf>\
         <transform name=\"to_world\"><translate z=\"-1\"/></transform></shape>",
    );
    let out = dir.path().join("out.toml");
    let warnings = import(&xml, &out);
    assert!(
        warnings.contains(":9: `radiance`: constant spectrum 16.032 is equal-energy light"),
        "{warnings}"
    );
    let f = toml_of(&out);
    // What Mitsuba 3.9's scalar_rgb holds for this light (its `radiance` after loading).
    let want = [19.3153, 15.2030, 14.5717];
    let got = floats(&object(&f, "lamp")["emission"]);
    assert!(
        got.len() == 3
            && got
                .iter()
                .zip(want)
                .all(|(g, w)| (g / w - 1.0).abs() < 5e-4),
        "{got:?}"
    );
    let card = floats(&object(&f, "card")["material"]["rho_d"]);
    assert!(close(&card, &[0.4], 1e-9), "{card:?}");
}

/// A `mask` imports as its nested BSDF, opaque, with a warning that names the light Mitsuba
/// lets through it.
#[test]
fn a_mask_is_opaque_with_a_warning_naming_its_opacity() {
    let dir = tempfile::tempdir().unwrap();
    let xml = scene_with(
        dir.path(),
        "<shape type=\"rectangle\" id=\"blind\"><bsdf type=\"mask\">\
         <float name=\"opacity\" value=\"0.25\"/><bsdf type=\"diffuse\">\
         <rgb name=\"reflectance\" value=\"0.6, 0.5, 0.4\"/></bsdf></bsdf></shape>",
    );
    let out = dir.path().join("out.toml");
    let warnings = import(&xml, &out);
    assert!(
        warnings.contains(
            ":9: <bsdf type=\"mask\">: Mitsuba passes 1 − opacity of the light straight \
             through it (opacity (0.2500, 0.2500, 0.2500)); matfit's surfaces are opaque"
        ),
        "{warnings}"
    );
    assert!(!warnings.contains("`opacity`"), "{warnings}");
    let rho = floats(&object(&toml_of(&out), "blind")["material"]["rho_d"]);
    assert!(close(&rho, &[0.6, 0.5, 0.4], 1e-6), "{rho:?}");
}

/// A `roughconductor` with eta and k keeps its microfacet lobe (distribution and α), with ρs its
/// Fresnel reflectance at normal incidence times specular_reflectance: a guess, warned.
#[test]
fn rough_conductors_with_eta_and_k_import_as_microfacet_guesses() {
    let dir = tempfile::tempdir().unwrap();
    let xml = scene_with(
        dir.path(),
        "<shape type=\"rectangle\" id=\"hood\"><bsdf type=\"roughconductor\">\
         <string name=\"distribution\" value=\"beckmann\"/>\
         <float name=\"alpha\" value=\"0.2\"/><rgb name=\"eta\" value=\"2\"/>\
         <rgb name=\"k\" value=\"3\"/><rgb name=\"specular_reflectance\" value=\"0.9\"/>\
         </bsdf></shape>",
    );
    let out = dir.path().join("out.toml");
    let warnings = import(&xml, &out);
    assert!(
        warnings.contains(":9: <bsdf type=\"roughconductor\"> imported as microfacet"),
        "{warnings}"
    );
    let f = toml_of(&out);
    let m = &object(&f, "hood")["material"];
    assert_eq!(m["type"].as_str(), Some("microfacet"), "{m}");
    assert_eq!(m["distribution"].as_str(), Some("beckmann"), "{m}");
    // F0 = ((η − 1)² + k²)/((η + 1)² + k²) = 10/18, times 0.9.
    assert!(close(&floats(&m["rho_s"]), &[0.5], 1e-6), "{m}");
    assert!(close(&floats(&m["alpha"]), &[0.2], 1e-6), "{m}");
}

/// A smooth `plastic` imports as matfit's plastic with the narrowest coat (GGX, the fitter's
/// least α), ρs = F0; its diffuse part ρ/(1 − F_s), or ρ/(1 − ρ·F_s) when `nonlinear`, goes
/// into ρd over the rough coat's 1/(1 − F_c): ρd = ρ(1 − F_c)/(1 − F_s) or
/// ρ(1 − F_c)/(1 − ρ·F_s), F_s Mitsuba's fdr_int of the smooth coat (here η = 1.5).
#[test]
fn a_smooth_plastic_imports_under_the_narrowest_coat() {
    let dir = tempfile::tempdir().unwrap();
    let plastic = |id: &str, nonlinear: bool| {
        format!(
            "<shape type=\"rectangle\" id=\"{id}\"><bsdf type=\"plastic\">\
             <float name=\"int_ior\" value=\"1.5\"/><float name=\"ext_ior\" value=\"1\"/>\
             <boolean name=\"nonlinear\" value=\"{nonlinear}\"/>\
             <rgb name=\"diffuse_reflectance\" value=\"0.6\"/></bsdf></shape>"
        )
    };
    let xml = scene_with(
        dir.path(),
        &format!("{}\n{}", plastic("tub", true), plastic("sink", false)),
    );
    let out = dir.path().join("out.toml");
    let warnings = import(&xml, &out);
    assert!(
        warnings.contains("imported as plastic with a GGX coat of α = 0.005"),
        "{warnings}"
    );
    let f = toml_of(&out);
    for name in ["tub", "sink"] {
        let m = &object(&f, name)["material"];
        assert_eq!(m["type"].as_str(), Some("plastic"), "{m}");
        assert!(close(&floats(&m["rho_s"]), &[0.04], 1e-6), "{m}");
        assert!(close(&floats(&m["alpha"]), &[0.005], 1e-9), "{m}");
        assert!(close(&floats(&m["eta"]), &[1.5], 1e-6), "{m}");
    }
    // Egan and Hilgeman's fit at 1/η, as Mitsuba computes fdr_int.
    let e = 1.0 / 1.5f64;
    let f_s = -1.4399 * e * e + 0.7099 * e + 0.6681 + 0.0636 / e;
    let tub = floats(&object(&f, "tub")["material"]["rho_d"]);
    let sink = floats(&object(&f, "sink")["material"]["rho_d"]);
    // The linear one gives F_c, which must be near the smooth coat's; the nonlinear one is
    // the linear one times (1 − F_s)/(1 − ρ·F_s).
    let f_c = 1.0 - sink[0] * (1.0 - f_s) / 0.6;
    assert!((f_c - f_s).abs() < 0.02, "F_c {f_c} vs F_s {f_s}");
    let want = sink[0] * (1.0 - f_s) / (1.0 - 0.6 * f_s);
    assert!(close(&tub, &[want], 2e-3), "{tub:?} vs {want}");
}

/// A plastic's bound is ρd ≤ 1 and ρs ≤ 1 apart (its coat's transmission scales the base):
/// matpreview's, whose ρd + ρs passes 1 in red, keeps its conversion and loads; one whose base
/// would pass 1 keeps its coat's ρs (set by η) and lowers ρd to 1, in that channel only.
#[test]
fn a_bright_plastic_keeps_its_coat_and_its_base_up_to_one() {
    let f0 = (0.9f64 / 2.9).powi(2);
    for (red, lowered) in [(0.94, false), (1.0, true)] {
        let dir = tempfile::tempdir().unwrap();
        let xml = scene_with(
            dir.path(),
            &format!(
                "<shape type=\"rectangle\" id=\"ball\"><bsdf type=\"plastic\">\
                 <float name=\"int_ior\" value=\"1.9\"/><float name=\"ext_ior\" value=\"1\"/>\
                 <rgb name=\"diffuse_reflectance\" value=\"{red}, 0.271, 0.361\"/></bsdf></shape>"
            ),
        );
        let out = dir.path().join("out.toml");
        let warnings = import(&xml, &out);
        assert_eq!(
            warnings.contains("lowered to 1 where over"),
            lowered,
            "{red}: {warnings}"
        );
        let f = toml_of(&out);
        let m = &object(&f, "ball")["material"];
        let s = floats(&m["rho_s"]);
        assert!(s.iter().all(|s| (s - f0).abs() < 1e-6), "{m}");
        let d = floats(&m["rho_d"]);
        if lowered {
            assert!((d[0] - 1.0).abs() < 1e-6, "{m}");
        } else {
            // The smooth plastic's conversion raises ρ, here past 1 − ρs.
            assert!(d[0] > 1.0 - f0 && d[0] > 0.94 && d[0] < 1.0, "{m}");
        }
        // The other channels as the smooth plastic's conversion gives them, above their ρ.
        assert!(
            d[1] > 0.271 && d[1] < 0.3 && d[2] > 0.361 && d[2] < 0.4,
            "{m}"
        );
        let sc = load_scene(&out).unwrap();
        assert!(sc
            .objects
            .iter()
            .any(|o| matches!(o.material, Material::Plastic { .. })));
    }
}

/// A smooth `plastic` over a bitmap keeps the texture under the narrowest coat: a linear
/// one's factor (1 − F_c)/(1 − F_s) as the texture's scale, a `nonlinear` one's texels each
/// ρ(1 − F_c)/(1 − ρ·F_s) in a copy.
#[test]
fn a_textured_smooth_plastic_keeps_its_texture_under_the_coat() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let (f, copy) = textured_plastic_pair(d, "tile", "<bsdf type=\"plastic\">", (0.005, 1e-9));
    let e = 1.0 / 1.5f64;
    let f_s = -1.4399 * e * e + 0.7099 * e + 0.6681 + 0.0636 / e;
    // The nonlinear copy's first texel gives F_c; the second and the linear scale must agree.
    let r0 = copy.get(0, 0).x as f64;
    let f_c = 1.0 - r0 * (1.0 - 0.2 * f_s) / 0.2;
    assert!((f_c - f_s).abs() < 0.02, "F_c {f_c} vs F_s {f_s}");
    let got = copy.get(1, 0);
    for (g, rho) in [(got.x, 0.8), (got.y, 0.6), (got.z, 0.4)] {
        let want = rho * (1.0 - f_c) / (1.0 - rho * f_s);
        assert!((g as f64 - want).abs() < 2e-3, "{got} vs {want}");
    }
    let scale = floats(&object(&f, "tilefalse")["material"]["scale"]);
    let want = (1.0 - f_c) / (1.0 - f_s);
    assert!(
        scale.iter().all(|s| (s - want).abs() < 2e-3),
        "{scale:?} vs {want}"
    );
}

/// Two shapes over the 2×1 texture `NAME.exr` (texels ρ 0.2 and (0.8, 0.6, 0.4)) under the
/// plastic `bsdf` (its opening tag and properties), one linear, one `nonlinear`, imported. Each
/// must come out textured (the linear one over the image itself, the nonlinear one over a
/// converted copy) with ρs 0.04, the coat's α (`alpha`: value, tolerance) and η 1.5, without
/// falling back to the texels' mean, and the scene must load as textured plastics. Returns the
/// imported file and the nonlinear one's copy.
fn textured_plastic_pair(
    d: &Path,
    name: &str,
    bsdf: &str,
    alpha: (f64, f64),
) -> (toml::Value, matfit::io::image::Image) {
    let mut img = matfit::io::image::Image::new(2, 1);
    img.set(0, 0, Rgb::splat(0.2));
    img.set(1, 0, Rgb::new(0.8, 0.6, 0.4));
    img.write(&d.join(format!("{name}.exr"))).unwrap();
    write(
        d,
        &format!("{name}.obj"),
        "v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 0 1\nf 1/1 2/2 3/3\n",
    );
    let shape = |nonlinear: bool| {
        format!(
            "<shape type=\"obj\" id=\"{name}{nonlinear}\">\
             <string name=\"filename\" value=\"{name}.obj\"/>{bsdf}\
             <float name=\"int_ior\" value=\"1.5\"/><float name=\"ext_ior\" value=\"1\"/>\
             <boolean name=\"nonlinear\" value=\"{nonlinear}\"/>\
             <texture type=\"bitmap\" name=\"diffuse_reflectance\">\
             <string name=\"filename\" value=\"{name}.exr\"/></texture></bsdf></shape>"
        )
    };
    let xml = scene_with(d, &format!("{}\n{}", shape(false), shape(true)));
    let out = d.join("out.toml");
    let warnings = import(&xml, &out);
    assert!(!warnings.contains("texels' mean"), "{warnings}");
    let f = toml_of(&out);
    let copy = format!("textures/{name}_linear.exr");
    for (id, texture) in [
        (format!("{name}false"), format!("{name}.exr")),
        (format!("{name}true"), copy.clone()),
    ] {
        let m = &object(&f, &id)["material"];
        assert_eq!(m["type"].as_str(), Some("textured"), "{m}");
        assert_eq!(m["texture"].as_str(), Some(texture.as_str()), "{m}");
        assert!(close(&floats(&m["rho_s"]), &[0.04], 1e-4), "{m}");
        assert!(close(&floats(&m["alpha"]), &[alpha.0], alpha.1), "{m}");
        assert!(close(&floats(&m["eta"]), &[1.5], 1e-6), "{m}");
    }
    let scene = load_scene(&out).unwrap();
    assert!(scene
        .objects
        .iter()
        .all(|o| matches!(o.material, Material::TexturedPlastic { .. })));
    (f, matfit::io::image::read_linear(&d.join(copy)).unwrap())
}

/// An XML scene around `body`, its camera 5 units up +z looking at the origin, written to
/// `dir/scene.xml` (lines 1–8 are the header; `body` starts on line 9).
fn scene_with(dir: &Path, body: &str) -> std::path::PathBuf {
    write(
        dir,
        "scene.xml",
        &format!(
            "<scene version=\"3.0.0\">\n<sensor type=\"perspective\">\n\
             <float name=\"fov\" value=\"60\"/>\n<transform name=\"to_world\">\
             <lookat origin=\"0, 0, 5\" target=\"0, 0, 0\" up=\"0, 1, 0\"/></transform>\n\
             <film type=\"hdrfilm\"><integer name=\"width\" value=\"16\"/>\n\
             <integer name=\"height\" value=\"16\"/><rfilter type=\"box\"/></film>\n\
             </sensor>\n<!-- body -->\n{body}\n</scene>\n"
        ),
    )
}

/// The imported scene file as TOML values.
fn toml_of(out: &Path) -> toml::Value {
    toml::from_str(&std::fs::read_to_string(out).unwrap()).unwrap()
}

fn floats(v: &toml::Value) -> Vec<f64> {
    match v {
        toml::Value::Array(a) => a.iter().flat_map(floats).collect(),
        toml::Value::Float(x) => vec![*x],
        toml::Value::Integer(i) => vec![*i as f64],
        other => panic!("not a number: {other}"),
    }
}

fn object<'a>(file: &'a toml::Value, name: &str) -> &'a toml::Value {
    file["object"]
        .as_array()
        .unwrap()
        .iter()
        .find(|o| o["name"].as_str() == Some(name))
        .unwrap_or_else(|| panic!("no object {name}: {file}"))
}

fn close(got: &[f64], want: &[f64], tol: f64) -> bool {
    got.len() == want.len() && got.iter().zip(want).all(|(a, b)| (a - b).abs() <= tol)
}

/// A Mitsuba 0.5 file (Bitterli's scenes' idiom) imports as Mitsuba 3 reads it: camelCase
/// names upgraded, `<lookAt>` read, nothing falling back to a default in silence.
#[test]
fn old_format_scenes_are_upgraded_as_mitsuba_3_upgrades_them() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let xml = write(
        d,
        "scene.xml",
        r#"<?xml version="1.0" encoding="utf-8"?>
<scene version="0.5.0">
	<integrator type="path">
		<integer name="maxDepth" value="9"/>
		<integer name="rrDepth" value="3"/>
	</integrator>
	<sensor type="perspective">
		<float name="fov" value="60"/>
		<string name="fovAxis" value="y"/>
		<transform name="toWorld">
			<lookAt origin="1, 2, 8" target="1, 2, 0" up="0, 1, 0"/>
		</transform>
		<sampler type="independent"><integer name="sampleCount" value="48"/></sampler>
		<film type="hdrfilm">
			<integer name="width" value="40"/><integer name="height" value="30"/>
			<rfilter type="box"/>
		</film>
	</sensor>
	<bsdf type="twosided" id="Paint">
		<bsdf type="diffuse"><rgb name="diffuseReflectance" value="0.2, 0.4, 0.6"/></bsdf>
	</bsdf>
	<bsdf type="twosided" id="Coat"><bsdf type="roughplastic">
		<float name="alpha" value="0.3"/>
		<string name="distribution" value="ggx"/>
		<float name="intIOR" value="1.6"/>
		<float name="extIOR" value="1.0"/>
		<rgb name="diffuseReflectance" value="0.5"/>
	</bsdf></bsdf>
	<shape type="rectangle" id="wall">
		<transform name="toWorld"><scale x="2" y="3"/><translate x="1" y="2" z="-1"/></transform>
		<ref id="Paint"/>
	</shape>
	<shape type="sphere" id="ball">
		<point name="center" x="0" y="1" z="0"/>
		<float name="radius" value="0.5"/>
		<ref id="Coat"/>
	</shape>
	<shape type="rectangle" id="lamp">
		<transform name="toWorld"><rotate x="1" angle="90"/><translate y="5"/></transform>
		<emitter type="area"><rgb name="radiance" value="4"/></emitter>
	</shape>
</scene>
"#,
    );
    let out = d.join("out.toml");
    let warnings = import(&xml, &out);
    assert!(!warnings.contains("warning"), "{warnings}");
    let f = toml_of(&out);
    let r = &f["render"];
    assert_eq!(
        (r["spp"].as_integer(), r["max_depth"].as_integer()),
        (Some(48), Some(9))
    );
    assert_eq!(r["rr_depth"].as_integer(), Some(3));
    let cam = &f["camera"];
    assert!(close(&floats(&cam["eye"]), &[1.0, 2.0, 8.0], 1e-6), "{cam}");
    assert!(
        close(&floats(&cam["target"]), &[1.0, 2.0, 7.0], 1e-6),
        "{cam}"
    );
    assert!(close(&floats(&cam["fov_y_deg"]), &[60.0], 1e-4), "{cam}");
    let wall = object(&f, "wall");
    assert!(
        close(&floats(&wall["corner"]), &[-1.0, -1.0, -1.0], 1e-6),
        "{wall}"
    );
    assert!(
        close(&floats(&wall["edge_u"]), &[4.0, 0.0, 0.0], 1e-6),
        "{wall}"
    );
    assert!(
        close(&floats(&wall["edge_v"]), &[0.0, 6.0, 0.0], 1e-6),
        "{wall}"
    );
    assert!(close(
        &floats(&wall["material"]["rho_d"]),
        &[0.2, 0.4, 0.6],
        1e-6
    ));
    let ball = object(&f, "ball");
    assert_eq!(ball["material"]["type"].as_str(), Some("plastic"));
    assert!(
        close(&floats(&ball["material"]["eta"]), &[1.6], 1e-6),
        "{ball}"
    );
    assert!(
        close(&floats(&ball["material"]["alpha"]), &[0.3], 1e-6),
        "{ball}"
    );
    assert!(
        close(&floats(&ball["center"]), &[0.0, 1.0, 0.0], 1e-6),
        "{ball}"
    );
    let lamp = object(&f, "lamp");
    assert!(
        close(&floats(&lamp["corner"]), &[-1.0, 5.0, -1.0], 1e-6),
        "{lamp}"
    );
}

/// A property the import does not read is a warning naming it and its line, never dropped in
/// silence; properties that change nothing in matfit's scene (output formats) are not.
#[test]
fn unknown_properties_are_warnings_naming_their_line() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let xml = xml_with(
        d,
        "<shape type=\"sphere\">\n<float name=\"radius\" value=\"0.5\"/>\n\
         <float name=\"radus\" value=\"2\"/>\n</shape>\n<shape type=\"sphere\">\n\
         <float name=\"radus\" value=\"3\"/>\n</shape>",
    );
    let out = d.join("out.toml");
    let warnings = import(&xml, &out);
    assert!(
        warnings.contains(&format!(
            "{}:7: property `radus` (<float name=\"radus\">) of <shape type=\"sphere\"> is not \
             read by matfit's import: ignored (on 2 elements, lines 7, 10)",
            xml.display()
        )),
        "{warnings}"
    );
    assert!(std::fs::read_to_string(&out)
        .unwrap()
        .contains("property `radus`"));
}

/// Every refusal of a file is reported in one run, each at its file and line; the `<path>`
/// and approximation warnings found on the way are shown with them.
#[test]
fn every_refusal_is_reported_in_one_run() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let xml = xml_with(
        d,
        "<shape type=\"cylinder\"/>\n\
         <shape type=\"obj\"><string name=\"filename\" value=\"gone.obj\"/></shape>\n\
         <emitter type=\"spot\"><texture type=\"bitmap\" name=\"texture\">\
         <string name=\"filename\" value=\"gone.png\"/></texture></emitter>\n\
         <shape type=\"sphere\"><bsdf type=\"dielectric\"/></shape>",
    );
    let e = import_fails(&xml);
    let x = xml.display();
    assert!(
        e.contains(&format!("{x}: the scene cannot be imported (3 problems):")),
        "{e}"
    );
    assert!(
        e.contains(&format!("{x}:5: shape type 'cylinder' is not supported")),
        "{e}"
    );
    assert!(
        e.contains(&format!("{x}:6: file ")) && e.contains("gone.obj not found"),
        "{e}"
    );
    assert!(
        e.contains(&format!("{x}:7: a textured spot light cannot be imported")),
        "{e}"
    );
    assert!(
        e.contains("these approximations") && e.contains(":8: <bsdf type=\"dielectric\">"),
        "{e}"
    );
    // Glass is made opaque: the warning says what that does to what lies behind it.
    assert!(
        e.contains(
            "diffuse 0.5 (matfit has no 'dielectric' material; opaque, so what Mitsuba lights \
             through it is darker)"
        ),
        "{e}"
    );
}

/// `<include>` splices another file in (its lines named in messages); `<path>` adds a folder
/// files are searched in.
#[test]
fn includes_and_search_paths_are_followed() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    write(d, "assets/tri.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n");
    write(
        d,
        "parts/objects.xml",
        "<scene version=\"3.0.0\">\n<bsdf type=\"diffuse\" id=\"grey\">\
         <rgb name=\"reflectance\" value=\"0.3\"/></bsdf>\n\
         <shape type=\"obj\" id=\"tri\"><string name=\"filename\" value=\"tri.obj\"/>\
         <ref id=\"grey\"/></shape>\n\
         <shape type=\"sphere\" id=\"odd\"><float name=\"radius\" value=\"1\"/>\
         <float name=\"radios\" value=\"1\"/></shape>\n</scene>\n",
    );
    let xml = xml_with(
        d,
        "<path value=\"assets\"/>\n<include filename=\"parts/objects.xml\"/>",
    );
    let out = d.join("out.toml");
    let warnings = import(&xml, &out);
    assert!(
        warnings.contains(&format!(
            "{}:4: property `radios`",
            d.join("parts/objects.xml").display()
        )),
        "{warnings}"
    );
    let f = toml_of(&out);
    let tri = object(&f, "tri");
    assert_eq!(tri["file"].as_str(), Some("assets/tri.obj"));
    assert_eq!(tri["group"].as_str(), Some("grey"));
    assert!(close(&floats(&tri["material"]["rho_d"]), &[0.3], 1e-6));
    // A missing include or folder is a refusal at its line.
    let e = d.join("e");
    std::fs::create_dir(&e).unwrap();
    let xml = xml_with(
        &e,
        "<path value=\"nowhere\"/>\n<include filename=\"none.xml\"/>\n<shape type=\"sphere\"/>",
    );
    let e = import_fails(&xml);
    assert!(e.contains(":5: <path>: folder"), "{e}");
    assert!(e.contains(":6: <include>: file none.xml not found"), "{e}");
}

/// A mesh as positions and triangles.
type Part = (Vec<[f32; 3]>, Vec<[u32; 3]>);

/// A Mitsuba serialized file (version 4, zlib-compressed) of `shapes`, as Mitsuba 0.5 writes
/// one: the shapes, then their offsets and count at the end.
fn serialized_v4(shapes: &[Part]) -> Vec<u8> {
    use std::io::Write;
    let mut out = Vec::new();
    let mut offsets = Vec::new();
    for (pos, tri) in shapes {
        offsets.push(out.len() as u64);
        out.extend_from_slice(&0x041Cu16.to_le_bytes());
        out.extend_from_slice(&4u16.to_le_bytes());
        let mut raw = 0x1000u32.to_le_bytes().to_vec();
        raw.extend_from_slice(b"part\0");
        raw.extend_from_slice(&(pos.len() as u64).to_le_bytes());
        raw.extend_from_slice(&(tri.len() as u64).to_le_bytes());
        for x in pos.iter().flatten() {
            raw.extend_from_slice(&x.to_le_bytes());
        }
        for i in tri.iter().flatten() {
            raw.extend_from_slice(&i.to_le_bytes());
        }
        let mut z = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::default());
        z.write_all(&raw).unwrap();
        out.extend(z.finish().unwrap());
    }
    for o in &offsets {
        out.extend_from_slice(&o.to_le_bytes());
    }
    out.extend_from_slice(&(shapes.len() as u32).to_le_bytes());
    out
}

/// A serialized file's shapes and a disk import as meshes written next to the scene, their
/// `to_world` (and a disk's `flip_normals`) applied.
#[test]
fn serialized_meshes_and_disks_import_as_meshes() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let tri = (
        vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
        vec![[0, 1, 2]],
    );
    let flat = (
        vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [2.0, 0.0, 0.0]],
        vec![[0, 1, 2]],
    );
    std::fs::write(d.join("parts.serialized"), serialized_v4(&[tri, flat])).unwrap();
    let xml = scene_with(
        d,
        "<shape type=\"serialized\" id=\"second\">\
         <string name=\"filename\" value=\"parts.serialized\"/>\
         <integer name=\"shape_index\" value=\"1\"/></shape>\n\
         <shape type=\"serialized\" id=\"first\">\
         <string name=\"filename\" value=\"parts.serialized\"/>\
         <transform name=\"to_world\"><scale value=\"2\"/><translate z=\"-3\"/></transform>\
         </shape>\n\
         <shape type=\"disk\" id=\"lamp\">\
         <transform name=\"to_world\"><rotate x=\"1\" angle=\"90\"/><translate y=\"4\"/>\
         </transform><boolean name=\"flip_normals\" value=\"true\"/>\
         <emitter type=\"area\"><rgb name=\"radiance\" value=\"3\"/></emitter></shape>",
    );
    let out = d.join("out.toml");
    let warnings = import(&xml, &out);
    // Shape 1's only triangle has no area: skipped, the file named.
    assert!(
        warnings.contains(
            ":9: <shape type=\"serialized\" id=\"second\"> is skipped: every \
                           triangle of it is degenerate"
        ),
        "{warnings}"
    );
    assert!(
        warnings.contains(":11: disk tessellated as a 256-gon mesh"),
        "{warnings}"
    );
    let f = toml_of(&out);
    assert!(f["object"]
        .as_array()
        .unwrap()
        .iter()
        .all(|o| o["name"].as_str() != Some("second")));
    assert_eq!(
        object(&f, "first")["file"].as_str(),
        Some("meshes/first.obj")
    );
    let obj = std::fs::read_to_string(d.join("meshes/first.obj")).unwrap();
    let v: Vec<&str> = obj.lines().filter(|l| l.starts_with("v ")).collect();
    assert_eq!(v, ["v 0 0 -3", "v 2 0 -3", "v 0 2 -3"]);
    // The disk, turned to face −z by the rotation, faces +y... flipped: down, at y = 4, and
    // emits downward (its wound normal), radius 1.
    let scene = load_scene(&out).unwrap();
    let lamp = scene.objects.iter().find(|o| o.name == "lamp").unwrap();
    assert!(
        (lamp.area - std::f32::consts::PI).abs() < 1e-3,
        "{}",
        lamp.area
    );
    assert_eq!(lamp.emission, Rgb::splat(3.0));
    let lamp_file = std::fs::read_to_string(d.join("meshes/lamp.obj")).unwrap();
    let pts: Vec<[f32; 3]> = lamp_file
        .lines()
        .filter_map(|l| l.strip_prefix("v "))
        .map(|l| {
            let v: Vec<f32> = l.split(' ').map(|x| x.parse().unwrap()).collect();
            [v[0], v[1], v[2]]
        })
        .collect();
    assert!(pts.iter().all(|p| (p[1] - 4.0).abs() < 1e-5));
    let f1: Vec<usize> = lamp_file
        .lines()
        .find_map(|l| l.strip_prefix("f "))
        .unwrap()
        .split(' ')
        .map(|x| x.parse::<usize>().unwrap() - 1)
        .collect();
    let [a, b, c] = [pts[f1[0]], pts[f1[1]], pts[f1[2]]].map(matfit::math::Vec3::from);
    let n = (b - a).cross(c - a);
    // rotate x by 90° takes +z to −y; flip_normals turns it to +y.
    assert!(n.y > 0.0 && n.x.abs() < 1e-6 && n.z.abs() < 1e-6, "{n}");
}

/// A checkerboard is drawn as Mitsuba evaluates it (color0 where both coordinates' fractions
/// are on the same side of ½), `to_uv` included.
#[test]
fn checkerboards_import_as_textures_drawn_as_mitsuba_evaluates_them() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let xml = scene_with(
        d,
        "<texture type=\"checkerboard\" id=\"checks\">\
         <rgb name=\"color0\" value=\"0.8, 0.7, 0.6\"/><rgb name=\"color1\" value=\"0.1\"/>\
         <transform name=\"to_uv\"><scale x=\"3\" y=\"2\"/></transform></texture>\n\
         <shape type=\"rectangle\" id=\"board\"><bsdf type=\"diffuse\">\
         <ref name=\"reflectance\" id=\"checks\"/></bsdf></shape>",
    );
    let out = d.join("out.toml");
    let warnings = import(&xml, &out);
    assert!(
        warnings.contains(":9: checkerboard drawn as a 192×192 texture"),
        "{warnings}"
    );
    let scene = load_scene(&out).unwrap();
    let Material::Textured { texture, scale, .. } = &scene.objects[0].material else {
        panic!("not textured")
    };
    assert_eq!(*scale, Rgb::ONE);
    // The rectangle's (u, v) = ((x + 1)/2, (y + 1)/2) in Mitsuba, v down the image: matfit's
    // texture is turned so that each point reads Mitsuba's value (texel centres, away from
    // the checks' edges).
    for (u, v) in [
        (0.05, 0.05),
        (0.2, 0.1),
        (0.4, 0.3),
        (0.7, 0.6),
        (0.95, 0.9),
    ] {
        let (fu, fv) = ((3.0 * u) % 1.0 > 0.5, (2.0 * v) % 1.0 > 0.5);
        let want = if fu == fv {
            Rgb::new(0.8, 0.7, 0.6)
        } else {
            Rgb::splat(0.1)
        };
        // matfit's rectangle has the same (u, v); its copy is flipped so that they read the
        // same texel.
        let got = texture.lookup(Vec2::new(u, v));
        assert!(
            (got - want).abs().max_element() < 1e-5,
            "({u}, {v}): {got} vs {want}"
        );
    }
}

/// A `roughplastic` over a bitmap imports as the texture under matfit's plastic coat (exact);
/// a `nonlinear` one's base goes into a copy of the texture, each texel ρ as
/// ρ(1 − F_int)/(1 − ρ·F_int).
#[test]
fn textured_rough_plastics_import_as_the_texture_under_the_coat() {
    let dir = tempfile::tempdir().unwrap();
    let (_, copy) = textured_plastic_pair(
        dir.path(),
        "wood",
        "<bsdf type=\"roughplastic\"><float name=\"alpha\" value=\"0.1\"/>\
         <string name=\"distribution\" value=\"ggx\"/>",
        (0.1, 1e-6),
    );
    // Nonlinear: every texel ρ(1 − F)/(1 − ρF) with one F (the coat's), found from the first.
    let r0 = copy.get(0, 0).x as f64;
    let f_int = (0.2 - r0) / (0.2 * (1.0 - r0));
    assert!(f_int > 0.3 && f_int < 0.8, "{f_int}");
    let got = copy.get(1, 0);
    for (g, rho) in [(got.x, 0.8), (got.y, 0.6), (got.z, 0.4)] {
        let want = rho * (1.0 - f_int) / (1.0 - rho * f_int);
        assert!((g as f64 - want).abs() < 1e-5, "{got} vs {want}");
    }
}

/// A plastic over a uniform texture renders as the plastic of that ρd: the same image, same
/// seed.
#[test]
fn a_plastic_over_a_uniform_texture_renders_as_the_plain_plastic() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let mut img = matfit::io::image::Image::new(2, 2);
    for (x, y) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
        img.set(x, y, Rgb::new(0.6, 0.4, 0.2));
    }
    img.write(&d.join("flat.exr")).unwrap();
    let scene_of = |base: &str, name: &str| {
        let body = format!(
            "<shape type=\"rectangle\" id=\"card\"><bsdf type=\"roughplastic\">\
             <float name=\"alpha\" value=\"0.2\"/>\
             <string name=\"distribution\" value=\"beckmann\"/>{base}</bsdf>\
             <transform name=\"to_world\"><rotate x=\"1\" angle=\"30\"/></transform></shape>\n\
             <shape type=\"sphere\"><transform name=\"to_world\"><scale value=\"0.3\"/>\
             <translate x=\"1\" y=\"1\" z=\"2\"/></transform>\
             <emitter type=\"area\"><rgb name=\"radiance\" value=\"20\"/></emitter></shape>"
        );
        let sub = d.join(name);
        std::fs::create_dir_all(&sub).unwrap();
        std::fs::copy(d.join("flat.exr"), sub.join("flat.exr")).unwrap();
        let xml = scene_with(&sub, &body);
        let out = sub.join("out.toml");
        import(&xml, &out);
        load_scene(&out).unwrap()
    };
    let textured = scene_of(
        "<texture type=\"bitmap\" name=\"diffuse_reflectance\">\
         <string name=\"filename\" value=\"flat.exr\"/></texture>",
        "textured",
    );
    let plain = scene_of(
        "<rgb name=\"diffuse_reflectance\" value=\"0.6, 0.4, 0.2\"/>",
        "plain",
    );
    assert!(matches!(
        textured.objects[0].material,
        Material::TexturedPlastic { .. }
    ));
    assert!(matches!(
        plain.objects[0].material,
        Material::Plastic { .. }
    ));
    let means = object_means(&textured, &plain, 16);
    let card = means.iter().find(|m| m.0 == "card").expect("card seen");
    assert!(card.3 >= 4, "{means:?}");
    assert!(
        ((card.1 - card.2) / card.2).abs().max_element() < 1e-4,
        "{means:?}"
    );
    // Exported to Mitsuba as a roughplastic over a bitmap, it comes back the same.
    let mi = d.join("mi");
    let src = d.join("textured/out.toml");
    let (code, stdout, stderr) = run(
        &[
            "export",
            "mitsuba",
            src.to_str().unwrap(),
            "-o",
            mi.to_str().unwrap(),
        ],
        d,
    );
    assert_eq!(code, 0, "{stdout}\n{stderr}");
    let back_toml = d.join("back.toml");
    import(&mi.join("scene.xml"), &back_toml);
    let back = load_scene(&back_toml).unwrap();
    let card = |sc: &Scene| {
        sc.objects
            .iter()
            .find(|o| o.name == "card")
            .unwrap()
            .material
            .clone()
    };
    match (card(&back), card(&textured)) {
        (
            Material::TexturedPlastic {
                rho_s,
                alpha,
                eta,
                distribution,
                ..
            },
            Material::TexturedPlastic {
                rho_s: r0,
                alpha: a0,
                eta: e0,
                distribution: d0,
                ..
            },
        ) => {
            assert!((rho_s - r0).abs().max_element() < 1e-5, "{rho_s} vs {r0}");
            assert_eq!((alpha, eta, distribution), (a0, e0, d0));
        }
        (m, _) => panic!("came back as {m:?}"),
    }
}

/// A bump map warns at its line and imports as its nested BSDF; an envmap's translation is
/// ignored as Mitsuba ignores it; a mesh whose triangles all have no area is skipped with a
/// warning naming the file.
#[test]
fn bump_maps_envmap_translations_and_degenerate_meshes() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let mut img = matfit::io::image::Image::new(4, 2);
    for p in img.data.iter_mut() {
        *p = Rgb::splat(0.5);
    }
    img.write(&d.join("sky.exr")).unwrap();
    write(d, "flat.obj", "v 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\n");
    let xml = scene_with(
        d,
        "<shape type=\"sphere\" id=\"ball\">\n<bsdf type=\"bumpmap\">\
         <texture type=\"checkerboard\"/>\
         <bsdf type=\"diffuse\"><rgb name=\"reflectance\" value=\"0.25\"/></bsdf></bsdf>\n\
         </shape>\n\
         <emitter type=\"envmap\"><string name=\"filename\" value=\"sky.exr\"/>\
         <transform name=\"to_world\"><rotate y=\"1\" angle=\"90\"/>\
         <translate x=\"5\" y=\"-2\"/></transform></emitter>\n\
         <shape type=\"obj\"><string name=\"filename\" value=\"flat.obj\"/></shape>",
    );
    let out = d.join("out.toml");
    let warnings = import(&xml, &out);
    assert!(
        warnings.contains(
            ":10: <bsdf type=\"bumpmap\">: matfit has no bump or normal maps; \
                           imported as its nested BSDF"
        ),
        "{warnings}"
    );
    assert!(
        warnings.contains(&format!(
            ":13: mesh {} is skipped: it has no triangle of non-zero area",
            d.join("flat.obj").display()
        )),
        "{warnings}"
    );
    assert!(!warnings.contains("a bug of the importer"), "{warnings}");
    let f = toml_of(&out);
    assert!(close(
        &floats(&object(&f, "ball")["material"]["rho_d"]),
        &[0.25],
        1e-6
    ));
    let env = &f["environment"];
    assert!(
        close(&floats(&env["rotate_deg"]), &[0.0, 90.0, 0.0], 1e-3),
        "{env}"
    );
    assert_eq!(f["object"].as_array().unwrap().len(), 1);
}
