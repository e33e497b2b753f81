//! Compressed sparse row matrices: the assembled operators in their own storage, so that
//! matrix–vector products (residuals, KKT checks) never touch the factorisation.

use super::par;
use faer::sparse::{SparseColMat, SymbolicSparseColMat};

/// Pieces of rows of [`Csr::tmul_vec_by_pieces`].
pub const TRANSPOSE_PIECES: usize = 16;

/// A square or rectangular CSR matrix with sorted, duplicate-free column indices per row.
/// Column indices are 32-bit: a product streams 12 bytes per entry instead of 16, and the
/// products are memory-bound (at most 2³² − 1 columns; asserted where matrices are made).
#[derive(Debug, Clone)]
pub struct Csr {
    pub nrows: usize,
    pub ncols: usize,
    pub indptr: Vec<usize>,
    pub indices: Vec<u32>,
    pub values: Vec<f64>,
}

impl Csr {
    /// Builds from (row, col, value) triplets; duplicates are summed.
    /// Bucketed by row (counting sort), then each short row is sorted: O(nnz) for FEM
    /// patterns, where a global sort of the triplets dominated the set-up time.
    pub fn from_triplets(nrows: usize, ncols: usize, t: Vec<(usize, usize, f64)>) -> Csr {
        assert!(
            ncols <= u32::MAX as usize,
            "{ncols} columns exceed 32-bit indices"
        );
        let mut start = vec![0usize; nrows + 1];
        for &(r, c, _) in &t {
            assert!(
                r < nrows && c < ncols,
                "triplet ({r}, {c}) outside {nrows} × {ncols}"
            );
            start[r + 1] += 1;
        }
        for r in 0..nrows {
            start[r + 1] += start[r];
        }
        let mut fill = start.clone();
        let mut bucket = vec![(0usize, 0.0f64); t.len()];
        for (r, c, v) in t {
            bucket[fill[r]] = (c, v);
            fill[r] += 1;
        }
        let mut indptr = Vec::with_capacity(nrows + 1);
        let mut indices = Vec::with_capacity(bucket.len());
        let mut values: Vec<f64> = Vec::with_capacity(bucket.len());
        indptr.push(0);
        for r in 0..nrows {
            let row = &mut bucket[start[r]..start[r + 1]];
            row.sort_unstable_by_key(|e| e.0);
            let first = indices.len();
            for &(c, v) in row.iter() {
                if indices.len() > first && indices[indices.len() - 1] == c as u32 {
                    *values.last_mut().unwrap() += v;
                } else {
                    indices.push(c as u32);
                    values.push(v);
                }
            }
            indptr.push(indices.len());
        }
        Csr {
            nrows,
            ncols,
            indptr,
            indices,
            values,
        }
    }

    /// The `nrows` × `ncols` matrix of the rows flagged in `keep` (the others empty), row i
    /// listed by `row(i, f)` calling f(j, a_ij) in increasing j (a matrix in another
    /// storage, or a few of its rows).
    pub fn from_rows(
        nrows: usize,
        ncols: usize,
        keep: &[bool],
        row: impl Fn(usize, &mut dyn FnMut(usize, f64)),
    ) -> Csr {
        assert_eq!(keep.len(), nrows, "a flag per row");
        let mut indptr = Vec::with_capacity(nrows + 1);
        let (mut indices, mut values) = (Vec::new(), Vec::new());
        indptr.push(0);
        for (i, &keep) in keep.iter().enumerate() {
            if keep {
                row(i, &mut |j, v| {
                    indices.push(j as u32);
                    values.push(v);
                });
            }
            indptr.push(indices.len());
        }
        Csr {
            nrows,
            ncols,
            indptr,
            indices,
            values,
        }
    }

    pub fn nnz(&self) -> usize {
        self.values.len()
    }

    /// y = A x, row blocks split over the calling pool's threads ([`par`]).
    pub fn mul_vec(&self, x: &[f64], y: &mut [f64]) {
        debug_assert_eq!(x.len(), self.ncols);
        debug_assert_eq!(y.len(), self.nrows);
        par::for_each_chunk_mut(y, par::ROW_CHUNK, |start, ys| {
            for (i, yr) in ys.iter_mut().enumerate() {
                let r = start + i;
                let mut s = 0.0;
                let row = self.indptr[r]..self.indptr[r + 1];
                for (&c, &v) in self.indices[row.clone()].iter().zip(&self.values[row]) {
                    s += v * x[c as usize];
                }
                *yr = s;
            }
        });
    }

    /// y += Aᵀ x.
    pub fn tmul_vec_add(&self, x: &[f64], y: &mut [f64]) {
        debug_assert_eq!(x.len(), self.nrows);
        debug_assert_eq!(y.len(), self.ncols);
        for (r, &xr) in x.iter().enumerate() {
            for p in self.indptr[r]..self.indptr[r + 1] {
                y[self.indices[p] as usize] += self.values[p] * xr;
            }
        }
    }

    /// y ← Aᵀ x without Aᵀ stored: [`TRANSPOSE_PIECES`] fixed pieces of A's rows each add
    /// into their own ncols-long slice of `scratch` (TRANSPOSE_PIECES × ncols, contents
    /// ignored), and y sums the slices in piece order, so the bits do not depend on the
    /// thread count. Meant for a short, wide Aᵀ (a smoothed-aggregation restriction: the
    /// scratch is a small share of the vector x).
    pub fn tmul_vec_by_pieces(&self, x: &[f64], y: &mut [f64], scratch: &mut [f64]) {
        debug_assert_eq!(x.len(), self.nrows);
        debug_assert_eq!(y.len(), self.ncols);
        let n = self.ncols;
        assert_eq!(scratch.len(), TRANSPOSE_PIECES * n, "scratch of the pieces");
        if n == 0 {
            return;
        }
        let rows = self.nrows.div_ceil(TRANSPOSE_PIECES);
        par::for_each_chunk_mut(scratch, n, |start, part| {
            part.fill(0.0);
            let piece = start / n;
            let first = (piece * rows).min(self.nrows);
            let last = ((piece + 1) * rows).min(self.nrows);
            for (r, &xr) in x.iter().enumerate().take(last).skip(first) {
                for p in self.indptr[r]..self.indptr[r + 1] {
                    part[self.indices[p] as usize] += self.values[p] * xr;
                }
            }
        });
        let scratch = &*scratch;
        par::for_each_chunk_mut(y, par::VECTOR_CHUNK, |start, ys| {
            for (j, y) in ys.iter_mut().enumerate() {
                *y = (0..TRANSPOSE_PIECES)
                    .map(|piece| scratch[piece * n + start + j])
                    .sum();
            }
        });
    }

    /// Entry (r, c), 0 when structurally absent.
    pub fn get(&self, r: usize, c: usize) -> f64 {
        let row = &self.indices[self.indptr[r]..self.indptr[r + 1]];
        match row.binary_search(&(c as u32)) {
            Ok(p) => self.values[self.indptr[r] + p],
            Err(_) => 0.0,
        }
    }

    pub fn diagonal(&self) -> Vec<f64> {
        (0..self.nrows).map(|r| self.get(r, r)).collect()
    }

    /// The block rows `rows`, columns `cols` (half-open ranges) as a new CSR matrix.
    pub fn block(&self, rows: std::ops::Range<usize>, cols: std::ops::Range<usize>) -> Csr {
        let mut t = Vec::new();
        for r in rows.clone() {
            for p in self.indptr[r]..self.indptr[r + 1] {
                let c = self.indices[p] as usize;
                if cols.contains(&c) {
                    t.push((r - rows.start, c - cols.start, self.values[p]));
                }
            }
        }
        Csr::from_triplets(rows.len(), cols.len(), t)
    }

    /// The lower triangle of a symmetric CSR matrix as a faer CSC matrix. For a symmetric
    /// matrix, row r of the upper triangle is column r of the lower one, so no sort is needed.
    pub fn lower_csc(&self) -> SparseColMat<usize, f64> {
        assert_eq!(self.nrows, self.ncols);
        let n = self.nrows;
        let mut col_ptr = Vec::with_capacity(n + 1);
        let mut row_idx = Vec::new();
        let mut val = Vec::new();
        col_ptr.push(0);
        for c in 0..n {
            // Column c of the lower triangle = entries (r ≥ c, c) = (by symmetry) row c, cols ≥ c.
            for p in self.indptr[c]..self.indptr[c + 1] {
                let r = self.indices[p] as usize;
                if r >= c {
                    row_idx.push(r);
                    val.push(self.values[p]);
                }
            }
            col_ptr.push(row_idx.len());
        }
        let sym = SymbolicSparseColMat::new_checked(n, n, col_ptr, None, row_idx);
        SparseColMat::new(sym, val)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn triplets_sum_duplicates_and_multiply() {
        let a = Csr::from_triplets(
            2,
            3,
            vec![(0, 0, 1.0), (1, 2, 2.0), (0, 0, 3.0), (1, 0, -1.0)],
        );
        assert_eq!(a.nnz(), 3);
        assert_eq!(a.get(0, 0), 4.0);
        let mut y = [0.0; 2];
        a.mul_vec(&[1.0, 5.0, 2.0], &mut y);
        assert_eq!(y, [4.0, 3.0]);
        let b = a.block(1..2, 1..3);
        assert_eq!((b.nrows, b.ncols, b.get(0, 1)), (1, 2, 2.0));
    }

    /// Aᵀ x by pieces equals the product with the stored transpose to rounding, and gives the
    /// same bits on any number of threads (a 300 × 40 matrix: rows in 16 pieces of 19).
    #[test]
    fn the_transpose_product_by_pieces_is_the_transposes_and_thread_independent() {
        let mut t = Vec::new();
        for r in 0..300usize {
            for c in [r % 40, (7 * r + 3) % 40, (r / 8) % 40] {
                t.push((r, c, 1.0 + ((r * 13 + c) % 17) as f64 / 7.0));
            }
        }
        let a = Csr::from_triplets(300, 40, t);
        let at = crate::linalg::galerkin::transpose(&a);
        let x: Vec<f64> = (0..300).map(|i| (0.37 * i as f64).sin()).collect();
        let mut want = vec![0.0; 40];
        at.mul_vec(&x, &mut want);
        let run = |threads: usize| {
            par::Threads::new(threads).install(|| {
                let (mut y, mut scratch) = (vec![f64::NAN; 40], vec![f64::NAN; 16 * 40]);
                a.tmul_vec_by_pieces(&x, &mut y, &mut scratch);
                y
            })
        };
        let one = run(1);
        for (j, (y, w)) in one.iter().zip(&want).enumerate() {
            assert!((y - w).abs() <= 1e-13 * w.abs().max(1.0), "column {j}");
        }
        assert_eq!(one, run(2));
        assert_eq!(one, run(3));
    }
}
