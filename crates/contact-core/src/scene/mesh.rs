//! The `mesh` section. For a rectangle: n = round(1/h) cells per unit length and the
//! triangle pattern. For a polygon: the size h and `refine`. For an imported mesh the
//! section is optional and carries only `refine`: r uniform (red) refinements.

use serde_json::Value;

use super::domain::Shape;
use super::fields::{MESH_FIELDS, PATTERNS};
use super::read::{choice, describe, integer, join, object, ratio, required, Cx, Range};
use super::WHOLE_TOL;
use crate::problem::MeshPattern;

/// Most cells per side: a representability guard (not a resource limit, which belongs to the
/// service), far inside the range where `usize` conversions are safe.
const MAX_CELLS_PER_SIDE: f64 = 1.0e6;

/// Most red refinements (each multiplies the cell count by 4).
pub(super) const MAX_REFINE: u64 = 8;

/// The discretisation the `mesh` section asks for.
#[derive(Debug, Clone, Copy)]
pub(super) struct MeshSpec {
    /// Rectangle: n = round(1/h); 0 otherwise.
    pub cells_per_unit: usize,
    pub pattern: MeshPattern,
    /// Polygon: the meshing size.
    pub h: Option<f64>,
    pub refine: usize,
}

/// Reads the section (absent: `None` value) for the shape it meshes.
pub(super) fn mesh_section(
    cx: &mut Cx,
    v: Option<&Value>,
    ptr: &str,
    shape: Option<&Shape>,
) -> Option<MeshSpec> {
    // The sides of a rectangle or box, which h must divide.
    let rect: Option<Vec<(&str, f64)>> = match shape {
        Some(Shape::Rectangle { width, height }) => {
            Some(vec![("width", *width), ("height", *height)])
        }
        Some(Shape::Cuboid {
            width,
            height,
            depth,
        }) => Some(vec![
            ("width", *width),
            ("height", *height),
            ("depth", *depth),
        ]),
        _ => None,
    };
    let cuboid = matches!(shape, Some(Shape::Cuboid { .. }));
    let imported = matches!(shape, Some(Shape::Mesh { .. }));
    let Some(v) = v else {
        if imported {
            return Some(MeshSpec {
                cells_per_unit: 0,
                pattern: MeshPattern::Diagonal,
                h: None,
                refine: 0,
            });
        }
        cx.err(ptr, "mesh is required: the mesh size h");
        return None;
    };
    let refine = match object(cx, v, ptr, "mesh", MESH_FIELDS)?.get("refine") {
        None => Some(0),
        Some(_) if rect.is_some() => {
            cx.err(
                &join(ptr, "refine"),
                "refine applies to imported and polygon meshes; a rectangle or box is refined by a smaller h",
            );
            None
        }
        Some(r) => integer(cx, r, &join(ptr, "refine"), 0).and_then(|r| {
            if r > MAX_REFINE {
                cx.err(&join(ptr, "refine"), format!("refine must be at most {MAX_REFINE} (each refinement multiplies the cells by 4), got {r}"));
                None
            } else {
                Some(r as usize)
            }
        }),
    };
    if rect.is_none() && shape.is_some() {
        let m = object(cx, v, ptr, "mesh", MESH_FIELDS)?;
        if let Some(p) = m.get("pattern") {
            cx.err(
                &join(ptr, "pattern"),
                format!("pattern applies to rectangles only, got {}", describe(p)),
            );
            return None;
        }
        if imported {
            if m.contains_key("h") {
                cx.err(
                    &join(ptr, "h"),
                    "an imported mesh has its own cells: give refine, not h",
                );
                return None;
            }
            return Some(MeshSpec {
                cells_per_unit: 0,
                pattern: MeshPattern::Diagonal,
                h: None,
                refine: refine?,
            });
        }
        let hptr = join(ptr, "h");
        let h = required(cx, m, ptr, "h", "the mesh size, e.g. \"1/8\"")
            .and_then(|hv| ratio(cx, hv, &hptr, Range::Positive));
        return Some(MeshSpec {
            cells_per_unit: 0,
            pattern: MeshPattern::Diagonal,
            h: Some(h?),
            refine: refine?,
        });
    }
    let dims = rect;
    let m = object(cx, v, ptr, "mesh", MESH_FIELDS)?;
    let pattern = match m.get("pattern") {
        None => Some(MeshPattern::Diagonal),
        Some(p) if cuboid => {
            cx.err(
                &join(ptr, "pattern"),
                format!(
                    "pattern applies to rectangles only (a box's cubes are cut into the 6 Kuhn \
                     tetrahedra), got {}",
                    describe(p)
                ),
            );
            None
        }
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
            // n = round(1/h) cells per unit length in both directions (docs/src/explanation/numerics.md); the summary reports the effective h = 1/n.
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
            let mut fits = true;
            for (side, len) in dims? {
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
    Some(MeshSpec {
        cells_per_unit: cells?,
        pattern: pattern?,
        h: None,
        refine: refine?,
    })
}
