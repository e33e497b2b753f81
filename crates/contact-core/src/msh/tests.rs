use super::*;
use proptest::prelude::*;
use std::f64::consts::PI;

/// A test file: the presets' meshes, else the reader's own test files.
fn mesh_file(name: &str) -> Vec<u8> {
    let core = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let path = core.join("preset-meshes").join(name);
    let path = if path.exists() {
        path
    } else {
        core.join("tests/meshes").join(name)
    };
    std::fs::read(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

fn read_file(name: &str) -> MshMesh {
    read(&mesh_file(name)).unwrap_or_else(|e| panic!("{name}: {e}"))
}

/// The four numbers after `$Nodes` or `$Elements` in an ASCII file.
fn header(text: &str, section: &str) -> Vec<u64> {
    let rest = text.split(section).nth(1).unwrap();
    rest.split_whitespace()
        .take(4)
        .map(|t| t.parse().unwrap())
        .collect()
}

fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn signed_measure(m: &MshMesh, cell: &[usize]) -> f64 {
    let p = |i: usize| m.nodes[cell[i]];
    let a = sub(p(1), p(0));
    let b = sub(p(2), p(0));
    if m.dim == 2 {
        (a[0] * b[1] - a[1] * b[0]) / 2.0
    } else {
        let c = sub(p(3), p(0));
        (a[0] * (b[1] * c[2] - b[2] * c[1]) - a[1] * (b[0] * c[2] - b[2] * c[0])
            + a[2] * (b[0] * c[1] - b[1] * c[0]))
            / 6.0
    }
}

/// All cells have a nonzero measure of one sign (a consistently oriented mesh); the total
/// measure.
fn total_measure(m: &MshMesh) -> f64 {
    let signed: Vec<f64> = m.cells().map(|c| signed_measure(m, c)).collect();
    let sign = signed[0].signum();
    for (i, s) in signed.iter().enumerate() {
        assert!(
            s * sign > 0.0,
            "cell {i} has measure {s}, cell 0 {}",
            signed[0]
        );
    }
    signed.iter().map(|s| s.abs()).sum()
}

/// The file's counts: nodes as declared, and every element is a cell or a facet of exactly one
/// group (the generator saves only the physical groups' elements, each in one group).
fn check_counts(m: &MshMesh, name: &str) {
    let text = String::from_utf8(mesh_file(name)).unwrap();
    assert_eq!(m.nodes.len() as u64, header(&text, "$Nodes")[1]);
    assert_eq!(m.node_tags.len(), m.nodes.len());
    let facets: usize = m.groups.iter().map(FacetGroup::len).sum();
    assert_eq!(
        (m.cell_count() + facets) as u64,
        header(&text, "$Elements")[1]
    );
    assert!(m.cell_nodes.iter().all(|&i| i < m.nodes.len()));
}

/// Every facet of the group is a face of exactly one cell.
fn check_boundary(m: &MshMesh) {
    let mut faces: HashMap<Vec<usize>, usize> = HashMap::new();
    for c in m.cells() {
        for skip in 0..c.len() {
            let mut f: Vec<usize> = (0..c.len()).filter(|&j| j != skip).map(|j| c[j]).collect();
            f.sort_unstable();
            *faces.entry(f).or_default() += 1;
        }
    }
    for g in &m.groups {
        assert!(!g.is_empty());
        for f in g.facets() {
            let mut f = f.to_vec();
            f.sort_unstable();
            assert_eq!(faces.get(&f), Some(&1), "group {:?}: facet {f:?}", g.name);
        }
    }
}

fn group_nodes<'m>(m: &'m MshMesh, name: &str) -> impl Iterator<Item = [f64; 3]> + 'm {
    let g = m.group(name).unwrap_or_else(|| panic!("no group {name}"));
    g.facet_nodes.iter().map(|&i| m.nodes[i])
}

fn names(m: &MshMesh) -> Vec<(i32, &str)> {
    m.groups
        .iter()
        .map(|g| (g.tag, g.name.as_deref().unwrap()))
        .collect()
}

#[test]
fn the_plate_with_a_hole_reads_back() {
    let m = read_file("plate-with-hole.msh");
    assert_eq!(m.dim, 2);
    assert_eq!(
        names(&m),
        [
            (1, "clamped"),
            (2, "contact"),
            (3, "traction"),
            (4, "free"),
            (5, "hole")
        ]
    );
    assert!(m
        .physical_names
        .iter()
        .any(|n| n.dim == 2 && n.name == "body"));
    check_counts(&m, "plate-with-hole.msh");
    check_boundary(&m);
    assert!(group_nodes(&m, "clamped").all(|p| p[0] == 0.0));
    assert!(group_nodes(&m, "contact").all(|p| p[1] == 0.0));
    assert!(group_nodes(&m, "traction").all(|p| p[1] == 1.0));
    assert!(group_nodes(&m, "free").all(|p| p[0] == 2.0));
    assert!(group_nodes(&m, "hole").all(|p| ((p[0] - 0.7).hypot(p[1] - 0.45) - 0.2).abs() < 1e-12));
    // The hole is an inscribed polygon: the plate is a little larger than 2 − π r².
    let excess = total_measure(&m) - (2.0 - PI * 0.04);
    assert!((0.0..2e-3).contains(&excess), "area excess {excess}");
}

/// gmsh writes ASCII coordinates with 16 significant digits, so they may differ from the
/// binary ones in the last bit; everything else is identical.
#[test]
fn the_binary_plate_equals_the_ascii_plate() {
    let binary = read_file("plate-with-hole-binary.msh");
    let ascii = read_file("plate-with-hole.msh");
    assert_eq!(binary.nodes.len(), ascii.nodes.len());
    for (b, a) in binary.nodes.iter().zip(&ascii.nodes) {
        for k in 0..3 {
            assert!((b[k] - a[k]).abs() <= 4.0 * f64::EPSILON, "{b:?} {a:?}");
        }
    }
    assert_eq!(
        MshMesh {
            nodes: ascii.nodes.clone(),
            ..binary
        },
        ascii
    );
}

#[test]
fn the_arch_reads_back() {
    let m = read_file("arch-on-support.msh");
    assert_eq!(m.dim, 2);
    assert_eq!(
        names(&m),
        [
            (1, "clamped"),
            (2, "contact"),
            (3, "outer"),
            (4, "free-end")
        ]
    );
    check_counts(&m, "arch-on-support.msh");
    check_boundary(&m);
    assert!(group_nodes(&m, "contact").all(|p| (p[0].hypot(p[1]) - 1.0).abs() < 1e-12));
    assert!(group_nodes(&m, "clamped").all(|p| p[1] == 0.0 && (1.0..=1.5).contains(&p[0])));
    let exact = PI / 3.0 * (1.5f64.powi(2) - 1.0);
    let area = total_measure(&m);
    assert!(
        (area / exact - 1.0).abs() < 5e-3,
        "area {area}, exact {exact}"
    );
}

#[test]
fn the_cylinder_reads_back() {
    let m = read_file("cylinder.msh");
    assert_eq!(m.dim, 3);
    assert_eq!(names(&m), [(1, "base"), (2, "top"), (3, "side")]);
    check_counts(&m, "cylinder.msh");
    check_boundary(&m);
    assert!(group_nodes(&m, "base").all(|p| p[2].abs() < 1e-12));
    assert!(group_nodes(&m, "top").all(|p| (p[2] - 1.0).abs() < 1e-12));
    assert!(group_nodes(&m, "side").all(|p| (p[0].hypot(p[1]) - 0.5).abs() < 1e-9));
    let exact = PI * 0.25;
    let volume = total_measure(&m);
    assert!(
        (volume / exact - 1.0).abs() < 0.03,
        "volume {volume}, exact {exact}"
    );
}

/// A unit square of two triangles with a named bottom edge.
const SQUARE: &str = "$MeshFormat
4.1 0 8
$EndMeshFormat
$PhysicalNames
2
1 1 \"bottom\"
2 2 \"body\"
$EndPhysicalNames
$Entities
0 1 1 0
1 0 0 0 1 0 0 1 1 0
1 0 0 0 1 1 0 1 2 0
$EndEntities
$Nodes
1 4 1 4
2 1 0 4
1
2
3
4
0 0 0
1 0 0
1 1 0
0 1 0
$EndNodes
$Elements
2 3 1 3
1 1 1 1
1 1 2
2 1 2 2
2 1 2 3
3 1 3 4
$EndElements
";

/// Writes binary MSH values in one byte order.
struct Binary {
    out: Vec<u8>,
    big_endian: bool,
}

impl Binary {
    fn raw(&mut self, mut le: Vec<u8>) -> &mut Self {
        if self.big_endian {
            le.reverse();
        }
        self.out.extend(le);
        self
    }
    fn text(&mut self, t: &str) -> &mut Self {
        self.out.extend_from_slice(t.as_bytes());
        self
    }
    fn ints(&mut self, v: &[i32]) -> &mut Self {
        v.iter().fold(self, |w, x| w.raw(x.to_le_bytes().to_vec()))
    }
    fn sizes(&mut self, v: &[u64]) -> &mut Self {
        v.iter().fold(self, |w, x| w.raw(x.to_le_bytes().to_vec()))
    }
    fn doubles(&mut self, v: &[f64]) -> &mut Self {
        v.iter().fold(self, |w, x| w.raw(x.to_le_bytes().to_vec()))
    }
}

/// [`SQUARE`] as a binary file in either byte order.
fn square_binary(big_endian: bool) -> Vec<u8> {
    let mut w = Binary {
        out: Vec::new(),
        big_endian,
    };
    w.text("$MeshFormat\n4.1 1 8\n").ints(&[1]);
    w.text("\n$EndMeshFormat\n$PhysicalNames\n2\n1 1 \"bottom\"\n2 2 \"body\"\n");
    w.text("$EndPhysicalNames\n$Entities\n")
        .sizes(&[0, 1, 1, 0]);
    for (max_y, physical) in [(0.0, 1), (1.0, 2)] {
        w.ints(&[1]).doubles(&[0.0, 0.0, 0.0, 1.0, max_y, 0.0]);
        w.sizes(&[1]).ints(&[physical]).sizes(&[0]);
    }
    w.text("\n$EndEntities\n$Nodes\n").sizes(&[1, 4, 1, 4]);
    w.ints(&[2, 1, 0]).sizes(&[4, 1, 2, 3, 4]);
    for p in [[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]] {
        w.doubles(&[p[0], p[1], 0.0]);
    }
    w.text("\n$EndNodes\n$Elements\n").sizes(&[2, 3, 1, 3]);
    w.ints(&[1, 1, 1]).sizes(&[1, 1, 1, 2]);
    w.ints(&[2, 1, 2]).sizes(&[2, 2, 1, 2, 3, 3, 1, 3, 4]);
    w.text("\n$EndElements\n");
    w.out
}

#[test]
fn binary_squares_of_both_byte_orders_read_as_the_ascii_square() {
    let ascii = read(SQUARE.as_bytes()).unwrap();
    assert_eq!(read(&square_binary(false)).unwrap(), ascii);
    assert_eq!(read(&square_binary(true)).unwrap(), ascii);
}

#[test]
fn every_truncation_of_the_binary_square_is_an_error() {
    for big_endian in [false, true] {
        let data = square_binary(big_endian);
        let complete = data.len() - 1;
        for len in 0..complete {
            assert!(read(&data[..len]).is_err(), "prefix of {len} bytes read");
        }
    }
}

fn square_with(from: &str, to: &str) -> Result<MshMesh, MshError> {
    assert!(SQUARE.contains(from));
    read(SQUARE.replacen(from, to, 1).as_bytes())
}

#[test]
fn a_small_square_reads_exactly() {
    let m = read(SQUARE.as_bytes()).unwrap();
    assert_eq!(m.dim, 2);
    assert_eq!(m.nodes[2], [1.0, 1.0, 0.0]);
    assert_eq!(m.node_tags, [1, 2, 3, 4]);
    assert_eq!(m.cell_nodes, [0, 1, 2, 0, 2, 3]);
    assert_eq!(m.groups.len(), 1);
    assert_eq!(m.groups[0].name.as_deref(), Some("bottom"));
    assert_eq!(m.groups[0].facet_nodes, [0, 1]);
    assert_eq!(total_measure(&m), 1.0);
}

#[test]
fn other_versions_are_refused_by_name() {
    for v in ["2.1", "3.0", "4.0", "4.2"] {
        let e = square_with("4.1 0 8", &format!("{v} 0 8")).unwrap_err();
        assert_eq!(e, MshError::UnsupportedVersion(v.into()));
        assert!(e.to_string().contains("2.2") && e.to_string().contains("4.1"));
    }
    assert_eq!(read(b"solid x\n").unwrap_err(), MshError::NotMsh);
    for header in ["4.1 0 999", "4.1 1 0", "4.1 2 8", "4.1 0 -8"] {
        let e = square_with("4.1 0 8", header).unwrap_err();
        assert!(
            matches!(e, MshError::BadHeader { .. } | MshError::Syntax { .. }),
            "{header}: {e}"
        );
    }
}

#[test]
fn bad_content_is_named() {
    let e = square_with("\n1 1 0\n0 1 0\n", "\n1 nan 0\n0 1 0\n").unwrap_err();
    assert!(matches!(e, MshError::NonFinite { node: 3, .. }), "{e}");
    assert!(e.to_string().contains("line 23"), "{e}");
    let e = square_with("0 1 0\n$End", "0 inf 0\n$End").unwrap_err();
    assert!(matches!(e, MshError::NonFinite { node: 4, .. }), "{e}");
    let e = square_with("3 1 3 4", "3 1 3 9").unwrap_err();
    assert_eq!(
        e,
        MshError::MissingNode {
            element: 3,
            node: 9
        }
    );
    let e = square_with("\n1 1 0\n0 1 0\n", "\n1 1 0.5\n0 1 0\n").unwrap_err();
    assert!(matches!(e, MshError::NotPlanar { node: 3, .. }), "{e}");
    let e = square_with("1 4 1 4\n", "1 3 1 4\n").unwrap_err();
    assert!(matches!(e, MshError::BadCount { .. }), "{e}");
    let quads = SQUARE
        .replace("2 3 1 3\n", "2 2 1 3\n")
        .replace("2 1 2 2\n2 1 2 3\n3 1 3 4", "2 1 3 1\n2 1 2 3 4");
    let e = read(quads.as_bytes()).unwrap_err();
    assert!(
        matches!(
            e,
            MshError::UnsupportedElementType {
                element_type: 3,
                ..
            }
        ),
        "{e}"
    );
    let e = square_with("2 1 2 2", "2 1 99 2").unwrap_err();
    assert!(
        matches!(
            e,
            MshError::UnknownElementType {
                element_type: 99,
                ..
            }
        ),
        "{e}"
    );
    let e = square_with("2 1 2 2", "2 7 2 2").unwrap_err();
    assert!(
        matches!(e, MshError::MissingEntity { dim: 2, tag: 7, .. }),
        "{e}"
    );
    let e = square_with("3\n4\n0 0 0", "3\n3\n0 0 0").unwrap_err();
    assert!(matches!(e, MshError::DuplicateNode { node: 3, .. }), "{e}");
    let e = square_with("$EndNodes", "$EndNode").unwrap_err();
    assert!(matches!(e, MshError::Syntax { .. }), "{e}");
    let e = square_with("\"body\"", "body").unwrap_err();
    assert!(matches!(e, MshError::Syntax { .. }), "{e}");
}

#[test]
fn huge_counts_are_refused_before_allocating() {
    for (from, to) in [
        ("1 4 1 4\n", "1 18446744073709551615 1 4\n"),
        ("1 4 1 4\n", "1 1000000000000 1 4\n"),
        ("2 1 0 4\n", "2 1 0 100000000\n"),
        ("2 3 1 3\n", "99999999999 3 1 3\n"),
        ("0 1 1 0\n", "0 1 1000000000 0\n"),
        ("$PhysicalNames\n2\n", "$PhysicalNames\n1000000\n"),
    ] {
        let e = square_with(from, to).unwrap_err();
        assert!(matches!(e, MshError::HugeCount { .. }), "{to}: {e}");
    }
    let e = square_with("2 1 0 4\n", "2 1 0 -1\n").unwrap_err();
    assert!(matches!(e, MshError::Syntax { .. }), "{e}");
}

#[test]
fn huge_binary_counts_are_refused_before_allocating() {
    let data = mesh_file("plate-with-hole-binary.msh");
    let nodes = data.windows(7).position(|w| w == b"$Nodes\n").unwrap() + 7;
    let elements = data.windows(10).position(|w| w == b"$Elements\n").unwrap() + 10;
    for at in [nodes, nodes + 8, elements, elements + 8] {
        for count in [u64::MAX, 1 << 40, 1 << 20] {
            let mut bad = data.clone();
            bad[at..at + 8].copy_from_slice(&count.to_le_bytes());
            let e = read(&bad).unwrap_err();
            assert!(matches!(e, MshError::HugeCount { .. }), "{at} {count}: {e}");
        }
    }
}

#[test]
fn a_million_physical_groups_are_refused() {
    let mut names = String::from("$PhysicalNames\n1000000\n");
    for i in 1..=1_000_000 {
        names.push_str(&format!("1 {i} \"g{i}\"\n"));
    }
    let e = square_with("$PhysicalNames\n2\n", &names).unwrap_err();
    assert!(
        matches!(
            e,
            MshError::TooMany {
                limit: MAX_PHYSICAL_GROUPS,
                ..
            }
        ),
        "{e}"
    );
}

#[test]
fn every_truncation_of_the_square_is_an_error() {
    let data = SQUARE.as_bytes();
    let complete = SQUARE.find("$EndElements").unwrap() + "$EndElements".len();
    for len in 0..data.len() {
        match read(&data[..len]) {
            Ok(_) => assert!(len >= complete, "prefix of {len} bytes read"),
            Err(e) => assert!(len < complete, "{len}: {e}"),
        }
    }
}

#[test]
fn truncations_of_the_binary_plate_are_errors() {
    let data = mesh_file("plate-with-hole-binary.msh");
    let end = data.len() - "$EndElements\n".len();
    for len in (0..end).step_by(97).chain(end - 40..end) {
        let e = read(&data[..len]).unwrap_err();
        assert!(!e.to_string().is_empty());
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 1024, ..ProptestConfig::default() })]

    #[test]
    fn mutated_squares_never_panic(
        edits in prop::collection::vec((any::<prop::sample::Index>(), any::<u8>()), 1..6)
    ) {
        let mut data = SQUARE.as_bytes().to_vec();
        for (at, byte) in edits {
            let i = at.index(data.len());
            data[i] = byte;
        }
        let _ = read(&data);
    }

    #[test]
    fn mutated_binary_plates_never_panic(
        edits in prop::collection::vec((any::<prop::sample::Index>(), any::<u8>()), 1..6),
        cut in any::<prop::sample::Index>(),
    ) {
        let mut data = mesh_file("plate-with-hole-binary.msh");
        for (at, byte) in edits {
            let i = at.index(data.len());
            data[i] = byte;
        }
        let _ = read(&data);
        let _ = read(&data[..cut.index(data.len())]);
    }

    #[test]
    fn mutated_tokens_never_panic(
        line in any::<prop::sample::Index>(),
        token in "[-+0-9eE.$\"a-z]{0,25}",
    ) {
        let lines: Vec<&str> = SQUARE.lines().collect();
        let i = line.index(lines.len());
        let mut edited = lines.clone();
        edited[i] = &token;
        let _ = read(edited.join("\n").as_bytes());
    }
}

/// [`SQUARE`] in MSH 2.2: the bottom edge in group 1, both triangles in group 2, the second
/// triangle also in group 3 (so written twice, as gmsh does).
const SQUARE_22: &str = "$MeshFormat
2.2 0 8
$EndMeshFormat
$PhysicalNames
2
1 1 \"bottom\"
2 2 \"body\"
$EndPhysicalNames
$Nodes
4
1 0 0 0
2 1 0 0
3 1 1 0
4 0 1 0
$EndNodes
$Elements
4
1 1 2 1 1 1 2
2 2 2 2 1 1 2 3
3 2 2 2 1 1 3 4
4 2 2 3 1 1 3 4
$EndElements
";

/// [`SQUARE_22`] as a binary file in either byte order.
fn square_22_binary(big_endian: bool) -> Vec<u8> {
    let mut w = Binary {
        out: Vec::new(),
        big_endian,
    };
    w.text("$MeshFormat\n2.2 1 8\n").ints(&[1]);
    w.text("\n$EndMeshFormat\n$PhysicalNames\n2\n1 1 \"bottom\"\n2 2 \"body\"\n");
    w.text("$EndPhysicalNames\n$Nodes\n4\n");
    for (i, p) in [[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]]
        .iter()
        .enumerate()
    {
        w.ints(&[i as i32 + 1]).doubles(&[p[0], p[1], 0.0]);
    }
    w.text("\n$EndNodes\n$Elements\n4\n");
    w.ints(&[1, 1, 2]).ints(&[1, 1, 1, 1, 2]);
    w.ints(&[2, 3, 2]);
    w.ints(&[2, 2, 1, 1, 2, 3])
        .ints(&[3, 2, 1, 1, 3, 4])
        .ints(&[4, 3, 1, 1, 3, 4]);
    w.text("\n$EndElements\n");
    w.out
}

#[test]
fn msh22_squares_read_as_the_41_square() {
    let want = read(SQUARE.as_bytes()).unwrap();
    let ascii = read(SQUARE_22.as_bytes()).unwrap();
    // The same mesh; 2.2 has no entities, and the repeated triangle is one cell.
    assert_eq!(ascii, want);
    assert_eq!(read(&square_22_binary(false)).unwrap(), want);
    assert_eq!(read(&square_22_binary(true)).unwrap(), want);
}

#[test]
fn msh22_errors_are_named() {
    let e = read(
        SQUARE_22
            .replace("3 2 2 2 1 1 3 4", "3 2 2 2 1 1 3 9")
            .as_bytes(),
    )
    .unwrap_err();
    assert_eq!(
        e,
        MshError::MissingNode {
            element: 3,
            node: 9
        }
    );
    let e = read(SQUARE_22.replace("\n4 0 1 0", "\n3 0 1 0").as_bytes()).unwrap_err();
    assert!(matches!(e, MshError::DuplicateNode { node: 3, .. }), "{e}");
    let e = read(SQUARE_22.replace("2 1 0 0", "2 nan 0 0").as_bytes()).unwrap_err();
    assert!(matches!(e, MshError::NonFinite { node: 2, .. }), "{e}");
    let e = read(
        SQUARE_22
            .replace("2 2 2 2 1 1 2 3", "2 99 2 2 1 1 2 3")
            .as_bytes(),
    )
    .unwrap_err();
    assert!(
        matches!(
            e,
            MshError::UnknownElementType {
                element_type: 99,
                ..
            }
        ),
        "{e}"
    );
    let e = read(
        SQUARE_22
            .replace("$Nodes\n4\n", "$Nodes\n4000000000\n")
            .as_bytes(),
    )
    .unwrap_err();
    assert!(matches!(e, MshError::HugeCount { .. }), "{e}");
    let e = read(
        SQUARE_22
            .replace("2 2 2 2 1 1 2 3", "2 2 99999 2 1 1 2 3")
            .as_bytes(),
    )
    .unwrap_err();
    assert!(matches!(e, MshError::TooManyTags { element: 2, .. }), "{e}");
    // A quadrangle cell: refused by name, with how to export triangles.
    let quad = SQUARE_22
        .replace("$Elements\n4\n", "$Elements\n2\n")
        .replace(
            "2 2 2 2 1 1 2 3\n3 2 2 2 1 1 3 4\n4 2 2 3 1 1 3 4\n",
            "2 3 2 2 1 1 2 3 4\n",
        );
    let e = read(quad.as_bytes()).unwrap_err();
    assert!(
        matches!(
            e,
            MshError::UnsupportedElementType {
                element_type: 3,
                ..
            }
        ),
        "{e}"
    );
    assert!(e.to_string().contains("RecombineAll"), "{e}");
}

#[test]
fn every_truncation_of_the_msh22_squares_is_an_error() {
    let data = SQUARE_22.as_bytes();
    let complete = SQUARE_22.find("$EndElements").unwrap() + "$EndElements".len();
    for len in 0..data.len() {
        match read(&data[..len]) {
            Ok(_) => assert!(len >= complete, "prefix of {len} bytes read"),
            Err(e) => assert!(len < complete, "{len}: {e}"),
        }
    }
    for big_endian in [false, true] {
        let data = square_22_binary(big_endian);
        for len in 0..data.len() - 1 {
            assert!(read(&data[..len]).is_err(), "prefix of {len} bytes read");
        }
    }
}

/// gmsh's own MSH 2.2 copies of the plate (ASCII and binary) and of the cylinder (binary)
/// read as the 4.1 files: the same nodes, cells and groups, in the same order.
#[test]
fn gmsh_msh22_files_read_as_their_41_originals() {
    let plate = read_file("plate-with-hole.msh");
    for name in [
        "plate-with-hole-msh22.msh",
        "plate-with-hole-msh22-binary.msh",
    ] {
        assert_eq!(read_file(name), plate, "{name}");
    }
    assert_eq!(
        read_file("cylinder-msh22-binary.msh"),
        read_file("cylinder.msh")
    );
}

/// Files gmsh writes with second-order triangles or quadrangles: refused by type, naming the
/// gmsh option that exports first-order simplices.
#[test]
fn gmsh_second_order_and_quadrangle_files_are_refused_by_name() {
    let e = read(&mesh_file("square-order2-msh22.msh")).unwrap_err();
    assert!(
        matches!(
            e,
            MshError::UnsupportedElementType {
                element_type: 9,
                dim: 2,
                ..
            }
        ),
        "{e}"
    );
    assert!(
        e.to_string().contains("6-node second-order triangle"),
        "{e}"
    );
    assert!(e.to_string().contains("gmsh -order 1"), "{e}");
    let e = read(&mesh_file("square-quads.msh")).unwrap_err();
    assert!(
        matches!(
            e,
            MshError::UnsupportedElementType {
                element_type: 3,
                dim: 2,
                ..
            }
        ),
        "{e}"
    );
    assert!(e.to_string().contains("4-node quadrangle"), "{e}");
    assert!(e.to_string().contains("RecombineAll = 0"), "{e}");
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 512, ..ProptestConfig::default() })]

    #[test]
    fn mutated_msh22_files_never_panic(
        edits in prop::collection::vec((any::<prop::sample::Index>(), any::<u8>()), 1..6),
        binary in any::<bool>(),
    ) {
        let mut data = if binary { square_22_binary(false) } else { SQUARE_22.as_bytes().to_vec() };
        for (at, byte) in edits {
            let i = at.index(data.len());
            data[i] = byte;
        }
        let _ = read(&data);
    }
}
