//! The true error of an adaptive study's runs: each run's w, interpolated onto the
//! reference's mesh, against the reference's w.
//!
//! The reference is the initial mesh with every cell bisected `depth` times
//! ([`uniform`]). The bisection forest of a cell does not depend on how it was reached
//! ([`crate::mesh::bisect`]), so bisecting an adaptive mesh whose cells are at most `depth`
//! bisections deep until every cell is `depth` deep gives the reference mesh itself, nodes
//! in another order; carrying a P1 field through those bisections (a new node takes the mean
//! of its edge's ends) is exact, and matching nodes by their coordinates' bits (a midpoint is
//! computed the same way on every path) puts it in the reference's node order.

use super::Row;
use crate::fem::{norms, Geometry};
use crate::mesh::bisect::Bisection;
use crate::mesh::Mesh;
use crate::output::Summary;
use std::collections::HashMap;

/// Which steps' w are kept for the true error: every `every`-th and the last, so that the
/// reference's kept fields stay within [`crate::study::SNAPSHOT_BUDGET_BYTES`].
#[derive(Debug, Clone, Copy)]
pub(super) struct Kept {
    every: usize,
    steps: usize,
}

impl Kept {
    /// Every step when N fields of `values` f64 fit the budget, else evenly thinned.
    pub(super) fn within(steps: usize, values: usize) -> Kept {
        let fit = (crate::study::SNAPSHOT_BUDGET_BYTES / (8 * values.max(1))).max(1);
        Kept {
            every: steps.div_ceil(fit).max(1),
            steps,
        }
    }

    pub(super) fn has(&self, n: usize) -> bool {
        n.is_multiple_of(self.every) || n == self.steps
    }
}

/// `initial` with every cell bisected `depth` times (and the closure's few more).
pub(super) fn uniform<const D: usize>(initial: &Mesh<D>, depth: usize) -> Bisection<D> {
    let mut b = Bisection::new(initial);
    deepen(&mut b, depth, &mut []);
    b
}

/// Bisects the cells of `b` less than `depth` deep until there are none, carrying the P1
/// fields `fields` (D values a node) along.
fn deepen<const D: usize>(b: &mut Bisection<D>, depth: usize, fields: &mut [Vec<f64>]) {
    loop {
        let shallow: Vec<usize> = (0..b.mesh().n_cells())
            .filter(|&c| b.generation(c) < depth)
            .collect();
        if shallow.is_empty() {
            return;
        }
        let step = b.refine(&shallow);
        for f in fields.iter_mut() {
            for &(_, [a, c]) in &step.midpoints {
                for k in 0..D {
                    let v = 0.5 * (f[a * D + k] + f[c * D + k]);
                    f.push(v);
                }
            }
        }
    }
}

fn bits<const D: usize>(p: [f64; D]) -> [u64; D] {
    p.map(f64::to_bits)
}

/// The reference run: its mesh, the bisection depth, w at the kept steps and
/// (Σ_kept |w_n|²_V)^½.
pub(super) struct Reference<const D: usize> {
    depth: usize,
    mesh: Mesh<D>,
    geo: Geometry<D>,
    index: HashMap<[u64; D], usize>,
    w: Vec<Vec<f64>>,
    norm: f64,
    pub(super) keep: Kept,
    /// Its row in the result (no true error).
    pub(super) row: Row,
}

impl<const D: usize> Reference<D> {
    pub(super) fn new(
        uniform: Bisection<D>,
        w: Vec<Vec<f64>>,
        keep: Kept,
        summary: &Summary,
        seconds: f64,
    ) -> Reference<D> {
        let depth = (0..uniform.mesh().n_cells())
            .map(|c| uniform.generation(c))
            .min()
            .unwrap_or(0);
        let mesh = uniform.mesh().clone();
        let geo = Geometry::new(&mesh);
        let index = mesh
            .nodes
            .iter()
            .enumerate()
            .map(|(i, &p)| (bits(p), i))
            .collect();
        let norm = w
            .iter()
            .map(|v| norms::strain_norm(&mesh, &geo, v).powi(2))
            .sum::<f64>()
            .sqrt();
        Reference {
            depth,
            row: Row::new(summary, depth, seconds, None),
            mesh,
            geo,
            index,
            w,
            norm,
            keep,
        }
    }

    /// (Σ_kept |w_ref,n − I w_n|²_V)^½ / (Σ_kept |w_ref,n|²_V)^½ of the run on `b`'s mesh
    /// with w `w` at the kept steps; None when `b` is not nested in the reference (refined
    /// somewhere beyond it: bisected to the reference's depth it has nodes the reference
    /// lacks).
    pub(super) fn error(&self, b: &Bisection<D>, w: &[Vec<f64>]) -> Option<f64> {
        let mut fine = b.clone();
        let mut fields = w.to_vec();
        deepen(&mut fine, self.depth, &mut fields);
        let mesh = fine.mesh();
        if mesh.n_nodes() != self.mesh.n_nodes() {
            return None;
        }
        let mut at = Vec::with_capacity(mesh.n_nodes());
        for &p in &mesh.nodes {
            at.push(*self.index.get(&bits(p))?);
        }
        let mut sum = 0.0;
        let mut d = vec![0.0; D * self.mesh.n_nodes()];
        for (f, r) in fields.iter().zip(&self.w) {
            for (i, &j) in at.iter().enumerate() {
                for k in 0..D {
                    d[j * D + k] = r[j * D + k] - f[i * D + k];
                }
            }
            sum += norms::strain_norm(&self.mesh, &self.geo, &d).powi(2);
        }
        Some(if sum == 0.0 {
            0.0
        } else {
            sum.sqrt() / self.norm
        })
    }
}
