//! Smoothed aggregation (Vaněk, Mandel, Brezina, "Algebraic multigrid by smoothed
//! aggregation for second and fourth order elliptic problems", Computing 56 (1996)): the
//! coarsening of a level that has no geometric hierarchy.
//!
//! 1. Strength: node blocks i ≠ j are strongly coupled when
//!    ‖A_ij‖_F ≥ θ (‖A_ii‖_F ‖A_jj‖_F)^½ (block norms; θ halves on each coarser level, as in
//!    AMGCL).
//! 2. Aggregates, in three passes: a block whose strong neighbours are all free starts an
//!    aggregate with them; the blocks left join the aggregate of a strong neighbour; the rest
//!    form aggregates of their still-free strong neighbourhood.
//! 3. Tentative prolongator T: on each aggregate, the thin QR factorisation B_a = Q_a R_a of
//!    the near-nullspace rows (rigid-body modes for elasticity, constants for a Laplacian);
//!    Q_a's columns are the aggregate's coarse DOFs, R_a its rows of the coarse near-nullspace,
//!    so T B_c = B exactly. Columns that are numerically dependent on an aggregate (a Γ3 node
//!    alone has fewer DOFs than rigid modes) are dropped: coarse blocks may be smaller.
//! 4. Smoothed prolongator P = (I − ω D⁻¹A) T, ω = 4/(3 λ_max(D⁻¹A)), D the block diagonal.

#![allow(clippy::needless_range_loop)] // Index loops over nodes, blocks and components spell out the formulas.

use super::smoother::BlockJacobi;
use super::Blocks;
use crate::linalg::block_products;
use crate::linalg::galerkin::{add, product};
use crate::linalg::{par, Csr};

/// A block that starts no aggregate and is not yet in one.
const FREE: usize = usize::MAX;

/// The strong-neighbour graph of the node blocks: CSR adjacency (ptr, list).
pub fn strength(a: &Csr, blocks: &Blocks, theta: f64) -> (Vec<usize>, Vec<usize>) {
    let nb = blocks.len();
    let block_of = blocks.block_of(a.nrows);
    let mut norm2 = vec![0.0; nb];
    let mut acc = vec![0.0; nb];
    let mut seen = vec![FREE; nb];
    let mut touched = Vec::new();
    // Diagonal block norms first.
    for b in 0..nb {
        for &r in blocks.dofs(b) {
            for p in a.indptr[r]..a.indptr[r + 1] {
                if block_of[a.indices[p] as usize] as usize == b {
                    norm2[b] += a.values[p] * a.values[p];
                }
            }
        }
    }
    let mut ptr = Vec::with_capacity(nb + 1);
    let mut list = Vec::new();
    ptr.push(0);
    for b in 0..nb {
        touched.clear();
        for &r in blocks.dofs(b) {
            for p in a.indptr[r]..a.indptr[r + 1] {
                let c = block_of[a.indices[p] as usize] as usize;
                if c == b {
                    continue;
                }
                if seen[c] != b {
                    seen[c] = b;
                    acc[c] = 0.0;
                    touched.push(c);
                }
                acc[c] += a.values[p] * a.values[p];
            }
        }
        touched.sort_unstable();
        for &c in &touched {
            if acc[c] >= theta * theta * (norm2[b] * norm2[c]).sqrt() && acc[c] > 0.0 {
                list.push(c);
            }
        }
        ptr.push(list.len());
    }
    (ptr, list)
}

/// The distance-two graph of (ptr, list): b's neighbours and their neighbours (b excluded),
/// sorted. Aggregates of it are about a neighbourhood of neighbourhoods (PETSc GAMG's
/// "square graph" on the finest level): on an unstructured tetrahedral mesh, where a node has
/// about 14 neighbours, aggregates of the plain graph are small and the smoothed
/// prolongator makes the first coarse operator nearly as large as the fine one.
pub fn squared(ptr: &[usize], list: &[usize]) -> (Vec<usize>, Vec<usize>) {
    par::sorted_rows(ptr.len() - 1, |b, out| {
        for &c in &list[ptr[b]..ptr[b + 1]] {
            out.push(c);
            out.extend(list[ptr[c]..ptr[c + 1]].iter().filter(|&&d| d != b));
        }
    })
}

/// The aggregate of every block (numbered 0..count) and the count.
pub fn aggregates(ptr: &[usize], list: &[usize]) -> (Vec<usize>, usize) {
    let nb = ptr.len() - 1;
    let mut agg = vec![FREE; nb];
    let mut count = 0;
    let neighbours = |b: usize| &list[ptr[b]..ptr[b + 1]];
    // Pass 1: whole free neighbourhoods.
    for b in 0..nb {
        if agg[b] != FREE || neighbours(b).iter().any(|&c| agg[c] != FREE) {
            continue;
        }
        agg[b] = count;
        for &c in neighbours(b) {
            agg[c] = count;
        }
        count += 1;
    }
    // Pass 2: join a neighbouring aggregate of pass 1 (the first one met).
    let first = agg.clone();
    for b in 0..nb {
        if agg[b] == FREE {
            if let Some(&c) = neighbours(b).iter().find(|&&c| first[c] != FREE) {
                agg[b] = first[c];
            }
        }
    }
    // Pass 3: what is left forms aggregates of its free neighbourhood.
    for b in 0..nb {
        if agg[b] != FREE {
            continue;
        }
        agg[b] = count;
        for &c in neighbours(b) {
            if agg[c] == FREE {
                agg[c] = count;
            }
        }
        count += 1;
    }
    (agg, count)
}

/// The tentative prolongator T (n × n_c), the coarse blocks (one per aggregate that keeps a
/// column) and the coarse near-nullspace B_c (n_c × k, row-major) with T B_c = B.
/// `nullspace` is n × k, row-major.
pub fn tentative(
    blocks: &Blocks,
    agg: &[usize],
    count: usize,
    nullspace: &[f64],
    k: usize,
) -> (Csr, Blocks, Vec<f64>) {
    let n = nullspace.len() / k;
    // DOFs of each aggregate, in block order.
    let mut members: Vec<Vec<usize>> = vec![Vec::new(); count];
    for (b, &a) in agg.iter().enumerate() {
        members[a].extend_from_slice(blocks.dofs(b));
    }
    let mut triplets = Vec::with_capacity(n * k);
    let mut coarse_ptr = vec![0usize];
    let mut coarse_null = Vec::with_capacity(count * k * k);
    let mut nc = 0;
    for dofs in &members {
        let m = dofs.len();
        // Columns of B restricted to the aggregate, orthonormalised by modified Gram–Schmidt
        // with one re-orthogonalisation pass; R collects the coefficients.
        let mut q: Vec<Vec<f64>> = Vec::with_capacity(k);
        let mut r: Vec<Vec<f64>> = Vec::with_capacity(k);
        let biggest = (0..k)
            .map(|c| {
                dofs.iter()
                    .map(|&i| nullspace[i * k + c].powi(2))
                    .sum::<f64>()
                    .sqrt()
            })
            .fold(0.0f64, f64::max);
        for c in 0..k {
            let mut v: Vec<f64> = dofs.iter().map(|&i| nullspace[i * k + c]).collect();
            let mut coef = vec![0.0; q.len()];
            for _ in 0..2 {
                for (j, qj) in q.iter().enumerate() {
                    let s: f64 = qj.iter().zip(&v).map(|(a, b)| a * b).sum();
                    coef[j] += s;
                    v.iter_mut().zip(qj).for_each(|(v, q)| *v -= s * q);
                }
            }
            for (j, rj) in r.iter_mut().enumerate() {
                rj[c] = coef[j];
            }
            let norm = v.iter().map(|x| x * x).sum::<f64>().sqrt();
            if q.len() < m && norm > 1e-8 * biggest && norm > 0.0 {
                v.iter_mut().for_each(|x| *x /= norm);
                q.push(v);
                let mut row = vec![0.0; k];
                row[c] = norm;
                r.push(row);
            }
        }
        for (j, qj) in q.iter().enumerate() {
            for (l, &i) in dofs.iter().enumerate() {
                triplets.push((i, nc + j, qj[l]));
            }
        }
        for row in &r {
            coarse_null.extend_from_slice(row);
        }
        nc += q.len();
        if !q.is_empty() {
            coarse_ptr.push(nc);
        }
    }
    let t = Csr::from_triplets(n, nc, triplets);
    (t, Blocks::contiguous(&coarse_ptr), coarse_null)
}

/// P = (I − ω D⁻¹A) T with ω = 4/(3 λ), λ ≥ λ_max(D⁻¹A); in node blocks where the fine
/// blocks (consecutive bounds `fine`) and aggregates (`coarse`) allow
/// ([`block_products::smoothed_prolongator`]).
pub fn smooth_prolongator(
    a: &Csr,
    jacobi: &BlockJacobi,
    lambda: f64,
    t: &Csr,
    fine: &[usize],
    coarse: &[usize],
) -> Csr {
    let omega = 4.0 / (3.0 * lambda);
    let dinv = jacobi.inverse_matrix();
    block_products::smoothed_prolongator(a, &dinv, omega, t, fine, coarse).unwrap_or_else(|| {
        let dinv_a = product(&dinv, a);
        add(1.0, t, -omega, &product(&dinv_a, t))
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The path 0 – 1 – … – 9 as an adjacency list.
    fn path(n: usize) -> (Vec<usize>, Vec<usize>) {
        let (mut ptr, mut list) = (vec![0], Vec::new());
        for b in 0..n {
            list.extend([b.wrapping_sub(1), b + 1].into_iter().filter(|&c| c < n));
            ptr.push(list.len());
        }
        (ptr, list)
    }

    #[test]
    fn the_squared_graph_holds_the_neighbours_within_two_steps() {
        let (ptr, list) = path(10);
        let (p2, l2) = crate::linalg::par::Threads::new(2).install(|| squared(&ptr, &list));
        for b in 0..10usize {
            let want: Vec<usize> = (b.saturating_sub(2)..=(b + 2).min(9))
                .filter(|&c| c != b)
                .collect();
            assert_eq!(&l2[p2[b]..p2[b + 1]], &want[..], "block {b}");
        }
        // Aggregates of the squared path are twice as long as those of the path.
        let (_, plain) = aggregates(&ptr, &list);
        let (_, wide) = aggregates(&p2, &l2);
        assert_eq!((plain, wide), (4, 2));
    }
}
