//! P1 elements on unstructured meshes (a polygon meshed in-process, refined red): the patch
//! test (a linear velocity is reproduced exactly) and a manufactured solution whose error
//! |w − w_h|_V = ‖ε(w − w_h)‖_L2 halves with h (order 1), for the operator
//! (A ε(w), ε(v)) = (f, v) of (3.13) with A(τ) = 2η τ + ξ tr(τ) I and w = w* on ∂Ω.

mod common;
use common::dirichlet;
use contact_core::expr::Expr;
use contact_core::fem::Geometry;
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
            sum += geo.measure(e) / 3.0 * (d[0] * d[0] + d[1] * d[1] + 2.0 * d[2] * d[2]);
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
    let w = dirichlet::solve(&mesh, (ETA, XI), &VectorField::constant([0.0, 0.0]), exact);
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
        let w = dirichlet::solve(&mesh, (ETA, XI), &f, exact);
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
