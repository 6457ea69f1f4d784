//! glTF 2.0 surface reader (`.gltf` with external `.bin` or base64 data-URI buffers, and binary
//! `.glb`).
//!
//! The `gltf` crate (1.4) parses and validates the JSON and splits GLB chunks. Malformed input
//! must give an error, never a panic, and the crate can panic on three kinds of bad file, so
//! this module checks first or does the work itself:
//! - a GLB header declaring a length below 12 bytes underflows in its splitter
//!   (`check_glb_header` runs before it);
//! - its validation indexes the accessor list with a primitive's POSITION attribute unchecked
//!   (`check_before_validation` runs before it);
//! - its accessor iterators assume well-formed accessors (a zero count or a mismatched type
//!   panics), so buffers and accessors are read here with explicit bounds checks.
//!
//! `truncations_and_corruptions_never_panic` and `json_field_mutations_never_panic` in
//! tests/mesh_io.rs exercise this.
//!
//! Geometry: every mesh instance of the default scene (else the first scene) is placed with its
//! node's world transform (parent x ... x node, each node `T * R * S` or its `matrix`), in f64.
//! Without any scene every mesh is taken once, untransformed. glTF units are metres. When a
//! world transform mirrors (negative determinant) the winding is reversed, as the glTF spec
//! prescribes, so outward faces stay outward.
//!
//! glTF stores vertices per primitive and exporters duplicate them at normal and UV seams, so a
//! closed model usually reads as an open mesh: call [`TriMesh::weld`] before
//! [`TriMesh::validate_solid`].

use std::path::{Path, PathBuf};

use ::gltf::accessor::{DataType, Dimensions};
use ::gltf::mesh::{Mode, Semantic};
use ::gltf::scene::Transform;
use ::gltf::{Accessor, Document, Node};
use base64::Engine as _;

use super::error::MeshError;
use super::trimesh::TriMesh;

/// Extensions that change how geometry is stored; files requiring them cannot be read here.
const UNSUPPORTED_GEOMETRY_EXTENSIONS: [&str; 3] =
    ["KHR_draco_mesh_compression", "EXT_meshopt_compression", "KHR_mesh_quantization"];

/// Row-major 4x4 affine transform acting on column vectors `[x, y, z, 1]`.
type Mat4 = [[f64; 4]; 4];

const IDENTITY: Mat4 = [[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0]];

/// Read the triangles of a `.gltf` or `.glb` file as one [`TriMesh`] in world coordinates
/// (metres). Only positions and indices are used; primitives must have mode TRIANGLES.
/// Non-indexed primitives use their vertices in order.
///
/// # Errors
/// - [`MeshError::Io`] if the file cannot be read;
/// - [`MeshError::Parse`] for invalid JSON, a truncated or malformed GLB, glTF validation
///   errors, unsupported features (other primitive modes, sparse or quantized accessors,
///   compression extensions, non-base64 or remote URIs), or accessors and buffer views that
///   run past the end of their data;
/// - [`MeshError::InFile`] wrapping [`MeshError::Io`] when an external buffer file cannot be
///   read, [`MeshError::IndexOutOfRange`] for an index past the end of its primitive's vertices
///   (reported in the numbering of the merged mesh), or any other [`TriMesh::try_new`] error.
pub fn read_gltf(path: &Path) -> Result<TriMesh, MeshError> {
    let bytes = std::fs::read(path).map_err(|source| MeshError::Io { path: path.to_path_buf(), source })?;
    let parse = |message: String| MeshError::Parse { path: path.to_path_buf(), message };
    check_glb_header(&bytes).map_err(parse)?;
    let ::gltf::Gltf { document, blob } = ::gltf::Gltf::from_slice_without_validation(&bytes)
        .map_err(|e| parse(format!("not a valid glTF 2.0 file: {e}")))?;
    let root = document.into_json();
    check_before_validation(&root).map_err(parse)?;
    let document = ::gltf::Document::from_json(root).map_err(|e| parse(format!("not a valid glTF 2.0 file: {e}")))?;
    let document = &document;
    let base = path.parent().unwrap_or(Path::new(""));
    let buffers = load_buffers(document, base, blob.as_deref(), path)?;

    let mut verts: Vec<[f64; 3]> = Vec::new();
    let mut tris: Vec<[usize; 3]> = Vec::new();
    for (mesh_index, world) in mesh_instances(document).map_err(parse)? {
        let mesh =
            document.meshes().nth(mesh_index).ok_or_else(|| parse(format!("mesh {mesh_index} does not exist")))?;
        for primitive in mesh.primitives() {
            let what = format!(
                "mesh {}{} primitive {}",
                mesh_index,
                mesh.name().map(|n| format!(" (\"{n}\")")).unwrap_or_default(),
                primitive.index()
            );
            append_primitive(&primitive, &what, &world, &buffers, &mut verts, &mut tris).map_err(|e| match e {
                PrimitiveError::Parse(message) => parse(message),
                PrimitiveError::Mesh(e) => e.in_file(path),
            })?;
        }
    }
    TriMesh::try_new(verts, tris).map_err(|e| e.in_file(path))
}

/// Checks that must precede `gltf`'s own validation: it indexes the accessor list with the
/// POSITION attribute without a bounds check (a panic on malformed files), and it rejects
/// compression extensions with a terse "Unsupported" where we can say what to do.
fn check_before_validation(root: &::gltf::json::Root) -> Result<(), String> {
    if let Some(ext) = root.extensions_required.iter().find(|e| UNSUPPORTED_GEOMETRY_EXTENSIONS.contains(&e.as_str())) {
        return Err(format!(
            "the file requires the extension {ext}, which this reader does not support \
             (re-export without mesh compression or quantization)"
        ));
    }
    let position = ::gltf::json::validation::Checked::Valid(::gltf::json::mesh::Semantic::Positions);
    for (m, mesh) in root.meshes.iter().enumerate() {
        for (p, primitive) in mesh.primitives.iter().enumerate() {
            if let Some(index) = primitive.attributes.get(&position) {
                if index.value() >= root.accessors.len() {
                    return Err(format!(
                        "mesh {m} primitive {p}: POSITION refers to accessor {}, but the file \
                         has {} accessors",
                        index.value(),
                        root.accessors.len()
                    ));
                }
            }
        }
    }
    Ok(())
}

/// The `gltf` crate's GLB splitter subtracts the header size from the declared length without
/// checking it (a panic in debug builds) and trusts the length when allocating; check first.
fn check_glb_header(bytes: &[u8]) -> Result<(), String> {
    if !bytes.starts_with(b"glTF") {
        return Ok(());
    }
    let word = |k: usize| bytes.get(4 * k..4 * k + 4).map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]));
    let (Some(version), Some(length)) = (word(1), word(2)) else {
        return Err(format!("truncated GLB: the file has {} bytes, fewer than the 12-byte header", bytes.len()));
    };
    if version != 2 {
        return Err(format!("GLB container version {version} is not supported (only glTF 2.0)"));
    }
    // 12-byte header + 8-byte JSON chunk header at least.
    if length < 20 {
        return Err(format!(
            "malformed GLB: the header declares a total length of {length} bytes, \
             less than the 20-byte minimum"
        ));
    }
    if length as usize > bytes.len() {
        return Err(format!("truncated GLB: the header declares {length} bytes but the file has only {}", bytes.len()));
    }
    Ok(())
}

/// Load every buffer: the GLB binary chunk, a base64 data URI, or a file relative to `base`.
fn load_buffers(document: &Document, base: &Path, blob: Option<&[u8]>, path: &Path) -> Result<Vec<Vec<u8>>, MeshError> {
    let parse = |message: String| MeshError::Parse { path: path.to_path_buf(), message };
    let engine = base64::engine::GeneralPurpose::new(
        &base64::alphabet::STANDARD,
        base64::engine::GeneralPurposeConfig::new()
            .with_decode_padding_mode(base64::engine::DecodePaddingMode::Indifferent),
    );
    let mut out = Vec::new();
    for buffer in document.buffers() {
        let i = buffer.index();
        let data: Vec<u8> = match buffer.source() {
            ::gltf::buffer::Source::Bin => blob
                .ok_or_else(|| parse(format!("buffer {i} refers to the GLB binary chunk, but the file has none")))?
                .to_vec(),
            ::gltf::buffer::Source::Uri(uri) if uri.starts_with("data:") => {
                let Some((_, payload)) = uri.split_once(";base64,") else {
                    return Err(parse(format!(
                        "buffer {i} has a data URI that is not base64-encoded, which is not supported"
                    )));
                };
                engine
                    .decode(payload.trim())
                    .map_err(|e| parse(format!("buffer {i} has an invalid base64 data URI: {e}")))?
            }
            ::gltf::buffer::Source::Uri(uri) => {
                if uri.contains("://") {
                    return Err(parse(format!(
                        "buffer {i} refers to \"{uri}\"; only relative file paths and data URIs \
                         are supported"
                    )));
                }
                let file: PathBuf = base.join(percent_decode(uri));
                std::fs::read(&file).map_err(|source| MeshError::Io { path: file, source }.in_file(path))?
            }
        };
        if data.len() < buffer.length() {
            return Err(parse(format!(
                "buffer {i} declares {} bytes but only {} are available (truncated data?)",
                buffer.length(),
                data.len()
            )));
        }
        out.push(data);
    }
    Ok(out)
}

/// Decode `%XX` escapes in a relative URI (other bytes are kept as they are).
fn percent_decode(uri: &str) -> String {
    let b = uri.as_bytes();
    let mut out = Vec::with_capacity(b.len());
    let mut k = 0;
    while k < b.len() {
        let hex = |c: u8| (c as char).to_digit(16);
        if b[k] == b'%' && k + 2 < b.len() {
            if let (Some(h), Some(l)) = (hex(b[k + 1]), hex(b[k + 2])) {
                out.push((16 * h + l) as u8);
                k += 3;
                continue;
            }
        }
        out.push(b[k]);
        k += 1;
    }
    String::from_utf8_lossy(&out).into_owned()
}

/// `(mesh index, world transform)` for every mesh instance, in depth-first scene order.
fn mesh_instances(document: &Document) -> Result<Vec<(usize, Mat4)>, String> {
    let Some(scene) = document.default_scene().or_else(|| document.scenes().next()) else {
        return Ok(document.meshes().map(|m| (m.index(), IDENTITY)).collect());
    };
    let mut out = Vec::new();
    let mut visited = vec![false; document.nodes().len()];
    // Explicit stack (no recursion, so a deep hierarchy cannot overflow the call stack);
    // children are pushed in reverse to visit them in file order.
    let mut stack: Vec<(Node, Mat4)> = scene.nodes().map(|n| (n, IDENTITY)).collect();
    stack.reverse();
    while let Some((node, parent)) = stack.pop() {
        let seen = visited.get_mut(node.index()).ok_or_else(|| format!("node {} does not exist", node.index()))?;
        if *seen {
            return Err(format!(
                "node {} is reached twice while traversing scene {} (a cycle, or a node with \
                 two parents); glTF requires the node hierarchy to be a forest",
                node.index(),
                scene.index()
            ));
        }
        *seen = true;
        let world = mat_mul(&parent, &local_transform(&node)?);
        if let Some(mesh) = node.mesh() {
            out.push((mesh.index(), world));
        }
        let children: Vec<Node> = node.children().collect();
        stack.extend(children.into_iter().rev().map(|c| (c, world)));
    }
    Ok(out)
}

/// The node's local transform in f64: its `matrix` (column-major in the file), or
/// `T * R * S` from translation, unit quaternion `[x, y, z, w]` and scale.
fn local_transform(node: &Node) -> Result<Mat4, String> {
    match node.transform() {
        Transform::Matrix { matrix } => {
            let mut m = IDENTITY;
            for (r, row) in m.iter_mut().enumerate() {
                for (c, x) in row.iter_mut().enumerate() {
                    *x = f64::from(matrix[c][r]);
                }
            }
            Ok(m)
        }
        Transform::Decomposed { translation, rotation, scale } => {
            trs_matrix(translation, rotation, scale).ok_or_else(|| {
                format!("node {} has rotation quaternion {rotation:?}, which cannot be normalised", node.index())
            })
        }
    }
}

/// `T * R * S` for translation `t`, rotation quaternion `q = [x, y, z, w]` (normalised here)
/// and per-axis scale `s`; `None` if `q` has zero or non-finite length.
fn trs_matrix(t: [f32; 3], q: [f32; 4], s: [f32; 3]) -> Option<Mat4> {
    let [x, y, z, w] = q.map(f64::from);
    let len = (x * x + y * y + z * z + w * w).sqrt();
    if !(len > 0.0 && len.is_finite()) {
        return None;
    }
    let (x, y, z, w) = (x / len, y / len, z / len, w / len);
    let r = [
        [1.0 - 2.0 * (y * y + z * z), 2.0 * (x * y - z * w), 2.0 * (x * z + y * w)],
        [2.0 * (x * y + z * w), 1.0 - 2.0 * (x * x + z * z), 2.0 * (y * z - x * w)],
        [2.0 * (x * z - y * w), 2.0 * (y * z + x * w), 1.0 - 2.0 * (x * x + y * y)],
    ];
    let mut m = IDENTITY;
    for i in 0..3 {
        for j in 0..3 {
            m[i][j] = r[i][j] * f64::from(s[j]);
        }
        m[i][3] = f64::from(t[i]);
    }
    Some(m)
}

fn mat_mul(a: &Mat4, b: &Mat4) -> Mat4 {
    let mut m = [[0.0; 4]; 4];
    for (i, row) in m.iter_mut().enumerate() {
        for (j, x) in row.iter_mut().enumerate() {
            *x = (0..4).map(|k| a[i][k] * b[k][j]).sum();
        }
    }
    m
}

fn apply(m: &Mat4, p: [f64; 3]) -> [f64; 3] {
    [0, 1, 2].map(|i| m[i][0] * p[0] + m[i][1] * p[1] + m[i][2] * p[2] + m[i][3])
}

fn det3(m: &Mat4) -> f64 {
    m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1]) - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
        + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0])
}

enum PrimitiveError {
    Parse(String),
    Mesh(MeshError),
}

impl From<String> for PrimitiveError {
    fn from(s: String) -> Self {
        PrimitiveError::Parse(s)
    }
}

fn append_primitive(
    primitive: &::gltf::Primitive,
    what: &str,
    world: &Mat4,
    buffers: &[Vec<u8>],
    verts: &mut Vec<[f64; 3]>,
    tris: &mut Vec<[usize; 3]>,
) -> Result<(), PrimitiveError> {
    if primitive.mode() != Mode::Triangles {
        return Err(format!(
            "{what} uses primitive mode {:?}; only Triangles (mode 4) is supported \
             (export triangle lists, not strips, fans, lines or points)",
            primitive.mode()
        )
        .into());
    }
    let positions = primitive.get(&Semantic::Positions).ok_or_else(|| format!("{what} has no POSITION attribute"))?;
    if positions.data_type() != DataType::F32 || positions.dimensions() != Dimensions::Vec3 {
        return Err(format!(
            "{what}: POSITION accessor {} is {:?} of {:?}; only Vec3 of F32 is supported",
            positions.index(),
            positions.dimensions(),
            positions.data_type()
        )
        .into());
    }
    let offset = verts.len();
    read_elements(&positions, buffers, what, |b| {
        let c = |k: usize| f32::from_le_bytes([b[4 * k], b[4 * k + 1], b[4 * k + 2], b[4 * k + 3]]);
        verts.push(apply(world, [c(0), c(1), c(2)].map(f64::from)));
    })?;
    let vertex_count = verts.len() - offset;

    let indices: Vec<usize> = match primitive.indices() {
        None => (0..vertex_count).collect(),
        Some(acc) => {
            let width = match (acc.data_type(), acc.dimensions()) {
                (DataType::U8, Dimensions::Scalar) => 1,
                (DataType::U16, Dimensions::Scalar) => 2,
                (DataType::U32, Dimensions::Scalar) => 4,
                (t, d) => {
                    return Err(format!(
                        "{what}: index accessor {} is {d:?} of {t:?}; indices must be scalar \
                         U8, U16 or U32",
                        acc.index()
                    )
                    .into())
                }
            };
            // No capacity from acc.count(): it is untrusted until read_elements checks it
            // against the buffer view.
            let mut out = Vec::new();
            read_elements(&acc, buffers, what, |b| {
                out.push(match width {
                    1 => usize::from(b[0]),
                    2 => usize::from(u16::from_le_bytes([b[0], b[1]])),
                    _ => u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as usize,
                })
            })?;
            out
        }
    };
    if !indices.len().is_multiple_of(3) {
        return Err(format!(
            "{what} has {} vertex indices, which is not a multiple of 3 (one triangle per 3)",
            indices.len()
        )
        .into());
    }
    // A mirroring transform reverses the winding (glTF spec, "Meshes"); undo it.
    let mirrored = det3(world) < 0.0;
    for corner in indices.chunks_exact(3) {
        if let Some(&bad) = corner.iter().find(|&&i| i >= vertex_count) {
            return Err(PrimitiveError::Mesh(MeshError::IndexOutOfRange {
                face: tris.len(),
                index: offset + bad,
                vertex_count: offset + vertex_count,
            }));
        }
        let [a, b, c] = [corner[0], corner[1], corner[2]].map(|i| offset + i);
        tris.push(if mirrored { [a, c, b] } else { [a, b, c] });
    }
    Ok(())
}

/// Call `f` with the bytes of each element of a (non-sparse) accessor, checking every offset
/// against the buffer view and the buffer.
fn read_elements(acc: &Accessor, buffers: &[Vec<u8>], what: &str, mut f: impl FnMut(&[u8])) -> Result<(), String> {
    let i = acc.index();
    if acc.sparse().is_some() {
        return Err(format!("{what}: accessor {i} is sparse, which is not supported"));
    }
    let Some(view) = acc.view() else {
        return Err(format!("{what}: accessor {i} has no buffer view (all zeros), which cannot describe a surface"));
    };
    let elem = acc.size();
    let stride = view.stride().unwrap_or(elem);
    if stride < elem {
        return Err(format!(
            "{what}: buffer view {} has byte stride {stride}, smaller than the {elem}-byte \
             elements of accessor {i}",
            view.index()
        ));
    }
    let buffer = buffers
        .get(view.buffer().index())
        .ok_or_else(|| format!("{what}: buffer {} does not exist", view.buffer().index()))?;
    let view_bytes =
        view.offset().checked_add(view.length()).and_then(|end| buffer.get(view.offset()..end)).ok_or_else(|| {
            format!(
                "{what}: buffer view {} (offset {}, length {}) runs past the end of buffer {} \
                 ({} bytes)",
                view.index(),
                view.offset(),
                view.length(),
                view.buffer().index(),
                buffer.len()
            )
        })?;
    let count = acc.count();
    if count == 0 {
        return Ok(());
    }
    let needed =
        (count - 1).checked_mul(stride).and_then(|x| x.checked_add(elem)).and_then(|x| x.checked_add(acc.offset()));
    match needed {
        Some(n) if n <= view_bytes.len() => {}
        _ => {
            return Err(format!(
                "{what}: accessor {i} ({count} elements of {elem} bytes, stride {stride}, \
                 offset {}) runs past the end of buffer view {} ({} bytes)",
                acc.offset(),
                view.index(),
                view_bytes.len()
            ))
        }
    }
    for k in 0..count {
        let start = acc.offset() + k * stride;
        f(&view_bytes[start..start + elem]);
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn glb_header_checks() {
        assert!(check_glb_header(b"{\"asset\":{}}").is_ok());
        assert!(check_glb_header(b"glTF\x02\x00").unwrap_err().contains("fewer than the 12-byte header"));
        let mut h = b"glTF".to_vec();
        h.extend(2u32.to_le_bytes());
        h.extend(4u32.to_le_bytes());
        assert!(check_glb_header(&h).unwrap_err().contains("20-byte minimum"));
        let mut h = b"glTF".to_vec();
        h.extend(2u32.to_le_bytes());
        h.extend(1000u32.to_le_bytes());
        assert!(check_glb_header(&h).unwrap_err().contains("declares 1000 bytes but the file has only 12"));
    }

    #[test]
    fn trs_rotates_scales_then_translates() {
        // 90 degrees about +z maps x to y; scale 2 along x first; then translate by (1, 2, 3).
        let h = std::f32::consts::FRAC_1_SQRT_2;
        let m = trs_matrix([1.0, 2.0, 3.0], [0.0, 0.0, h, h], [2.0, 1.0, 1.0]).unwrap();
        let p = apply(&m, [1.0, 0.0, 0.0]);
        let want = [1.0, 4.0, 3.0];
        for k in 0..3 {
            assert!((p[k] - want[k]).abs() < 1e-6, "{p:?}");
        }
        assert!((det3(&m) - 2.0).abs() < 1e-6);
        let mirror = trs_matrix([0.0; 3], [0.0, 0.0, 0.0, 1.0], [-1.0, 1.0, 1.0]).unwrap();
        assert!(det3(&mirror) < 0.0);
        assert_eq!(mat_mul(&IDENTITY, &m), m);
        assert!(trs_matrix([0.0; 3], [0.0; 4], [1.0; 3]).is_none());
    }

    #[test]
    fn percent_decoding() {
        assert_eq!(percent_decode("a%20b.bin"), "a b.bin");
        assert_eq!(percent_decode("100%"), "100%");
        assert_eq!(percent_decode("%4"), "%4");
    }
}
