//! The `loads` (body force f0) and `initial` (displacement u0) sections: each holds one
//! optional vector field, zero when the section or the field is absent.

use serde_json::{Map, Value};

use super::fields::{INITIAL_FIELDS, LOADS_FIELDS};
use super::formulas::{vector_field, Sampled};
use super::read::{join, object, Cx};
use crate::problem::VectorField;

/// A section holding one vector field.
pub(super) struct VectorSection {
    /// The section's key in the scene.
    name: &'static str,
    /// The keys it accepts.
    fields: &'static [&'static str],
    /// The field's key.
    key: &'static str,
    /// Whether the field may depend on t.
    time_dependent: bool,
}

/// The body force f0(x, y, z, t).
pub(super) const LOADS: VectorSection = VectorSection {
    name: "loads",
    fields: LOADS_FIELDS,
    key: "f0",
    time_dependent: true,
};

/// The initial displacement u0(x, y, z).
pub(super) const INITIAL: VectorSection = VectorSection {
    name: "initial",
    fields: INITIAL_FIELDS,
    key: "u0",
    time_dependent: false,
};

/// The field of section `s` of the scene object `top` (a formula is queued for sampling).
pub(super) fn vector_section(
    cx: &mut Cx,
    top: &Map<String, Value>,
    s: &VectorSection,
    sampled: &mut Vec<Sampled>,
    dim: usize,
) -> Option<VectorField> {
    let Some(v) = top.get(s.name) else {
        return Some(VectorField::constant([0.0, 0.0]));
    };
    let ptr = format!("/{}", s.name);
    let m = object(cx, v, &ptr, s.name, s.fields)?;
    match m.get(s.key) {
        None => Some(VectorField::constant([0.0, 0.0])),
        Some(f) => vector_field(
            cx,
            f,
            &join(&ptr, s.key),
            s.time_dependent,
            None,
            sampled,
            dim,
        ),
    }
}
