//! Whether the recovered scene explains the photo, group by group and for the run, and if not,
//! what most likely went wrong. A fit always ends somewhere; a group whose final render misses
//! the photo by many times its noise floor was not explained by any model the hierarchy has,
//! and calling it "confirmed" would be confident nonsense. The usual causes are the inputs,
//! not the materials: a photo brighter than any reflectance under the given lights can make
//! (exposure, or the lights' emission), a response that is not linear, clipped pixels, or a
//! model of the scene that is not the photo's (geometry, the lights' placement, unmodelled
//! objects). The verdict names those the numbers point at.

use crate::fit::Recovery;
use crate::photo::Photo;
use serde::Serialize;

/// A group is explained while its final ε is at most this many times its noise floor…
pub const NOISE_FACTOR: f32 = 3.0;
/// …or within this much of it (a large noise floor leaves room for no more than that).
pub const MARGIN: f32 = 0.02;

/// Whether a final ε `error` with noise floor `noise` is explained (module comment).
pub fn explained(error: f32, noise: f32) -> bool {
    error <= (NOISE_FACTOR * noise).max(noise + MARGIN)
}

/// The run's verdict, as results.json, the report and the terminal state it.
#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct Verdict {
    /// Every fitted group explained.
    pub explained: bool,
    /// The fitted groups that are not, and their share of the fitted groups' usable pixels.
    pub not_explained: Vec<String>,
    pub not_explained_share: f32,
    /// Share of the photo's pixels that were clipped (never used in a fit).
    pub clipped_share: f32,
    /// The likely causes, most likely first (empty when explained).
    pub causes: Vec<Cause>,
}

/// One likely cause and the numbers that point at it.
#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct Cause {
    /// "exposure", "response", "clipped pixels" or "scene model".
    pub cause: &'static str,
    pub evidence: String,
}

impl Verdict {
    /// One paragraph for the terminal and the report.
    pub fn text(&self) -> String {
        if self.explained {
            return format!(
                "verdict: every fitted group is explained (final ε within {NOISE_FACTOR}× its \
                 noise floor or {:.0} points of it){}",
                100.0 * MARGIN,
                clipped_note(self.clipped_share)
            );
        }
        let causes: Vec<String> = self
            .causes
            .iter()
            .map(|c| format!("{} ({})", c.cause, c.evidence))
            .collect();
        format!(
            "verdict: NOT EXPLAINED: {} of the fitted groups ({:.0}% of their usable pixels: {}) \
             end with a final ε far above their noise floor; their materials are not to be \
             trusted. Likely causes: {}{}",
            self.not_explained.len(),
            100.0 * self.not_explained_share,
            self.not_explained.join(", "),
            causes.join("; "),
            clipped_note(self.clipped_share)
        )
    }
}

fn clipped_note(share: f32) -> String {
    if share > 0.0 {
        format!(
            "; {:.2}% of the photo's pixels were clipped and left out of every fit",
            100.0 * share
        )
    } else {
        String::new()
    }
}

/// The verdict on `rec`, recovered from `photo`.
pub fn verdict(rec: &Recovery, photo: &Photo) -> Verdict {
    let (mut bad, mut bad_px, mut all_px) = (Vec::new(), 0usize, 0usize);
    for (g, s) in rec.groups.iter().enumerate() {
        let Some((e, n)) = rec.final_error[g] else {
            continue;
        };
        if !s.is_fitted() {
            continue;
        }
        let px = rec.pixel_stats[g].usable;
        all_px += px;
        if !explained(e, n) {
            bad.push(g);
            bad_px += px;
        }
    }
    let clipped_share = photo.invalid_saturated as f32 / photo.valid.len().max(1) as f32;
    let mut causes = Vec::new();
    if !bad.is_empty() {
        causes = likely_causes(rec, photo, &bad, clipped_share);
    }
    Verdict {
        explained: bad.is_empty(),
        not_explained: bad.iter().map(|&g| rec.groups[g].name.clone()).collect(),
        not_explained_share: bad_px as f32 / all_px.max(1) as f32,
        clipped_share,
        causes,
    }
}

/// The causes the numbers of the groups `bad` point at.
fn likely_causes(rec: &Recovery, photo: &Photo, bad: &[usize], clipped_share: f32) -> Vec<Cause> {
    let mut causes = Vec::new();
    let lum = |c: crate::math::Rgb| (c.x + c.y + c.z) / 3.0;
    // Per pixel of the groups not explained: photo and synthetic luminance.
    let mut pairs = Vec::new();
    for (i, &g) in rec.mask.group.iter().enumerate() {
        if g >= 0 && bad.contains(&(g as usize)) {
            let (p, s) = (lum(photo.image.data[i]), lum(rec.synthetic.data[i]));
            if p > 0.0 && s > 0.0 {
                pairs.push((p, s));
            }
        }
    }
    // Groups whose reflectance ended at its physical bound: the photo asked for more light
    // than the lights give.
    let at_bound: Vec<&str> = bad
        .iter()
        .map(|&g| &rec.groups[g])
        .filter(|s| {
            let (rd, rs) = (s.params.rho_d, s.params.rho_s);
            (0..3).any(|c| s.level.rho_bound().reach(rd[c] as f64, rs[c] as f64) >= 0.985)
        })
        .map(|s| s.name.as_str())
        .collect();
    let ratio = {
        let (sp, ss) = pairs.iter().fold((0.0f64, 0.0f64), |a, &(p, s)| {
            (a.0 + p as f64, a.1 + s as f64)
        });
        (ss > 0.0).then(|| (sp / ss) as f32)
    };
    if !at_bound.is_empty() || ratio.is_some_and(|r| !(0.8..=1.25).contains(&r)) {
        let mut evidence = Vec::new();
        if !at_bound.is_empty() {
            evidence.push(format!(
                "reflectance at its bound of 1 in {}",
                at_bound.join(", ")
            ));
        }
        if let Some(r) = ratio {
            evidence.push(format!(
                "the photo is {r:.2}× the recovered scene's render there"
            ));
        }
        causes.push(Cause {
            cause: "exposure",
            evidence: format!(
                "{}: give the photo's exposure (--exposure, --grey-card, \
                 --exposure-from-lights) or check the lights' emission",
                evidence.join("; ")
            ),
        });
    }
    // A response that is not linear: the log ratio photo/synthetic drifts with brightness.
    if photo.bits.is_some() && pairs.len() >= 100 {
        let slope = log_slope(&pairs);
        if (slope - 1.0).abs() > 0.15 {
            causes.push(Cause {
                cause: "response",
                evidence: format!(
                    "ln photo grows {slope:.2}× as fast as ln render over these pixels, where a \
                     linear photo gives 1: give the camera's response (--response) or a linear \
                     (RAW, EXR) photo"
                ),
            });
        }
    }
    if clipped_share > 0.005 {
        causes.push(Cause {
            cause: "clipped pixels",
            evidence: format!(
                "{:.1}% of the photo is clipped: what remains of a bright surface is its darker \
                 part",
                100.0 * clipped_share
            ),
        });
    }
    if causes.is_empty() {
        causes.push(Cause {
            cause: "scene model",
            evidence: "neither the exposure nor the response explains it: the geometry, the \
                       lights' placement or size, or objects the model lacks differ from the \
                       photo (see error.png)"
                .into(),
        });
    }
    causes
}

/// The least-squares slope of ln photo on ln synthetic.
fn log_slope(pairs: &[(f32, f32)]) -> f32 {
    let n = pairs.len() as f64;
    let (mut sx, mut sy, mut sxx, mut sxy) = (0.0f64, 0.0f64, 0.0f64, 0.0f64);
    for &(p, s) in pairs {
        let (x, y) = ((s as f64).ln(), (p as f64).ln());
        sx += x;
        sy += y;
        sxx += x * x;
        sxy += x * y;
    }
    let var = sxx / n - (sx / n).powi(2);
    if var <= 1e-9 {
        return 1.0;
    }
    ((sxy / n - sx / n * sy / n) / var) as f32
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn explained_within_three_noise_floors_or_two_points() {
        assert!(explained(0.011, 0.01));
        assert!(explained(0.029, 0.01));
        assert!(!explained(0.16, 0.011));
        // A noisy photo's large floor: three floors.
        assert!(explained(0.9, 0.36));
        assert!(!explained(0.94, 0.1));
    }

    #[test]
    fn a_gamma_encoded_response_has_a_log_slope_far_from_one() {
        let linear: Vec<(f32, f32)> = (1..200)
            .map(|k| (k as f32 * 0.004, k as f32 * 0.002))
            .collect();
        assert!((log_slope(&linear) - 1.0).abs() < 1e-4);
        let gamma: Vec<(f32, f32)> = linear
            .iter()
            .map(|&(_, s)| (s.powf(1.0 / 2.2), s))
            .collect();
        assert!((log_slope(&gamma) - 1.0 / 2.2).abs() < 1e-3);
    }
}
