//! The microfacet lobe of a rough perfect conductor: Mitsuba 3's `roughconductor` with
//! `material = "none"` (Fresnel F = 1) and `distribution = "ggx"` or `"beckmann"`, which matfit
//! exports it as, value for value. In the local frame (normal +z, tangent +x rotated by the
//! material's θ), with ĥ the normalised half vector of ωi and ωo, (u, v) = (ĥx, ĥy)/ĥz its
//! slopes and A = u²/αx² + v²/αy²:
//!
//!   f_s = ρs · D(ĥ) G1(ωi) G1(ωo) / (4 cosθi cosθo)
//!   GGX:      D = 1 / (π αx αy cos⁴θh (1 + A)²)           (Walter et al. 2007, eq. 33;
//!                                                          anisotropic: Heitz 2014, eq. 85)
//!             G1(ω) = 2 / (1 + √(1 + t)),                  (Smith, Heitz 2014 eq. 86)
//!   Beckmann: D = exp(−A) / (π αx αy cos⁴θh)               (Walter et al. 2007, eq. 25)
//!             G1(ω) = (3.535a + 2.181a²) / (1 + 2.276a + 2.577a²) for a = 1/√t < 1.6, else 1
//!                                                          (Walter et al. 2007, eq. 27)
//!   with t = (αx² ωx² + αy² ωy²) / ωz²,
//!
//! and Mitsuba's separable masking-shadowing G1(ωi) G1(ωo) (not the height-correlated form).
//! GGX's D falls off as a power of the half-vector slope: a sharp core with a wide halo, the
//! shape of most measured glossy surfaces (Walter et al. 2007, §5.2); Beckmann's is Ward's
//! Gaussian (exp through `math::exp_neg_poly`, as Ward's).
//!
//! Sampling draws ĥ from D(ĥ) cos θh: its slopes are (αx, αy) · r · (cos 2πu2, sin 2πu2) with
//! r = √(u1/(1 − u1)) for GGX and √(−ln(1 − u1)) for Beckmann (Walter et al. 2007, eq. 28–29,
//! 35–36), and p(ωi) = D cos θh / (4 |ωo·ĥ|).
//!
//! All values are per unit ρs, as the Ward lobe's: the caller multiplies by ρs. The fitter
//! evaluates the isotropic lobe from the cache's precomputed half vectors with its derivative
//! in ln α ([`ggx_at`], [`ggx_sums`]).

use super::ward::lanes::row;
use super::ward::{chunks8, lanes8, HalfVector, LobeSample};
use crate::math::{exp_neg_poly, exp_neg_poly8, Rgb, Vec2, Vec3, PI};
pub use crate::scene::Distribution;
use wide::{f32x8, CmpGe, CmpGt};

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MicrofacetLobe {
    pub alpha_x: f32,
    pub alpha_y: f32,
    pub distribution: Distribution,
}

/// Beckmann's G1 of the module comment from t: Walter et al.'s rational fit of Smith's
/// integral, in a = 1/√t.
#[inline]
fn beckmann_g1(t: f32) -> f32 {
    let a = 1.0 / t.sqrt();
    if a >= 1.6 {
        1.0
    } else {
        (3.535 * a + 2.181 * a * a) / (1.0 + 2.276 * a + 2.577 * a * a)
    }
}

impl MicrofacetLobe {
    /// A GGX lobe (the coat of `plastic.rs`, and tests).
    pub fn ggx(alpha_x: f32, alpha_y: f32) -> MicrofacetLobe {
        MicrofacetLobe {
            alpha_x,
            alpha_y,
            distribution: Distribution::Ggx,
        }
    }

    /// D(ĥ) for a unit half vector in the upper hemisphere.
    #[inline]
    fn distribution(&self, h: Vec3) -> f32 {
        if h.z <= 0.0 {
            return 0.0;
        }
        let (a, b) = (h.x / self.alpha_x, h.y / self.alpha_y);
        match self.distribution {
            Distribution::Ggx => {
                let t = a * a + b * b + h.z * h.z;
                1.0 / (PI * self.alpha_x * self.alpha_y * t * t)
            }
            Distribution::Beckmann => {
                let z2 = h.z * h.z;
                exp_neg_poly((a * a + b * b) / z2) / (PI * self.alpha_x * self.alpha_y * z2 * z2)
            }
        }
    }

    /// Smith's G1 of a direction above the surface (and above the microfacet, which a half
    /// vector of two directions above the surface always is).
    #[inline]
    pub(crate) fn g1(&self, w: Vec3) -> f32 {
        let (a, b) = (self.alpha_x * w.x, self.alpha_y * w.y);
        let t = (a * a + b * b) / (w.z * w.z);
        match self.distribution {
            Distribution::Ggx => 2.0 / (1.0 + (1.0 + t).sqrt()),
            Distribution::Beckmann => beckmann_g1(t),
        }
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

    /// Density (per solid angle of ωi) of [`MicrofacetLobe::sample`].
    #[inline]
    pub fn pdf(&self, wo: Vec3, wi: Vec3) -> f32 {
        if wo.z <= 0.0 || wi.z <= 0.0 {
            return 0.0;
        }
        let h = (wi + wo).normalize();
        self.distribution(h) * h.z / (4.0 * wo.dot(h).abs())
    }

    /// The half vector's slope over α drawn from D cos θh at `u1` in [0, 1) (module comment).
    #[inline]
    pub(crate) fn slope_radius(&self, u1: f32) -> f32 {
        match self.distribution {
            Distribution::Ggx => (u1 / (1.0 - u1)).sqrt(),
            Distribution::Beckmann => (-(1.0 - u1).ln()).sqrt(),
        }
    }

    /// Draws ωi by sampling the half vector; None when the reflected direction is below the
    /// surface (the sample is then lost, which `pdf` accounts for by not renormalising).
    #[inline]
    pub fn sample(&self, wo: Vec3, u: Vec2) -> Option<Vec3> {
        let r = self.slope_radius(u.x.min(1.0 - f32::EPSILON));
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

/// Eight cached pairs' [`Pair`] and [`cosines`] on lanes, each lane its pair's values to the
/// bit (the same operations in the same order): what the isotropic lobe, the coat
/// (`plastic_sums`) and the anisotropic lobe ([`aniso_sums`]) recover from a half vector. `valid` marks the pairs above the surface; the
/// others get harmless values (no NaN), which the caller masks.
pub(super) struct Pairs8 {
    pub valid: f32x8,
    /// The half vector's tangential components, 1/hz² and the cosines' product P.
    pub hx: f32x8,
    pub hy: f32x8,
    pub inv_hz2: f32x8,
    pub p: f32x8,
    /// The larger and the smaller cosine, and cos θd = ωi·ĥ.
    pub big: f32x8,
    pub small: f32x8,
    pub cos_d: f32x8,
    pub tan2_h: f32x8,
    pub tan2_i: f32x8,
    pub tan2_o: f32x8,
    pub inv_4cc: f32x8,
    /// c, per channel.
    pub c: [f32x8; 3],
}

impl Pairs8 {
    #[inline(always)]
    pub(super) fn of(chunk: &[LobeSample; 8]) -> Pairs8 {
        let splat = f32x8::splat;
        let (zero, one) = (f32x8::ZERO, f32x8::ONE);
        let r = lanes8(chunk);
        let (hx, hy) = (r[row::HX], r[row::HY]);
        let valid = r[row::NORM].cmp_gt(zero);
        let n = valid.blend(r[row::NORM], splat(0.1));
        let inv_hz2 = valid.blend(r[row::INV_HZ2], one);
        let hz2 = one / inv_hz2;
        let k = splat(4.0 * PI) * n;
        let p = one / (k * k);
        let big = splat(0.5) * (hz2.sqrt() + (hz2 - splat(4.0) * p).max(zero).sqrt());
        let small = p / big;
        let tan2 = |c: f32x8| (one - c * c).max(zero) / (c * c);
        let t2 = hx * hx + hy * hy;
        Pairs8 {
            valid,
            hx,
            hy,
            inv_hz2,
            p,
            big,
            small,
            cos_d: splat(0.5) * (t2 + hz2).sqrt(),
            tan2_h: t2 * inv_hz2,
            tan2_i: tan2(big),
            tan2_o: tan2(small),
            inv_4cc: splat(0.25) / p,
            c: [r[row::C], r[row::C + 1], r[row::C + 2]],
        }
    }

    /// [`isotropic_at`] on the eight pairs (zero where not valid).
    #[inline(always)]
    pub(super) fn isotropic(&self, alpha: f32, distribution: Distribution) -> f32x8 {
        let splat = f32x8::splat;
        let (one, two) = (f32x8::ONE, splat(2.0));
        let a2 = splat(alpha * alpha);
        let one_t = one + self.tan2_h;
        let g = match distribution {
            Distribution::Ggx => {
                let d_den = a2 + self.tan2_h;
                let d = a2 * one_t * one_t / (splat(PI) * d_den * d_den);
                let si = (one + a2 * self.tan2_i).sqrt();
                let so = (one + a2 * self.tan2_o).sqrt();
                d * (two / (one + si)) * (two / (one + so)) * self.inv_4cc
            }
            Distribution::Beckmann => {
                let d = exp_neg_poly8(self.tan2_h / a2) * one_t * one_t / (splat(PI) * a2);
                d * beckmann_g1_8(a2 * self.tan2_i) * beckmann_g1_8(a2 * self.tan2_o) * self.inv_4cc
            }
        };
        self.valid.blend(g, f32x8::ZERO)
    }
}

/// [`beckmann_g1`] on eight lanes, to the bit.
#[inline(always)]
pub(super) fn beckmann_g1_8(t: f32x8) -> f32x8 {
    let splat = f32x8::splat;
    let a = f32x8::ONE / t.sqrt();
    let g = (splat(3.535) * a + splat(2.181) * a * a)
        / (f32x8::ONE + splat(2.276) * a + splat(2.577) * a * a);
    a.cmp_ge(splat(1.6)).blend(f32x8::ONE, g)
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

/// The isotropic lobe per unit ρs at a cached pair, value only, of either distribution (the
/// plastic coat's lobe, `plastic::plastic_sums`). Beckmann's D of the module comment with
/// t = tan²θh and 1/cos⁴θh = (1 + t)²: D = exp(−t/α²) (1 + t)² / (π α²).
#[inline]
pub fn isotropic_at(hv: &HalfVector, alpha: f32, distribution: Distribution) -> f32 {
    match distribution {
        Distribution::Ggx => ggx_at(hv, alpha).0,
        Distribution::Beckmann => {
            let Some(q) = Pair::of(hv) else {
                return 0.0;
            };
            let a2 = alpha * alpha;
            let one_t = 1.0 + q.tan2_h;
            let d = exp_neg_poly(q.tan2_h / a2) * one_t * one_t / (PI * a2);
            d * beckmann_g1(a2 * q.tan2_i) * beckmann_g1(a2 * q.tan2_o) * q.inv_4cc
        }
    }
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

/// An anisotropic lobe's parameters as [`aniso_sums`] takes them (θ in radians, the tangent's
/// rotation, as the renderer's `frame.rotated(θ)`).
#[derive(Clone, Copy, Debug)]
pub struct AnisoParams {
    pub alpha_x: f32,
    pub alpha_y: f32,
    pub theta: f32,
    pub distribution: Distribution,
}

/// Σ c·g over `samples` and, if asked, Σ c·2∂g/∂k for k = ln αx, ln αy, θ (zero otherwise), for
/// the lobe of the module comment (either distribution, any anisotropy), eight samples at a
/// time (the rest padded with empty samples). Each pair's directions come from its half vector
/// h and d = ωi − ωo (their tangential parts are (h ± d)/2; the two cosines are [`Pair`]'s
/// roots, the larger one belonging to the direction with the smaller tangential part). Rotated
/// by −θ, with the slopes (u, v) of ĥ and (pu, pv) of each direction, A = u²/αx² + v²/αy² and
/// t = αx² pu² + αy² pv² (∂u/∂θ = v, ∂v/∂θ = −u; the αy rows as the αx ones):
///   ∂A/∂ln αx = −2u²/αx²,   ∂A/∂θ = 2uv (1/αx² − 1/αy²),
///   ∂t/∂ln αx = 2 αx² pu²,  ∂t/∂θ = 2 pu pv (αx² − αy²),
///   GGX:      ∂ln D = −∂ln(αx αy) − 2 ∂A/(1 + A),   ∂ln G1/∂t = −1 / (2s (1 + s)), s = √(1 + t);
///   Beckmann: ∂ln D = −∂ln(αx αy) − ∂A,
///             ∂ln G1/∂t = −(1/2t) [(3.535 + 4.362a)/(3.535 + 2.181a)
///                                  − (2.276a + 5.154a²)/(1 + 2.276a + 2.577a²)] for a < 1.6.
pub fn aniso_sums(samples: &[LobeSample], p: &AnisoParams, derivatives: bool) -> (Rgb, [Rgb; 3]) {
    let splat = f32x8::splat;
    let (one, two, zero) = (f32x8::ONE, splat(2.0), f32x8::ZERO);
    let (sin_t, cos_t) = p.theta.sin_cos();
    let (st, ct) = (splat(sin_t), splat(cos_t));
    let (ax2, ay2) = (p.alpha_x * p.alpha_x, p.alpha_y * p.alpha_y);
    let (ax2v, ay2v) = (splat(ax2), splat(ay2));
    let (iax2, iay2) = (splat(1.0 / ax2), splat(1.0 / ay2));
    let d_norm = splat(1.0 / (PI * p.alpha_x * p.alpha_y));
    let beckmann = p.distribution == Distribution::Beckmann;
    let mut s = [zero; 3];
    let mut ds = [[zero; 3]; 3];
    let add = |chunk: &[LobeSample; 8]| {
        // Empty lanes get harmless values, and their c is zero or they are masked below.
        let q = Pairs8::of(chunk);
        let (hx, hy, inv_hz2, prod, c) = (q.hx, q.hy, q.inv_hz2, q.p, q.c);
        let (valid, big, small) = (q.valid, q.big, q.small);
        let tangent = |k: usize| f32x8::from(std::array::from_fn::<f32, 8, _>(|i| chunk[i].d[k]));
        let (dx, dy) = (tangent(0), tangent(1));
        let (ix, iy) = (splat(0.5) * (hx + dx), splat(0.5) * (hy + dy));
        let (ox, oy) = (splat(0.5) * (hx - dx), splat(0.5) * (hy - dy));
        let i_grazer = (ix * ix + iy * iy).cmp_gt(ox * ox + oy * oy);
        let ci = i_grazer.blend(small, big);
        let co = i_grazer.blend(big, small);
        let rot = |x: f32x8, y: f32x8| (x * ct + y * st, y * ct - x * st);
        let inv_hz = inv_hz2.sqrt();
        let (hu, hv) = rot(hx * inv_hz, hy * inv_hz);
        let (u2, v2) = (hu * hu, hv * hv);
        let a = u2 * iax2 + v2 * iay2;
        let one_t = one + u2 + v2;
        // D, and ∂ln D/∂A.
        let (d, dd_da) = if beckmann {
            (d_norm * one_t * one_t * exp_neg_poly8(a), -one)
        } else {
            let one_a = one + a;
            (d_norm * one_t * one_t / (one_a * one_a), -two / one_a)
        };
        // G1 of a direction, its slopes, and ∂ln G1/∂t.
        let masking = |x: f32x8, y: f32x8, c: f32x8| {
            let (pu, pv) = rot(x / c, y / c);
            let t = ax2v * pu * pu + ay2v * pv * pv;
            if beckmann {
                let r = one / t.sqrt();
                let num = splat(3.535) * r + splat(2.181) * r * r;
                let den = one + splat(2.276) * r + splat(2.577) * r * r;
                let dln_dr = (splat(3.535) + splat(4.362) * r) / (splat(3.535) + splat(2.181) * r)
                    - (splat(2.276) * r + splat(5.154) * r * r) / den;
                let smooth = r.cmp_ge(splat(1.6));
                let g = smooth.blend(one, num / den);
                let dg = smooth.blend(zero, -dln_dr / (two * t));
                (g, pu, pv, dg)
            } else {
                let sq = (one + t).sqrt();
                (two / (one + sq), pu, pv, -one / (two * sq * (one + sq)))
            }
        };
        let (gi, piu, piv, dgi) = masking(ix, iy, ci);
        let (go, pou, pov, dgo) = masking(ox, oy, co);
        let g = valid.blend(d * gi * go * splat(0.25) / prod, zero);
        for ch in 0..3 {
            s[ch] += c[ch] * g;
        }
        if derivatives {
            let dln = [
                dd_da * splat(-2.0) * u2 * iax2 - one
                    + dgi * two * ax2v * piu * piu
                    + dgo * two * ax2v * pou * pou,
                dd_da * splat(-2.0) * v2 * iay2 - one
                    + dgi * two * ay2v * piv * piv
                    + dgo * two * ay2v * pov * pov,
                dd_da * two * hu * hv * (iax2 - iay2)
                    + (dgi * piu * piv + dgo * pou * pov) * two * (ax2v - ay2v),
            ];
            for (k, dl) in dln.iter().enumerate() {
                let w = two * g * *dl;
                for ch in 0..3 {
                    ds[k][ch] += c[ch] * w;
                }
            }
        }
    };
    chunks8(samples, add);
    let sum = |v: &[f32x8; 3]| Rgb::from_array(v.map(|x| x.reduce_add()));
    (sum(&s), ds.each_ref().map(sum))
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
        let l = MicrofacetLobe::ggx(0.13, 0.31);
        for (a, b) in [(0.3, 0.1), (1.2, 2.0), (0.7, -1.0), (1.5, 0.4)] {
            let (wo, wi) = (dir(a, b), dir(b.abs() * 0.5, a));
            let (f1, f2) = (l.eval(wo, wi), l.eval(wi, wo));
            assert!((f1 - f2).abs() <= 1e-5 * f1.max(1e-6), "{f1} {f2}");
        }
        let iso = MicrofacetLobe::ggx(0.2, 0.2);
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
        let shapes = [(0.05, 0.05), (0.1, 0.3), (0.5, 0.5)];
        let lobes = [Distribution::Ggx, Distribution::Beckmann].map(|distribution| {
            shapes.map(|(alpha_x, alpha_y)| MicrofacetLobe {
                alpha_x,
                alpha_y,
                distribution,
            })
        });
        for l in lobes.into_iter().flatten() {
            let (ax, ay) = (l.alpha_x, l.alpha_y);
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
                assert!(albedo <= 1.0 + 1e-6, "albedo {albedo} at θo {theta_o}");
                if theta_o == 0.0 && ax == 0.05 {
                    assert!(albedo > 0.97, "smooth lobe at normal incidence: {albedo}");
                }
            }
        }
    }

    /// The fitter's form from a half vector: the renderer's value for the isotropic lobe (GGX
    /// and Beckmann), and GGX's derivative in ln α against central differences.
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
                let lobe = MicrofacetLobe::ggx(alpha, alpha);
                let hv = HalfVector::new(wo, wi);
                let (g, dg) = ggx_at(&hv, alpha);
                let f = lobe.eval(wo, wi);
                assert!((g - f).abs() <= 2e-3 * f + 1e-6, "α {alpha}: {g} vs {f}");
                let beckmann = MicrofacetLobe {
                    distribution: Distribution::Beckmann,
                    ..lobe
                };
                let (b, fb) = (
                    isotropic_at(&hv, alpha, Distribution::Beckmann),
                    beckmann.eval(wo, wi),
                );
                assert!((b - fb).abs() <= 2e-3 * fb + 1e-6, "α {alpha}: {b} vs {fb}");
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

    /// The anisotropic sums are the renderer's lobe in the frame rotated by θ, pair by pair
    /// (each pair alone, so that the padding of a short chunk is exercised too), and their
    /// derivatives are central differences of the sums.
    #[test]
    fn aniso_sums_are_the_rotated_lobe_and_its_derivatives() {
        let pairs = [
            (dir(0.3, 0.2), dir(0.5, 2.9)),
            (dir(1.2, 0.0), dir(1.1, 3.0)),
            (dir(0.05, 1.0), dir(0.02, 4.0)),
            (dir(1.5, 0.5), dir(0.2, 3.3)),
            (dir(0.2, 0.5), dir(1.4, 2.1)),
            (dir(0.6, 0.1), dir(0.6, 0.1 + PI)),
            (dir(0.9, 1.9), dir(0.3, -1.0)),
        ];
        let shapes = [(0.1f32, 0.3f32, 0.0f32), (0.3, 0.07, 0.6), (0.2, 0.2, -1.1)];
        for distribution in [Distribution::Ggx, Distribution::Beckmann] {
            for (ax, ay, theta) in shapes {
                check_aniso(&pairs, ax, ay, theta, distribution);
            }
        }
    }

    fn check_aniso(
        pairs: &[(Vec3, Vec3)],
        ax: f32,
        ay: f32,
        theta: f32,
        distribution: Distribution,
    ) {
        {
            let p = AnisoParams {
                alpha_x: ax,
                alpha_y: ay,
                theta,
                distribution,
            };
            let lobe = MicrofacetLobe {
                alpha_x: ax,
                alpha_y: ay,
                distribution,
            };
            let (st, ct) = theta.sin_cos();
            let rot = |w: Vec3| Vec3::new(w.x * ct + w.y * st, w.y * ct - w.x * st, w.z);
            let mut all = Vec::new();
            for (k, &(wo, wi)) in pairs.iter().enumerate() {
                let c = Rgb::new(1.0, 0.5, 0.25) * (1.0 + k as f32);
                let smp = LobeSample::new(wo, wi, c);
                all.push(smp);
                let f = lobe.eval(rot(wo), rot(wi));
                let (g, dg) = aniso_sums(&[smp], &p, true);
                assert!(
                    (g.x - f * c.x).abs() <= 2e-3 * f * c.x + 1e-6,
                    "{distribution:?} α ({ax}, {ay}) θ {theta}: {} vs {}",
                    g.x,
                    f * c.x
                );
                let h = 1e-3f32;
                let at = |q: AnisoParams| aniso_sums(&[smp], &q, false).0.x as f64;
                let steps = [
                    (
                        AnisoParams {
                            alpha_x: ax * h.exp(),
                            ..p
                        },
                        AnisoParams {
                            alpha_x: ax / h.exp(),
                            ..p
                        },
                    ),
                    (
                        AnisoParams {
                            alpha_y: ay * h.exp(),
                            ..p
                        },
                        AnisoParams {
                            alpha_y: ay / h.exp(),
                            ..p
                        },
                    ),
                    (
                        AnisoParams {
                            theta: theta + h,
                            ..p
                        },
                        AnisoParams {
                            theta: theta - h,
                            ..p
                        },
                    ),
                ];
                for (j, (up, down)) in steps.into_iter().enumerate() {
                    // The sums carry 2∂g (the halves' convention).
                    let num = (at(up) - at(down)) / h as f64;
                    assert!(
                        (dg[j].x as f64 - num).abs() < 4e-3 * g.x as f64 + 1e-6,
                        "{distribution:?} α ({ax}, {ay}) θ {theta} pair {k} d{j}: {} vs {num}",
                        dg[j].x
                    );
                }
            }
            // The isotropic lobe is the isotropic sums, whatever θ.
            if ax == ay && distribution == Distribution::Ggx {
                let (s, ds) = aniso_sums(&all, &p, true);
                let (s1, ds1) = ggx_sums(&all, ax, true);
                assert!((s - s1).abs().max_element() <= 1e-4 * s1.max_element());
                let both = ds[0] + ds[1];
                assert!((both - ds1).abs().max_element() <= 1e-3 * ds1.abs().max_element());
            }
        }
    }
}
