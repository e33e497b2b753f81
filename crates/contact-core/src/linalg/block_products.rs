//! The products of a smoothed-aggregation level's set-up in node blocks: the fine DOFs cut
//! into node blocks of at most SF DOFs (3 in 3D, 2 in 2D; an aggregate's SF = 6 coarse DOFs
//! on the levels below), the coarse DOFs into aggregates of at most SC (the near-nullspace's
//! 6 or 3 rigid modes).
//!
//! - the smoothed prolongator P = T − ω D⁻¹ A T ([`smoothed_prolongator`]);
//! - the Galerkin coarse operator A_c = Pᵀ A P ([`galerkin`]).
//!
//! The scalar products ([`super::galerkin`]) spend their time finding the place of each
//! scalar term (some 450 M for PᵀAP on the 80k-node part). In blocks the places are found
//! once per block pair, and the arithmetic is dense SF × SC and SC × SC block products:
//!
//! 1. **Symbolic, once:** the block pattern of each fine block row of A P (the aggregates
//!    within two block steps), and from it the block pattern of A_c, row by row over the
//!    aggregates.
//! 2. **Numeric:** the rows of A P are formed one block row at a time from A's scalar rows
//!    (A is not copied). For A_c, [`PIECES`] fixed pieces of the fine block rows each add
//!    P_iᵀ (A P)_i into their own copy of the band of A_c's rows their aggregates meet; the
//!    copies are summed in piece order, so the bits do not depend on the thread count, and
//!    the result is symmetrised entrywise as the scalar product's is.
//!
//! Smaller blocks (Γ3 nodes, clamped components, aggregates of fewer modes) are padded
//! with zeros, and the padding is dropped from the results: scalar CSR with every entry of
//! each nonzero block pair.

use super::galerkin::{add, transpose};
use super::{par, Csr};

/// Pieces of the fine block rows of the numeric product: fixed, so the sums (and the bits)
/// do not depend on the thread count.
const PIECES: usize = 16;

/// Pᵀ A P for `a` square with P's rows, the fine DOFs in the blocks of consecutive DOFs
/// `fine[b]..fine[b + 1]` and the coarse DOFs in `coarse[b]..coarse[b + 1]` (both
/// increasing from 0 to the dimension). None where the largest blocks are not (3, 6),
/// (6, 6), (2, 3) or (3, 3) fine × coarse DOFs: the caller takes the scalar product.
pub fn galerkin(a: &Csr, p: &Csr, fine: &[usize], coarse: &[usize]) -> Option<Csr> {
    assert_eq!(
        (a.nrows, a.ncols),
        (p.nrows, p.nrows),
        "A square with P's rows"
    );
    assert_eq!(fine.last(), Some(&p.nrows), "fine blocks cover P's rows");
    assert_eq!(
        coarse.last(),
        Some(&p.ncols),
        "coarse blocks cover P's columns"
    );
    let largest = |ptr: &[usize]| ptr.windows(2).map(|w| w[1] - w[0]).max().unwrap_or(0);
    Some(match (largest(fine), largest(coarse)) {
        (3, 6) => blocked::<3, 6>(a, p, fine, coarse),
        (6, 6) => blocked::<6, 6>(a, p, fine, coarse),
        (2, 3) => blocked::<2, 3>(a, p, fine, coarse),
        (3, 3) => blocked::<3, 3>(a, p, fine, coarse),
        _ => return None,
    })
}

/// P = T − ω D⁻¹ A T for `a` square with T's rows and `dinv` = D⁻¹ block diagonal in the
/// fine blocks, in the blocks of [`galerkin`] (the same sizes, or None).
pub fn smoothed_prolongator(
    a: &Csr,
    dinv: &Csr,
    omega: f64,
    t: &Csr,
    fine: &[usize],
    coarse: &[usize],
) -> Option<Csr> {
    assert_eq!(
        (a.nrows, a.ncols),
        (t.nrows, t.nrows),
        "A square with T's rows"
    );
    assert_eq!(fine.last(), Some(&t.nrows), "fine blocks cover T's rows");
    assert_eq!(
        coarse.last(),
        Some(&t.ncols),
        "coarse blocks cover T's columns"
    );
    // D⁻¹ must lie in the fine blocks.
    let fine_of = block_of(fine);
    let within = (0..dinv.nrows).all(|r| {
        dinv.indices[dinv.indptr[r]..dinv.indptr[r + 1]]
            .iter()
            .all(|&c| fine_of[c as usize] == fine_of[r])
    });
    if !within {
        return None;
    }
    let largest = |ptr: &[usize]| ptr.windows(2).map(|w| w[1] - w[0]).max().unwrap_or(0);
    Some(match (largest(fine), largest(coarse)) {
        (3, 6) => prolongator::<3, 6>(a, dinv, omega, t, fine, coarse),
        (6, 6) => prolongator::<6, 6>(a, dinv, omega, t, fine, coarse),
        (2, 3) => prolongator::<2, 3>(a, dinv, omega, t, fine, coarse),
        (3, 3) => prolongator::<3, 3>(a, dinv, omega, t, fine, coarse),
        _ => return None,
    })
}

fn prolongator<const SF: usize, const SC: usize>(
    a: &Csr,
    dinv: &Csr,
    omega: f64,
    t: &Csr,
    fine: &[usize],
    coarse: &[usize],
) -> Csr {
    let n_coarse = coarse.len() - 1;
    let (fine_of, coarse_of) = (block_of(fine), block_of(coarse));
    let tb = blocks_of_p::<SF, SC>(t, fine, coarse, &coarse_of);
    let (ap_row, ap_cols) = product_pattern(a, fine, &fine_of, &tb, n_coarse);
    let parts = par::map_ranges(fine.len() - 1, CHUNK, |range| {
        let mut place = vec![u32::MAX; n_coarse];
        let mut w: Vec<[[f64; SC]; SF]> = Vec::new();
        let (mut lengths, mut indices, mut values) = (Vec::new(), Vec::new(), Vec::new());
        for i in range {
            let pattern = &ap_cols[ap_row[i]..ap_row[i + 1]];
            for (q, &big_j) in pattern.iter().enumerate() {
                place[big_j as usize] = q as u32;
            }
            w.clear();
            w.resize(pattern.len(), [[0.0; SC]; SF]);
            row_of_product(a, fine, &fine_of, &tb, &place, i, &mut w);
            let (js, ti) = tb.blocks(i);
            assert!(
                js.iter().all(|j| pattern.binary_search(j).is_ok()),
                "T's blocks lie in A T's pattern (A's diagonal blocks are stored)"
            );
            for (x, r) in (fine[i]..fine[i + 1]).enumerate() {
                // Row x of T_i − ω D_i⁻¹ W, block by block.
                let d = dinv.indptr[r]..dinv.indptr[r + 1];
                for (q, &big_j) in pattern.iter().enumerate() {
                    let mut row = [0.0f64; SC];
                    for (&c, &dv) in dinv.indices[d.clone()].iter().zip(&dinv.values[d.clone()]) {
                        let y = c as usize - fine[i];
                        for (v, &wv) in row.iter_mut().zip(&w[q][y]) {
                            *v -= omega * dv * wv;
                        }
                    }
                    if let Ok(k) = js.binary_search(&big_j) {
                        for (v, &tv) in row.iter_mut().zip(&ti[k][x]) {
                            *v += tv;
                        }
                    }
                    let cols = coarse[big_j as usize]..coarse[big_j as usize + 1];
                    for (col, &v) in cols.zip(&row) {
                        indices.push(col as u32);
                        values.push(v);
                    }
                }
                lengths.push(indices.len());
            }
        }
        (lengths, indices, values)
    });
    // Rows joined in order (the lengths above are running ends within each part), into
    // vectors of their final size.
    let mut indptr = Vec::with_capacity(t.nrows + 1);
    indptr.push(0usize);
    let mut indices = Vec::with_capacity(parts.iter().map(|p| p.1.len()).sum());
    let mut values = Vec::with_capacity(parts.iter().map(|p| p.2.len()).sum());
    for (ends, i, v) in parts {
        let base = indices.len();
        indptr.extend(ends.into_iter().map(|e| base + e));
        indices.extend(i);
        values.extend(v);
    }
    Csr {
        nrows: t.nrows,
        ncols: t.ncols,
        indptr,
        indices,
        values,
    }
}

/// Block row i of A B into `w` (zeroed, one block per entry of i's pattern, whose places
/// `place` gives by aggregate), from A's scalar rows and B in blocks.
fn row_of_product<const SF: usize, const SC: usize>(
    a: &Csr,
    fine: &[usize],
    fine_of: &[u32],
    b: &BlockRows<SF, SC>,
    place: &[u32],
    i: usize,
    w: &mut [[[f64; SC]; SF]],
) {
    for (x, r) in (fine[i]..fine[i + 1]).enumerate() {
        for e in a.indptr[r]..a.indptr[r + 1] {
            let (col, v) = (a.indices[e] as usize, a.values[e]);
            let j = fine_of[col] as usize;
            let y = col - fine[j];
            let (js, bj) = b.blocks(j);
            for (&big_j, bj) in js.iter().zip(bj) {
                let wx = &mut w[place[big_j as usize] as usize][x];
                for (w, &bv) in wx.iter_mut().zip(&bj[y]) {
                    *w += v * bv;
                }
            }
        }
    }
}

/// The block of each DOF of the consecutive blocks `ptr`.
fn block_of(ptr: &[usize]) -> Vec<u32> {
    let mut of = vec![0u32; *ptr.last().unwrap_or(&0)];
    for b in 0..ptr.len() - 1 {
        of[ptr[b]..ptr[b + 1]].fill(b as u32);
    }
    of
}

/// A block-sparse matrix of dense R × C blocks: row b's blocks are cols[row[b]..row[b + 1]]
/// (increasing) with values vals[row[b]..row[b + 1]].
struct BlockRows<const R: usize, const C: usize> {
    row: Vec<usize>,
    cols: Vec<u32>,
    vals: Vec<[[f64; C]; R]>,
}

impl<const R: usize, const C: usize> BlockRows<R, C> {
    fn blocks(&self, b: usize) -> (&[u32], &[[[f64; C]; R]]) {
        let range = self.row[b]..self.row[b + 1];
        (&self.cols[range.clone()], &self.vals[range])
    }
}

/// Block rows per task of the set-up loops.
const CHUNK: usize = 2048;

/// P in R × C blocks (rows in the fine blocks, columns in the coarse ones).
fn blocks_of_p<const R: usize, const C: usize>(
    p: &Csr,
    fine: &[usize],
    coarse: &[usize],
    coarse_of: &[u32],
) -> BlockRows<R, C> {
    let (row, cols) = par::sorted_rows(fine.len() - 1, |i, cols| {
        for r in fine[i]..fine[i + 1] {
            let entries = p.indptr[r]..p.indptr[r + 1];
            cols.extend(p.indices[entries].iter().map(|&c| coarse_of[c as usize]));
        }
    });
    let parts = par::map_ranges(fine.len() - 1, CHUNK, |range| {
        let mut vals = vec![[[0.0; C]; R]; row[range.end] - row[range.start]];
        for i in range.clone() {
            let blocks = &cols[row[i]..row[i + 1]];
            for (x, r) in (fine[i]..fine[i + 1]).enumerate() {
                for e in p.indptr[r]..p.indptr[r + 1] {
                    let c = p.indices[e] as usize;
                    let j = coarse_of[c];
                    let k = row[i] - row[range.start] + blocks.binary_search(&j).expect("listed");
                    vals[k][x][c - coarse[j as usize]] = p.values[e];
                }
            }
        }
        vals
    });
    let mut vals = Vec::with_capacity(cols.len());
    parts.into_iter().for_each(|part| vals.extend(part));
    BlockRows { row, cols, vals }
}

/// The `n` rows of a pattern over `n_cols` columns whose row i is the union of the columns
/// `row(i, add)` adds (repeats allowed), each row increasing: a marker per task drops the
/// repeats, so only a row's distinct columns are sorted.
fn union_rows(
    n: usize,
    n_cols: usize,
    row: impl Fn(usize, &mut dyn FnMut(u32)) + Sync + Send,
) -> (Vec<usize>, Vec<u32>) {
    let parts = par::map_ranges(n, CHUNK, |range| {
        let mut seen = vec![u32::MAX; n_cols];
        let (mut lengths, mut cols) = (Vec::new(), Vec::new());
        for i in range {
            let first = cols.len();
            row(i, &mut |j| {
                if seen[j as usize] != i as u32 {
                    seen[j as usize] = i as u32;
                    cols.push(j);
                }
            });
            cols[first..].sort_unstable();
            lengths.push(cols.len() - first);
        }
        (lengths, cols)
    });
    par::join_rows(n, parts)
}

/// For each fine block row i, the aggregates J of its blocks of A P (the P columns of the
/// blocks of A's row i), increasing.
fn product_pattern<const R: usize, const C: usize>(
    a: &Csr,
    fine: &[usize],
    fine_of: &[u32],
    pb: &BlockRows<R, C>,
    n_coarse: usize,
) -> (Vec<usize>, Vec<u32>) {
    union_rows(fine.len() - 1, n_coarse, |i, add| {
        for r in fine[i]..fine[i + 1] {
            for &c in &a.indices[a.indptr[r]..a.indptr[r + 1]] {
                pb.blocks(fine_of[c as usize] as usize)
                    .0
                    .iter()
                    .for_each(|&big_j| add(big_j));
            }
        }
    })
}

/// The block pattern of Pᵀ A P: row I is the union of the A P patterns of the fine block
/// rows that P's column block I meets.
fn coarse_pattern<const R: usize, const C: usize>(
    pb: &BlockRows<R, C>,
    ap_row: &[usize],
    ap_cols: &[u32],
    n_coarse: usize,
) -> (Vec<usize>, Vec<u32>) {
    // Pᵀ's block pattern: the fine block rows of each aggregate (counting sort).
    let mut start = vec![0usize; n_coarse + 1];
    for &j in &pb.cols {
        start[j as usize + 1] += 1;
    }
    for j in 0..n_coarse {
        start[j + 1] += start[j];
    }
    let mut next = start.clone();
    let mut rows_of = vec![0u32; pb.cols.len()];
    for i in 0..pb.row.len() - 1 {
        for &j in pb.blocks(i).0 {
            rows_of[next[j as usize]] = i as u32;
            next[j as usize] += 1;
        }
    }
    union_rows(n_coarse, n_coarse, |big_i, add| {
        for &i in &rows_of[start[big_i]..start[big_i + 1]] {
            let i = i as usize;
            ap_cols[ap_row[i]..ap_row[i + 1]]
                .iter()
                .for_each(|&big_j| add(big_j));
        }
    })
}

fn blocked<const SF: usize, const SC: usize>(
    a: &Csr,
    p: &Csr,
    fine: &[usize],
    coarse: &[usize],
) -> Csr {
    let (n_fine, n_coarse) = (fine.len() - 1, coarse.len() - 1);
    let (fine_of, coarse_of) = (block_of(fine), block_of(coarse));
    let pb = blocks_of_p::<SF, SC>(p, fine, coarse, &coarse_of);
    let (ap_row, ap_cols) = product_pattern(a, fine, &fine_of, &pb, n_coarse);
    let (c_row, c_cols) = coarse_pattern(&pb, &ap_row, &ap_cols, n_coarse);

    let rows = n_fine.div_ceil(PIECES).max(1);
    let pieces = n_fine.div_ceil(rows);
    // A piece's term lives on the rows of A_c of the aggregates its fine rows meet: a band
    // of A_c for a numbering with locality (its first value's place, and the values).
    let term = |k: usize| {
        let piece = k * rows..((k + 1) * rows).min(n_fine);
        let met = &pb.cols[pb.row[piece.start]..pb.row[piece.end]];
        let (Some(&low), Some(&high)) = (met.iter().min(), met.iter().max()) else {
            return (0, Vec::new());
        };
        let band = c_row[low as usize]..c_row[high as usize + 1];
        let mut c = vec![[[0.0f64; SC]; SC]; band.len()];
        let mut place = vec![u32::MAX; n_coarse];
        let mut w: Vec<[[f64; SC]; SF]> = Vec::new();
        for i in piece {
            // Row block i of A P: W[J] = Σ_j A_ij P_jJ, from A's scalar rows.
            let pattern = &ap_cols[ap_row[i]..ap_row[i + 1]];
            for (q, &big_j) in pattern.iter().enumerate() {
                place[big_j as usize] = q as u32;
            }
            w.clear();
            w.resize(pattern.len(), [[0.0; SC]; SF]);
            row_of_product(a, fine, &fine_of, &pb, &place, i, &mut w);
            // C_IJ += P_iIᵀ W_J.
            let (is, pi) = pb.blocks(i);
            for (&big_i, pi) in is.iter().zip(pi) {
                let c_range = c_row[big_i as usize]..c_row[big_i as usize + 1];
                let c_of_row = &c_cols[c_range.clone()];
                for (&big_j, wj) in pattern.iter().zip(&w) {
                    let q = c_range.start + c_of_row.binary_search(&big_j).expect("in pattern");
                    let cq = &mut c[q - band.start];
                    for x in 0..SF {
                        for (cy, &pxy) in cq.iter_mut().zip(&pi[x]) {
                            if pxy != 0.0 {
                                for (c, &wv) in cy.iter_mut().zip(&wj[x]) {
                                    *c += pxy * wv;
                                }
                            }
                        }
                    }
                }
            }
        }
        (band.start, c)
    };
    let round = par::current_threads().max(1);
    let mut values = vec![[[0.0f64; SC]; SC]; c_cols.len()];
    for first in (0..pieces).step_by(round) {
        let terms = par::map_ranges(round.min(pieces - first), 1, |k| term(first + k.start));
        for (start, t) in terms {
            for (v, t) in values[start..].iter_mut().zip(&t) {
                for (v, t) in v.iter_mut().zip(t) {
                    for (v, t) in v.iter_mut().zip(t) {
                        *v += t;
                    }
                }
            }
        }
    }

    // Scalar rows, the padding dropped.
    let nc = *coarse.last().unwrap();
    let (mut indptr, mut indices, mut vals) = (vec![0], Vec::new(), Vec::new());
    for big_i in 0..n_coarse {
        let range = c_row[big_i]..c_row[big_i + 1];
        for x in 0..coarse[big_i + 1] - coarse[big_i] {
            for (&big_j, v) in c_cols[range.clone()].iter().zip(&values[range.clone()]) {
                let cols = coarse[big_j as usize]..coarse[big_j as usize + 1];
                for (y, col) in cols.enumerate() {
                    indices.push(col as u32);
                    vals.push(v[x][y]);
                }
            }
            indptr.push(indices.len());
        }
    }
    let c = Csr {
        nrows: nc,
        ncols: nc,
        indptr,
        indices,
        values: vals,
    };
    add(0.5, &c, 0.5, &transpose(&c))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A symmetric positive definite A on 3D-like node blocks of 3, 2 and 1 DOFs, and a P
    /// whose aggregates have 6, 4 and 1 columns, with structural zeros inside blocks.
    fn case() -> (Csr, Csr, Vec<usize>, Vec<usize>) {
        let sizes = [3usize, 3, 2, 3, 1, 3, 3, 2, 3, 3, 3, 1, 3, 2, 3, 3];
        let mut fine = vec![0];
        for s in sizes {
            fine.push(fine.last().unwrap() + s);
        }
        let n = *fine.last().unwrap();
        let block = |i: usize| fine.iter().rposition(|&f| f <= i).unwrap();
        let mut t = Vec::new();
        for i in 0..n {
            for j in 0..n {
                let (bi, bj) = (block(i), block(j));
                if bi.abs_diff(bj) <= 2 && (i + 2 * j) % 7 != 3 || i == j {
                    let v = 1.0 / (1.0 + (i as f64 - j as f64).abs()) + (i + j) as f64 * 0.01;
                    t.push((i, j, v));
                    t.push((j, i, v));
                }
                if i == j {
                    t.push((i, i, 10.0));
                }
            }
        }
        let a = Csr::from_triplets(n, n, t);
        let coarse = vec![0, 6, 10, 11, 17];
        let nc = 17;
        let mut t = Vec::new();
        for r in 0..n {
            let agg = block(r) / 4;
            for c in 0..nc {
                let cb = coarse.iter().rposition(|&f| f <= c).unwrap();
                if cb.abs_diff(agg) <= 1 && (r * 3 + c) % 5 != 0 {
                    t.push((r, c, ((r * 7 + c * 3) % 11) as f64 / 11.0 - 0.4));
                }
            }
        }
        (a, Csr::from_triplets(n, nc, t), fine, coarse)
    }

    fn dense(a: &Csr) -> Vec<Vec<f64>> {
        let mut d = vec![vec![0.0; a.ncols]; a.nrows];
        for (r, row) in d.iter_mut().enumerate() {
            for e in a.indptr[r]..a.indptr[r + 1] {
                row[a.indices[e] as usize] += a.values[e];
            }
        }
        d
    }

    #[test]
    fn equals_the_scalar_galerkin_product_on_padded_blocks() {
        let (a, p, fine, coarse) = case();
        let scalar = dense(&super::super::galerkin::galerkin(&a, &p, None));
        let blocked = galerkin(&a, &p, &fine, &coarse).expect("3 × 6 blocks");
        for (r, (b, s)) in dense(&blocked).iter().zip(&scalar).enumerate() {
            for (c, (b, s)) in b.iter().zip(s).enumerate() {
                assert!(
                    (b - s).abs() <= 1e-13 * (1.0 + s.abs()),
                    "({r}, {c}): {b} against {s}"
                );
            }
        }
        // Symmetric to the bit, rows sorted.
        let d = dense(&blocked);
        for (r, row) in d.iter().enumerate() {
            for (c, v) in row.iter().enumerate() {
                assert_eq!(*v, d[c][r]);
            }
            let cols = &blocked.indices[blocked.indptr[r]..blocked.indptr[r + 1]];
            assert!(cols.windows(2).all(|w| w[0] < w[1]), "row {r} sorted");
        }
    }

    #[test]
    fn the_smoothed_prolongator_equals_the_scalar_products() {
        let (a, t, fine, coarse) = case();
        // A block-diagonal D⁻¹ in the fine blocks (any values: the product does not assume
        // an inverse).
        let mut d = Vec::new();
        for b in 0..fine.len() - 1 {
            for i in fine[b]..fine[b + 1] {
                for j in fine[b]..fine[b + 1] {
                    d.push((i, j, 0.1 + 0.01 * (3 * i + j) as f64));
                }
            }
        }
        let dinv = Csr::from_triplets(a.nrows, a.nrows, d.clone());
        let omega = 0.7;
        let scalar = dense(&add(
            1.0,
            &t,
            -omega,
            &super::super::galerkin::product(&super::super::galerkin::product(&dinv, &a), &t),
        ));
        let run = |threads: usize| {
            par::Threads::new(threads).install(|| {
                smoothed_prolongator(&a, &dinv, omega, &t, &fine, &coarse).expect("3 × 6 blocks")
            })
        };
        let blocked = run(1);
        for (r, (b, s)) in dense(&blocked).iter().zip(&scalar).enumerate() {
            for (c, (b, s)) in b.iter().zip(s).enumerate() {
                assert!(
                    (b - s).abs() <= 1e-13 * (1.0 + s.abs()),
                    "({r}, {c}): {b} against {s}"
                );
            }
            let cols = &blocked.indices[blocked.indptr[r]..blocked.indptr[r + 1]];
            assert!(cols.windows(2).all(|w| w[0] < w[1]), "row {r} sorted");
        }
        let two = run(2);
        assert_eq!(
            (&blocked.indptr, &blocked.indices),
            (&two.indptr, &two.indices)
        );
        assert_eq!(blocked.values, two.values);
        // A D⁻¹ across blocks is declined.
        d.push((0, 3, 0.5));
        let across = Csr::from_triplets(a.nrows, a.nrows, d);
        assert!(smoothed_prolongator(&a, &across, omega, &t, &fine, &coarse).is_none());
    }

    #[test]
    fn gives_the_same_bits_on_any_number_of_threads_and_declines_other_sizes() {
        let (a, p, fine, coarse) = case();
        let run = |threads: usize| {
            par::Threads::new(threads).install(|| galerkin(&a, &p, &fine, &coarse).unwrap())
        };
        let one = run(1);
        for threads in [2, 3] {
            let other = run(threads);
            assert_eq!((&one.indptr, &one.indices), (&other.indptr, &other.indices));
            assert_eq!(one.values, other.values, "{threads} threads");
        }
        let scalar: Vec<usize> = (0..=a.nrows).collect();
        assert!(galerkin(&a, &p, &scalar, &coarse).is_none());
    }
}
