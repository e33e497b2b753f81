use super::*;
use crate::linalg::galerkin::galerkin;
use crate::linalg::multigrid::{Blocks, Coarsening, Params};
use crate::linalg::pcg::{self, PcgWork};

/// The 5-point Laplacian on an m × m grid of interior points (Dirichlet all round), plus a
/// small multiple of the identity so that a fixed-free DOF pattern stays SPD.
fn laplacian(m: usize) -> Csr {
    let id = |i: usize, j: usize| i * m + j;
    let mut t = Vec::new();
    for i in 0..m {
        for j in 0..m {
            t.push((id(i, j), id(i, j), 4.0));
            if i > 0 {
                t.push((id(i, j), id(i - 1, j), -1.0));
            }
            if i + 1 < m {
                t.push((id(i, j), id(i + 1, j), -1.0));
            }
            if j > 0 {
                t.push((id(i, j), id(i, j - 1), -1.0));
            }
            if j + 1 < m {
                t.push((id(i, j), id(i, j + 1), -1.0));
            }
        }
    }
    Csr::from_triplets(m * m, m * m, t)
}

fn hierarchy(a: &Csr) -> Hierarchy {
    hierarchy_in(a, false)
}

/// [`hierarchy`] with single-precision level operators when `mixed`.
fn hierarchy_in(a: &Csr, mixed: bool) -> Hierarchy {
    Hierarchy::new(
        Arc::new(a.clone()),
        Blocks::scalar(a.nrows),
        Coarsening::Aggregation {
            nullspace: vec![1.0; a.nrows],
            k: 1,
        },
        Params {
            coarse_size: 40,
            mixed,
            ..Params::default()
        },
    )
    .unwrap()
}

/// Fixed DOFs on the first grid row (every other one) and 1 × 1 blocks, one of them
/// negative, on the rest of that row: the shape of a Γ3 with stick and slip nodes.
fn modification(m: usize) -> (Vec<usize>, Vec<NodeBlock>) {
    let fixed: Vec<usize> = (0..m).step_by(2).collect();
    let blocks = (1..m)
        .step_by(2)
        .map(|i| NodeBlock {
            start: i,
            size: 1,
            m: [if i % 4 == 1 { 3.0 } else { -0.5 }, 0.0, 0.0, 0.0],
        })
        .collect();
    (fixed, blocks)
}

/// M as an explicit matrix, from its definition.
fn explicit(a: &Csr, fixed: &[usize], blocks: &[NodeBlock]) -> Csr {
    let n = a.nrows;
    let mut t = Vec::new();
    for i in 0..n {
        for k in a.indptr[i]..a.indptr[i + 1] {
            let j = a.indices[k] as usize;
            if !fixed.contains(&i) && !fixed.contains(&j) {
                t.push((i, j, a.values[k]));
            }
        }
    }
    t.extend(fixed.iter().map(|&s| (s, s, 1.0)));
    for b in blocks {
        for k in 0..b.size * b.size {
            t.push((b.start + k / b.size, b.start + k % b.size, b.m[k]));
        }
    }
    Csr::from_triplets(n, n, t)
}

#[test]
fn jacobian_is_the_masked_operator_plus_blocks() {
    let m = 12;
    let a = laplacian(m);
    let (fixed, blocks) = modification(m);
    let mut is_fixed = vec![false; a.nrows];
    fixed.iter().for_each(|&s| is_fixed[s] = true);
    let op = Jacobian {
        a: &Sparse::from(a.clone()),
        fixed: &fixed,
        is_fixed: &is_fixed,
        blocks: &blocks,
    };
    let dense = explicit(&a, &fixed, &blocks);
    let x: Vec<f64> = (0..a.nrows).map(|i| (i as f64 * 0.37).sin()).collect();
    let (mut y, mut z) = (vec![0.0; a.nrows], vec![0.0; a.nrows]);
    op.apply(&x, &mut y);
    dense.mul_vec(&x, &mut z);
    for (u, v) in y.iter().zip(&z) {
        assert!((u - v).abs() < 1e-13, "{u} vs {v}");
    }
}

#[test]
fn first_coarse_operator_is_galerkin_for_the_truncated_prolongator() {
    let m = 16;
    let a = laplacian(m);
    let h = Arc::new(hierarchy(&a));
    assert!(h.n_levels() >= 3, "{:?}", h.sizes());
    let (fixed, blocks) = modification(m);
    let positive: Vec<NodeBlock> = blocks.iter().map(NodeBlock::positive_part).collect();
    assert!(positive.iter().all(|b| b.m[0] >= 0.0));
    let t = Truncated::new(&h, fixed.clone(), &blocks).unwrap();
    let Cycle::Levels(levels) = &t.cycle else {
        panic!("levels expected")
    };
    let Levels { fine, coarse, .. } = &**levels;
    // P̃: A's first prolongator with the rows of F removed (the cycle masks them instead).
    let p_full = fine.prolongator(0).unwrap();
    let mut is_fixed = vec![false; p_full.nrows()];
    fixed.iter().for_each(|&s| is_fixed[s] = true);
    let not_fixed: Vec<bool> = is_fixed.iter().map(|f| !f).collect();
    let p = &p_full.rows_of(&not_fixed);
    let pt = &transpose(p);
    // A₁' from its definition, P̃ᵀ M⁺ P̃ with M⁺'s fixed rows zeroed.
    let mut m_plus = explicit(&a, &fixed, &positive);
    for &s in &fixed {
        m_plus.values[m_plus.indptr[s]..m_plus.indptr[s + 1]].fill(0.0);
    }
    let same = |expected: &Csr, got: &Csr, what: &str| {
        let nc = expected.nrows;
        assert_eq!(got.nrows, nc, "{what}");
        for i in 0..nc {
            for j in 0..nc {
                let (e, g) = (expected.get(i, j), got.get(i, j));
                assert!(
                    (e - g).abs() < 1e-12 * (1.0 + e.abs()),
                    "{what} ({i},{j}): {e} vs {g}"
                );
            }
        }
    };
    let below = coarse.hierarchy();
    same(&galerkin(&m_plus, p, Some(pt)), below.operator(), "A₁'");
    // The levels below are Galerkin for A₁' with A's prolongators, though they are updated
    // by the products of the change A₁' − A₁ only.
    assert!(below.n_levels() >= 2, "{:?}", below.sizes());
    for l in 1..below.n_levels() {
        let p = below.prolongator(l - 1).unwrap().to_csr();
        let expected = galerkin(below.operator_at(l - 1).unwrap(), &p, None);
        same(
            &expected,
            below.operator_at(l).unwrap(),
            &format!("level {l}"),
        );
    }
}

#[test]
fn conjugate_gradients_on_the_jacobian_converge_like_on_the_operator() {
    let m = 48;
    let a = laplacian(m);
    let h = Arc::new(hierarchy(&a));
    let (fixed, blocks) = modification(m);
    let mut t = Truncated::new(&h, fixed.clone(), &blocks).unwrap();
    let mut b: Vec<f64> = (0..a.nrows)
        .map(|i| ((i * 7919) % 13) as f64 - 6.0)
        .collect();
    fixed.iter().for_each(|&s| b[s] = 0.0);
    let mut x = vec![0.0; a.nrows];
    let rep = {
        let blocks = blocks.clone();
        let op = explicit(&a, &fixed, &blocks);
        pcg::solve(&op, &mut t, &b, &mut x, 1e-10, 200, &mut PcgWork::default())
    };
    // The same solve on A with A's own V-cycle, as the yardstick.
    let mut plain = Arc::new(h).vcycle();
    let mut y = vec![0.0; a.nrows];
    let base = pcg::solve(
        &a,
        &mut plain,
        &b,
        &mut y,
        1e-10,
        200,
        &mut PcgWork::default(),
    );
    assert!(rep.converged && base.converged, "{rep:?} {base:?}");
    assert!(
        rep.iterations <= base.iterations + 5,
        "truncated {} vs plain {}",
        rep.iterations,
        base.iterations
    );
    for &s in &fixed {
        assert_eq!(x[s], 0.0);
    }
}

/// With single-precision levels the truncated V-cycle is still a symmetric operator (its
/// smoother multiplies the rounded A with the fixed DOFs masked, never the f64 entries), and
/// conjugate gradients reach the same tolerance in about as many iterations.
#[test]
fn mixed_precision_keeps_the_truncated_cycle_symmetric_and_as_strong() {
    let m = 48;
    let a = laplacian(m);
    let build = |mixed: bool| {
        let h = hierarchy_in(&a, mixed);
        assert_eq!(h.level_f32(0).is_some(), mixed);
        Arc::new(h)
    };
    let (fixed, blocks) = modification(m);
    let n = a.nrows;
    let u: Vec<f64> = (0..n).map(|i| ((i * 31) % 17) as f64 - 8.0).collect();
    let v: Vec<f64> = (0..n).map(|i| (0.3 * i as f64).sin()).collect();
    let mut iterations = Vec::new();
    for mixed in [false, true] {
        let mut t = Truncated::new(&build(mixed), fixed.clone(), &blocks).unwrap();
        let (mut bu, mut bv) = (vec![0.0; n], vec![0.0; n]);
        t.apply(&u, &mut bu);
        t.apply(&v, &mut bv);
        let (vbu, ubv) = (dot(&v, &bu), dot(&u, &bv));
        assert!(
            (vbu - ubv).abs() <= 1e-12 * vbu.abs().max(ubv.abs()),
            "mixed {mixed}: vᵀBu {vbu} against uᵀBv {ubv}"
        );
        let mut b = u.clone();
        fixed.iter().for_each(|&s| b[s] = 0.0);
        let mut x = vec![0.0; n];
        let op = explicit(&a, &fixed, &blocks);
        let rep = pcg::solve(&op, &mut t, &b, &mut x, 1e-10, 200, &mut PcgWork::default());
        assert!(rep.converged, "mixed {mixed}: {rep:?}");
        iterations.push(rep.iterations);
    }
    assert!(
        iterations[1] <= iterations[0] + 1,
        "double {} against mixed {} iterations",
        iterations[0],
        iterations[1]
    );
}

fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

/// A cycle updated from another stick set and other blocks is the cycle made afresh for the
/// new ones: the same first coarse operator and levels below (to rounding; to f32's with
/// single-precision levels), the same smoother blocks, and so the same preconditioner. The
/// change flips DOFs both ways (fixed to free and free to fixed), alters, adds and removes
/// blocks, and keeps some; a second update goes back, with a clone of the cycle alive (the
/// levels then shared, so copied, not changed in place).
#[test]
fn an_updated_cycle_is_the_cycle_made_afresh() {
    for mixed in [false, true] {
        update_and_back(mixed);
    }
}

fn update_and_back(mixed: bool) {
    let m = 16;
    let a = laplacian(m);
    let n = a.nrows;
    let h = Arc::new(hierarchy_in(&a, mixed));
    let (fixed, blocks) = modification(m);
    // Relative agreement: rounding, or single precision's.
    let tol = if mixed { 1e-6 } else { 1e-13 };
    // DOF 0 fixed → free (a block), 1 free → fixed, 3 block changed, 5 block removed, 7 kept,
    // 2 and 4 stay fixed, 16 (second row) gains a block.
    let new_fixed: Vec<usize> = [1, 2, 4].into_iter().chain((6..m).step_by(2)).collect();
    let mut new_blocks: Vec<NodeBlock> = blocks
        .iter()
        .filter(|b| b.start != 1 && b.start != 5)
        .map(|b| {
            let mut b = *b;
            if b.start == 3 {
                b.m[0] = 0.25;
            }
            b
        })
        .collect();
    for (start, v) in [(0, 2.0), (m, 1.5)] {
        new_blocks.push(NodeBlock {
            start,
            size: 1,
            m: [v, 0.0, 0.0, 0.0],
        });
    }
    let same = |updated: Truncated, fresh: Truncated, what: &str| {
        let levels = |t: &Truncated| match &t.cycle {
            Cycle::Levels(l) => l.coarse.hierarchy().clone(),
            Cycle::Direct(_) => panic!("levels expected"),
        };
        let (u, f) = (levels(&updated), levels(&fresh));
        assert_eq!(u.n_levels(), f.n_levels());
        for l in 0..u.n_levels() {
            let (x, y) = (u.operator_in_f64(l).unwrap(), f.operator_in_f64(l).unwrap());
            for i in 0..y.nrows {
                for j in 0..y.nrows {
                    let (e, g) = (y.get(i, j), x.get(i, j));
                    assert!(
                        (e - g).abs() < tol * (1.0 + e.abs()),
                        "mixed {mixed}, {what}, level {l} ({i},{j}): fresh {e} against updated {g}"
                    );
                }
            }
        }
        // The preconditioner applied: the fine smoother's blocks and every level together.
        let r: Vec<f64> = (0..n).map(|i| (0.7 * i as f64).cos()).collect();
        let (mut zu, mut zf) = (vec![0.0; n], vec![0.0; n]);
        let (mut updated, mut fresh) = (updated, fresh);
        updated.apply(&r, &mut zu);
        fresh.apply(&r, &mut zf);
        let scale = zf.iter().fold(0.0f64, |s, v| s.max(v.abs()));
        for (i, (x, y)) in zu.iter().zip(&zf).enumerate() {
            assert!(
                (x - y).abs() < 10.0 * tol * scale,
                "mixed {mixed}, {what}, z[{i}]: {x} against {y}"
            );
        }
    };
    let first = Truncated::new(&h, fixed.clone(), &blocks).unwrap();
    let updated = first.updated(&h, new_fixed.clone(), &new_blocks).unwrap();
    let fresh = Truncated::new(&h, new_fixed.clone(), &new_blocks).unwrap();
    same(updated.clone(), fresh, "there");
    let alive = updated.clone();
    let back = updated.updated(&h, fixed.clone(), &blocks).unwrap();
    same(
        back,
        Truncated::new(&h, fixed, &blocks).unwrap(),
        "and back",
    );
    drop(alive);
}
