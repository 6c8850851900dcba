//! Export of a scene to other renderers' formats, so that people can keep working in their own
//! tools and so that an independent renderer can check ours (`bench/crosscheck.py`).

pub mod gltf;
pub mod mitsuba;
pub mod standin;

/// The formats `matfit export` writes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Format {
    /// Mitsuba 3 scene (XML, version 3.0.0) with one binary PLY per object.
    Mitsuba,
    /// glTF 2.0 binary (.glb): meshes, metallic-roughness materials, textures, the camera.
    Gltf,
}

/// What an export wrote, and what it could not carry over exactly.
#[derive(Clone, Debug, Default)]
pub struct ExportReport {
    /// Files written, the scene file first.
    pub files: Vec<std::path::PathBuf>,
    /// One message per approximation (a material or camera the target cannot express).
    pub warnings: Vec<String>,
}

/// A far clipping distance that cuts nothing: twice the distance from `eye` to the farthest
/// corner of the scene's bounds.
pub(crate) fn far_clip(scene: &crate::scene::Scene, eye: crate::math::Vec3) -> f32 {
    let b = scene.geometry.bvh.bounds();
    let mut far = 0.0f32;
    for i in 0..8 {
        let corner = crate::math::Vec3::new(
            if i & 1 == 0 { b.min.x } else { b.max.x },
            if i & 2 == 0 { b.min.y } else { b.max.y },
            if i & 4 == 0 { b.min.z } else { b.max.z },
        );
        far = far.max((corner - eye).length());
    }
    (2.0 * far).max(1e-3)
}

/// A texture's texels × `factor` as an image for a renderer that reads it through UVs with a
/// plain bilinear filter. In an atlas each chart's edge texels are copied into the one-texel gap
/// around it, so that a lookup within half a texel of a chart's edge blends the chart's own
/// colour (matfit's lookup clamps to the chart), not the next chart's or the empty gap's.
pub(crate) fn texture_image(
    texture: &crate::scene::texture::Texture,
    factor: crate::math::Rgb,
) -> crate::io::image::Image {
    let (w, h) = (texture.width, texture.height);
    let mut img = crate::io::image::Image::new(w, h);
    for (o, t) in img.data.iter_mut().zip(&texture.texels) {
        *o = *t * factor;
    }
    if let crate::scene::texture::Mapping::Atlas(atlas) = &texture.mapping {
        let src = img.data.clone();
        for [x0, y0, cw, ch] in atlas.chart_rects() {
            for y in y0.saturating_sub(1)..(y0 + ch + 1).min(h) {
                for x in x0.saturating_sub(1)..(x0 + cw + 1).min(w) {
                    let (sx, sy) = (x.clamp(x0, x0 + cw - 1), y.clamp(y0, y0 + ch - 1));
                    img.data[y * w + x] = src[sy * w + sx];
                }
            }
        }
    }
    img
}
