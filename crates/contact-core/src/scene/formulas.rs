//! Numbers or formulas in x, y, z, t, and the check of a formula's values on a sample grid
//! once the domain and time interval are known.

use serde_json::Value;

use super::read::{describe, index, number, Cx, Range};
use crate::expr::Expr;
use crate::problem::{ScalarField, Segment, VectorField};

/// Sample points per direction used to check formulas (values must be finite).
const SAMPLES: usize = 5;

/// A formula whose values are checked once the domain and time interval are known.
pub(super) struct Sampled {
    pub(super) pointer: String,
    pub(super) expr: Expr,
    /// Where to sample: the whole rectangle, or one boundary segment.
    pub(super) on: Option<Segment>,
    /// Sample t over [0, T] (else t = 0 only).
    pub(super) in_time: bool,
    /// Values must lie in [0, 1] (initial damage).
    pub(super) unit_interval: bool,
}

/// A number, or a formula string in x, y and (if `with_t`) t. Formulas without variables are
/// evaluated once here.
pub(super) fn scalar_field(cx: &mut Cx, v: &Value, ptr: &str, with_t: bool) -> Option<ScalarField> {
    let vars = if with_t { "x, y, z, t" } else { "x, y, z" };
    match v {
        Value::Number(_) => number(cx, v, ptr, Range::Any).map(ScalarField::Const),
        Value::String(s) => {
            let e = match Expr::parse(s) {
                Ok(e) => e,
                Err(msg) => {
                    cx.err(ptr, format!("invalid formula: {msg}"));
                    return None;
                }
            };
            if e.uses_z() && !cx.solid {
                cx.err(
                    ptr,
                    format!(
                        "unknown variable 'z' in \"{s}\": the body is 2D, so formulas may use \
                         only x, y and t"
                    ),
                );
                return None;
            }
            if !with_t && e.uses_t() {
                let vars = if cx.solid { "x, y and z" } else { "x and y" };
                cx.err(
                    ptr,
                    format!("this initial value may depend on {vars} only (it is taken at t = 0)"),
                );
                return None;
            }
            if e.uses_x() || e.uses_y() || e.uses_z() || e.uses_t() {
                return Some(ScalarField::Expr(e));
            }
            let c = e.eval(0.0, 0.0, 0.0);
            if c.is_finite() {
                Some(ScalarField::Const(c))
            } else {
                cx.err(ptr, format!("the formula \"{s}\" evaluates to {c}"));
                None
            }
        }
        other => {
            cx.err(
                ptr,
                format!(
                    "expected a number or a formula in {vars} such as \"-0.2*min(t/0.1, 1)\", got {}",
                    describe(other)
                ),
            );
            None
        }
    }
}

/// A d-vector of [`scalar_field`]s (d = `dim`, 2 or 3). Formulas are queued for sampling
/// over the body, or over the segment `on` when given.
pub(super) fn vector_field(
    cx: &mut Cx,
    v: &Value,
    ptr: &str,
    with_t: bool,
    on: Option<Segment>,
    sampled: &mut Vec<Sampled>,
    dim: usize,
) -> Option<VectorField> {
    let Some(items) = v.as_array().filter(|a| a.len() == dim) else {
        let shape = if dim == 3 {
            "[x, y, z components] (the body is 3D)"
        } else {
            "[x component, y component] (the body is 2D)"
        };
        cx.err(
            ptr,
            format!(
                "expected a vector {shape} of numbers or formulas, got {}",
                describe(v)
            ),
        );
        return None;
    };
    let c0 = scalar_field(cx, &items[0], &index(ptr, 0), with_t);
    let c1 = scalar_field(cx, &items[1], &index(ptr, 1), with_t);
    let c2 = match items.get(2) {
        Some(item) => scalar_field(cx, item, &index(ptr, 2), with_t),
        None => Some(ScalarField::Const(0.0)),
    };
    for (i, c) in [&c0, &c1, &c2].into_iter().enumerate() {
        if let Some(ScalarField::Expr(e)) = c {
            sampled.push(Sampled {
                pointer: index(ptr, i),
                expr: e.clone(),
                on,
                in_time: with_t,
                unit_interval: false,
            });
        }
    }
    Some(VectorField([c0?, c1?, c2?]))
}

/// Evaluates a formula on a small grid (SAMPLES² points of the rectangle, or 2·SAMPLES − 1
/// points of a segment) at t = 0, T/2 and T, and reports the first bad value.
/// The SAMPLES × SAMPLES grid of the rectangle [0, w] × [0, h] (z = 0), or with a depth d
/// the SAMPLES³ grid of the box [0, w] × [0, h] × [0, d].
pub(super) fn grid_points(w: f64, h: f64, d: Option<f64>) -> Vec<[f64; 3]> {
    let n = SAMPLES - 1;
    let layers = if d.is_some() { n } else { 0 };
    let mut points = Vec::with_capacity(SAMPLES * SAMPLES * (layers + 1));
    for k in 0..=layers {
        for i in 0..=n {
            for j in 0..=n {
                let z = d.map_or(0.0, |d| d * k as f64 / n as f64);
                points.push([w * i as f64 / n as f64, h * j as f64 / n as f64, z]);
            }
        }
    }
    points
}

pub(super) fn check_samples(cx: &mut Cx, s: &Sampled, body: &[[f64; 3]], t_end: Option<f64>) {
    let times: Vec<f64> = match (s.in_time, t_end) {
        (true, Some(t)) => vec![0.0, 0.5 * t, t],
        _ => vec![0.0],
    };
    let mut points = Vec::new();
    match s.on {
        Some(seg) => {
            let n = 2 * SAMPLES - 2;
            for i in 0..=n {
                let f = i as f64 / n as f64;
                points.push([
                    seg.a[0] + f * (seg.b[0] - seg.a[0]),
                    seg.a[1] + f * (seg.b[1] - seg.a[1]),
                    0.0,
                ]);
            }
        }
        None => points.extend_from_slice(body),
    }
    for &t in &times {
        let solid = body.iter().any(|p| p[2] != 0.0);
        for &[x, y, z] in &points {
            let value = s.expr.eval3(x, y, z, t);
            let bad = if !value.is_finite() {
                Some("formulas must be finite on the whole domain and time interval")
            } else if s.unit_interval && !Range::ClosedUnit.holds(value) {
                Some("the initial damage must be in [0, 1] (1 = intact)")
            } else {
                None
            };
            if let Some(why) = bad {
                let at = match (s.in_time, solid) {
                    (true, false) => format!("(x, y, t) = ({x}, {y}, {t})"),
                    (false, false) => format!("(x, y) = ({x}, {y})"),
                    (true, true) => format!("(x, y, z, t) = ({x}, {y}, {z}, {t})"),
                    (false, true) => format!("(x, y, z) = ({x}, {y}, {z})"),
                };
                cx.err(
                    &s.pointer,
                    format!(
                        "\"{}\" evaluates to {value} at {at}; {why}",
                        s.expr.source()
                    ),
                );
                return;
            }
        }
    }
}
