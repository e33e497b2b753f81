//! VTK XML output for ParaView: one UnstructuredGrid file (`.vtu`) per stored step, and a
//! ParaView collection (`.pvd`) that lists the steps with their times.
//!
//! The `.vtu` files use VTK's XML format version 1.0 with `header_type="UInt64"` and inline
//! `format="binary"` data arrays, in one of two encodings ([`Compression`]):
//! - `Zlib` (the default; `compressor="vtkZLibDataCompressor"` on the root): each array's raw
//!   little-endian values are cut into blocks of 32 KiB (VTK's own block size), each block
//!   deflated on its own as a zlib stream (level [`ZLIB_LEVEL`]), and the array
//!   is written as the base64 of the header `[number of blocks, block size, size of the last
//!   block, compressed size of each block]` (UInt64 each) followed by the base64 of the
//!   compressed blocks, as VTK's `vtkZLibDataCompressor`, ParaView and meshio read it. Mesh
//!   connectivity, offsets, cell types and contact flags shrink to a fraction; the field
//!   values less.
//! - `None`: each array is the base64 encoding of an 8-byte little-endian byte count followed
//!   by the raw little-endian values, for readers without zlib.
//!
//! Both keep every `f64` bit-exact; raw binary takes about half the space of full-precision
//! ASCII.
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
//! The document is streamed array by array through a buffered writer. Raw arrays are
//! base64-encoded on the fly, so memory does not grow with the size of the mesh; a compressed
//! array is held compressed until its last block (its header, which comes first, lists every
//! block's size), so memory grows with the largest compressed array, not with the file.
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
/// Uncompressed bytes per zlib block: VTK's default, a multiple of every value size.
const ZLIB_BLOCK: usize = 32 * 1024;
/// The zlib level (1 fastest … 9 smallest): the fastest. On this output the levels hardly
/// differ in size: the last step of box-exp3 at h = 1/16 (9,537 nodes) compresses to 60.3 %
/// at level 1, 59.9 % at 5 (VTK's default) and 9, in half the time of level 5. Mesh arrays
/// (points, connectivity, offsets, types, contact flags) shrink to 0.5–16 %; the fields'
/// `f64` values, whose low bits are noise, only to 87–95 %.
pub const ZLIB_LEVEL: u32 = 1;

/// How a `.vtu` file's data arrays are encoded (see the module docs).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Compression {
    /// zlib blocks, `compressor="vtkZLibDataCompressor"`: the smaller file, what ParaView
    /// itself writes.
    #[default]
    Zlib,
    /// The raw values, for readers without zlib.
    None,
}

/// Writes one step as a VTK XML UnstructuredGrid (`.vtu`) document (see the module docs).
///
/// `nodes` and `cells` (D + 1 node indices per simplex, flat) are the mesh; `u` and `w` in
/// `fields` are interleaved (D components per node), `zeta` is per node, `sigma` (written as
/// the 6 components of a symmetric tensor) and `von_mises` are per cell, the contact state
/// per Γ3 node; `compression` is the arrays' encoding. Errors with `InvalidInput`, before
/// writing anything, when a field's length does not match the mesh or a cell refers to a
/// missing node.
pub fn write_vtu<W: Write, const D: usize>(
    out: W,
    nodes: &[[f64; D]],
    cells: &[usize],
    fields: &StepFields,
    compression: Compression,
) -> io::Result<()> {
    validate(nodes, cells, fields)?;
    let np = nodes.len();
    let nc = cells.len() / (D + 1);
    let mut out = BufWriter::with_capacity(64 * 1024, out);
    let mut arrays = Arrays::new(compression);
    let o = &mut out;

    o.write_all(b"<?xml version=\"1.0\"?>\n")?;
    o.write_all(
        b"<VTKFile type=\"UnstructuredGrid\" version=\"1.0\" byte_order=\"LittleEndian\" \
          header_type=\"UInt64\"",
    )?;
    if compression == Compression::Zlib {
        o.write_all(b" compressor=\"vtkZLibDataCompressor\"")?;
    }
    o.write_all(b">\n")?;
    o.write_all(b"  <UnstructuredGrid>\n")?;
    o.write_all(b"    <FieldData>\n")?;
    arrays.write(o, 6, "TimeValue", &[], Some(1), 1, [fields.t])?;
    arrays.write(o, 6, "Step", &[], Some(1), 1, [to_i64(fields.n)?])?;
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
                arrays.write(o, 8, name, &["x", "y", "z"], None, 3 * np, values)?;
            }
        }
        if let Some(z) = &fields.zeta {
            arrays.write(o, 8, "zeta", &[], None, np, z.iter().copied())?;
        }
        if let Some(contact) = &fields.contact {
            let mut state = vec![0u8; np];
            let mut slip = vec![0.0f64; np];
            for c in contact {
                state[c.node] = if c.slipping { 2 } else { 1 };
                slip[c.node] = c.slip_velocity.abs();
            }
            arrays.write(o, 8, "contact_state", &[], None, np, state)?;
            arrays.write(o, 8, "slip_velocity", &[], None, np, slip)?;
        }
        o.write_all(b"      </PointData>\n")?;
    }
    if fields.sigma.is_some() || fields.von_mises.is_some() || fields.estimate.is_some() {
        if fields.sigma.is_some() {
            o.write_all(b"      <CellData Tensors=\"sigma\">\n")?;
        } else {
            o.write_all(b"      <CellData>\n")?;
        }
        if let Some(s) = &fields.sigma {
            let values = (0..nc).flat_map(|e| s.six(e));
            arrays.write(o, 8, "sigma", &SYM_TENSOR, None, 6 * nc, values)?;
        }
        if let Some(vm) = &fields.von_mises {
            arrays.write(o, 8, "von_mises", &[], None, nc, vm.iter().copied())?;
        }
        if let Some(eta) = &fields.estimate {
            arrays.write(o, 8, "estimate", &[], None, nc, eta.iter().copied())?;
        }
        o.write_all(b"      </CellData>\n")?;
    }

    o.write_all(b"      <Points>\n")?;
    let points = nodes.iter().flat_map(|p| xyz(p));
    arrays.write(o, 8, "Points", &["x", "y", "z"], None, 3 * np, points)?;
    o.write_all(b"      </Points>\n")?;

    o.write_all(b"      <Cells>\n")?;
    // `validate` checked that every index and offset fits in an i64.
    let connectivity = cells.iter().map(|&i| i as i64);
    arrays.write(o, 8, "connectivity", &[], None, (D + 1) * nc, connectivity)?;
    let offsets = (1..=nc).map(|c| ((D + 1) * c) as i64);
    arrays.write(o, 8, "offsets", &[], None, nc, offsets)?;
    let kind = if D == 3 { VTK_TETRA } else { VTK_TRIANGLE };
    let types = std::iter::repeat_n(kind, nc);
    arrays.write(o, 8, "types", &[], None, nc, types)?;
    o.write_all(b"      </Cells>\n")?;

    o.write_all(b"    </Piece>\n")?;
    o.write_all(b"  </UnstructuredGrid>\n")?;
    o.write_all(b"</VTKFile>\n")?;
    out.flush()
}

/// [`write_vtu`] of a mesh of either dimension.
pub fn write_mesh_vtu<W: Write>(
    out: W,
    mesh: &AnyMesh,
    fields: &StepFields,
    compression: Compression,
) -> io::Result<()> {
    match mesh {
        AnyMesh::Plane(m) => write_vtu(out, &m.nodes, m.cells_flat(), fields, compression),
        AnyMesh::Solid(m) => write_vtu(out, &m.nodes, m.cells_flat(), fields, compression),
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
    check("estimate", f.estimate.as_ref().map(Vec::len), nc, &per_cell)?;
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

/// The writer of a file's data arrays in its encoding, with the buffers a compressed array
/// reuses from one array to the next.
struct Arrays {
    compression: Compression,
    /// The zlib state, reset for each block (allocated once per file, not per block).
    zlib: flate2::Compress,
    /// One block's raw bytes.
    block: Vec<u8>,
    /// The array's compressed blocks, one after the other.
    compressed: Vec<u8>,
}

impl Arrays {
    fn new(compression: Compression) -> Arrays {
        Arrays {
            compression,
            zlib: flate2::Compress::new(flate2::Compression::new(ZLIB_LEVEL), true),
            block: Vec::new(),
            compressed: Vec::new(),
        }
    }

    /// Writes one inline binary `<DataArray>` in the file's encoding. `components` names
    /// the components of a multi-component array (empty: scalar). `count` is the number of
    /// values (tuples × components) `values` yields; callers pass iterators over validated
    /// data, and a mismatch is reported as an error.
    #[allow(clippy::too_many_arguments)]
    fn write<W: Write, T: Scalar>(
        &mut self,
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
        let written = match self.compression {
            Compression::None => raw_payload(out, bytes, values)?,
            Compression::Zlib => self.zlib_payload(out, values)?,
        };
        if written != count {
            return Err(io::Error::other(format!(
                "data array {name}: {written} values written, {count} announced"
            )));
        }
        writeln!(out, "\n{:indent$}</DataArray>", "")
    }

    /// The zlib encoding of `values`: blocks of [`ZLIB_BLOCK`] raw bytes deflated one by one,
    /// then the base64 of the header and the base64 of the blocks. Returns the number of
    /// values.
    fn zlib_payload<W: Write, T: Scalar>(
        &mut self,
        out: &mut W,
        values: impl IntoIterator<Item = T>,
    ) -> io::Result<usize> {
        self.compressed.clear();
        self.block.clear();
        let mut sizes: Vec<u64> = Vec::new();
        let mut written = 0usize;
        let mut last = 0usize;
        for v in values {
            v.put(&mut self.block);
            written += 1;
            if self.block.len() == ZLIB_BLOCK {
                sizes.push(self.deflate_block()?);
                last = ZLIB_BLOCK;
                self.block.clear();
            }
        }
        if !self.block.is_empty() {
            last = self.block.len();
            sizes.push(self.deflate_block()?);
        }
        let header = [sizes.len() as u64, ZLIB_BLOCK as u64, last as u64]
            .into_iter()
            .chain(sizes)
            .flat_map(u64::to_le_bytes)
            .collect::<Vec<u8>>();
        // Two base64 texts, as VTK writes them: the header is decoded first, on its own, to
        // learn the blocks' sizes.
        let mut enc = EncoderWriter::new(&mut *out, &STANDARD);
        enc.write_all(&header)?;
        enc.finish()?;
        drop(enc);
        let mut enc = EncoderWriter::new(&mut *out, &STANDARD);
        enc.write_all(&self.compressed)?;
        enc.finish()?;
        Ok(written)
    }

    /// Deflates `self.block` as one zlib stream onto the end of `self.compressed`; returns
    /// its compressed size.
    fn deflate_block(&mut self) -> io::Result<u64> {
        self.zlib.reset();
        let start = self.compressed.len();
        let in0 = self.zlib.total_in();
        loop {
            // `compress_vec` writes into spare capacity only: room for the whole block (and
            // zlib's framing) unless it is incompressible, and more on the next round then.
            self.compressed.reserve(self.block.len() + 64);
            let consumed = (self.zlib.total_in() - in0) as usize;
            let status = self
                .zlib
                .compress_vec(
                    &self.block[consumed..],
                    &mut self.compressed,
                    flate2::FlushCompress::Finish,
                )
                .map_err(io::Error::other)?;
            if status == flate2::Status::StreamEnd {
                break;
            }
        }
        Ok((self.compressed.len() - start) as u64)
    }
}

/// The raw encoding of `values` (`bytes` of them): the base64 of the u64 byte count followed
/// by the values, encoded as they come. Returns the number of values.
fn raw_payload<W: Write, T: Scalar>(
    out: &mut W,
    bytes: usize,
    values: impl IntoIterator<Item = T>,
) -> io::Result<usize> {
    let mut written = 0usize;
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
    Ok(written)
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
