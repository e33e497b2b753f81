//! Overrides of the discretisation (h, k, t_end) from a command line or a request, written
//! into the scene document before validation.

use serde_json::{Map, Value};

/// Command-line (or request) overrides of the discretisation, applied to the JSON document
/// before validation so that their errors are reported at the usual pointers.
#[derive(Debug, Clone, Default)]
pub struct Overrides {
    /// Replaces `/mesh/h`.
    pub h: Option<Value>,
    /// Replaces `/time/k` and removes `/time/N` and `/time/steps`.
    pub k: Option<Value>,
    /// Replaces `/time/t_end` and removes its alias `/time/T`. With only this override and a
    /// scene that gives k, the number of steps follows from the new t_end; with a scene that
    /// gives N, the step k = t_end/N changes instead.
    pub t_end: Option<Value>,
}

/// Writes the overrides into the document. A document or section of the wrong type is left
/// alone: validation reports it.
pub fn apply_overrides(doc: &mut Value, o: &Overrides) {
    let Some(top) = doc.as_object_mut() else {
        return;
    };
    if let Some(h) = &o.h {
        if let Some(mesh) = section(top, "mesh") {
            mesh.insert("h".into(), h.clone());
        }
    }
    if let Some(k) = &o.k {
        if let Some(time) = section(top, "time") {
            time.remove("N");
            time.remove("steps");
            time.insert("k".into(), k.clone());
        }
    }
    if let Some(t_end) = &o.t_end {
        if let Some(time) = section(top, "time") {
            time.remove("T");
            time.insert("t_end".into(), t_end.clone());
        }
    }
}

fn section<'a>(top: &'a mut Map<String, Value>, key: &str) -> Option<&'a mut Map<String, Value>> {
    top.entry(key)
        .or_insert_with(|| Value::Object(Map::new()))
        .as_object_mut()
}
