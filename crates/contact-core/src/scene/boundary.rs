//! Boundary parts: each a straight segment on one side of the rectangle, parts not overlapping.

use serde_json::Value;

use super::fields::PART_VARIANTS;
use super::formulas::{vector_field, Sampled};
use super::read::{describe, index, join, point, required, variant_object, Cx};
use crate::problem::{BoundaryKind, BoundaryPart, Segment, VectorField};

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
    dims: Option<(f64, f64)>,
    sampled: &mut Vec<Sampled>,
) -> Option<Vec<BoundaryPart>> {
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
        let from = required(cx, m, &pptr, "from", "the start point [x, y]")
            .and_then(|p| point(cx, p, &join(&pptr, "from")));
        let to = required(cx, m, &pptr, "to", "the end point [x, y]")
            .and_then(|p| point(cx, p, &join(&pptr, "to")));
        let segment = match (from, to, dims) {
            (Some(a), Some(b), Some((w, h))) => place(cx, &pptr, a, b, w, h),
            _ => None,
        };
        placed.push(segment.as_ref().map(|(_, p)| *p));
        let kind = match ty {
            "clamped" => Some(BoundaryKind::Clamped),
            "contact" => Some(BoundaryKind::Contact),
            _ => match m.get("f2") {
                None => Some(BoundaryKind::Traction(VectorField::constant([0.0, 0.0]))),
                Some(f2) => {
                    let on = segment.as_ref().map(|(s, _)| *s);
                    vector_field(cx, f2, &join(&pptr, "f2"), true, on, sampled)
                        .map(BoundaryKind::Traction)
                }
            },
        };
        match (kind, segment) {
            (Some(kind), Some((segment, _))) => parts.push(BoundaryPart { kind, segment }),
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
            "at least one clamped segment is required: without Γ1 the velocity problem is \
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
) -> Option<(Segment, Placed)> {
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
    Some((Segment { a, b }, Placed { side, lo, hi }))
}
