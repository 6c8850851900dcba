//! Recovering a camera's response curve from exposure brackets: the least squares of Debevec &
//! Malik 1997 ("Recovering high dynamic range radiance maps from photographs", SIGGRAPH, eq. 3)
//! over a smooth family of curves instead of one free value per code plus a smoothness term.
//!
//! With g(z) = ln f(z) the log inverse response, t_j the exposure times and E_s the unknown
//! radiance of sample s (a pixel's channel), it minimises
//!
//! Σ_s Σ_j [w(z_sj) (g(z_sj) − ln E_s − ln t_j)]²
//!
//! with w the merge's hat ([`hat`]) and g(z) = Σ_k θ_k φ_k(z) on the basis
//! φ = (ln z, z, z², z³, z⁴), each shifted to vanish at the middle code (so f(mid) = 1: the
//! scale of a response recovered from the images alone is arbitrary, and so is the merged
//! radiance's — calibrate it in `recover` with a grey card or the lights). For given θ the best
//! ln E_s is the w²-weighted mean of g(z_sj) − ln t_j, linear in θ, so the whole problem is a
//! linear least squares in the five θ_k: its normal equations are solved here directly.
//!
//! Why not one value per code: brackets a constant factor apart (±2 EV) determine the curve
//! only up to a modulation periodic in ln E with the bracket step, which 8-bit quantisation
//! then picks. Robertson et al.'s 2003 iteration (one free value per code, no smoothness term)
//! measured it on gamma-2.2 brackets 4× apart: the curve 3–5% off after 1000 iterations, even
//! started from the exact curve. The ln z term carries a power law's slope at black; the
//! polynomial, the toe and shoulder of an S-shaped curve.
//!
//! Each channel gets its own curve, as Debevec & Malik recover colour images' responses: a
//! camera's red, green and blue responses differ in shape, and a curve pooled over the three
//! is off the outer ones at both ends of the range (the test below). Each is scaled to 1 at the
//! middle code, so a neutral grey recorded with equal codes (what the camera's white balance
//! makes of it) stays neutral. A channel the brackets do not constrain on its own (fewer than
//! 16 codes seen, or singular) takes the curve of the three pooled.

use crate::photo::brackets::Brackets;
use crate::photo::hdr::hat;
use crate::photo::ResponseTable;
use std::path::PathBuf;

/// Largest number of (pixel, channel) samples used: an evenly strided subset of a larger image.
pub const MAX_SAMPLES: usize = 200_000;

/// Largest root-mean-square misfit (ln units) of brackets to the curve: 8-bit quantisation
/// alone gives 0.001–0.002 (the tests here, `tests/photo_inputs.rs`); one exposure twice,
/// claimed 4× apart, 0.13–0.25.
pub const MAX_RMS: f64 = 0.1;

/// Number of basis functions of g.
const K: usize = 5;

/// The basis φ(z), before the shift that makes it vanish at the middle code.
fn basis(z: f64) -> [f64; K] {
    [z.ln(), z, z * z, z * z * z, z * z * z * z]
}

/// The recovered curve and how well the brackets fit it.
#[derive(Clone, Debug)]
pub struct Recovered {
    pub table: ResponseTable,
    /// Root-mean-square of the weighted residuals, in ln units: how far the brackets are from
    /// one curve (noise, motion, a wrong exposure time).
    pub rms: f64,
}

/// Recovers the response of `b` (module documentation), tabulated on `bins` evenly spaced codes
/// (256 for 8-bit brackets). Fails when the brackets do not constrain it: fewer than 16 codes
/// seen with weight, or a degenerate system.
pub fn recover_response(b: &Brackets, bins: usize) -> Result<Recovered, String> {
    let (tmin, tmax) = b
        .times
        .iter()
        .fold((f32::MAX, 0.0f32), |(a, c), &t| (a.min(t), c.max(t)));
    if tmax < 1.01 * tmin {
        return Err(
            "the exposure times are all equal: brackets of one exposure do not \
                    determine the response; give it (--response srgb, gamma:G or table:FILE)"
                .into(),
        );
    }
    let top = (bins - 1) as f64;
    let mid = ((bins - 1) / 2) as f64 / top;
    let shift = basis(mid);
    let phi = |z: f64| {
        let p = basis(z);
        std::array::from_fn::<f64, K, _>(|k| p[k] - shift[k])
    };
    let n_px = b.width() * b.height();
    let stride = (n_px * 3).div_ceil(MAX_SAMPLES).max(1);
    let lt: Vec<f64> = b.times.iter().map(|&t| (t as f64).ln()).collect();
    // Per channel; the three pooled are their sums.
    let mut seen = vec![vec![false; bins]; 3];
    let mut ata = [[[0.0f64; K]; K]; 3];
    let mut atb = [[0.0f64; K]; 3];
    let mut rows: [Vec<([f64; K], f64)>; 3] = Default::default();
    for s in (0..n_px * 3).step_by(stride) {
        let ch = s % 3;
        // Codes quantised to the bins (16-bit brackets are binned like the table).
        let z: Vec<f64> = b
            .images
            .iter()
            .map(|img| (img.data[s / 3][ch].clamp(0.0, 1.0) as f64 * top).round() / top)
            .collect();
        let w2: Vec<f64> = z.iter().map(|&z| (hat(z as f32) as f64).powi(2)).collect();
        let sw2: f64 = w2.iter().sum();
        if w2.iter().filter(|&&w| w > 0.0).count() < 2 {
            continue; // one exposure alone says nothing about the curve
        }
        for (&zz, &w) in z.iter().zip(&w2) {
            seen[ch][(zz * top).round() as usize] |= w > 0.0;
        }
        // ln E_s = Σ α_k (g(z_k) − ln t_k), α = w² / Σ w²: its φ and ln t parts.
        let p: Vec<[f64; K]> = z
            .iter()
            .zip(&w2)
            .map(|(&z, &w)| if w > 0.0 { phi(z) } else { [0.0; K] })
            .collect();
        let mean_p: [f64; K] =
            std::array::from_fn(|k| p.iter().zip(&w2).map(|(p, w)| w * p[k]).sum::<f64>() / sw2);
        let mean_lt: f64 = lt.iter().zip(&w2).map(|(l, w)| w * l).sum::<f64>() / sw2;
        for j in 0..z.len() {
            if w2[j] == 0.0 {
                continue;
            }
            let w = w2[j].sqrt();
            let a: [f64; K] = std::array::from_fn(|k| w * (p[j][k] - mean_p[k]));
            let r = w * (lt[j] - mean_lt);
            for k in 0..K {
                for l in 0..K {
                    ata[ch][k][l] += a[k] * a[l];
                }
                atb[ch][k] += a[k] * r;
            }
            rows[ch].push((a, r));
        }
    }
    let n_seen = |c: usize| seen[c].iter().filter(|&&x| x).count();
    let n_seen_all = (0..bins).filter(|&m| seen.iter().any(|s| s[m])).count();
    if n_seen_all < 16 {
        return Err(format!(
            "the brackets show only {n_seen_all} well-exposed code values in pixels seen well \
             exposed twice: too few to recover the response; give it (--response srgb, gamma:G \
             or table:FILE)"
        ));
    }
    let ata_all: [[f64; K]; K] =
        std::array::from_fn(|k| std::array::from_fn(|l| (0..3).map(|c| ata[c][k][l]).sum()));
    let atb_all: [f64; K] = std::array::from_fn(|k| (0..3).map(|c| atb[c][k]).sum());
    let pooled = solve(ata_all, atb_all).ok_or_else(|| {
        "the brackets do not determine the response; give it (--response srgb, gamma:G or \
         table:FILE)"
            .to_string()
    })?;
    let theta: [[f64; K]; 3] = std::array::from_fn(|c| {
        (n_seen(c) >= 16)
            .then(|| solve(ata[c], atb[c]))
            .flatten()
            .unwrap_or(pooled)
    });
    let mut sq = 0.0f64;
    for c in 0..3 {
        sq += rows[c]
            .iter()
            .map(|(a, r)| (a.iter().zip(&theta[c]).map(|(a, t)| a * t).sum::<f64>() - r).powi(2))
            .sum::<f64>();
    }
    let g = |z: f64, c: usize| {
        phi(z)
            .iter()
            .zip(&theta[c])
            .map(|(p, t)| p * t)
            .sum::<f64>()
    };
    let mut values: Vec<[f64; 3]> = (0..bins)
        .map(|m| {
            std::array::from_fn(|c| {
                if m == 0 {
                    0.0
                } else {
                    g(m as f64 / top, c).exp()
                }
            })
        })
        .collect();
    let n_rows: usize = rows.iter().map(Vec::len).sum();
    let rms = (sq / n_rows.max(1) as f64).sqrt();
    if rms > MAX_RMS
        || values
            .iter()
            .flatten()
            .any(|v| !(v.is_finite() && *v < 1e30))
    {
        return Err(format!(
            "the brackets do not fit a response curve (rms misfit {rms:.3} ln units, more than \
             {MAX_RMS}): check the exposure times and their order, and that neither the camera \
             nor the scene moved"
        ));
    }
    // A table's values never decrease (a brighter code cannot mean less light).
    for m in 1..bins {
        for c in 0..3 {
            values[m][c] = values[m][c].max(values[m - 1][c]);
        }
    }
    Ok(Recovered {
        table: ResponseTable {
            path: PathBuf::from("recovered"),
            codes: (0..bins).map(|m| m as f32 / top as f32).collect(),
            values: values.iter().map(|v| v.map(|x| x as f32)).collect(),
        },
        rms,
    })
}

/// Solves the K×K system by Gaussian elimination with partial pivoting; None when singular.
fn solve(mut a: [[f64; K]; K], mut b: [f64; K]) -> Option<[f64; K]> {
    let scale = (0..K).map(|k| a[k][k].abs()).fold(0.0, f64::max);
    for c in 0..K {
        let p = (c..K).max_by(|&i, &j| a[i][c].abs().total_cmp(&a[j][c].abs()))?;
        if a[p][c].abs() <= 1e-12 * scale {
            return None;
        }
        a.swap(c, p);
        b.swap(c, p);
        for r in c + 1..K {
            let f = a[r][c] / a[c][c];
            for k in c..K {
                a[r][k] -= f * a[c][k];
            }
            b[r] -= f * b[c];
        }
    }
    let mut x = [0.0; K];
    for c in (0..K).rev() {
        let s: f64 = (c + 1..K).map(|k| a[c][k] * x[k]).sum();
        x[c] = (b[c] - s) / a[c][c];
    }
    Some(x)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::photo::hdr::merge;
    use crate::photo::hdr::tests::{log_ramp, merge_errors, synthesize, synthesize_bits};
    use crate::photo::Response;
    use std::path::Path;

    /// Largest relative error of the recovered curve against `truth` (both scaled to 1 at the
    /// middle code) over codes 0.1–0.95, and of the merge through it over pixels with a
    /// well-exposed code (after the one free scale factor, the median ratio).
    fn errors(truth: &Response) -> (f32, f32, f32) {
        let times = [0.125, 0.5, 2.0];
        let l = log_ramp(20000, 0.01, 5.0);
        let b = synthesize(&l, &times, |x| truth.encode_channel(x, 0));
        let r = recover_response(&b, 256).unwrap();
        eprintln!("{}: rms {:.4} ln units", truth.name(), r.rms);
        let mid = truth.linearize(127.0 / 255.0);
        let curve = (26..=242)
            .map(|m| {
                let z = m as f32 / 255.0;
                (r.table.eval(z, 0) / (truth.linearize(z) / mid) - 1.0).abs()
            })
            .fold(0.0, f32::max);
        let m = merge(&b, &Response::Table(std::sync::Arc::new(r.table)));
        let mut ratios: Vec<f32> = m.image.data.iter().zip(&l).map(|(c, &x)| c.x / x).collect();
        let k = crate::photo::robust::median(&mut ratios).unwrap();
        let merged: Vec<f32> = m.image.data.iter().map(|c| c.x / k).collect();
        let (well, all) = merge_errors(&b, &merged, &l);
        (curve, well, all)
    }

    /// A gamma 2.2 camera and an S-shaped one (gamma 2.2 then a smoothstep blend, flatter at
    /// both ends), 8-bit brackets 4× apart: the curve within 1% of the truth over codes
    /// 0.1–0.95, and the merge through it within 2% on the well-exposed pixels (a code in
    /// [0.3, 0.7]) and 4.5% on all, up to the one free scale — what the true curve gives
    /// (`hdr`'s test): the 8-bit codes, not the recovery, limit the merge.
    #[test]
    fn gamma_and_s_curve_responses_are_recovered() {
        let s_codes: Vec<f32> = (0..=4096).map(|k| k as f32 / 4096.0).collect();
        let s_curve = ResponseTable {
            path: "s".into(),
            values: s_codes
                .iter()
                .map(|&c| {
                    // Code → linear: the inverse of c = s(x^(1/2.2)), s(u) = u/2 + (3u² − 2u³)/2,
                    // found by bisection.
                    let (mut lo, mut hi) = (0.0f32, 1.0f32);
                    for _ in 0..40 {
                        let u = 0.5 * (lo + hi);
                        let s = 0.5 * u + 0.5 * (3.0 * u * u - 2.0 * u * u * u);
                        if s < c {
                            lo = u;
                        } else {
                            hi = u;
                        }
                    }
                    [(0.5 * (lo + hi)).powf(2.2); 3]
                })
                .collect(),
            codes: s_codes,
        };
        for truth in [
            Response::Gamma(2.2),
            Response::Table(std::sync::Arc::new(s_curve)),
        ] {
            let (curve, well, all) = errors(&truth);
            eprintln!(
                "{}: curve {curve:.4}, merge worst {well:.4} well exposed, {all:.4} all",
                truth.name()
            );
            assert!(
                curve < 0.01 && well < 0.02 && all < 0.045,
                "{}",
                truth.name()
            );
        }
        // The table round-trips through its file format.
        let b = synthesize(&log_ramp(2000, 0.01, 5.0), &[0.125, 0.5, 2.0], |x| {
            Response::Gamma(2.2).encode_channel(x, 0)
        });
        let r = recover_response(&b, 256).unwrap();
        let back = ResponseTable::parse(&r.table.to_text(), Path::new("r.txt")).unwrap();
        for z in [0.1f32, 0.5, 0.9] {
            assert!((back.eval(z, 0) / r.table.eval(z, 0) - 1.0).abs() < 1e-5);
        }
    }

    /// 16-bit brackets, binned to 1024 codes as `matfit hdr` does: the curve within 0.5% of a
    /// gamma-2.2 camera, and the table file keeps its 1024 evenly spaced codes.
    #[test]
    fn sixteen_bit_brackets_are_binned() {
        let g = Response::Gamma(2.2);
        let b = synthesize_bits(
            &log_ramp(20000, 0.01, 5.0),
            &[0.125, 0.5, 2.0],
            |x| g.encode_channel(x, 0),
            16,
        );
        let r = recover_response(&b, 1024).unwrap();
        let mid = g.linearize(511.0 / 1023.0);
        let curve = (103..=972)
            .map(|m| {
                let z = m as f32 / 1023.0;
                (r.table.eval(z, 0) / (g.linearize(z) / mid) - 1.0).abs()
            })
            .fold(0.0, f32::max);
        eprintln!("16-bit: curve {curve:.5}, rms {:.5}", r.rms);
        assert!(curve < 0.005, "{curve}");
        let back = ResponseTable::parse(&r.table.to_text(), Path::new("r.txt")).unwrap();
        assert_eq!(back.codes.len(), 1024);
        assert!((back.eval(0.3, 0) / r.table.eval(0.3, 0) - 1.0).abs() < 1e-5);
    }

    /// A camera whose channels have gamma 2.0, 2.2 and 2.4, white-balanced (a radiance of 0.2
    /// gives the middle code in all three), 8-bit brackets 4× apart of a grey ramp: each
    /// channel's curve within 1% of its truth over codes 0.1–0.95, and the merge neutral — each
    /// channel within 2.5% of the grey truth where well exposed, after one scale for all three.
    #[test]
    fn each_channel_gets_its_own_curve() {
        let gammas = [2.0f32, 2.2, 2.4];
        let encode = |x: f32, c: usize| (0.5 * (x / 0.2).powf(1.0 / gammas[c])).min(1.0);
        let times = [0.125f32, 0.5, 2.0];
        let l = log_ramp(20000, 0.01, 5.0);
        let images = times
            .iter()
            .map(|&t| {
                let mut img = crate::io::image::Image::new(l.len(), 1);
                for (px, &x) in img.data.iter_mut().zip(&l) {
                    for c in 0..3 {
                        px[c] = (encode(x * t, c) * 255.0).round() / 255.0;
                    }
                }
                img
            })
            .collect();
        let b = Brackets {
            paths: Vec::new(),
            images,
            times: times.to_vec(),
            bits: 8,
        };
        let r = recover_response(&b, 256).unwrap();
        for (c, g) in gammas.iter().enumerate() {
            let curve = (26..=242)
                .map(|m| {
                    let z = m as f32 / 255.0;
                    (r.table.eval(z, c) / (z / (127.0 / 255.0)).powf(*g) - 1.0).abs()
                })
                .fold(0.0, f32::max);
            eprintln!("channel {c} (gamma {g}): curve worst {curve:.4}");
            assert!(curve < 0.01, "channel {c}: {curve}");
        }
        // Three columns in the table file, read back as written.
        let back = ResponseTable::parse(&r.table.to_text(), Path::new("r.txt")).unwrap();
        for (z, c) in [(0.2f32, 0), (0.5, 1), (0.9, 2)] {
            assert!((back.eval(z, c) / r.table.eval(z, c) - 1.0).abs() < 1e-5);
        }
        let m = merge(&b, &Response::Table(std::sync::Arc::new(r.table)));
        let mut ratios: Vec<f32> = m.image.data.iter().zip(&l).map(|(p, &x)| p.y / x).collect();
        let k = crate::photo::robust::median(&mut ratios).unwrap();
        for c in 0..3 {
            let merged: Vec<f32> = m.image.data.iter().map(|p| p[c] / k).collect();
            let (well, all) = merge_errors(&b, &merged, &l);
            eprintln!("channel {c}: merge worst {well:.4} well exposed, {all:.4} all");
            assert!(well < 0.025, "channel {c}: {well}");
        }
    }

    #[test]
    fn brackets_with_few_codes_are_refused() {
        let b = synthesize(&[0.1, 0.2, 0.3], &[1.0, 2.0], |x| x);
        let e = recover_response(&b, 256).unwrap_err();
        assert!(e.contains("too few"), "{e}");
        let b = synthesize(&log_ramp(2000, 0.1, 0.9), &[1.0, 1.0], |x| x);
        let e = recover_response(&b, 256).unwrap_err();
        assert!(e.contains("exposure times are all equal"), "{e}");
        // One exposure twice, claimed 4× apart: no curve fits.
        let mut b = synthesize(&log_ramp(2000, 0.1, 0.9), &[1.0, 1.0], |x| x.powf(0.45));
        b.times = vec![0.25, 1.0];
        let e = recover_response(&b, 256).unwrap_err();
        assert!(e.contains("do not fit a response curve"), "{e}");
    }
}
