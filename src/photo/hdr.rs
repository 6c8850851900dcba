//! Merging exposure brackets into one linear (HDR) image, after Debevec & Malik 1997,
//! "Recovering high dynamic range radiance maps from photographs", SIGGRAPH, eq. 6:
//!
//! ln E = Σ_j w(Z_j) (ln f(Z_j) − ln Δt_j) / Σ_j w(Z_j)
//!
//! per pixel and channel, over the exposures j, where f is the response (code → linear value,
//! `photo::response`) and w the hat weight of their eq. 4, here on codes scaled to [0, 1]:
//! w(z) = min(z, 1 − z). The hat gives no weight to the bottom code (under-exposed: only a
//! bound) and the top one (clipped), and little to the codes near them, where quantisation
//! and noise are largest relative to the value.
//!
//! A pixel and channel with no code of positive weight in any exposure has no measured value:
//! it gets the bound its extreme exposure gives (f(top)/Δt of the shortest exposure where it
//! is clipped in all, f(bottom)/Δt of the longest where it is black in all) and is counted.

use crate::io::image::Image;
use crate::math::Rgb;
use crate::photo::brackets::Brackets;
use crate::photo::Response;

/// The hat weight of Debevec & Malik's eq. 4 on a code scaled to [0, 1].
pub fn hat(z: f32) -> f32 {
    z.min(1.0 - z).max(0.0)
}

/// A merged image and what the merge could not measure.
#[derive(Clone, Debug)]
pub struct Merged {
    pub image: Image,
    /// Pixels with a channel clipped in every exposure (their value is a lower bound).
    pub clipped_everywhere: usize,
    /// Pixels with a channel black in every exposure (their value is an upper bound).
    pub black_everywhere: usize,
    /// Pixels none of whose channels has a well-exposed code in any exposure.
    pub unmeasured: usize,
}

/// Merges `b` through `response` (eq. 6 of the module documentation).
pub fn merge(b: &Brackets, response: &Response) -> Merged {
    let (w, h) = (b.width(), b.height());
    let mut image = Image::new(w, h);
    let (mut clipped, mut black, mut unmeasured) = (0, 0, 0);
    let shortest = argmin(&b.times, |t| t);
    let longest = argmin(&b.times, |t| -t);
    for i in 0..w * h {
        let (mut is_clipped, mut is_black, mut measured) = (false, false, false);
        let mut c = Rgb::ZERO;
        for ch in 0..3 {
            let (mut sw, mut sl) = (0.0f64, 0.0f64);
            for (img, &t) in b.images.iter().zip(&b.times) {
                let z = img.data[i][ch];
                let wz = hat(z) as f64;
                let f = response.linearize_channel(z, ch) as f64;
                if wz > 0.0 && f > 0.0 {
                    sw += wz;
                    sl += wz * (f.ln() - (t as f64).ln());
                }
            }
            measured |= sw > 0.0;
            c[ch] = if sw > 0.0 {
                (sl / sw).exp() as f32
            } else {
                // No well-exposed code: clipped in the shortest exposure, or dark in the longest.
                let z = b.images[shortest].data[i][ch];
                if z >= 0.5 {
                    is_clipped = true;
                    response.linearize_channel(z, ch) / b.times[shortest]
                } else {
                    is_black = true;
                    let z = b.images[longest].data[i][ch];
                    response.linearize_channel(z, ch) / b.times[longest]
                }
            };
        }
        clipped += is_clipped as usize;
        black += is_black as usize;
        unmeasured += !measured as usize;
        image.data[i] = c;
    }
    Merged {
        image,
        clipped_everywhere: clipped,
        black_everywhere: black,
        unmeasured,
    }
}

/// Index of the smallest `key(x)`.
fn argmin(v: &[f32], key: impl Fn(f32) -> f32) -> usize {
    (0..v.len())
        .min_by(|&a, &b| key(v[a]).total_cmp(&key(v[b])))
        .unwrap_or(0)
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// Brackets of `radiance` (one grey value per pixel) through `encode` (linear → code in
    /// [0, 1]) with 8-bit quantisation.
    pub fn synthesize(radiance: &[f32], times: &[f32], encode: impl Fn(f32) -> f32) -> Brackets {
        synthesize_bits(radiance, times, encode, 8)
    }

    /// [`synthesize`] with `bits`-bit quantisation.
    pub fn synthesize_bits(
        radiance: &[f32],
        times: &[f32],
        encode: impl Fn(f32) -> f32,
        bits: u32,
    ) -> Brackets {
        let top = ((1u32 << bits) - 1) as f32;
        let n = radiance.len();
        let images = times
            .iter()
            .map(|&t| {
                let mut img = Image::new(n, 1);
                for (c, &l) in img.data.iter_mut().zip(radiance) {
                    *c = Rgb::splat((encode((l * t).min(1.0)) * top).round() / top);
                }
                img
            })
            .collect();
        Brackets {
            paths: Vec::new(),
            images,
            times: times.to_vec(),
            bits,
        }
    }

    /// Radiance spread log-uniformly over [lo, hi].
    pub fn log_ramp(n: usize, lo: f32, hi: f32) -> Vec<f32> {
        (0..n)
            .map(|k| lo * (hi / lo).powf(k as f32 / (n - 1) as f32))
            .collect()
    }

    /// Largest relative error of `merged` against `truth` over the pixels with a code in
    /// [0.3, 0.7] in some exposure (well exposed), and over all pixels.
    pub fn merge_errors(b: &Brackets, merged: &[f32], truth: &[f32]) -> (f32, f32) {
        let (mut well, mut all) = (0.0f32, 0.0f32);
        for (i, (&m, &t)) in merged.iter().zip(truth).enumerate() {
            let e = (m / t - 1.0).abs();
            all = all.max(e);
            if b.images.iter().any(|img| hat(img.data[i].x) >= 0.3) {
                well = well.max(e);
            }
        }
        (well, all)
    }

    /// With the true response, the pixels of a 2.7-decade ramp that some exposure puts at a
    /// code in [0.3, 0.7] are merged within 2% (one 8-bit code step through gamma 2.2 is
    /// 2.2/code relative, 2.9% at code 77), and every pixel within 3.5% (the darkest, at codes
    /// 43 and 22). The clipped and black-everywhere pixels are counted and get their bound.
    #[test]
    fn the_true_response_merges_within_two_percent_where_well_exposed() {
        let times = [0.125, 0.5, 2.0];
        let l = log_ramp(2000, 0.01, 5.0);
        let g = Response::Gamma(2.2);
        let b = synthesize(&l, &times, |x| g.encode_channel(x, 0));
        let m = merge(&b, &g);
        let merged: Vec<f32> = m.image.data.iter().map(|c| c.x).collect();
        let (well, all) = merge_errors(&b, &merged, &l);
        eprintln!("true response: well-exposed worst {well:.4}, all worst {all:.4}");
        assert!(well < 0.02 && all < 0.035, "{well} {all}");
        assert_eq!((m.clipped_everywhere, m.black_everywhere), (0, 0));
        // 20 is clipped at 1/8 (it gets 1 / (1/8) = 8); 1e-7 is black at 2.
        let b = synthesize(&[20.0, 1e-7, 1.0], &times, |x| g.encode_channel(x, 0));
        let m = merge(&b, &g);
        assert_eq!(
            (m.clipped_everywhere, m.black_everywhere, m.unmeasured),
            (1, 1, 2)
        );
        assert!(
            (m.image.data[0].x - 8.0).abs() < 1e-4,
            "{:?}",
            m.image.data[0]
        );
        assert_eq!(m.image.data[1].x, 0.0);
    }
}
