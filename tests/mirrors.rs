//! End-to-end mirrors (issue 25, §5.1 of the notes): scenes/facing-mirrors, two non-perfect
//! mirrors facing each other (ρs 0.85 and 0.7), each seen directly and in the other, and a
//! textured book seen directly and in the left mirror. Its photo rendered by matfit with the
//! true materials, recovered blind.

use crate::recover::{run_keeping_photo, scaled, state, truth};
use crate::texture::scores;
use matfit::fit::Level;
use matfit::math::Rgb;

#[test]
fn facing_mirrors_are_confirmed_and_the_book_textured() {
    // Full size (320×240), 512-spp photo. Measured: mirrors ρs (0.850, 0.850, 0.850) and
    // (0.703, 0.702, 0.701); walls and floor within 0.005; the book 29.3 dB over 2680 seen
    // texels (the texture cut from the photo: 22.8 dB), 29.8 dB from a 1024-spp photo: what
    // is left is the cover's sharp edges against a texel the size of a pixel, and the side
    // face seen at a grazing angle.
    let scene = scaled("scenes/facing-mirrors/scene.toml", 1.0);
    let (rec, photo, _) = run_keeping_photo(&scene, 512, Default::default());
    let mut table = String::new();
    for g in rec.groups.iter().filter(|g| g.is_fitted()) {
        table += &format!(
            "{:<13} {:<10} {:?} ρd {:.4} ρs {:.4} (true ρd {:.4} ρs {:.4})\n",
            g.name,
            g.level.name(),
            g.status,
            g.params.rho_d,
            g.params.rho_s,
            truth(&scene, &g.name).rho_d(),
            truth(&scene, &g.name).rho_s()
        );
    }
    eprintln!("{table}");
    for (name, rho_s) in [("mirror_left", 0.85), ("mirror_right", 0.7)] {
        let g = state(&rec, name);
        assert_eq!(g.level, Level::Specular, "{name}\n{table}");
        let e = (g.params.rho_s - Rgb::splat(rho_s)).abs().max_element();
        assert!(e < 0.01, "{name}: ρs off by {e}\n{table}");
    }
    for name in ["floor", "walls", "left_wall", "right_wall"] {
        let g = state(&rec, name);
        assert_eq!(g.level, Level::Diffuse, "{name}\n{table}");
        let e = (g.params.rho_d - truth(&scene, name).rho_d())
            .abs()
            .max_element();
        assert!(e < 0.01, "{name}: ρd off by {e}\n{table}");
    }
    assert_eq!(state(&rec, "book").level, Level::Textured, "{table}");
    let (book, cut) = scores(&scene, &photo, &rec, "book");
    eprintln!("book recovered {book:?}\nbook cut       {cut:?}");
    assert!(book.psnr >= 29.0, "{book:?}");
    assert!(book.psnr > cut.psnr + 3.0, "{book:?} vs cut {cut:?}");
}
