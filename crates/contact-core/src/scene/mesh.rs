//! The `mesh` section: n = round(1/h) cells per unit length and the triangle pattern.

use serde_json::Value;

use super::fields::{MESH_FIELDS, PATTERNS};
use super::read::{choice, join, object, ratio, required, Cx, Range};
use super::WHOLE_TOL;
use crate::problem::MeshPattern;

/// Most cells per side: a representability guard (not a resource limit, which belongs to the
/// service), far inside the range where `usize` conversions are safe.
const MAX_CELLS_PER_SIDE: f64 = 1.0e6;

/// (n, pattern) with n = round(1/h); W·n and H·n must be whole.
pub(super) fn mesh(
    cx: &mut Cx,
    v: &Value,
    ptr: &str,
    dims: Option<(f64, f64)>,
) -> Option<(usize, MeshPattern)> {
    let m = object(cx, v, ptr, "mesh", MESH_FIELDS)?;
    let pattern = match m.get("pattern") {
        None => Some(MeshPattern::Diagonal),
        Some(p) => choice(cx, p, &join(ptr, "pattern"), "pattern", PATTERNS).map(|i| match i {
            0 => MeshPattern::Diagonal,
            1 => MeshPattern::AntiDiagonal,
            _ => MeshPattern::Cross,
        }),
    };
    let hptr = join(ptr, "h");
    let cells = required(cx, m, ptr, "h", "the mesh size, e.g. \"1/32\"")
        .and_then(|hv| ratio(cx, hv, &hptr, Range::Positive))
        .and_then(|h| {
            // n = round(1/h) cells per unit length in both directions (docs/numerics.md); the summary reports the effective h = 1/n.
            let inv = 1.0 / h;
            let n = inv.round();
            if n < 1.0 {
                cx.err(
                    &hptr,
                    format!(
                        "h = {h} gives round(1/h) = 0 cells per unit length; \
                         h must be at most 2 (n = round(1/h) ≥ 1)"
                    ),
                );
                return None;
            }
            if n > MAX_CELLS_PER_SIDE {
                cx.err(
                    &hptr,
                    format!("h = {h} gives more than {MAX_CELLS_PER_SIDE} cells per unit length"),
                );
                return None;
            }
            let (w, ht) = dims?;
            let mut fits = true;
            for (side, len) in [("width", w), ("height", ht)] {
                let c = len * n;
                let whole = c.round();
                if whole < 1.0 || (c - whole).abs() > WHOLE_TOL * c.max(1.0) {
                    cx.err(
                        &hptr,
                        format!(
                            "the {side} {len} is not a whole number of cells of size h = 1/{n} \
                             ({side}/h = {c}); choose h so that {side}/h is a whole number ≥ 1"
                        ),
                    );
                    fits = false;
                } else if whole > MAX_CELLS_PER_SIDE {
                    cx.err(
                        &hptr,
                        format!("{side}/h = {whole} cells is more than {MAX_CELLS_PER_SIDE}"),
                    );
                    fits = false;
                }
            }
            fits.then_some(n as usize)
        });
    Some((cells?, pattern?))
}
