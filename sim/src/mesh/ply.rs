//! Stanford PLY surface reader and writer.
//!
//! Reading: `format ascii 1.0` and `format binary_little_endian 1.0` (big-endian files are
//! refused with a clear message). From the `vertex` element the properties `x`, `y`, `z`
//! (any scalar type; metres) are used; from the `face` element the list property
//! `vertex_indices` (or `vertex_index`) with any integer count and index type (in practice
//! `uchar`/`int`/`uint`). Polygons are fan-triangulated `(a, b_k, b_k+1)` as in the OBJ
//! reader. Every other element and property (colours, normals, edges, materials) is read past
//! and ignored. Errors name the header line, or the element and its 0-based record for the
//! body (and the line for ASCII bodies).
//!
//! Writing ([`write_ply`]): `binary_little_endian`, vertex coordinates as `double` (metres,
//! lossless), optional extra per-vertex `float` properties (e.g. a signed error in metres for
//! colouring in a viewer), faces as `list uchar int vertex_indices`.

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::Path;

use super::error::MeshError;
use super::trimesh::TriMesh;

/// Read a triangle surface from a PLY file (coordinates taken as metres).
///
/// # Errors
/// - [`MeshError::Io`] if the file cannot be read;
/// - [`MeshError::Parse`] naming the header line or the element record for a malformed
///   header, an unsupported format or type, a missing `x`/`y`/`z` or `vertex_indices`
///   property, a truncated body, a non-numeric value, a face with fewer than 3 vertices or a
///   negative index;
/// - [`MeshError::InFile`] wrapping the [`TriMesh::try_new`] error for an empty mesh, NaN or
///   infinite coordinates, an index past the last vertex or a face repeating a vertex.
pub fn read_ply(path: &Path) -> Result<TriMesh, MeshError> {
    let bytes = std::fs::read(path).map_err(|source| MeshError::Io { path: path.to_path_buf(), source })?;
    let (verts, tris) = parse_ply(&bytes).map_err(|message| MeshError::Parse { path: path.to_path_buf(), message })?;
    TriMesh::try_new(verts, tris).map_err(|e| e.in_file(path))
}

/// Write `mesh` to `path` as binary little-endian PLY (see [`write_ply_to`]).
pub fn write_ply(path: &Path, mesh: &TriMesh, vertex_props: &[(&str, &[f32])], comment: &str) -> std::io::Result<()> {
    let mut w = BufWriter::new(File::create(path)?);
    write_ply_to(&mut w, mesh, vertex_props, comment)?;
    w.flush()
}

/// Write `mesh` as binary little-endian PLY: each line of `comment` as a `comment` header
/// line, vertices `double x, y, z` (metres) followed by one `float` per entry of
/// `vertex_props` (name, one value per vertex), faces `list uchar int vertex_indices`.
///
/// # Errors
/// `InvalidInput` if a property has the wrong length or a name that is not a single word, or
/// the mesh has more than `i32::MAX` vertices; otherwise the writer's errors.
pub fn write_ply_to(
    w: &mut impl Write,
    mesh: &TriMesh,
    vertex_props: &[(&str, &[f32])],
    comment: &str,
) -> std::io::Result<()> {
    let invalid = |m: String| std::io::Error::new(std::io::ErrorKind::InvalidInput, m);
    for (name, values) in vertex_props {
        if values.len() != mesh.verts.len() {
            return Err(invalid(format!(
                "PLY vertex property {name} has {} values for {} vertices",
                values.len(),
                mesh.verts.len()
            )));
        }
        if name.is_empty() || name.chars().any(|c| c.is_whitespace()) || ["x", "y", "z"].contains(name) {
            return Err(invalid(format!("PLY vertex property name {name:?} must be one word other than x, y, z")));
        }
    }
    if mesh.verts.len() > i32::MAX as usize {
        return Err(invalid(format!("{} vertices do not fit PLY int indices", mesh.verts.len())));
    }
    writeln!(w, "ply")?;
    writeln!(w, "format binary_little_endian 1.0")?;
    for line in comment.lines() {
        writeln!(w, "comment {line}")?;
    }
    writeln!(w, "comment coordinates in metres")?;
    writeln!(w, "element vertex {}", mesh.verts.len())?;
    for axis in ["x", "y", "z"] {
        writeln!(w, "property double {axis}")?;
    }
    for (name, _) in vertex_props {
        writeln!(w, "property float {name}")?;
    }
    writeln!(w, "element face {}", mesh.tris.len())?;
    writeln!(w, "property list uchar int vertex_indices")?;
    writeln!(w, "end_header")?;
    let mut buf = Vec::with_capacity(mesh.verts.len() * (24 + 4 * vertex_props.len()) + mesh.tris.len() * 13);
    for (i, p) in mesh.verts.iter().enumerate() {
        for c in p {
            buf.extend_from_slice(&c.to_le_bytes());
        }
        for (_, values) in vertex_props {
            buf.extend_from_slice(&values[i].to_le_bytes());
        }
    }
    for t in &mesh.tris {
        buf.push(3u8);
        for &v in t {
            buf.extend_from_slice(&(v as i32).to_le_bytes());
        }
    }
    w.write_all(&buf)
}

/// Scalar types of PLY properties (both the classic and the sized names).
#[derive(Clone, Copy, Debug, PartialEq)]
enum Scalar {
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    F32,
    F64,
}

impl Scalar {
    fn parse(word: &str) -> Option<Scalar> {
        Some(match word {
            "char" | "int8" => Scalar::I8,
            "uchar" | "uint8" => Scalar::U8,
            "short" | "int16" => Scalar::I16,
            "ushort" | "uint16" => Scalar::U16,
            "int" | "int32" => Scalar::I32,
            "uint" | "uint32" => Scalar::U32,
            "float" | "float32" => Scalar::F32,
            "double" | "float64" => Scalar::F64,
            _ => return None,
        })
    }

    fn size(self) -> usize {
        match self {
            Scalar::I8 | Scalar::U8 => 1,
            Scalar::I16 | Scalar::U16 => 2,
            Scalar::I32 | Scalar::U32 | Scalar::F32 => 4,
            Scalar::F64 => 8,
        }
    }

    fn is_integer(self) -> bool {
        !matches!(self, Scalar::F32 | Scalar::F64)
    }

    /// Little-endian value at the start of `b` (which holds at least `size()` bytes).
    fn read_le(self, b: &[u8]) -> f64 {
        match self {
            Scalar::I8 => b[0] as i8 as f64,
            Scalar::U8 => b[0] as f64,
            Scalar::I16 => i16::from_le_bytes([b[0], b[1]]) as f64,
            Scalar::U16 => u16::from_le_bytes([b[0], b[1]]) as f64,
            Scalar::I32 => i32::from_le_bytes([b[0], b[1], b[2], b[3]]) as f64,
            Scalar::U32 => u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as f64,
            Scalar::F32 => f32::from_le_bytes([b[0], b[1], b[2], b[3]]) as f64,
            Scalar::F64 => f64::from_le_bytes([b[0], b[1], b[2], b[3], b[4], b[5], b[6], b[7]]),
        }
    }
}

#[derive(Debug)]
enum PropKind {
    Scalar(Scalar),
    List { count: Scalar, item: Scalar },
}

#[derive(Debug)]
struct Property {
    name: String,
    kind: PropKind,
}

#[derive(Debug)]
struct Element {
    name: String,
    count: usize,
    props: Vec<Property>,
    /// 1-based header line of the `element` statement.
    line: usize,
}

#[derive(Clone, Copy, PartialEq)]
enum Format {
    Ascii,
    BinaryLe,
}

type VertsTris = (Vec<[f64; 3]>, Vec<[usize; 3]>);

/// One element record's values: scalars as f64, lists as their items.
enum Value {
    Scalar(f64),
    List(Vec<f64>),
}

/// Where the values we need sit in the vertex and face records.
struct Layout {
    xyz: [usize; 3],
    indices: Option<usize>,
}

fn parse_ply(bytes: &[u8]) -> Result<VertsTris, String> {
    let (format, elements, body_start, header_lines) = parse_header(bytes)?;
    // Which properties we need.
    let mut layouts: Vec<Layout> = Vec::new();
    let mut have_vertex = false;
    for e in &elements {
        let mut l = Layout { xyz: [usize::MAX; 3], indices: None };
        if e.name == "vertex" {
            have_vertex = true;
            for (axis, slot) in ["x", "y", "z"].iter().zip(l.xyz.iter_mut()) {
                let Some(k) = e.props.iter().position(|p| p.name == *axis) else {
                    return Err(format!("line {}: element vertex has no property {axis}", e.line));
                };
                if !matches!(e.props[k].kind, PropKind::Scalar(_)) {
                    return Err(format!("line {}: vertex property {axis} must be a scalar, not a list", e.line));
                }
                *slot = k;
            }
        } else if e.name == "face" {
            let Some(k) = e.props.iter().position(|p| p.name == "vertex_indices" || p.name == "vertex_index") else {
                return Err(format!("line {}: element face has no list property vertex_indices", e.line));
            };
            match e.props[k].kind {
                PropKind::List { count, item } if count.is_integer() && item.is_integer() => {}
                _ => {
                    return Err(format!(
                        "line {}: face property vertex_indices must be a list of integers with an integer count",
                        e.line
                    ))
                }
            }
            l.indices = Some(k);
        }
        layouts.push(l);
    }
    if !have_vertex {
        return Err("the header declares no element vertex".into());
    }
    let mut verts = Vec::new();
    let mut tris = Vec::new();
    let mut reader = BodyReader { bytes, pos: body_start, line: header_lines + 1, format };
    for (e, l) in elements.iter().zip(&layouts) {
        for record in 0..e.count {
            let where_ = |reader: &BodyReader| match format {
                Format::Ascii => format!("line {}: element {} record {record}", reader.line, e.name),
                Format::BinaryLe => format!("element {} record {record} (byte {})", e.name, reader.pos),
            };
            let values = reader.record(e).map_err(|m| format!("{}: {m}", where_(&reader)))?;
            if e.name == "vertex" {
                let get = |k: usize| match values[k] {
                    Value::Scalar(v) => v,
                    Value::List(_) => f64::NAN,
                };
                verts.push([get(l.xyz[0]), get(l.xyz[1]), get(l.xyz[2])]);
            } else if let Some(k) = l.indices {
                let Value::List(idx) = &values[k] else { unreachable!("checked in the header") };
                if idx.len() < 3 {
                    return Err(format!(
                        "{}: a face needs at least 3 vertices, this one has {}",
                        where_(&reader),
                        idx.len()
                    ));
                }
                if let Some(bad) = idx.iter().find(|v| **v < 0.0) {
                    return Err(format!("{}: negative vertex index {bad}", where_(&reader)));
                }
                let idx: Vec<usize> = idx.iter().map(|&v| v as usize).collect();
                for k in 1..idx.len() - 1 {
                    tris.push([idx[0], idx[k], idx[k + 1]]);
                }
            }
            if format == Format::Ascii {
                reader.end_line().map_err(|m| format!("{}: {m}", where_(&reader)))?;
            }
        }
    }
    Ok((verts, tris))
}

/// Parses the header: format, elements, byte offset of the body, number of header lines.
fn parse_header(bytes: &[u8]) -> Result<(Format, Vec<Element>, usize, usize), String> {
    let mut pos = 0;
    let mut lineno = 0;
    let mut format = None;
    let mut elements: Vec<Element> = Vec::new();
    loop {
        let Some(len) = bytes[pos..].iter().position(|&b| b == b'\n') else {
            return Err(if lineno == 0 {
                "not a PLY file: the first line must be \"ply\"".into()
            } else {
                format!("line {}: the header ends without \"end_header\"", lineno + 1)
            });
        };
        lineno += 1;
        let raw = &bytes[pos..pos + len];
        pos += len + 1;
        let line = std::str::from_utf8(raw)
            .map_err(|_| format!("line {lineno}: the header is not text"))?
            .trim_end_matches('\r')
            .trim();
        let words: Vec<&str> = line.split_whitespace().collect();
        if lineno == 1 {
            if line != "ply" {
                return Err("not a PLY file: the first line must be \"ply\"".into());
            }
            continue;
        }
        match words.first().copied() {
            None | Some("comment") | Some("obj_info") => {}
            Some("format") => {
                if words.len() != 3 {
                    return Err(format!("line {lineno}: expected \"format <ascii|binary_little_endian> 1.0\""));
                }
                if words[2] != "1.0" {
                    return Err(format!("line {lineno}: unsupported PLY version {}; only 1.0 exists", words[2]));
                }
                format = Some(match words[1] {
                    "ascii" => Format::Ascii,
                    "binary_little_endian" => Format::BinaryLe,
                    "binary_big_endian" => {
                        return Err(format!(
                            "line {lineno}: binary_big_endian PLY is not supported; convert to ascii or binary_little_endian"
                        ))
                    }
                    other => return Err(format!("line {lineno}: unknown PLY format {other:?}")),
                });
            }
            Some("element") => {
                if words.len() != 3 {
                    return Err(format!("line {lineno}: expected \"element <name> <count>\""));
                }
                let count = words[2]
                    .parse::<usize>()
                    .map_err(|_| format!("line {lineno}: element {} count {:?} is not a count", words[1], words[2]))?;
                if elements.iter().any(|e| e.name == words[1]) {
                    return Err(format!("line {lineno}: element {} is declared twice", words[1]));
                }
                elements.push(Element { name: words[1].to_string(), count, props: Vec::new(), line: lineno });
            }
            Some("property") => {
                let Some(e) = elements.last_mut() else {
                    return Err(format!("line {lineno}: property before any element"));
                };
                let scalar =
                    |w: &str| Scalar::parse(w).ok_or_else(|| format!("line {lineno}: unknown property type {w:?}"));
                let (kind, name) = match words.get(1).copied() {
                    Some("list") if words.len() == 5 => {
                        let count = scalar(words[2])?;
                        if !count.is_integer() {
                            return Err(format!("line {lineno}: a list count type must be an integer type"));
                        }
                        (PropKind::List { count, item: scalar(words[3])? }, words[4])
                    }
                    Some("list") => {
                        return Err(format!(
                            "line {lineno}: expected \"property list <count type> <item type> <name>\""
                        ))
                    }
                    Some(t) if words.len() == 3 => (PropKind::Scalar(scalar(t)?), words[2]),
                    _ => return Err(format!("line {lineno}: expected \"property <type> <name>\"")),
                };
                e.props.push(Property { name: name.to_string(), kind });
            }
            Some("end_header") => {
                let Some(format) = format else {
                    return Err(format!("line {lineno}: end_header before a format line"));
                };
                return Ok((format, elements, pos, lineno));
            }
            Some(other) => return Err(format!("line {lineno}: unknown header keyword {other:?}")),
        }
    }
}

struct BodyReader<'a> {
    bytes: &'a [u8],
    pos: usize,
    /// Current 1-based line (ASCII bodies).
    line: usize,
    format: Format,
}

impl BodyReader<'_> {
    fn record(&mut self, e: &Element) -> Result<Vec<Value>, String> {
        let mut out = Vec::with_capacity(e.props.len());
        for p in &e.props {
            out.push(match p.kind {
                PropKind::Scalar(t) => Value::Scalar(self.value(t, &p.name)?),
                PropKind::List { count, item } => {
                    let n = self.value(count, &p.name)?;
                    if n < 0.0 {
                        return Err(format!("property {}: negative list length {n}", p.name));
                    }
                    let mut items = Vec::with_capacity(n as usize);
                    for _ in 0..n as usize {
                        items.push(self.value(item, &p.name)?);
                    }
                    Value::List(items)
                }
            });
        }
        Ok(out)
    }

    fn value(&mut self, t: Scalar, name: &str) -> Result<f64, String> {
        match self.format {
            Format::BinaryLe => {
                let n = t.size();
                if self.pos + n > self.bytes.len() {
                    return Err(format!("property {name}: the file ends early (truncated)"));
                }
                let v = t.read_le(&self.bytes[self.pos..]);
                self.pos += n;
                Ok(v)
            }
            Format::Ascii => {
                // Skip blanks (not newlines: one record per line).
                while self.pos < self.bytes.len() && matches!(self.bytes[self.pos], b' ' | b'\t' | b'\r') {
                    self.pos += 1;
                }
                let start = self.pos;
                while self.pos < self.bytes.len() && !self.bytes[self.pos].is_ascii_whitespace() {
                    self.pos += 1;
                }
                if start == self.pos {
                    return Err(if self.pos >= self.bytes.len() {
                        format!("property {name}: the file ends early (truncated)")
                    } else {
                        format!("property {name}: the line ends early")
                    });
                }
                let word = std::str::from_utf8(&self.bytes[start..self.pos]).unwrap_or("(not text)");
                let v: f64 = word.parse().map_err(|_| format!("property {name}: {word:?} is not a number"))?;
                if t.is_integer() && v.fract() != 0.0 {
                    return Err(format!("property {name}: {word:?} is not an integer"));
                }
                Ok(v)
            }
        }
    }

    /// ASCII: the rest of the record's line must be blank; moves to the next line.
    fn end_line(&mut self) -> Result<(), String> {
        while self.pos < self.bytes.len() && self.bytes[self.pos] != b'\n' {
            if !self.bytes[self.pos].is_ascii_whitespace() {
                return Err("more values on the line than the header declares".into());
            }
            self.pos += 1;
        }
        if self.pos < self.bytes.len() {
            self.pos += 1;
            self.line += 1;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(s: &[u8]) -> Result<VertsTris, String> {
        parse_ply(s)
    }

    #[test]
    fn ascii_with_quad_extra_props_and_other_elements() {
        let s = b"ply\nformat ascii 1.0\ncomment hi\nelement vertex 4\nproperty float x\nproperty float y\n\
property double z\nproperty uchar red\nelement face 1\nproperty list uchar int vertex_indices\n\
element edge 1\nproperty int vertex1\nproperty int vertex2\nend_header\n\
0 0 0 255\n1 0 0 0\n1 1 0.5 0\n0 1 0 0\n4 0 1 2 3\n0 1\n";
        let (v, t) = parse(s).unwrap();
        assert_eq!(v.len(), 4);
        assert_eq!(v[2], [1.0, 1.0, 0.5]);
        assert_eq!(t, vec![[0, 1, 2], [0, 2, 3]]);
    }

    #[test]
    fn binary_round_trip_is_exact() {
        let mesh = TriMesh::try_new(
            vec![[0.1, 0.2, 0.3], [1.0 / 3.0, 0.0, -2.5e-3], [0.0, 1e-7, 4.0], [5.0, 6.0, 7.0]],
            vec![[0, 1, 2], [0, 2, 3]],
        )
        .unwrap();
        let err = [0.5f32, -1.0, 2.0, 3.0];
        let mut buf = Vec::new();
        write_ply_to(&mut buf, &mesh, &[("error_m", &err)], "test").unwrap();
        let (v, t) = parse(&buf).unwrap();
        assert_eq!(v, mesh.verts);
        assert_eq!(t, mesh.tris);
    }

    #[test]
    fn binary_uint_indices_and_uchar_count() {
        let mut s = b"ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nelement face 1\nproperty list uchar uint vertex_indices\nend_header\n".to_vec();
        for v in [[0f32, 0., 0.], [1., 0., 0.], [0., 1., 0.]] {
            for c in v {
                s.extend_from_slice(&c.to_le_bytes());
            }
        }
        s.push(3);
        for i in [0u32, 1, 2] {
            s.extend_from_slice(&i.to_le_bytes());
        }
        let (v, t) = parse(&s).unwrap();
        assert_eq!(v[1], [1.0, 0.0, 0.0]);
        assert_eq!(t, vec![[0, 1, 2]]);
        // Truncated by one byte.
        let e = parse(&s[..s.len() - 1]).unwrap_err();
        assert!(e.contains("element face record 0") && e.contains("truncated"), "{e}");
    }

    #[test]
    fn errors_name_the_line() {
        let e = parse(b"plx\n").unwrap_err();
        assert!(e.contains("not a PLY file"), "{e}");
        let e = parse(b"ply\nformat binary_big_endian 1.0\nend_header\n").unwrap_err();
        assert!(e.contains("line 2") && e.contains("big_endian"), "{e}");
        let e =
            parse(b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nend_header\n0 0\n")
                .unwrap_err();
        assert!(e.contains("line 3") && e.contains("no property z"), "{e}");
        let e = parse(
            b"ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\nproperty float z\nend_header\n0 0 0\n0 abc 0\n",
        )
        .unwrap_err();
        assert!(e.contains("line 9") && e.contains("\"abc\" is not a number"), "{e}");
        let e = parse(
            b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n2 0 1\n",
        )
        .unwrap_err();
        assert!(e.contains("line 13") && e.contains("at least 3 vertices"), "{e}");
        let e = parse(b"ply\nformat ascii 1.0\nelement vertex 1\nproperty blob x\nend_header\n").unwrap_err();
        assert!(e.contains("line 4") && e.contains("blob"), "{e}");
        let e = parse(b"ply\nformat ascii 1.0\nelement vertex 1\n").unwrap_err();
        assert!(e.contains("end_header"), "{e}");
    }
}
