//! A rough plastic: a diffuse base under a rough dielectric coat, as Mitsuba 3's `roughplastic`
//! with `distribution = "ggx"` or `"beckmann"` (and `nonlinear = false`), which matfit exports it
//! as. With η the coat's relative index of refraction, F(η, cos) the unpolarised Fresnel
//! reflectance of a dielectric interface (Born & Wolf; total internal reflection where η < 1)
//! and the microfacet lobe D G1 G1 of `microfacet.rs` (GGX or Beckmann):
//!
//!   f = specular_reflectance · F(η, ωi·ĥ) D G1 G1 / (4 cosθi cosθo)
//!     + diffuse_reflectance / (1 − F_int) · t(cosθi) t(cosθo) / (π η²)
//!
//! where t(μ) is the light the rough coat lets through at incidence μ: over the normals ĥ it
//! shows (Heitz's visible normals), (1 − F(η, ωi·ĥ)) times the masking G1 of the refracted
//! direction (the light the coat's shadowing loses is neither reflected nor transmitted, so
//! t < 1 − R); and F_int = 2 ∫ R_{1/η}(μ) μ dμ, the coat's reflectance from inside averaged,
//! with R_η(μ) the directional albedo of its reflection (the first term's ∫ f cosθo dωo at
//! specular_reflectance 1). Mitsuba tabulates t at 64
//! cosines i/63 and interpolates linearly, and averages F_int over the same 64 cosines; matfit
//! does the same, with its own quadrature of R (a 128 × 64 midpoint grid in the lobe's sampling
//! variables, exact importance for D cos θh).
//!
//! The diffuse part falls off faster than the cosine towards grazing (t falls as the coat's
//! Fresnel reflection rises), and the specular part rises there: the shape of a coated surface
//! that neither Lambert nor a constant-ρs lobe has.
//!
//! matfit's parameters: ρd = diffuse_reflectance, and ρs = F0 · specular_reflectance with
//! F0 = F(η, 1), the coat's reflectance at normal incidence (so that ρs means what it means at
//! the other levels, and ρd + ρs ≤ 1 holds). The lobe per unit ρs is F(η, ωi·ĥ)/F0 · D G1 G1 /
//! (4 cosθi cosθo).

use super::microfacet::{Distribution, MicrofacetLobe, Pairs8};
use super::ward::{chunks8, LobeSample};
use crate::math::{Rgb, Vec3, PI};
use rayon::prelude::*;
use std::collections::HashMap;
use std::sync::{Mutex, OnceLock};
use wide::{f32x8, CmpGe, CmpGt, CmpLe};

pub use crate::scene::material::DEFAULT_ETA;

/// Entries of the transmittance table (Mitsuba's `MI_ROUGH_TRANSMITTANCE_RES`).
const RES: usize = 64;

/// Unpolarised Fresnel reflectance of a dielectric interface of relative index `eta` (inside
/// over outside) for light arriving from outside at cosine `cos_i` ≥ 0; 1 under total internal
/// reflection (η < 1).
pub fn fresnel_dielectric(cos_i: f32, eta: f32) -> f32 {
    let cos_i = cos_i.clamp(0.0, 1.0);
    let sin_t2 = (1.0 - cos_i * cos_i) / (eta * eta);
    if sin_t2 >= 1.0 {
        return 1.0;
    }
    let cos_t = (1.0 - sin_t2).sqrt();
    let a_s = (cos_i - eta * cos_t) / (cos_i + eta * cos_t);
    let a_p = (eta * cos_i - cos_t) / (eta * cos_i + cos_t);
    0.5 * (a_s * a_s + a_p * a_p)
}

/// A rough dielectric coat of roughness α (GGX or Beckmann) and index η, with its tables.
#[derive(Debug, PartialEq)]
pub struct Coat {
    pub lobe: MicrofacetLobe,
    pub eta: f32,
    /// F(η, 1).
    pub f0: f32,
    /// t(μ) at μ = i/63 (the first at 1e-6).
    transmittance: [f32; RES],
    /// 1 / (π η² (1 − F_int)): the diffuse part per unit ρd, but the two t's.
    diffuse_scale: f32,
}

impl Coat {
    fn new(alpha: f32, eta: f32, distribution: Distribution) -> Coat {
        let q = Quadrature::new(MicrofacetLobe {
            alpha_x: alpha,
            alpha_y: alpha,
            distribution,
        });
        let mu = |i: usize| (i as f32 / (RES - 1) as f32).max(1e-6);
        // Each table entry is its own integral, one task each (the sum keeps its order).
        let table = |f: &(dyn Fn(usize) -> f32 + Sync)| -> Vec<f32> {
            (0..RES).into_par_iter().map(f).collect()
        };
        let transmittance = table(&|i| q.transmitted(eta, mu(i)));
        let internal = 2.0
            * table(&|i| q.albedo(1.0 / eta, mu(i)) * mu(i))
                .iter()
                .sum::<f32>()
            / RES as f32;
        Coat {
            lobe: q.lobe,
            eta,
            f0: fresnel_dielectric(1.0, eta),
            transmittance: transmittance.try_into().expect("RES entries"),
            diffuse_scale: 1.0 / (PI * eta * eta * (1.0 - internal)),
        }
    }

    /// The coat of roughness `alpha`, index `eta` and `distribution`, computed once per triple
    /// and kept for the run (a BSDF is a plain value that refers to it; a level-9 fit makes one
    /// per trial α).
    pub fn get(alpha: f32, eta: f32, distribution: Distribution) -> &'static Coat {
        type Key = (u32, u32, Distribution);
        static COATS: OnceLock<Mutex<HashMap<Key, &'static Coat>>> = OnceLock::new();
        let coats = COATS.get_or_init(Default::default);
        let lock = || coats.lock().unwrap_or_else(|e| e.into_inner());
        let key = (alpha.to_bits(), eta.to_bits(), distribution);
        if let Some(&c) = lock().get(&key) {
            return c;
        }
        // Built unlocked: the build runs on the thread pool, whose tasks may want a coat too.
        // Two threads building the same coat build the same one; the first is kept.
        let coat = Coat::new(alpha, eta, distribution);
        lock()
            .entry(key)
            .or_insert_with(|| Box::leak(Box::new(coat)))
    }

    /// t(μ), linearly interpolated in the table as Mitsuba does.
    #[inline]
    pub fn transmittance(&self, mu: f32) -> f32 {
        let x = mu.clamp(0.0, 1.0) * (RES - 1) as f32;
        let i = (x as usize).min(RES - 2);
        let w = x - i as f32;
        (1.0 - w) * self.transmittance[i] + w * self.transmittance[i + 1]
    }

    /// [`Coat::transmittance`] on eight lanes, to the bit.
    #[inline(always)]
    fn transmittance8(&self, mu: f32x8) -> f32x8 {
        let x = (mu.max(f32x8::ZERO).min(f32x8::ONE) * f32x8::splat((RES - 1) as f32)).to_array();
        let (mut lo, mut hi, mut w) = ([0.0f32; 8], [0.0f32; 8], [0.0f32; 8]);
        for l in 0..8 {
            let i = (x[l] as usize).min(RES - 2);
            w[l] = x[l] - i as f32;
            (lo[l], hi[l]) = (self.transmittance[i], self.transmittance[i + 1]);
        }
        let w = f32x8::from(w);
        (f32x8::ONE - w) * f32x8::from(lo) + w * f32x8::from(hi)
    }

    /// The diffuse part per unit ρd (both directions above the surface).
    #[inline]
    pub fn diffuse(&self, cos_o: f32, cos_i: f32) -> f32 {
        self.transmittance(cos_o) * self.transmittance(cos_i) * self.diffuse_scale
    }

    /// The specular part per unit ρs: F(η, ωi·ĥ)/F0 times the microfacet lobe.
    #[inline]
    pub fn specular(&self, wo: Vec3, wi: Vec3) -> f32 {
        if wo.z <= 0.0 || wi.z <= 0.0 {
            return 0.0;
        }
        let h = (wi + wo).normalize();
        fresnel_dielectric(wi.dot(h), self.eta) / self.f0 * self.lobe.eval(wo, wi)
    }
}

/// Per unit ρs and ρd, Σ c·(specular part) and Σ c·(diffuse part) over cached direction pairs
/// (`ward::LobeSample`): what the fitter's objective needs for a trial coat. The pairs' cosines
/// come from their half vectors (`microfacet::cosines`). Eight pairs at a time, the last eight
/// padded with empty ones: each lane is its pair's terms as [`Coat::specular`] and
/// [`Coat::diffuse`] give them to rounding (the cosines, F, the lobe and t to the bit), but the
/// totals are summed in another order than one pair at a time.
pub fn plastic_sums(samples: &[LobeSample], coat: &Coat) -> (Rgb, Rgb) {
    let splat = f32x8::splat;
    let (mut s, mut d) = ([f32x8::ZERO; 3], [f32x8::ZERO; 3]);
    let (f0, scale) = (splat(coat.f0), splat(coat.diffuse_scale));
    let lobe = &coat.lobe;
    let add = |chunk: &[LobeSample; 8]| {
        let q = Pairs8::of(chunk);
        let spec = fresnel_dielectric8(q.cos_d, coat.eta) / f0
            * q.isotropic(lobe.alpha_x, lobe.distribution);
        let diff = q.valid.blend(
            coat.transmittance8(q.big) * coat.transmittance8(q.small) * scale,
            f32x8::ZERO,
        );
        for ch in 0..3 {
            s[ch] += q.c[ch] * spec;
            d[ch] += q.c[ch] * diff;
        }
    };
    chunks8(samples, add);
    let sum = |v: &[f32x8; 3]| Rgb::from_array(v.map(|x| x.reduce_add()));
    (sum(&s), sum(&d))
}

/// [`fresnel_dielectric`] on eight lanes, to the bit.
#[inline(always)]
fn fresnel_dielectric8(cos_i: f32x8, eta: f32) -> f32x8 {
    let (zero, one) = (f32x8::ZERO, f32x8::ONE);
    let e = f32x8::splat(eta);
    let cos_i = cos_i.max(zero).min(one);
    let sin_t2 = (one - cos_i * cos_i) / (e * e);
    let cos_t = (one - sin_t2).max(zero).sqrt();
    let a_s = (cos_i - e * cos_t) / (cos_i + e * cos_t);
    let a_p = (e * cos_i - cos_t) / (e * cos_i + cos_t);
    let f = f32x8::splat(0.5) * (a_s * a_s + a_p * a_p);
    sin_t2.cmp_ge(one).blend(one, f)
}

/// The quadrature of the coat's integrals: a 128 × 64 midpoint grid of the lobe's sampling
/// variables (`MicrofacetLobe::sample`), ĥ distributed as D cos θh. The normals do not depend
/// on the incidence, so they are computed once per coat rather than once per table entry.
/// ωi lies in the xz-plane and the lobe is isotropic, so the normals at azimuths φ and −φ give
/// the same term: only the half grid with sin φ > 0 is kept, each normal counting twice.
struct Quadrature {
    lobe: MicrofacetLobe,
    /// The normals ĥ, eight per entry, as lanes of x, y and z.
    normals: Vec<[f32x8; 3]>,
}

/// Three lanes of vectors: x, y and z.
type V8 = [f32x8; 3];

impl Quadrature {
    fn new(lobe: MicrofacetLobe) -> Quadrature {
        debug_assert_eq!(
            lobe.alpha_x, lobe.alpha_y,
            "the half grid needs an isotropic lobe"
        );
        let (n1, n2) = (128, 64);
        let a = lobe.alpha_x;
        let mut normals = Vec::with_capacity(n1 * n2 / 2);
        for i in 0..n1 {
            let u1 = (i as f32 + 0.5) / n1 as f32;
            let r = a * lobe.slope_radius(u1);
            for j in 0..n2 / 2 {
                let (s, c) = (2.0 * PI * (j as f32 + 0.5) / n2 as f32).sin_cos();
                normals.push(Vec3::new(r * c, r * s, 1.0).normalize());
            }
        }
        let normals = normals
            .chunks_exact(8)
            .map(|h| [0, 1, 2].map(|k| f32x8::from(std::array::from_fn(|l| h[l][k]))))
            .collect();
        Quadrature { lobe, normals }
    }

    /// G1 of eight directions ([`MicrofacetLobe::g1`] on lanes, to the bit).
    #[inline(always)]
    fn g1(&self, w: &V8) -> f32x8 {
        let (a, b) = (
            f32x8::splat(self.lobe.alpha_x) * w[0],
            f32x8::splat(self.lobe.alpha_y) * w[1],
        );
        let t = (a * a + b * b) / (w[2] * w[2]);
        match self.lobe.distribution {
            Distribution::Ggx => f32x8::splat(2.0) / (f32x8::ONE + (f32x8::ONE + t).sqrt()),
            Distribution::Beckmann => super::microfacet::beckmann_g1_8(t),
        }
    }

    /// The mean of `term(ωi, ĥ, ωi·ĥ, G1(ωi))` over the grid, ωi at incidence μ, eight normals
    /// at a time; terms where ωi·ĥ ≤ 0 are 0. Each term is the scalar formula's to the bit, and
    /// the terms are summed in the grid's order, so the tables do not depend on the lanes.
    fn mean(&self, mu: f32, term: impl Fn(&V8, &V8, f32x8, f32x8) -> f32x8) -> f32 {
        let wi = Vec3::new((1.0 - mu * mu).max(0.0).sqrt(), 0.0, mu);
        let wi8 = [wi.x, wi.y, wi.z].map(f32x8::splat);
        let g1_wi = self.g1(&wi8);
        let mut sum = 0.0f64;
        for h in &self.normals {
            // glam's dot: (x·x' + y·y') + z·z'.
            let d = wi8[0] * h[0] + wi8[1] * h[1] + wi8[2] * h[2];
            let t = d
                .cmp_gt(f32x8::ZERO)
                .blend(term(&wi8, h, d, g1_wi), f32x8::ZERO);
            for v in t.to_array() {
                sum += v as f64;
            }
        }
        (sum / (8 * self.normals.len()) as f64) as f32
    }

    /// t(μ) of the module comment: with ĥ drawn from D cos θh, the visible normals' density
    /// is G1(ωi) (ωi·ĥ) D / μ, so t = E[(1 − F) G1(ωt) G1(ωi) (ωi·ĥ) / (μ cos θh)], ωt the
    /// refraction of ωi through ĥ (into the coat, 1/η).
    fn transmitted(&self, eta: f32, mu: f32) -> f32 {
        let splat = f32x8::splat;
        self.mean(mu, |wi, h, d, g1_wi| {
            let f = fresnel_dielectric8(d, eta);
            let inv = splat(1.0 / eta);
            let cos_t = (f32x8::ONE - inv * inv * (f32x8::ONE - d * d))
                .max(f32x8::ZERO)
                .sqrt();
            let k = d * inv - cos_t;
            let wt = [0, 1, 2].map(|c| h[c] * k - wi[c] * inv);
            let t = (f32x8::ONE - f) * self.g1(&wt) * g1_wi * d / (splat(mu) * h[2]);
            f.cmp_ge(f32x8::ONE).blend(f32x8::ZERO, t)
        })
    }

    /// R_η(μ): the directional albedo of the coat's reflection at incidence μ (specular
    /// reflectance 1). With ĥ drawn from D cos θh (pdf_h), ωo its reflection,
    /// dωo = 4 (ωo·ĥ) dωh: R = E[F G1(ωi) G1(ωo) (ωi·ĥ) / (μ cos θh)].
    fn albedo(&self, eta: f32, mu: f32) -> f32 {
        self.mean(mu, |wi, h, d, g1_wi| {
            let k = f32x8::splat(2.0) * d;
            let wo = [0, 1, 2].map(|c| k * h[c] - wi[c]);
            let r =
                fresnel_dielectric8(d, eta) * g1_wi * self.g1(&wo) * d / (f32x8::splat(mu) * h[2]);
            wo[2].cmp_le(f32x8::ZERO).blend(f32x8::ZERO, r)
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::Sampler;

    /// Fresnel at normal incidence is ((η − 1)/(η + 1))², 1 at grazing, total internal
    /// reflection beyond the critical angle from inside.
    #[test]
    fn fresnel_limits() {
        let f0 = fresnel_dielectric(1.0, 1.5);
        assert!((f0 - 0.04).abs() < 1e-6, "{f0}");
        assert!(fresnel_dielectric(1e-4, 1.5) > 0.99);
        let critical = (1.0f32 - 1.0 / 1.5f32.powi(2)).sqrt(); // cos of asin(1/1.5)
        assert_eq!(fresnel_dielectric(critical - 1e-3, 1.0 / 1.5), 1.0);
        assert!(fresnel_dielectric(critical + 1e-2, 1.0 / 1.5) < 1.0);
    }

    /// The eight-lane sums are the sums of [`Coat::specular`] and [`Coat::diffuse`] over the
    /// pairs' own directions (computed from ωo and ωi, not from the cached half vectors), for
    /// both distributions, a smooth and a rough coat, grazing pairs and pairs below the surface
    /// (which count zero), and a count of pairs not a multiple of eight.
    #[test]
    fn lane_sums_are_the_coats_terms_summed() {
        let mut s = Sampler::new(11, 0);
        let mut pairs = Vec::new();
        for k in 0..1003 {
            s.start_sample(k);
            let [a, b, c, d, r, g, bl] = s.next_n::<7>();
            let dir = |u: f32, v: f32, lift: f32| {
                let z = (u * 1.1 - lift).clamp(-1.0, 1.0);
                let rxy = (1.0 - z * z).max(0.0).sqrt();
                let phi = 2.0 * PI * v;
                Vec3::new(rxy * phi.cos(), rxy * phi.sin(), z)
            };
            // About one pair in twenty has a direction below the surface.
            pairs.push((dir(a, b, 0.05), dir(c, d, 0.05), Rgb::new(r, g, bl)));
        }
        for distribution in [Distribution::Ggx, Distribution::Beckmann] {
            for alpha in [0.03f32, 0.3] {
                let coat = Coat::get(alpha, DEFAULT_ETA, distribution);
                let samples: Vec<LobeSample> = pairs
                    .iter()
                    .map(|&(wo, wi, c)| LobeSample::new(wo, wi, c))
                    .collect();
                let (spec, diff) = plastic_sums(&samples, coat);
                let (mut want_s, mut want_d) = (Rgb::ZERO, Rgb::ZERO);
                for &(wo, wi, c) in &pairs {
                    if wo.z > 0.0 && wi.z > 0.0 {
                        want_s += c * coat.specular(wo, wi);
                        want_d += c * coat.diffuse(wo.z, wi.z);
                    }
                }
                let close = |a: Rgb, b: Rgb| ((a - b).abs() / b.abs()).max_element() < 2e-4;
                let case = format!("{distribution:?} α {alpha}");
                assert!(close(spec, want_s), "{case}: {spec:?} vs {want_s:?}");
                assert!(close(diff, want_d), "{case}: {diff:?} vs {want_d:?}");
                assert!(
                    want_s.min_element() > 0.0 && want_d.min_element() > 0.0,
                    "{case}"
                );
            }
        }
    }

    /// The coat's tables against brute force: the albedo R by sampling the coat's own lobe
    /// (an independent estimate of the same integral), energy conservation of the whole BSDF
    /// (diffuse reflectance 1 under the coat reflects at most what arrives), and the smooth
    /// limit: a nearly smooth coat transmits 1 − F(η, μ).
    #[test]
    fn tables_match_brute_force_and_conserve_energy() {
        let eta = DEFAULT_ETA;
        let cases = [Distribution::Ggx, Distribution::Beckmann]
            .into_iter()
            .flat_map(|d| [0.05f32, 0.2, 0.5].map(|a| (a, d)));
        for (alpha, distribution) in cases {
            let coat = Coat::get(alpha, eta, distribution);
            let mut s = Sampler::new(5, 0);
            for mu in [0.2f32, 0.5, 0.9] {
                let wo = Vec3::new((1.0 - mu * mu).sqrt(), 0.0, mu);
                let (n, mut r, mut all) = (200_000, 0.0f64, 0.0f64);
                for k in 0..n {
                    s.start_sample(k);
                    let u = s.next_2d();
                    // Cosine sampling: f cos / pdf = π f.
                    let wi = crate::math::warp::cosine_hemisphere(u);
                    let spec = coat.specular(wo, wi) * coat.f0;
                    r += (PI * spec) as f64;
                    all += (PI * (spec + coat.diffuse(wo.z, wi.z))) as f64;
                }
                let (r, all) = (r / n as f64, all / n as f64);
                let t = coat.transmittance(mu) as f64;
                let table_r = Quadrature::new(coat.lobe).albedo(eta, mu) as f64;
                assert!(
                    (table_r - r).abs() < 0.01,
                    "{distribution:?} α {alpha} μ {mu}: quadrature R {table_r} vs sampled {r}"
                );
                // What the coat's masking loses is neither reflected nor transmitted.
                assert!(
                    t + r <= 1.0 + 0.01 && t + r > 0.6,
                    "{distribution:?} α {alpha} μ {mu}: t {t} R {r}"
                );
                assert!(all < 1.0 + 0.01, "{distribution:?} α {alpha} μ {mu}: {all}");
            }
        }
        let smooth = Coat::get(0.005, eta, Distribution::Ggx);
        for mu in [0.3f32, 0.7, 1.0] {
            let t = smooth.transmittance(mu);
            let want = 1.0 - fresnel_dielectric(mu, eta);
            assert!((t - want).abs() < 0.01, "μ {mu}: {t} vs {want}");
        }
        let ggx = Coat::get(0.2, eta, Distribution::Ggx);
        assert!(std::ptr::eq(ggx, Coat::get(0.2, eta, Distribution::Ggx)));
        assert!(!std::ptr::eq(
            ggx,
            Coat::get(0.2, eta, Distribution::Beckmann)
        ));
    }
}
