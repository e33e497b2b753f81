//! P1 elements on unstructured meshes (a polygon meshed in-process, refined red): the patch
//! test (a linear velocity is reproduced exactly) and a manufactured solution whose error
//! |w − w_h|_V = ‖ε(w − w_h)‖_L2 halves with h (order 1), for the operator
//! (A ε(w), ε(v)) = (f, v) of (3.13) with A(τ) = 2η τ + ξ tr(τ) I and w = w* on ∂Ω.

use contact_core::expr::Expr;
use contact_core::fem::{assembly, loads, DofMap, Geometry};
use contact_core::linalg::{Cholesky, Csr};
use contact_core::mesh::{polygon, Mesh};
use contact_core::problem::{ScalarField, VectorField};

const ETA: f64 = 1.0;
const XI: f64 = 0.5;

/// The L-bracket with a square hole, meshed at h = 1/4 (the coarsest level).
fn bracket() -> Mesh {
    let outer = [
        [0.0, 0.0],
        [2.0, 0.0],
        [2.0, 0.5],
        [1.0, 0.5],
        [1.0, 1.0],
        [0.0, 1.0],
    ];
    let hole = vec![[0.3, 0.3], [0.6, 0.3], [0.6, 0.6], [0.3, 0.6]];
    let t = polygon::triangulate(&outer, &[hole], 0.25, 100_000).unwrap();
    Mesh::from_cells(t.nodes, t.triangles.concat()).unwrap()
}

/// Solves (A ε(w_h), ε(v)) = (f, v) with w_h = w* at the boundary nodes.
fn solve(mesh: &Mesh, f: &VectorField, exact: impl Fn([f64; 2]) -> [f64; 2]) -> Vec<f64> {
    let geo = Geometry::new(mesh);
    let all = DofMap::all_free(mesh);
    let k = assembly::viscous_stiffness(mesh, &geo, &all, ETA, XI);
    let mut rhs = vec![0.0; 2 * mesh.n_nodes()];
    loads::add_body_force(mesh, &geo, f, 0.0, &mut rhs);
    let mut boundary = vec![false; mesh.n_nodes()];
    mesh.facets
        .iter()
        .flat_map(|f| f.nodes)
        .for_each(|i| boundary[i] = true);
    let mut w = vec![0.0; 2 * mesh.n_nodes()];
    for (i, p) in mesh.nodes.iter().enumerate().filter(|(i, _)| boundary[*i]) {
        let v = exact(*p);
        w[2 * i] = v[0];
        w[2 * i + 1] = v[1];
    }
    // Interior numbering, and the right-hand side minus the boundary values' contribution.
    let mut index = vec![usize::MAX; 2 * mesh.n_nodes()];
    let mut n = 0;
    for d in 0..2 * mesh.n_nodes() {
        if !boundary[d / 2] {
            index[d] = n;
            n += 1;
        }
    }
    let mut kw = vec![0.0; w.len()];
    k.mul_vec(&w, &mut kw);
    let mut b = vec![0.0; n];
    let mut t = Vec::new();
    for r in 0..w.len() {
        if index[r] == usize::MAX {
            continue;
        }
        b[index[r]] = rhs[r] - kw[r];
        for j in k.indptr[r]..k.indptr[r + 1] {
            let c = k.indices[j];
            if index[c] != usize::MAX {
                t.push((index[r], index[c], k.values[j]));
            }
        }
    }
    let kii = Csr::from_triplets(n, n, t);
    let mut chol = Cholesky::new(kii.lower_csc().as_ref()).unwrap();
    chol.solve_in_place(&mut b);
    for d in 0..w.len() {
        if index[d] != usize::MAX {
            w[d] = b[index[d]];
        }
    }
    w
}

/// ‖ε(w*) − ε(w_h)‖_L2 with ε(w*) given pointwise (exact for linear ε(w*) by the
/// edge-midpoint rule).
fn strain_error(mesh: &Mesh, w: &[f64], eps: impl Fn([f64; 2]) -> [f64; 3]) -> f64 {
    let geo = Geometry::new(mesh);
    let mut sum = 0.0;
    for (e, tri) in mesh.triangles().iter().enumerate() {
        let h = geo.strain(mesh, e, w);
        for a in 0..3 {
            let (p, q) = (mesh.nodes[tri[a]], mesh.nodes[tri[(a + 1) % 3]]);
            let x = eps([0.5 * (p[0] + q[0]), 0.5 * (p[1] + q[1])]);
            let d = [x[0] - h[(0, 0)], x[1] - h[(1, 1)], x[2] - h[(0, 1)]];
            sum += geo.measure[e] / 3.0 * (d[0] * d[0] + d[1] * d[1] + 2.0 * d[2] * d[2]);
        }
    }
    sum.sqrt()
}

fn field(fx: &str, fy: &str) -> VectorField {
    VectorField::plane(
        ScalarField::Expr(Expr::parse(fx).unwrap()),
        ScalarField::Expr(Expr::parse(fy).unwrap()),
    )
}

#[test]
fn patch_test_a_linear_velocity_is_exact_on_an_unstructured_mesh() {
    let mesh = bracket().refine();
    let exact = |p: [f64; 2]| [0.1 * p[0] + 0.3 * p[1] + 0.2, -0.2 * p[0] + 0.05 * p[1]];
    let w = solve(&mesh, &VectorField::constant([0.0, 0.0]), exact);
    for (i, p) in mesh.nodes.iter().enumerate() {
        let v = exact(*p);
        assert!((w[2 * i] - v[0]).abs() < 1e-12 && (w[2 * i + 1] - v[1]).abs() < 1e-12);
    }
    let err = strain_error(&mesh, &w, |_| [0.1, 0.05, 0.5 * (0.3 - 0.2)]);
    assert!(err < 1e-12, "{err}");
}

#[test]
fn manufactured_solution_converges_at_order_one() {
    // w* = (x²y, xy²): ε = [[2xy, (x²+y²)/2], [(x²+y²)/2, 2xy]], f = −div σ = −(6η + 4ξ)(y, x).
    let c = 6.0 * ETA + 4.0 * XI;
    let f = field(&format!("-{c}*y"), &format!("-{c}*x"));
    let exact = |p: [f64; 2]| [p[0] * p[0] * p[1], p[0] * p[1] * p[1]];
    let eps = |p: [f64; 2]| {
        let (x, y) = (p[0], p[1]);
        [2.0 * x * y, 2.0 * x * y, 0.5 * (x * x + y * y)]
    };
    let mut mesh = bracket();
    let mut errors = Vec::new();
    for _ in 0..4 {
        let w = solve(&mesh, &f, exact);
        errors.push(strain_error(&mesh, &w, eps));
        mesh = mesh.refine();
    }
    let orders: Vec<f64> = errors.windows(2).map(|e| (e[0] / e[1]).log2()).collect();
    eprintln!("errors {errors:?}, orders {orders:?}");
    assert!(
        orders.iter().all(|&o| (0.9..1.2).contains(&o)),
        "orders {orders:?}"
    );
}
