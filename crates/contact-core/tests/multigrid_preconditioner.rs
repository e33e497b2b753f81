//! The multigrid V-cycle (crate::linalg::multigrid) as a preconditioner: symmetric, exact on the near-nullspace, a contracting
//! two-grid method, and conjugate-gradient iteration counts that do not grow with 1/h.

use contact_core::fem::rigid_modes::{node_blocks, rigid_modes};
use contact_core::fem::{assembly, multilevel, DofMap, Geometry};
use contact_core::linalg::multigrid::prolongator::Prolongator;
use contact_core::linalg::multigrid::*;
use contact_core::linalg::pcg::Preconditioner;
use contact_core::linalg::pcg::{self, PcgWork};
use contact_core::linalg::Csr;
use contact_core::mesh::{Mesh, MeshPattern};
use contact_core::problem::BoundaryPart;
use contact_core::scene;
use std::sync::Arc;

/// The velocity operator of paper-convergence (Γ1 left, Γ3 bottom) at h = 1/n.
fn elasticity_2d(n: usize) -> (Arc<Csr>, Blocks, Vec<f64>) {
    let problem = preset("paper-convergence", n);
    let mesh: Mesh<2> = problem.mesh().unwrap();
    operator(&mesh, &problem.boundary)
}

fn operator<const D: usize>(
    mesh: &Mesh<D>,
    parts: &[BoundaryPart],
) -> (Arc<Csr>, Blocks, Vec<f64>) {
    let geo = Geometry::new(mesh);
    let dofs = DofMap::new(mesh, parts);
    let k = assembly::viscous_stiffness(mesh, &geo, &dofs, 2.0, 2.0);
    (
        Arc::new(k),
        node_blocks(mesh, &dofs),
        rigid_modes(mesh, &dofs),
    )
}

fn preset(name: &str, n: usize) -> contact_core::problem::Problem {
    let mut doc = scene::presets::get(name).expect("preset");
    let o = scene::Overrides {
        h: Some(format!("1/{n}").into()),
        k: Some("1/2".into()),
        t_end: None,
    };
    scene::apply_overrides(&mut doc, &o);
    scene::validate(&doc).expect("valid scene")
}

/// The Kuhn box [0,2]×[0,1]×[0,1] at h = 1/n, clamped at x = 0, Γ3 at z = 0.
fn elasticity_3d(n: usize) -> (Arc<Csr>, Blocks, Vec<f64>) {
    let problem = preset("box-exp3", n);
    let mesh: Mesh<3> = problem.mesh().unwrap();
    operator(&mesh, &problem.boundary)
}

/// The Dirichlet Laplacian plus a small mass on the unit square at h = 1/n.
fn laplacian(n: usize) -> Arc<Csr> {
    let mesh = Mesh::rectangle(1.0, 1.0, n, n, MeshPattern::Diagonal);
    let geo = Geometry::new(&mesh);
    let l = assembly::laplacian(&mesh, &geo);
    let m = assembly::mass(&mesh, &geo);
    Arc::new(assembly::combine(1.0, &l, 1e-3, &m))
}

fn aggregation(
    a: Arc<Csr>,
    blocks: Blocks,
    nullspace: Vec<f64>,
    k: usize,
    params: Params,
) -> Arc<Hierarchy> {
    Arc::new(Hierarchy::new(a, blocks, Coarsening::Aggregation { nullspace, k }, params).unwrap())
}

fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

fn pseudo_random(n: usize, seed: f64) -> Vec<f64> {
    (0..n)
        .map(|i| ((i as f64 + seed) * 12.9898).sin() * 43758.5453 % 1.0)
        .collect()
}

#[test]
fn v_cycle_is_symmetric() {
    let (a, blocks, modes) = elasticity_2d(32);
    let params = Params {
        coarse_size: 50,
        ..Params::default()
    };
    let h = aggregation(a.clone(), blocks, modes, 3, params);
    assert!(h.n_levels() >= 3, "levels {:?}", h.sizes());
    assert_symmetric_positive(&h, a.nrows);
}

/// xᵀ B y = yᵀ B x and xᵀ B x > 0 for one V-cycle B of `h` (n DOFs) and two vectors.
fn assert_symmetric_positive(h: &Arc<Hierarchy>, n: usize) {
    let mut b = h.vcycle();
    let (x, y) = (pseudo_random(n, 1.0), pseudo_random(n, 7.0));
    let (mut bx, mut by) = (vec![0.0; n], vec![0.0; n]);
    b.apply(&x, &mut bx);
    b.apply(&y, &mut by);
    let (l, r) = (dot(&y, &bx), dot(&x, &by));
    assert!((l - r).abs() <= 1e-12 * l.abs().max(r.abs()), "{l} vs {r}");
    assert!(dot(&x, &bx) > 0.0 && dot(&y, &by) > 0.0);
}

/// 3D elasticity aggregated on the distance-two graph has few enough coarse DOFs that the
/// first level restricts from P's rows by pieces instead of a stored Pᵀ: that restriction is
/// Pᵀ to rounding, and the V-cycle stays symmetric and positive. With mixed precision P is
/// held in f32 node blocks: its products are those of its entries in scalar CSR.
#[test]
fn v_cycle_restricting_by_pieces_is_symmetric() {
    let (a, blocks, modes) = elasticity_3d(12);
    for mixed in [false, true] {
        let params = Params {
            coarse_size: 200,
            mixed,
            ..Params::default()
        };
        let h = aggregation(a.clone(), blocks.clone(), modes.clone(), 6, params);
        assert!(h.restriction_scratch(0) > 0, "levels {:?}", h.sizes());
        let p = h.prolongator(0).unwrap();
        assert_eq!(matches!(p, Prolongator::Blocks(_)), mixed);
        let scalar = p.to_csr();
        let pt = contact_core::linalg::galerkin::transpose(&scalar);
        let n = a.nrows;
        let x = pseudo_random(n, 3.0);
        let (mut want, mut got) = (vec![0.0; p.ncols()], vec![f64::NAN; p.ncols()]);
        pt.mul_vec(&x, &mut want);
        h.restrict(0, &x, &mut got, &mut vec![0.0; h.restriction_scratch(0)]);
        let scale = want.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        assert!(want
            .iter()
            .zip(&got)
            .all(|(w, g)| (w - g).abs() <= 1e-13 * scale));
        let xc = pseudo_random(p.ncols(), 1.0);
        let (mut want, mut got) = (vec![0.0; n], vec![f64::NAN; n]);
        scalar.mul_vec(&xc, &mut want);
        p.mul_vec(&xc, &mut got);
        let scale = want.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        assert!(want
            .iter()
            .zip(&got)
            .all(|(w, g)| (w - g).abs() <= 1e-13 * scale));
        assert_symmetric_positive(&h, n);
    }
}

/// Below the geometric levels of box-exp3 (halved down to a few hundred nodes), a coarsest
/// level of more DOFs than the limit is aggregated further with the rigid modes at its nodes
/// (as a large base mesh refined is): more levels, a symmetric positive V-cycle, and CG with
/// it solves K to the residual asked for in as few iterations, within a few, as with the
/// coarsest level factored.
#[test]
fn geometric_levels_aggregate_below_a_large_coarsest_level() {
    let problem = preset("box-exp3", 16);
    let mesh: Mesh<3> = problem.mesh().unwrap();
    let geo = Geometry::new(&mesh);
    let dofs = DofMap::new(&mesh, &problem.boundary);
    let a = Arc::new(assembly::viscous_stiffness(&mesh, &geo, &dofs, 2.0, 2.0));
    let n = a.nrows;
    let blocks = node_blocks(&mesh, &dofs);
    let hierarchy = |factored: usize| {
        let coarsening =
            multilevel::geometric_velocity_factoring(&mesh, &dofs, n, factored).unwrap();
        let params = Params {
            coarse_size: 100,
            ..Params::default()
        };
        Arc::new(Hierarchy::new(a.clone(), blocks.clone(), coarsening, params).unwrap())
    };
    let (factored, aggregated) = (hierarchy(usize::MAX), hierarchy(100));
    assert_eq!(factored.kind(), "geometric");
    assert_eq!(aggregated.kind(), "geometric, then smoothed aggregation");
    assert!(
        aggregated.n_levels() > factored.n_levels(),
        "{:?} against {:?}",
        aggregated.sizes(),
        factored.sizes()
    );
    assert!(*aggregated.sizes().last().unwrap() < *factored.sizes().last().unwrap());
    assert_symmetric_positive(&aggregated, n);

    let (with_factor, below) = (
        pcg_iterations(a.clone(), &factored),
        pcg_iterations(a.clone(), &aggregated),
    );
    assert!(below <= with_factor + 4, "{below} against {with_factor}");
}

#[test]
fn tentative_prolongator_reproduces_the_near_nullspace() {
    for (a, blocks, modes, k) in [
        {
            let (a, b, m) = elasticity_2d(16);
            (a, b, m, 3)
        },
        {
            let (a, b, m) = elasticity_3d(4);
            (a, b, m, 6)
        },
    ] {
        let (ptr, list) = aggregation::strength(&a, &blocks, 0.08);
        let (agg, count) = aggregation::aggregates(&ptr, &list);
        assert!(count > 1 && count < blocks.len());
        let (t, _, coarse) = aggregation::tentative(&blocks, &agg, count, &modes, k);
        for m in 0..k {
            let bc: Vec<f64> = (0..t.ncols).map(|i| coarse[i * k + m]).collect();
            let mut tb = vec![0.0; t.nrows];
            t.mul_vec(&bc, &mut tb);
            for (i, v) in tb.iter().enumerate() {
                assert!((v - modes[i * k + m]).abs() < 1e-10, "mode {m} dof {i}");
            }
        }
        // Orthonormal columns: TᵀT = I.
        let tt = contact_core::linalg::galerkin::product(
            &contact_core::linalg::galerkin::transpose(&t),
            &t,
        );
        for r in 0..tt.nrows {
            for p in tt.indptr[r]..tt.indptr[r + 1] {
                let want = if tt.indices[p] as usize == r {
                    1.0
                } else {
                    0.0
                };
                assert!((tt.values[p] - want).abs() < 1e-12);
            }
        }
    }
}

/// ρ(I − B A) of the two-grid method (one level above a direct coarse solve), by power
/// iteration in the A norm.
fn two_grid_factor(h: &Arc<Hierarchy>) -> f64 {
    let a = h.operator().clone();
    let n = a.nrows;
    let mut b = h.vcycle();
    let mut e = pseudo_random(n, 3.0);
    let (mut ae, mut bae) = (vec![0.0; n], vec![0.0; n]);
    let mut rate = 0.0;
    let anorm = |e: &[f64], ae: &mut Vec<f64>| {
        a.mul_vec(e, ae);
        dot(e, ae).sqrt()
    };
    for _ in 0..25 {
        let before = anorm(&e, &mut ae);
        b.apply(&ae, &mut bae);
        e.iter_mut().zip(&bae).for_each(|(e, v)| *e -= v);
        let after = anorm(&e, &mut ae);
        rate = after / before;
        e.iter_mut().for_each(|v| *v /= after);
    }
    rate
}

/// Smoothed aggregation with a Chebyshev smoother of degree 3 over [λ/10, 1.1λ]: the
/// Laplacian's two-grid factor is below 0.2; elasticity's (aggregates of a whole
/// neighbourhood, 3 or 6 coarse DOFs each) stays near 0.3 at every size, which conjugate
/// gradients accelerate. With the finest graph squared (the default for 3D elasticity:
/// aggregates of a neighbourhood of neighbourhoods) the factor is larger (measured 0.40–0.43)
/// but bounded independently of h, on a coarse space at least twice smaller.
#[test]
fn two_grid_convergence_factor_is_small_at_three_sizes() {
    let two = |coarse: usize| Params {
        coarse_size: coarse,
        max_levels: 2,
        degree: 3,
        ratio: 10.0,
        square_finest: false,
        ..Params::default()
    };
    let squared = |coarse: usize| Params {
        square_finest: true,
        ..two(coarse)
    };
    for n in [16, 32, 64] {
        let h = aggregation(
            laplacian(n),
            Blocks::scalar((n + 1) * (n + 1)),
            vec![1.0; (n + 1) * (n + 1)],
            1,
            two(10),
        );
        let rho = two_grid_factor(&h);
        assert!(rho <= 0.2, "Laplacian 1/{n}: {rho}");
        let (a, blocks, modes) = elasticity_2d(n);
        let h = aggregation(a, blocks, modes, 3, two(10));
        let rho = two_grid_factor(&h);
        assert!(rho <= 0.35, "elasticity 1/{n}: {rho}");
    }
    for n in [2, 4, 6] {
        let (a, blocks, modes) = elasticity_3d(n);
        let plain = aggregation(a.clone(), blocks.clone(), modes.clone(), 6, two(10));
        let rho = two_grid_factor(&plain);
        assert!(rho <= 0.3, "3D elasticity 1/{n}: {rho}");
        let h = aggregation(a, blocks, modes, 6, squared(10));
        let rho = two_grid_factor(&h);
        assert!(rho <= 0.5, "squared, 3D elasticity 1/{n}: {rho}");
        if n > 2 {
            assert!(
                2 * h.sizes()[1] <= plain.sizes()[1],
                "squared, 3D elasticity 1/{n}: coarse sizes {:?} against {:?}",
                h.sizes(),
                plain.sizes()
            );
        }
    }
}

/// Geometric levels (the grid or box of 2h, Galerkin operators): the two-grid factors of
/// the Laplacian, of 2D elasticity in the rotated Γ3 frames and of the clamped Kuhn box at
/// three sizes each, with the default smoother (degree 2 over [λ/7, 1.1λ]: measured
/// 0.22, 0.43–0.44 and 0.45–0.46; the cheapest per step once CG accelerates it) and with
/// degree 5 over [λ/15, 1.1λ] (0.05, 0.19 and 0.21–0.22). The factors do not grow with 1/h.
#[test]
fn geometric_two_grid_factors_are_bounded_independently_of_h() {
    let default = Params {
        max_levels: 2,
        ..Params::default()
    };
    let strong = Params {
        degree: 5,
        ratio: 15.0,
        ..default
    };
    // (what, factors with the default smoother, with the strong one)
    let mut rows: Vec<(&str, Vec<f64>, Vec<f64>)> = vec![
        ("Laplacian", vec![], vec![]),
        ("2D elasticity", vec![], vec![]),
        ("3D elasticity", vec![], vec![]),
    ];
    let mut factors = |row: usize, a: Arc<Csr>, blocks: Blocks, c: Coarsening| {
        for (params, out) in [(default, 1), (strong, 2)] {
            let h = Hierarchy::new(a.clone(), blocks.clone(), c.clone(), params).unwrap();
            let rho = two_grid_factor(&Arc::new(h));
            if out == 1 {
                rows[row].1.push(rho);
            } else {
                rows[row].2.push(rho);
            }
        }
    };
    for n in [32, 64, 128] {
        let mesh = Mesh::rectangle(1.0, 1.0, n, n, MeshPattern::Diagonal);
        let c = multilevel::geometric_scalar(&mesh).expect("levels");
        factors(0, laplacian(n), Blocks::scalar(mesh.n_nodes()), c);
        let problem = preset("paper-convergence", n);
        let mesh: Mesh<2> = problem.mesh().unwrap();
        let (a, blocks, _) = operator(&mesh, &problem.boundary);
        let dofs = DofMap::new(&mesh, &problem.boundary);
        let c = multilevel::geometric_velocity(&mesh, &dofs, a.nrows).expect("levels");
        factors(1, a, blocks, c);
    }
    for n in [8, 12, 16] {
        let problem = preset("box-exp3", n);
        let mesh: Mesh<3> = problem.mesh().unwrap();
        let (a, blocks, _) = operator(&mesh, &problem.boundary);
        let dofs = DofMap::new(&mesh, &problem.boundary);
        let c = multilevel::geometric_velocity(&mesh, &dofs, a.nrows).expect("levels");
        factors(2, a, blocks, c);
    }
    let bounds = [(0.25, 0.1), (0.5, 0.2), (0.5, 0.25)];
    for ((what, by_default, by_strong), (b_default, b_strong)) in rows.iter().zip(bounds) {
        let max = |v: &[f64]| v.iter().fold(0.0f64, |m, &x| m.max(x));
        let min = |v: &[f64]| v.iter().fold(1.0f64, |m, &x| m.min(x));
        assert!(
            max(by_default) <= b_default,
            "{what}, degree 2: {by_default:?}"
        );
        assert!(
            max(by_strong) <= b_strong,
            "{what}, degree 5: {by_strong:?}"
        );
        assert!(
            max(by_default) <= 1.1 * min(by_default),
            "{what} grows with 1/h: {by_default:?}"
        );
    }
}

fn pcg_iterations(a: Arc<Csr>, h: &Arc<Hierarchy>) -> usize {
    let n = a.nrows;
    let b = pseudo_random(n, 5.0);
    let scale = b.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let mut x = vec![0.0; n];
    let rep = pcg::solve(
        &a,
        &mut h.vcycle(),
        &b,
        &mut x,
        1e-10 * scale,
        500,
        &mut PcgWork::default(),
    );
    assert!(rep.converged, "{rep:?}");
    rep.iterations
}

#[test]
fn iteration_counts_do_not_grow_with_refinement() {
    let params = Params {
        coarse_size: 200,
        ..Params::default()
    };
    let counts: Vec<usize> = [16, 32, 64, 128]
        .into_iter()
        .map(|n| {
            let (a, blocks, modes) = elasticity_2d(n);
            pcg_iterations(a.clone(), &aggregation(a, blocks, modes, 3, params))
        })
        .collect();
    assert!(
        counts[3] as f64 <= 1.5 * counts[0] as f64 + 2.0,
        "{counts:?}"
    );
    let counts3: Vec<usize> = [4, 8, 12]
        .into_iter()
        .map(|n| {
            let (a, blocks, modes) = elasticity_3d(n);
            pcg_iterations(a.clone(), &aggregation(a, blocks, modes, 6, params))
        })
        .collect();
    assert!(
        counts3[2] as f64 <= 1.5 * counts3[0] as f64 + 2.0,
        "{counts3:?}"
    );
}

/// Clamped nodes have no block; every other node (Γ3 ones with their tangential DOFs) one.
#[test]
fn clamped_nodes_are_absent_from_the_blocks() {
    let (a, blocks, _) = elasticity_2d(4);
    // paper-convergence: 5 × 5 nodes, the 5 on x = 0 clamped.
    assert_eq!(blocks.len(), 20);
    assert_eq!(blocks.n_dofs(), a.nrows);
}
