//! Mesh files: Wavefront OBJ (tobj), PLY (ply-rs-bw), glTF 2.0 (gltf). Each loader returns one
//! triangle mesh in the file's coordinates (glTF: with its node transforms applied), or a
//! message saying what is wrong with the file.

use crate::geometry::{shapes, TriangleMesh};
use glam::{Mat4, Vec2, Vec3};
use std::path::Path;

/// Largest mesh file read (bytes): a bigger file is refused with a message rather than read.
pub const MAX_MESH_BYTES: u64 = 4 << 30;

/// Loads a mesh, choosing the format by the file's extension.
pub fn load_mesh(path: &Path) -> Result<TriangleMesh, String> {
    let meta = match std::fs::metadata(path) {
        Ok(m) => m,
        Err(_) => return Err(format!("mesh file {} not found", path.display())),
    };
    if meta.is_dir() {
        return Err(format!(
            "mesh file {} is a folder, not a file",
            path.display()
        ));
    }
    if !meta.is_file() {
        return Err(format!(
            "mesh file {} is not a regular file",
            path.display()
        ));
    }
    if meta.len() > MAX_MESH_BYTES {
        return Err(format!(
            "mesh file {} is {} MB, more than matfit reads ({} MB)",
            path.display(),
            meta.len() >> 20,
            MAX_MESH_BYTES >> 20
        ));
    }
    let ext = extension(path);
    if !["obj", "ply", "gltf", "glb"].contains(&ext.as_str()) {
        return Err(unknown_format(path, &ext));
    }
    let bytes = std::fs::read(path)
        .map_err(|e| format!("mesh file {}: cannot read: {e}", path.display()))?;
    mesh_from_bytes(&bytes, path, path.parent())
}

fn extension(path: &Path) -> String {
    path.extension()
        .and_then(|e| e.to_str())
        .map(|e| e.to_ascii_lowercase())
        .unwrap_or_default()
}

fn unknown_format(path: &Path, ext: &str) -> String {
    format!(
        "mesh file {}: unknown format '.{ext}' (expected .obj, .ply, .gltf or .glb)",
        path.display()
    )
}

/// Decodes a mesh file's bytes; `path` names it in messages and its extension chooses the
/// format; `base` is the folder glTF buffers with relative URIs are read from (None: only
/// embedded buffers).
pub fn mesh_from_bytes(
    bytes: &[u8],
    path: &Path,
    base: Option<&Path>,
) -> Result<TriangleMesh, String> {
    match extension(path).as_str() {
        "obj" => obj_from_bytes(bytes, path),
        "ply" => ply_from_bytes(bytes, path),
        "gltf" | "glb" => gltf_from_bytes(bytes, path, base),
        ext => Err(unknown_format(path, ext)),
    }
}

/// Checks an OBJ file's face indices before tobj sees them: tobj's arithmetic on an index that
/// is huge, or negative beyond the elements defined so far, overflows (a panic in debug builds,
/// a wrong index in release ones).
fn check_obj_faces(bytes: &[u8]) -> Result<(), String> {
    let mut counts = [0i64; 3]; // v, vt, vn lines so far
    for (n, line) in bytes.split(|&b| b == b'\n').enumerate() {
        let line = String::from_utf8_lossy(line);
        let mut words = line.split_whitespace();
        match words.next() {
            Some("v") => counts[0] += 1,
            Some("vt") => counts[1] += 1,
            Some("vn") => counts[2] += 1,
            Some("f") | Some("l") => {
                for word in words {
                    for (k, part) in word.split('/').enumerate().take(3) {
                        let Ok(x) = part.parse::<i64>() else {
                            continue; // empty, or not a number: tobj reports it
                        };
                        if x.abs() > i32::MAX as i64 || (x < 0 && counts[k] + x < 0) {
                            return Err(format!(
                                "line {}: face index {x} refers to a {} that does not exist",
                                n + 1,
                                ["vertex", "texture coordinate", "normal"][k]
                            ));
                        }
                    }
                }
            }
            _ => {}
        }
    }
    Ok(())
}

fn obj_from_bytes(bytes: &[u8], path: &Path) -> Result<TriangleMesh, String> {
    check_obj_faces(bytes).map_err(|e| {
        format!(
            "mesh file {}: not a readable OBJ file ({e})",
            path.display()
        )
    })?;
    let opts = tobj::LoadOptions {
        triangulate: true,
        single_index: true,
        ..Default::default()
    };
    // Materials are not read from OBJ files (the scene file gives them).
    let (models, _) = tobj::load_obj_buf(&mut std::io::Cursor::new(bytes), &opts, |_| {
        Err(tobj::LoadError::OpenFileFailed)
    })
    .map_err(|e| {
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

/// Checks a PLY header before the parser sees it: ply-rs panics on numbers that overflow u64 and
/// loops `count` times over elements that have no properties (no bytes to run out of), so a
/// header can make it panic or exhaust memory. Every element must have a property, and no count
/// may exceed the bytes left after the header (each element takes at least one).
fn check_ply_header(bytes: &[u8]) -> Result<(), String> {
    let end = bytes
        .windows(10)
        .position(|w| w == b"end_header")
        .ok_or("no 'end_header' line")?;
    let header = String::from_utf8_lossy(&bytes[..end]);
    let left = (bytes.len() - end) as u64;
    let mut elements: Vec<(String, u64, usize)> = Vec::new();
    for line in header.lines() {
        let mut digits = 0;
        for c in line.chars() {
            digits = if c.is_ascii_digit() { digits + 1 } else { 0 };
            if digits > 18 {
                return Err(format!(
                    "header line '{}' has a number too large",
                    line.trim()
                ));
            }
        }
        let words: Vec<&str> = line.split_whitespace().collect();
        match words.as_slice() {
            ["element", name, n] => {
                let n: u64 = n.parse().unwrap_or(0);
                if n > left {
                    return Err(format!(
                        "element '{name}' claims {n} entries but the file has {left} bytes after \
                         its header"
                    ));
                }
                elements.push((name.to_string(), n, 0));
            }
            ["property", ..] => {
                if let Some(e) = elements.last_mut() {
                    e.2 += 1;
                }
            }
            _ => {}
        }
    }
    if let Some((name, n, _)) = elements.iter().find(|e| e.1 > 0 && e.2 == 0) {
        return Err(format!(
            "element '{name}' has {n} entries but no properties"
        ));
    }
    Ok(())
}

/// A PLY property as a number, whatever its stored type; None for lists.
fn ply_number(p: &ply_rs_bw::ply::Property) -> Option<f32> {
    use ply_rs_bw::ply::Property;
    Some(match *p {
        Property::Float(x) => x,
        Property::Double(x) => x as f32,
        Property::Int(x) => x as f32,
        Property::UInt(x) => x as f32,
        Property::Short(x) => x as f32,
        Property::UShort(x) => x as f32,
        Property::Char(x) => x as f32,
        Property::UChar(x) => x as f32,
        _ => return None,
    })
}

/// One PLY vertex as matfit reads it: position, normal and UV (under the three names PLY files
/// give it), NaN where the file has no such property. The parser hands over every property by
/// name; a typed element keeps only these (ply-rs's generic `DefaultElement` kept a hash map per
/// vertex and per face).
struct PlyVertex {
    p: [f32; 3],
    n: [f32; 3],
    /// u, s, texture_u and v, t, texture_v, in that order of preference.
    uv: [[f32; 3]; 2],
}

impl ply_rs_bw::ply::PropertyAccess for PlyVertex {
    fn new() -> Self {
        PlyVertex {
            p: [f32::NAN; 3],
            n: [f32::NAN; 3],
            uv: [[f32::NAN; 3]; 2],
        }
    }

    fn set_property(&mut self, name: String, p: ply_rs_bw::ply::Property) {
        let slot = match name.as_str() {
            "x" => &mut self.p[0],
            "y" => &mut self.p[1],
            "z" => &mut self.p[2],
            "nx" => &mut self.n[0],
            "ny" => &mut self.n[1],
            "nz" => &mut self.n[2],
            "u" => &mut self.uv[0][0],
            "s" => &mut self.uv[0][1],
            "texture_u" => &mut self.uv[0][2],
            "v" => &mut self.uv[1][0],
            "t" => &mut self.uv[1][1],
            "texture_v" => &mut self.uv[1][2],
            _ => return,
        };
        *slot = ply_number(&p).unwrap_or(f32::NAN);
    }
}

/// One PLY face: its vertex indices (`vertex_indices`, or `vertex_index` as some writers name
/// it), the first three inline so that a triangle needs no allocation of its own.
#[derive(Default)]
struct PlyFace {
    /// Whether an integer list was read.
    read: bool,
    len: usize,
    head: [u32; 3],
    rest: Vec<u32>,
}

impl ply_rs_bw::ply::PropertyAccess for PlyFace {
    fn new() -> Self {
        Self::default()
    }

    fn set_property(&mut self, name: String, p: ply_rs_bw::ply::Property) {
        use ply_rs_bw::ply::Property;
        if !(name == "vertex_indices" || (name == "vertex_index" && !self.read)) {
            return;
        }
        let idx: Vec<u32> = match p {
            Property::ListInt(v) => v.iter().map(|&x| x.max(0) as u32).collect(),
            Property::ListUInt(v) => v,
            Property::ListUChar(v) => v.iter().map(|&x| x as u32).collect(),
            Property::ListUShort(v) => v.iter().map(|&x| x as u32).collect(),
            Property::ListShort(v) => v.iter().map(|&x| x.max(0) as u32).collect(),
            Property::ListChar(v) => v.iter().map(|&x| x.max(0) as u32).collect(),
            _ => return,
        };
        self.read = true;
        self.len = idx.len();
        self.head = [0; 3];
        for (h, &i) in self.head.iter_mut().zip(&idx) {
            *h = i;
        }
        self.rest = idx.get(3..).map(<[u32]>::to_vec).unwrap_or_default();
    }
}

/// Elements matfit does not read (edges, materials, …): parsed past, kept as nothing.
struct PlyIgnored;

impl ply_rs_bw::ply::PropertyAccess for PlyIgnored {
    fn new() -> Self {
        PlyIgnored
    }
}

fn ply_from_bytes(bytes: &[u8], path: &Path) -> Result<TriangleMesh, String> {
    use ply_rs_bw::parser::Parser;
    let bad = |what: String| format!("mesh file {}: {what}", path.display());
    let unreadable = |e: std::io::Error| bad(format!("not a readable PLY file ({e})"));
    check_ply_header(bytes).map_err(|e| bad(format!("not a readable PLY file ({e})")))?;
    let mut reader = std::io::Cursor::new(bytes);
    let (vp, fp) = (Parser::<PlyVertex>::new(), Parser::<PlyFace>::new());
    let header = vp.read_header(&mut reader).map_err(unreadable)?;
    let (mut verts, mut faces) = (None, None);
    for element in header.elements.values() {
        match element.name.as_str() {
            "vertex" if verts.is_none() => {
                verts = Some(vp.read_payload_for_element(&mut reader, element, &header));
            }
            "face" if faces.is_none() => {
                faces = Some(fp.read_payload_for_element(&mut reader, element, &header));
            }
            _ => {
                Parser::<PlyIgnored>::new()
                    .read_payload_for_element(&mut reader, element, &header)
                    .map_err(unreadable)?;
            }
        }
    }
    let verts = verts
        .ok_or_else(|| bad("no 'vertex' element".into()))?
        .map_err(unreadable)?;
    let faces = faces
        .ok_or_else(|| bad("no 'face' element".into()))?
        .map_err(unreadable)?;
    let mut m = TriangleMesh::default();
    let (mut ns, mut uvs) = (Vec::new(), Vec::new());
    let given = |x: &[f32; 3]| x.iter().all(|c| !c.is_nan());
    for (i, v) in verts.iter().enumerate() {
        if !given(&v.p) {
            return Err(bad(format!("vertex {i} lacks numeric x, y, z")));
        }
        m.positions.push(Vec3::from_array(v.p));
        if given(&v.n) {
            ns.push(Vec3::from_array(v.n));
        }
        let first = |names: [f32; 3]| names.into_iter().find(|c| !c.is_nan());
        if let (Some(u), Some(w)) = (first(v.uv[0]), first(v.uv[1])) {
            uvs.push(Vec2::new(u, w));
        }
    }
    for (i, f) in faces.iter().enumerate() {
        if !f.read {
            return Err(bad(format!(
                "face {i} has no integer 'vertex_indices' list"
            )));
        }
        // Fan triangulation of polygons.
        let idx = |k: usize| if k < 3 { f.head[k] } else { f.rest[k - 3] };
        for k in 1..f.len.saturating_sub(1) {
            m.indices.push([idx(0), idx(k), idx(k + 1)]);
        }
    }
    m.normals = (ns.len() == m.positions.len() && !ns.is_empty()).then_some(ns);
    m.uvs = (uvs.len() == m.positions.len() && !uvs.is_empty()).then_some(uvs);
    Ok(m)
}

/// The file a glTF buffer URI names, if it names one (not a `data:` URI), resolved against
/// `base` as the gltf crate resolves it; Err for a relative URI whose percent-encoding is not
/// UTF-8, on which the gltf crate panics.
fn buffer_file(uri: &str, base: Option<&Path>) -> Result<Option<std::path::PathBuf>, String> {
    if uri.starts_with("data:") {
        return Ok(None);
    }
    if let Some(rest) = uri
        .strip_prefix("file://")
        .or_else(|| uri.strip_prefix("file:"))
    {
        return Ok(base.map(|_| std::path::PathBuf::from(rest)));
    }
    if uri.contains(':') {
        return Ok(None); // an unsupported scheme: the gltf crate refuses it
    }
    let b = uri.as_bytes();
    let mut out = Vec::with_capacity(b.len());
    let mut i = 0;
    while i < b.len() {
        if b[i] == b'%' && i + 2 < b.len() {
            let hex = std::str::from_utf8(&b[i + 1..i + 3]).ok();
            if let Some(v) = hex.and_then(|h| u8::from_str_radix(h, 16).ok()) {
                out.push(v);
                i += 3;
                continue;
            }
        }
        out.push(b[i]);
        i += 1;
    }
    let decoded = String::from_utf8(out).map_err(|_| "its percent-encoding is not UTF-8")?;
    Ok(base.map(|b| b.join(decoded)))
}

/// The bytes of an accessor's elements: (data, stride), every range checked. The gltf crate's
/// own readers panic on inconsistent accessors (overflowing offsets, a count of zero with a
/// sparse part, component types a semantic does not allow), so matfit reads them itself.
fn accessor_bytes<'b>(
    acc: &gltf::Accessor,
    buffers: &'b [gltf::buffer::Data],
    elem: usize,
) -> Result<(&'b [u8], usize), String> {
    if acc.sparse().is_some() {
        return Err("sparse accessors are not supported".into());
    }
    let view = acc.view().ok_or("the accessor has no buffer view")?;
    let data = buffers
        .get(view.buffer().index())
        .ok_or("the buffer view's buffer does not exist")?;
    let out_of_range = || {
        format!(
            "accessor {} reaches past the end of its buffer view or buffer",
            acc.index()
        )
    };
    let view_bytes = view
        .offset()
        .checked_add(view.length())
        .and_then(|end| data.0.get(view.offset()..end))
        .ok_or_else(out_of_range)?;
    let stride = view.stride().unwrap_or(elem);
    if stride < elem {
        return Err(format!(
            "accessor {}: byte stride {stride} is smaller than an element ({elem} bytes)",
            acc.index()
        ));
    }
    let count = acc.count();
    if count == 0 {
        return Ok((&[], stride));
    }
    let end = (count - 1)
        .checked_mul(stride)
        .and_then(|n| n.checked_add(elem))
        .and_then(|n| n.checked_add(acc.offset()))
        .ok_or_else(out_of_range)?;
    let bytes = view_bytes.get(acc.offset()..end).ok_or_else(out_of_range)?;
    Ok((bytes, stride))
}

/// An accessor of N-component vectors as f32 (float, or normalized unsigned byte / short).
fn read_floats<const N: usize>(
    acc: &gltf::Accessor,
    buffers: &[gltf::buffer::Data],
) -> Result<Vec<[f32; N]>, String> {
    use gltf::accessor::{DataType, Dimensions};
    let dims = match N {
        2 => Dimensions::Vec2,
        _ => Dimensions::Vec3,
    };
    if acc.dimensions() != dims {
        return Err(format!(
            "accessor {} is {:?}, expected {dims:?}",
            acc.index(),
            acc.dimensions()
        ));
    }
    let (size, scale): (usize, fn(&[u8]) -> f32) = match (acc.data_type(), acc.normalized()) {
        (DataType::F32, _) => (4, |b| f32::from_le_bytes([b[0], b[1], b[2], b[3]])),
        (DataType::U8, true) => (1, |b| b[0] as f32 / 255.0),
        (DataType::U16, true) => (2, |b| u16::from_le_bytes([b[0], b[1]]) as f32 / 65535.0),
        (t, n) => {
            return Err(format!(
                "accessor {} has components {t:?}{}, expected float",
                acc.index(),
                if n { " (normalized)" } else { "" }
            ))
        }
    };
    let (bytes, stride) = accessor_bytes(acc, buffers, size * N)?;
    Ok((0..acc.count())
        .map(|i| std::array::from_fn(|k| scale(&bytes[i * stride + k * size..])))
        .collect())
}

/// An index accessor (unsigned byte, short or int scalars).
fn read_indices(acc: &gltf::Accessor, buffers: &[gltf::buffer::Data]) -> Result<Vec<u32>, String> {
    use gltf::accessor::{DataType, Dimensions};
    if acc.dimensions() != Dimensions::Scalar {
        return Err(format!("accessor {} is not scalar", acc.index()));
    }
    let (size, read): (usize, fn(&[u8]) -> u32) = match acc.data_type() {
        DataType::U8 => (1, |b| b[0] as u32),
        DataType::U16 => (2, |b| u16::from_le_bytes([b[0], b[1]]) as u32),
        DataType::U32 => (4, |b| u32::from_le_bytes([b[0], b[1], b[2], b[3]])),
        t => {
            return Err(format!(
                "accessor {} has components {t:?}, expected unsigned integers",
                acc.index()
            ))
        }
    };
    let (bytes, stride) = accessor_bytes(acc, buffers, size)?;
    Ok((0..acc.count())
        .map(|i| read(&bytes[i * stride..]))
        .collect())
}

/// gltf's own validation (what `Gltf::from_slice` runs), after the check it lacks: it looks up
/// each primitive's POSITION accessor before checking that the index exists, and panics.
fn validate_gltf(root: &gltf::json::Root) -> Result<(), String> {
    use gltf::json::validation::Validate;
    for (m, mesh) in root.meshes.iter().enumerate() {
        for (p, prim) in mesh.primitives.iter().enumerate() {
            for acc in prim.attributes.values() {
                if acc.value() >= root.accessors.len() {
                    return Err(format!(
                        "mesh {m}, primitive {p}: accessor {} does not exist",
                        acc.value()
                    ));
                }
            }
        }
    }
    let mut errors = Vec::new();
    root.validate(root, gltf::json::Path::new, &mut |path, error| {
        errors.push(format!("{}: {error}", path()))
    });
    if errors.is_empty() {
        Ok(())
    } else {
        Err(errors.join("; "))
    }
}

fn gltf_from_bytes(bytes: &[u8], path: &Path, base: Option<&Path>) -> Result<TriangleMesh, String> {
    let bad = |what: String| format!("mesh file {}: {what}", path.display());
    let unreadable = |e: gltf::Error| bad(format!("not a readable glTF file ({e})"));
    // The gltf crate subtracts the header's size from the GLB length without checking it.
    if let Some(len) = bytes
        .strip_prefix(b"glTF")
        .and_then(|b| b.get(4..8))
        .map(|l| u32::from_le_bytes([l[0], l[1], l[2], l[3]]))
    {
        if len < 12 {
            return Err(bad(format!(
                "not a readable glTF file (the GLB header gives a length of {len} bytes, less \
                 than the header itself)"
            )));
        }
    }
    let gltf::Gltf {
        document: doc,
        blob,
    } = gltf::Gltf::from_slice_without_validation(bytes).map_err(unreadable)?;
    validate_gltf(doc.as_json()).map_err(|e| bad(format!("not a valid glTF file ({e})")))?;
    // Buffer files are checked before the gltf crate reads them whole.
    for b in doc.buffers() {
        if let gltf::buffer::Source::Uri(uri) = b.source() {
            let file = buffer_file(uri, base).map_err(|e| {
                bad(format!(
                    "buffer {} has an invalid URI '{uri}': {e}",
                    b.index()
                ))
            })?;
            if let Some(f) = file {
                match std::fs::metadata(&f) {
                    Ok(m) if !m.is_file() || m.len() > MAX_MESH_BYTES => {
                        return Err(bad(format!(
                            "buffer {}: {} is not a regular file of at most {} MB",
                            b.index(),
                            f.display(),
                            MAX_MESH_BYTES >> 20
                        )))
                    }
                    Ok(_) => {}
                    Err(e) => {
                        return Err(bad(format!(
                            "buffer {}: cannot read {}: {e}",
                            b.index(),
                            f.display()
                        )))
                    }
                }
            }
        }
    }
    let buffers = gltf::import_buffers(&doc, base, blob).map_err(unreadable)?;
    let mut parts = Vec::new();
    let scene = doc.default_scene().or_else(|| doc.scenes().next());
    let roots: Vec<gltf::Node> = match &scene {
        Some(s) => s.nodes().collect(),
        None => {
            // No scene: every node that is no other node's child is a root.
            let mut child = vec![false; doc.nodes().len()];
            for n in doc.nodes() {
                for c in n.children() {
                    child[c.index()] = true;
                }
            }
            doc.nodes().filter(|n| !child[n.index()]).collect()
        }
    };
    // glTF's node hierarchy is a set of disjoint trees: a node reached twice is a cycle (which
    // would never end) or a shared child; both are refused.
    let mut seen = vec![false; doc.nodes().len()];
    let mut stack: Vec<(gltf::Node, Mat4)> =
        roots.into_iter().map(|n| (n, Mat4::IDENTITY)).collect();
    while let Some((node, parent)) = stack.pop() {
        if std::mem::replace(&mut seen[node.index()], true) {
            return Err(bad(format!(
                "node {} is reached twice in the node hierarchy (a cycle or a shared child)",
                node.index()
            )));
        }
        let m = parent * Mat4::from_cols_array_2d(&node.transform().matrix());
        if let Some(mesh) = node.mesh() {
            for prim in mesh.primitives() {
                if prim.mode() != gltf::mesh::Mode::Triangles {
                    continue;
                }
                let get = |sem: gltf::Semantic| prim.get(&sem);
                let Some(pos) = get(gltf::Semantic::Positions) else {
                    continue;
                };
                let at = |what: &str, e: String| {
                    bad(format!(
                        "mesh {}, primitive {}: {what}: {e}",
                        mesh.index(),
                        prim.index()
                    ))
                };
                let positions: Vec<Vec3> = read_floats::<3>(&pos, &buffers)
                    .map_err(|e| at("POSITION", e))?
                    .into_iter()
                    .map(Vec3::from)
                    .collect();
                let indices: Vec<u32> = match prim.indices() {
                    Some(a) => read_indices(&a, &buffers).map_err(|e| at("indices", e))?,
                    None => (0..positions.len() as u32).collect(),
                };
                let normals = match get(gltf::Semantic::Normals) {
                    Some(a) => Some(
                        read_floats::<3>(&a, &buffers)
                            .map_err(|e| at("NORMAL", e))?
                            .into_iter()
                            .map(Vec3::from)
                            .collect(),
                    ),
                    None => None,
                };
                let uvs = match get(gltf::Semantic::TexCoords(0)) {
                    // glTF puts v = 0 at the top of the image; matfit's textures at the bottom.
                    Some(a) => Some(
                        read_floats::<2>(&a, &buffers)
                            .map_err(|e| at("TEXCOORD_0", e))?
                            .into_iter()
                            .map(|[u, v]| Vec2::new(u, 1.0 - v))
                            .collect(),
                    ),
                    None => None,
                };
                let mut part = TriangleMesh {
                    normals,
                    uvs,
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

    /// Inputs that made the parsers underneath panic, loop or exhaust memory are refused with a
    /// message instead.
    #[test]
    fn hostile_mesh_files_are_refused_not_crashed_on() {
        let p = |name: &str| Path::new(name).to_path_buf();
        let cases: [(&str, &[u8], &str); 5] = [
            (
                "big.ply",
                b"ply\nformat ascii 1.0\nelement vertex 123456789012345678901\nproperty float x\nend_header\n",
                "number too large",
            ),
            (
                "noprop.ply",
                b"ply\nformat binary_little_endian 1.0\nelement vertex 9000000000\nend_header\n",
                "claims 9000000000 entries",
            ),
            (
                "noprop2.ply",
                b"ply\nformat ascii 1.0\nelement vertex 3\nend_header\n\n\n\n",
                "no properties",
            ),
            (
                "cycle.gltf",
                br#"{"asset":{"version":"2.0"},"nodes":[{"children":[1]},{"children":[0]}],"scenes":[{"nodes":[0]}]}"#,
                "reached twice",
            ),
            (
                "uri.gltf",
                br#"{"asset":{"version":"2.0"},"buffers":[{"byteLength":4,"uri":"%ff%fe.bin"}]}"#,
                "percent-encoding",
            ),
        ];
        let dir = tempfile::tempdir().unwrap();
        for (name, bytes, needle) in cases {
            let e = mesh_from_bytes(bytes, &p(name), Some(dir.path())).unwrap_err();
            assert!(e.contains(name) && e.contains(needle), "{name}: {e}");
        }
    }
}
