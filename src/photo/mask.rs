//! Usable pixels per group: the index buffer minus a band of `band` pixels around every id
//! boundary (so a model a few pixels off does not poison a group), minus invalid photo pixels.

use crate::photo::Photo;
use crate::render::aov::IndexBuffers;

#[derive(Clone, Debug)]
pub struct MaskOptions {
    /// Half-width, in pixels, of the band removed around every boundary between ids.
    pub band: usize,
}

impl Default for MaskOptions {
    fn default() -> Self {
        MaskOptions { band: 2 }
    }
}

/// Per-group pixel counts.
#[derive(Clone, Debug, Default, PartialEq, Eq, serde::Serialize)]
pub struct GroupPixelStats {
    pub visible: usize,
    pub usable: usize,
    pub rejected: usize,
}

#[derive(Clone, Debug)]
pub struct UsableMask {
    pub width: usize,
    pub height: usize,
    /// Group of each usable pixel, −1 where the pixel is not usable.
    pub group: Vec<i32>,
    pub stats: Vec<GroupPixelStats>,
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
}

/// Computes the usable pixels of every group.
pub fn usable_pixels(
    ib: &IndexBuffers,
    photo: &Photo,
    groups: usize,
    opts: &MaskOptions,
) -> UsableMask {
    let (w, h) = (ib.width, ib.height);
    let b = opts.band as i64;
    let mut group = vec![-1i32; w * h];
    let mut stats = vec![GroupPixelStats::default(); groups];
    for y in 0..h {
        for x in 0..w {
            let i = y * w + x;
            let id = ib.object[i];
            let g = ib.group[i];
            if g < 0 {
                continue;
            }
            stats[g as usize].visible += 1;
            // Every pixel within the band must see the same object.
            let mut clean = true;
            'band: for dy in -b..=b {
                for dx in -b..=b {
                    let (xx, yy) = (x as i64 + dx, y as i64 + dy);
                    if xx < 0 || yy < 0 || xx >= w as i64 || yy >= h as i64 {
                        continue;
                    }
                    if ib.object[yy as usize * w + xx as usize] != id {
                        clean = false;
                        break 'band;
                    }
                }
            }
            if clean && photo.valid[i] {
                group[i] = g;
                stats[g as usize].usable += 1;
            } else {
                stats[g as usize].rejected += 1;
            }
        }
    }
    UsableMask {
        width: w,
        height: h,
        group,
        stats,
    }
}
