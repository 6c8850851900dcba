//! Image textures over mesh UVs (bilinear, repeat) or over a group's atlas (`atlas.rs`), stored
//! as linear RGB.

use super::atlas::Atlas;
use super::SurfaceHit;
use crate::math::{Rgb, Vec2, Vec3};
use std::path::PathBuf;
use std::sync::Arc;

/// How surface points find their texel.
#[derive(Debug, Clone)]
pub enum Mapping {
    /// The mesh's UVs, repeating.
    Uv,
    /// A group's chart atlas (recovered textures: the model needs no UVs).
    Atlas(Arc<Atlas>),
}

#[derive(Debug, Clone)]
pub struct Texture {
    pub width: usize,
    pub height: usize,
    /// Row-major, top row first; linear RGB.
    pub texels: Vec<Rgb>,
    /// Where it came from (written back into scene files).
    pub path: PathBuf,
    pub mapping: Mapping,
}

impl Texture {
    /// The texture's value at a hit point.
    #[inline]
    pub fn at(&self, hit: &SurfaceHit) -> Rgb {
        self.at_point(hit.object, hit.uv, hit.p, hit.ng)
    }

    /// The texture's value at a point of `object` (its UV, position and geometric normal: what
    /// the two mappings read of a hit).
    #[inline]
    pub fn at_point(&self, object: u32, uv: Vec2, p: Vec3, ng: Vec3) -> Rgb {
        match &self.mapping {
            Mapping::Uv => self.lookup(uv),
            Mapping::Atlas(a) => a.lookup(&self.texels, object, p, ng),
        }
    }

    /// Bilinear lookup; v = 0 is the bottom row (OpenGL convention, as OBJ and glTF UVs... glTF
    /// has v down, so loaders flip it to this convention).
    pub fn lookup(&self, uv: Vec2) -> Rgb {
        let x = (uv.x - uv.x.floor()) * self.width as f32 - 0.5;
        let y = (1.0 - (uv.y - uv.y.floor())) * self.height as f32 - 0.5;
        let (x0, y0) = (x.floor(), y.floor());
        let (fx, fy) = (x - x0, y - y0);
        let at = |xi: i64, yi: i64| {
            let xi = xi.rem_euclid(self.width as i64) as usize;
            let yi = yi.rem_euclid(self.height as i64) as usize;
            self.texels[yi * self.width + xi]
        };
        let (x0, y0) = (x0 as i64, y0 as i64);
        let top = at(x0, y0) * (1.0 - fx) + at(x0 + 1, y0) * fx;
        let bottom = at(x0, y0 + 1) * (1.0 - fx) + at(x0 + 1, y0 + 1) * fx;
        top * (1.0 - fy) + bottom * fy
    }
}
