//! The Trowbridge–Reitz (GGX) microfacet lobe of a rough perfect conductor: Mitsuba 3's
//! `roughconductor` with `distribution = "ggx"` and `material = "none"` (Fresnel F = 1), which
//! matfit exports it as, value for value. In the local frame (normal +z, tangent +x rotated by
//! the material's θ), with ĥ the normalised half vector of ωi and ωo:
//!
//!   f_s = ρs · D(ĥ) G1(ωi) G1(ωo) / (4 cosθi cosθo)
//!   D(ĥ) = 1 / (π αx αy (ĥx²/αx² + ĥy²/αy² + ĥz²)²)          (Walter et al. 2007, eq. 33;
//!                                                            anisotropic: Heitz 2014, eq. 85)
//!   G1(ω) = 2 / (1 + √(1 + (αx² ωx² + αy² ωy²) / ωz²))        (Smith, Heitz 2014 eq. 86)
//!
//! with Mitsuba's separable masking-shadowing G1(ωi) G1(ωo) (not the height-correlated form).
//! Unlike Ward's Gaussian, D falls off as a power of the half-vector slope: a sharp core with
//! a wide halo, the shape of most measured glossy surfaces (Walter et al. 2007, §5.2).
//!
//! Sampling draws ĥ from D(ĥ) cos θh: its slopes (ĥx/ĥz, ĥy/ĥz) are (αx, αy) · √(u1/(1 − u1))
//! · (cos 2πu2, sin 2πu2) (Walter et al. 2007, eq. 35–36), and p(ωi) = D cos θh / (4 |ωo·ĥ|).
//!
//! All values are per unit ρs, as the Ward lobe's: the caller multiplies by ρs. The fitter
//! evaluates the isotropic lobe from the cache's precomputed half vectors with its derivative
//! in ln α ([`ggx_at`], [`ggx_sums`]).

use super::ward::{HalfVector, LobeSample};
use crate::math::{Rgb, Vec2, Vec3, PI};
use wide::f32x8;

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GgxLobe {
    pub alpha_x: f32,
    pub alpha_y: f32,
}

impl GgxLobe {
    /// D(ĥ) for a unit half vector in the upper hemisphere.
    #[inline]
    fn distribution(&self, h: Vec3) -> f32 {
        let (a, b) = (h.x / self.alpha_x, h.y / self.alpha_y);
        let t = a * a + b * b + h.z * h.z;
        1.0 / (PI * self.alpha_x * self.alpha_y * t * t)
    }

    /// Smith's G1 of a direction above the surface (and above the microfacet, which a half
    /// vector of two directions above the surface always is).
    #[inline]
    pub(crate) fn g1(&self, w: Vec3) -> f32 {
        let (a, b) = (self.alpha_x * w.x, self.alpha_y * w.y);
        let t = (a * a + b * b) / (w.z * w.z);
        2.0 / (1.0 + (1.0 + t).sqrt())
    }

    /// f_s / ρs (both directions in the upper hemisphere, else 0).
    #[inline]
    pub fn eval(&self, wo: Vec3, wi: Vec3) -> f32 {
        if wo.z <= 0.0 || wi.z <= 0.0 {
            return 0.0;
        }
        let h = (wi + wo).normalize();
        self.distribution(h) * self.g1(wi) * self.g1(wo) / (4.0 * wi.z * wo.z)
    }

    /// Density (per solid angle of ωi) of [`GgxLobe::sample`].
    #[inline]
    pub fn pdf(&self, wo: Vec3, wi: Vec3) -> f32 {
        if wo.z <= 0.0 || wi.z <= 0.0 {
            return 0.0;
        }
        let h = (wi + wo).normalize();
        self.distribution(h) * h.z / (4.0 * wo.dot(h).abs())
    }

    /// Draws ωi by sampling the half vector; None when the reflected direction is below the
    /// surface (the sample is then lost, which `pdf` accounts for by not renormalising).
    #[inline]
    pub fn sample(&self, wo: Vec3, u: Vec2) -> Option<Vec3> {
        let u1 = u.x.min(1.0 - f32::EPSILON);
        let r = (u1 / (1.0 - u1)).sqrt();
        let (s, c) = (2.0 * PI * u.y).sin_cos();
        let h = Vec3::new(self.alpha_x * r * c, self.alpha_y * r * s, 1.0).normalize();
        let wi = 2.0 * wo.dot(h) * h - wo;
        (wi.z > 0.0 && wo.z > 0.0).then_some(wi)
    }
}

/// What the isotropic lobe needs of a cached pair of directions, recovered from its
/// [`HalfVector`] (which keeps what Ward's lobe needs): tan²θh, tan²θi, tan²θo and
/// 1 / (4 cosθi cosθo). With h = ωi + ωo unnormalised, hz = cosθi + cosθo, and Ward 1992's
/// norm 1 / (4π √(cosθi cosθo)) gives their product P; the two cosines are the roots of
/// x² − hz x + P (G1 is symmetric in them, so which is which does not matter). The smaller
/// root is taken as P / the larger, which does not cancel.
#[derive(Clone, Copy, Debug, Default)]
struct Pair {
    tan2_h: f32,
    tan2_i: f32,
    tan2_o: f32,
    inv_4cc: f32,
}

impl Pair {
    #[inline]
    fn of(hv: &HalfVector) -> Option<Pair> {
        let (big, small, p, _) = roots(hv)?;
        let tan2 = |c: f32| (1.0 - c * c).max(0.0) / (c * c);
        Some(Pair {
            tan2_h: (hv.hx * hv.hx + hv.hy * hv.hy) * hv.inv_hz2,
            tan2_i: tan2(big),
            tan2_o: tan2(small),
            inv_4cc: 0.25 / p,
        })
    }
}

/// cos θi and cos θo of a cached pair (in either order), and cos θd = ωi·ĥ, from its half
/// vector (see [`Pair`]); None below the surface.
pub fn cosines(hv: &HalfVector) -> Option<(f32, f32, f32)> {
    let (big, small, _, hz2) = roots(hv)?;
    let len2 = hv.hx * hv.hx + hv.hy * hv.hy + hz2;
    Some((big, small, 0.5 * len2.sqrt()))
}

/// The larger and the smaller of a cached pair's two cosines, their product P and hz² (see
/// [`Pair`]); None below the surface.
#[inline]
fn roots(hv: &HalfVector) -> Option<(f32, f32, f32, f32)> {
    let n = hv.norm[0];
    if n <= 0.0 {
        return None;
    }
    let hz2 = 1.0 / hv.inv_hz2;
    let k = 4.0 * PI * n; // 1 / √P
    let p = 1.0 / (k * k);
    let big = 0.5 * (hz2.sqrt() + (hz2 - 4.0 * p).max(0.0).sqrt());
    Some((big, p / big, p, hz2))
}

/// The isotropic lobe per unit ρs at a cached pair, and its derivative in ln α:
///   D = α² (1 + t)² / (π (α² + t)²)            (t = tan²θh; D of the module comment),
///   ∂ln D/∂ln α = 2 − 4α² / (α² + t),
///   ∂ln G1/∂ln α = −(s − 1/s) / (1 + s) with s = √(1 + α² tan²θ).
#[inline]
pub fn ggx_at(hv: &HalfVector, alpha: f32) -> (f32, f32) {
    let Some(q) = Pair::of(hv) else {
        return (0.0, 0.0);
    };
    let a2 = alpha * alpha;
    let d_den = a2 + q.tan2_h;
    let one_t = 1.0 + q.tan2_h;
    let d = a2 * one_t * one_t / (PI * d_den * d_den);
    let (si, so) = ((1.0 + a2 * q.tan2_i).sqrt(), (1.0 + a2 * q.tan2_o).sqrt());
    let g = d * (2.0 / (1.0 + si)) * (2.0 / (1.0 + so)) * q.inv_4cc;
    let dln = 2.0 - 4.0 * a2 / d_den - (si - 1.0 / si) / (1.0 + si) - (so - 1.0 / so) / (1.0 + so);
    (g, g * dln)
}

/// Σ c·g over `samples` and, if asked, Σ c·2∂g/∂ln α (zero otherwise), for the isotropic lobe
/// of roughness `alpha`: [`ggx_at`] on eight samples at a time, the rest one by one (the lanes
/// reorder no operation, but may differ from the scalar sum in the last bits of the totals).
pub fn ggx_sums(samples: &[LobeSample], alpha: f32, derivatives: bool) -> (Rgb, Rgb) {
    let splat = f32x8::splat;
    let a2 = splat(alpha * alpha);
    let (one, two) = (f32x8::ONE, splat(2.0));
    let (mut s, mut ds) = ([f32x8::ZERO; 3], [f32x8::ZERO; 3]);
    let mut chunks = samples.chunks_exact(8);
    for chunk in &mut chunks {
        let q: [Pair; 8] = std::array::from_fn(|i| Pair::of(&chunk[i].half).unwrap_or_default());
        let lanes = |f: &dyn Fn(&Pair) -> f32| f32x8::from(std::array::from_fn(|i| f(&q[i])));
        let (th, ti, to) = (
            lanes(&|p| p.tan2_h),
            lanes(&|p| p.tan2_i),
            lanes(&|p| p.tan2_o),
        );
        let k = lanes(&|p| p.inv_4cc);
        let c = [0, 1, 2].map(|ch| f32x8::from(std::array::from_fn(|i| chunk[i].c[ch])));
        let d_den = a2 + th;
        let one_t = one + th;
        let d = a2 * one_t * one_t / (splat(PI) * d_den * d_den);
        let (si, so) = ((one + a2 * ti).sqrt(), (one + a2 * to).sqrt());
        let g = d * (two / (one + si)) * (two / (one + so)) * k;
        for ch in 0..3 {
            s[ch] += c[ch] * g;
        }
        if derivatives {
            let dln = two
                - splat(4.0) * a2 / d_den
                - (si - one / si) / (one + si)
                - (so - one / so) / (one + so);
            for ch in 0..3 {
                ds[ch] += c[ch] * (two * g * dln);
            }
        }
    }
    let sum = |v: &[f32x8; 3]| Rgb::from_array(v.map(|x| x.reduce_add()));
    let (mut s, mut ds) = (sum(&s), sum(&ds));
    for smp in chunks.remainder() {
        let (g, dg) = ggx_at(&smp.half, alpha);
        s += smp.c * g;
        if derivatives {
            ds += smp.c * (2.0 * dg);
        }
    }
    (s, ds)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::Sampler;

    fn dir(theta: f32, phi: f32) -> Vec3 {
        Vec3::new(
            theta.sin() * phi.cos(),
            theta.sin() * phi.sin(),
            theta.cos(),
        )
    }

    /// Reciprocity, and the closed form at normal incidence and reflection: ĥ = n, D = 1/(π α²)
    /// and G1 = 1, so f = 1 / (4π α²).
    #[test]
    fn reciprocal_and_the_closed_form_at_the_normal() {
        let l = GgxLobe {
            alpha_x: 0.13,
            alpha_y: 0.31,
        };
        for (a, b) in [(0.3, 0.1), (1.2, 2.0), (0.7, -1.0), (1.5, 0.4)] {
            let (wo, wi) = (dir(a, b), dir(b.abs() * 0.5, a));
            let (f1, f2) = (l.eval(wo, wi), l.eval(wi, wo));
            assert!((f1 - f2).abs() <= 1e-5 * f1.max(1e-6), "{f1} {f2}");
        }
        let iso = GgxLobe {
            alpha_x: 0.2,
            alpha_y: 0.2,
        };
        let n = Vec3::Z;
        let f = iso.eval(n, n);
        assert!((f - 1.0 / (4.0 * PI * 0.04)).abs() < 1e-4 * f, "{f}");
    }

    /// The D of a unit area of surface projects to exactly that area: ∫ D(ĥ) cos θh dĥ = 1,
    /// by sampling ĥ uniformly over the hemisphere; and a perfect conductor's lobe reflects at
    /// most what arrives, and nearly all of it at normal incidence for a smooth lobe (the G1
    /// loss is small), estimated by sampling the lobe (which also checks `pdf` against
    /// `sample`: E[f cos / pdf] is the albedo only if they agree).
    #[test]
    fn distribution_is_normalised_and_albedo_is_at_most_one() {
        let mut s = Sampler::new(3, 0);
        for (ax, ay) in [(0.05, 0.05), (0.1, 0.3), (0.5, 0.5)] {
            let l = GgxLobe {
                alpha_x: ax,
                alpha_y: ay,
            };
            let n = 400_000;
            let mut area = 0.0f64;
            for i in 0..n {
                s.start_sample(i);
                let u = s.next_2d();
                let z = u.x;
                let r = (1.0 - z * z).max(0.0).sqrt();
                let h = Vec3::new(r * (2.0 * PI * u.y).cos(), r * (2.0 * PI * u.y).sin(), z);
                area += (l.distribution(h) * h.z) as f64 * 2.0 * std::f64::consts::PI;
            }
            let area = area / n as f64;
            assert!(
                (area - 1.0).abs() < 0.02,
                "α ({ax}, {ay}): ∫ D cos = {area}"
            );
            for theta_o in [0.0f32, 0.7, 1.3] {
                let wo = dir(theta_o, 0.3);
                let mut sum = 0.0f64;
                for i in 0..50_000 {
                    s.start_sample(i);
                    if let Some(wi) = l.sample(wo, s.next_2d()) {
                        sum += (l.eval(wo, wi) * wi.z / l.pdf(wo, wi)) as f64;
                    }
                }
                let albedo = sum / 50_000.0;
                assert!(albedo <= 1.0, "albedo {albedo} at θo {theta_o}");
                if theta_o == 0.0 && ax == 0.05 {
                    assert!(albedo > 0.97, "smooth lobe at normal incidence: {albedo}");
                }
            }
        }
    }

    /// The fitter's form from a half vector: the renderer's value for the isotropic lobe, and
    /// its derivative in ln α against central differences.
    #[test]
    fn the_fitters_form_is_the_lobe_and_its_derivative() {
        let pairs = [
            (dir(0.3, 0.2), dir(0.5, 2.9)),
            (dir(1.2, 0.0), dir(1.1, 3.0)),
            (dir(0.05, 1.0), dir(0.02, 4.0)),
            (dir(1.5, 0.5), dir(0.2, 3.3)),
            (dir(0.6, 0.1), dir(0.6, 0.1 + PI)),
        ];
        for (wo, wi) in pairs {
            for alpha in [0.02f32, 0.1, 0.4, 0.9] {
                let lobe = GgxLobe {
                    alpha_x: alpha,
                    alpha_y: alpha,
                };
                let hv = HalfVector::new(wo, wi);
                let (g, dg) = ggx_at(&hv, alpha);
                let f = lobe.eval(wo, wi);
                assert!((g - f).abs() <= 2e-3 * f + 1e-6, "α {alpha}: {g} vs {f}");
                let h = 1e-3f32;
                let num = (ggx_at(&hv, alpha * h.exp()).0 as f64
                    - ggx_at(&hv, alpha / h.exp()).0 as f64)
                    / (2.0 * h as f64);
                assert!(
                    (dg as f64 - num).abs() < 3e-3 * (g as f64) + 1e-6,
                    "α {alpha}: {dg} vs {num}"
                );
            }
        }
        // The eight-lane sums are the scalar sums.
        let samples: Vec<LobeSample> = (0..37)
            .map(|i| {
                let t = i as f32 * 0.37;
                LobeSample::new(
                    dir(0.1 + 0.03 * i as f32, t),
                    dir(0.9 - 0.02 * i as f32, t + 2.5),
                    Rgb::new(1.0, 0.5, 0.25) * (1.0 + t),
                )
            })
            .collect();
        let (s, ds) = ggx_sums(&samples, 0.17, true);
        let (mut s1, mut ds1) = (Rgb::ZERO, Rgb::ZERO);
        for x in &samples {
            let (g, dg) = ggx_at(&x.half, 0.17);
            s1 += x.c * g;
            ds1 += x.c * (2.0 * dg);
        }
        for ch in 0..3 {
            assert!(
                (s[ch] - s1[ch]).abs() <= 1e-4 * s1[ch].abs(),
                "{s:?} {s1:?}"
            );
            assert!((ds[ch] - ds1[ch]).abs() <= 1e-4 * ds1[ch].abs() + 1e-6);
        }
    }
}
