//! Solvers of the fit: the per-channel bounded least squares that gives ρd and ρs for a fixed
//! lobe shape (variable projection, docs/DESIGN.md, "Making it fast" 2), and a small
//! Levenberg–Marquardt loop for the lobe shape itself.

use crate::scene::RhoBound;

/// Sufficient statistics of one channel's least-squares problem
/// min Σ (ρd d + ρs s − p)² over the pixels, where d and s are Monte Carlo estimates.
///
/// Noise in the regressors biases plain least squares towards zero (errors in variables:
/// Σ d² = Σ E[d]² + Σ var d), badly so with the heavy-tailed noise of caustic paths. The cache
/// holds two independent half estimates of d and s per pixel, so the quadratic terms are built
/// from cross-half products, Σ d₀ d₁ etc., whose expectations are the noise-free Σ E[d]². The
/// cost is then an unbiased estimate of the noise-free cost (up to a constant) and can be
/// negative.
#[derive(Clone, Copy, Debug, Default)]
pub struct Moments {
    pub dd: f64,
    pub ds: f64,
    pub ss: f64,
    /// Σ ½(s₀² + s₁²): the lobe's energy as each half sees it alone (see [`Moments::ss_eff`]).
    pub ss_self: f64,
    pub dp: f64,
    pub sp: f64,
    pub pp: f64,
}

impl Moments {
    /// Adds a pixel from the two half estimates of d and s and the photo value p.
    #[inline]
    pub fn add(&mut self, d: [f32; 2], s: [f32; 2], p: f32) {
        let (d0, d1, s0, s1, p) = (d[0] as f64, d[1] as f64, s[0] as f64, s[1] as f64, p as f64);
        let (dm, sm) = (0.5 * (d0 + d1), 0.5 * (s0 + s1));
        self.dd += d0 * d1;
        self.ds += 0.5 * (d0 * s1 + d1 * s0);
        self.ss += s0 * s1;
        self.ss_self += 0.5 * (s0 * s0 + s1 * s1);
        self.dp += dm * p;
        self.sp += sm * p;
        self.pp += p * p;
    }

    /// Adds a pixel whose d and s are exact (no noise).
    #[inline]
    pub fn add_exact(&mut self, d: f32, s: f32, p: f32) {
        self.add([d, d], [s, s], p);
    }

    /// The quadratic specular moment the solve uses: the cross-half Σ s₀ s₁, but never below
    /// half of Σ ½(s₀² + s₁²). A lobe much narrower than the spacing of the cache's directions
    /// is seen by one half's samples and not the other's, so Σ s₀ s₁ ≈ 0 while the lobe's
    /// energy is not: with the cross product alone the cost would fall without bound as ρs
    /// grows, and the narrowest lobe would win every fit (α jumping to its lower bound from one
    /// iteration to the next). A lobe the halves agree on (Σ s₀ s₁ close to the self products)
    /// is unaffected, so the errors-in-variables correction stands where the cache resolves the
    /// lobe.
    pub fn ss_eff(&self) -> f64 {
        self.ss.max(0.5 * self.ss_self)
    }

    /// Σ (ρd d + ρs s − p)², noise-free estimate.
    pub fn cost(&self, rd: f64, rs: f64) -> f64 {
        self.pp - 2.0 * (rd * self.dp + rs * self.sp)
            + rd * rd * self.dd
            + 2.0 * rd * rs * self.ds
            + rs * rs * self.ss_eff()
    }
}

/// Which reflectances are free.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Free {
    /// ρd only (ρs = 0).
    Diffuse,
    /// ρs only (ρd = 0).
    Specular,
    /// Both, within the model's bound on them: the triangle ρd + ρs ≤ 1, or the square
    /// ρd, ρs ≤ 1.
    Both(RhoBound),
}

/// The (ρd, ρs) minimising the channel's cost within 0 ≤ ρd, ρs and the bound. The problem is
/// a convex quadratic in two variables: the optimum is the unconstrained one if feasible, else
/// the best of the optima on the edges of the feasible triangle (or square).
pub fn solve_rho(m: &Moments, free: Free) -> (f64, f64) {
    let ss = m.ss_eff();
    let edge_d = || {
        if m.dd > 0.0 {
            (m.dp / m.dd).clamp(0.0, 1.0)
        } else {
            0.0
        }
    };
    let edge_s = || {
        if ss > 0.0 {
            (m.sp / ss).clamp(0.0, 1.0)
        } else {
            0.0
        }
    };
    match free {
        Free::Diffuse => (edge_d(), 0.0),
        Free::Specular => (0.0, edge_s()),
        Free::Both(bound) => {
            let det = m.dd * ss - m.ds * m.ds;
            if det > 1e-12 * (m.dd * ss).max(1e-300) {
                let rd = (m.dp * ss - m.sp * m.ds) / det;
                let rs = (m.sp * m.dd - m.dp * m.ds) / det;
                if rd >= 0.0 && rs >= 0.0 && bound.reach(rd, rs) <= 1.0 {
                    return (rd, rs);
                }
            }
            // Edges: ρs = 0, ρd = 0, then the bound's.
            let a = (edge_d(), 0.0);
            let b = (0.0, edge_s());
            let bound_edges = match bound {
                RhoBound::Sum => {
                    // ρd + ρs = 1: ρd = t, ρs = 1 − t.
                    let den = m.dd - 2.0 * m.ds + ss;
                    let t = if den > 0.0 {
                        ((m.dp - m.sp - m.ds + ss) / den).clamp(0.0, 1.0)
                    } else {
                        0.0
                    };
                    [Some((t, 1.0 - t)), None]
                }
                RhoBound::Each => {
                    // ρd = 1 (ρs free), ρs = 1 (ρd free).
                    let rs = if ss > 0.0 {
                        ((m.sp - m.ds) / ss).clamp(0.0, 1.0)
                    } else {
                        0.0
                    };
                    let rd = if m.dd > 0.0 {
                        ((m.dp - m.ds) / m.dd).clamp(0.0, 1.0)
                    } else {
                        0.0
                    };
                    [Some((1.0, rs)), Some((rd, 1.0))]
                }
            };
            [Some(a), Some(b)]
                .into_iter()
                .chain(bound_edges)
                .flatten()
                .min_by(|x, y| m.cost(x.0, x.1).total_cmp(&m.cost(y.0, y.1)))
                .unwrap()
        }
    }
}

/// One evaluation of a nonlinear least-squares objective at a parameter vector: the cost and
/// the Gauss–Newton normal equations JᵀJ, Jᵀr.
pub struct Linearisation<const N: usize> {
    pub cost: f64,
    pub jtj: [[f64; N]; N],
    pub jtr: [f64; N],
}

/// Solves the N×N system A x = b by Gaussian elimination with partial pivoting.
fn solve_dense<const N: usize>(mut a: [[f64; N]; N], mut b: [f64; N]) -> Option<[f64; N]> {
    for col in 0..N {
        let piv = (col..N).max_by(|&i, &j| a[i][col].abs().total_cmp(&a[j][col].abs()))?;
        if a[piv][col].abs() < 1e-300 {
            return None;
        }
        a.swap(col, piv);
        b.swap(col, piv);
        for row in col + 1..N {
            let f = a[row][col] / a[col][col];
            for k in col..N {
                a[row][k] -= f * a[col][k];
            }
            b[row] -= f * b[col];
        }
    }
    let mut x = [0.0; N];
    for row in (0..N).rev() {
        let s: f64 = (row + 1..N).map(|k| a[row][k] * x[k]).sum();
        x[row] = (b[row] - s) / a[row][row];
    }
    Some(x)
}

/// The step below which [`levenberg_marquardt`] stops. Its parameters are roughnesses' logarithms
/// and angles in radians, so this is 0.01% of α and 0.006° of θ: far below what one cache
/// determines, and above the steps whose change of cost the f32 sums can no longer resolve.
const STEP_TOLERANCE: f64 = 1e-4;

/// Levenberg–Marquardt (Marquardt's diagonal scaling) from `x0`, with `eval` returning the
/// linearisation at a point and `project` mapping a point into the feasible box. Returns the
/// best point, its cost and the number of evaluations.
pub fn levenberg_marquardt<const N: usize>(
    x0: [f64; N],
    mut eval: impl FnMut(&[f64; N]) -> Linearisation<N>,
    project: impl Fn([f64; N]) -> [f64; N],
    max_evals: u32,
) -> ([f64; N], f64, u32) {
    let mut x = project(x0);
    let mut lin = eval(&x);
    let mut evals = 1;
    let mut lambda = 1e-3;
    while evals < max_evals {
        let mut a = lin.jtj;
        for (i, row) in a.iter_mut().enumerate() {
            row[i] += lambda * lin.jtj[i][i].max(1e-12);
        }
        let b = lin.jtr.map(|v| -v);
        let Some(step) = solve_dense(a, b) else { break };
        let mut trial = x;
        for i in 0..N {
            trial[i] += step[i];
        }
        let trial = project(trial);
        let moved = (0..N).map(|i| (trial[i] - x[i]).abs()).fold(0.0, f64::max);
        if moved < STEP_TOLERANCE {
            break;
        }
        let t = eval(&trial);
        evals += 1;
        if t.cost < lin.cost {
            let rel = (lin.cost - t.cost) / lin.cost.max(1e-300);
            x = trial;
            lin = t;
            lambda = (lambda / 3.0).max(1e-9);
            if rel < 1e-9 {
                break;
            }
        } else {
            lambda *= 4.0;
            if lambda > 1e9 {
                break;
            }
        }
    }
    (x, lin.cost, evals)
}

/// Inverse of a small symmetric positive matrix by Gauss–Jordan; None when singular.
pub fn invert(a: &[Vec<f64>]) -> Option<Vec<Vec<f64>>> {
    let n = a.len();
    let scale = (0..n).map(|i| a[i][i].abs()).fold(0.0, f64::max);
    if !(scale > 0.0) || !scale.is_finite() {
        return None;
    }
    let mut m: Vec<Vec<f64>> = a.to_vec();
    let mut inv: Vec<Vec<f64>> = (0..n)
        .map(|i| (0..n).map(|j| (i == j) as u8 as f64).collect())
        .collect();
    for c in 0..n {
        let p = (c..n).max_by(|&i, &j| m[i][c].abs().total_cmp(&m[j][c].abs()))?;
        if m[p][c].abs() <= 1e-12 * scale {
            return None;
        }
        m.swap(c, p);
        inv.swap(c, p);
        let d = m[c][c];
        for j in 0..n {
            m[c][j] /= d;
            inv[c][j] /= d;
        }
        for i in 0..n {
            if i != c {
                let f = m[i][c];
                for j in 0..n {
                    m[i][j] -= f * m[c][j];
                    inv[i][j] -= f * inv[c][j];
                }
            }
        }
    }
    Some(inv)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bounded_rho_recovers_truth_and_respects_bounds() {
        let mut m = Moments::default();
        for i in 0..100 {
            let d = 1.0 + (i as f32 * 0.37).sin();
            let s = (i as f32 * 0.11).cos().abs() * 3.0;
            m.add_exact(d, s, 0.3 * d + 0.6 * s);
        }
        let (rd, rs) = solve_rho(&m, Free::Both(RhoBound::Sum));
        assert!(
            (rd - 0.3).abs() < 1e-6 && (rs - 0.6).abs() < 1e-6,
            "{rd} {rs}"
        );
        // Truth outside the triangle: the answer lies on ρd + ρs = 1.
        let mut m = Moments::default();
        for i in 0..100 {
            let d = 1.0 + (i as f32 * 0.37).sin();
            let s = (i as f32 * 0.11).cos().abs();
            m.add_exact(d, s, 0.9 * d + 0.9 * s);
        }
        let (rd, rs) = solve_rho(&m, Free::Both(RhoBound::Sum));
        assert!(
            rd >= 0.0 && rs >= 0.0 && (rd + rs - 1.0).abs() < 1e-9,
            "{rd} {rs}"
        );
    }

    /// A coated model's square ρd, ρs ≤ 1 holds a truth the triangle cuts off, and meets one
    /// outside it on its edge ρd = 1 with ρs still fitted.
    #[test]
    fn the_square_bound_reaches_a_plastics_reflectances() {
        let moments = |rd: f32, rs: f32| {
            let mut m = Moments::default();
            for i in 0..100 {
                let d = 1.0 + (i as f32 * 0.37).sin();
                let s = (i as f32 * 0.11).cos().abs();
                m.add_exact(d, s, rd * d + rs * s);
            }
            m
        };
        let (rd, rs) = solve_rho(&moments(0.9, 0.3), Free::Both(RhoBound::Each));
        assert!((rd - 0.9).abs() < 1e-5 && (rs - 0.3).abs() < 1e-5, "{rd} {rs}");
        let (rd, rs) = solve_rho(&moments(0.9, 0.3), Free::Both(RhoBound::Sum));
        assert!((rd + rs - 1.0).abs() < 1e-9, "{rd} {rs}");
        let (rd, rs) = solve_rho(&moments(1.2, 0.3), Free::Both(RhoBound::Each));
        assert!(rd == 1.0 && rs > 0.3 && rs < 1.0, "{rd} {rs}");
    }

    #[test]
    fn cross_half_moments_remove_errors_in_variables_bias() {
        // d has heavy noise, independent in its two halves; plain least squares on the mean
        // is biased low, the cross-half estimator is not.
        let mut rng = crate::math::sampler::TestRng(7);
        let mut rnd = || rng.f32();
        let (mut m, mut plain) = (Moments::default(), Moments::default());
        for i in 0..20000 {
            let d = 1.0 + 0.5 * (i as f32 * 0.01).sin();
            // Rare large outliers: mean-preserving noise d·(x / 0.2) with P(x = 1) = 0.2.
            let noisy = |u: f32| if u < 0.2 { d / 0.2 } else { 0.0 };
            let (d0, d1) = (noisy(rnd()), noisy(rnd()));
            m.add([d0, d1], [0.0, 0.0], 0.6 * d);
            plain.add_exact(0.5 * (d0 + d1), 0.0, 0.6 * d);
        }
        let (rd, _) = solve_rho(&m, Free::Diffuse);
        let (rp, _) = solve_rho(&plain, Free::Diffuse);
        assert!((rd - 0.6).abs() < 0.02, "cross-half {rd}");
        assert!(rp < 0.5, "plain least squares should show the bias: {rp}");
    }

    #[test]
    fn lm_fits_an_exponential() {
        // y = exp(−k x) with k = 1.7, fitted in k from k = 0.2.
        let xs: Vec<f64> = (0..50).map(|i| i as f64 * 0.05).collect();
        let eval = |p: &[f64; 1]| {
            let mut l = Linearisation {
                cost: 0.0,
                jtj: [[0.0]],
                jtr: [0.0],
            };
            for &x in &xs {
                let r = (-p[0] * x).exp() - (-1.7 * x).exp();
                let j = -x * (-p[0] * x).exp();
                l.cost += r * r;
                l.jtj[0][0] += j * j;
                l.jtr[0] += j * r;
            }
            l
        };
        let (k, cost, _) = levenberg_marquardt([0.2], eval, |p| p, 100);
        assert!((k[0] - 1.7).abs() < 1e-4 && cost < 1e-9, "{k:?} {cost}");
    }
}
