//! The Ward lobe eight at a time: sums over many weighted direction pairs, what the fitter's
//! objective needs for each trial lobe (Σ c·g and Σ c·∂g), the inner loop of a recovery; and
//! eight lobes evaluated, their density and their sampling on eight lanes ([`Lobes8`]), for the
//! renderer's eight-lane path loop.

use super::half_vector::{HalfVector, LobeParams};
use crate::math::warp::sin_cos_turn_x8;
use crate::math::{exp_neg_poly8, ln_poly8, Rgb, Vec3, PI};
use crate::scene::WardVariant;
use wide::{f32x8, CmpGt};

/// Eight Ward lobes, one a lane, of one normalisation (a scene's): [`super::WardLobe`]'s
/// `eval`, `pdf` and `sample` repeated operation for operation on eight lanes (Rust never fuses
/// a·b + c), with the same exp, ln and sin/cos polynomials (`exp_neg_poly8`, `ln_poly8`,
/// `sin_cos_turn_x8`). So each lane's result is the scalar one to the bit (the eight-lane path
/// loop, `render::batch`, relies on it; a test holds them together). ωo (and for `eval` and
/// `pdf`, ωi) must be in the upper hemisphere, where the scalar functions do their arithmetic
/// rather than return 0.
#[derive(Clone, Copy, Debug)]
pub struct Lobes8 {
    pub alpha_x: f32x8,
    pub alpha_y: f32x8,
    /// 1 / αx and 1 / αy, which every exponent takes (`WardLobe::exponent`).
    inv_alpha: [f32x8; 2],
    pub variant: WardVariant,
}

type V8 = [f32x8; 3];

fn dot8(a: &V8, b: &V8) -> f32x8 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn add8(a: &V8, b: &V8) -> V8 {
    std::array::from_fn(|k| a[k] + b[k])
}

impl Lobes8 {
    #[inline(always)]
    pub fn new(alpha_x: f32x8, alpha_y: f32x8, variant: WardVariant) -> Lobes8 {
        Lobes8 {
            alpha_x,
            alpha_y,
            inv_alpha: [f32x8::ONE / alpha_x, f32x8::ONE / alpha_y],
            variant,
        }
    }

    /// `WardLobe::exponent`.
    #[inline(always)]
    fn exponent(&self, h: &V8) -> f32x8 {
        let (a, b) = (h[0] * self.inv_alpha[0], h[1] * self.inv_alpha[1]);
        (a * a + b * b) / (h[2] * h[2])
    }

    /// exp(−E) for (ωo, ωi), which `eval` and `pdf` take (`WardLobe::eval` and `pdf` compute
    /// it alike).
    #[inline(always)]
    pub fn gaussian(&self, wo: &V8, wi: &V8) -> f32x8 {
        exp_neg_poly8(self.exponent(&add8(wi, wo)))
    }

    /// `WardLobe::eval`, given `e` = `gaussian(wo, wi)`.
    #[inline(always)]
    pub fn eval(&self, wo: &V8, wi: &V8, e: f32x8) -> f32x8 {
        let splat = f32x8::splat;
        let (ax, ay) = (self.alpha_x, self.alpha_y);
        match self.variant {
            WardVariant::Ward1992 => e / (splat(4.0 * PI) * ax * ay * (wi[2] * wo[2]).sqrt()),
            WardVariant::Balanced => {
                let h = add8(wi, wo);
                let hz2 = h[2] * h[2];
                e * dot8(&h, &h) / (splat(PI) * ax * ay * hz2 * hz2)
            }
        }
    }

    /// `WardLobe::pdf`, given `e` = `gaussian(wo, wi)`.
    #[inline(always)]
    pub fn pdf(&self, wo: &V8, wi: &V8, e: f32x8) -> f32x8 {
        let h = add8(wi, wo);
        e * dot8(&h, &h)
            / (f32x8::splat(2.0 * PI) * self.alpha_x * self.alpha_y * h[2] * h[2] * h[2])
    }

    /// `WardLobe::sample_with_gaussian` from (u0, u1) on every lane: ωi, where it is above
    /// the surface (elsewhere the scalar function returns None), and exp(−E) there.
    #[inline(always)]
    pub fn sample(&self, wo: &V8, u0: f32x8, u1: f32x8) -> (V8, f32x8, f32x8) {
        let splat = f32x8::splat;
        let one = f32x8::ONE;
        let m = (one - u0).max(splat(f32::MIN_POSITIVE));
        let r = (-ln_poly8(m)).sqrt();
        let (s, c) = sin_cos_turn_x8(u1);
        let v = [self.alpha_x * r * c, self.alpha_y * r * s, one];
        let t = splat(2.0) * dot8(wo, &v) / dot8(&v, &v);
        let wi: V8 = std::array::from_fn(|k| t * v[k] - wo[k]);
        let above = wi[2].cmp_gt(f32x8::ZERO) & wo[2].cmp_gt(f32x8::ZERO);
        (wi, above, m)
    }
}

/// A direction pair reduced to its half vector, with the weight c it is summed with (for the
/// cache: incident radiance · cos θi · MIS weight / (pdf · N)), and the tangential components
/// of ωi − ωo: with the half vector's they give each direction's own, which the anisotropic
/// microfacet lobe's masking needs (`microfacet::aniso_sums`); zero below the surface.
/// `repr(C)`: ten floats, hx, hy, 1/hz², the two norms, c and d, which the sums read eight
/// samples at a time as rows and transpose into lanes ([`LobeSample::row`]).
#[derive(Clone, Copy, Debug, Default, bytemuck::Pod, bytemuck::Zeroable)]
#[repr(C)]
pub struct LobeSample {
    pub half: HalfVector,
    pub c: Rgb,
    pub d: [f32; 2],
}

/// Rows of a [`LobeSample`] (indices into [`LobeSample::row`] and [`lanes8`]).
pub(crate) mod row {
    pub const HX: usize = 0;
    pub const HY: usize = 1;
    pub const INV_HZ2: usize = 2;
    pub const NORM: usize = 3;
    pub const C: usize = 5;
}

impl LobeSample {
    pub fn new(wo: Vec3, wi: Vec3, c: Rgb) -> LobeSample {
        let half = HalfVector::new(wo, wi);
        let d = if half.norm[0] > 0.0 {
            [wi.x - wo.x, wi.y - wo.y]
        } else {
            [0.0; 2]
        };
        LobeSample { half, c, d }
    }

    /// The sample's ten floats in field order.
    #[inline(always)]
    pub fn row(&self) -> &[f32; 10] {
        bytemuck::cast_ref(self)
    }
}

/// Eight samples' first eight floats (hx, hy, 1/hz², both norms, c) as eight lanes each, indexed
/// by [`row`]: the samples are stored as rows, the sums want lanes.
#[inline(always)]
pub fn lanes8(chunk: &[LobeSample; 8]) -> [f32x8; 8] {
    crate::math::transpose(std::array::from_fn(|i| {
        chunk[i].row().first_chunk::<8>().expect("ten floats")
    }))
}

/// Calls `f` on `samples` eight at a time, the last eight padded with empty samples (zero c,
/// below the surface), which the sums over them count as nothing.
#[inline(always)]
pub fn chunks8(samples: &[LobeSample], mut f: impl FnMut(&[LobeSample; 8])) {
    let (chunks, rest) = samples.as_chunks::<8>();
    for chunk in chunks {
        f(chunk);
    }
    if !rest.is_empty() {
        let mut pad = [LobeSample::default(); 8];
        pad[..rest.len()].copy_from_slice(rest);
        f(&pad);
    }
}

/// [`LobeParams`] splat on eight lanes.
struct Lanes8Params {
    cos_t: f32x8,
    sin_t: f32x8,
    inv_ax2: f32x8,
    inv_ay2: f32x8,
    inv_axay: f32x8,
    variant: usize,
}

/// c, g and, if asked, 2∂g per shape parameter of eight samples: [`ward_at`](super::ward_at)'s
/// operations in its order, so each lane is its value to the bit.
#[inline(always)]
fn lobe8(
    chunk: &[LobeSample; 8],
    k: &Lanes8Params,
    derivatives: bool,
) -> ([f32x8; 3], f32x8, [f32x8; 3]) {
    let splat = f32x8::splat;
    let r = lanes8(chunk);
    let (hx, hy, inv_hz2) = (r[row::HX], r[row::HY], r[row::INV_HZ2]);
    let norm = r[row::NORM + k.variant];
    let c = [r[row::C], r[row::C + 1], r[row::C + 2]];
    let rx = hx * k.cos_t + hy * k.sin_t;
    let ry = -hx * k.sin_t + hy * k.cos_t;
    let a2 = rx * rx * k.inv_ax2 * inv_hz2;
    let b2 = ry * ry * k.inv_ay2 * inv_hz2;
    let g = exp_neg_poly8(a2 + b2) * k.inv_axay * norm;
    let dg2 = if derivatives {
        [
            splat(2.0) * (g * (splat(2.0) * a2 - f32x8::ONE)),
            splat(2.0) * (g * (splat(2.0) * b2 - f32x8::ONE)),
            splat(2.0) * (-g * splat(2.0) * rx * ry * (k.inv_ax2 - k.inv_ay2) * inv_hz2),
        ]
    } else {
        [f32x8::ZERO; 3]
    };
    (c, g, dg2)
}

/// Σ c·g over `samples` and, if asked, Σ c·2∂g/∂k for k = ln αx, ln αy, θ (zero otherwise):
/// [`ward_at`](super::ward_at) on eight samples at a time (AVX), the tail too, its lanes then
/// added one by one. Both take the renderer's exp ([`crate::math::exp_neg_poly`] and its lanes,
/// equal to the bit), so fitter and renderer evaluate one lobe.
pub fn lobe_sums(samples: &[LobeSample], p: &LobeParams, derivatives: bool) -> (Rgb, [Rgb; 3]) {
    let splat = f32x8::splat;
    let lp = Lanes8Params {
        cos_t: splat(p.cos_t),
        sin_t: splat(p.sin_t),
        inv_ax2: splat(p.inv_ax2),
        inv_ay2: splat(p.inv_ay2),
        inv_axay: splat(p.inv_axay),
        variant: p.variant,
    };
    let lobe = |chunk: &[LobeSample; 8]| lobe8(chunk, &lp, derivatives);
    let mut s = [f32x8::ZERO; 3];
    let mut ds = [[f32x8::ZERO; 3]; 3];
    let (chunks, tail) = samples.as_chunks::<8>();
    for chunk in chunks {
        let (c, g, dg2) = lobe(chunk);
        for ch in 0..3 {
            s[ch] += c[ch] * g;
        }
        if derivatives {
            for k in 0..3 {
                for ch in 0..3 {
                    ds[k][ch] += c[ch] * dg2[k];
                }
            }
        }
    }
    let sum = |v: &[f32x8; 3]| Rgb::from_array(v.map(|x| x.reduce_add()));
    let (mut s, mut ds) = (sum(&s), ds.map(|d| sum(&d)));
    // The tail on eight lanes too (zero samples after it), then added one by one in order, as
    // `ward_at` one sample at a time would add it.
    if !tail.is_empty() {
        let mut pad = [LobeSample::default(); 8];
        pad[..tail.len()].copy_from_slice(tail);
        let (_, g, dg2) = lobe(&pad);
        let (g, dg2) = (g.to_array(), dg2.map(|d| d.to_array()));
        for (i, smp) in tail.iter().enumerate() {
            s += smp.c * g[i];
            if derivatives {
                for k in 0..3 {
                    ds[k] += smp.c * dg2[k][i];
                }
            }
        }
    }
    (s, ds)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::Vec2;
    use crate::render::bsdf::ward::half_vector::ward_at;
    use crate::render::bsdf::{Bsdf, WardLobe};
    use crate::scene::WardVariant;

    #[test]
    fn eight_lobes_are_the_scalar_lobe_to_the_bit() {
        // Random lobes (both normalisations, narrow to wide, isotropic and not) and random
        // directions above the surface, grazing ones included: eval, pdf and sample of
        // `Lobes8` against `WardLobe`, and `Bsdf::ward_eval8` / `ward_pdf8` against `Bsdf`.
        let mut rng = crate::math::sampler::TestRng(7);
        let up = |rng: &mut crate::math::sampler::TestRng| loop {
            let v = Vec3::new(rng.f32() - 0.5, rng.f32() - 0.5, rng.f32().powi(3));
            if v.z > 0.0 && v.length_squared() > 1e-6 {
                return v.normalize();
            }
        };
        let bits = |v: f32x8| v.to_array().map(f32::to_bits);
        let (mut lobe_samples, mut above) = (0, 0);
        for i in 0..2000 {
            // One normalisation for the eight, as in a scene.
            let variant = if i % 2 == 0 {
                WardVariant::Ward1992
            } else {
                WardVariant::Balanced
            };
            let lobes: [WardLobe; 8] = std::array::from_fn(|_| {
                let ax = 0.01 + rng.f32() * 0.6;
                let iso = rng.f32() < 0.3;
                WardLobe {
                    alpha_x: ax,
                    alpha_y: if iso { ax } else { 0.01 + rng.f32() * 0.6 },
                    variant,
                }
            });
            let rho_d: [Rgb; 8] = std::array::from_fn(|_| rng.vec3());
            let rho_s: [Rgb; 8] = std::array::from_fn(|_| rng.vec3());
            let wo: [Vec3; 8] = std::array::from_fn(|_| up(&mut rng));
            let wi: [Vec3; 8] = std::array::from_fn(|_| up(&mut rng));
            let u: [Vec2; 8] = std::array::from_fn(|_| Vec2::new(rng.f32(), rng.f32()));
            let x8 = |f: &dyn Fn(usize) -> f32| f32x8::from(std::array::from_fn(f));
            let v8 = |v: &[Vec3; 8]| [0, 1, 2].map(|k| x8(&|j| v[j][k]));
            let l8 = Lobes8::new(
                x8(&|j| lobes[j].alpha_x),
                x8(&|j| lobes[j].alpha_y),
                variant,
            );
            let (wo8, wi8) = (v8(&wo), v8(&wi));
            let g = l8.gaussian(&wo8, &wi8);
            let (e, p) = (l8.eval(&wo8, &wi8, g), l8.pdf(&wo8, &wi8, g));
            let (ws, ok, m8) = l8.sample(&wo8, x8(&|j| u[j].x), x8(&|j| u[j].y));
            let bsdfs: [Bsdf; 8] = std::array::from_fn(|j| Bsdf::Ward {
                rho_d: rho_d[j],
                rho_s: rho_s[j],
                lobe: lobes[j],
            });
            let pd = Bsdf::diffuse_prob8(&v8(&rho_d), &v8(&rho_s));
            for j in 0..8 {
                let scalar = Bsdf::diffuse_prob(rho_d[j], rho_s[j]);
                assert_eq!(
                    bits(pd)[j],
                    scalar.to_bits(),
                    "{:?} {:?}",
                    rho_d[j],
                    rho_s[j]
                );
            }
            let f8 = Bsdf::ward_eval8(&v8(&rho_d), &v8(&rho_s), &l8, &wo8, &wi8, g);
            let p8 = Bsdf::ward_pdf8(pd, &l8, &wo8, &wi8, g);
            for j in 0..8 {
                let l = &lobes[j];
                assert_eq!(bits(e)[j], l.eval(wo[j], wi[j]).to_bits(), "{l:?}");
                assert_eq!(bits(p)[j], l.pdf(wo[j], wi[j]).to_bits(), "{l:?}");
                let f = bsdfs[j].eval(wo[j], wi[j]);
                for k in 0..3 {
                    assert_eq!(bits(f8[k])[j], f[k].to_bits());
                }
                assert_eq!(bits(p8)[j], bsdfs[j].pdf(wo[j], wi[j]).to_bits());
                let one = l.sample_with_gaussian(wo[j], u[j]);
                assert_eq!(one.is_some(), ok.to_array()[j] != 0.0, "{l:?}");
                if let Some((w, m)) = one {
                    for k in 0..3 {
                        assert_eq!(bits(ws[k])[j], w[k].to_bits());
                    }
                    assert_eq!(bits(m8)[j], m.to_bits());
                    above += 1;
                }
                lobe_samples += 1;
            }
        }
        assert!(above > lobe_samples / 2, "{above} of {lobe_samples}");
        let black = [f32x8::ZERO; 3];
        let pd = Bsdf::diffuse_prob8(&black, &black).to_array()[0];
        assert_eq!(
            pd.to_bits(),
            Bsdf::diffuse_prob(Rgb::ZERO, Rgb::ZERO).to_bits()
        );
    }

    /// Σ c·g and Σ c·2∂g of `samples` by `ward_at`, one sample at a time in order.
    fn one_by_one(samples: &[LobeSample], p: &LobeParams) -> (Rgb, [Rgb; 3]) {
        let (mut s, mut ds) = (Rgb::ZERO, [Rgb::ZERO; 3]);
        for smp in samples {
            let (g, dg) = ward_at(&smp.half, p);
            s += smp.c * g;
            for k in 0..3 {
                ds[k] += smp.c * (2.0 * dg[k]);
            }
        }
        (s, ds)
    }

    #[test]
    fn lobe_sums_of_fewer_than_eight_samples_are_ward_at_summed_in_order() {
        // A pixel's half ends in a tail of up to seven samples; the sums must add it exactly as
        // `ward_at` one sample at a time does (every fit's numbers depend on it).
        let mut rng = crate::math::sampler::TestRng(5);
        let mut dir = || Vec3::new(rng.f32() - 0.5, rng.f32() - 0.5, rng.f32()).normalize();
        for n in 1..8 {
            let samples: Vec<LobeSample> = (0..n)
                .map(|i| LobeSample::new(dir(), dir(), Rgb::new(0.3, 0.6, 0.9) * (1.0 + i as f32)))
                .collect();
            for variant in [WardVariant::Ward1992, WardVariant::Balanced] {
                let p = LobeParams::new(0.11, 0.27, 0.4, variant);
                let (s, ds) = lobe_sums(&samples, &p, true);
                let (s1, ds1) = one_by_one(&samples, &p);
                assert!(s1.max_element() > 0.0, "{n}");
                assert_eq!(
                    s.to_array().map(f32::to_bits),
                    s1.to_array().map(f32::to_bits)
                );
                for k in 0..3 {
                    assert_eq!(
                        ds[k].to_array().map(f32::to_bits),
                        ds1[k].to_array().map(f32::to_bits)
                    );
                }
            }
        }
    }

    #[test]
    fn eight_lane_lobe_sums_match_the_one_sample_lobe() {
        let mut rng = crate::math::sampler::TestRng(21);
        let mut dir = || {
            let v = Vec3::new(rng.f32() - 0.5, rng.f32() - 0.5, rng.f32() - 0.1);
            v.normalize()
        };
        // 37 samples: four chunks of eight and a tail; some directions below the surface.
        let samples: Vec<LobeSample> = (0..37)
            .map(|i| {
                LobeSample::new(
                    dir(),
                    dir(),
                    Rgb::new(0.2, 0.5, 1.0) * (1.0 + i as f32 / 9.0),
                )
            })
            .collect();
        for variant in [WardVariant::Ward1992, WardVariant::Balanced] {
            for (ax, ay, th) in [
                (0.3f32, 0.3f32, 0.0f32),
                (0.12, 0.35, 0.7),
                (0.05, 0.02, -1.2),
            ] {
                let p = LobeParams::new(ax, ay, th, variant);
                let (s, ds) = lobe_sums(&samples, &p, true);
                let (s1, ds1) = one_by_one(&samples, &p);
                assert!(s1.max_element() > 0.0);
                let tol = 1e-5
                    * (s1.abs().max_element()
                        + ds1
                            .iter()
                            .map(|d| d.abs().max_element())
                            .fold(0.0, f32::max));
                assert!(
                    (s - s1).abs().max_element() <= tol,
                    "{variant:?} {ax} {ay} {th}: {s} vs {s1}"
                );
                for k in 0..3 {
                    assert!(
                        (ds[k] - ds1[k]).abs().max_element() <= tol,
                        "d{k}: {} vs {}",
                        ds[k],
                        ds1[k]
                    );
                }
                let (s0, ds0) = lobe_sums(&samples, &p, false);
                assert_eq!(s0, s);
                assert_eq!(ds0, [Rgb::ZERO; 3]);
            }
        }
    }
}
