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
//! - `Points`: the mesh nodes as `Float64` with 3 components (z = 0);
//! - `Cells`: `connectivity` and `offsets` (`Int64`), `types` (`UInt8`, all 5 = VTK_TRIANGLE);
//! - `PointData`: `u` and `w` (3 components, z = 0) and `zeta`, each when present;
//! - `CellData`: `sigma` (3 components named xx, yy, xy) and `von_mises`, each when present;
//! - `FieldData`: `TimeValue` (the step's time t, which ParaView uses as the time of the data
//!   set) and `Step` (the step index n).
//!
//! The document is streamed array by array through a buffered writer, with each array's
//! base64 encoded on the fly, so memory does not grow with the size of the mesh.
//! All input is validated before the first byte is written: a field whose length does not
//! match the mesh, or a triangle with an out-of-range node, is an `InvalidInput` error.

use crate::solve::stepper::StepFields;
use base64::engine::general_purpose::STANDARD;
use base64::write::EncoderWriter;
use std::borrow::Cow;
use std::io::{self, BufWriter, Write};

/// VTK cell type of a linear triangle.
const VTK_TRIANGLE: u8 = 5;
/// Raw bytes gathered before they are handed to the base64 encoder.
const CHUNK_BYTES: usize = 48 * 1024;

/// Writes one step as a VTK XML UnstructuredGrid (`.vtu`) document (see the module docs).
///
/// `nodes` and `triangles` are the mesh; `u` and `w` in `fields` are interleaved (x, y) per
/// node, `zeta` is per node, `sigma` and `von_mises` are per triangle. The contact state is
/// not written. Errors with `InvalidInput`, before writing anything, when a field's length
/// does not match the mesh or a triangle refers to a missing node.
pub fn write_vtu<W: Write>(
    out: W,
    nodes: &[[f64; 2]],
    triangles: &[[usize; 3]],
    fields: &StepFields,
) -> io::Result<()> {
    validate(nodes, triangles, fields)?;
    let np = nodes.len();
    let nc = triangles.len();
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

    let has_point_data = fields.u.is_some() || fields.w.is_some() || fields.zeta.is_some();
    if has_point_data {
        o.write_all(b"      <PointData>\n")?;
        for (name, v) in [("u", &fields.u), ("w", &fields.w)] {
            if let Some(v) = v {
                let values = v.chunks_exact(2).flat_map(|c| [c[0], c[1], 0.0]);
                data_array(o, 8, name, &["x", "y", "z"], None, 3 * np, values)?;
            }
        }
        if let Some(z) = &fields.zeta {
            data_array(o, 8, "zeta", &[], None, np, z.iter().copied())?;
        }
        o.write_all(b"      </PointData>\n")?;
    }
    if fields.sigma.is_some() || fields.von_mises.is_some() {
        o.write_all(b"      <CellData>\n")?;
        if let Some(s) = &fields.sigma {
            let values = s.iter().flatten().copied();
            data_array(o, 8, "sigma", &["xx", "yy", "xy"], None, 3 * nc, values)?;
        }
        if let Some(vm) = &fields.von_mises {
            data_array(o, 8, "von_mises", &[], None, nc, vm.iter().copied())?;
        }
        o.write_all(b"      </CellData>\n")?;
    }

    o.write_all(b"      <Points>\n")?;
    let points = nodes.iter().flat_map(|p| [p[0], p[1], 0.0]);
    data_array(o, 8, "Points", &["x", "y", "z"], None, 3 * np, points)?;
    o.write_all(b"      </Points>\n")?;

    o.write_all(b"      <Cells>\n")?;
    // `validate` checked that every index and offset fits in an i64.
    let connectivity = triangles.iter().flatten().map(|&i| i as i64);
    data_array(o, 8, "connectivity", &[], None, 3 * nc, connectivity)?;
    let offsets = (1..=nc).map(|c| 3 * c as i64);
    data_array(o, 8, "offsets", &[], None, nc, offsets)?;
    let types = std::iter::repeat_n(VTK_TRIANGLE, nc);
    data_array(o, 8, "types", &[], None, nc, types)?;
    o.write_all(b"      </Cells>\n")?;

    o.write_all(b"    </Piece>\n")?;
    o.write_all(b"  </UnstructuredGrid>\n")?;
    o.write_all(b"</VTKFile>\n")?;
    out.flush()
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

/// Checks that every field matches the mesh and every index fits the file's types.
fn validate(nodes: &[[f64; 2]], triangles: &[[usize; 3]], f: &StepFields) -> io::Result<()> {
    let np = nodes.len();
    let nc = triangles.len();
    to_i64(nc.saturating_mul(3))?;
    to_i64(f.n)?;
    if let Some((e, t)) = triangles
        .iter()
        .enumerate()
        .find(|(_, t)| t.iter().any(|&i| i >= np))
    {
        return Err(invalid(format!(
            "triangle {e} {t:?} refers to a node beyond the mesh's {np} nodes"
        )));
    }
    let check = |name: &str, len: Option<usize>, expected: usize, per: &str| match len {
        Some(len) if len != expected => Err(invalid(format!(
            "field {name} has {len} values but the mesh needs {expected} ({per})"
        ))),
        _ => Ok(()),
    };
    let nodal2 = np.saturating_mul(2);
    check("u", f.u.as_ref().map(Vec::len), nodal2, "x, y per node")?;
    check("w", f.w.as_ref().map(Vec::len), nodal2, "x, y per node")?;
    check("zeta", f.zeta.as_ref().map(Vec::len), np, "one per node")?;
    check(
        "sigma",
        f.sigma.as_ref().map(Vec::len),
        nc,
        "one per triangle",
    )?;
    check(
        "von_mises",
        f.von_mises.as_ref().map(Vec::len),
        nc,
        "one per triangle",
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
/// values. `components` names the components of a multi-component array (empty: scalar). `count` is the number of values (tuples × components) `values` yields; callers
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
mod tests {
    use super::*;
    use crate::mesh::Mesh;
    use crate::problem::MeshPattern;
    use crate::solve::stepper::ContactNode;
    use base64::Engine;

    /// An element of the strict little XML reader below.
    #[derive(Debug)]
    struct Element {
        name: String,
        attrs: Vec<(String, String)>,
        children: Vec<Element>,
        text: String,
    }

    impl Element {
        fn attr(&self, key: &str) -> &str {
            self.attrs
                .iter()
                .find(|(k, _)| k == key)
                .map(|(_, v)| v.as_str())
                .unwrap_or_else(|| panic!("<{}> has no attribute {key}", self.name))
        }

        fn has_attr(&self, key: &str) -> bool {
            self.attrs.iter().any(|(k, _)| k == key)
        }

        fn all(&self, name: &str) -> Vec<&Element> {
            self.children.iter().filter(|c| c.name == name).collect()
        }

        /// The only child called `name`.
        fn child(&self, name: &str) -> &Element {
            let found = self.all(name);
            assert_eq!(
                found.len(),
                1,
                "<{}> has {} <{name}>",
                self.name,
                found.len()
            );
            found[0]
        }

        fn array(&self, name: &str) -> &Element {
            let found: Vec<_> = self
                .all("DataArray")
                .into_iter()
                .filter(|a| a.attr("Name") == name)
                .collect();
            assert_eq!(
                found.len(),
                1,
                "<{}> has {} arrays {name}",
                self.name,
                found.len()
            );
            found[0]
        }

        fn array_names(&self) -> Vec<&str> {
            self.all("DataArray")
                .iter()
                .map(|a| a.attr("Name"))
                .collect()
        }
    }

    /// A strict reader for the XML subset written here: an optional `<?xml …?>` declaration,
    /// then one root element; elements with double-quoted attributes (no duplicates), text,
    /// the five predefined entities and numeric character references. Anything else —
    /// mismatched or unclosed tags, a bare `&`, `<` in a value, trailing content — panics.
    fn parse_xml(doc: &str) -> Element {
        let mut p = Parser { s: doc, i: 0 };
        if p.rest().starts_with("<?xml") {
            let end = p.rest().find("?>").expect("unterminated declaration");
            p.i += end + 2;
        }
        p.skip_ws();
        let root = p.element();
        p.skip_ws();
        assert_eq!(p.i, doc.len(), "content after the root element");
        root
    }

    struct Parser<'a> {
        s: &'a str,
        i: usize,
    }

    impl<'a> Parser<'a> {
        fn rest(&self) -> &'a str {
            &self.s[self.i..]
        }

        fn skip_ws(&mut self) {
            let trimmed = self.rest().trim_start_matches([' ', '\t', '\n', '\r']);
            self.i = self.s.len() - trimmed.len();
        }

        fn expect(&mut self, token: &str) {
            assert!(
                self.rest().starts_with(token),
                "expected {token:?} at byte {}: {:?}",
                self.i,
                &self.rest()[..self.rest().len().min(40)]
            );
            self.i += token.len();
        }

        fn name(&mut self) -> String {
            let len = self
                .rest()
                .find(|c: char| !(c.is_ascii_alphanumeric() || c == '_'))
                .unwrap_or(self.rest().len());
            let name = &self.rest()[..len];
            assert!(
                name.starts_with(|c: char| c.is_ascii_alphabetic() || c == '_'),
                "bad name at byte {}",
                self.i
            );
            self.i += len;
            name.to_string()
        }

        fn element(&mut self) -> Element {
            self.expect("<");
            let name = self.name();
            let mut attrs: Vec<(String, String)> = Vec::new();
            loop {
                let before = self.i;
                self.skip_ws();
                if self.rest().starts_with("/>") {
                    self.i += 2;
                    return Element {
                        name,
                        attrs,
                        children: Vec::new(),
                        text: String::new(),
                    };
                }
                if self.rest().starts_with('>') {
                    self.i += 1;
                    break;
                }
                assert!(self.i > before, "attributes must be separated by space");
                let key = self.name();
                self.expect("=\"");
                let end = self.rest().find('"').expect("unterminated attribute value");
                let raw = &self.rest()[..end];
                assert!(!raw.contains('<'), "'<' in attribute value");
                let value = unescape(raw);
                self.i += end + 1;
                assert!(
                    attrs.iter().all(|(k, _)| *k != key),
                    "duplicate attribute {key}"
                );
                attrs.push((key, value));
            }
            let mut children = Vec::new();
            let mut text = String::new();
            loop {
                if self.rest().starts_with("</") {
                    self.i += 2;
                    let close = self.name();
                    assert_eq!(close, name, "mismatched closing tag");
                    self.skip_ws();
                    self.expect(">");
                    return Element {
                        name,
                        attrs,
                        children,
                        text,
                    };
                }
                if self.rest().starts_with('<') {
                    children.push(self.element());
                    continue;
                }
                let end = self.rest().find('<').expect("unclosed element");
                text.push_str(&unescape(&self.rest()[..end]));
                self.i += end;
            }
        }
    }

    fn unescape(raw: &str) -> String {
        let mut out = String::new();
        let mut rest = raw;
        while let Some(amp) = rest.find('&') {
            out.push_str(&rest[..amp]);
            let semi = rest[amp..].find(';').expect("bare '&'") + amp;
            let entity = &rest[amp + 1..semi];
            match entity {
                "amp" => out.push('&'),
                "lt" => out.push('<'),
                "gt" => out.push('>'),
                "quot" => out.push('"'),
                "apos" => out.push('\''),
                _ => {
                    let code = entity.strip_prefix('#').expect("unknown entity");
                    let code: u32 = code.parse().expect("bad character reference");
                    out.push(char::from_u32(code).expect("bad character"));
                }
            }
            rest = &rest[semi + 1..];
        }
        out.push_str(rest);
        out
    }

    /// Decodes an inline binary array: checks the format, the type, the UInt64 byte-count
    /// header against the payload and the payload against tuples × components; returns the
    /// payload.
    fn payload(a: &Element, vtk_type: &str, size: usize, tuples: usize, comps: usize) -> Vec<u8> {
        assert_eq!(a.attr("format"), "binary");
        assert_eq!(a.attr("type"), vtk_type, "array {}", a.attr("Name"));
        let declared = if a.has_attr("NumberOfComponents") {
            a.attr("NumberOfComponents").parse().unwrap()
        } else {
            1
        };
        assert_eq!(declared, comps, "components of {}", a.attr("Name"));
        assert!(a.children.is_empty());
        let raw = base64::engine::general_purpose::STANDARD
            .decode(a.text.trim())
            .expect("valid base64");
        assert!(raw.len() >= 8);
        let (head, data) = raw.split_at(8);
        let count = u64::from_le_bytes(head.try_into().unwrap());
        assert_eq!(
            count as usize,
            data.len(),
            "byte-count header of {}",
            a.attr("Name")
        );
        assert_eq!(
            data.len(),
            tuples * comps * size,
            "length of {}",
            a.attr("Name")
        );
        data.to_vec()
    }

    fn f64s(a: &Element, tuples: usize, comps: usize) -> Vec<f64> {
        payload(a, "Float64", 8, tuples, comps)
            .chunks_exact(8)
            .map(|c| f64::from_le_bytes(c.try_into().unwrap()))
            .collect()
    }

    fn i64s(a: &Element, tuples: usize) -> Vec<i64> {
        payload(a, "Int64", 8, tuples, 1)
            .chunks_exact(8)
            .map(|c| i64::from_le_bytes(c.try_into().unwrap()))
            .collect()
    }

    fn vec3(interleaved: &[f64]) -> Vec<f64> {
        interleaved
            .chunks_exact(2)
            .flat_map(|c| [c[0], c[1], 0.0])
            .collect()
    }

    fn hand_built(mesh: &Mesh) -> StepFields {
        let np = mesh.nodes.len();
        let nc = mesh.triangles.len();
        StepFields {
            n: 7,
            t: 0.35,
            u: Some((0..2 * np).map(|i| i as f64 * 1e-3 - 0.01).collect()),
            w: Some((0..2 * np).map(|i| -(i as f64) / 7.0).collect()),
            zeta: Some((0..np).map(|i| 1.0 - i as f64 / 100.0).collect()),
            sigma: Some(
                (0..nc)
                    .map(|e| [e as f64, -(e as f64) * 2.5, 0.125 * e as f64])
                    .collect(),
            ),
            von_mises: Some((0..nc).map(|e| (e as f64).sqrt()).collect()),
            contact: Some(vec![ContactNode {
                node: 0,
                slip_velocity: 0.5,
                friction_traction: 0.1,
                bound: 0.2,
                slipping: true,
            }]),
        }
    }

    fn render(mesh: &Mesh, f: &StepFields) -> String {
        let mut buf = Vec::new();
        write_vtu(&mut buf, &mesh.nodes, &mesh.triangles, f).unwrap();
        String::from_utf8(buf).expect("UTF-8")
    }

    /// Everything every .vtu must satisfy; returns the Piece.
    fn check_grid(root: &Element, mesh: &Mesh, f: &StepFields) {
        let np = mesh.nodes.len();
        let nc = mesh.triangles.len();
        assert_eq!(root.name, "VTKFile");
        assert_eq!(root.attr("type"), "UnstructuredGrid");
        assert_eq!(root.attr("version"), "1.0");
        assert_eq!(root.attr("byte_order"), "LittleEndian");
        assert_eq!(root.attr("header_type"), "UInt64");
        assert_eq!(root.children.len(), 1);
        let grid = root.child("UnstructuredGrid");
        assert_eq!(grid.children.len(), 2);

        let fd = grid.child("FieldData");
        let time = fd.array("TimeValue");
        assert_eq!(time.attr("NumberOfTuples"), "1");
        assert_eq!(f64s(time, 1, 1)[0].to_bits(), f.t.to_bits());
        assert_eq!(i64s(fd.array("Step"), 1), [f.n as i64]);

        let piece = grid.child("Piece");
        assert_eq!(piece.attr("NumberOfPoints"), np.to_string());
        assert_eq!(piece.attr("NumberOfCells"), nc.to_string());

        let points = piece.child("Points").child("DataArray");
        let expected: Vec<f64> = mesh.nodes.iter().flat_map(|p| [p[0], p[1], 0.0]).collect();
        assert_eq!(f64s(points, np, 3), expected);

        let cells = piece.child("Cells");
        assert_eq!(cells.array_names(), ["connectivity", "offsets", "types"]);
        let conn = i64s(cells.array("connectivity"), 3 * nc);
        let tri: Vec<i64> = mesh.triangles.iter().flatten().map(|&i| i as i64).collect();
        assert_eq!(conn, tri);
        let offsets = i64s(cells.array("offsets"), nc);
        assert_eq!(offsets, (1..=nc as i64).map(|c| 3 * c).collect::<Vec<_>>());
        let types = payload(cells.array("types"), "UInt8", 1, nc, 1);
        assert!(types.iter().all(|&t| t == 5));
    }

    #[test]
    fn vtu_of_all_fields_reads_back() {
        let mesh = Mesh::rectangle(2.0, 1.0, 4, 2, MeshPattern::Diagonal);
        let (np, nc) = (mesh.nodes.len(), mesh.triangles.len());
        assert_eq!((np, nc), (15, 16));
        let f = hand_built(&mesh);
        let doc = render(&mesh, &f);
        let root = parse_xml(&doc);
        check_grid(&root, &mesh, &f);
        let piece = root.child("UnstructuredGrid").child("Piece");

        let pd = piece.child("PointData");
        assert_eq!(pd.array_names(), ["u", "w", "zeta"]);
        for (name, v) in [("u", &f.u), ("w", &f.w)] {
            assert_eq!(f64s(pd.array(name), np, 3), vec3(v.as_ref().unwrap()));
        }
        assert_eq!(&f64s(pd.array("zeta"), np, 1), f.zeta.as_ref().unwrap());

        let cd = piece.child("CellData");
        assert_eq!(cd.array_names(), ["sigma", "von_mises"]);
        let sigma = cd.array("sigma");
        assert_eq!(sigma.attr("ComponentName0"), "xx");
        assert_eq!(sigma.attr("ComponentName1"), "yy");
        assert_eq!(sigma.attr("ComponentName2"), "xy");
        let expected: Vec<f64> = f
            .sigma
            .as_ref()
            .unwrap()
            .iter()
            .flatten()
            .copied()
            .collect();
        assert_eq!(f64s(sigma, nc, 3), expected);
        assert_eq!(
            &f64s(cd.array("von_mises"), nc, 1),
            f.von_mises.as_ref().unwrap()
        );
    }

    #[test]
    fn vtu_writes_only_the_present_fields() {
        let mesh = Mesh::rectangle(2.0, 1.0, 4, 2, MeshPattern::Diagonal);
        let full = hand_built(&mesh);
        let none = StepFields {
            u: None,
            w: None,
            zeta: None,
            sigma: None,
            von_mises: None,
            contact: None,
            ..full.clone()
        };
        let root = parse_xml(&render(&mesh, &none));
        check_grid(&root, &mesh, &none);
        let piece = root.child("UnstructuredGrid").child("Piece");
        assert!(piece.all("PointData").is_empty() && piece.all("CellData").is_empty());

        let some = StepFields {
            w: full.w.clone(),
            von_mises: full.von_mises.clone(),
            ..none.clone()
        };
        let root = parse_xml(&render(&mesh, &some));
        check_grid(&root, &mesh, &some);
        let piece = root.child("UnstructuredGrid").child("Piece");
        assert_eq!(piece.child("PointData").array_names(), ["w"]);
        assert_eq!(piece.child("CellData").array_names(), ["von_mises"]);
    }

    #[test]
    fn vtu_of_a_larger_mesh_crosses_chunk_boundaries() {
        // 61 × 41 nodes: every array is larger than one encoder chunk.
        let mesh = Mesh::rectangle(3.0, 2.0, 60, 40, MeshPattern::Cross);
        let f = hand_built(&mesh);
        assert!(8 * 3 * 3 * mesh.triangles.len() > CHUNK_BYTES * 2);
        let root = parse_xml(&render(&mesh, &f));
        check_grid(&root, &mesh, &f);
        let piece = root.child("UnstructuredGrid").child("Piece");
        let np = mesh.nodes.len();
        let u = f64s(piece.child("PointData").array("u"), np, 3);
        assert_eq!(u, vec3(f.u.as_ref().unwrap()));
    }

    #[test]
    fn vtu_rejects_fields_that_do_not_match_the_mesh() {
        let mesh = Mesh::rectangle(2.0, 1.0, 4, 2, MeshPattern::Diagonal);
        let good = hand_built(&mesh);
        let mut bad = Vec::new();
        let mut u = good.clone();
        u.u.as_mut().unwrap().pop();
        bad.push(u);
        let mut zeta = good.clone();
        zeta.zeta.as_mut().unwrap().push(1.0);
        bad.push(zeta);
        let mut sigma = good.clone();
        sigma.sigma.as_mut().unwrap().pop();
        bad.push(sigma);
        let mut vm = good.clone();
        vm.von_mises = Some(Vec::new());
        bad.push(vm);
        for f in &bad {
            let mut buf = Vec::new();
            let err = write_vtu(&mut buf, &mesh.nodes, &mesh.triangles, f).unwrap_err();
            assert_eq!(err.kind(), io::ErrorKind::InvalidInput, "{err}");
            assert!(buf.is_empty(), "nothing is written for invalid input");
        }
        let mut triangles = mesh.triangles.clone();
        triangles[3][1] = mesh.nodes.len();
        let mut buf = Vec::new();
        let err = write_vtu(&mut buf, &mesh.nodes, &triangles, &good).unwrap_err();
        assert_eq!(err.kind(), io::ErrorKind::InvalidInput);
        assert!(err.to_string().contains("triangle 3"), "{err}");
        assert!(buf.is_empty());
    }

    #[test]
    fn pvd_lists_the_steps_with_escaped_file_names() {
        let entries = vec![
            (0.0, "step_0.vtu".to_string()),
            (0.1, "fields?step=1&format=vtu".to_string()),
            (1e-7, "a<b>\"c\" 'd'.vtu".to_string()),
            (2.5e3, "tab\there.vtu".to_string()),
        ];
        let mut buf = Vec::new();
        write_pvd(&mut buf, &entries).unwrap();
        let doc = String::from_utf8(buf).unwrap();
        assert!(
            doc.contains("file=\"fields?step=1&amp;format=vtu\""),
            "{doc}"
        );
        let root = parse_xml(&doc);
        assert_eq!(root.name, "VTKFile");
        assert_eq!(root.attr("type"), "Collection");
        assert_eq!(root.attr("version"), "1.0");
        assert_eq!(root.attr("byte_order"), "LittleEndian");
        let sets = root.child("Collection").all("DataSet");
        assert_eq!(sets.len(), entries.len());
        for (set, (t, file)) in sets.iter().zip(&entries) {
            assert_eq!(set.attr("timestep").parse::<f64>().unwrap(), *t);
            assert_eq!(set.attr("group"), "");
            assert_eq!(set.attr("part"), "0");
            assert_eq!(set.attr("file"), file);
            assert!(set.children.is_empty());
        }

        let mut buf = Vec::new();
        write_pvd(&mut buf, &[]).unwrap();
        let root = parse_xml(std::str::from_utf8(&buf).unwrap());
        assert!(root.child("Collection").children.is_empty());

        let mut buf = Vec::new();
        let err = write_pvd(&mut buf, &[(0.0, "bell\u{7}.vtu".to_string())]).unwrap_err();
        assert_eq!(err.kind(), io::ErrorKind::InvalidInput);
        assert!(buf.is_empty());
    }

    #[test]
    fn the_test_reader_is_strict() {
        for bad in [
            "<a><b></a></b>",
            "<a>",
            "<a x=\"1\" x=\"2\"/>",
            "<a x=\"&\"/>",
            "<a>&bogus;</a>",
            "<a/><b/>",
            "<a x=\"1\"y=\"2\"/>",
        ] {
            let r = std::panic::catch_unwind(|| parse_xml(bad));
            assert!(r.is_err(), "accepted {bad:?}");
        }
        let ok = parse_xml("<?xml version=\"1.0\"?>\n<a x=\"&lt;&#38;\"><b/>t&amp;</a>\n");
        assert_eq!(ok.attr("x"), "<&");
        assert_eq!(ok.text, "t&");
        assert_eq!(ok.child("b").name, "b");
    }
}
