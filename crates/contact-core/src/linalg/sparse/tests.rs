use super::*;
use crate::fem::{assembly, multilevel, DofMap, Geometry};
use crate::linalg::par;
use crate::scene::{self, presets};
use serde_json::json;

/// K of box-exp3 at h = 1/4 on its free DOFs (interior nodes of 3 DOFs, Γ3 nodes of 2 last)
/// and the bounds of its node blocks.
fn box_k() -> (Csr, Vec<usize>) {
    let mut doc = presets::get("box-exp3").unwrap();
    doc["mesh"]["h"] = json!("1/4");
    let p = scene::validate(&doc).unwrap();
    let mesh = p.mesh::<3>().unwrap();
    let geo = Geometry::new(&mesh);
    let dofs = DofMap::new(&mesh, &p.boundary);
    let visc = p.material.viscosity;
    let k = assembly::viscous_stiffness_in_pattern(&mesh, &geo, &dofs, visc.eta, visc.xi);
    let (blocks, _) = multilevel::velocity_levels(&mesh, &dofs, dofs.n_free());
    let bounds = blocks.consecutive_bounds(k.nrows);
    (k, bounds)
}

/// 11 DOFs in blocks of 3, 2, 1, 3 and 2: the last block's window is moved back over the
/// block before it, and some block pairs are absent or partly filled.
fn ragged() -> (Csr, Vec<usize>) {
    let ptr = [0usize, 3, 5, 6, 9, 11];
    let block = |i: usize| ptr.iter().rposition(|&p| p <= i).unwrap();
    let mut t = Vec::new();
    for i in 0..11usize {
        for j in 0..11usize {
            let far = block(i).abs_diff(block(j)) > 2;
            let hole = (i * 7 + j * 7) % 5 == 1 && i != j;
            if !far && !hole {
                let v = 1.0 / (1.0 + (i + j) as f64) + if i == j { 4.0 } else { 0.0 };
                t.push((i, j, v));
            }
        }
    }
    (Csr::from_triplets(11, 11, t), ptr.to_vec())
}

fn cases() -> Vec<(Csr, Vec<usize>)> {
    vec![ragged(), box_k()]
}

/// Row i's nonzero entries, as the scalar CSR stores them.
fn nonzeros(a: &Csr, i: usize) -> Vec<(usize, f64)> {
    (a.indptr[i]..a.indptr[i + 1])
        .filter(|&p| a.values[p] != 0.0)
        .map(|p| (a.indices[p] as usize, a.values[p]))
        .collect()
}

#[test]
fn node_blocks_list_every_row_and_entry_of_the_scalar_storage() {
    for (a, ptr) in cases() {
        let b = Sparse::in_blocks(&a, &ptr);
        assert!(b.scalar().is_none());
        assert_eq!(b.nrows(), a.nrows);
        for i in 0..a.nrows {
            let mut got = Vec::new();
            b.for_each_in_row(i, |j, v| got.push((j, v)));
            assert_eq!(got, nonzeros(&a, i), "row {i}");
            for j in 0..a.nrows {
                assert_eq!(b.get(i, j), a.get(i, j), "entry ({i}, {j})");
            }
        }
        let half: Vec<bool> = (0..a.nrows).map(|i| i % 3 != 1).collect();
        let (rows, cols) = (a.nrows / 3..a.nrows, 0..a.nrows / 2);
        for (got, want) in [
            (b.rows_of(&half), Sparse::from(a.clone()).rows_of(&half)),
            (b.block(rows.clone(), cols.clone()), a.block(rows, cols)),
            (b.to_csr().into_owned(), a.clone()),
        ] {
            assert_eq!((got.nrows, got.ncols), (want.nrows, want.ncols));
            for i in 0..want.nrows {
                assert_eq!(nonzeros(&got, i), nonzeros(&want, i), "row {i}");
            }
        }
    }
}

/// The block product sums each row's terms in another order: the same to rounding, and the
/// same bits on any number of threads.
#[test]
fn node_block_products_equal_scalar_products_to_rounding() {
    for (a, ptr) in cases() {
        let n = a.nrows;
        let b = Sparse::in_blocks(&a, &ptr);
        let x: Vec<f64> = (0..n).map(|i| (0.37 * i as f64).sin() + 0.2).collect();
        let mut want = vec![0.0; n];
        a.mul_vec(&x, &mut want);
        let run = |threads: usize| {
            par::Threads::new(threads).install(|| {
                let mut y = vec![f64::NAN; n];
                b.mul_vec(&x, &mut y);
                y
            })
        };
        let one = run(1);
        assert_eq!(one, run(2));
        assert_eq!(one, run(3));
        let scale = Sparse::from(a.clone()).max_abs_row_product(&x);
        assert!(
            (b.max_abs_row_product(&x) - scale).abs() <= 1e-14 * scale,
            "Σ|a_ij x_j|"
        );
        for i in 0..n {
            assert!(
                (one[i] - want[i]).abs() <= 4.0 * f64::EPSILON * scale,
                "row {i}: {} against {}",
                one[i],
                want[i]
            );
        }
    }
}

#[test]
fn removing_columns_in_node_blocks_equals_removing_them_in_scalar_storage() {
    for (a, ptr) in cases() {
        let n = a.nrows;
        let b = Sparse::in_blocks(&a, &ptr);
        let s = Sparse::from(a.clone());
        let x: Vec<f64> = (0..n).map(|i| 0.5 + (1.3 * i as f64).sin()).collect();
        let cols: Vec<usize> = (0..n).filter(|i| i % 4 == 0 || *i == n - 1).collect();
        let (mut yb, mut ys) = (vec![0.0; n], vec![0.0; n]);
        b.mul_vec(&x, &mut yb);
        s.mul_vec(&x, &mut ys);
        b.sub_columns(&cols, &x, &mut yb);
        s.sub_columns(&cols, &x, &mut ys);
        let mut masked = x.clone();
        cols.iter().for_each(|&c| masked[c] = 0.0);
        let mut want = vec![0.0; n];
        a.mul_vec(&masked, &mut want);
        let scale = s.max_abs_row_product(&x);
        for i in 0..n {
            assert!((yb[i] - want[i]).abs() <= 1e-14 * scale, "row {i}");
            assert!((ys[i] - want[i]).abs() <= 1e-14 * scale, "row {i}");
        }
    }
}

/// K of a 3D body in f64 node blocks takes about 76/108 of its scalar bytes.
#[test]
fn node_blocks_hold_fewer_bytes_than_scalar_rows() {
    let (a, ptr) = box_k();
    let (b, s) = (Sparse::in_blocks(&a, &ptr), Sparse::from(a));
    let ratio = b.bytes() as f64 / s.bytes() as f64;
    assert!(ratio < 0.85, "{ratio}");
}
