//! Usable pixels per group (§3.3 of the notes): the index buffer, minus
//!
//! 0. pixels the user asked to ignore (`--ignore-mask`, [`ignore`](crate::photo::ignore));
//! 1. photo pixels that are not valid (NaN/Inf, negative, saturated: see [`Photo`]);
//! 2. a band of `band` pixels around every boundary between groups, so a model a few pixels
//!    off does not poison a group with its neighbour's pixels (pixels are judged per group, not
//!    per object: a floor split into many objects of one material loses no pixel at its seams);
//! 3. strong photo edges (`edges`) within `edge_reach` pixels of an id boundary, grown by one
//!    pixel: where the model is off by more than the band, the photo's real boundary is an edge
//!    just beyond the band, and the pixels on it belong to the wrong surface;
//! 4. optionally, for planar groups, pixels far from a plane fitted to their log-intensity (the
//!    planar approximation, [`robust::planar_inliers`]): an unmodelled object on a wall or floor.
//!
//! The band's width adapts to each group (thin frames and small objects keep their interior) and
//! sub-pixel coverage replaces it where it narrows to nothing: see [`usable_pixels_covered`].
//!
//! The rim rule. Where an object meets the background (the model sees nothing there: a ball
//! against a dark cloth, a statue against the sky), no other modelled surface can leak into the
//! object's pixels, only the background, whose outline registration aligns: the band there is
//! [`MaskOptions::rim_band`] (1) and the edge test does not apply, since a strong edge just
//! inside a convex object's outline is its own shading (the terminator of a side light), not a
//! neighbour.
//!
//! Step 4 is off unless `planar_groups` names groups: a plane over the intensities of a glossy
//! floor would throw its highlight away as an "outlier", so use it for surfaces known diffuse,
//! or prefer the ratio form in [`estimate`](super::estimate) which compares the photo with a
//! rendering and so keeps highlights the model predicts.

use crate::photo::{edges, robust, Photo};
use crate::render::aov::IndexBuffers;
use crate::scene::Scene;

#[derive(Clone, Debug)]
pub struct MaskOptions {
    /// Half-width, in pixels, of the band removed around every boundary between ids.
    pub band: usize,
    /// Edge detector threshold on |∇ ln Y| in ln units per pixel ([`edges`]); 0 disables it.
    pub edge_threshold: f32,
    /// Strong edges are removed only within this many pixels of an id boundary (elsewhere they
    /// are shadows, texture: signal).
    pub edge_reach: usize,
    /// Groups to which the planar-intensity outlier test applies (index = group); empty = none.
    pub planar_groups: Vec<bool>,
    /// Outlier threshold of the planar test, in robust σ.
    pub planar_k: f32,
    /// The band narrows for a group until it keeps min(`min_usable`, `min_usable_fraction` ×
    /// visible) pixels ([`usable_pixels_covered`]).
    pub min_usable: usize,
    pub min_usable_fraction: f32,
    /// Half-width of the band where an object meets the background (the rim rule, module
    /// comment); at most `band`.
    pub rim_band: usize,
}

impl MaskOptions {
    /// The number of usable pixels the band narrows for, for a group of `visible` pixels.
    pub fn min_keep(&self, visible: usize) -> usize {
        let frac = (self.min_usable_fraction.clamp(0.0, 1.0) as f64 * visible as f64).ceil();
        self.min_usable.min(frac as usize)
    }
}

impl Default for MaskOptions {
    fn default() -> Self {
        MaskOptions {
            band: 2,
            edge_threshold: 0.12,
            edge_reach: 6,
            planar_groups: Vec::new(),
            planar_k: 4.0,
            min_usable: 100,
            min_usable_fraction: 0.5,
            rim_band: 1,
        }
    }
}

/// Why a pixel is not usable.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Reject {
    /// Usable.
    None,
    /// The model sees nothing there.
    Background,
    /// In the user's ignore mask.
    User,
    Invalid,
    Band,
    Edge,
    Outlier,
}

/// Per-group pixel counts: `visible` = `usable` + `rejected`, and `rejected` split by reason.
#[derive(Clone, Debug, Default, PartialEq, Eq, serde::Serialize)]
pub struct GroupPixelStats {
    pub visible: usize,
    pub usable: usize,
    pub rejected: usize,
    /// Rejected because the user's ignore mask covers them.
    pub user: usize,
    /// Rejected because the photo pixel is NaN/Inf, negative or saturated.
    pub invalid: usize,
    /// Rejected by the band around id boundaries.
    pub band: usize,
    /// Rejected as a strong photo edge near an id boundary.
    pub edge: usize,
    /// Rejected by the planar approximation.
    pub outlier: usize,
    /// The band width this group's mask used (narrower than asked for thin or small groups).
    pub band_width: usize,
    /// Whether the edge test was applied to this group (dropped as a last resort).
    pub edge_test: bool,
}

impl GroupPixelStats {
    /// Why the group lost the pixels it lost, in words (empty when it lost none).
    pub fn why(&self) -> String {
        let mut parts = Vec::new();
        for (n, what) in [
            (self.user, "masked by the user"),
            (self.band, "band/mixed"),
            (self.edge, "edge"),
            (self.invalid, "invalid/saturated"),
            (self.outlier, "outlier"),
        ] {
            if n > 0 {
                parts.push(format!("{n} {what}"));
            }
        }
        let mut s = parts.join(", ");
        if self.visible > 0 {
            s.push_str(&format!(
                "{}band {} px{}",
                if s.is_empty() { "" } else { "; " },
                self.band_width,
                if self.edge_test { "" } else { ", no edge test" }
            ));
        }
        s
    }
}

#[derive(Clone, Debug)]
pub struct UsableMask {
    pub width: usize,
    pub height: usize,
    /// Group of each usable pixel, −1 where the pixel is not usable.
    pub group: Vec<i32>,
    pub stats: Vec<GroupPixelStats>,
    /// Why each pixel is not usable (`Reject::None` where it is).
    pub reason: Vec<Reject>,
    /// The strong-edge map of the photo (all strong edges, wherever they are).
    pub edges: Vec<bool>,
}

impl UsableMask {
    /// Indices of the usable pixels of group `g`.
    pub fn pixels_of(&self, g: usize) -> Vec<usize> {
        self.group
            .iter()
            .enumerate()
            .filter(|&(_, &x)| x == g as i32)
            .map(|(i, _)| i)
            .collect()
    }

    /// [`Self::pixels_of`] of every group below `groups` at once: one pass over the image
    /// instead of one per group (a room's dozens of groups at 1–2 Mpx, bench/SCALE.md).
    pub fn pixels_by_group(&self, groups: usize) -> Vec<Vec<usize>> {
        let mut out = vec![Vec::new(); groups];
        for (i, &g) in self.group.iter().enumerate() {
            if let Some(v) = usize::try_from(g).ok().and_then(|g| out.get_mut(g)) {
                v.push(i);
            }
        }
        out
    }
}

/// Whether a step between group ids `a` and `b` is a boundary: any change of id, or with
/// `objects_only` a change between two groups (not to or from the background).
fn boundary(a: i32, b: i32, objects_only: bool) -> bool {
    a != b && !(objects_only && (a < 0 || b < 0))
}

/// Chessboard distance of every pixel to the nearest pixel whose 4-neighbour is across a
/// [`boundary`] (two-pass chamfer), capped at `cap`.
fn boundary_distance(ib: &IndexBuffers, cap: u32, objects_only: bool) -> Vec<u32> {
    let (w, h) = (ib.width, ib.height);
    let mut d = vec![cap; w * h];
    for y in 0..h {
        for x in 0..w {
            let i = y * w + x;
            let id = ib.group[i];
            let across = |j: usize| boundary(id, ib.group[j], objects_only);
            let diff = (x > 0 && across(i - 1))
                || (x + 1 < w && across(i + 1))
                || (y > 0 && across(i - w))
                || (y + 1 < h && across(i + w));
            if diff {
                d[i] = 0;
            }
        }
    }
    for y in 0..h {
        for x in 0..w {
            let i = y * w + x;
            let mut m = d[i];
            if x > 0 {
                m = m.min(d[i - 1] + 1);
            }
            if y > 0 {
                m = m.min(d[i - w] + 1);
                if x > 0 {
                    m = m.min(d[i - w - 1] + 1);
                }
                if x + 1 < w {
                    m = m.min(d[i - w + 1] + 1);
                }
            }
            d[i] = m;
        }
    }
    for y in (0..h).rev() {
        for x in (0..w).rev() {
            let i = y * w + x;
            let mut m = d[i];
            if x + 1 < w {
                m = m.min(d[i + 1] + 1);
            }
            if y + 1 < h {
                m = m.min(d[i + w] + 1);
                if x + 1 < w {
                    m = m.min(d[i + w + 1] + 1);
                }
                if x > 0 {
                    m = m.min(d[i + w - 1] + 1);
                }
            }
            d[i] = m;
        }
    }
    d
}

/// Groups whose triangles all lie in one plane (the planar approximation applies to them).
/// Emitters are never planar groups here: they are not fitted.
pub fn planar_groups(scene: &Scene) -> Vec<bool> {
    let g = &*scene.geometry;
    let mut out = vec![true; scene.groups.len()];
    let mut plane: Vec<Option<(crate::math::Vec3, f32)>> = vec![None; scene.groups.len()];
    for t in &g.tris {
        let obj = &scene.objects[t.object as usize];
        let gi = obj.group;
        if obj.is_emitter() {
            out[gi] = false;
        }
        if !out[gi] {
            continue;
        }
        let [a, b, c] = t.v.map(|i| g.positions[i as usize]);
        let n = (b - a).cross(c - a).normalize_or_zero();
        if n == crate::math::Vec3::ZERO {
            continue;
        }
        let scale = a.abs().max_element().max(1.0);
        match plane[gi] {
            None => plane[gi] = Some((n, n.dot(a))),
            Some((n0, d0)) => {
                let same = n.dot(n0).abs() > 1.0 - 1e-4
                    && [a, b, c]
                        .iter()
                        .all(|p| (n0.dot(*p) - d0).abs() < 1e-4 * scale);
                if !same {
                    out[gi] = false;
                }
            }
        }
    }
    out
}

/// Computes the usable pixels of every group from the index buffer alone (no sub-pixel
/// coverage: the narrowest band is then 1 pixel). See [`usable_pixels_covered`].
pub fn usable_pixels(
    ib: &IndexBuffers,
    photo: &Photo,
    groups: usize,
    opts: &MaskOptions,
) -> UsableMask {
    usable_pixels_covered(ib, None, photo, groups, opts)
}

/// Radius of the largest window (up to `cap`) around each pixel with no [`boundary`] to the
/// pixel's own group; pixels off the image do not count.
fn clean_radius(ib: &IndexBuffers, cap: usize, objects_only: bool) -> Vec<u8> {
    let (w, h) = (ib.width, ib.height);
    let mut out = vec![0u8; w * h];
    for y in 0..h {
        for x in 0..w {
            let id = ib.group[y * w + x];
            let mut r = 0;
            'grow: while r < cap {
                let n = r as i64 + 1;
                // Only the ring at distance n is new.
                for dy in -n..=n {
                    for dx in -n..=n {
                        if dx.abs() != n && dy.abs() != n {
                            continue;
                        }
                        let (xx, yy) = (x as i64 + dx, y as i64 + dy);
                        if xx < 0 || yy < 0 || xx >= w as i64 || yy >= h as i64 {
                            continue;
                        }
                        if boundary(id, ib.group[yy as usize * w + xx as usize], objects_only) {
                            break 'grow;
                        }
                    }
                }
                r += 1;
            }
            out[y * w + x] = r as u8;
        }
    }
    out
}

/// Computes the usable pixels of every group.
///
/// The band adapts to each group: it starts at `opts.band` with the edge test on, and narrows
/// one pixel at a time (down to 0 = sub-pixel purity alone when `pure` is given, else 1) until
/// the group keeps [`MaskOptions::min_keep`] of its visible pixels; if no band width does, the
/// edge test is dropped for that group and the band narrows again. A group that reaches the
/// minimum at none of these steps gets the step that keeps most. So a large group's mask is the
/// fixed band's, and a thin frame keeps its interior. `pure` ([`coverage::pure_pixels`],
/// one flag per pixel) is always required when given: a pixel part of which sees another
/// object is never usable.
///
/// [`coverage::pure_pixels`]: super::coverage::pure_pixels
pub fn usable_pixels_covered(
    ib: &IndexBuffers,
    pure: Option<&[bool]>,
    photo: &Photo,
    groups: usize,
    opts: &MaskOptions,
) -> UsableMask {
    let (w, h) = (ib.width, ib.height);
    let mut group = vec![-1i32; w * h];
    let mut reason = vec![Reject::Background; w * h];
    let mut stats = vec![GroupPixelStats::default(); groups];
    let edges = if opts.edge_threshold > 0.0 {
        edges::strong_edges(photo, opts.edge_threshold, 4.0).0
    } else {
        vec![false; w * h]
    };
    // Strong edges near a boundary between objects, grown by one pixel (the rim rule: not
    // near the background).
    let reach = (opts.edge_reach.max(opts.band) + 1) as u32;
    let dist = boundary_distance(ib, reach + 1, true);
    let mut edge_near = vec![false; w * h];
    for y in 0..h {
        for x in 0..w {
            let i = y * w + x;
            if edges[i] && dist[i] <= reach {
                for yy in y.saturating_sub(1)..(y + 2).min(h) {
                    for xx in x.saturating_sub(1)..(x + 2).min(w) {
                        edge_near[yy * w + xx] = true;
                    }
                }
            }
        }
    }
    // The band from other objects, and the (narrower) one from the background.
    let band_cap = opts.band.min(u8::MAX as usize);
    let radius = clean_radius(ib, band_cap, true);
    let rim = clean_radius(ib, opts.rim_band.min(band_cap), false);
    let outside =
        |i: usize, b: usize| (radius[i] as usize) < b || (rim[i] as usize) < b.min(opts.rim_band);
    let is_pure = |i: usize| pure.is_none_or(|p| p[i]);
    let narrowest = if pure.is_some() { 0 } else { opts.band.min(1) };
    // The ladder of (band, edge test) steps, from the strictest.
    let steps: Vec<(usize, bool)> = [true, false]
        .iter()
        .flat_map(|&e| (narrowest..=opts.band).rev().map(move |b| (b, e)))
        .collect();
    // Usable count of every group at every step.
    let mut counts = vec![vec![0usize; steps.len()]; groups];
    for i in 0..w * h {
        let g = ib.group[i];
        if g < 0 || g as usize >= groups {
            continue;
        }
        stats[g as usize].visible += 1;
        if photo.ignored[i] || !photo.valid[i] || !is_pure(i) {
            continue;
        }
        for (k, &(b, e)) in steps.iter().enumerate() {
            if !(outside(i, b) || e && edge_near[i]) {
                counts[g as usize][k] += 1;
            }
        }
    }
    let chosen: Vec<(usize, bool)> = (0..groups)
        .map(|g| {
            let target = opts.min_keep(stats[g].visible);
            let c = &counts[g];
            let k = (0..steps.len())
                .find(|&k| c[k] >= target)
                .unwrap_or_else(|| {
                    // The first of the steps that keep most.
                    let best = c.iter().copied().max().unwrap_or(0);
                    c.iter().position(|&n| n == best).unwrap_or(0)
                });
            steps[k]
        })
        .collect();
    for (g, s) in stats.iter_mut().enumerate() {
        (s.band_width, s.edge_test) = chosen[g];
    }
    for i in 0..w * h {
        let g = ib.group[i];
        if g < 0 || g as usize >= groups {
            continue;
        }
        let (b, e) = chosen[g as usize];
        let s = &mut stats[g as usize];
        reason[i] = if photo.ignored[i] {
            s.user += 1;
            Reject::User
        } else if !photo.valid[i] {
            s.invalid += 1;
            Reject::Invalid
        } else if outside(i, b) || !is_pure(i) {
            s.band += 1;
            Reject::Band
        } else if e && edge_near[i] {
            s.edge += 1;
            Reject::Edge
        } else {
            group[i] = g;
            Reject::None
        };
    }
    // The planar approximation, on ln-luminance, for the groups asked for.
    for (g, _) in opts.planar_groups.iter().enumerate().filter(|(_, &p)| p) {
        if g >= groups {
            break;
        }
        let px: Vec<usize> = (0..w * h).filter(|&i| group[i] == g as i32).collect();
        let pts: Vec<(f32, f32, f32)> = px
            .iter()
            .map(|&i| {
                let c = photo.image.data[i];
                let y = ((c.x + c.y + c.z) / 3.0).max(1e-12);
                ((i % w) as f32, (i / w) as f32, y.ln())
            })
            .collect();
        let (_, keep) = robust::planar_inliers(&pts, opts.planar_k, 0.02);
        for (&i, k) in px.iter().zip(keep) {
            if !k {
                group[i] = -1;
                reason[i] = Reject::Outlier;
                stats[g].outlier += 1;
            }
        }
    }
    for s in &mut stats {
        s.rejected = s.user + s.invalid + s.band + s.edge + s.outlier;
        s.usable = s.visible - s.rejected;
    }
    UsableMask {
        width: w,
        height: h,
        group,
        stats,
        reason,
        edges,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::image::Image;
    use crate::math::Rgb;

    #[test]
    fn pixels_by_group_is_pixels_of_every_group() {
        let group = vec![2, -1, 0, 2, 7, 0, -1, 2];
        let m = UsableMask {
            width: 4,
            height: 2,
            reason: vec![Reject::None; group.len()],
            edges: vec![false; group.len()],
            group,
            stats: Vec::new(),
        };
        // Group 7 is beyond the 3 asked for: left out, not a panic.
        let all = m.pixels_by_group(3);
        assert_eq!(all, [vec![2, 5], vec![], vec![0, 3, 7]]);
        for (g, px) in all.iter().enumerate() {
            assert_eq!(*px, m.pixels_of(g));
        }
    }

    /// Two objects split at x = 20 in the model, at x = 23 in the photo (3 px misregistration);
    /// the band (2) alone would keep a wrong strip; the edge detector removes it.
    #[test]
    fn edges_remove_the_strip_a_misregistered_model_leaves() {
        let (w, h) = (40, 10);
        let object: Vec<i32> = (0..w * h).map(|i| if i % w < 20 { 0 } else { 1 }).collect();
        let ib = IndexBuffers {
            width: w,
            height: h,
            group: object.clone(),
            object,
            mirror_object: vec![-1; w * h],
            mirror_group: vec![-1; w * h],
            normal: vec![crate::math::Vec3::new(0.0, 0.0, -1.0); w * h],
        };
        let mut img = Image::new(w, h);
        for (i, c) in img.data.iter_mut().enumerate() {
            *c = Rgb::splat(if i % w < 23 { 0.2 } else { 0.8 });
        }
        let photo = Photo::from_linear(img);
        let no_edges = MaskOptions {
            edge_threshold: 0.0,
            ..Default::default()
        };
        let m = usable_pixels(&ib, &photo, 2, &no_edges);
        assert_eq!(
            m.group[5 * w + 22],
            1,
            "without edges the wrong strip is kept"
        );
        let m = usable_pixels(&ib, &photo, 2, &MaskOptions::default());
        for y in 0..h {
            for x in 20..23 {
                assert_eq!(m.group[y * w + x], -1, "({x}, {y})");
            }
        }
        let s = &m.stats[1];
        assert_eq!(s.visible, 200);
        assert_eq!(s.usable + s.rejected, s.visible);
        assert!(s.edge > 0 && s.band > 0);
        assert!(m.stats[0].usable > 100);
    }

    /// Pixels in the user's mask are usable for no group and counted as such, apart from the
    /// invalid ones.
    #[test]
    fn ignored_pixels_have_their_own_reason() {
        let (w, h) = (30, 10);
        let ib = IndexBuffers {
            width: w,
            height: h,
            group: vec![0; w * h],
            object: vec![0; w * h],
            mirror_object: vec![-1; w * h],
            mirror_group: vec![-1; w * h],
            normal: vec![crate::math::Vec3::new(0.0, 0.0, -1.0); w * h],
        };
        let mut photo = Photo::from_linear(Image::new(w, h));
        photo.image.data.fill(Rgb::splat(0.5));
        photo.valid[0] = false;
        let ignored: Vec<bool> = (0..w * h).map(|i| i % w >= 20).collect();
        assert_eq!(photo.set_ignored(ignored), 100);
        let m = usable_pixels(&ib, &photo, 1, &MaskOptions::default());
        let s = &m.stats[0];
        assert_eq!((s.user, s.invalid, s.usable), (100, 1, 199), "{s:?}");
        assert!(s.why().starts_with("100 masked by the user"), "{}", s.why());
        assert!((0..w * h).all(|i| (m.reason[i] == Reject::User) == (i % w >= 20)));
    }
}
