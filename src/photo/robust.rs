//! Robust statistics over a group's pixels: median, trimmed mean, MAD scale, and the *planar
//! approximation* of §3.3 of the notes — a plane v ≈ a + b·x + c·y fitted to values over the
//! image and refitted without the points far from it — which separates a smooth surface from
//! whatever does not belong to it (an unmodelled object, a strip of a neighbouring surface left
//! by a misregistered model).

/// Median of the finite values (NaN-free input assumed); None when empty. Reorders `v`.
pub fn median(v: &mut [f32]) -> Option<f32> {
    if v.is_empty() {
        return None;
    }
    let mid = v.len() / 2;
    let (_, m, _) = v.select_nth_unstable_by(mid, f32::total_cmp);
    let m = *m;
    if v.len() % 2 == 1 {
        Some(m)
    } else {
        let lower = v[..mid].iter().copied().fold(f32::MIN, f32::max);
        Some(0.5 * (lower + m))
    }
}

/// Mean of the values left after dropping the fraction `trim` (0 ≤ trim < 0.5) at each end.
pub fn trimmed_mean(v: &mut [f32], trim: f32) -> Option<f32> {
    if v.is_empty() {
        return None;
    }
    v.sort_unstable_by(f32::total_cmp);
    let k = ((v.len() as f32) * trim.clamp(0.0, 0.49)).floor() as usize;
    let kept = &v[k..v.len() - k];
    Some(kept.iter().map(|&x| x as f64).sum::<f64>() as f32 / kept.len() as f32)
}

/// The median absolute deviation scaled to a Gaussian σ (× 1.4826).
pub fn mad_sigma(v: &[f32]) -> Option<f32> {
    let mut w = v.to_vec();
    let m = median(&mut w)?;
    for x in &mut w {
        *x = (*x - m).abs();
    }
    Some(1.4826 * median(&mut w)?)
}

/// A plane v = a + b x + c y over image coordinates.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Plane {
    pub a: f32,
    pub b: f32,
    pub c: f32,
}

impl Plane {
    #[inline]
    pub fn at(&self, x: f32, y: f32) -> f32 {
        self.a + self.b * x + self.c * y
    }
}

/// Least-squares plane through (x, y, v) points (coordinates in pixels). Falls back to the
/// constant mean when the points are (nearly) collinear.
pub fn fit_plane(pts: &[(f32, f32, f32)]) -> Option<Plane> {
    if pts.is_empty() {
        return None;
    }
    // Centre the coordinates for conditioning.
    let n = pts.len() as f64;
    let (mx, my) = pts.iter().fold((0.0, 0.0), |(sx, sy), p| {
        (sx + p.0 as f64 / n, sy + p.1 as f64 / n)
    });
    let (mut sxx, mut sxy, mut syy, mut sv, mut sxv, mut syv) = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0);
    for &(x, y, v) in pts {
        let (x, y, v) = (x as f64 - mx, y as f64 - my, v as f64);
        sxx += x * x;
        sxy += x * y;
        syy += y * y;
        sv += v;
        sxv += x * v;
        syv += y * v;
    }
    let mean = sv / n;
    let det = sxx * syy - sxy * sxy;
    let (b, c) = if det > 1e-9 * (sxx * syy).max(1e-30) && pts.len() >= 3 {
        ((sxv * syy - syv * sxy) / det, (syv * sxx - sxv * sxy) / det)
    } else {
        (0.0, 0.0)
    };
    Some(Plane {
        a: (mean - b * mx - c * my) as f32,
        b: b as f32,
        c: c as f32,
    })
}

/// The planar approximation with outlier rejection: fits a plane, drops the points whose
/// residual exceeds `k` robust σ (MAD of the residuals, at least `min_sigma`), refits, and repeats
/// until nothing changes (at most 5 rounds). Returns the plane and a flag per point (true =
/// inlier). With fewer than 8 points everything is kept.
pub fn planar_inliers(
    pts: &[(f32, f32, f32)],
    k: f32,
    min_sigma: f32,
) -> (Option<Plane>, Vec<bool>) {
    let mut keep = vec![true; pts.len()];
    if pts.len() < 8 {
        return (fit_plane(pts), keep);
    }
    let mut plane = fit_plane(pts);
    for _ in 0..5 {
        let Some(p) = plane else { break };
        let res: Vec<f32> = pts.iter().map(|&(x, y, v)| v - p.at(x, y)).collect();
        let kept_res: Vec<f32> = res
            .iter()
            .zip(&keep)
            .filter(|(_, &k)| k)
            .map(|(r, _)| *r)
            .collect();
        let sigma = mad_sigma(&kept_res).unwrap_or(0.0).max(min_sigma);
        let new_keep: Vec<bool> = res.iter().map(|r| r.abs() <= k * sigma).collect();
        if new_keep.iter().filter(|&&b| b).count() < 3 {
            break;
        }
        let changed = new_keep != keep;
        keep = new_keep;
        let kept: Vec<(f32, f32, f32)> = pts
            .iter()
            .zip(&keep)
            .filter(|(_, &k)| k)
            .map(|(p, _)| *p)
            .collect();
        plane = fit_plane(&kept);
        if !changed {
            break;
        }
    }
    (plane, keep)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn medians_and_means() {
        assert_eq!(median(&mut [3.0, 1.0, 2.0]), Some(2.0));
        assert_eq!(median(&mut [4.0, 1.0, 3.0, 2.0]), Some(2.5));
        assert_eq!(median(&mut []), None);
        let mut v = vec![1.0, 2.0, 3.0, 4.0, 1000.0];
        assert_eq!(trimmed_mean(&mut v, 0.2), Some(3.0));
        let s = mad_sigma(&[1.0, 2.0, 3.0, 4.0, 5.0, 1e6]).unwrap();
        assert!((s - 1.4826 * 1.5).abs() < 1e-4, "{s}");
    }

    #[test]
    fn plane_rejects_an_unmodelled_blob() {
        // A gradient 1 + 0.01 x − 0.02 y over 40×30 pixels with a bright 5×5 "book".
        let mut pts = Vec::new();
        for y in 0..30 {
            for x in 0..40 {
                let mut v = 1.0 + 0.01 * x as f32 - 0.02 * y as f32;
                v += 0.002 * (((x * 7 + y * 13) % 5) as f32 - 2.0);
                if (10..15).contains(&x) && (10..15).contains(&y) {
                    v += 0.5;
                }
                pts.push((x as f32, y as f32, v));
            }
        }
        let (p, keep) = planar_inliers(&pts, 3.5, 1e-3);
        let p = p.unwrap();
        assert!(
            (p.b - 0.01).abs() < 1e-3 && (p.c + 0.02).abs() < 1e-3,
            "{p:?}"
        );
        for (i, &(x, y, _)) in pts.iter().enumerate() {
            let book = (10.0..15.0).contains(&x) && (10.0..15.0).contains(&y);
            assert_eq!(keep[i], !book, "({x}, {y})");
        }
    }
}
