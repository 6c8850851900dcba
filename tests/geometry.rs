//! Index buffers against analytic projections, and the BVH against brute force on the bundled
//! scenes (meshes included).

use crate::common::root;
use matfit::geometry::triangle::{intersect, RayShear};
use matfit::geometry::Ray;
use matfit::math::{Vec2, Vec3};
use matfit::render::aov::index_buffers;
use matfit::scene::load::parse_scene;
use matfit::scene::load_scene;

/// Area of a polygon (shoelace formula).
fn polygon_area(p: &[Vec2]) -> f32 {
    let n = p.len();
    0.5 * (0..n)
        .map(|i| p[i].x * p[(i + 1) % n].y - p[(i + 1) % n].x * p[i].y)
        .sum::<f32>()
        .abs()
}

#[test]
fn quad_index_buffer_matches_its_analytic_projected_area() {
    // A tilted quad well inside the view of a calibrated and of a look-at camera: the number of
    // pixel centres it covers equals the area of its projected polygon within 0.5%.
    let quad = r#"
[[object]]
name = "card"
group = "card"
shape = "quad"
corner = [-0.8, -0.5, 0.1]
edge_u = [1.5, 0.3, -0.2]
edge_v = [0.2, 1.1, 0.3]
"#;
    let cameras = [
        "[camera]\nwidth = 640\nheight = 480\neye = [0.3, 0.2, 3.0]\ntarget = [0.0, 0.0, 0.0]\nfov_y_deg = 40.0\n",
        "[camera]\nwidth = 600\nheight = 500\nfx = 700.0\nfy = 690.0\ncx = 310.2\ncy = 240.7\n\
         rotation = [[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, -1.0]]\ntranslation = [0.1, -0.1, 3.2]\n",
    ];
    for cam in cameras {
        let text = format!("{cam}{quad}");
        let scene = parse_scene(&text, std::path::Path::new("inline.toml")).unwrap();
        let ib = index_buffers(&scene, &scene.camera);
        let count = ib.group.iter().filter(|&&g| g == 0).count() as f32;
        let corners = [
            Vec3::new(-0.8, -0.5, 0.1),
            Vec3::new(0.7, -0.2, -0.1),
            Vec3::new(0.9, 0.9, 0.2),
            Vec3::new(-0.6, 0.6, 0.4),
        ];
        let proj: Vec<Vec2> = corners
            .iter()
            .map(|&c| scene.camera.project(c).unwrap())
            .collect();
        let area = polygon_area(&proj);
        let rel = (count - area).abs() / area;
        assert!(area > 20000.0, "the quad should be large on screen: {area}");
        assert!(
            rel < 0.005,
            "index buffer {count} px vs analytic {area:.1} px ({:.3}%)",
            rel * 100.0
        );
    }
}

#[test]
fn index_buffer_sees_each_visible_figure6_group_and_not_the_ceiling() {
    let scene = load_scene(&root().join("scenes/figure6/scene.toml")).unwrap();
    let ib = index_buffers(&scene, &scene.camera);
    let count = |name: &str| {
        let g = scene.group_index(name).unwrap() as i32;
        ib.group.iter().filter(|&&x| x == g).count()
    };
    for g in [
        "floor",
        "left_wall",
        "right_wall",
        "back_wall",
        "big_block",
        "small_block",
    ] {
        assert!(
            count(g) > 1000,
            "group {g} should be visible: {} px",
            count(g)
        );
    }
    assert_eq!(count("ceiling"), 0, "the ceiling must be out of view");
    assert!(
        ib.group.iter().all(|&g| g >= 0),
        "a closed room: every pixel sees something"
    );
    // The floor reflects the blocks: the through-mirror buffer sees them from floor pixels.
    let floor = scene.group_index("floor").unwrap() as i32;
    let big = scene.group_index("big_block").unwrap() as i32;
    let seen = ib
        .group
        .iter()
        .zip(&ib.mirror_group)
        .filter(|&(&g, &m)| g == floor && m == big)
        .count();
    assert!(seen > 500, "floor pixels reflecting the big block: {seen}");
}

/// Closest hit by testing every triangle of the scene.
fn brute(scene: &matfit::scene::Scene, ray: &Ray) -> Option<(f32, u32)> {
    let g = &scene.geometry;
    let sh = RayShear::new(ray.d);
    let mut best: Option<(f32, u32)> = None;
    for (i, t) in g.tris.iter().enumerate() {
        let [a, b, c] = t.v.map(|k| g.positions[k as usize]);
        let lim = best.map_or(f32::INFINITY, |b| b.0);
        if let Some((t, _, _)) = intersect(ray.o, &sh, a, b, c, lim) {
            best = Some((t, i as u32));
        }
    }
    best
}

#[test]
fn bvh_equals_brute_force_on_100k_rays_with_meshes() {
    // The Cornell box (OBJ meshes) and a scene with an OBJ sphere mesh, PLY and built-in shapes.
    let dir = tempfile::tempdir().unwrap();
    let sphere = matfit::geometry::shapes::sphere(Vec3::new(0.2, 0.5, -0.3), 0.4, 48);
    let mut obj = String::new();
    for p in &sphere.positions {
        obj += &format!("v {} {} {}\n", p.x, p.y, p.z);
    }
    for t in &sphere.indices {
        obj += &format!("f {} {} {}\n", t[0] + 1, t[1] + 1, t[2] + 1);
    }
    crate::common::write(dir.path(), "ball.obj", &obj);
    let scene_text = format!(
        "{}\n[[object]]\nname = \"ball\"\ngroup = \"ball\"\nshape = \"mesh\"\nfile = \"ball.obj\"\n\
         [[object]]\nname = \"cube\"\ngroup = \"cube\"\nshape = \"box\"\nmin = [-0.9, 0.0, -0.9]\nmax = [-0.4, 0.5, -0.4]\n\
         transform = {{ rotate_deg = [10.0, 30.0, 0.0] }}\n\
         [[object]]\nname = \"orb\"\ngroup = \"orb\"\nshape = \"sphere\"\ncenter = [0.6, 0.3, 0.4]\nradius = 0.3\n",
        crate::common::small_scene()
    );
    let p = crate::common::write(dir.path(), "scene.toml", &scene_text);
    let scenes = [
        load_scene(&p).unwrap(),
        load_scene(&root().join("scenes/cornell/scene.toml")).unwrap(),
    ];
    let mut state = 12345u64;
    let mut rnd = || {
        state = state.wrapping_add(1);
        matfit::math::sampler::unit_f32(matfit::math::sampler::mix64(state))
    };
    let mut hits = 0;
    for scene in &scenes {
        let b = scene.geometry.bvh.bounds();
        let ext = b.max - b.min;
        for _ in 0..50_000 {
            let o = b.min - 0.1 * ext + 1.2 * ext * Vec3::new(rnd(), rnd(), rnd());
            let target = b.min + ext * Vec3::new(rnd(), rnd(), rnd());
            let ray = Ray::new(o, (target - o).normalize());
            let fast = scene.intersect(&ray, f32::INFINITY).map(|h| (h.t, h.prim));
            let slow = brute(scene, &ray);
            match (fast, slow) {
                (None, None) => {}
                (Some(a), Some(b)) => {
                    assert!((a.0 - b.0).abs() <= 1e-5 * b.0.max(1.0), "t {a:?} vs {b:?}");
                    hits += 1;
                }
                _ => panic!("BVH {fast:?} vs brute force {slow:?} for {ray:?}"),
            }
        }
    }
    assert!(hits > 50_000, "most rays should hit something: {hits}");
}
