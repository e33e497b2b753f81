//! A mesh written as a gmsh MSH 2.2 ASCII file, which [`super::import`] (and gmsh, meshio,
//! ParaView) read back: the mesh an adaptive study ends on is downloaded this way, and a scene
//! can run on it again as on any uploaded mesh.
//!
//! - `$PhysicalNames`: the facet groups, tags 1, 2, … in [`Mesh::groups`] order, and the
//!   cells' group `body` (dimension D) after them;
//! - `$Nodes`: tags 1..N in node order, z = 0 in 2D;
//! - `$Elements`: the cells (triangles, type 2, or tetrahedra, type 4) in cell order, then each
//!   group's facets (lines, type 1, or triangles, type 2) with its physical tag; a facet in
//!   two groups is written once per group, as gmsh does.
//!
//! Coordinates are written with Rust's shortest round-trip formatting, so the nodes read
//! back are bit for bit the nodes written.

use super::{AnyMesh, Mesh};
use std::fmt::Write as _;

/// [`msh`] of a mesh of either dimension.
pub fn any_msh(mesh: &AnyMesh) -> String {
    match mesh {
        AnyMesh::Plane(m) => msh(m),
        AnyMesh::Solid(m) => msh(m),
    }
}

/// The MSH 2.2 ASCII text of `mesh` (module doc).
pub fn msh<const D: usize>(mesh: &Mesh<D>) -> String {
    let mut s = String::new();
    let body = mesh.groups.len() + 1;
    s.push_str("$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$PhysicalNames\n");
    let _ = writeln!(s, "{}", body);
    for (i, g) in mesh.groups.iter().enumerate() {
        let _ = writeln!(s, "{} {} \"{}\"", D - 1, i + 1, g.name.replace('"', "'"));
    }
    let _ = writeln!(s, "{D} {body} \"body\"\n$EndPhysicalNames\n$Nodes");
    let _ = writeln!(s, "{}", mesh.n_nodes());
    for (i, p) in mesh.nodes.iter().enumerate() {
        let z = if D == 3 { p[2] } else { 0.0 };
        let _ = writeln!(s, "{} {:?} {:?} {:?}", i + 1, p[0], p[1], z);
    }
    s.push_str("$EndNodes\n$Elements\n");
    let facets: usize = mesh.groups.iter().map(|g| g.facets.len()).sum();
    let _ = writeln!(s, "{}", mesh.n_cells() + facets);
    let (cell_type, facet_type) = if D == 2 { (2, 1) } else { (4, 2) };
    let mut id = 0;
    let mut element = |s: &mut String, kind: usize, tag: usize, nodes: &[usize]| {
        id += 1;
        let _ = write!(s, "{id} {kind} 2 {tag} {tag}");
        for &n in nodes {
            let _ = write!(s, " {}", n + 1);
        }
        s.push('\n');
    };
    for c in mesh.cells() {
        element(&mut s, cell_type, body, c);
    }
    for (i, g) in mesh.groups.iter().enumerate() {
        for &f in &g.facets {
            element(&mut s, facet_type, i + 1, &mesh.facets[f].nodes);
        }
    }
    s.push_str("$EndElements\n");
    s
}

#[cfg(test)]
mod tests {
    use super::msh;
    use crate::mesh::bisect::Bisection;
    use crate::mesh::import::import;
    use crate::mesh::{Mesh, MeshPattern};

    /// Nodes bit for bit, cells in order, the groups' facets as sets of node sets.
    fn assert_round_trip<const D: usize>(mesh: &Mesh<D>) {
        let back: Mesh<D> = import(msh(mesh).as_bytes()).unwrap();
        assert_eq!(back.nodes, mesh.nodes);
        assert!(back.cells().eq(mesh.cells()));
        assert_eq!(back.facets.len(), mesh.facets.len());
        let key = |m: &Mesh<D>, f: usize| {
            let mut k = m.facets[f].nodes;
            k.sort_unstable();
            k
        };
        assert_eq!(back.groups.len(), mesh.groups.len());
        for (a, b) in mesh.groups.iter().zip(&back.groups) {
            assert_eq!(a.name, b.name);
            let mut fa: Vec<_> = a.facets.iter().map(|&f| key(mesh, f)).collect();
            let mut fb: Vec<_> = b.facets.iter().map(|&f| key(&back, f)).collect();
            fa.sort_unstable();
            fb.sort_unstable();
            assert_eq!(fa, fb, "group {}", a.name);
        }
    }

    #[test]
    fn a_bisected_plate_with_groups_reads_back_as_written() {
        let mesh: Mesh<2> =
            import(include_bytes!("../../preset-meshes/plate-with-hole.msh")).unwrap();
        assert!(!mesh.groups.is_empty());
        let mut b = Bisection::new(&mesh);
        b.refine(&[0, 3, 7]);
        assert_round_trip(b.mesh());
    }

    #[test]
    fn a_bisected_box_reads_back_as_written() {
        let mut b = Bisection::new(&Mesh::cuboid(1.0, 1.0, 1.0, 2, 2, 2));
        b.refine(&[0, 5]);
        assert_round_trip(b.mesh());
        assert_round_trip(&Mesh::rectangle(2.0, 1.0, 3, 2, MeshPattern::Diagonal));
    }
}
