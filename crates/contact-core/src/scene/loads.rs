//! The `loads` (body force f0) and `initial` (displacement u0) sections: vector fields.

use serde_json::Value;

use super::fields::{INITIAL_FIELDS, LOADS_FIELDS};
use super::formulas::{vector_field, Sampled};
use super::read::{join, object, Cx};
use crate::problem::VectorField;

/// The body force f0(x, y, t); zero when absent.
pub(super) fn loads(
    cx: &mut Cx,
    v: &Value,
    ptr: &str,
    sampled: &mut Vec<Sampled>,
) -> Option<VectorField> {
    let m = object(cx, v, ptr, "loads", LOADS_FIELDS)?;
    match m.get("f0") {
        None => Some(VectorField::constant([0.0, 0.0])),
        Some(f0) => vector_field(cx, f0, &join(ptr, "f0"), true, None, sampled),
    }
}

/// The initial displacement u0(x, y); zero when absent.
pub(super) fn initial(
    cx: &mut Cx,
    v: &Value,
    ptr: &str,
    sampled: &mut Vec<Sampled>,
) -> Option<VectorField> {
    let m = object(cx, v, ptr, "initial", INITIAL_FIELDS)?;
    match m.get("u0") {
        None => Some(VectorField::constant([0.0, 0.0])),
        Some(u0) => vector_field(cx, u0, &join(ptr, "u0"), false, None, sampled),
    }
}
