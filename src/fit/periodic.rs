//! A repeating print (a wallpaper, tiles, a woven fabric) carried from the texels the photo
//! shows to those it does not, on one chart of a textured group's atlas.
//!
//! A texel no pixel sees is otherwise filled from its seen neighbours, fading to its object's
//! mean (`texture::fill_unseen`): right for a painting, whose detail does not repeat, but a
//! papered wall seen only in a strip comes out plain over the rest, and a new view shows it
//! plain. Where the seen texels repeat, the repeat says what the unseen ones hold.
//!
//! The lattice: the normalised autocorrelation of the seen texels' luminance,
//!   C(d) = Σ y(p) y(p+d) / √(Σ y(p)² Σ y(p+d)²)   (y: luminance minus its mean; sums over the
//!   pairs both seen),
//! over displacements up to [`REACH`] texels. Its local maxima above [`MIN_PEAK`], refined to a
//! fraction of a texel by a parabola through each axis' neighbours, are the lattice's points;
//! the shortest is d₁, the shortest one not along d₁ is d₂, each then refined by the peaks at its
//! multiples (a print that repeats along one direction only, whose correlation is a ridge with
//! no second peak, is left alone). The chart's atlas axes are fixed by the world's up direction
//! and its texels are square, so a print's lattice is the same in every chart of one orientation.
//!
//! The tile: every seen texel p falls at the fractional coordinates f = frac(A⁻¹ p), A = [d₁ d₂],
//! of one lattice cell; a grid of about a texel per bin over the cell averages them. Many cells'
//! texels go into each bin, so the tile holds the print with their noise averaged down, and an
//! unseen texel takes its bin's mean. The phase is the chart's own (its seen texels set it), so
//! a chart seen nowhere keeps its mean: with the phase unknown the mean is the fill of least
//! expected error.
//!
//! The check (a repeat is believed only where it predicts): the cells are split by the parity
//! of ⌊f₁⌋ + ⌊f₂⌋; a tile built from one half predicts the other half's seen texels and the other
//! way round. It is used only if that explains at least [`MIN_EXPLAINED`] of their variance about
//! the chart's mean (R²): a painting, a gradient or a print with noise as strong as its contrast
//! fails and keeps the fill from the neighbours and the mean.

use crate::math::{luminance_mean, Rgb};

/// The longest lattice vector looked for, texels.
pub const REACH: i32 = 24;
/// The shortest: a displacement of a texel or two correlates through the smoothing alone.
const SHORTEST: f32 = 2.5;
/// A lattice point's normalised autocorrelation at least.
pub const MIN_PEAK: f32 = 0.5;
/// The held-out share of variance the tile must explain. Any share above 0 predicts the unseen
/// texels better than the mean does; the margin keeps a chance lattice out. (The faint print
/// of `tests/texture.rs`, ±10% diamonds six texels apart, explains 0.51–0.54.)
pub const MIN_EXPLAINED: f32 = 0.3;
/// Pairs a displacement's correlation is computed from at least.
const MIN_PAIRS: usize = 64;
/// Lattice cells' worth of seen texels needed before a repeat is looked for.
const MIN_CELLS: f32 = 3.0;
/// Seen texels, about, that the autocorrelation takes its pairs' origins from.
const MAX_ORIGINS: usize = 16384;
/// Seen texels per bin of a half-texel tile (`Lattice::bins`).
const PER_BIN: f32 = 4.0;

/// A print's lattice on a chart: two vectors in texels (x right, y down).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Lattice {
    pub d1: [f32; 2],
    pub d2: [f32; 2],
}

impl Lattice {
    /// The cell area in texels.
    fn area(&self) -> f32 {
        (self.d1[0] * self.d2[1] - self.d1[1] * self.d2[0]).abs()
    }

    /// Fractional cell coordinates of the point (x, y), and the cell's integer index.
    fn coords(&self, x: f32, y: f32) -> ([f32; 2], [i64; 2]) {
        let det = self.d1[0] * self.d2[1] - self.d1[1] * self.d2[0];
        let a = (x * self.d2[1] - y * self.d2[0]) / det;
        let b = (self.d1[0] * y - self.d1[1] * x) / det;
        (
            [a - a.floor(), b - b.floor()],
            [a.floor() as i64, b.floor() as i64],
        )
    }

    /// Bins per cell axis for `n` seen texels: half a texel each where there are at least
    /// [`PER_BIN`] texels per bin of the held-out halves (a print's edges stay sharp: a
    /// period that is not a whole number of texels samples its cell at many offsets), else
    /// a texel each.
    fn bins(&self, n: usize) -> [usize; 2] {
        let fine = n as f32 / 2.0 >= PER_BIN * 4.0 * self.area();
        let k = if fine { 2.0 } else { 1.0 };
        let len = |d: [f32; 2]| ((k * d[0].hypot(d[1])).round() as usize).max(1);
        [len(self.d1), len(self.d2)]
    }
}

/// The print carried over a chart, when its seen texels repeat.
#[derive(Clone, Debug)]
pub struct Repeat {
    pub lattice: Lattice,
    /// The held-out share of variance the tile explained.
    pub explained: f32,
    /// Per texel of the chart (row-major, w × h): the tile's value there, None where its bin
    /// holds no seen texel.
    pub fill: Vec<Option<Rgb>>,
}

/// The repeat of a w × h chart's seen texels, if they repeat (module comment). `img` is the
/// chart as `texture::fill_unseen` holds it for pull–push: each texel's value and weight, a
/// weight above 0 where the photo saw it.
pub fn find(img: &[(Rgb, f32)], w: usize, h: usize) -> Option<Repeat> {
    let n_seen = img.iter().filter(|p| seen(p)).count();
    let lattice = lattice(img, w, h)?;
    if (n_seen as f32) < MIN_CELLS * lattice.area() {
        return None;
    }
    let bins = lattice.bins(n_seen);
    let explained = held_out_explained(img, w, &lattice, bins)?;
    if explained < MIN_EXPLAINED {
        return None;
    }
    let tile = Tile::of(img, w, &lattice, bins, None);
    let fill = (0..w * h)
        .map(|i| tile.at(&lattice, (i % w) as f32 + 0.5, (i / w) as f32 + 0.5))
        .collect();
    Some(Repeat {
        lattice,
        explained,
        fill,
    })
}

/// Whether a texel of a chart image (value, weight) was seen.
fn seen(p: &(Rgb, f32)) -> bool {
    p.1 > 0.0
}

/// The lattice of the seen texels' repeat (module comment), if two independent directions
/// repeat.
pub fn lattice(img: &[(Rgb, f32)], w: usize, h: usize) -> Option<Lattice> {
    let lum: Vec<Option<f32>> = img
        .iter()
        .map(|p| seen(p).then(|| luminance_mean(p.0)))
        .collect();
    let n_seen = lum.iter().flatten().count();
    if n_seen < MIN_PAIRS {
        return None;
    }
    let mean = lum.iter().flatten().map(|&l| l as f64).sum::<f64>() / n_seen as f64;
    let y: Vec<Option<f32>> = lum.iter().map(|l| l.map(|l| l - mean as f32)).collect();
    let r = REACH.min(w as i32 - 1).min(h as i32 - 1).max(0);
    if r < 3 {
        return None;
    }
    // C over the displacements (dx, dy), |dx|, |dy| ≤ r; C(−d) = C(d), so only dy ≥ 0 is summed.
    // On a large chart every `stride`-th row of pair origins is enough for the statistic and
    // bounds the cost (each displacement sums over the chart).
    let stride = n_seen.div_ceil(MAX_ORIGINS).max(1);
    let side = (2 * r + 1) as usize;
    let mut c = vec![f32::NAN; side * side];
    let at = |dx: i32, dy: i32| ((dy + r) as usize) * side + (dx + r) as usize;
    for dy in 0..=r {
        for dx in -r..=r {
            if dy == 0 && dx < 0 {
                continue;
            }
            let (mut xy, mut xx, mut yy, mut n) = (0.0f64, 0.0f64, 0.0f64, 0usize);
            for py in (0..h as i32 - dy).step_by(stride) {
                for px in (-dx).max(0)..(w as i32).min(w as i32 - dx) {
                    let (Some(a), Some(b)) = (
                        y[py as usize * w + px as usize],
                        y[(py + dy) as usize * w + (px + dx) as usize],
                    ) else {
                        continue;
                    };
                    xy += (a * b) as f64;
                    xx += (a * a) as f64;
                    yy += (b * b) as f64;
                    n += 1;
                }
            }
            let v = if n >= MIN_PAIRS && xx > 0.0 && yy > 0.0 {
                (xy / (xx * yy).sqrt()) as f32
            } else {
                f32::NAN
            };
            c[at(dx, dy)] = v;
            c[at(-dx, -dy)] = v;
        }
    }
    // Local maxima (8 neighbours) above MIN_PEAK, refined by parabolas.
    let mut peaks: Vec<[f32; 2]> = Vec::new();
    for dy in 0..=r {
        for dx in -r..=r {
            let v = c[at(dx, dy)];
            if !(v >= MIN_PEAK) || ((dx * dx + dy * dy) as f32) < SHORTEST * SHORTEST {
                continue;
            }
            if dy == 0 && dx < 0 {
                continue;
            }
            let mut top = true;
            for (ex, ey) in [(-1, -1), (0, -1), (1, -1), (-1, 0), (1, 0), (-1, 1), (0, 1), (1, 1)] {
                let (nx, ny) = (dx + ex, dy + ey);
                if nx.abs() > r || ny.abs() > r {
                    continue;
                }
                if c[at(nx, ny)] > v {
                    top = false;
                }
            }
            if !top {
                continue;
            }
            let offset = |lo: f32, hi: f32| {
                let den = lo - 2.0 * v + hi;
                if lo.is_finite() && hi.is_finite() && den < 0.0 {
                    (0.5 * (lo - hi) / den).clamp(-0.5, 0.5)
                } else {
                    0.0
                }
            };
            let get = |x: i32, y: i32| {
                if x.abs() <= r && y.abs() <= r {
                    c[at(x, y)]
                } else {
                    f32::NAN
                }
            };
            let ox = offset(get(dx - 1, dy), get(dx + 1, dy));
            let oy = offset(get(dx, dy - 1), get(dx, dy + 1));
            peaks.push([dx as f32 + ox, dy as f32 + oy]);
        }
    }
    let len = |d: &[f32; 2]| d[0].hypot(d[1]);
    peaks.sort_by(|a, b| len(a).total_cmp(&len(b)));
    let d1 = *peaks.first()?;
    // Not along d₁: at least 20° away (sin 20° ≈ 0.34).
    let d2 = *peaks
        .iter()
        .find(|d| (d1[0] * d[1] - d1[1] * d[0]).abs() >= 0.34 * len(&d1) * len(d))?;
    Some(Lattice {
        d1: by_multiples(d1, &peaks),
        d2: by_multiples(d2, &peaks),
    })
}

/// A lattice vector refined by its multiples among the peaks: d = Σ k pₖ / Σ k², pₖ the peak
/// within a texel of k·d. A peak's parabola is good to a tenth of a texel or so, and that error
/// adds up over the tens of periods a fill reaches; at k periods it is divided by k.
fn by_multiples(d: [f32; 2], peaks: &[[f32; 2]]) -> [f32; 2] {
    let (mut sx, mut sy, mut kk) = (0.0f32, 0.0f32, 0.0f32);
    for k in 1..=8 {
        let target = [k as f32 * d[0], k as f32 * d[1]];
        let near = (peaks.iter().copied())
            .chain(peaks.iter().map(|p| [-p[0], -p[1]]))
            .map(|p| (p, (p[0] - target[0]).hypot(p[1] - target[1])))
            .filter(|(_, e)| *e < 1.0)
            .min_by(|a, b| a.1.total_cmp(&b.1));
        if let Some((p, _)) = near {
            sx += k as f32 * p[0];
            sy += k as f32 * p[1];
            kk += (k * k) as f32;
        }
    }
    if kk > 0.0 {
        [sx / kk, sy / kk]
    } else {
        d
    }
}

/// Mean of the seen texels per bin of a lattice cell.
struct Tile {
    bins: [usize; 2],
    sums: Vec<(Rgb, u32)>,
}

impl Tile {
    /// From the seen texels of the cells of parity `parity` (all cells: None), in `bins`
    /// (`Lattice::bins`).
    fn of(
        img: &[(Rgb, f32)],
        w: usize,
        lattice: &Lattice,
        bins: [usize; 2],
        parity: Option<i64>,
    ) -> Tile {
        let mut sums = vec![(Rgb::ZERO, 0u32); bins[0] * bins[1]];
        for (i, p) in img.iter().enumerate() {
            if !seen(p) {
                continue;
            }
            let (f, cell) = lattice.coords((i % w) as f32 + 0.5, (i / w) as f32 + 0.5);
            if parity.is_some_and(|q| (cell[0] + cell[1]).rem_euclid(2) != q) {
                continue;
            }
            let b = Self::bin(bins, f);
            sums[b].0 += p.0;
            sums[b].1 += 1;
        }
        Tile { bins, sums }
    }

    fn bin(bins: [usize; 2], f: [f32; 2]) -> usize {
        let k = |x: f32, n: usize| ((x * n as f32) as usize).min(n - 1);
        k(f[1], bins[1]) * bins[0] + k(f[0], bins[0])
    }

    fn at(&self, lattice: &Lattice, x: f32, y: f32) -> Option<Rgb> {
        let (f, _) = lattice.coords(x, y);
        let (sum, n) = self.sums[Self::bin(self.bins, f)];
        (n > 0).then(|| sum / n as f32)
    }
}

/// The share of the seen texels' variance about their mean that tiles built from the other
/// parity's cells explain (module comment). None if too few texels are predicted.
fn held_out_explained(
    img: &[(Rgb, f32)],
    w: usize,
    lattice: &Lattice,
    bins: [usize; 2],
) -> Option<f32> {
    let values: Vec<Rgb> = img.iter().filter(|p| seen(p)).map(|p| p.0).collect();
    let mean = values.iter().fold(Rgb::ZERO, |a, &b| a + b) / values.len() as f32;
    let tiles = [
        Tile::of(img, w, lattice, bins, Some(0)),
        Tile::of(img, w, lattice, bins, Some(1)),
    ];
    let (mut res, mut tot, mut n) = (0.0f64, 0.0f64, 0usize);
    for (i, p) in img.iter().enumerate() {
        if !seen(p) {
            continue;
        }
        let (x, y) = ((i % w) as f32 + 0.5, (i / w) as f32 + 0.5);
        let (_, cell) = lattice.coords(x, y);
        let other = &tiles[1 - (cell[0] + cell[1]).rem_euclid(2) as usize];
        let Some(t) = other.at(lattice, x, y) else {
            continue;
        };
        let sq = |v: Rgb| (v.x * v.x + v.y * v.y + v.z * v.z) as f64;
        res += sq(p.0 - t);
        tot += sq(p.0 - mean);
        n += 1;
    }
    (n * 2 >= values.len() && tot > 0.0).then(|| (1.0 - res / tot) as f32)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A chart image with seen texels weighed 1 and unseen 0, as `fill_unseen` holds it.
    fn weighed(img: &[(Rgb, bool)]) -> Vec<(Rgb, f32)> {
        img.iter().map(|&(v, s)| (v, f32::from(u8::from(s)))).collect()
    }

    /// A print of diamonds on a skewed lattice, seen in a band: its lattice is found to a tenth
    /// of a texel, the check passes, and the fill reproduces the unseen texels.
    #[test]
    fn a_repeating_print_seen_in_a_band_fills_the_rest() {
        let (w, h) = (80usize, 60usize);
        let (d1, d2) = ([7.3f32, 0.0], [3.65f32, 6.1]);
        let truth = |x: f32, y: f32| {
            let l = Lattice { d1, d2 };
            let (f, _) = l.coords(x, y);
            let dist = (f[0] - 0.5).abs() + (f[1] - 0.5).abs();
            if dist < 0.3 {
                Rgb::new(0.1, 0.2, 0.6)
            } else {
                Rgb::new(0.8, 0.75, 0.7)
            }
        };
        let mut rng = 12345u64;
        let mut noise = || {
            rng = rng.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            ((rng >> 40) as f32 / (1u64 << 24) as f32 - 0.5) * 0.1
        };
        let img: Vec<(Rgb, bool)> = (0..w * h)
            .map(|i| {
                let (x, y) = ((i % w) as f32 + 0.5, (i / w) as f32 + 0.5);
                // Seen: a diagonal band across the chart.
                let seen = ((x - 1.2 * y) as i32).abs() < 14;
                (truth(x, y) + Rgb::splat(noise()), seen)
            })
            .collect();
        let rep = find(&weighed(&img), w, h).expect("a repeat");
        let l = rep.lattice;
        // Any basis of the same lattice will do: both vectors are lattice points to a tenth
        // of a texel, and they span a cell of the true area.
        let truth_lattice = Lattice { d1, d2 };
        for d in [l.d1, l.d2] {
            let (f, _) = truth_lattice.coords(d[0], d[1]);
            let off = |x: f32| x.min(1.0 - x);
            let err = off(f[0]) * d1[0].hypot(d1[1]) + off(f[1]) * d2[0].hypot(d2[1]);
            assert!(err < 0.1 * 2.0, "{l:?}");
        }
        assert!((l.area() - 7.3 * 6.1).abs() < 0.05 * 7.3 * 6.1, "{l:?}");
        assert!(rep.explained > 0.7, "{}", rep.explained);
        // The unseen texels: the fill against the truth, against the mean's error.
        let (mut fill_err, mut mean_err, mut n) = (0.0f32, 0.0f32, 0);
        let mean = Rgb::new(0.6, 0.6, 0.68);
        for (i, p) in img.iter().enumerate() {
            if p.1 {
                continue;
            }
            let (x, y) = ((i % w) as f32 + 0.5, (i / w) as f32 + 0.5);
            let t = truth(x, y);
            if let Some(f) = rep.fill[i] {
                fill_err += (f - t).abs().max_element();
                mean_err += (mean - t).abs().max_element();
                n += 1;
            }
        }
        let unseen = img.iter().filter(|p| !p.1).count();
        assert!(n * 10 >= unseen * 9, "{n} of {unseen} filled");
        assert!(fill_err < 0.3 * mean_err, "{fill_err} vs the mean's {mean_err}");
    }

    /// What looking for a repeat costs on a large chart (a 4 × 3 m wall at 1-cm texels, a
    /// third of it seen), printed: `cargo test --profile ci -p matfit --features internals --lib
    /// periodic_costs -- --ignored --nocapture`.
    #[test]
    #[ignore]
    fn periodic_costs() {
        let (w, h) = (400usize, 300usize);
        let img: Vec<(Rgb, bool)> = (0..w * h)
            .map(|i| {
                let (x, y) = ((i % w) as f32, (i / w) as f32);
                let v = 0.5 + 0.3 * (x * 0.9).sin() * (y * 0.9).sin();
                (Rgb::splat(v), ((x - y) as i32).abs() < 70)
            })
            .collect();
        let img = weighed(&img);
        let t = std::time::Instant::now();
        let runs = 5;
        for _ in 0..runs {
            assert!(find(&img, w, h).is_some());
        }
        eprintln!(
            "{w}x{h} chart, {} seen: {:.1} ms per search",
            img.iter().filter(|p| seen(p)).count(),
            1e3 * t.elapsed().as_secs_f64() / runs as f64
        );
    }

    /// What does not repeat keeps today's fill: a smooth gradient, a painting-like random
    /// arrangement of blocks, and noise alone.
    #[test]
    fn what_does_not_repeat_is_left_alone() {
        let (w, h) = (64usize, 48usize);
        let mut rng = 99u64;
        let mut next = || {
            rng = rng.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (rng >> 40) as f32 / (1u64 << 24) as f32
        };
        let gradient: Vec<(Rgb, bool)> = (0..w * h)
            .map(|i| (Rgb::splat((i % w) as f32 / w as f32), i % w < 40))
            .collect();
        assert!(find(&weighed(&gradient), w, h).is_none());
        let blocks: Vec<[f32; 5]> = (0..12)
            .map(|_| [next() * 56.0, next() * 40.0, 3.0 + 10.0 * next(), 3.0 + 10.0 * next(), next()])
            .collect();
        let painting: Vec<(Rgb, bool)> = (0..w * h)
            .map(|i| {
                let (x, y) = ((i % w) as f32, (i / w) as f32);
                let v = (blocks.iter().rev())
                    .find(|b| x >= b[0] && x < b[0] + b[2] && y >= b[1] && y < b[1] + b[3])
                    .map_or(0.5, |b| b[4]);
                (Rgb::new(v, 0.5 * v, 1.0 - v), y < 30.0)
            })
            .collect();
        assert!(find(&weighed(&painting), w, h).is_none());
        let noise: Vec<(Rgb, bool)> = (0..w * h).map(|_| (Rgb::splat(next()), true)).collect();
        assert!(find(&weighed(&noise), w, h).is_none());
    }
}
