//! A square operator in node-block storage: block CSR with one column index per block, the
//! entries in f64 (K of the velocity step on the multigrid path) or rounded to f32 (a level
//! operator of the mixed-precision V-cycle, docs/src/speed/speed.md#mixed-precision-levels);
//! y = A x with x, y and every sum in f64 either way.
//!
//! The rows are cut into the operator's node blocks (a node's free velocity components, an
//! aggregate's coarse DOFs, or single DOFs), consecutive DOF ranges in order. Every block is
//! stored as S × S, S the largest block's size: block row b holds, for every block column c
//! that meets it, A's s_b × s_c block padded with zeros, column by column, and one index per
//! block, the first DOF of a window of S consecutive DOFs that holds c's DOFs (c's first DOF,
//! moved back at the end of the vector). The product then reads S entries of x from one index
//! without looking up block sizes; the few smaller blocks (Γ3 nodes, partly fixed nodes)
//! cost their padding. A 3D node block is 9 entries and one index: 76 bytes in f64 and 40
//! in f32, against 108 in scalar f64 CSR, and a product streams those bytes.
//!
//! Column by column, a block's product y_b += A_bc x_c is C multiples of a column of R
//! contiguous entries, added lane by lane in the order of a row's dot product (the same
//! bits as row by row), which the compiler does in vector registers: in f32 the conversions
//! to f64 dominate a row-by-row product, and the product of a 3D f32 level took 0.78 × the
//! time of row by row here (0.92 × in f64; docs/src/speed/speed.md).
//!
//! In f32 the rounding is a perturbation of relative size 2⁻²⁴ of the preconditioner only:
//! the outer conjugate gradients, the residuals and the operator K itself stay in f64, so the
//! solution is the same to the solver's tolerance (crates/contact-core/tests/multigrid.rs
//! checks both precisions against the direct path). In f64 a product differs from the scalar
//! CSR one only in the order of its sums.

use super::csr::TRANSPOSE_PIECES;
use super::{par, Csr, LinearOperator};
use std::ops::Range;

/// An entry type of [`BlockCsr`]: f64, or f32 for the mixed-precision levels.
pub trait Entry: Copy + Default + Send + Sync + Into<f64> + std::fmt::Debug + 'static {
    /// A's entry in this type (rounded to nearest for f32).
    fn from_f64(v: f64) -> Self;
}

impl Entry for f32 {
    fn from_f64(v: f64) -> f32 {
        v as f32
    }
}

impl Entry for f64 {
    fn from_f64(v: f64) -> f64 {
        v
    }
}

/// A level operator in f32 node blocks (the mixed-precision V-cycle).
pub type BlockCsr32 = BlockCsr<f32>;

/// An operator in block CSR with R × C blocks of entries of type T: square (R = C, the
/// node blocks of a level) or rectangular (a smoothed-aggregation prolongator: a fine node's
/// DOFs by an aggregate's coarse DOFs).
#[derive(Debug, Clone)]
pub struct BlockCsr<T: Entry> {
    /// Block row b covers rows ptr[b]..ptr[b + 1] ...
    ptr: Vec<usize>,
    /// ... and block column c columns col_ptr[c]..col_ptr[c + 1].
    col_ptr: Vec<usize>,
    /// The block sizes R and C.
    s: usize,
    sc: usize,
    /// Block row b's entries are window[row[b]..row[b + 1]].
    row: Vec<usize>,
    /// The first column of each entry's window of C columns.
    window: Vec<u32>,
    /// R × C entries per block entry, column by column ([`BlockCsr::at`]).
    values: Vec<T>,
    /// Pieces of whole block rows for the threads: piece s is blocks split_blocks[s]..
    /// (rows split_dofs[s]..), each about [`par::ROW_CHUNK`] rows, the same for any thread
    /// count.
    split_blocks: Vec<usize>,
    split_dofs: Vec<usize>,
}

/// The first DOF of block column c's window of `sc` columns: c's first DOF, moved back at
/// the end of the vector so that the window stays inside it.
fn window_start(col_ptr: &[usize], sc: usize, c: usize) -> usize {
    let m = *col_ptr.last().expect("block bounds");
    col_ptr[c].min(m - sc)
}

impl<T: Entry> BlockCsr<T> {
    /// `a` (square) in the blocks of consecutive DOFs ptr[b]..ptr[b + 1] (increasing from 0
    /// to n; [`super::multigrid::Blocks::consecutive_bounds`] of a level's node blocks).
    pub fn new(a: &Csr, ptr: &[usize]) -> BlockCsr<T> {
        assert_eq!(a.nrows, a.ncols, "a square operator");
        Self::rectangular(a, ptr, ptr)
    }

    /// `a` in blocks of the consecutive rows ptr[b]..ptr[b + 1] and the consecutive columns
    /// col_ptr[c]..col_ptr[c + 1].
    pub fn rectangular(a: &Csr, ptr: &[usize], col_ptr: &[usize]) -> BlockCsr<T> {
        let (n, m) = (a.nrows, a.ncols);
        let bounds = |ptr: &[usize], n: usize| {
            ptr.first() == Some(&0) && ptr.last() == Some(&n) && ptr.windows(2).all(|w| w[0] < w[1])
        };
        assert!(bounds(ptr, n) && bounds(col_ptr, m), "block bounds");
        let (ptr, col_ptr) = (ptr.to_vec(), col_ptr.to_vec());
        let nb = ptr.len() - 1;
        let largest = |ptr: &[usize]| ptr.windows(2).map(|w| w[1] - w[0]).max().unwrap_or(1);
        let (s, sc) = (largest(&ptr), largest(&col_ptr));
        let mut block_of = vec![0u32; m];
        for c in 0..col_ptr.len() - 1 {
            block_of[col_ptr[c]..col_ptr[c + 1]].fill(c as u32);
        }
        // The block pattern: each piece of block rows on its own, joined in order.
        let (split_blocks, split_dofs) = split(&ptr);
        let pieces = par::map_ranges(split_blocks.len() - 1, 1, |pieces| {
            let (mut row, mut cols) = (Vec::new(), Vec::<u32>::new());
            for b in split_blocks[pieces.start]..split_blocks[pieces.end] {
                let first = cols.len();
                for r in ptr[b]..ptr[b + 1] {
                    let entries = a.indptr[r]..a.indptr[r + 1];
                    cols.extend(a.indices[entries].iter().map(|&c| block_of[c as usize]));
                }
                cols[first..].sort_unstable();
                let mut unique = first;
                for k in first..cols.len() {
                    if k == first || cols[k] != cols[unique - 1] {
                        cols[unique] = cols[k];
                        unique += 1;
                    }
                }
                cols.truncate(unique);
                row.push(first);
            }
            (row, cols)
        });
        let mut row = Vec::with_capacity(nb + 1);
        let mut cols = Vec::with_capacity(pieces.iter().map(|p| p.1.len()).sum());
        for (r, c) in pieces {
            let base = cols.len();
            row.extend(r.into_iter().map(|r| r + base));
            cols.extend(c);
        }
        row.push(cols.len());
        // The entries, in one allocation (the copy is the only transient), each piece of
        // block rows filling its own part.
        let start = |c: u32| window_start(&col_ptr, sc, c as usize);
        let rc = s * sc;
        let mut values = vec![T::default(); rc * cols.len()];
        let value_bounds: Vec<usize> = split_blocks.iter().map(|&b| rc * row[b]).collect();
        par::for_each_segment_mut(&mut values, &value_bounds, |piece, values| {
            let first = row[split_blocks[piece]];
            for b in split_blocks[piece]..split_blocks[piece + 1] {
                let row_cols = &cols[row[b]..row[b + 1]];
                for (i, r) in (ptr[b]..ptr[b + 1]).enumerate() {
                    for p in a.indptr[r]..a.indptr[r + 1] {
                        let c = a.indices[p];
                        let cb = block_of[c as usize];
                        let k = row_cols.binary_search(&cb).expect("column listed");
                        let j = c as usize - start(cb);
                        values[rc * (row[b] + k - first) + j * s + i] = T::from_f64(a.values[p]);
                    }
                }
            }
        });
        let window = cols.iter().map(|&c| start(c) as u32).collect();
        BlockCsr {
            ptr,
            col_ptr,
            s,
            sc,
            row,
            window,
            values,
            split_blocks,
            split_dofs,
        }
    }

    pub fn nrows(&self) -> usize {
        *self.ptr.last().unwrap_or(&0)
    }

    pub fn ncols(&self) -> usize {
        *self.col_ptr.last().unwrap_or(&0)
    }

    /// Where entry (a, j) of block entry p lies in `values`: column by column.
    fn at(&self, p: usize, a: usize, j: usize) -> usize {
        self.s * (self.sc * p + j) + a
    }

    /// Bytes held.
    pub fn bytes(&self) -> usize {
        8 * (self.ptr.len() + self.col_ptr.len() + self.row.len())
            + 4 * self.window.len()
            + std::mem::size_of::<T>() * self.values.len()
    }

    /// y ← A x.
    pub fn mul_vec(&self, x: &[f64], y: &mut [f64]) {
        debug_assert_eq!(x.len(), self.ncols());
        debug_assert_eq!(y.len(), self.nrows());
        par::for_each_segment_mut(y, &self.split_dofs, |seg, y| {
            let base = self.split_dofs[seg];
            let blocks = self.split_blocks[seg]..self.split_blocks[seg + 1];
            match (self.s, self.sc) {
                (1, 1) => self.scalar_rows(blocks, x, y, base),
                (2, 2) => self.rows::<2, 2>(blocks, x, y, base),
                (3, 3) => self.rows::<3, 3>(blocks, x, y, base),
                (6, 6) => self.rows::<6, 6>(blocks, x, y, base),
                (2, 3) => self.rows::<2, 3>(blocks, x, y, base),
                (3, 6) => self.rows::<3, 6>(blocks, x, y, base),
                _ => self.rows_any(blocks, x, y, base),
            }
        });
    }

    /// The block rows `blocks` of y (which starts at row `base`) for blocks of R × C, spelled
    /// out for the compiler: 2D and 3D node blocks, smoothed aggregation's six rigid modes,
    /// and the prolongators between them.
    #[inline(always)]
    fn rows<const R: usize, const C: usize>(
        &self,
        blocks: Range<usize>,
        x: &[f64],
        y: &mut [f64],
        base: usize,
    ) {
        for b in blocks {
            let entries = self.row[b]..self.row[b + 1];
            let values = &self.values[R * C * entries.start..R * C * entries.end];
            let mut sum = [0.0f64; R];
            for (&w, v) in self.window[entries].iter().zip(values.chunks_exact(R * C)) {
                let xw: &[f64; C] = x[w as usize..w as usize + C].try_into().expect("C");
                // Row a's dot product ((v_a0 x_0 + v_a1 x_1) + …), all R rows at once.
                let mut t = [0.0f64; R];
                for (j, column) in v.chunks_exact(R).enumerate() {
                    for (t, &v) in t.iter_mut().zip(column) {
                        *t += v.into() * xw[j];
                    }
                }
                for (sum, t) in sum.iter_mut().zip(t) {
                    *sum += t;
                }
            }
            let r0 = self.ptr[b] - base;
            let sr = self.ptr[b + 1] - self.ptr[b];
            y[r0..r0 + sr].copy_from_slice(&sum[..sr]);
        }
    }

    /// The rows `blocks` of y for 1 × 1 blocks (a scalar operator): four partial sums per
    /// row, so that a row's additions do not wait on one another (one chain of dependent
    /// additions made the product latency-bound, slower than the f64 scalar CSR product).
    fn scalar_rows(&self, blocks: Range<usize>, x: &[f64], y: &mut [f64], base: usize) {
        for b in blocks {
            let entries = self.row[b]..self.row[b + 1];
            let (window, values) = (&self.window[entries.clone()], &self.values[entries]);
            let mut sum = [0.0f64; 4];
            let (w4, v4) = (window.chunks_exact(4), values.chunks_exact(4));
            let (w_rest, v_rest) = (w4.remainder(), v4.remainder());
            for (w, v) in w4.zip(v4) {
                for k in 0..4 {
                    sum[k] += v[k].into() * x[w[k] as usize];
                }
            }
            for (k, (&w, &v)) in w_rest.iter().zip(v_rest).enumerate() {
                sum[k] += v.into() * x[w as usize];
            }
            y[self.ptr[b] - base] = (sum[0] + sum[1]) + (sum[2] + sum[3]);
        }
    }

    /// [`BlockCsr::rows`] for any R and C.
    fn rows_any(&self, blocks: Range<usize>, x: &[f64], y: &mut [f64], base: usize) {
        let sc = self.sc;
        for b in blocks {
            let r0 = self.ptr[b] - base;
            let sr = self.ptr[b + 1] - self.ptr[b];
            let yb = &mut y[r0..r0 + sr];
            yb.fill(0.0);
            for p in self.row[b]..self.row[b + 1] {
                let w = self.window[p] as usize;
                for (a, y) in yb.iter_mut().enumerate() {
                    *y += (0..sc)
                        .map(|j| self.values[self.at(p, a, j)].into() * x[w + j])
                        .sum::<f64>();
                }
            }
        }
    }

    /// y ← Aᵀ x without Aᵀ stored, as [`Csr::tmul_vec_by_pieces`]: [`TRANSPOSE_PIECES`] fixed
    /// pieces of block rows each add into their own ncols-long slice of `scratch`
    /// (TRANSPOSE_PIECES × ncols, contents ignored), and y sums the slices in piece order,
    /// so the bits do not depend on the thread count.
    pub fn tmul_vec_by_pieces(&self, x: &[f64], y: &mut [f64], scratch: &mut [f64]) {
        debug_assert_eq!(x.len(), self.nrows());
        debug_assert_eq!(y.len(), self.ncols());
        let m = self.ncols();
        assert_eq!(scratch.len(), TRANSPOSE_PIECES * m, "scratch of the pieces");
        if m == 0 {
            return;
        }
        let nb = self.ptr.len() - 1;
        let per_piece = nb.div_ceil(TRANSPOSE_PIECES);
        par::for_each_chunk_mut(scratch, m, |start, part| {
            part.fill(0.0);
            let piece = start / m;
            let blocks = (piece * per_piece).min(nb)..((piece + 1) * per_piece).min(nb);
            match (self.s, self.sc) {
                (1, 1) => self.scatter_rows::<1, 1>(blocks, x, part),
                (3, 6) => self.scatter_rows::<3, 6>(blocks, x, part),
                (6, 6) => self.scatter_rows::<6, 6>(blocks, x, part),
                (2, 3) => self.scatter_rows::<2, 3>(blocks, x, part),
                _ => self.scatter_rows_any(blocks, x, part),
            }
        });
        let scratch = &*scratch;
        par::for_each_chunk_mut(y, par::VECTOR_CHUNK, |start, ys| {
            for (j, y) in ys.iter_mut().enumerate() {
                *y = (0..TRANSPOSE_PIECES)
                    .map(|piece| scratch[piece * m + start + j])
                    .sum();
            }
        });
    }

    /// part += A[blocks, :]ᵀ x[blocks] for blocks of R × C.
    #[inline(always)]
    fn scatter_rows<const R: usize, const C: usize>(
        &self,
        blocks: Range<usize>,
        x: &[f64],
        part: &mut [f64],
    ) {
        for b in blocks {
            let mut xb = [0.0f64; R];
            let r0 = self.ptr[b];
            let sr = self.ptr[b + 1] - r0;
            xb[..sr].copy_from_slice(&x[r0..r0 + sr]);
            let entries = self.row[b]..self.row[b + 1];
            let values = &self.values[R * C * entries.start..R * C * entries.end];
            for (&w, v) in self.window[entries].iter().zip(values.chunks_exact(R * C)) {
                let out: &mut [f64; C] = (&mut part[w as usize..w as usize + C])
                    .try_into()
                    .expect("C");
                for (out, column) in out.iter_mut().zip(v.chunks_exact(R)) {
                    let mut t = 0.0;
                    for (&v, xb) in column.iter().zip(xb) {
                        t += v.into() * xb;
                    }
                    *out += t;
                }
            }
        }
    }

    /// [`BlockCsr::scatter_rows`] for any R and C.
    fn scatter_rows_any(&self, blocks: Range<usize>, x: &[f64], part: &mut [f64]) {
        for b in blocks {
            for (a, r) in (self.ptr[b]..self.ptr[b + 1]).enumerate() {
                for p in self.row[b]..self.row[b + 1] {
                    let w = self.window[p] as usize;
                    for j in 0..self.sc {
                        part[w + j] += self.values[self.at(p, a, j)].into() * x[r];
                    }
                }
            }
        }
    }

    /// y ← y − A[:, F] x_F for the DOFs F in `dofs`, from A's rows of F (A square and
    /// symmetric: the same entries as the product's columns, so A − A[:, F] stays
    /// symmetric).
    pub fn sub_columns(&self, dofs: &[usize], x: &[f64], y: &mut [f64]) {
        debug_assert_eq!(self.s, self.sc);
        for &d in dofs {
            if x[d] != 0.0 {
                self.for_each_in_row(d, |j, v| y[j] -= v * x[d]);
            }
        }
    }

    /// The operator in scalar CSR, its nonzero entries widened to f64: for what reads an f64
    /// operator where only this copy is kept ([`super::multigrid::Hierarchy::operator_in_f64`]).
    pub fn to_csr(&self) -> Csr {
        let keep = vec![true; self.nrows()];
        Csr::from_rows(self.nrows(), self.ncols(), &keep, |i, push| {
            self.for_each_in_row(i, push)
        })
    }

    /// The block row holding row i.
    fn block_row(&self, i: usize) -> usize {
        self.ptr.partition_point(|&p| p <= i) - 1
    }

    /// f(j, a_ij) for the nonzero entries of row i, in increasing j. Zero entries are not
    /// listed: the padding cannot be told from a stored zero, and neither adds to a product.
    pub fn for_each_in_row(&self, i: usize, mut f: impl FnMut(usize, f64)) {
        let b = self.block_row(i);
        let r = i - self.ptr[b];
        for p in self.row[b]..self.row[b + 1] {
            let w = self.window[p] as usize;
            for j in 0..self.sc {
                let v: f64 = self.values[self.at(p, r, j)].into();
                if v != 0.0 {
                    f(w + j, v);
                }
            }
        }
    }

    /// A ← A + `delta` (square, A's size) in place, each changed entry rounded into T again
    /// (in f32 a perturbation of 2⁻²⁴ relative per call, as the copy made afresh has once).
    /// Every entry of `delta` has to lie in a stored block whose window is its block column's
    /// alone (not one moved back and shared at the end of the vector); where one does not,
    /// nothing changes and it returns false, and the caller forms the sum afresh.
    pub fn add_in_place(&mut self, delta: &Csr) -> bool {
        assert_eq!((delta.nrows, delta.ncols), (self.nrows(), self.ncols()));
        let position = |i: usize, j: usize| {
            let b = self.block_row(i);
            let c = self.col_ptr.partition_point(|&p| p <= j) - 1;
            let window = window_start(&self.col_ptr, self.sc, c) as u32;
            let slots = &self.window[self.row[b]..self.row[b + 1]];
            let first = slots.partition_point(|&w| w < window);
            let end = slots.partition_point(|&w| w <= window);
            (end == first + 1)
                .then(|| self.at(self.row[b] + first, i - self.ptr[b], j - window as usize))
        };
        let positions: Option<Vec<usize>> = (0..delta.nrows)
            .flat_map(|i| (delta.indptr[i]..delta.indptr[i + 1]).map(move |k| (i, k)))
            .map(|(i, k)| position(i, delta.indices[k] as usize))
            .collect();
        let Some(positions) = positions else {
            return false;
        };
        for (p, &v) in positions.into_iter().zip(&delta.values) {
            self.values[p] = T::from_f64(self.values[p].into() + v);
        }
        true
    }

    /// Entry (i, j), 0 when absent.
    pub fn get(&self, i: usize, j: usize) -> f64 {
        let sc = self.sc;
        let b = self.block_row(i);
        let r = i - self.ptr[b];
        // A column lies in one block column; a moved-back window may also cover it with
        // padding, which is zero, so the sum over every window that covers j is a_ij.
        (self.row[b]..self.row[b + 1])
            .filter(|&p| (self.window[p] as usize..self.window[p] as usize + sc).contains(&j))
            .map(|p| self.values[self.at(p, r, j - self.window[p] as usize)].into())
            .sum()
    }
}

impl<T: Entry> LinearOperator for BlockCsr<T> {
    fn dim(&self) -> usize {
        self.nrows()
    }

    fn apply(&self, x: &[f64], y: &mut [f64]) {
        self.mul_vec(x, y);
    }
}

/// Pieces of whole blocks of about [`par::ROW_CHUNK`] DOFs: (first block, first DOF) of each,
/// both ending with the totals.
fn split(ptr: &[usize]) -> (Vec<usize>, Vec<usize>) {
    let nb = ptr.len() - 1;
    let (mut blocks, mut dofs) = (vec![0], vec![0]);
    for (b, &start) in ptr.iter().enumerate().take(nb).skip(1) {
        if start - dofs.last().unwrap() >= par::ROW_CHUNK {
            blocks.push(b);
            dofs.push(start);
        }
    }
    blocks.push(nb);
    dofs.push(ptr[nb]);
    (blocks, dofs)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A symmetric pattern on 11 DOFs in blocks of 3, 2, 1, 3 and 2 DOFs with some block
    /// pairs absent and some blocks only partly filled.
    fn matrix() -> (Csr, Vec<usize>) {
        let ptr = [0usize, 3, 5, 6, 9, 11];
        let block = |i: usize| ptr.iter().rposition(|&p| p <= i).unwrap();
        let mut t = Vec::new();
        for i in 0..11 {
            for j in 0..11 {
                let (bi, bj) = (block(i), block(j));
                let far = bi.abs_diff(bj) > 2;
                let hole = (i * 7 + j * 7) % 5 == 1 && i != j;
                if !far && !hole {
                    t.push((
                        i,
                        j,
                        1.0 / (1.0 + i as f64 + j as f64) + if i == j { 4.0 } else { 0.0 },
                    ));
                }
            }
        }
        (Csr::from_triplets(11, 11, t), ptr.to_vec())
    }

    /// `a` with its entries rounded to f32.
    fn reference_matrix(a: &Csr) -> Csr {
        Csr {
            values: a.values.iter().map(|&v| v as f32 as f64).collect(),
            ..a.clone()
        }
    }

    fn reference(a: &Csr, x: &[f64]) -> Vec<f64> {
        let rounded = reference_matrix(a);
        let mut y = vec![0.0; a.nrows];
        rounded.mul_vec(x, &mut y);
        y
    }

    #[test]
    fn applies_the_rounded_operator_in_node_blocks_and_in_scalar_blocks() {
        let (a, blocks) = matrix();
        let x: Vec<f64> = (0..11).map(|i| (0.9 * i as f64).cos() + 0.3).collect();
        let expected = reference(&a, &x);
        let mixed_sizes = vec![0, 1, 2, 3, 4, 6, 7, 8, 11];
        for blocks in [blocks, (0..=11).collect(), mixed_sizes] {
            let b = BlockCsr32::new(&a, &blocks);
            assert_eq!(b.dim(), 11);
            let mut y = vec![f64::NAN; 11];
            b.mul_vec(&x, &mut y);
            for i in 0..11 {
                assert!(
                    (y[i] - expected[i]).abs() <= 1e-14 * expected[i].abs().max(1.0),
                    "row {i}: {} against {}",
                    y[i],
                    expected[i]
                );
            }
        }
    }

    #[test]
    fn a_row_adds_its_blocks_dot_products_in_block_and_column_order_bit_for_bit() {
        // Row r of block row b is Σ over the block columns c meeting b, in increasing c, of
        // ((a_r,w x_w + a_r,w+1 x_w+1) + …) over the S columns of c's window w: the sums of a
        // row-by-row product, whatever order the entries are stored in.
        let (a, ptr) = matrix();
        let x: Vec<f64> = (0..11).map(|i| (0.7 * i as f64).sin() + 0.2).collect();
        let block = |i: usize| ptr.iter().rposition(|&p| p <= i).unwrap();
        let s = 3;
        let mut in_f64 = vec![0.0; 11];
        BlockCsr::<f64>::new(&a, &ptr).mul_vec(&x, &mut in_f64);
        let mut in_f32 = vec![0.0; 11];
        BlockCsr32::new(&a, &ptr).mul_vec(&x, &mut in_f32);
        let widen = |v: f64| v as f32 as f64;
        for (y, round) in [(in_f64, (|v| v) as fn(f64) -> f64), (in_f32, widen)] {
            for r in 0..11 {
                let entry = |c: usize| {
                    let row = a.indptr[r]..a.indptr[r + 1];
                    let k = a.indices[row.clone()].iter().position(|&j| j as usize == c);
                    k.map_or(0.0, |k| round(a.values[row.start + k]))
                };
                let mut met: Vec<usize> = (a.indptr[ptr[block(r)]]..a.indptr[ptr[block(r) + 1]])
                    .map(|k| block(a.indices[k] as usize))
                    .collect();
                met.sort_unstable();
                met.dedup();
                let mut sum = 0.0;
                for c in met {
                    let w = ptr[c].min(11 - s);
                    let mut t = 0.0;
                    for (j, x) in x.iter().enumerate().skip(w).take(s) {
                        t += if block(j) == c { entry(j) } else { 0.0 } * x;
                    }
                    sum += t;
                }
                assert_eq!(y[r].to_bits(), sum.to_bits(), "row {r}");
            }
        }
    }

    /// A change on a's pattern (every third entry) and inside a stored block where a has
    /// no entry (one of the holes of [`matrix`]).
    fn change(a: &Csr) -> Csr {
        let mut t = Vec::new();
        for i in 0..a.nrows {
            for k in a.indptr[i]..a.indptr[i + 1] {
                if k % 3 == 0 {
                    t.push((i, a.indices[k] as usize, 0.37 * a.values[k] - 0.01));
                }
            }
        }
        assert_eq!(a.get(1, 2), 0.0, "a hole inside the first diagonal block");
        t.push((1, 2, 0.125));
        Csr::from_triplets(a.nrows, a.ncols, t)
    }

    #[test]
    fn a_change_added_in_place_is_the_sum_rounded_again() {
        let (a, ptr) = matrix();
        let delta = change(&a);
        let mut single = BlockCsr32::new(&a, &ptr);
        let mut double = BlockCsr::<f64>::new(&a, &ptr);
        assert!(single.add_in_place(&delta) && double.add_in_place(&delta));
        for i in 0..11 {
            for j in 0..11 {
                let d = delta.get(i, j);
                let rounded_again = (a.get(i, j) as f32 as f64 + d) as f32 as f64;
                assert_eq!(single.get(i, j), rounded_again, "({i}, {j})");
                assert_eq!(double.get(i, j), a.get(i, j) + d, "({i}, {j})");
            }
        }
    }

    #[test]
    fn a_change_outside_the_stored_blocks_or_in_a_shared_window_is_refused_whole() {
        let (a, ptr) = matrix();
        let mut delta = change(&a);
        // Blocks 0 and 4 are more than two blocks apart: no block is stored there.
        delta = crate::linalg::galerkin::add(
            1.0,
            &delta,
            1.0,
            &Csr::from_triplets(11, 11, vec![(0, 9, 1.0)]),
        );
        let mut b = BlockCsr32::new(&a, &ptr);
        let before = b.values.clone();
        assert!(!b.add_in_place(&delta));
        assert_eq!(b.values, before, "nothing added before the refusal");
        // Blocks of 3, 1 and 1 DOFs: the last two share the window 2..5.
        let full = Csr::from_triplets(
            5,
            5,
            (0..5)
                .flat_map(|i| (0..5).map(move |j| (i, j, 1.0)))
                .collect(),
        );
        let mut shared = BlockCsr32::new(&full, &[0, 3, 4, 5]);
        let before = shared.values.clone();
        assert!(!shared.add_in_place(&Csr::from_triplets(5, 5, vec![(0, 4, 1.0)])));
        assert_eq!(shared.values, before);
        assert!(shared.add_in_place(&Csr::from_triplets(5, 5, vec![(4, 1, 1.0)])));
        assert_eq!(shared.get(4, 1), 2.0);
    }

    #[test]
    fn differs_from_the_double_operator_by_single_rounding_only() {
        let (a, blocks) = matrix();
        let x: Vec<f64> = (0..11).map(|i| 1.0 + (i as f64).sin()).collect();
        let mut exact = vec![0.0; 11];
        a.mul_vec(&x, &mut exact);
        let mut y = vec![0.0; 11];
        BlockCsr32::new(&a, &blocks).mul_vec(&x, &mut y);
        let bound: Vec<f64> = (0..11)
            .map(|r| {
                let row = a.indptr[r]..a.indptr[r + 1];
                a.indices[row.clone()]
                    .iter()
                    .zip(&a.values[row])
                    .map(|(&c, v)| (v * x[c as usize]).abs())
                    .sum::<f64>()
                    * f32::EPSILON as f64
            })
            .collect();
        let mut differs = false;
        for i in 0..11 {
            assert!((y[i] - exact[i]).abs() <= bound[i], "row {i}");
            differs |= y[i] != exact[i];
        }
        assert!(differs, "the entries were not rounded");
    }

    #[test]
    fn gives_the_same_bits_on_any_number_of_threads() {
        // Large enough for several pieces (ROW_CHUNK is 32 under test).
        let n: usize = 3 * 200;
        let mut t = Vec::new();
        for i in 0..n {
            for j in [i.saturating_sub(7), i, (i + 5).min(n - 1)] {
                t.push((i, j, 1.0 + 0.01 * (i + 2 * j) as f64));
                t.push((j, i, 1.0 + 0.01 * (i + 2 * j) as f64));
            }
        }
        let a = Csr::from_triplets(n, n, t);
        let blocks: Vec<usize> = (0..=n / 3).map(|b| 3 * b).collect();
        let b = BlockCsr32::new(&a, &blocks);
        let x: Vec<f64> = (0..n).map(|i| (i as f64 * 0.37).sin()).collect();
        let run = |threads: usize| {
            par::Threads::new(threads).install(|| {
                let mut y = vec![0.0; n];
                b.mul_vec(&x, &mut y);
                y
            })
        };
        let one = run(1);
        assert_eq!(one, run(2));
        assert_eq!(one, run(3));
        // The blocked sums group the terms differently from the scalar rows.
        for (i, (e, v)) in reference(&a, &x).iter().zip(&one).enumerate() {
            assert!((e - v).abs() <= 1e-13 * e.abs().max(1.0), "row {i}");
        }
    }

    /// A prolongator-like 40 × 27 matrix in blocks of 3 rows (2 for some, like Γ3 nodes) by
    /// 6 columns (the last aggregate of 3), and in 1 × 1, 6 × 6 and 4 × 5 blocks (each
    /// kernel of the product and the transpose product): its product and its transpose
    /// product by pieces are those of the rounded entries in scalar CSR, row by row and for
    /// any thread count.
    #[test]
    fn rectangular_blocks_multiply_and_restrict_like_scalar_rows() {
        let every = |step: usize, end: usize| -> Vec<usize> {
            (0..end).step_by(step).chain([end]).collect()
        };
        let rows: Vec<usize> = (0..=40)
            .filter(|&r| r % 3 == 0 || r == 40 || r == 20)
            .collect();
        multiply_and_restrict_like_scalar_rows(&rows, &[0, 6, 12, 18, 24, 27]);
        multiply_and_restrict_like_scalar_rows(&every(1, 40), &every(1, 27));
        multiply_and_restrict_like_scalar_rows(&every(6, 40), &every(6, 27));
        multiply_and_restrict_like_scalar_rows(&every(4, 40), &every(5, 27));
    }

    fn multiply_and_restrict_like_scalar_rows(rows: &[usize], cols: &[usize]) {
        let (n, m) = (40, 27);
        let col_blocks = cols.len() - 1;
        let mut t = Vec::new();
        for i in 0..n {
            let home = (i * col_blocks / n).min(col_blocks - 1);
            for j in 0..m {
                let block = cols.iter().rposition(|&c| c <= j).unwrap();
                if block.abs_diff(home) <= 1 && (i + 2 * j) % 7 != 3 {
                    t.push((i, j, 0.1 + ((i * 13 + j * 7) % 11) as f64 / 9.0));
                }
            }
        }
        let a = Csr::from_triplets(n, m, t);
        let rounded = reference_matrix(&a);
        let b = BlockCsr32::rectangular(&a, rows, cols);
        assert_eq!((b.nrows(), b.ncols()), (n, m));
        // Widened back, the same pattern and the rounded entries.
        let widened = b.to_csr();
        assert_eq!(widened.indptr, rounded.indptr);
        assert_eq!(widened.indices, rounded.indices);
        assert_eq!(widened.values, rounded.values);
        let xc: Vec<f64> = (0..m).map(|j| (0.7 * j as f64).cos()).collect();
        let x: Vec<f64> = (0..n).map(|i| (0.3 * i as f64).sin() + 0.1).collect();
        let mut want = vec![0.0; n];
        rounded.mul_vec(&xc, &mut want);
        let mut want_t = vec![0.0; m];
        crate::linalg::galerkin::transpose(&rounded).mul_vec(&x, &mut want_t);
        let run = |threads: usize| {
            par::Threads::new(threads).install(|| {
                let (mut y, mut yt) = (vec![f64::NAN; n], vec![f64::NAN; m]);
                b.mul_vec(&xc, &mut y);
                b.tmul_vec_by_pieces(&x, &mut yt, &mut vec![f64::NAN; TRANSPOSE_PIECES * m]);
                (y, yt)
            })
        };
        let (y, yt) = run(1);
        assert_eq!((y.clone(), yt.clone()), run(2));
        assert_eq!((y.clone(), yt.clone()), run(3));
        for (got, want) in [(&y, &want), (&yt, &want_t)] {
            for (i, (g, w)) in got.iter().zip(want.iter()).enumerate() {
                assert!((g - w).abs() <= 1e-13 * w.abs().max(1.0), "entry {i}");
            }
        }
        for i in 0..n {
            let mut listed = Vec::new();
            b.for_each_in_row(i, |j, v| listed.push((j, v)));
            let row = rounded.indptr[i]..rounded.indptr[i + 1];
            let stored: Vec<(usize, f64)> = rounded.indices[row.clone()]
                .iter()
                .zip(&rounded.values[row])
                .map(|(&j, &v)| (j as usize, v))
                .collect();
            assert_eq!(listed, stored, "row {i}");
        }
    }

    #[test]
    fn removing_columns_equals_the_product_with_those_entries_of_x_zeroed() {
        let (a, blocks) = matrix();
        let b = BlockCsr32::new(&a, &blocks);
        let x: Vec<f64> = (0..11).map(|i| 0.5 + (1.3 * i as f64).sin()).collect();
        let fixed = [0usize, 4, 5, 10];
        let mut masked = x.clone();
        fixed.iter().for_each(|&d| masked[d] = 0.0);
        let mut expected = vec![0.0; 11];
        b.mul_vec(&masked, &mut expected);
        let mut y = vec![0.0; 11];
        b.mul_vec(&x, &mut y);
        b.sub_columns(&fixed, &x, &mut y);
        for i in 0..11 {
            assert!(
                (y[i] - expected[i]).abs() <= 1e-14 * (1.0 + expected[i].abs()),
                "row {i}"
            );
        }
    }
}
