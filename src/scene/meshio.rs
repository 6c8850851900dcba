//! Mesh files: Wavefront OBJ (tobj), PLY (ply-rs-bw), glTF 2.0 (gltf). Each loader returns one
//! triangle mesh in the file's coordinates (glTF: with its node transforms applied), or a
//! message saying what is wrong with the file.

use crate::geometry::{shapes, TriangleMesh};
use glam::{Mat4, Vec2, Vec3};
use std::path::Path;

/// Loads a mesh, choosing the format by the file's extension.
pub fn load_mesh(path: &Path) -> Result<TriangleMesh, String> {
    if !path.exists() {
        return Err(format!("mesh file {} not found", path.display()));
    }
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .map(|e| e.to_ascii_lowercase())
        .unwrap_or_default();
    match ext.as_str() {
        "obj" => load_obj(path),
        "ply" => load_ply(path),
        "gltf" | "glb" => load_gltf(path),
        _ => Err(format!(
            "mesh file {}: unknown format '.{ext}' (expected .obj, .ply, .gltf or .glb)",
            path.display()
        )),
    }
}

fn load_obj(path: &Path) -> Result<TriangleMesh, String> {
    let opts = tobj::LoadOptions {
        triangulate: true,
        single_index: true,
        ..Default::default()
    };
    let (models, _) = tobj::load_obj(path, &opts).map_err(|e| {
        format!(
            "mesh file {}: not a readable OBJ file ({e})",
            path.display()
        )
    })?;
    let parts: Vec<TriangleMesh> = models
        .iter()
        .map(|m| {
            let mm = &m.mesh;
            let v3 = |a: &[f32]| {
                a.chunks_exact(3)
                    .map(|c| Vec3::new(c[0], c[1], c[2]))
                    .collect::<Vec<_>>()
            };
            let positions = v3(&mm.positions);
            let normals = (mm.normals.len() == mm.positions.len() && !mm.normals.is_empty())
                .then(|| v3(&mm.normals));
            let uvs = (mm.texcoords.len() / 2 == positions.len() && !mm.texcoords.is_empty()).then(
                || {
                    mm.texcoords
                        .chunks_exact(2)
                        .map(|c| Vec2::new(c[0], c[1]))
                        .collect()
                },
            );
            TriangleMesh {
                positions,
                normals,
                uvs,
                indices: mm
                    .indices
                    .chunks_exact(3)
                    .map(|c| [c[0], c[1], c[2]])
                    .collect(),
            }
        })
        .collect();
    Ok(shapes::merge(&parts))
}

fn load_ply(path: &Path) -> Result<TriangleMesh, String> {
    use ply_rs_bw::parser::Parser;
    use ply_rs_bw::ply::{DefaultElement, Property};
    let bad = |what: String| format!("mesh file {}: {what}", path.display());
    let mut f = std::fs::File::open(path).map_err(|e| bad(e.to_string()))?;
    let ply = Parser::<DefaultElement>::new()
        .read_ply(&mut f)
        .map_err(|e| bad(format!("not a readable PLY file ({e})")))?;
    let num = |p: Option<&Property>| -> Option<f32> {
        Some(match p? {
            Property::Float(x) => *x,
            Property::Double(x) => *x as f32,
            Property::Int(x) => *x as f32,
            Property::UInt(x) => *x as f32,
            Property::Short(x) => *x as f32,
            Property::UShort(x) => *x as f32,
            Property::Char(x) => *x as f32,
            Property::UChar(x) => *x as f32,
            _ => return None,
        })
    };
    let verts = ply
        .payload
        .get("vertex")
        .ok_or_else(|| bad("no 'vertex' element".into()))?;
    let mut m = TriangleMesh::default();
    let (mut ns, mut uvs) = (Vec::new(), Vec::new());
    for (i, v) in verts.iter().enumerate() {
        let p = (num(v.get("x")), num(v.get("y")), num(v.get("z")));
        let (Some(x), Some(y), Some(z)) = p else {
            return Err(bad(format!("vertex {i} lacks numeric x, y, z")));
        };
        m.positions.push(Vec3::new(x, y, z));
        if let (Some(a), Some(b), Some(c)) = (num(v.get("nx")), num(v.get("ny")), num(v.get("nz")))
        {
            ns.push(Vec3::new(a, b, c));
        }
        let u = num(v.get("u"))
            .or(num(v.get("s")))
            .or(num(v.get("texture_u")));
        let w = num(v.get("v"))
            .or(num(v.get("t")))
            .or(num(v.get("texture_v")));
        if let (Some(u), Some(w)) = (u, w) {
            uvs.push(Vec2::new(u, w));
        }
    }
    let faces = ply
        .payload
        .get("face")
        .ok_or_else(|| bad("no 'face' element".into()))?;
    for (i, f) in faces.iter().enumerate() {
        let list = f.get("vertex_indices").or(f.get("vertex_index"));
        let idx: Vec<u32> = match list {
            Some(Property::ListInt(v)) => v.iter().map(|&x| x.max(0) as u32).collect(),
            Some(Property::ListUInt(v)) => v.clone(),
            Some(Property::ListUChar(v)) => v.iter().map(|&x| x as u32).collect(),
            Some(Property::ListUShort(v)) => v.iter().map(|&x| x as u32).collect(),
            Some(Property::ListShort(v)) => v.iter().map(|&x| x.max(0) as u32).collect(),
            Some(Property::ListChar(v)) => v.iter().map(|&x| x.max(0) as u32).collect(),
            _ => {
                return Err(bad(format!(
                    "face {i} has no integer 'vertex_indices' list"
                )))
            }
        };
        // Fan triangulation of polygons.
        for k in 1..idx.len().saturating_sub(1) {
            m.indices.push([idx[0], idx[k], idx[k + 1]]);
        }
    }
    m.normals = (ns.len() == m.positions.len() && !ns.is_empty()).then_some(ns);
    m.uvs = (uvs.len() == m.positions.len() && !uvs.is_empty()).then_some(uvs);
    Ok(m)
}

fn load_gltf(path: &Path) -> Result<TriangleMesh, String> {
    let bad = |what: String| format!("mesh file {}: {what}", path.display());
    let (doc, buffers, _) =
        gltf::import(path).map_err(|e| bad(format!("not a readable glTF file ({e})")))?;
    let mut parts = Vec::new();
    let scene = doc.default_scene().or_else(|| doc.scenes().next());
    let roots: Vec<gltf::Node> = match &scene {
        Some(s) => s.nodes().collect(),
        None => doc.nodes().collect(),
    };
    let mut stack: Vec<(gltf::Node, Mat4)> =
        roots.into_iter().map(|n| (n, Mat4::IDENTITY)).collect();
    while let Some((node, parent)) = stack.pop() {
        let m = parent * Mat4::from_cols_array_2d(&node.transform().matrix());
        if let Some(mesh) = node.mesh() {
            for prim in mesh.primitives() {
                if prim.mode() != gltf::mesh::Mode::Triangles {
                    continue;
                }
                let reader = prim.reader(|b| buffers.get(b.index()).map(|d| &d.0[..]));
                let Some(pos) = reader.read_positions() else {
                    continue;
                };
                let positions: Vec<Vec3> = pos.map(Vec3::from).collect();
                let n = positions.len() as u32;
                let indices: Vec<u32> = match reader.read_indices() {
                    Some(i) => i.into_u32().collect(),
                    None => (0..n).collect(),
                };
                let mut part = TriangleMesh {
                    normals: reader.read_normals().map(|it| it.map(Vec3::from).collect()),
                    // glTF puts v = 0 at the top of the image; matfit's textures at the bottom.
                    uvs: reader
                        .read_tex_coords(0)
                        .map(|t| t.into_f32().map(|[u, v]| Vec2::new(u, 1.0 - v)).collect()),
                    positions,
                    indices: indices
                        .chunks_exact(3)
                        .map(|c| [c[0], c[1], c[2]])
                        .collect(),
                };
                part.transform(&glam::Affine3A::from_mat4(m));
                parts.push(part);
            }
        }
        stack.extend(node.children().map(|c| (c, m)));
    }
    if parts.is_empty() {
        return Err(bad("no triangle primitives".into()));
    }
    Ok(shapes::merge(&parts))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn loads_obj_and_ply_quads() {
        let dir = tempfile::tempdir().unwrap();
        let obj = dir.path().join("q.obj");
        std::fs::write(&obj, "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3 4\n").unwrap();
        let m = load_mesh(&obj).unwrap();
        assert_eq!(m.indices.len(), 2);
        assert!((m.area() - 1.0).abs() < 1e-6);
        let ply = dir.path().join("q.ply");
        std::fs::write(
            &ply,
            "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\n\
             element face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n2 0 0\n2 1 0\n0 1 0\n4 0 1 2 3\n",
        )
        .unwrap();
        let m = load_mesh(&ply).unwrap();
        assert_eq!(m.indices.len(), 2);
        assert!((m.area() - 2.0).abs() < 1e-6);
        assert!(load_mesh(&dir.path().join("missing.obj"))
            .unwrap_err()
            .contains("not found"));
    }

    #[test]
    fn loads_gltf_with_node_transforms() {
        // One triangle (0,0,0), (1,0,0), (0,1,0) in an embedded buffer, under a node that
        // scales by 2 and moves by (0, 0, 3).
        let gltf = r#"{
  "asset": {"version": "2.0"},
  "scene": 0,
  "scenes": [{"nodes": [0]}],
  "nodes": [{"mesh": 0, "scale": [2, 2, 2], "translation": [0, 0, 3]}],
  "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1}]}],
  "buffers": [{"byteLength": 44, "uri": "data:application/octet-stream;base64,AAAAAAAAAAAAAAAAAACAPwAAAAAAAAAAAAAAAAAAgD8AAAAAAAABAAIAAAA="}],
  "bufferViews": [{"buffer": 0, "byteOffset": 0, "byteLength": 36}, {"buffer": 0, "byteOffset": 36, "byteLength": 6}],
  "accessors": [
    {"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3", "min": [0, 0, 0], "max": [1, 1, 0]},
    {"bufferView": 1, "componentType": 5123, "count": 3, "type": "SCALAR"}
  ]
}"#;
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("tri.gltf");
        std::fs::write(&p, gltf).unwrap();
        let m = load_mesh(&p).unwrap();
        assert_eq!(m.indices.len(), 1);
        assert!((m.area() - 2.0).abs() < 1e-6, "area {}", m.area());
        assert!((m.positions[1] - Vec3::new(2.0, 0.0, 3.0)).length() < 1e-6);
        std::fs::write(&p, "{ not json").unwrap();
        assert!(load_mesh(&p).unwrap_err().contains("tri.gltf"));
    }
}
