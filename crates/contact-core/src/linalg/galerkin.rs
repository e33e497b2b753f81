//! Sparse products of the multigrid set-up: the transpose, A·B (Gustavson's row-by-row
//! product with a dense accumulator), a·A + b·B, and the Galerkin coarse operator
//! A_c = Pᵀ A P that keeps every constraint built into A's DOFs (Γ1 removed, Γ3 normals
//! removed, rotated contact frames) on every level.
//!
//! All results are [`Csr`] with sorted, duplicate-free rows; work and memory are linear in
//! the number of products formed (no triplet lists).

use super::{par, Csr};

/// Aᵀ (ncols × nrows), rows sorted by construction (a counting sort by column).
pub fn transpose(a: &Csr) -> Csr {
    let mut indptr = vec![0usize; a.ncols + 1];
    for &c in &a.indices {
        indptr[c as usize + 1] += 1;
    }
    for c in 0..a.ncols {
        indptr[c + 1] += indptr[c];
    }
    let mut next = indptr.clone();
    let mut indices = vec![0u32; a.nnz()];
    let mut values = vec![0.0; a.nnz()];
    for r in 0..a.nrows {
        for p in a.indptr[r]..a.indptr[r + 1] {
            let c = a.indices[p] as usize;
            indices[next[c]] = r as u32;
            values[next[c]] = a.values[p];
            next[c] += 1;
        }
    }
    Csr {
        nrows: a.ncols,
        ncols: a.nrows,
        indptr,
        indices,
        values,
    }
}

/// A·B for A (n × m) and B (m × k).
pub fn product(a: &Csr, b: &Csr) -> Csr {
    assert_eq!(a.ncols, b.nrows, "inner dimensions differ");
    by_rows(a.nrows, b.ncols, |r, acc| {
        for p in a.indptr[r]..a.indptr[r + 1] {
            let (m, av) = (a.indices[p] as usize, a.values[p]);
            for q in b.indptr[m]..b.indptr[m + 1] {
                acc.add(b.indices[q] as usize, av * b.values[q]);
            }
        }
    })
}

/// A·B for A (n × m) and a B (m × `ncols`) given by its rows: `b_row(k, f)` calls f(j, b_kj)
/// for row k's entries in increasing j (B in another storage: a prolongator in node blocks).
pub fn product_with_rows(
    a: &Csr,
    ncols: usize,
    b_row: impl Fn(usize, &mut dyn FnMut(usize, f64)) + Sync + Send,
) -> Csr {
    by_rows(a.nrows, ncols, |r, acc| {
        for p in a.indptr[r]..a.indptr[r + 1] {
            let (k, av) = (a.indices[p] as usize, a.values[p]);
            b_row(k, &mut |j, v| acc.add(j, av * v));
        }
    })
}

/// The dense accumulator of one row of a product (Gustavson): the entries of the row being
/// formed, and which columns it has.
struct Accumulator {
    acc: Vec<f64>,
    /// The row that last touched each column (`usize::MAX`: none).
    seen: Vec<usize>,
    cols: Vec<usize>,
    row: usize,
}

impl Accumulator {
    #[inline]
    fn add(&mut self, c: usize, v: f64) {
        if self.seen[c] != self.row {
            self.seen[c] = self.row;
            self.acc[c] = 0.0;
            self.cols.push(c);
        }
        self.acc[c] += v;
    }
}

/// Rows of a product as formed by one thread: each row's length, then all their columns
/// and values in row order.
type RowBlock = (Vec<usize>, Vec<u32>, Vec<f64>);

/// The rows `rows` of a matrix with `ncols` columns whose row i `row(i, acc)` adds into
/// `acc`, with one dense accumulator for the block.
fn row_block(
    rows: std::ops::Range<usize>,
    ncols: usize,
    row: impl Fn(usize, &mut Accumulator),
) -> RowBlock {
    let mut acc = Accumulator {
        acc: vec![0.0; ncols],
        seen: vec![usize::MAX; ncols],
        cols: Vec::new(),
        row: 0,
    };
    let (mut lengths, mut indices, mut values) =
        (Vec::with_capacity(rows.len()), Vec::new(), Vec::new());
    for i in rows {
        acc.row = i;
        acc.cols.clear();
        row(i, &mut acc);
        acc.cols.sort_unstable();
        for &j in &acc.cols {
            indices.push(j as u32);
            values.push(acc.acc[j]);
        }
        lengths.push(acc.cols.len());
    }
    (lengths, indices, values)
}

/// The `nrows` × `ncols` matrix made of consecutive row blocks, joined in order.
fn join(nrows: usize, ncols: usize, blocks: Vec<RowBlock>) -> Csr {
    let nnz = blocks.iter().map(|b| b.1.len()).sum();
    let mut indptr = Vec::with_capacity(nrows + 1);
    let (mut indices, mut values) = (Vec::with_capacity(nnz), Vec::with_capacity(nnz));
    indptr.push(0);
    for (lengths, i, v) in blocks {
        for l in lengths {
            indptr.push(indptr.last().unwrap() + l);
        }
        indices.extend_from_slice(&i);
        values.extend_from_slice(&v);
    }
    assert_eq!(indptr.len(), nrows + 1, "row blocks cover the rows");
    Csr {
        nrows,
        ncols,
        indptr,
        indices,
        values,
    }
}

/// The `nrows` × `ncols` matrix whose row i `row(i, acc)` adds into `acc`. Blocks of rows
/// are formed on the pool's threads, each with an accumulator of its own, and joined in
/// order; a row's arithmetic does not depend on the split, so neither does the result.
fn by_rows(nrows: usize, ncols: usize, row: impl Fn(usize, &mut Accumulator) + Sync + Send) -> Csr {
    let threads = par::current_threads();
    let chunk = match threads {
        1 => nrows.max(1),
        t => nrows.div_ceil(4 * t).max(1),
    };
    let blocks = par::map_ranges(nrows, chunk, |rows| row_block(rows, ncols, &row));
    join(nrows, ncols, blocks)
}

/// α·A + β·B for two matrices of one shape (any patterns).
pub fn add(alpha: f64, a: &Csr, beta: f64, b: &Csr) -> Csr {
    assert_eq!((a.nrows, a.ncols), (b.nrows, b.ncols), "shapes differ");
    let mut indptr = Vec::with_capacity(a.nrows + 1);
    let mut indices = Vec::with_capacity(a.nnz().max(b.nnz()));
    let mut values = Vec::with_capacity(a.nnz().max(b.nnz()));
    indptr.push(0);
    for r in 0..a.nrows {
        let (mut p, pe) = (a.indptr[r], a.indptr[r + 1]);
        let (mut q, qe) = (b.indptr[r], b.indptr[r + 1]);
        while p < pe || q < qe {
            let ca = if p < pe { a.indices[p] } else { u32::MAX };
            let cb = if q < qe { b.indices[q] } else { u32::MAX };
            if ca == cb {
                indices.push(ca);
                values.push(alpha * a.values[p] + beta * b.values[q]);
                p += 1;
                q += 1;
            } else if ca < cb {
                indices.push(ca);
                values.push(alpha * a.values[p]);
                p += 1;
            } else {
                indices.push(cb);
                values.push(beta * b.values[q]);
                q += 1;
            }
        }
        indptr.push(indices.len());
    }
    Csr {
        nrows: a.nrows,
        ncols: a.ncols,
        indptr,
        indices,
        values,
    }
}

/// The Galerkin coarse operator Pᵀ A P (coarse × coarse), symmetrised entrywise so that
/// rounding cannot make a coarse operator unsymmetric.
///
/// A·P, on a fine 3D level, has more entries than A and would be the set-up's largest
/// transient; it is never formed whole. With a sparse P (geometric levels: at most two
/// fine-to-coarse weights per row) the product goes row by row of the result
/// ([`triple_product`]). A smoothed-aggregation P has tens of entries per row, which would
/// make that triple loop as many times the work: the sum over the fine rows is cut into
/// [`GALERKIN_PIECES`] pieces instead ([`by_pieces`]). `pt` is Pᵀ where the caller holds it;
/// the row-by-row product forms it otherwise.
pub fn galerkin(a: &Csr, p: &Csr, pt: Option<&Csr>) -> Csr {
    let c = if p.nnz() <= 2 * p.nrows {
        match pt {
            Some(pt) => triple_product(a, p, pt),
            None => triple_product(a, p, &transpose(p)),
        }
    } else {
        by_pieces(a, p)
    };
    add(0.5, &c, 0.5, &transpose(&c))
}

/// Pieces of the fine rows in [`by_pieces`]. Fixed, so the sums (and the bits) do not depend
/// on the thread count.
const GALERKIN_PIECES: usize = 16;

/// Pᵀ A P = Σ_R P_Rᵀ (A P)_R over [`GALERKIN_PIECES`] consecutive pieces R of the fine rows:
/// each piece forms (A P)_R and its term, and the terms are added in piece order as they
/// come, a round of as many pieces as threads at a time. Every row of A·P is formed once;
/// what is held beside the result is a round's rows of A·P and terms.
fn by_pieces(a: &Csr, p: &Csr) -> Csr {
    assert_eq!(
        (a.nrows, a.ncols),
        (p.nrows, p.nrows),
        "A square with P's rows"
    );
    let (nf, nc) = (p.nrows, p.ncols);
    let rows = nf.div_ceil(GALERKIN_PIECES).max(1);
    let pieces = nf.div_ceil(rows);
    let term = |k: usize| {
        let fine = k * rows..((k + 1) * rows).min(nf);
        let (lengths, ap_cols, ap_values) = row_block(fine.clone(), nc, |r, acc| {
            for s in a.indptr[r]..a.indptr[r + 1] {
                let (m, av) = (a.indices[s] as usize, a.values[s]);
                for t in p.indptr[m]..p.indptr[m + 1] {
                    acc.add(p.indices[t] as usize, av * p.values[t]);
                }
            }
        });
        let mut start = Vec::with_capacity(lengths.len() + 1);
        start.push(0);
        for l in lengths {
            start.push(start.last().unwrap() + l);
        }
        let entries = p.indptr[fine.start]..p.indptr[fine.end];
        let p_r = Csr {
            nrows: fine.len(),
            ncols: nc,
            indptr: p.indptr[fine.clone()]
                .iter()
                .chain(std::iter::once(&p.indptr[fine.end]))
                .map(|&e| e - entries.start)
                .collect(),
            indices: p.indices[entries.clone()].to_vec(),
            values: p.values[entries].to_vec(),
        };
        let p_rt = transpose(&p_r);
        join(
            nc,
            nc,
            vec![row_block(0..nc, nc, |i, acc| {
                for q in p_rt.indptr[i]..p_rt.indptr[i + 1] {
                    let (r, w) = (p_rt.indices[q] as usize, p_rt.values[q]);
                    for e in start[r]..start[r + 1] {
                        acc.add(ap_cols[e] as usize, w * ap_values[e]);
                    }
                }
            })],
        )
    };
    let round = par::current_threads().max(1);
    let mut c = Csr::from_triplets(nc, nc, Vec::new());
    for first in (0..pieces).step_by(round) {
        let terms = par::map_ranges(round.min(pieces - first), 1, |k| term(first + k.start));
        for t in terms {
            c = add(1.0, &c, 1.0, &t);
        }
    }
    c
}

/// C_IJ = Σ_r Pᵀ_Ir Σ_m A_rm P_mJ, one row of C at a time: only C and one dense accumulator
/// per thread are held.
fn triple_product(a: &Csr, p: &Csr, pt: &Csr) -> Csr {
    assert_eq!(
        (a.nrows, a.ncols),
        (p.nrows, p.nrows),
        "A must be square, P's rows A's"
    );
    assert_eq!(
        (pt.nrows, pt.ncols),
        (p.ncols, p.nrows),
        "Pᵀ must be P's transpose"
    );
    by_rows(p.ncols, p.ncols, |i, acc| {
        for q in pt.indptr[i]..pt.indptr[i + 1] {
            let (r, w) = (pt.indices[q] as usize, pt.values[q]);
            for s in a.indptr[r]..a.indptr[r + 1] {
                let (m, wa) = (a.indices[s] as usize, w * a.values[s]);
                for t in p.indptr[m]..p.indptr[m + 1] {
                    acc.add(p.indices[t] as usize, wa * p.values[t]);
                }
            }
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn dense(a: &Csr) -> Vec<Vec<f64>> {
        let mut d = vec![vec![0.0; a.ncols]; a.nrows];
        for (r, row) in d.iter_mut().enumerate() {
            for p in a.indptr[r]..a.indptr[r + 1] {
                row[a.indices[p] as usize] += a.values[p];
            }
        }
        d
    }

    fn sample(n: usize, m: usize, seed: u64) -> Csr {
        let mut s = seed;
        let mut t = Vec::new();
        for r in 0..n {
            for c in 0..m {
                s = s
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                if (s >> 60) < 5 {
                    t.push((r, c, ((s >> 20) % 1000) as f64 / 100.0 - 5.0));
                }
            }
        }
        Csr::from_triplets(n, m, t)
    }

    #[test]
    fn products_agree_with_dense_arithmetic() {
        let (a, b) = (sample(7, 5, 1), sample(5, 6, 2));
        let (da, db) = (dense(&a), dense(&b));
        let ab = dense(&product(&a, &b));
        for i in 0..7 {
            for j in 0..6 {
                let want: f64 = (0..5).map(|k| da[i][k] * db[k][j]).sum();
                assert!((ab[i][j] - want).abs() < 1e-12);
            }
        }
        let at = dense(&transpose(&a));
        let s = dense(&add(2.0, &a, -3.0, &sample(7, 5, 3)));
        let d3 = dense(&sample(7, 5, 3));
        for i in 0..7 {
            for j in 0..5 {
                assert_eq!(at[j][i], da[i][j]);
                assert!((s[i][j] - (2.0 * da[i][j] - 3.0 * d3[i][j])).abs() < 1e-12);
            }
        }
    }

    #[test]
    fn products_on_threads_are_the_same_bits() {
        let b = sample(300, 300, 7);
        let a = add(1.0, &b, 1.0, &transpose(&b));
        let p = sample(300, 40, 8);
        let pt = transpose(&p);
        let bits = |c: Csr| {
            (
                c.indptr,
                c.indices,
                c.values.iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
            )
        };
        let all = || {
            [
                bits(product(&a, &p)),
                bits(triple_product(&a, &p, &pt)),
                bits(by_pieces(&a, &p)),
                bits(galerkin(&a, &p, Some(&pt))),
                bits(galerkin(&a, &p, None)),
            ]
        };
        let one = all();
        for t in [2, 3] {
            assert!(one == par::Threads::new(t).install(all), "{t} threads");
        }
    }

    #[test]
    fn galerkin_operator_is_pt_a_p() {
        let b = sample(6, 6, 4);
        let a = add(1.0, &b, 1.0, &transpose(&b));
        let p = sample(6, 3, 5);
        let pt = transpose(&p);
        let (da, dp) = (dense(&a), dense(&p));
        let forms = [
            galerkin(&a, &p, Some(&pt)),
            triple_product(&a, &p, &pt),
            by_pieces(&a, &p),
            product(&pt, &product(&a, &p)),
        ];
        for c in forms.iter().map(dense) {
            for i in 0..3 {
                for j in 0..3 {
                    let mut want = 0.0;
                    for k in 0..6 {
                        for l in 0..6 {
                            want += dp[k][i] * da[k][l] * dp[l][j];
                        }
                    }
                    assert!((c[i][j] - want).abs() < 1e-10, "{i} {j}");
                }
            }
        }
    }
}
