//! Wavefront OBJ surface reader and writer.
//!
//! Reading keeps only what a surface needs: vertex positions (`v x y z`, metres) and faces
//! (`f`), each polygon fan-triangulated `(a, b_k, b_k+1)` as most exporters and `tobj` do (exact
//! for convex polygons). Texture coordinates, normals, groups, materials, points (`p`) and
//! polylines (`l`) are ignored; extra numbers after `v x y z` (vertex colours or a rational
//! weight `w`) are ignored too.
//!
//! Why not `tobj` (measured with tobj 4 and `use_f64`, on the malformed corpus and 120,000
//! random files): it renumbers vertices by first use and drops unused ones (so a written mesh
//! does not read back identical), gives each `o`/`g` group its own copy of shared vertices
//! (which opens closed surfaces), silently drops a two-vertex face `f 1 2`, and reports errors
//! such as an out-of-range index without the face or line. Wrapping it to restore those
//! guarantees took more code than this parser, which is f64, keeps one global vertex list,
//! and reports the line of every syntax error. `tobj` remains the test oracle
//! (tests/mesh_io.rs).

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::Path;

use super::error::MeshError;
use super::trimesh::TriMesh;

/// Read a triangle surface from a Wavefront OBJ file (coordinates taken as metres).
///
/// All objects and groups share one vertex list, as in the file; the result is not welded or
/// validated beyond [`TriMesh::try_new`] (call [`TriMesh::validate_solid`] for a solid).
///
/// # Errors
/// - [`MeshError::Io`] if the file cannot be read;
/// - [`MeshError::Parse`] (with the line number) for binary or non-UTF-8 content, a vertex with
///   fewer than 3 numbers or a non-numeric one, a face with fewer than 3 vertices, vertex index
///   0, or a relative index pointing before the first vertex;
/// - [`MeshError::InFile`] wrapping the [`TriMesh::try_new`] error for an empty mesh, NaN or
///   infinite coordinates (`nan`, `inf`, `1e999`), an index past the last vertex, or a face
///   repeating a vertex.
pub fn read_obj(path: &Path) -> Result<TriMesh, MeshError> {
    let bytes = std::fs::read(path).map_err(|source| MeshError::Io { path: path.to_path_buf(), source })?;
    let (verts, tris) = parse_obj(&bytes).map_err(|message| MeshError::Parse { path: path.to_path_buf(), message })?;
    TriMesh::try_new(verts, tris).map_err(|e| e.in_file(path))
}

/// Write `mesh` to `path` as OBJ (see [`write_obj_to`]).
pub fn write_obj(path: &Path, mesh: &TriMesh, comment: &str) -> std::io::Result<()> {
    let mut w = BufWriter::new(File::create(path)?);
    write_obj_to(&mut w, mesh, comment)?;
    w.flush()
}

/// Write `mesh` as OBJ: each line of `comment` as a `#` line, then `v x y z` lines (metres) in
/// the shortest decimal form that parses back to the identical f64, then 1-based `f a b c`
/// lines.
pub fn write_obj_to(w: &mut impl Write, mesh: &TriMesh, comment: &str) -> std::io::Result<()> {
    for line in comment.lines() {
        writeln!(w, "# {line}")?;
    }
    writeln!(w, "# {} vertices, {} triangles; coordinates in metres", mesh.verts.len(), mesh.tris.len())?;
    for p in &mesh.verts {
        writeln!(w, "v {} {} {}", Exact(p[0]), Exact(p[1]), Exact(p[2]))?;
    }
    for t in &mesh.tris {
        writeln!(w, "f {} {} {}", t[0] + 1, t[1] + 1, t[2] + 1)?;
    }
    Ok(())
}

/// Shortest round-trip formatting: plain decimal for ordinary magnitudes, exponent form for
/// very small or large ones (where `{}` would print hundreds of digits). Both are exact.
struct Exact(f64);

impl std::fmt::Display for Exact {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let a = self.0.abs();
        if a == 0.0 || (1e-5..1e16).contains(&a) || !a.is_finite() {
            write!(f, "{}", self.0)
        } else {
            write!(f, "{:e}", self.0)
        }
    }
}

/// `(verts, tris)`: #V x 3 positions and #F x 3 0-based indices.
type VertsTris = (Vec<[f64; 3]>, Vec<[usize; 3]>);

/// Parse OBJ text into 0-based `(verts, tris)`; errors are messages naming the line.
fn parse_obj(bytes: &[u8]) -> Result<VertsTris, String> {
    let text = match std::str::from_utf8(bytes) {
        Ok(t) => t,
        Err(e) => {
            return Err(format!(
                "line {} is not valid UTF-8 text; an OBJ file must be plain text (is this a binary file?)",
                line_of(bytes, e.valid_up_to())
            ))
        }
    };
    if let Some(pos) = text.find('\0') {
        return Err(format!(
            "line {} contains a NUL byte; an OBJ file must be plain text (is this a binary file?)",
            line_of(bytes, pos)
        ));
    }
    let mut verts: Vec<[f64; 3]> = Vec::new();
    let mut tris: Vec<[usize; 3]> = Vec::new();
    let mut corners: Vec<usize> = Vec::new();
    // A line ending in a backslash continues on the next one.
    let mut logical = String::new();
    let mut first_line = 1;
    for (k, raw) in text.lines().enumerate() {
        if logical.is_empty() {
            first_line = k + 1;
        }
        if let Some(head) = raw.strip_suffix('\\') {
            logical.push_str(head);
            logical.push(' ');
            continue;
        }
        logical.push_str(raw);
        parse_line(&logical, first_line, &mut verts, &mut tris, &mut corners)?;
        logical.clear();
    }
    if !logical.is_empty() {
        parse_line(&logical, first_line, &mut verts, &mut tris, &mut corners)?;
    }
    Ok((verts, tris))
}

fn parse_line(
    line: &str,
    lineno: usize,
    verts: &mut Vec<[f64; 3]>,
    tris: &mut Vec<[usize; 3]>,
    corners: &mut Vec<usize>,
) -> Result<(), String> {
    let content = line.split('#').next().unwrap_or("");
    let mut words = content.split_whitespace();
    match words.next() {
        Some("v") => {
            let mut p = [0.0; 3];
            for (c, x) in p.iter_mut().enumerate() {
                let word = words
                    .next()
                    .ok_or_else(|| format!("line {lineno}: a vertex (\"v\") needs 3 coordinates but has {c}"))?;
                *x = word
                    .parse::<f64>()
                    .map_err(|_| format!("line {lineno}: vertex coordinate \"{word}\" is not a number"))?;
            }
            verts.push(p);
        }
        Some("f") => {
            corners.clear();
            for word in words {
                corners.push(parse_vertex_ref(word, verts.len(), lineno)?);
            }
            if corners.len() < 3 {
                return Err(format!(
                    "line {lineno}: a face (\"f\") needs at least 3 vertices but has {}",
                    corners.len()
                ));
            }
            for k in 1..corners.len() - 1 {
                tris.push([corners[0], corners[k], corners[k + 1]]);
            }
        }
        _ => {}
    }
    Ok(())
}

/// Parse the position part of a face corner `v`, `v/vt`, `v//vn` or `v/vt/vn` into a 0-based
/// index. Negative indices count back from the last vertex defined so far. Indices past the
/// end are returned as is and reported by [`TriMesh::try_new`], since OBJ lets a face refer
/// to vertices defined later in the file.
fn parse_vertex_ref(word: &str, defined: usize, lineno: usize) -> Result<usize, String> {
    let v = word.split('/').next().unwrap_or("");
    let i: i64 = v
        .parse()
        .map_err(|_| format!("line {lineno}: face corner \"{word}\" does not start with an integer vertex index"))?;
    match i {
        0 => Err(format!("line {lineno}: face corner \"{word}\" uses vertex index 0, but OBJ indices start at 1")),
        i if i > 0 => usize::try_from(i - 1)
            .map_err(|_| format!("line {lineno}: vertex index {i} does not fit in memory indices")),
        i => {
            let back = usize::try_from(i.unsigned_abs()).unwrap_or(usize::MAX);
            defined.checked_sub(back).ok_or_else(|| {
                format!(
                    "line {lineno}: relative vertex index {i} points before the first vertex \
                     (only {defined} vertices are defined above this line)"
                )
            })
        }
    }
}

/// 1-based line number of byte offset `pos`.
fn line_of(bytes: &[u8], pos: usize) -> usize {
    1 + bytes[..pos.min(bytes.len())].iter().filter(|&&b| b == b'\n').count()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn polygons_are_fan_triangulated_and_relative_indices_resolve() {
        let text = "# square pyramid\nv 0 0 0\nv 1 0 0\nv 1 1 0 0.5 0.5 0.5\nv 0 1 0\n\
                    f 1//1 4/2 3/3/3 2\nv 0.5 0.5 1\nf -1 -5 -4\n";
        let (verts, tris) = parse_obj(text.as_bytes()).unwrap();
        assert_eq!(verts.len(), 5);
        assert_eq!(verts[2], [1.0, 1.0, 0.0]);
        assert_eq!(tris, vec![[0, 3, 2], [0, 2, 1], [4, 0, 1]]);
    }

    #[test]
    fn syntax_errors_name_the_line() {
        let cases: [(&str, &str); 6] = [
            ("v 0 0\n", "line 1: a vertex (\"v\") needs 3 coordinates but has 2"),
            ("v 0 0 0\nv 1 x 0\n", "line 2: vertex coordinate \"x\" is not a number"),
            ("v 0 0 0\nv 1 0 0\nf 1 2\n", "line 3: a face (\"f\") needs at least 3"),
            ("v 0 0 0\nf 0 1 1\n", "vertex index 0, but OBJ indices start at 1"),
            ("v 0 0 0\nf -2 1 1\n", "relative vertex index -2 points before the first vertex"),
            ("v 0 0 0\nf a b c\n", "face corner \"a\" does not start with an integer"),
        ];
        for (text, want) in cases {
            let err = parse_obj(text.as_bytes()).unwrap_err();
            assert!(err.contains(want), "{text:?}: {err}");
        }
        let err = parse_obj(&[b'v', b' ', 0xff, 0xfe]).unwrap_err();
        assert!(err.contains("not valid UTF-8"), "{err}");
    }

    #[test]
    fn continuation_lines_and_comments() {
        let text = "v 0 0 0 # origin\nv 1 0 0\nv 0 \\\n 1 0\nf 1 2 \\\n3\n";
        let (verts, tris) = parse_obj(text.as_bytes()).unwrap();
        assert_eq!(verts, vec![[0., 0., 0.], [1., 0., 0.], [0., 1., 0.]]);
        assert_eq!(tris, vec![[0, 1, 2]]);
    }

    #[test]
    fn exact_formatting_round_trips() {
        for x in [0.1, -0.0, 1.0 / 3.0, 1e-300, 5e-324, f64::MAX, 123456.789e10, -2.5e-5, 1e16] {
            let s = Exact(x).to_string();
            assert!(s.len() < 32, "{s}");
            assert_eq!(s.parse::<f64>().unwrap().to_bits(), x.to_bits(), "{s}");
        }
    }
}
