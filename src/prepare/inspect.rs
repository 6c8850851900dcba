//! `matfit inspect`: pictures to check by eye, before fitting, that the model lines up with the
//! photo, and which pixels each group will be judged on.
//!
//! - `outlines.png`: the photo (auto-exposed preview) with the model's group boundaries in
//!   yellow and boundaries between objects of one group in cyan; invalid pixels in red;
//! - `usable.png`: usable pixels in their group's colour shaded by the photo, rejected pixels of
//!   a group dark (band and edges darker grey-blue, planar outliers dark magenta, invalid dark
//!   red, masked by the user dark olive), background black;
//! - `edges.png`: the strong edges of the photo (white) over the darkened photo.

use crate::io::image::Image;
use crate::math::Rgb;
use crate::photo::robust;
use crate::prepare::mask::Reject;
use crate::prepare::{openness, prepare, PhotoArgs, PreparedPhoto};
use crate::render::aov::id_color;
use crate::scene::Scene;
use std::fmt::Write as _;
use std::path::Path;

/// Preview scale: the 99th percentile of the valid pixels' luminance maps to 0.9.
fn preview_scale(p: &PreparedPhoto) -> f32 {
    let mut l: Vec<f32> = p
        .photo
        .image
        .data
        .iter()
        .zip(&p.photo.valid)
        .filter(|(_, &v)| v)
        .map(|(c, _)| (c.x + c.y + c.z) / 3.0)
        .collect();
    if l.is_empty() {
        return 1.0;
    }
    let k = ((l.len() - 1) as f32 * 0.99) as usize;
    let (_, v, _) = l.select_nth_unstable_by(k, f32::total_cmp);
    if *v > 0.0 {
        0.9 / *v
    } else {
        1.0
    }
}

/// Runs the inspection: writes the pictures into `out` and returns the text report.
// Pixel loops index several parallel buffers by the same pixel index.
#[allow(clippy::needless_range_loop)]
pub fn inspect(
    scene: &Scene,
    photo_path: &Path,
    args: &PhotoArgs,
    out: &Path,
) -> Result<String, String> {
    let p = prepare(scene, photo_path, args)?;
    std::fs::create_dir_all(out)
        .map_err(|e| format!("cannot create the folder {}: {e}", out.display()))?;
    let (w, h) = (p.mask.width, p.mask.height);
    let s = preview_scale(&p);
    let shown: Vec<Rgb> = p.photo.image.data.iter().map(|c| *c * s).collect();
    let ib = &p.index;

    let mut outlines = Image::new(w, h);
    for i in 0..w * h {
        let (x, y) = (i % w, i / w);
        let neigh = [
            (x > 0).then(|| i - 1),
            (x + 1 < w).then(|| i + 1),
            (y > 0).then(|| i - w),
            (y + 1 < h).then(|| i + w),
        ];
        let group_edge = neigh.iter().flatten().any(|&j| ib.group[j] != ib.group[i]);
        let obj_edge = neigh
            .iter()
            .flatten()
            .any(|&j| ib.object[j] != ib.object[i]);
        outlines.data[i] = if group_edge {
            Rgb::new(1.0, 1.0, 0.0)
        } else if obj_edge {
            Rgb::new(0.0, 1.0, 1.0)
        } else if !p.photo.valid[i] {
            Rgb::new(1.0, 0.0, 0.0)
        } else {
            shown[i]
        };
    }
    let mut usable = Image::new(w, h);
    let mut edges = Image::new(w, h);
    for i in 0..w * h {
        let l = ((shown[i].x + shown[i].y + shown[i].z) / 3.0).clamp(0.0, 1.0);
        let g = ib.group[i];
        usable.data[i] = match p.mask.reason[i] {
            Reject::None => id_color(g) * (0.35 + 0.65 * l.sqrt()),
            Reject::Background => Rgb::ZERO,
            Reject::Band | Reject::Edge => Rgb::new(0.03, 0.03, 0.06),
            Reject::Outlier => Rgb::new(0.12, 0.0, 0.12),
            Reject::Invalid => Rgb::new(0.15, 0.0, 0.0),
            Reject::User => Rgb::new(0.1, 0.1, 0.0),
        };
        edges.data[i] = if p.mask.edges[i] {
            Rgb::ONE
        } else {
            shown[i] * 0.3
        };
    }
    for (img, name) in [
        (&outlines, "outlines.png"),
        (&usable, "usable.png"),
        (&edges, "edges.png"),
    ] {
        img.write(&out.join(name))?;
    }

    let mut r = String::new();
    let ph = &p.photo;
    let _ = writeln!(
        r,
        "photo {} {}×{}, {}, exposure {}",
        photo_path.display(),
        w,
        h,
        match ph.bits {
            Some(b) => format!("{b}-bit, response {}", args.response.name()),
            None => "float (linear)".into(),
        },
        match &p.calibration {
            Some(c) => format!(
                "{:.6} calibrated from {} (per channel {:.6}, {:.6}, {:.6})",
                c.factor, c.source, c.per_channel[0], c.per_channel[1], c.per_channel[2]
            ),
            None if args.exposure.is_some() => format!("{} (given)", ph.exposure),
            None => format!("{} (default, not given)", ph.exposure),
        }
    );
    if let Some(g) = &p.registration {
        let _ = writeln!(
            r,
            "registration: {}, over {} edge points; {}",
            g.found(),
            g.edges,
            if p.camera != scene.camera {
                "masks use the corrected camera".to_string()
            } else {
                g.not_applied_because()
            }
        );
    }
    let open = openness::open_share(scene, &p.camera, &p.mask);
    let _ = writeln!(
        r,
        "open share: {:.1}% of what the usable pixels' surfaces face (cosine-weighted) is no \
         geometry; light from outside the model: {}",
        100.0 * open,
        if scene.environment.is_some() {
            "the scene's environment".to_string()
        } else if scene.stray_light.max_element() > 0.0 {
            format!(
                "the stray light ({}, {}, {})",
                scene.stray_light.x, scene.stray_light.y, scene.stray_light.z
            )
        } else {
            "none".into()
        }
    );
    if scene.outside_light_is_none() && open > openness::OPEN_SCENE {
        let _ = writeln!(r, "warning: {}", openness::open_scene_warning(open));
    }
    let _ = writeln!(
        r,
        "invalid pixels: {} NaN/infinite, {} negative, {} saturated; {} masked by the user{}",
        ph.invalid_nonfinite,
        ph.invalid_negative,
        ph.invalid_saturated,
        ph.ignored.iter().filter(|&&m| m).count(),
        match &args.ignore_mask {
            Some(f) => format!(" ({})", f.display()),
            None => String::new(),
        }
    );
    let _ = writeln!(
        r,
        "{:<16} {:>8} {:>8} {:>8}   {:>7} {:>7} {:>7} {:>7} {:>7}   {:>12}  {:>5}",
        "group",
        "visible",
        "usable",
        "rejected",
        "user",
        "band",
        "edge",
        "invalid",
        "outlier",
        "median L",
        "width"
    );
    for (g, st) in p.mask.stats.iter().enumerate() {
        let mut l: Vec<f32> = p
            .mask
            .pixels_of(g)
            .iter()
            .map(|&i| {
                let c = ph.image.data[i];
                (c.x + c.y + c.z) / 3.0
            })
            .collect();
        let med = robust::median(&mut l)
            .map(|m| format!("{m:.5}"))
            .unwrap_or_else(|| "-".into());
        let _ = writeln!(
            r,
            "{:<16} {:>8} {:>8} {:>8}   {:>7} {:>7} {:>7} {:>7} {:>7}   {:>12}  {:>5}{}",
            scene.groups[g].name,
            st.visible,
            st.usable,
            st.rejected,
            st.user,
            st.band,
            st.edge,
            st.invalid,
            st.outlier,
            med,
            format!("{}{}", st.band_width, if st.edge_test { "" } else { "*" }),
            if st.visible > 0 && st.usable == 0 {
                "  (no usable pixel!)"
            } else {
                ""
            }
        );
    }
    let _ = writeln!(
        r,
        "user: in the --ignore-mask; band: removed around id boundaries or not covered by one object at sub-pixel level; \
         width: the band each group used (narrowed until it keeps min({}, {:.0}% of visible)), \
         * = edge test dropped to keep them",
        args.mask_options(scene).min_usable,
        100.0 * args.mask_options(scene).min_usable_fraction
    );
    let _ = writeln!(
        r,
        "wrote {} (outlines.png, usable.png, edges.png)",
        out.display()
    );
    Ok(r)
}
