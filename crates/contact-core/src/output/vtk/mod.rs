//! VTK XML output for ParaView: one UnstructuredGrid file (`.vtu`) per stored step, and a
//! ParaView collection (`.pvd`) that lists the steps with their times.
//!
//! The `.vtu` files use VTK's XML format version 1.0 with `header_type="UInt64"` and inline
//! `format="binary"` data arrays: each array is the base64 encoding of an 8-byte
//! little-endian byte count followed by the raw little-endian values — the layout
//! ParaView/VTK readers expect for uncompressed binary arrays with 64-bit headers. Binary
//! keeps every `f64` bit-exact and takes about half the space of full-precision ASCII.
//!
//! What one file holds:
//! - `Points`: the mesh nodes as `Float64` with 3 components (z = 0 in 2D);
//! - `Cells`: `connectivity` and `offsets` (`Int64`), `types` (`UInt8`, all 5 = VTK_TRIANGLE
//!   in 2D, all 10 = VTK_TETRA in 3D);
//! - `PointData`: `u` and `w` (3 components, z = 0 in 2D) and `zeta`, each when present, and
//!   with the contact state `contact_state` (`UInt8`: 0 off Γ3, 1 stick, 2 slip) and
//!   `slip_velocity` (|w_τ|, 0 off Γ3);
//! - `CellData`: `sigma` and `von_mises`, each when present. σ is a symmetric tensor of 6
//!   components in VTK's order for symmetric tensors, xx, yy, zz, xy, yz, xz (the order
//!   `vtkMath::TensorFromSymmetricTensor` expands); in 2D σ_zz = σ_yz = σ_xz = 0: the plane
//!   model's constitutive laws (4.1) act on 2 × 2 tensors, so it has no σ_zz. `CellData`
//!   carries `Tensors="sigma"`, which makes it the cells' active tensors for VTK's XML
//!   readers (VTK 9 accepts 6-component tensors), so ParaView's tensor filters find it;
//! - `FieldData`: `TimeValue` (the step's time t, which ParaView uses as the time of the data
//!   set) and `Step` (the step index n).
//!
//! The document is streamed array by array through a buffered writer, with each array's
//! base64 encoded on the fly, so memory does not grow with the size of the mesh.
//! All input is validated before the first byte is written: a field whose length does not
//! match the mesh, or a cell with an out-of-range node, is an `InvalidInput` error.

use crate::mesh::AnyMesh;
use crate::solve::stepper::StepFields;
use base64::engine::general_purpose::STANDARD;
use base64::write::EncoderWriter;
use std::borrow::Cow;
use std::io::{self, BufWriter, Write};

/// VTK cell types of a linear triangle and a linear tetrahedron.
const VTK_TRIANGLE: u8 = 5;
const VTK_TETRA: u8 = 10;
/// Component names of a symmetric tensor, in the order VTK reads 6-component tensors.
const SYM_TENSOR: [&str; 6] = ["xx", "yy", "zz", "xy", "yz", "xz"];
/// Raw bytes gathered before they are handed to the base64 encoder.
const CHUNK_BYTES: usize = 48 * 1024;

/// Writes one step as a VTK XML UnstructuredGrid (`.vtu`) document (see the module docs).
///
/// `nodes` and `cells` (D + 1 node indices per simplex, flat) are the mesh; `u` and `w` in
/// `fields` are interleaved (D components per node), `zeta` is per node, `sigma` (written as
/// the 6 components of a symmetric tensor) and `von_mises` are per cell, the contact state
/// per Γ3 node. Errors with `InvalidInput`, before writing anything, when a field's length
/// does not match the mesh or a cell refers to a missing node.
pub fn write_vtu<W: Write, const D: usize>(
    out: W,
    nodes: &[[f64; D]],
    cells: &[usize],
    fields: &StepFields,
) -> io::Result<()> {
    validate(nodes, cells, fields)?;
    let np = nodes.len();
    let nc = cells.len() / (D + 1);
    let mut out = BufWriter::with_capacity(64 * 1024, out);
    let o = &mut out;

    o.write_all(b"<?xml version=\"1.0\"?>\n")?;
    o.write_all(
        b"<VTKFile type=\"UnstructuredGrid\" version=\"1.0\" byte_order=\"LittleEndian\" \
          header_type=\"UInt64\">\n",
    )?;
    o.write_all(b"  <UnstructuredGrid>\n")?;
    o.write_all(b"    <FieldData>\n")?;
    data_array(o, 6, "TimeValue", &[], Some(1), 1, [fields.t])?;
    data_array(o, 6, "Step", &[], Some(1), 1, [to_i64(fields.n)?])?;
    o.write_all(b"    </FieldData>\n")?;
    writeln!(
        o,
        "    <Piece NumberOfPoints=\"{np}\" NumberOfCells=\"{nc}\">"
    )?;

    let has_point_data = fields.u.is_some()
        || fields.w.is_some()
        || fields.zeta.is_some()
        || fields.contact.is_some();
    if has_point_data {
        o.write_all(b"      <PointData>\n")?;
        for (name, v) in [("u", &fields.u), ("w", &fields.w)] {
            if let Some(v) = v {
                let values = v.chunks_exact(D).flat_map(xyz);
                data_array(o, 8, name, &["x", "y", "z"], None, 3 * np, values)?;
            }
        }
        if let Some(z) = &fields.zeta {
            data_array(o, 8, "zeta", &[], None, np, z.iter().copied())?;
        }
        if let Some(contact) = &fields.contact {
            let mut state = vec![0u8; np];
            let mut slip = vec![0.0f64; np];
            for c in contact {
                state[c.node] = if c.slipping { 2 } else { 1 };
                slip[c.node] = c.slip_velocity.abs();
            }
            data_array(o, 8, "contact_state", &[], None, np, state)?;
            data_array(o, 8, "slip_velocity", &[], None, np, slip)?;
        }
        o.write_all(b"      </PointData>\n")?;
    }
    if fields.sigma.is_some() || fields.von_mises.is_some() {
        if fields.sigma.is_some() {
            o.write_all(b"      <CellData Tensors=\"sigma\">\n")?;
        } else {
            o.write_all(b"      <CellData>\n")?;
        }
        if let Some(s) = &fields.sigma {
            let values = (0..nc).flat_map(|e| s.six(e));
            data_array(o, 8, "sigma", &SYM_TENSOR, None, 6 * nc, values)?;
        }
        if let Some(vm) = &fields.von_mises {
            data_array(o, 8, "von_mises", &[], None, nc, vm.iter().copied())?;
        }
        o.write_all(b"      </CellData>\n")?;
    }

    o.write_all(b"      <Points>\n")?;
    let points = nodes.iter().flat_map(|p| xyz(p));
    data_array(o, 8, "Points", &["x", "y", "z"], None, 3 * np, points)?;
    o.write_all(b"      </Points>\n")?;

    o.write_all(b"      <Cells>\n")?;
    // `validate` checked that every index and offset fits in an i64.
    let connectivity = cells.iter().map(|&i| i as i64);
    data_array(o, 8, "connectivity", &[], None, (D + 1) * nc, connectivity)?;
    let offsets = (1..=nc).map(|c| ((D + 1) * c) as i64);
    data_array(o, 8, "offsets", &[], None, nc, offsets)?;
    let kind = if D == 3 { VTK_TETRA } else { VTK_TRIANGLE };
    let types = std::iter::repeat_n(kind, nc);
    data_array(o, 8, "types", &[], None, nc, types)?;
    o.write_all(b"      </Cells>\n")?;

    o.write_all(b"    </Piece>\n")?;
    o.write_all(b"  </UnstructuredGrid>\n")?;
    o.write_all(b"</VTKFile>\n")?;
    out.flush()
}

/// [`write_vtu`] of a mesh of either dimension.
pub fn write_mesh_vtu<W: Write>(out: W, mesh: &AnyMesh, fields: &StepFields) -> io::Result<()> {
    match mesh {
        AnyMesh::Plane(m) => write_vtu(out, &m.nodes, m.cells_flat(), fields),
        AnyMesh::Solid(m) => write_vtu(out, &m.nodes, m.cells_flat(), fields),
    }
}

/// Writes a ParaView collection (`.pvd`) listing `(time, file)` entries, one data set per
/// stored step; ParaView opens it as one time series. File names are XML-escaped; a name
/// with a control character XML cannot carry is an `InvalidInput` error (nothing written).
pub fn write_pvd<W: Write>(out: W, entries: &[(f64, String)]) -> io::Result<()> {
    let files = entries
        .iter()
        .map(|(_, f)| xml_escape(f))
        .collect::<io::Result<Vec<_>>>()?;
    let mut out = BufWriter::new(out);
    out.write_all(b"<?xml version=\"1.0\"?>\n")?;
    out.write_all(b"<VTKFile type=\"Collection\" version=\"1.0\" byte_order=\"LittleEndian\">\n")?;
    out.write_all(b"  <Collection>\n")?;
    for ((t, _), file) in entries.iter().zip(&files) {
        // `Display` of f64 is the shortest decimal that round-trips, without exponent.
        writeln!(
            out,
            "    <DataSet timestep=\"{t}\" group=\"\" part=\"0\" file=\"{file}\"/>"
        )?;
    }
    out.write_all(b"  </Collection>\n")?;
    out.write_all(b"</VTKFile>\n")?;
    out.flush()
}

fn invalid(msg: String) -> io::Error {
    io::Error::new(io::ErrorKind::InvalidInput, msg)
}

fn to_i64(v: usize) -> io::Result<i64> {
    i64::try_from(v).map_err(|_| invalid(format!("{v} does not fit VTK's Int64")))
}

/// A point or vector of R^D as 3 components (z = 0 in 2D).
fn xyz(v: &[f64]) -> [f64; 3] {
    [v[0], v[1], if v.len() > 2 { v[2] } else { 0.0 }]
}

/// Checks that every field matches the mesh and every index fits the file's types.
fn validate<const D: usize>(nodes: &[[f64; D]], cells: &[usize], f: &StepFields) -> io::Result<()> {
    let np = nodes.len();
    let cell = if D == 3 { "tetrahedron" } else { "triangle" };
    if !cells.len().is_multiple_of(D + 1) {
        return Err(invalid(format!(
            "{} cell indices are not whole {cell}s of {} nodes",
            cells.len(),
            D + 1
        )));
    }
    let nc = cells.len() / (D + 1);
    to_i64(cells.len())?;
    to_i64(f.n)?;
    if let Some((e, t)) = cells
        .chunks_exact(D + 1)
        .enumerate()
        .find(|(_, t)| t.iter().any(|&i| i >= np))
    {
        return Err(invalid(format!(
            "{cell} {e} {t:?} refers to a node beyond the mesh's {np} nodes"
        )));
    }
    if let Some(c) = f.contact.iter().flatten().find(|c| c.node >= np) {
        return Err(invalid(format!(
            "contact node {} is beyond the mesh's {np} nodes",
            c.node
        )));
    }
    let check = |name: &str, len: Option<usize>, expected: usize, per: &str| match len {
        Some(len) if len != expected => Err(invalid(format!(
            "field {name} has {len} values but the mesh needs {expected} ({per})"
        ))),
        _ => Ok(()),
    };
    let nodal = np.saturating_mul(D);
    let per_node = if D == 3 {
        "x, y, z per node"
    } else {
        "x, y per node"
    };
    let per_cell = format!("one per {cell}");
    check("u", f.u.as_ref().map(Vec::len), nodal, per_node)?;
    check("w", f.w.as_ref().map(Vec::len), nodal, per_node)?;
    check("zeta", f.zeta.as_ref().map(Vec::len), np, "one per node")?;
    check("sigma", f.sigma.as_ref().map(|s| s.len()), nc, &per_cell)?;
    if matches!(
        (&f.sigma, D),
        (Some(crate::solve::stepper::Stress::Solid(_)), 2)
            | (Some(crate::solve::stepper::Stress::Plane(_)), 3)
    ) {
        return Err(invalid(format!(
            "field sigma has the wrong dimension for {cell}s"
        )));
    }
    check(
        "von_mises",
        f.von_mises.as_ref().map(Vec::len),
        nc,
        &per_cell,
    )?;
    Ok(())
}

/// A value type of a VTK DataArray.
trait Scalar: Copy {
    const VTK_TYPE: &'static str;
    const SIZE: usize;
    fn put(self, buf: &mut Vec<u8>);
}

impl Scalar for f64 {
    const VTK_TYPE: &'static str = "Float64";
    const SIZE: usize = 8;
    fn put(self, buf: &mut Vec<u8>) {
        buf.extend_from_slice(&self.to_le_bytes());
    }
}

impl Scalar for i64 {
    const VTK_TYPE: &'static str = "Int64";
    const SIZE: usize = 8;
    fn put(self, buf: &mut Vec<u8>) {
        buf.extend_from_slice(&self.to_le_bytes());
    }
}

impl Scalar for u8 {
    const VTK_TYPE: &'static str = "UInt8";
    const SIZE: usize = 1;
    fn put(self, buf: &mut Vec<u8>) {
        buf.push(self);
    }
}

/// Writes one inline binary `<DataArray>`: base64 of the u64 byte count followed by the
/// values. `components` names the components of a multi-component array (empty: scalar).
/// `count` is the number of values (tuples × components) `values` yields; callers
/// pass iterators over validated data, and a mismatch is reported as an error.
fn data_array<W: Write, T: Scalar>(
    out: &mut W,
    indent: usize,
    name: &str,
    components: &[&str],
    number_of_tuples: Option<usize>,
    count: usize,
    values: impl IntoIterator<Item = T>,
) -> io::Result<()> {
    let bytes = count
        .checked_mul(T::SIZE)
        .ok_or_else(|| invalid(format!("data array {name} is too large")))?;

    write!(
        out,
        "{:indent$}<DataArray type=\"{}\" Name=\"{name}\"",
        "",
        T::VTK_TYPE
    )?;
    if components.len() > 1 {
        write!(out, " NumberOfComponents=\"{}\"", components.len())?;
    }
    for (i, c) in components.iter().enumerate() {
        write!(out, " ComponentName{i}=\"{c}\"")?;
    }
    if let Some(n) = number_of_tuples {
        write!(out, " NumberOfTuples=\"{n}\"")?;
    }
    write!(out, " format=\"binary\">\n{:indent$}  ", "")?;

    let mut written = 0usize;
    {
        let mut enc = EncoderWriter::new(&mut *out, &STANDARD);
        enc.write_all(&(bytes as u64).to_le_bytes())?;
        let mut chunk = Vec::with_capacity(CHUNK_BYTES.min(bytes) + T::SIZE);
        for v in values {
            v.put(&mut chunk);
            written += 1;
            if chunk.len() >= CHUNK_BYTES {
                enc.write_all(&chunk)?;
                chunk.clear();
            }
        }
        enc.write_all(&chunk)?;
        enc.finish()?;
    }
    if written != count {
        return Err(io::Error::other(format!(
            "data array {name}: {written} values written, {count} announced"
        )));
    }
    writeln!(out, "\n{:indent$}</DataArray>", "")
}

/// Escapes text for a double-quoted XML attribute. Tab, LF and CR become character
/// references (so attribute-value normalisation keeps them); other control characters
/// cannot appear in XML 1.0 at all and are an error.
fn xml_escape(s: &str) -> io::Result<Cow<'_, str>> {
    let special = |c: char| {
        matches!(c, '&' | '<' | '>' | '"' | '\'' | '\u{fffe}' | '\u{ffff}') || c.is_control()
    };
    if !s.contains(special) {
        return Ok(Cow::Borrowed(s));
    }
    let mut out = String::with_capacity(s.len() + 16);
    for c in s.chars() {
        match c {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            '\'' => out.push_str("&apos;"),
            '\t' => out.push_str("&#9;"),
            '\n' => out.push_str("&#10;"),
            '\r' => out.push_str("&#13;"),
            c if (c as u32) < 0x20 || c == '\u{fffe}' || c == '\u{ffff}' => {
                return Err(invalid(format!(
                    "file name {s:?} contains a character XML cannot carry"
                )))
            }
            c => out.push(c),
        }
    }
    Ok(Cow::Owned(out))
}

#[cfg(test)]
mod tests;
