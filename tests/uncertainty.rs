//! Are the error bars honest? Reduced figure6 and glossy rooms, each rendered and
//! recovered with several seeds (photo and recovery alike): the true value of every parameter
//! must lie within ±2σ of the recovered one for ≥ 90% of them, and the σ must not be inflated
//! (the RMS of error/σ at least 0.5). A group that ends at another level than its truth's counts
//! all its parameters as misses.

use crate::recover::{scaled, truth};
use matfit::fit::params::Value;
use matfit::fit::{recover, GroupParams, Level, RecoverOptions};
use matfit::photo::Photo;
use matfit::prepare::coverage::pure_pixels;
use matfit::prepare::usable_pixels_covered;
use matfit::render::aov::index_buffers;
use matfit::render::film::{render, RenderOptions};
use matfit::scene::{Material, Scene};

/// The level a scene material belongs to.
fn level_of(m: &Material) -> Option<Level> {
    Some(match m {
        Material::Diffuse { .. } => Level::Diffuse,
        Material::Mirror { .. } => Level::Specular,
        Material::DiffuseMirror { .. } => Level::DiffuseSpecular,
        Material::Ward {
            alpha_x, alpha_y, ..
        } if alpha_x == alpha_y => Level::Isotropic,
        Material::Ward { .. } => Level::Anisotropic,
        _ => return None,
    })
}

fn flat(v: &Value) -> Vec<f32> {
    match v {
        Value::Rgb(c) => c.to_vec(),
        Value::Scalar(x) => vec![*x],
    }
}

/// Per parameter channel of every fitted group, (recovered − true) / σ (infinite for a group at
/// the wrong level or without σ), and a line for the report.
fn z_scores(scene: &Scene, seed: u64, lines: &mut String) -> Vec<f32> {
    let photo = Photo::from_linear(render(
        scene,
        &scene.camera,
        &RenderOptions {
            spp: 256,
            seed,
            progress: false,
        },
    ));
    let ib = index_buffers(scene, &scene.camera);
    let pure = pure_pixels(scene, &scene.camera, &ib);
    let mask = usable_pixels_covered(
        &ib,
        Some(&pure),
        &photo,
        scene.groups.len(),
        &Default::default(),
    );
    let opts = RecoverOptions {
        progress: false,
        seed,
        final_spp: Some(4),
        ..Default::default()
    };
    let rec = recover(scene, &photo, &mask, &opts, |_| {}).unwrap();
    let mut z = Vec::new();
    for g in rec.groups.iter().filter(|g| g.is_fitted()) {
        let t = truth(scene, &g.name);
        let want = level_of(&t).expect("a uniform truth");
        let named = |p: &GroupParams| p.named(want);
        let truth_params = GroupParams::from_material(&t);
        let (Some(sigma), true) = (g.sigma.as_ref(), g.level == want) else {
            *lines += &format!("seed {seed} {}: level {:?} for {want:?}\n", g.name, g.level);
            z.extend(
                named(&truth_params)
                    .iter()
                    .flat_map(|(_, v)| flat(v))
                    .map(|_| f32::INFINITY),
            );
            continue;
        };
        for (((name, t), (_, v)), (_, s)) in named(&truth_params)
            .iter()
            .zip(named(&g.params))
            .zip(named(sigma))
        {
            for ((t, v), s) in flat(t).into_iter().zip(flat(&v)).zip(flat(&s)) {
                let zi = if v == t { 0.0 } else { (v - t) / s };
                if zi.abs() > 2.0 {
                    *lines += &format!(
                        "seed {seed} {} {name}: {v:.4} ± {s:.4} for {t:.4}\n",
                        g.name
                    );
                }
                z.push(zi);
            }
        }
    }
    z
}

#[test]
fn error_bars_hold_the_truth_at_the_stated_rate() {
    // Measured over 6 seeds each (2026-12-08): figure6 at 128×96 with the ceiling given white
    // as in the notes, 100% of 144 within 2σ, RMS z 0.39; glossy at 200×150, 100% of 168,
    // 0.61 (bench/README.md, "Design measurements", has an earlier run, before the misfit
    // terms widened the bars: 93.8%, 0.95 and 98.8%, 0.92).
    let mut f6 = scaled("scenes/figure6/scene.toml", 0.25);
    let ceiling = f6.group_index("ceiling").unwrap();
    f6.groups[ceiling].fixed = true;
    let glossy = scaled("scenes/glossy/scene.toml", 0.5);
    let mut lines = String::new();
    let mut all = Vec::new();
    for (name, scene) in [("figure6", &f6), ("glossy", &glossy)] {
        let z: Vec<f32> = (1..=6)
            .flat_map(|s| z_scores(scene, s, &mut lines))
            .collect();
        let within = z.iter().filter(|z| z.abs() <= 2.0).count() as f32 / z.len() as f32;
        let rms = (z.iter().map(|z| z.min(10.0).powi(2)).sum::<f32>() / z.len() as f32).sqrt();
        lines += &format!(
            "{name}: {:.1}% within 2σ of {} parameters, RMS z {rms:.2}\n",
            100.0 * within,
            z.len()
        );
        all.extend(z);
    }
    eprintln!("{lines}");
    let within = all.iter().filter(|z| z.abs() <= 2.0).count() as f32 / all.len() as f32;
    let rms = (all.iter().map(|z| z.min(10.0).powi(2)).sum::<f32>() / all.len() as f32).sqrt();
    assert!(within >= 0.9, "{lines}");
    assert!(rms >= 0.5, "σ inflated: {lines}");
}
