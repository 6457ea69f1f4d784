//! VTK XML writers: `.vtu` (UnstructuredGrid, one mesh with point and cell data) and `.pvd`
//! (a time series of `.vtu` files), for ParaView and meshio.
//!
//! Format: `<VTKFile type="UnstructuredGrid" version="1.0" byte_order="LittleEndian"
//! header_type="UInt64">`; every `DataArray` is `format="binary"`: the base64 encoding of an
//! 8-byte little-endian byte count followed by the raw little-endian values (header and data
//! encoded together as one base64 stream, as VTK and meshio write and read it). Points are
//! Float64 x 3 (metres); `connectivity` and `offsets` are Int64; `types` are UInt8 (VTK_TETRA
//! = 10, VTK_TRIANGLE = 5). Vertex order is passed through unchanged: VTK expects tetrahedra
//! with positive orientation `((p1 - p0) x (p2 - p0)) . (p3 - p0) > 0`, and triangles
//! counter-clockwise seen from the side their normal points to.

use std::io::{self, Write};

use base64::Engine as _;

/// Cells of a `.vtu` piece, all of one kind.
#[derive(Clone, Copy, Debug)]
pub enum Cells<'a> {
    /// #T x 4 vertex indices (VTK_TETRA = 10).
    Tetra(&'a [[usize; 4]]),
    /// #F x 3 vertex indices (VTK_TRIANGLE = 5).
    Triangle(&'a [[usize; 3]]),
}

impl Cells<'_> {
    /// Number of cells.
    pub fn len(&self) -> usize {
        match self {
            Cells::Tetra(c) => c.len(),
            Cells::Triangle(c) => c.len(),
        }
    }

    /// True if there are no cells.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// VTK cell type code.
    pub fn vtk_type(&self) -> u8 {
        match self {
            Cells::Tetra(_) => VTK_TETRA,
            Cells::Triangle(_) => VTK_TRIANGLE,
        }
    }

    fn vertices_per_cell(&self) -> usize {
        match self {
            Cells::Tetra(_) => 4,
            Cells::Triangle(_) => 3,
        }
    }

    fn flat(&self) -> impl Iterator<Item = usize> + '_ {
        let (tets, tris): (&[[usize; 4]], &[[usize; 3]]) = match *self {
            Cells::Tetra(c) => (c, &[]),
            Cells::Triangle(c) => (&[], c),
        };
        tets.iter().flat_map(|c| c.iter().copied()).chain(tris.iter().flat_map(|c| c.iter().copied()))
    }
}

/// VTK cell type code of a linear tetrahedron.
pub const VTK_TETRA: u8 = 10;
/// VTK cell type code of a linear triangle.
pub const VTK_TRIANGLE: u8 = 5;

/// One data array: a value per point (or per cell), in the units the caller documents in the
/// array name (e.g. `"temperature_K"`).
#[derive(Clone, Copy, Debug)]
pub enum DataArray<'a> {
    /// Scalars, written as Float64.
    F64(&'a [f64]),
    /// Integer labels, written as Int32.
    I32(&'a [i32]),
    /// 3-vectors, written as Float64 with NumberOfComponents="3".
    Vec3(&'a [[f64; 3]]),
}

impl DataArray<'_> {
    /// Number of tuples (points or cells covered).
    pub fn len(&self) -> usize {
        match self {
            DataArray::F64(a) => a.len(),
            DataArray::I32(a) => a.len(),
            DataArray::Vec3(a) => a.len(),
        }
    }

    /// True if the array is empty.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    fn vtk_type(&self) -> &'static str {
        match self {
            DataArray::F64(_) | DataArray::Vec3(_) => "Float64",
            DataArray::I32(_) => "Int32",
        }
    }

    fn components(&self) -> usize {
        match self {
            DataArray::Vec3(_) => 3,
            _ => 1,
        }
    }

    fn bytes(&self) -> Vec<u8> {
        match self {
            DataArray::F64(a) => a.iter().flat_map(|x| x.to_le_bytes()).collect(),
            DataArray::I32(a) => a.iter().flat_map(|x| x.to_le_bytes()).collect(),
            DataArray::Vec3(a) => a.iter().flatten().flat_map(|x| x.to_le_bytes()).collect(),
        }
    }
}

/// Write one UnstructuredGrid piece: `points` #V x 3 (metres), `cells` indexing into them,
/// `point_data` arrays of length #V and `cell_data` arrays of length #cells, as
/// `(name, values)`.
///
/// # Errors
/// `io::ErrorKind::InvalidInput` (before anything is written) if a cell index is
/// `>= points.len()` or a data array has the wrong length; otherwise errors from `w`.
pub fn write_vtu(
    w: &mut impl Write,
    points: &[[f64; 3]],
    cells: Cells,
    point_data: &[(&str, DataArray)],
    cell_data: &[(&str, DataArray)],
) -> io::Result<()> {
    let invalid = |msg: String| io::Error::new(io::ErrorKind::InvalidInput, msg);
    if let Some((k, v)) = cells.flat().enumerate().find(|&(_, v)| v >= points.len()) {
        return Err(invalid(format!(
            "cell {} references point {v} but there are {} points",
            k / cells.vertices_per_cell(),
            points.len()
        )));
    }
    for (kind, arrays, n) in [("point", point_data, points.len()), ("cell", cell_data, cells.len())] {
        for (name, a) in arrays {
            if a.len() != n {
                return Err(invalid(format!(
                    "{kind} data array \"{name}\" has {} values but there are {n} {kind}s",
                    a.len()
                )));
            }
        }
    }

    let npc = cells.vertices_per_cell();
    writeln!(w, "<?xml version=\"1.0\"?>")?;
    writeln!(
        w,
        "<VTKFile type=\"UnstructuredGrid\" version=\"1.0\" byte_order=\"LittleEndian\" header_type=\"UInt64\">"
    )?;
    writeln!(w, "  <UnstructuredGrid>")?;
    writeln!(w, "    <Piece NumberOfPoints=\"{}\" NumberOfCells=\"{}\">", points.len(), cells.len())?;
    for (tag, arrays) in [("PointData", point_data), ("CellData", cell_data)] {
        if arrays.is_empty() {
            continue;
        }
        writeln!(w, "      <{tag}>")?;
        for (name, a) in arrays {
            write_array(w, a.vtk_type(), name, a.components(), &a.bytes())?;
        }
        writeln!(w, "      </{tag}>")?;
    }
    writeln!(w, "      <Points>")?;
    write_array(w, "Float64", "Points", 3, &DataArray::Vec3(points).bytes())?;
    writeln!(w, "      </Points>")?;
    writeln!(w, "      <Cells>")?;
    let connectivity: Vec<u8> = cells.flat().flat_map(|v| (v as i64).to_le_bytes()).collect();
    write_array(w, "Int64", "connectivity", 1, &connectivity)?;
    let offsets: Vec<u8> = (1..=cells.len()).flat_map(|c| ((c * npc) as i64).to_le_bytes()).collect();
    write_array(w, "Int64", "offsets", 1, &offsets)?;
    write_array(w, "UInt8", "types", 1, &vec![cells.vtk_type(); cells.len()])?;
    writeln!(w, "      </Cells>")?;
    writeln!(w, "    </Piece>")?;
    writeln!(w, "  </UnstructuredGrid>")?;
    writeln!(w, "</VTKFile>")?;
    Ok(())
}

/// Write a ParaView collection listing `(time in seconds, relative .vtu file name)` entries.
pub fn write_pvd(w: &mut impl Write, entries: &[(f64, &str)]) -> io::Result<()> {
    writeln!(w, "<?xml version=\"1.0\"?>")?;
    writeln!(w, "<VTKFile type=\"Collection\" version=\"0.1\" byte_order=\"LittleEndian\">")?;
    writeln!(w, "  <Collection>")?;
    for (time, file) in entries {
        writeln!(w, "    <DataSet timestep=\"{time}\" group=\"\" part=\"0\" file=\"{}\"/>", xml_escape(file))?;
    }
    writeln!(w, "  </Collection>")?;
    writeln!(w, "</VTKFile>")?;
    Ok(())
}

fn write_array(w: &mut impl Write, vtk_type: &str, name: &str, components: usize, data: &[u8]) -> io::Result<()> {
    let mut payload = Vec::with_capacity(8 + data.len());
    payload.extend((data.len() as u64).to_le_bytes());
    payload.extend_from_slice(data);
    let encoded = base64::engine::general_purpose::STANDARD.encode(&payload);
    let components = if components > 1 { format!(" NumberOfComponents=\"{components}\"") } else { String::new() };
    writeln!(w, "        <DataArray type=\"{vtk_type}\" Name=\"{}\"{components} format=\"binary\">", xml_escape(name))?;
    writeln!(w, "          {encoded}")?;
    writeln!(w, "        </DataArray>")
}

fn xml_escape(s: &str) -> String {
    let mut out = String::with_capacity(s.len());
    for c in s.chars() {
        match c {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            '\'' => out.push_str("&apos;"),
            c => out.push(c),
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rejects_bad_lengths_and_indices() {
        let pts = [[0.0; 3], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]];
        let tris = [[0, 1, 2]];
        let mut out = Vec::new();
        let e =
            write_vtu(&mut out, &pts, Cells::Triangle(&tris), &[("T", DataArray::F64(&[1.0, 2.0]))], &[]).unwrap_err();
        assert!(e.to_string().contains("\"T\" has 2 values but there are 3 points"));
        let e = write_vtu(&mut out, &pts, Cells::Triangle(&[[0, 1, 3]]), &[], &[]).unwrap_err();
        assert!(e.to_string().contains("cell 0 references point 3"));
        assert!(out.is_empty());
    }

    #[test]
    fn escapes_names() {
        assert_eq!(xml_escape("a<b>&\"c'"), "a&lt;b&gt;&amp;&quot;c&apos;");
    }
}
