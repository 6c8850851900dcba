//! Sampled spectra (Mitsuba's `<spectrum value="400:0.343, 404:0.445, …"/>`) to linear sRGB, the
//! way Mitsuba 3's RGB variants turn them into colours when they load a scene, so that an
//! imported scene renders what Mitsuba renders (tools/cornell_rgb.md compares the conventions on
//! the measured Cornell box; Mitsuba's own values are within 0.2% of these):
//!
//! - a spectrum is piecewise linear between its samples and zero outside them;
//! - an emitter's radiance L(λ): XYZ = ∫ L·(x̄, ȳ, z̄) dλ / ∫ ȳ dλ (so a flat L maps to Y = L);
//! - a reflectance R(λ): XYZ = ∫ R·D65·(x̄, ȳ, z̄) dλ / ∫ D65·ȳ dλ (seen under D65, the sRGB white);
//! - then linear sRGB = M·XYZ with IEC 61966-2-1's matrix M.
//!
//! The CIE 1931 2° colour-matching functions and D65 are CIE 015:2018's tables, every 5 nm over
//! 360–830 nm (`cie1931_d65.csv`); the integrals step 1 nm with both linearly interpolated.

use glam::DVec3;
use std::sync::OnceLock;

/// Rows of (λ nm, x̄, ȳ, z̄, D65), 5 nm apart from 360 nm.
fn table() -> &'static [[f64; 5]] {
    static TABLE: OnceLock<Vec<[f64; 5]>> = OnceLock::new();
    TABLE.get_or_init(|| {
        include_str!("cie1931_d65.csv")
            .lines()
            .filter(|l| !l.starts_with('#') && !l.trim().is_empty())
            .map(|l| {
                let v: Vec<f64> = l.split(',').map(|x| x.trim().parse().unwrap()).collect();
                [v[0], v[1], v[2], v[3], v[4]]
            })
            .collect()
    })
}

/// (x̄, ȳ, z̄) and D65 at λ, linearly interpolated; zero outside the table.
fn cie(lambda: f64) -> (DVec3, f64) {
    let t = table();
    let (first, step) = (t[0][0], t[1][0] - t[0][0]);
    let f = (lambda - first) / step;
    if f < 0.0 || f > (t.len() - 1) as f64 {
        return (DVec3::ZERO, 0.0);
    }
    let i = (f as usize).min(t.len() - 2);
    let w = f - i as f64;
    let lerp = |k: usize| t[i][k] * (1.0 - w) + t[i + 1][k] * w;
    (DVec3::new(lerp(1), lerp(2), lerp(3)), lerp(4))
}

/// Linear sRGB of a sampled spectrum; `emission` selects the radiance rule over the
/// reflectance one (module comment). `samples` are (λ nm, value), λ strictly increasing.
pub fn to_srgb(samples: &[(f64, f64)], emission: bool) -> DVec3 {
    let value = |lambda: f64| -> f64 {
        let j = samples.partition_point(|s| s.0 <= lambda);
        if j == 0 || (j == samples.len() && lambda > samples[j - 1].0) {
            return 0.0;
        }
        if j == samples.len() {
            return samples[j - 1].1;
        }
        let (a, b) = (samples[j - 1], samples[j]);
        a.1 + (b.1 - a.1) * (lambda - a.0) / (b.0 - a.0)
    };
    let (mut xyz, mut norm) = (DVec3::ZERO, 0.0);
    for nm in 360..=830 {
        let lambda = f64::from(nm);
        let (cmf, d65) = cie(lambda);
        let weight = if emission { 1.0 } else { d65 };
        xyz += cmf * (weight * value(lambda));
        norm += cmf.y * weight;
    }
    xyz_to_srgb(xyz / norm)
}

/// Linear sRGB of a constant spectrum `value` given for an emitter: Mitsuba's RGB variants take
/// it as XYZ = (value, value, value), equal-energy light, which is pinkish in sRGB (whose white
/// is D65), so that they match its spectral variants. A constant reflectance stays grey.
pub fn uniform_emission_to_srgb(value: f64) -> DVec3 {
    xyz_to_srgb(DVec3::splat(value))
}

fn xyz_to_srgb(xyz: DVec3) -> DVec3 {
    DVec3::new(
        3.2406 * xyz.x - 1.5372 * xyz.y - 0.4986 * xyz.z,
        -0.9689 * xyz.x + 1.8758 * xyz.y + 0.0415 * xyz.z,
        0.0557 * xyz.x - 0.2040 * xyz.y + 1.0570 * xyz.z,
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    /// tools/cornell_rgb.md's "CIE" columns (1 nm tables): the light's emission, and the light's
    /// flat 0.78 reflectance under D65.
    #[test]
    fn the_cornell_box_light_converts_as_the_1nm_tables_do() {
        let light = [(400.0, 0.0), (500.0, 8.0), (600.0, 15.6), (700.0, 18.4)];
        let e = to_srgb(&light, true);
        let want = DVec3::new(20.7177, 10.8564, 2.7708);
        assert!(((e - want) / want).abs().max_element() < 2e-3, "{e}");
        let flat = [(400.0, 0.78), (700.0, 0.78)];
        let r = to_srgb(&flat, false);
        let want = DVec3::new(0.7773, 0.7807, 0.7772);
        assert!((r - want).abs().max_element() < 2e-3, "{r}");
        // D65 is the sRGB white: a flat spectrum over the whole range stays grey.
        let white = to_srgb(&[(360.0, 0.5), (830.0, 0.5)], false);
        assert!(
            (white - DVec3::splat(0.5)).abs().max_element() < 2e-3,
            "{white}"
        );
        // Zero outside its samples.
        assert_eq!(to_srgb(&[(900.0, 1.0), (950.0, 1.0)], true), DVec3::ZERO);
    }

    /// Mitsuba 3.9's `scalar_rgb` loads `<spectrum name="radiance" value="16.032"/>` on an area
    /// light as the colour (19.3153, 15.2030, 14.5717); a flat spectrum sampled over the whole
    /// range converts to nearly the same.
    #[test]
    fn a_constant_emission_spectrum_is_equal_energy_light() {
        let got = uniform_emission_to_srgb(16.032);
        let want = DVec3::new(19.3153, 15.2030, 14.5717);
        assert!(((got - want) / want).abs().max_element() < 5e-4, "{got}");
        let sampled = to_srgb(&[(360.0, 16.032), (830.0, 16.032)], true);
        assert!(((sampled - want) / want).abs().max_element() < 5e-3, "{sampled}");
    }
}
