//! Orthographic cameras through the binary: a Lambert sphere under a directional light, seen
//! along parallel rays, against analytic answers for each pixel's radiance and for the area of
//! its silhouette.

use crate::common::{from_f32, run, vec3, write, SceneToml};
use matfit::io::image::read_linear;
use matfit::math::{Vec2, Vec3};

const R: f32 = 0.5;
const W: usize = 96;
/// Pixels per scene unit: a film 1.5 units wide on 96 pixels.
const F: f32 = W as f32 / 1.5;

fn scene(material: &str, light: &str) -> String {
    let w = W.to_string();
    SceneToml::compact()
        .render(&[("spp", "64")])
        .table(
            "[camera]",
            &[
                ("width", &w),
                ("height", &w),
                ("projection", "\"orthographic\""),
                ("eye", &vec3([0.0, 0.0, 3.0])),
                ("target", &vec3([0.0; 3])),
                ("width_m", "1.5"),
            ],
        )
        .sphere("ball", "ball", [0.0; 3], from_f32([R])[0], Some(512), "")
        .raw(&format!("{material}\n{light}"))
        .to_toml()
}

/// Where the orthographic ray through film position `film` meets the sphere, if it does: the
/// ray starts at ((x − 48)/F, (48 − y)/F, 3) and runs along −z.
fn sphere_point(film: Vec2) -> Option<Vec3> {
    let (x, y) = ((film.x - 0.5 * W as f32) / F, (0.5 * W as f32 - film.y) / F);
    let z2 = R * R - x * x - y * y;
    (z2 >= 0.0).then(|| Vec3::new(x, y, z2.sqrt()))
}

#[test]
fn an_orthographic_camera_sees_a_lambert_sphere_as_rho_over_pi_e_cos_and_its_true_area() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let (rho, e) = (0.6f32, 2.0f32);
    let light = Vec3::new(-0.5, -0.3, -1.0).normalize(); // the way the light travels
    write(
        d,
        "lit.toml",
        &scene(
            &format!("material = {{ type = \"diffuse\", rho_d = {rho} }}"),
            &format!(
                "[[light]]\nname = \"sun\"\ntype = \"directional\"\ndirection = [{}, {}, {}]\nirradiance = {e}\n",
                light.x, light.y, light.z
            ),
        ),
    );
    // The silhouette: the sphere black against a wall glowing with a radiance of 1, so that a
    // pixel's value is the fraction of it the sphere leaves uncovered.
    write(
        d,
        "glow.toml",
        &scene(
            "material = { type = \"black\" }",
            "[[object]]\nname = \"wall\"\ngroup = \"wall\"\nshape = \"quad\"\n\
             corner = [-2.0, -2.0, -1.0]\nedge_u = [4.0, 0.0, 0.0]\nedge_v = [0.0, 4.0, 0.0]\n\
             material = { type = \"black\" }\nemission = 1.0",
        ),
    );
    for s in ["lit", "glow"] {
        let (code, _, err) = run(
            &["render", &format!("{s}.toml"), "-o", &format!("{s}.exr")],
            d,
        );
        assert_eq!(code, 0, "{err}");
    }
    let lit = read_linear(&d.join("lit.exr")).unwrap();
    let glow = read_linear(&d.join("glow.exr")).unwrap();

    // Each pixel against ρ/π · E · max(0, n·(−light)), averaged over a 16×16 grid in it (the
    // box pixel filter). Only direct light: a lone convex object reflects nothing onto itself.
    let (mut worst, mut inside) = (0.0f32, 0);
    for y in 0..W {
        for x in 0..W {
            let n = 16;
            let mut want = 0.0;
            for k in 0..n * n {
                let film = Vec2::new(
                    x as f32 + ((k % n) as f32 + 0.5) / n as f32,
                    y as f32 + ((k / n) as f32 + 0.5) / n as f32,
                );
                if let Some(p) = sphere_point(film) {
                    want += rho / std::f32::consts::PI * e * (p / R).dot(-light).max(0.0);
                }
            }
            want /= (n * n) as f32;
            let got = lit.get(x, y).y;
            // Edge and terminator pixels are estimates (64 samples of a partly covered pixel);
            // a pixel wholly on the lit sphere is exact up to the mesh's facets.
            let peak = rho / std::f32::consts::PI * e;
            worst = worst.max((got - want).abs() / peak);
            let corners = [(0.0, 0.0), (1.0, 0.0), (0.0, 1.0), (1.0, 1.0)];
            let whole = corners.iter().all(|&(i, j)| {
                sphere_point(Vec2::new(x as f32 + i, y as f32 + j))
                    .is_some_and(|p| (p / R).dot(-light) > 0.05)
            });
            if whole {
                inside += 1;
                assert!(
                    (got - want).abs() < 2e-3 * peak,
                    "pixel ({x}, {y}): {got} vs {want}"
                );
            }
        }
    }
    assert!(inside > 2000, "{inside} pixels wholly on the lit side");
    assert!(
        worst < 0.15,
        "worst pixel off by {worst} of the peak radiance"
    );

    // The silhouette's area in pixels: π r² · F².
    let area: f64 = glow.data.iter().map(|c| 1.0 - c.y as f64).sum();
    let want = std::f64::consts::PI * (R * F) as f64 * (R * F) as f64;
    assert!(
        ((area - want) / want).abs() < 2e-3,
        "silhouette {area:.1} px² vs π r² F² = {want:.1}"
    );
}
