//! Boundary parts. Each selects boundary facets in one of three ways
//! (docs/src/explanation/numerics.md#boundary-tagging): a straight segment `from`/`to` (on a rectangle: on
//! one side, parts not overlapping), a physical `group` of an imported mesh, or the zero set
//! of a formula `on` where the formula `where` is ≥ 0. Whether every part selects facets,
//! and no facet two parts, is checked on the mesh itself once it exists (`scene/mod.rs`).

use serde_json::Value;

use super::domain::Shape;
use super::fields::PART_VARIANTS;
use super::formulas::{vector_field, Sampled};
use super::read::{describe, index, join, point, required, variant_object, Cx};
use crate::expr::Expr;
use crate::problem::{BoundaryKind, BoundaryPart, Segment, Support, VectorField};

/// Most boundary parts (their overlap check is quadratic in the count).
pub(super) const MAX_BOUNDARY_PARTS: usize = 1000;
/// Relative tolerance (times the rectangle's size) of "lies on a side" checks.
const SIDE_TOL: f64 = 1e-12;

/// The sides of the rectangle [0, W] × [0, H]: (name, fixed coordinate index, its value).
fn sides(w: f64, h: f64) -> [(&'static str, usize, f64); 4] {
    [
        ("left", 0, 0.0),
        ("right", 0, w),
        ("bottom", 1, 0.0),
        ("top", 1, h),
    ]
}

/// "right side x = 2", for messages.
fn side_name(side: usize, w: f64, h: f64) -> String {
    let (name, fixed, value) = sides(w, h)[side];
    format!("{name} side {} = {value}", ["x", "y"][fixed])
}

/// Bit mask of the sides a point lies on (corners lie on two).
fn sides_of(p: [f64; 2], w: f64, h: f64, tol: f64) -> u8 {
    let mut mask = 0;
    for (i, (_, fixed, value)) in sides(w, h).iter().enumerate() {
        let along = 1 - fixed;
        let len = if along == 0 { w } else { h };
        if (p[*fixed] - value).abs() <= tol && p[along] >= -tol && p[along] <= len + tol {
            mask |= 1 << i;
        }
    }
    mask
}

/// A boundary segment placed on a side: the side's index and the interval it covers.
#[derive(Clone, Copy)]
struct Placed {
    side: usize,
    lo: f64,
    hi: f64,
}

pub(super) fn boundary(
    cx: &mut Cx,
    v: &Value,
    ptr: &str,
    shape: Option<&Shape>,
    sampled: &mut Vec<Sampled>,
) -> Option<Vec<BoundaryPart>> {
    let dims = match shape {
        Some(Shape::Rectangle { width, height }) => Some((*width, *height)),
        _ => None,
    };
    let dim = shape.map_or(2, Shape::dim);
    let Some(items) = v.as_array() else {
        cx.err(
            ptr,
            format!(
                "boundary must be an array of parts {{\"type\", \"from\", \"to\"}}, got {}",
                describe(v)
            ),
        );
        return None;
    };
    if items.len() > MAX_BOUNDARY_PARTS {
        cx.err(
            ptr,
            format!(
                "boundary must have at most {MAX_BOUNDARY_PARTS} parts, got {}",
                describe(v)
            ),
        );
        return None;
    }
    let mut parts = Vec::with_capacity(items.len());
    let mut placed: Vec<Option<Placed>> = Vec::with_capacity(items.len());
    let mut types_known = true;
    let mut has_clamped = false;
    let mut all_ok = true;
    for (i, item) in items.iter().enumerate() {
        let pptr = index(ptr, i);
        let Some((ty, m)) =
            variant_object(cx, item, &pptr, "a boundary part", "type", PART_VARIANTS)
        else {
            types_known = false;
            all_ok = false;
            placed.push(None);
            continue;
        };
        has_clamped |= ty == "clamped";
        let ways: Vec<&str> = ["from", "group", "on"]
            .into_iter()
            .filter(|k| m.contains_key(*k) || (*k == "from" && m.contains_key("to")))
            .collect();
        let support = match ways.as_slice() {
            ["group"] | ["on"] if m.contains_key("to") => {
                cx.err(
                    &join(&pptr, "to"),
                    "to belongs to a segment part {from, to}",
                );
                None
            }
            ["group"] if m.contains_key("where") => {
                cx.err(
                    &join(&pptr, "where"),
                    "where belongs to a part selected by a formula \"on\"",
                );
                None
            }
            ["group"] => match (&m["group"], shape) {
                (Value::String(g), Some(Shape::Mesh { .. })) if !g.is_empty() => {
                    Some(Support::Group(g.clone()))
                }
                (Value::String(_), Some(Shape::Mesh { .. })) | (_, Some(Shape::Mesh { .. })) => {
                    cx.err(
                        &join(&pptr, "group"),
                        format!(
                            "group must be the name of a physical group, got {}",
                            describe(&m["group"])
                        ),
                    );
                    None
                }
                _ => {
                    cx.err(
                        &join(&pptr, "group"),
                        "groups exist only on an imported mesh (domain.mesh)",
                    );
                    None
                }
            },
            ["on"] => {
                let on = formula(cx, &m["on"], &join(&pptr, "on"));
                let within = match m.get("where") {
                    None => Some(None),
                    Some(w) => formula(cx, w, &join(&pptr, "where")).map(Some),
                };
                match (on, within) {
                    (Some(on), Some(within)) => Some(Support::Zero { on, within }),
                    _ => None,
                }
            }
            ["from"] if m.contains_key("where") => {
                cx.err(
                    &join(&pptr, "where"),
                    "where belongs to a part selected by a formula \"on\"",
                );
                None
            }
            ["from"] if dim == 3 => {
                cx.err(
                    &join(&pptr, if m.contains_key("from") { "from" } else { "to" }),
                    "a segment {from, to} selects edges of a 2D body; select faces of a 3D body \
                     by a formula \"on\" (e.g. \"on\": \"z\" for the plane z = 0) or a group",
                );
                None
            }
            ["from"] => None.or_else(|| {
                let from = required(cx, m, &pptr, "from", "the start point [x, y]")
                    .and_then(|p| point(cx, p, &join(&pptr, "from")));
                let to = required(cx, m, &pptr, "to", "the end point [x, y]")
                    .and_then(|p| point(cx, p, &join(&pptr, "to")));
                Some(Support::Segment(Segment { a: from?, b: to? }))
            }),
            [] => {
                cx.err(&pptr, "a boundary part needs its facets: a segment {from, to}, a group, or a formula on (with an optional where)");
                None
            }
            _ => {
                cx.err(
                    &pptr,
                    format!(
                        "give one way of selecting facets, got {}",
                        ways.join(" and ")
                    ),
                );
                None
            }
        };
        let segment = match (&support, dims) {
            (Some(Support::Segment(s)), Some((w, h))) => place(cx, &pptr, s.a, s.b, w, h),
            (Some(Support::Segment(s)), None) if shape.is_some() => Some((*s, None)),
            _ => None,
        };
        let support = match (support, &segment) {
            (Some(Support::Segment(_)), Some((s, _))) => Some(Support::Segment(*s)),
            (Some(Support::Segment(_)), None) => None,
            (other, _) => other,
        };
        placed.push(segment.as_ref().and_then(|(_, p)| *p));
        let kind = match ty {
            "clamped" => Some(BoundaryKind::Clamped),
            "contact" => Some(BoundaryKind::Contact),
            _ => match m.get("f2") {
                None => Some(BoundaryKind::Traction(VectorField::constant([0.0, 0.0]))),
                Some(f2) => {
                    let on = segment.as_ref().map(|(s, _)| *s);
                    vector_field(cx, f2, &join(&pptr, "f2"), true, on, sampled, dim)
                        .map(BoundaryKind::Traction)
                }
            },
        };
        match (kind, support) {
            (Some(kind), Some(support)) => parts.push(BoundaryPart { kind, support }),
            _ => all_ok = false,
        }
    }
    // Parts may touch at end points but not share a piece of positive length: every boundary
    // edge must belong to exactly one part.
    if let Some((w, h)) = dims {
        let tol = SIDE_TOL * w.max(h);
        for j in 0..placed.len() {
            let Some(pj) = &placed[j] else { continue };
            for (i, pi) in placed.iter().enumerate().take(j) {
                let Some(pi) = pi else { continue };
                let overlap = pi.hi.min(pj.hi) - pi.lo.max(pj.lo);
                if pi.side == pj.side && overlap > tol {
                    let side = side_name(pj.side, w, h);
                    let coord = if sides(w, h)[pj.side].1 == 0 {
                        "y"
                    } else {
                        "x"
                    };
                    cx.err(
                        &index(ptr, j),
                        format!(
                            "this segment overlaps {} on the {side}, for {coord} in [{}, {}]; \
                             parts may touch only at end points",
                            index(ptr, i),
                            pi.lo.max(pj.lo),
                            pi.hi.min(pj.hi)
                        ),
                    );
                    all_ok = false;
                    break;
                }
            }
        }
    }
    if types_known && !has_clamped {
        cx.err(
            ptr,
            "at least one clamped part is required: without Γ1 the velocity problem is \
             singular (Korn's inequality)",
        );
        all_ok = false;
    }
    all_ok.then_some(parts)
}

/// Checks that the segment a → b lies on one side of [0, W] × [0, H] with positive length, and
/// snaps it onto that side exactly.
fn place(
    cx: &mut Cx,
    ptr: &str,
    a: [f64; 2],
    b: [f64; 2],
    w: f64,
    h: f64,
) -> Option<(Segment, Option<Placed>)> {
    let tol = SIDE_TOL * w.max(h);
    let (ma, mb) = (sides_of(a, w, h, tol), sides_of(b, w, h, tol));
    let outside = |p: [f64; 2]| {
        format!(
            "the point [{}, {}] is not on the boundary of the rectangle [0, {w}] × [0, {h}]",
            p[0], p[1]
        )
    };
    if ma == 0 {
        cx.err(&join(ptr, "from"), outside(a));
    }
    if mb == 0 {
        cx.err(&join(ptr, "to"), outside(b));
    }
    if ma == 0 || mb == 0 {
        return None;
    }
    let common = ma & mb;
    if common == 0 {
        let name = |m: u8| side_name(m.trailing_zeros() as usize, w, h);
        cx.err(
            &join(ptr, "to"),
            format!(
                "from is on the {} but to is on the {}: a segment must lie on one side of the \
                 rectangle (use one part per side)",
                name(ma),
                name(mb)
            ),
        );
        return None;
    }
    let side = common.trailing_zeros() as usize;
    let (_, fixed, value) = sides(w, h)[side];
    let along = 1 - fixed;
    let len = if along == 0 { w } else { h };
    let snap = |p: [f64; 2]| {
        let mut q = p;
        q[fixed] = value;
        q[along] = p[along].clamp(0.0, len);
        q
    };
    let (a, b) = (snap(a), snap(b));
    let (lo, hi) = (a[along].min(b[along]), a[along].max(b[along]));
    if hi - lo <= tol {
        cx.err(
            &join(ptr, "to"),
            "the segment has zero length (from and to coincide)",
        );
        return None;
    }
    Some((Segment { a, b }, Some(Placed { side, lo, hi })))
}

/// A formula in x, y and z (no t: the boundary does not move).
fn formula(cx: &mut Cx, v: &Value, ptr: &str) -> Option<Expr> {
    let Some(src) = v.as_str() else {
        cx.err(
            ptr,
            format!(
                "expected a formula in x, y (and z) such as \"x^2 + y^2 - 2.25\", got {}",
                describe(v)
            ),
        );
        return None;
    };
    match Expr::parse(src) {
        Ok(e) if e.uses_z() && !cx.solid => {
            cx.err(
                ptr,
                format!("unknown variable 'z' in \"{src}\": the body is 2D (x and y only)"),
            );
            None
        }
        Ok(e) if e.uses_t() => {
            cx.err(
                ptr,
                format!("\"{src}\" uses t; a boundary part is fixed in time (x, y and z only)"),
            );
            None
        }
        Ok(e) => Some(e),
        Err(why) => {
            cx.err(ptr, format!("\"{src}\" is not a formula: {why}"));
            None
        }
    }
}
