//! A symmetric tensor field constant on each cell (B_{n−1} of the time step), stored as each
//! tensor's upper triangle: D(D + 1)/2 numbers a cell instead of D², 48 bytes of a
//! tetrahedron's 72.
//!
//! The tensors stored are symmetric to the bit (the strain is formed symmetric, and the
//! elastic laws act on its entries alike), so a tensor read back is the one stored.

use crate::laws::Tensor;
use crate::linalg::par;

/// One symmetric D × D tensor per cell, by its upper triangle in row order.
#[derive(Debug, Clone, PartialEq)]
pub struct CellTensors<const D: usize> {
    upper: Vec<f64>,
}

impl<const D: usize> CellTensors<D> {
    /// Numbers stored per cell.
    const STRIDE: usize = D * (D + 1) / 2;

    /// `cells` zero tensors.
    pub fn zeros(cells: usize) -> CellTensors<D> {
        CellTensors {
            upper: vec![0.0; cells * Self::STRIDE],
        }
    }

    /// Cells held.
    pub fn len(&self) -> usize {
        self.upper.len() / Self::STRIDE
    }

    pub fn is_empty(&self) -> bool {
        self.upper.is_empty()
    }

    /// Cell e's tensor.
    #[inline]
    pub fn get(&self, e: usize) -> Tensor<D> {
        let t = &self.upper[Self::STRIDE * e..Self::STRIDE * (e + 1)];
        let mut m = Tensor::<D>::zeros();
        let mut k = 0;
        for i in 0..D {
            for j in i..D {
                m[(i, j)] = t[k];
                m[(j, i)] = t[k];
                k += 1;
            }
        }
        m
    }

    /// Every cell's tensor ← `f(e)` (its upper triangle), in fixed chunks of cells on the
    /// pool's threads.
    pub fn fill(&mut self, f: impl Fn(usize) -> Tensor<D> + Sync + Send) {
        par::for_each_chunk_mut(
            &mut self.upper,
            Self::STRIDE * par::ROW_CHUNK,
            |first, chunk| {
                for (i, t) in chunk.chunks_exact_mut(Self::STRIDE).enumerate() {
                    let m = f(first / Self::STRIDE + i);
                    let mut k = 0;
                    for r in 0..D {
                        for c in r..D {
                            t[k] = m[(r, c)];
                            k += 1;
                        }
                    }
                }
            },
        );
    }

    /// The bytes it holds.
    pub fn bytes(&self) -> usize {
        8 * self.upper.len()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::linalg::par::Threads;

    /// A symmetric tensor per cell, different in every entry.
    fn tensor<const D: usize>(e: usize) -> Tensor<D> {
        Tensor::<D>::from_fn(|r, c| ((7 * e + 3 * r.min(c) + r.max(c)) as f64).sin())
    }

    fn round_trip<const D: usize>() {
        let n = 3 * par::ROW_CHUNK + 5;
        let mut t = CellTensors::<D>::zeros(n);
        assert_eq!((t.len(), t.bytes()), (n, 8 * n * D * (D + 1) / 2));
        for threads in [1, 2, 3] {
            Threads::new(threads).install(|| t.fill(tensor::<D>));
            for e in 0..n {
                let (got, want) = (t.get(e), tensor::<D>(e));
                assert!(
                    got.iter()
                        .zip(want.iter())
                        .all(|(a, b)| a.to_bits() == b.to_bits()),
                    "cell {e}, {threads} threads"
                );
            }
        }
    }

    #[test]
    fn symmetric_tensors_read_back_bit_for_bit_in_2d_and_3d() {
        round_trip::<2>();
        round_trip::<3>();
    }
}
