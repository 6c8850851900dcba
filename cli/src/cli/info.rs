//! `matfit info`: a summary of a scene file (camera, render settings, groups, lights).

use super::*;

/// The arguments of `matfit info` (see `Command::Info`).
#[derive(clap::Args)]
pub struct InfoCli {
    #[arg(help = SCENE_HELP)]
    scene: PathBuf,
}

/// Runs `matfit info`.
pub fn command(args: InfoCli) -> Result<()> {
    let InfoCli { scene } = args;
    let (sc, lighting) = load(&scene)?;
    info(&sc, &lighting);
    Ok(())
}

/// `info`: the camera, render settings, groups with their objects and materials, lights.
fn info(sc: &Scene, lighting: &matfit::scene::lint::Lighting) {
    use table::{num, rgb, vec3};
    let c = &sc.camera;
    outln!("scene {}", sc.path.display());
    outln!(
        "camera {}×{} px, eye {}, looking along {}, {}, fx {} fy {} px{}",
        c.width,
        c.height,
        vec3(c.eye()),
        vec3(
            c.ray(matfit::math::Vec2::new(
                c.width as f32 / 2.0,
                c.height as f32 / 2.0
            ))
            .d
        ),
        match (c.fov_y_deg(), c.film_size_m()) {
            (Some(fov), _) => format!("fov_y {}°", num(fov, 3)),
            (None, Some(s)) => format!(
                "orthographic, film {} × {} scene units",
                num(s.x, 4),
                num(s.y, 4)
            ),
            (None, None) => unreachable!("a camera is perspective or orthographic"),
        },
        num(c.fx, 2),
        num(c.fy, 2),
        if c.is_orthographic() { " per unit" } else { "" }
    );
    let r = &sc.render;
    outln!(
        "render spp {}, max_depth {}, rr_depth {}, seed {}, ward_variant {}",
        r.spp,
        r.max_depth,
        r.rr_depth,
        r.seed,
        r.ward_variant.name()
    );
    outln!("triangles {}", sc.triangle_count());
    for g in &sc.groups {
        let names: Vec<&str> = g
            .objects
            .iter()
            .map(|&o| sc.objects[o].name.as_str())
            .collect();
        let mats: Vec<String> = {
            let mut m: Vec<String> = g
                .objects
                .iter()
                .filter(|&&o| !sc.objects[o].is_emitter())
                .map(|&o| table::material(&sc.objects[o].material))
                .collect();
            m.dedup();
            m
        };
        outln!(
            "group {}{}: {}{}",
            g.name,
            if g.fixed { " (fixed)" } else { "" },
            names.join(", "),
            if mats.is_empty() {
                String::new()
            } else {
                format!("; {}", mats.join(" | "))
            }
        );
    }
    for (i, o) in sc
        .objects
        .iter()
        .enumerate()
        .filter(|(_, o)| o.is_emitter())
    {
        outln!(
            "light {}: radiance {}, area {}{}",
            o.name,
            rgb(o.emission),
            num(o.area, 4),
            if lighting.facing_away.contains(&i) {
                " (faces away from everything in view)"
            } else {
                ""
            }
        );
    }
    for l in &sc.punctual_lights {
        use matfit::scene::Punctual;
        outln!(
            "light {}: {}",
            l.name,
            match l.kind {
                Punctual::Directional {
                    direction,
                    irradiance,
                    angle,
                } => format!(
                    "directional, travelling along {}, irradiance {}{}",
                    vec3(direction),
                    rgb(irradiance),
                    if angle > 0.0 {
                        format!(", {}° wide", num(angle.to_degrees(), 3))
                    } else {
                        String::new()
                    }
                ),
                Punctual::Point {
                    position,
                    intensity,
                } => format!("point at {}, intensity {}", vec3(position), rgb(intensity)),
                Punctual::Spot {
                    position,
                    direction,
                    intensity,
                    cutoff,
                    beam_width,
                } => format!(
                    "spot at {} along {}, intensity {}, beam {}°, cutoff {}°",
                    vec3(position),
                    vec3(direction),
                    rgb(intensity),
                    num(beam_width.to_degrees(), 3),
                    num(cutoff.to_degrees(), 3)
                ),
            }
        );
    }
    if let Some(e) = &sc.environment {
        outln!("environment: {e:?}");
    }
    for (k, v) in sc.views.iter().enumerate() {
        outln!(
            "view {} '{}': lights {}; camera {}",
            k + 1,
            v.name,
            v.lights
                .as_ref()
                .map_or("all".to_string(), |l| l.join(", ")),
            if v.camera == sc.camera {
                "[camera]".to_string()
            } else {
                format!(
                    "eye {}, {}×{} px",
                    vec3(v.camera.eye()),
                    v.camera.width,
                    v.camera.height
                )
            }
        );
    }
    if lighting.none() {
        out::warn(format!("{}: nothing emits light", sc.path.display()));
    }
}
