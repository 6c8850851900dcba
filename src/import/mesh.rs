//! Meshes the import writes itself, for Mitsuba shapes matfit's scene format has no word for:
//! `serialized` meshes (Mitsuba's own zlib-compressed format, versions 3 and 4, which Mitsuba
//! 0.5/0.6 wrote and Mitsuba 3 reads) and `disk`s. Each is written as an OBJ with its
//! `to_world` applied, its texture coordinates as Mitsuba reads them.

use glam::{DMat3, DMat4, DVec3};
use std::io::Read;
use std::path::Path;

/// A triangle mesh in f64, as read.
#[derive(Clone, Debug, Default)]
pub struct Mesh {
    pub positions: Vec<DVec3>,
    pub normals: Option<Vec<DVec3>>,
    /// Mitsuba's (u, v): v = 0 is a bitmap's top row.
    pub uvs: Option<Vec<[f64; 2]>>,
    pub indices: Vec<[u32; 3]>,
}

/// Mitsuba's disk: radius 1 in the plane z = 0, facing +z, as a fan of `segments` triangles.
pub fn disk(segments: usize) -> Mesh {
    let mut positions = vec![DVec3::ZERO];
    for k in 0..segments {
        let phi = std::f64::consts::TAU * k as f64 / segments as f64;
        positions.push(DVec3::new(phi.cos(), phi.sin(), 0.0));
    }
    let s = segments as u32;
    let indices = (0..s).map(|k| [0, 1 + k, 1 + (k + 1) % s]).collect();
    Mesh {
        positions,
        normals: None,
        uvs: None,
        indices,
    }
}

const MAGIC: u16 = 0x041C;
const HAS_NORMALS: u32 = 0x0001;
const HAS_TEXCOORDS: u32 = 0x0002;
const HAS_COLORS: u32 = 0x0008;
const DOUBLE: u32 = 0x2000;

/// Shape `index` of the serialized file at `path`.
pub fn read_serialized(path: &Path, index: usize) -> Result<Mesh, String> {
    let bytes = std::fs::read(path).map_err(|e| format!("cannot read {}: {e}", path.display()))?;
    parse_serialized(&bytes, index).map_err(|e| format!("serialized mesh {}: {e}", path.display()))
}

fn u16_at(b: &[u8], at: usize) -> Option<u16> {
    Some(u16::from_le_bytes(b.get(at..at + 2)?.try_into().ok()?))
}

fn u32_at(b: &[u8], at: usize) -> Option<u32> {
    Some(u32::from_le_bytes(b.get(at..at + 4)?.try_into().ok()?))
}

fn u64_at(b: &[u8], at: usize) -> Option<u64> {
    Some(u64::from_le_bytes(b.get(at..at + 8)?.try_into().ok()?))
}

pub fn parse_serialized(b: &[u8], index: usize) -> Result<Mesh, String> {
    let short = || "the file is cut short".to_string();
    if u16_at(b, 0) != Some(MAGIC) {
        return Err("not a Mitsuba serialized mesh (no 0x041C header)".into());
    }
    let version = u16_at(b, 2).ok_or_else(short)?;
    if version == 5 {
        return Err(
            "version 5 (Mitsuba 3's packed layout) is not read by matfit's import: save the \
             mesh as PLY"
                .into(),
        );
    }
    if version != 3 && version != 4 {
        return Err(format!("unknown version {version} (3 and 4 are read)"));
    }
    // The shapes' offsets are listed at the file's end, then their count.
    let start = if index == 0 {
        0
    } else {
        let count =
            u32_at(b, b.len().checked_sub(4).ok_or_else(short)?).ok_or_else(short)? as usize;
        if index >= count {
            return Err(format!(
                "shape_index {index} is out of range: the file holds {count} shapes"
            ));
        }
        if version == 4 {
            let at = b.len() - 4 - 8 * (count - index);
            u64_at(b, at).ok_or_else(short)? as usize
        } else {
            let at = b.len() - 4 * (count - index + 1);
            u32_at(b, at).ok_or_else(short)? as usize
        }
    };
    let body = b.get(start + 4..).ok_or_else(short)?;
    let mut z = flate2::read::ZlibDecoder::new(body);
    let mut read = |n: usize| -> Result<Vec<u8>, String> {
        let mut v = vec![0u8; n];
        z.read_exact(&mut v)
            .map_err(|e| format!("its compressed data cannot be read: {e}"))?;
        Ok(v)
    };
    let flags = u32::from_le_bytes(read(4)?.try_into().unwrap());
    if version == 4 {
        // The shape's name, null-terminated.
        while read(1)?[0] != 0 {}
    }
    let vertices = u64::from_le_bytes(read(8)?.try_into().unwrap());
    let triangles = u64::from_le_bytes(read(8)?.try_into().unwrap());
    if vertices > u32::MAX as u64 || triangles > (1 << 31) {
        return Err(format!(
            "{vertices} vertices and {triangles} triangles: more than matfit reads"
        ));
    }
    let (nv, nt) = (vertices as usize, triangles as usize);
    let double = flags & DOUBLE != 0;
    let mut floats = |count: usize| -> Result<Vec<f64>, String> {
        Ok(if double {
            read(count * 8)?
                .chunks_exact(8)
                .map(|c| f64::from_le_bytes(c.try_into().unwrap()))
                .collect()
        } else {
            read(count * 4)?
                .chunks_exact(4)
                .map(|c| f32::from_le_bytes(c.try_into().unwrap()) as f64)
                .collect()
        })
    };
    let vec3s = |v: Vec<f64>| -> Vec<DVec3> {
        v.chunks_exact(3)
            .map(|c| DVec3::new(c[0], c[1], c[2]))
            .collect()
    };
    let positions = vec3s(floats(3 * nv)?);
    let normals = if flags & HAS_NORMALS != 0 {
        Some(vec3s(floats(3 * nv)?))
    } else {
        None
    };
    let uvs = if flags & HAS_TEXCOORDS != 0 {
        Some(
            floats(2 * nv)?
                .chunks_exact(2)
                .map(|c| [c[0], c[1]])
                .collect(),
        )
    } else {
        None
    };
    if flags & HAS_COLORS != 0 {
        floats(3 * nv)?;
    }
    let indices: Vec<[u32; 3]> = read(12 * nt)?
        .chunks_exact(12)
        .map(|c| {
            let i = |k: usize| u32::from_le_bytes(c[4 * k..4 * k + 4].try_into().unwrap());
            [i(0), i(1), i(2)]
        })
        .collect();
    if let Some(bad) = indices.iter().flatten().find(|&&i| i as usize >= nv) {
        return Err(format!(
            "a triangle refers to vertex {bad} of {nv}: the file is damaged"
        ));
    }
    Ok(Mesh {
        positions,
        normals,
        uvs,
        indices,
    })
}

impl Mesh {
    /// Applies `m` (normals by its inverse transpose); `flip` reverses every triangle's winding
    /// (and the normals), so that the wound normal stays Mitsuba's.
    pub fn apply(&mut self, m: &DMat4, flip: bool) {
        for p in &mut self.positions {
            *p = m.transform_point3(*p);
        }
        if let Some(ns) = &mut self.normals {
            let nm = DMat3::from_mat4(*m).inverse().transpose();
            for n in ns.iter_mut() {
                *n = (nm * *n).normalize_or_zero();
                if flip {
                    *n = -*n;
                }
            }
        }
        if flip {
            for t in &mut self.indices {
                t.swap(1, 2);
            }
        }
    }

    /// Vertex normals as Mitsuba generates them for a mesh that has none (and no
    /// `face_normals`): each triangle's unit normal added to its corners' weighted by the
    /// corner's angle (Thürmer and Wüthrich 1998), normalised.
    pub fn generate_normals(&mut self) {
        let mut acc = vec![DVec3::ZERO; self.positions.len()];
        for t in &self.indices {
            let p = t.map(|i| self.positions[i as usize]);
            let n = (p[1] - p[0]).cross(p[2] - p[0]).normalize_or_zero();
            if n == DVec3::ZERO {
                continue;
            }
            for k in 0..3 {
                let a = (p[(k + 1) % 3] - p[k]).normalize_or_zero();
                let b = (p[(k + 2) % 3] - p[k]).normalize_or_zero();
                acc[t[k] as usize] += n * a.dot(b).clamp(-1.0, 1.0).acos();
            }
        }
        self.normals = Some(
            acc.into_iter()
                .map(|n| n.try_normalize().unwrap_or(DVec3::X))
                .collect(),
        );
    }

    /// True when no triangle has an area (matfit's rule in `TriangleMesh::validate`).
    pub fn all_degenerate(&self) -> bool {
        !self.indices.iter().any(|&[a, b, c]| {
            let (a, b, c) = (
                self.positions[a as usize],
                self.positions[b as usize],
                self.positions[c as usize],
            );
            let area2 = (b - a).cross(c - a).length();
            let scale = (b - a).length().max((c - a).length()).max(1e-30);
            area2 > 1e-7 * scale * scale
        })
    }

    /// The mesh as an OBJ file: Mitsuba's (u, v) written as (u, 1 − v), which Mitsuba's and
    /// matfit's OBJ readers both read back as the same point of a bitmap.
    pub fn to_obj(&self) -> Vec<u8> {
        use std::fmt::Write;
        let mut s = String::with_capacity(self.positions.len() * 40 + self.indices.len() * 30);
        s.push_str("# Written by matfit import mitsuba\n");
        for p in &self.positions {
            let _ = writeln!(s, "v {} {} {}", p.x as f32, p.y as f32, p.z as f32);
        }
        if let Some(uv) = &self.uvs {
            for t in uv {
                let _ = writeln!(s, "vt {} {}", t[0] as f32, (1.0 - t[1]) as f32);
            }
        }
        if let Some(ns) = &self.normals {
            for n in ns {
                let _ = writeln!(s, "vn {} {} {}", n.x as f32, n.y as f32, n.z as f32);
            }
        }
        for t in &self.indices {
            let _ = write!(s, "f");
            for &i in t {
                let i = i + 1;
                let _ = match (self.uvs.is_some(), self.normals.is_some()) {
                    (false, false) => write!(s, " {i}"),
                    (true, false) => write!(s, " {i}/{i}"),
                    (false, true) => write!(s, " {i}//{i}"),
                    (true, true) => write!(s, " {i}/{i}/{i}"),
                };
            }
            s.push('\n');
        }
        s.into_bytes()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::Write;

    /// A version-4 file of `meshes`, as Mitsuba 0.5 writes one (offsets and count at its end).
    pub fn serialized(meshes: &[Mesh]) -> Vec<u8> {
        let mut out = Vec::new();
        let mut offsets = Vec::new();
        for m in meshes {
            offsets.push(out.len() as u64);
            out.extend_from_slice(&MAGIC.to_le_bytes());
            out.extend_from_slice(&4u16.to_le_bytes());
            let mut raw = Vec::new();
            let flags = (HAS_TEXCOORDS * m.uvs.is_some() as u32) | 0x1000;
            raw.extend_from_slice(&flags.to_le_bytes());
            raw.extend_from_slice(b"part\0");
            raw.extend_from_slice(&(m.positions.len() as u64).to_le_bytes());
            raw.extend_from_slice(&(m.indices.len() as u64).to_le_bytes());
            for p in &m.positions {
                for x in p.to_array() {
                    raw.extend_from_slice(&(x as f32).to_le_bytes());
                }
            }
            for t in m.uvs.iter().flatten() {
                for x in t {
                    raw.extend_from_slice(&(*x as f32).to_le_bytes());
                }
            }
            for t in &m.indices {
                for i in t {
                    raw.extend_from_slice(&i.to_le_bytes());
                }
            }
            let mut z = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::default());
            z.write_all(&raw).unwrap();
            out.extend(z.finish().unwrap());
        }
        for o in &offsets {
            out.extend_from_slice(&o.to_le_bytes());
        }
        out.extend_from_slice(&(meshes.len() as u32).to_le_bytes());
        out
    }

    #[test]
    fn serialized_files_read_back_each_shape() {
        let a = Mesh {
            positions: vec![DVec3::ZERO, DVec3::X, DVec3::Y],
            uvs: Some(vec![[0.0, 0.0], [1.0, 0.0], [0.0, 0.25]]),
            indices: vec![[0, 1, 2]],
            normals: None,
        };
        let mut b = disk(8);
        b.apply(&DMat4::from_translation(DVec3::new(0.0, 0.0, 2.0)), false);
        let bytes = serialized(&[a.clone(), b.clone()]);
        let ra = parse_serialized(&bytes, 0).unwrap();
        let rb = parse_serialized(&bytes, 1).unwrap();
        assert_eq!(ra.positions, a.positions);
        assert_eq!(ra.uvs, a.uvs);
        assert_eq!(ra.indices, a.indices);
        assert_eq!(rb.indices, b.indices);
        assert!((rb.positions[3] - b.positions[3]).length() < 1e-6);
        assert!(parse_serialized(&bytes, 2)
            .unwrap_err()
            .contains("holds 2 shapes"));
    }

    /// A tent of two faces meeting at a ridge: the ridge's normals point up between the
    /// faces' (each face's angle at a ridge vertex weighs the same), the eaves' are the faces'.
    #[test]
    fn generated_normals_weigh_faces_by_their_corner_angles() {
        let mut m = Mesh {
            positions: vec![
                DVec3::new(-1.0, 0.0, 0.0),
                DVec3::new(0.0, 1.0, 0.0),
                DVec3::new(0.0, 1.0, 1.0),
                DVec3::new(-1.0, 0.0, 1.0),
                DVec3::new(1.0, 0.0, 0.0),
                DVec3::new(1.0, 0.0, 1.0),
            ],
            indices: vec![[0, 2, 1], [0, 3, 2], [1, 2, 5], [1, 5, 4]],
            ..Default::default()
        };
        m.generate_normals();
        let n = m.normals.unwrap();
        assert!((n[1] - DVec3::Y).length() < 1e-9, "{}", n[1]);
        assert!(
            (n[0] - DVec3::new(-1.0, 1.0, 0.0).normalize()).length() < 1e-9,
            "{}",
            n[0]
        );
    }

    #[test]
    fn a_flipped_disk_faces_down() {
        let mut d = disk(16);
        let n = |d: &Mesh| {
            let [a, b, c] = d.indices[0].map(|i| d.positions[i as usize]);
            (b - a).cross(c - a).normalize()
        };
        assert!((n(&d) - DVec3::Z).length() < 1e-9);
        d.apply(&DMat4::IDENTITY, true);
        assert!((n(&d) + DVec3::Z).length() < 1e-9);
        assert!(!d.all_degenerate());
        d.apply(&DMat4::from_scale(DVec3::new(1.0, 1.0, 0.0)), false);
        d.apply(&DMat4::from_scale(DVec3::new(1.0, 0.0, 1.0)), false);
        assert!(d.all_degenerate());
    }
}
