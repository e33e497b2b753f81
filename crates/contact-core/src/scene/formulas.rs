//! Numbers or formulas in x, y, t, and the check of a formula's values on a sample grid
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
    let vars = if with_t { "x, y, t" } else { "x, y" };
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
            if !with_t && e.uses_t() {
                cx.err(
                    ptr,
                    "this initial value may depend on x and y only (it is taken at t = 0)",
                );
                return None;
            }
            if e.uses_x() || e.uses_y() || e.uses_t() {
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

/// A 2-vector of [`scalar_field`]s. Formulas are queued for sampling over the rectangle, or
/// over the segment `on` when given.
pub(super) fn vector_field(
    cx: &mut Cx,
    v: &Value,
    ptr: &str,
    with_t: bool,
    on: Option<Segment>,
    sampled: &mut Vec<Sampled>,
) -> Option<VectorField> {
    let Some(items) = v.as_array().filter(|a| a.len() == 2) else {
        cx.err(
            ptr,
            format!(
                "expected a vector [x component, y component] of numbers or formulas, got {}",
                describe(v)
            ),
        );
        return None;
    };
    let c0 = scalar_field(cx, &items[0], &index(ptr, 0), with_t);
    let c1 = scalar_field(cx, &items[1], &index(ptr, 1), with_t);
    for (i, c) in [&c0, &c1].into_iter().enumerate() {
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
    Some(VectorField([c0?, c1?]))
}

/// Evaluates a formula on a small grid (SAMPLES² points of the rectangle, or 2·SAMPLES − 1
/// points of a segment) at t = 0, T/2 and T, and reports the first bad value.
/// The SAMPLES × SAMPLES grid of the rectangle [0, w] × [0, h].
pub(super) fn grid_points(w: f64, h: f64) -> Vec<[f64; 2]> {
    let n = SAMPLES - 1;
    let mut points = Vec::with_capacity(SAMPLES * SAMPLES);
    for i in 0..=n {
        for j in 0..=n {
            points.push([w * i as f64 / n as f64, h * j as f64 / n as f64]);
        }
    }
    points
}

pub(super) fn check_samples(cx: &mut Cx, s: &Sampled, body: &[[f64; 2]], t_end: Option<f64>) {
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
                ]);
            }
        }
        None => points.extend_from_slice(body),
    }
    for &t in &times {
        for &[x, y] in &points {
            let value = s.expr.eval(x, y, t);
            let bad = if !value.is_finite() {
                Some("formulas must be finite on the whole domain and time interval")
            } else if s.unit_interval && !Range::ClosedUnit.holds(value) {
                Some("the initial damage must be in [0, 1] (1 = intact)")
            } else {
                None
            };
            if let Some(why) = bad {
                let at = if s.in_time {
                    format!("(x, y, t) = ({x}, {y}, {t})")
                } else {
                    format!("(x, y) = ({x}, {y})")
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
