//! The viscosity operator (A ε(w), ε(v)) = (f, v) of (3.13), A(τ) = 2η τ + ξ tr(τ) I, solved
//! with w = w* at every boundary node: what the patch tests and manufactured solutions of
//! tests/unstructured.rs (triangles) and tests/solid.rs (tetrahedra) compare with.

use contact_core::fem::{assembly, loads, DofMap, Geometry};
use contact_core::linalg::{Cholesky, Csr};
use contact_core::mesh::Mesh;
use contact_core::problem::VectorField;

/// w_h with (A ε(w_h), ε(v)) = (f, v) for every v vanishing on ∂Ω, w_h = w* at the boundary
/// nodes; D components per node, interleaved.
pub fn solve<const D: usize>(
    mesh: &Mesh<D>,
    (eta, xi): (f64, f64),
    f: &VectorField,
    exact: impl Fn([f64; D]) -> [f64; D],
) -> Vec<f64> {
    let geo = Geometry::new(mesh);
    let all = DofMap::all_free(mesh);
    let k = assembly::viscous_stiffness(mesh, &geo, &all, eta, xi);
    let nd = D * mesh.n_nodes();
    let mut rhs = vec![0.0; nd];
    loads::add_body_force(mesh, &geo, f, 0.0, &mut rhs);
    let mut boundary = vec![false; mesh.n_nodes()];
    mesh.facets
        .iter()
        .flat_map(|f| f.nodes)
        .for_each(|i| boundary[i] = true);
    let mut w = vec![0.0; nd];
    for (i, p) in mesh.nodes.iter().enumerate().filter(|(i, _)| boundary[*i]) {
        w[D * i..D * i + D].copy_from_slice(&exact(*p));
    }
    // Interior numbering, and the right-hand side minus the boundary values' contribution.
    let mut index = vec![usize::MAX; nd];
    let mut n = 0;
    for (d, slot) in index.iter_mut().enumerate() {
        if !boundary[d / D] {
            *slot = n;
            n += 1;
        }
    }
    let mut kw = vec![0.0; nd];
    k.mul_vec(&w, &mut kw);
    let mut b = vec![0.0; n];
    let mut t = Vec::new();
    for r in 0..nd {
        if index[r] == usize::MAX {
            continue;
        }
        b[index[r]] = rhs[r] - kw[r];
        for j in k.indptr[r]..k.indptr[r + 1] {
            let c = k.indices[j] as usize;
            if index[c] != usize::MAX {
                t.push((index[r], index[c], k.values[j]));
            }
        }
    }
    let kii = Csr::from_triplets(n, n, t);
    let mut chol = Cholesky::new(kii.lower_csc().as_ref()).unwrap();
    chol.solve_in_place(&mut b);
    for d in 0..nd {
        if index[d] != usize::MAX {
            w[d] = b[index[d]];
        }
    }
    w
}

/// R and t of tests/meshes/box-rotated.msh (copied from generate_box_rotated.py): the file's
/// nodes are R x + t for the nodes x of `Mesh::<3>::cuboid(2.0, 1.0, 1.0, 8, 4, 4)`.
// 17 significant digits, as written into the file: they round-trip to the same f64.
#[allow(clippy::excessive_precision)]
pub const BOX_ROTATION: [[f64; 3]; 3] = [
    [
        0.78163917390702509,
        -0.48292928421421222,
        0.39473979817379978,
    ],
    [
        0.55011723070435836,
        0.83203013377463464,
        -0.071392499417875857,
    ],
    [
        -0.29395787843858057,
        0.27295633888831428,
        0.91601506688731726,
    ],
];
