//! The `output` section: which steps and fields a run stores, and whether it estimates its
//! error a posteriori.

use serde_json::Value;

use super::fields::{OUTPUT_FIELDS, OUTPUT_FIELD_NAMES};
use super::read::{choice, describe, index, integer, join, object, Cx};
use crate::problem::{FieldSet, OutputSpec};

/// Longest list of output field names (there are six; repeats are harmless).
pub(super) const MAX_OUTPUT_FIELDS: usize = 64;

/// Which steps (every, last) and fields a run stores.
pub(super) fn output(cx: &mut Cx, v: &Value, ptr: &str) -> Option<OutputSpec> {
    let m = object(cx, v, ptr, "output", OUTPUT_FIELDS)?;
    let every = match m.get("every") {
        None => Some(1),
        Some(e) => integer(cx, e, &join(ptr, "every"), 0).map(|n| n as usize),
    };
    let last = match m.get("last") {
        None => Some(true),
        Some(Value::Bool(b)) => Some(*b),
        Some(other) => {
            cx.err(
                &join(ptr, "last"),
                format!("last must be true or false, got {}", describe(other)),
            );
            None
        }
    };
    let estimate = match m.get("estimate") {
        None => Some(false),
        Some(Value::Bool(b)) => Some(*b),
        Some(other) => {
            cx.err(
                &join(ptr, "estimate"),
                format!(
                    "estimate must be true (compute the a posteriori error estimate of every step) or false, got {}",
                    describe(other)
                ),
            );
            None
        }
    };
    let fields = match m.get("fields") {
        None => Some(all_fields()),
        Some(f) => output_fields(cx, f, &join(ptr, "fields")),
    };
    Some(OutputSpec {
        every: every?,
        last: last?,
        fields: fields?,
        estimate: estimate?,
    })
}

/// Every field (the default).
pub(super) fn all_fields() -> FieldSet {
    FieldSet {
        u: true,
        w: true,
        zeta: true,
        sigma: true,
        von_mises: true,
        contact: true,
    }
}

/// The names of the stored fields.
fn output_fields(cx: &mut Cx, v: &Value, ptr: &str) -> Option<FieldSet> {
    let Some(items) = v.as_array() else {
        cx.err(
            ptr,
            format!(
                "fields must be an array of names from {}, got {}",
                OUTPUT_FIELD_NAMES.join(", "),
                describe(v)
            ),
        );
        return None;
    };
    if items.len() > MAX_OUTPUT_FIELDS {
        cx.err(
            ptr,
            format!(
                "fields must list at most {MAX_OUTPUT_FIELDS} names (from {}), got {}",
                OUTPUT_FIELD_NAMES.join(", "),
                describe(v)
            ),
        );
        return None;
    }
    let mut set = FieldSet::default();
    let mut ok = true;
    for (i, item) in items.iter().enumerate() {
        match choice(
            cx,
            item,
            &index(ptr, i),
            "an output field",
            OUTPUT_FIELD_NAMES,
        ) {
            Some(0) => set.u = true,
            Some(1) => set.w = true,
            Some(2) => set.zeta = true,
            Some(3) => set.sigma = true,
            Some(4) => set.von_mises = true,
            Some(_) => set.contact = true,
            None => ok = false,
        }
    }
    ok.then_some(set)
}
