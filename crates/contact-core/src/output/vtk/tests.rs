//! The `.vtu` and `.pvd` documents read back with a strict XML parser (roxmltree): structure,
//! attributes, and every binary array decoded and compared bit for bit.

use super::*;
use crate::mesh::Mesh;
use crate::problem::MeshPattern;
use crate::solve::stepper::{ContactNode, Stress};
use base64::engine::general_purpose::STANDARD;
use base64::Engine;
use roxmltree::{Document, Node};

/// What the checks below ask of an element.
trait Element<'a> {
    /// The attribute's value; panics when it is missing.
    fn attr(&self, key: &str) -> &'a str;
    /// The element children, in document order (text and comments left out).
    fn elements(&self) -> Vec<Node<'a, 'a>>;
    /// The element children called `name`.
    fn all(&self, name: &str) -> Vec<Node<'a, 'a>>;
    /// The only child called `name`.
    fn child(&self, name: &str) -> Node<'a, 'a>;
    /// The only `<DataArray>` child with `Name="name"`.
    fn array(&self, name: &str) -> Node<'a, 'a>;
    /// The `Name`s of the `<DataArray>` children, in order.
    fn array_names(&self) -> Vec<&'a str>;
    /// All text directly inside the element.
    fn text_content(&self) -> String;
}

impl<'a> Element<'a> for Node<'a, 'a> {
    fn attr(&self, key: &str) -> &'a str {
        self.attribute(key)
            .unwrap_or_else(|| panic!("<{}> has no attribute {key}", self.tag_name().name()))
    }

    fn elements(&self) -> Vec<Node<'a, 'a>> {
        self.children().filter(Node::is_element).collect()
    }

    fn all(&self, name: &str) -> Vec<Node<'a, 'a>> {
        self.children()
            .filter(|c| c.is_element() && c.tag_name().name() == name)
            .collect()
    }

    fn child(&self, name: &str) -> Node<'a, 'a> {
        let found = self.all(name);
        assert_eq!(
            found.len(),
            1,
            "<{}> has {} <{name}>",
            self.tag_name().name(),
            found.len()
        );
        found[0]
    }

    fn array(&self, name: &str) -> Node<'a, 'a> {
        let found: Vec<_> = self
            .all("DataArray")
            .into_iter()
            .filter(|a| a.attr("Name") == name)
            .collect();
        assert_eq!(
            found.len(),
            1,
            "<{}> has {} arrays {name}",
            self.tag_name().name(),
            found.len()
        );
        found[0]
    }

    fn array_names(&self) -> Vec<&'a str> {
        self.all("DataArray")
            .iter()
            .map(|a| a.attr("Name"))
            .collect()
    }

    fn text_content(&self) -> String {
        self.children().filter_map(|c| c.text()).collect()
    }
}

/// Parses a whole document; anything that is not well-formed XML panics.
fn parse_xml(doc: &str) -> Document<'_> {
    Document::parse(doc).unwrap_or_else(|e| panic!("not well-formed XML: {e}"))
}

/// Decodes an inline binary array: checks the format, the type, the header against the
/// payload (the UInt64 byte count of a raw file; the zlib header of a file with
/// `compressor="vtkZLibDataCompressor"`, each block inflated) and the payload against
/// tuples × components; returns the payload.
fn payload(a: Node, vtk_type: &str, size: usize, tuples: usize, comps: usize) -> Vec<u8> {
    assert_eq!(a.attr("format"), "binary");
    assert_eq!(a.attr("type"), vtk_type, "array {}", a.attr("Name"));
    let declared = match a.attribute("NumberOfComponents") {
        Some(c) => c.parse().unwrap(),
        None => 1,
    };
    assert_eq!(declared, comps, "components of {}", a.attr("Name"));
    assert!(a.elements().is_empty());
    let text = a.text_content();
    let data = match a.document().root_element().attribute("compressor") {
        None => raw_data(text.trim()),
        Some("vtkZLibDataCompressor") => zlib_data(text.trim()),
        Some(other) => panic!("unknown compressor {other}"),
    };
    assert_eq!(
        data.len(),
        tuples * comps * size,
        "length of {}",
        a.attr("Name")
    );
    data
}

/// A raw array: one base64 text, the UInt64 byte count, then the bytes.
fn raw_data(text: &str) -> Vec<u8> {
    let raw = STANDARD.decode(text).expect("valid base64");
    assert!(raw.len() >= 8);
    let (head, data) = raw.split_at(8);
    let count = u64::from_le_bytes(head.try_into().unwrap());
    assert_eq!(count as usize, data.len(), "byte-count header");
    data.to_vec()
}

/// A zlib array, read as VTK reads it: the base64 of the header `[blocks, block size, last
/// block size, compressed sizes…]` on its own (its length follows from its first number),
/// then the base64 of the blocks, each inflated to its announced size.
fn zlib_data(text: &str) -> Vec<u8> {
    use std::io::Read;
    let chars = |bytes: usize| bytes.div_ceil(3) * 4;
    let first = STANDARD.decode(&text[..chars(8)]).expect("valid base64");
    let blocks = u64::from_le_bytes(first[..8].try_into().unwrap()) as usize;
    let header_chars = chars(8 * (3 + blocks));
    let header: Vec<u64> = STANDARD
        .decode(&text[..header_chars])
        .expect("valid base64")
        .chunks_exact(8)
        .map(|c| u64::from_le_bytes(c.try_into().unwrap()))
        .collect();
    assert_eq!(header.len(), 3 + blocks);
    let (block, last) = (header[1] as usize, header[2] as usize);
    assert_eq!(block, ZLIB_BLOCK);
    assert!(last <= block && (blocks == 0 || last > 0));
    let compressed = STANDARD
        .decode(&text[header_chars..])
        .expect("valid base64");
    assert_eq!(
        compressed.len() as u64,
        header[3..].iter().sum::<u64>(),
        "the blocks' sizes add up"
    );
    let mut data = Vec::new();
    let mut at = 0;
    for (i, &size) in header[3..].iter().enumerate() {
        let mut inflated = Vec::new();
        flate2::read::ZlibDecoder::new(&compressed[at..at + size as usize])
            .read_to_end(&mut inflated)
            .expect("a zlib stream");
        let expected = if i + 1 == blocks { last } else { block };
        assert_eq!(inflated.len(), expected, "block {i}");
        data.extend(inflated);
        at += size as usize;
    }
    data
}

fn f64s(a: Node, tuples: usize, comps: usize) -> Vec<f64> {
    payload(a, "Float64", 8, tuples, comps)
        .chunks_exact(8)
        .map(|c| f64::from_le_bytes(c.try_into().unwrap()))
        .collect()
}

fn i64s(a: Node, tuples: usize) -> Vec<i64> {
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

/// Plane (σ_xx, σ_yy, σ_xy) as VTK's symmetric tensor (xx, yy, zz, xy, yz, xz).
fn sym6(plane: &Stress) -> Vec<f64> {
    let Stress::Plane(plane) = plane else {
        panic!("plane stresses expected")
    };
    plane
        .iter()
        .flat_map(|s| [s[0], s[1], 0.0, s[2], 0.0, 0.0])
        .collect()
}

/// Checks that `sigma` is declared as the cells' symmetric tensor and returns its values.
fn sigma_tensor(cd: Node, nc: usize) -> Vec<f64> {
    assert_eq!(cd.attr("Tensors"), "sigma", "the active cell tensors");
    let sigma = cd.array("sigma");
    assert_eq!(sigma.attr("NumberOfComponents"), "6");
    for (i, name) in ["xx", "yy", "zz", "xy", "yz", "xz"].iter().enumerate() {
        assert_eq!(sigma.attr(&format!("ComponentName{i}")), *name);
    }
    assert!(sigma.attribute("ComponentName6").is_none());
    f64s(sigma, nc, 6)
}

fn hand_built(mesh: &Mesh) -> StepFields {
    let np = mesh.nodes.len();
    let nc = mesh.n_cells();
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
            tangential_velocity: None,
            traction: None,
        }]),
        estimate: Some((0..nc).map(|e| 1.0 / (1.0 + e as f64)).collect()),
    }
}

/// The document in the default encoding (zlib).
fn render(mesh: &Mesh, f: &StepFields) -> String {
    render_as(mesh, f, Compression::default())
}

fn render_as(mesh: &Mesh, f: &StepFields, compression: Compression) -> String {
    let mut buf = Vec::new();
    write_vtu(&mut buf, &mesh.nodes, mesh.cells_flat(), f, compression).unwrap();
    String::from_utf8(buf).expect("UTF-8")
}

/// Everything every .vtu must satisfy.
fn check_grid(root: Node, mesh: &Mesh, f: &StepFields) {
    let np = mesh.nodes.len();
    let nc = mesh.n_cells();
    assert_eq!(root.tag_name().name(), "VTKFile");
    assert_eq!(root.attr("type"), "UnstructuredGrid");
    assert_eq!(root.attr("version"), "1.0");
    assert_eq!(root.attr("byte_order"), "LittleEndian");
    assert_eq!(root.attr("header_type"), "UInt64");
    assert_eq!(root.elements().len(), 1);
    let grid = root.child("UnstructuredGrid");
    assert_eq!(grid.elements().len(), 2);

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
    let tri: Vec<i64> = mesh
        .triangles()
        .iter()
        .flatten()
        .map(|&i| i as i64)
        .collect();
    assert_eq!(conn, tri);
    let offsets = i64s(cells.array("offsets"), nc);
    assert_eq!(offsets, (1..=nc as i64).map(|c| 3 * c).collect::<Vec<_>>());
    let types = payload(cells.array("types"), "UInt8", 1, nc, 1);
    assert!(types.iter().all(|&t| t == 5));
}

#[test]
fn vtu_of_all_fields_reads_back() {
    for compression in [Compression::Zlib, Compression::None] {
        all_fields_read_back(compression);
    }
}

fn all_fields_read_back(compression: Compression) {
    let mesh = Mesh::rectangle(2.0, 1.0, 4, 2, MeshPattern::Diagonal);
    let (np, nc) = (mesh.nodes.len(), mesh.n_cells());
    assert_eq!((np, nc), (15, 16));
    let f = hand_built(&mesh);
    let doc = render_as(&mesh, &f, compression);
    let xml = parse_xml(&doc);
    let root = xml.root_element();
    check_grid(root, &mesh, &f);
    let piece = root.child("UnstructuredGrid").child("Piece");

    let pd = piece.child("PointData");
    assert_eq!(
        pd.array_names(),
        ["u", "w", "zeta", "contact_state", "slip_velocity"]
    );
    for (name, v) in [("u", &f.u), ("w", &f.w)] {
        assert_eq!(f64s(pd.array(name), np, 3), vec3(v.as_ref().unwrap()));
    }
    assert_eq!(&f64s(pd.array("zeta"), np, 1), f.zeta.as_ref().unwrap());
    // Node 0 slips at 0.5; every other node is off Γ3.
    let slip = f64s(pd.array("slip_velocity"), np, 1);
    assert_eq!(slip[0], 0.5);
    assert!(slip[1..].iter().all(|v| *v == 0.0));

    let cd = piece.child("CellData");
    assert_eq!(cd.array_names(), ["sigma", "von_mises", "estimate"]);
    assert_eq!(sigma_tensor(cd, nc), sym6(f.sigma.as_ref().unwrap()));
    assert_eq!(
        &f64s(cd.array("von_mises"), nc, 1),
        f.von_mises.as_ref().unwrap()
    );
    assert_eq!(
        &f64s(cd.array("estimate"), nc, 1),
        f.estimate.as_ref().unwrap()
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
        estimate: None,
        ..full.clone()
    };
    let doc = render(&mesh, &none);
    let xml = parse_xml(&doc);
    let root = xml.root_element();
    check_grid(root, &mesh, &none);
    let piece = root.child("UnstructuredGrid").child("Piece");
    assert!(piece.all("PointData").is_empty() && piece.all("CellData").is_empty());

    let some = StepFields {
        w: full.w.clone(),
        von_mises: full.von_mises.clone(),
        ..none.clone()
    };
    let doc = render(&mesh, &some);
    let xml = parse_xml(&doc);
    let root = xml.root_element();
    check_grid(root, &mesh, &some);
    let piece = root.child("UnstructuredGrid").child("Piece");
    assert_eq!(piece.child("PointData").array_names(), ["w"]);
    let cd = piece.child("CellData");
    assert_eq!(cd.array_names(), ["von_mises"]);
    assert!(
        cd.attribute("Tensors").is_none(),
        "no sigma, no active tensors"
    );
}

#[test]
fn vtu_of_a_larger_mesh_crosses_chunk_boundaries() {
    // 61 × 41 nodes: every array is larger than one encoder chunk and one zlib block.
    let mesh = Mesh::rectangle(3.0, 2.0, 60, 40, MeshPattern::Cross);
    let f = hand_built(&mesh);
    assert!(8 * 3 * 3 * mesh.n_cells() > CHUNK_BYTES * 2);
    assert!(8 * 3 * mesh.nodes.len() > ZLIB_BLOCK * 2);
    let mut sizes = Vec::new();
    for compression in [Compression::Zlib, Compression::None] {
        let doc = render_as(&mesh, &f, compression);
        sizes.push(doc.len());
        let xml = parse_xml(&doc);
        let root = xml.root_element();
        check_grid(root, &mesh, &f);
        let piece = root.child("UnstructuredGrid").child("Piece");
        let np = mesh.nodes.len();
        let u = f64s(piece.child("PointData").array("u"), np, 3);
        assert_eq!(u, vec3(f.u.as_ref().unwrap()));
    }
    assert!(
        sizes[0] < sizes[1],
        "zlib {} < raw {} bytes",
        sizes[0],
        sizes[1]
    );
}

/// The two encodings carry the same bytes: every array of a compressed file equals its raw
/// twin, and only the compressed root names the compressor.
#[test]
fn zlib_and_raw_files_hold_the_same_arrays() {
    let mesh = Mesh::rectangle(3.0, 2.0, 30, 20, MeshPattern::Diagonal);
    let f = hand_built(&mesh);
    let (zlib, raw) = (
        render_as(&mesh, &f, Compression::Zlib),
        render_as(&mesh, &f, Compression::None),
    );
    let (zx, rx) = (parse_xml(&zlib), parse_xml(&raw));
    assert_eq!(
        zx.root_element().attr("compressor"),
        "vtkZLibDataCompressor"
    );
    assert!(rx.root_element().attribute("compressor").is_none());
    let arrays = |d: &Document| -> Vec<(String, String, Vec<u8>)> {
        d.descendants()
            .filter(|n| n.has_tag_name("DataArray"))
            .map(|a| {
                let text = a.text_content();
                let data = match a.document().root_element().attribute("compressor") {
                    Some(_) => zlib_data(text.trim()),
                    None => raw_data(text.trim()),
                };
                (a.attr("Name").to_string(), a.attr("type").to_string(), data)
            })
            .collect()
    };
    let (za, ra) = (arrays(&zx), arrays(&rx));
    assert_eq!(za.len(), 14);
    assert_eq!(za, ra);
}

/// σ of a known constant-strain field, written and read back: the initial state of a scene
/// with a linear u_0 = (a x + b y, c x + d y) and a constant ζ_0 has ε = [[a, (b + c)/2],
/// [(b + c)/2, d]] on every triangle and σ_0 = B(ε, ζ_0) = ζ_0 (2μ ε + λ tr ε I) (4.1), so
/// each of the six components is known in closed form, and all differ (an order mix-up
/// cannot go unseen). Also: step 0 at t = 0, u_0 and ζ_0 as the run starts from them, w_0 = 0.
#[test]
fn vtu_sigma_is_the_symmetric_tensor_of_a_constant_strain_field() {
    use crate::solve::stepper::{initial_fields, Simulation};
    use crate::solve::SolverSettings;
    let (a, b, c, d) = (0.012, 0.02, -0.05, -0.007);
    let (mu, lambda, zeta0) = (4.0, 3.0, 0.75);
    let mut doc = crate::scene::presets::get("paper-exp1").unwrap();
    doc["mesh"]["h"] = serde_json::json!("1/4");
    doc["time"] = serde_json::json!({"t_end": 1, "N": 4});
    doc["material"]["elasticity"] =
        serde_json::json!({"type": "linear", "mu": mu, "lambda": lambda});
    doc["initial"]["u0"] = serde_json::json!([format!("{a}*x + {b}*y"), format!("{c}*x + {d}*y")]);
    doc["damage"]["zeta0"] = serde_json::json!(zeta0);
    let problem = crate::scene::validate(&doc).unwrap();
    let sim = Simulation::<2>::new(problem.clone(), SolverSettings::default()).unwrap();
    let mesh = &sim.mesh;
    let f = initial_fields(&problem, mesh).unwrap();
    let (np, nc) = (mesh.nodes.len(), mesh.n_cells());
    assert_eq!((f.n, f.t), (0, 0.0));
    assert_eq!(
        f.u.as_ref(),
        Some(&sim.state.u),
        "u_0 as the run starts from it"
    );
    assert_eq!(
        f.zeta.as_ref(),
        Some(&sim.state.zeta),
        "ζ_0 as the run starts from it"
    );
    assert_eq!(f.w.as_ref(), Some(&vec![0.0; 2 * np]));
    assert!(
        f.contact.is_none(),
        "no contact state before the first step"
    );

    let doc = render(mesh, &f);
    let xml = parse_xml(&doc);
    let root = xml.root_element();
    check_grid(root, mesh, &f);
    let piece = root.child("UnstructuredGrid").child("Piece");
    let pd = piece.child("PointData");
    let u = f64s(pd.array("u"), np, 3);
    for (p, u) in mesh.nodes.iter().zip(u.chunks_exact(3)) {
        let exact = [a * p[0] + b * p[1], c * p[0] + d * p[1], 0.0];
        for (got, want) in u.iter().zip(exact) {
            assert!((got - want).abs() <= 1e-15, "u at {p:?}: {u:?}");
        }
    }
    assert!(f64s(pd.array("w"), np, 3).iter().all(|&w| w == 0.0));
    assert!(f64s(pd.array("zeta"), np, 1).iter().all(|&z| z == zeta0));

    let (exx, eyy, exy) = (a, d, 0.5 * (b + c));
    let tr = exx + eyy;
    let xx = zeta0 * (2.0 * mu * exx + lambda * tr);
    let yy = zeta0 * (2.0 * mu * eyy + lambda * tr);
    let xy = zeta0 * 2.0 * mu * exy;
    let expected = [xx, yy, 0.0, xy, 0.0, 0.0];
    let cd = piece.child("CellData");
    let sigma = sigma_tensor(cd, nc);
    for (e, s) in sigma.chunks_exact(6).enumerate() {
        for (i, (got, want)) in s.iter().zip(expected).enumerate() {
            assert!(
                (got - want).abs() <= 1e-12,
                "triangle {e}, component {i}: {got} ≠ {want} ({s:?})"
            );
        }
        assert_eq!([s[2], s[4], s[5]], [0.0; 3], "plane model: no zz, yz, xz");
    }
    // Von Mises of the plane tensor, (3/2 σ^D:σ^D)^½ with the 2D deviator.
    let half = 0.5 * (xx - yy);
    let vm = (1.5 * (2.0 * half * half + 2.0 * xy * xy)).sqrt();
    for v in f64s(cd.array("von_mises"), nc, 1) {
        assert!((v - vm).abs() <= 1e-12, "von Mises {v} ≠ {vm}");
    }
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
    if let Some(Stress::Plane(s)) = sigma.sigma.as_mut() {
        s.pop();
    }
    bad.push(sigma);
    let mut vm = good.clone();
    vm.von_mises = Some(Vec::new());
    bad.push(vm);
    for f in &bad {
        let mut buf = Vec::new();
        let err = write_vtu(
            &mut buf,
            &mesh.nodes,
            mesh.cells_flat(),
            f,
            Compression::Zlib,
        )
        .unwrap_err();
        assert_eq!(err.kind(), io::ErrorKind::InvalidInput, "{err}");
        assert!(buf.is_empty(), "nothing is written for invalid input");
    }
    let mut triangles = mesh.cells_flat().to_vec();
    triangles[3 * 3 + 1] = mesh.nodes.len();
    let mut buf = Vec::new();
    let err = write_vtu(&mut buf, &mesh.nodes, &triangles, &good, Compression::Zlib).unwrap_err();
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
    let xml = parse_xml(&doc);
    let root = xml.root_element();
    assert_eq!(root.tag_name().name(), "VTKFile");
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
        assert!(!set.has_children());
    }

    let mut buf = Vec::new();
    write_pvd(&mut buf, &[]).unwrap();
    let xml = parse_xml(std::str::from_utf8(&buf).unwrap());
    assert!(xml.root_element().child("Collection").elements().is_empty());

    let mut buf = Vec::new();
    let err = write_pvd(&mut buf, &[(0.0, "bell\u{7}.vtu".to_string())]).unwrap_err();
    assert_eq!(err.kind(), io::ErrorKind::InvalidInput);
    assert!(buf.is_empty());
}

/// The reader these checks rest on rejects what is not well-formed, so a document that reads
/// back is one ParaView's XML parser accepts too.
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
        assert!(Document::parse(bad).is_err(), "accepted {bad:?}");
    }
    let xml = parse_xml("<?xml version=\"1.0\"?>\n<a x=\"&lt;&#38;\"><b/>t&amp;</a>\n");
    let ok = xml.root_element();
    assert_eq!(ok.attr("x"), "<&");
    assert_eq!(ok.text_content(), "t&");
    assert_eq!(ok.child("b").tag_name().name(), "b");
}
