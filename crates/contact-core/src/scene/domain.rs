//! The `domain` section: the rectangle [0, W] × [0, H].

use serde_json::Value;

use super::fields::{DOMAIN_FIELDS, RECTANGLE_FIELDS};
use super::read::{join, object, required_number, Cx, Range};

/// (W, H) from `{width, height}` or `{"rectangle": {width, height}}`, both > 0.
pub(super) fn domain(cx: &mut Cx, v: &Value, ptr: &str) -> Option<(f64, f64)> {
    let m = object(cx, v, ptr, "domain", DOMAIN_FIELDS)?;
    let (m, ptr) = match m.get("rectangle") {
        Some(r) => {
            let rptr = join(ptr, "rectangle");
            if m.contains_key("width") || m.contains_key("height") {
                cx.err(
                    &rptr,
                    "give either width and height, or a rectangle {width, height}, not both",
                );
                return None;
            }
            (object(cx, r, &rptr, "rectangle", RECTANGLE_FIELDS)?, rptr)
        }
        None => (m, ptr.to_string()),
    };
    let w = required_number(cx, m, &ptr, "width", Range::Positive, "length along x");
    let h = required_number(cx, m, &ptr, "height", Range::Positive, "length along y");
    Some((w?, h?))
}
