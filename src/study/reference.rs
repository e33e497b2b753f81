//! Reference ("true") runs and their cache. Several studies of one scene (Tables 1 and 2
//! share h = k = 1/128) compare with the same reference; it is computed once per process and
//! kept, keyed by a content hash of the scene and the reference resolution.

use super::levels::LevelRun;
use crate::fem::{assembly, norms, Geometry};
use crate::linalg::Csr;
use std::collections::VecDeque;
use std::sync::{Arc, Mutex};

/// A finished reference run with what every comparison needs: its geometry, mass matrix and
/// the norms |w(t)|_V, |ζ(t)|_Z0 at its kept steps.
pub struct Reference {
    pub run: LevelRun,
    pub geo: Geometry,
    pub mass: Csr,
    /// Per snapshot (same order): |w|_V and |ζ|_Z0.
    pub w_norms: Vec<f64>,
    pub zeta_norms: Vec<f64>,
}

impl Reference {
    pub fn new(run: LevelRun) -> Reference {
        let geo = Geometry::new(&run.mesh);
        let mass = assembly::mass(&run.mesh, &geo);
        let mut scratch = vec![0.0; run.mesh.n_nodes()];
        let w_norms = run
            .snapshots
            .iter()
            .map(|s| norms::strain_norm(&run.mesh, &geo, &s.w))
            .collect();
        let zeta_norms = run
            .snapshots
            .iter()
            .map(|s| norms::mass_norm(&mass, &s.zeta, &mut scratch))
            .collect();
        Reference {
            run,
            geo,
            mass,
            w_norms,
            zeta_norms,
        }
    }

    /// Index of the snapshot at `step`.
    pub fn index(&self, step: usize) -> Option<usize> {
        self.run
            .snapshots
            .binary_search_by_key(&step, |s| s.step)
            .ok()
    }
}

pub type Slot = Arc<Mutex<Option<Arc<Reference>>>>;

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
