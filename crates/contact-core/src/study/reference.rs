//! Reference ("true") runs and their cache. Several studies of one scene (Tables 1 and 2
//! share h = k = 1/128) compare with the same reference; it is computed once per process and
//! kept, keyed by a content hash of the scene and the reference resolution.

use super::levels::{LevelRun, RunStats};
use crate::fem::{assembly, norms, Geometry};
use crate::linalg::Csr;
use crate::mesh::{Mesh, SharedMesh};
use std::any::Any;
use std::collections::{BTreeSet, VecDeque};
use std::sync::{Arc, Mutex};

/// A finished reference run reduced to what comparisons need: per kept step the strain
/// ε(w) on every cell (w itself is never needed: errors in |·|_V compare strains) and ζ,
/// with the norms |w|_V and |ζ|_Z0; the mesh, its geometry and mass matrix.
pub struct Reference<const D: usize = 2> {
    pub mesh: SharedMesh<D>,
    pub geo: Geometry<D>,
    pub mass: Csr,
    pub unknowns: usize,
    pub steps: usize,
    pub seconds: f64,
    pub stats: RunStats,
    /// In increasing step order.
    pub snapshots: Vec<RefSnapshot>,
    pub w_norms: Vec<f64>,
    pub zeta_norms: Vec<f64>,
}

pub struct RefSnapshot {
    pub step: usize,
    /// The [`sym_len`] independent components of ε per cell, cell after cell
    /// ([`strains`]).
    pub strain: Vec<f64>,
    pub zeta: Vec<f64>,
}

/// Independent components of a symmetric D × D tensor: 3 in 2D, 6 in 3D.
pub const fn sym_len(d: usize) -> usize {
    d * (d + 1) / 2
}

/// ε of the nodal field `w` on every cell, as [`sym_len`]`(D)` numbers per cell: the
/// diagonal (xx, yy[, zz]) first, then the off-diagonal entries (xy[, yz, xz]).
pub fn strains<const D: usize>(mesh: &Mesh<D>, geo: &Geometry<D>, w: &[f64]) -> Vec<f64> {
    let mut out = Vec::with_capacity(sym_len(D) * mesh.n_cells());
    for t in 0..mesh.n_cells() {
        let e = geo.strain(mesh, t, w);
        out.extend((0..D).map(|i| e[(i, i)]));
        out.extend(
            (1..D)
                .flat_map(|off| (0..D - off).map(move |i| (i, i + off)))
                .map(|ij| e[ij]),
        );
    }
    out
}

/// ε:ε of a symmetric tensor stored as [`strains`] stores it: each off-diagonal entry
/// counts twice.
#[inline]
pub fn double_dot<const D: usize>(e: &[f64]) -> f64 {
    let (diagonal, off) = e.split_at(D);
    diagonal.iter().map(|x| x * x).sum::<f64>() + 2.0 * off.iter().map(|x| x * x).sum::<f64>()
}

impl<const D: usize> Reference<D> {
    pub fn new(run: LevelRun<D>) -> Reference<D> {
        let LevelRun {
            mesh,
            unknowns,
            steps,
            seconds,
            stats,
            snapshots,
        } = run;
        let geo = Geometry::new(&mesh);
        let mass = assembly::mass(&mesh, &geo);
        let mut scratch = vec![0.0; mesh.n_nodes()];
        let mut w_norms = Vec::with_capacity(snapshots.len());
        let mut zeta_norms = Vec::with_capacity(snapshots.len());
        let snapshots = snapshots
            .into_iter()
            .map(|s| {
                let strain = strains(&mesh, &geo, &s.w);
                let w2: f64 = strain
                    .chunks_exact(sym_len(D))
                    .zip(geo.measures())
                    .map(|(e, a)| a * double_dot::<D>(e))
                    .sum();
                w_norms.push(w2.sqrt());
                zeta_norms.push(norms::mass_norm(&mass, &s.zeta, &mut scratch));
                RefSnapshot {
                    step: s.step,
                    strain,
                    zeta: s.zeta,
                }
            })
            .collect();
        Reference {
            mesh,
            geo,
            mass,
            unknowns,
            steps,
            seconds,
            stats,
            snapshots,
            w_norms,
            zeta_norms,
        }
    }

    pub fn snapshot_steps(&self) -> BTreeSet<usize> {
        self.snapshots.iter().map(|s| s.step).collect()
    }

    /// Index of the snapshot at `step`.
    pub fn index(&self, step: usize) -> Option<usize> {
        self.snapshots.binary_search_by_key(&step, |s| s.step).ok()
    }
}

/// A cached reference: a [`Reference<D>`] of the scene's dimension (the key, a hash of the
/// scene, fixes D).
pub type Slot = Arc<Mutex<Option<Arc<dyn Any + Send + Sync>>>>;

/// At most `capacity` references, least recently used evicted first.
pub struct ReferenceCache {
    capacity: usize,
    slots: Mutex<VecDeque<(String, Slot)>>,
}

impl ReferenceCache {
    pub fn new(capacity: usize) -> ReferenceCache {
        ReferenceCache {
            capacity,
            slots: Mutex::new(VecDeque::new()),
        }
    }

    /// The slot for `key` (created empty if unknown). An empty key is never shared.
    pub fn slot(&self, key: &str) -> Slot {
        if key.is_empty() || self.capacity == 0 {
            return Slot::default();
        }
        let mut slots = self.slots.lock().unwrap_or_else(|e| e.into_inner());
        let slot = match slots.iter().position(|(k, _)| k == key) {
            Some(i) => slots.remove(i).expect("present").1,
            None => Slot::default(),
        };
        slots.push_front((key.to_string(), slot.clone()));
        slots.truncate(self.capacity);
        slot
    }

    /// Keys currently held, most recently used first.
    pub fn keys(&self) -> Vec<String> {
        let slots = self.slots.lock().unwrap_or_else(|e| e.into_inner());
        slots.iter().map(|(k, _)| k.clone()).collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn slots_are_shared_by_key_and_evicted_least_recently_used() {
        let c = ReferenceCache::new(2);
        let a = c.slot("a");
        assert!(Arc::ptr_eq(&a, &c.slot("a")));
        c.slot("b");
        c.slot("a");
        c.slot("c");
        assert_eq!(c.keys(), vec!["c", "a"]);
        assert!(!Arc::ptr_eq(&c.slot("b"), &c.slot("x")));
        assert!(!Arc::ptr_eq(&c.slot(""), &c.slot("")));
    }
}
