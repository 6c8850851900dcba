//! Level 8, the GGX microfacet lobe (issue 20): figure6 with a diffuse floor (ρd 0.5) and its
//! small block made a rough green metal (Lambert 0 + GGX ρs (0.2, 0.7, 0.3), α 0.2, as Mitsuba's `roughconductor` with
//! `material = "none"`; the photo rendered by matfit at half size), recovered blind. The block
//! must end at the microfacet level with its lobe, every other group diffuse, and without level 8 the block's best Ward lobe must leave
//! a clearly larger error. bench/nonward.py does the same from Mitsuba's photos and scores the
//! predictions.

use crate::recover::{run_keeping_photo, scaled, truth};
use matfit::fit::hierarchy::HierarchyOptions;
use matfit::fit::{Level, RecoverOptions};
use matfit::math::Rgb;
use matfit::scene::Material;

#[test]
fn a_rough_metal_is_recovered_at_the_microfacet_level() {
    let mut scene = scaled("scenes/figure6/scene.toml", 0.5);
    let (rho_s, alpha) = (Rgb::new(0.2, 0.7, 0.3), 0.2f32);
    let g = scene.group_index("small_block").unwrap();
    let floor = scene.group_index("floor").unwrap();
    for &o in &scene.groups[floor].objects.clone() {
        scene.objects[o].material = Material::Diffuse {
            rho_d: Rgb::splat(0.5),
        };
    }
    for &o in &scene.groups[g].objects.clone() {
        scene.objects[o].material = Material::Microfacet {
            rho_d: Rgb::ZERO,
            rho_s,
            alpha_x: alpha,
            alpha_y: alpha,
            theta: 0.0,
        };
    }
    let fit = |microfacet: bool| {
        let opts = RecoverOptions {
            hierarchy: HierarchyOptions {
                microfacet,
                ..Default::default()
            },
            ..Default::default()
        };
        run_keeping_photo(&scene, 256, opts).0
    };
    let rec = fit(true);
    let mut table = String::new();
    for s in rec.groups.iter().filter(|s| s.is_fitted()) {
        table += &format!(
            "{:<12} {:<12} ε {:.4} ρd {:?} ρs {:?} α {:.4}\n",
            s.name,
            s.level.name(),
            s.error,
            s.params.rho_d.to_array(),
            s.params.rho_s.to_array(),
            s.params.alpha_x
        );
    }
    eprintln!("{table}");
    let block = &rec.groups[g];
    assert_eq!(block.level, Level::Microfacet, "{table}");
    let p = &block.params;
    assert!(
        (p.alpha_x / alpha - 1.0).abs() < 0.05,
        "α {}\n{table}",
        p.alpha_x
    );
    assert!((p.rho_s - rho_s).abs().max_element() < 0.03, "{table}");
    assert!(p.rho_d.max_element() < 0.03, "{table}");
    // Every other group stays diffuse.
    for s in rec
        .groups
        .iter()
        .filter(|s| s.is_fitted() && s.name != "small_block")
    {
        assert!(matches!(truth(&scene, &s.name), Material::Diffuse { .. }));
        assert_eq!(s.level, Level::Diffuse, "{}\n{table}", s.name);
    }
    // What level 8 buys: the best Ward lobe leaves a clearly larger error on the block.
    let ward = fit(false);
    let wb = &ward.groups[g];
    eprintln!(
        "without level 8: small_block {} ε {:.4} (with: {:.4})",
        wb.level.name(),
        wb.error,
        block.error
    );
    assert!(wb.level.is_ward(), "{:?}", wb.level);
    assert!(
        wb.error > 1.5 * block.error,
        "{} vs {}",
        wb.error,
        block.error
    );
}
