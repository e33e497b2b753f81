//! The `friction` section: the friction law on Γ3 (Tresca, slip weakening or a table).

use serde_json::Value;

use super::fields::FRICTION_VARIANTS;
use super::read::{
    describe, index, join, number, required, required_number, variant_object, Cx, Range,
};
use crate::problem::FrictionLaw;

/// The paper's friction bound j(ξ) = 20|ξ|, used when a scene with contact gives no friction.
pub const DEFAULT_FRICTION: FrictionLaw = FrictionLaw::Tresca { g: 20.0 };

/// Most points in a piecewise-linear friction table.
pub(super) const MAX_TABLE_POINTS: usize = 1000;

/// The friction law, by its `law` tag.
pub(super) fn friction(cx: &mut Cx, v: &Value, ptr: &str) -> Option<FrictionLaw> {
    let (law, m) = variant_object(cx, v, ptr, "friction", "law", FRICTION_VARIANTS)?;
    match law {
        "tresca" => {
            let g = required_number(
                cx,
                m,
                ptr,
                "g",
                Range::NonNegative,
                "the friction bound, j(ξ) = g|ξ|",
            );
            Some(FrictionLaw::Tresca { g: g? })
        }
        "slip_weakening" => {
            let mu0 = required_number(
                cx,
                m,
                ptr,
                "mu0",
                Range::NonNegative,
                "μ(0), the static bound",
            );
            let mu1 = required_number(
                cx,
                m,
                ptr,
                "mu1",
                Range::NonNegative,
                "μ(∞), the sliding bound",
            );
            let alpha = required_number(
                cx,
                m,
                ptr,
                "alpha",
                Range::NonNegative,
                "the weakening rate α",
            );
            Some(FrictionLaw::SlipWeakening {
                mu0: mu0?,
                mu1: mu1?,
                alpha: alpha?,
            })
        }
        _ => {
            let pv = required(cx, m, ptr, "points", "the table [[r, μ], ...]")?;
            friction_table(cx, pv, &join(ptr, "points"))
                .map(|points| FrictionLaw::PiecewiseLinear { points })
        }
    }
}

/// A piecewise-linear table [[r, μ], ...]: r from 0, strictly increasing; μ ≥ 0.
fn friction_table(cx: &mut Cx, v: &Value, ptr: &str) -> Option<Vec<[f64; 2]>> {
    let rule = format!(
        "the table must be an array of 1 to {MAX_TABLE_POINTS} points [r, μ] with r_0 = 0 < r_1 < ... and μ ≥ 0"
    );
    let items = match v.as_array() {
        Some(a) if !a.is_empty() && a.len() <= MAX_TABLE_POINTS => a,
        Some(a) => {
            cx.err(ptr, format!("{rule}; got {} points", a.len()));
            return None;
        }
        None => {
            cx.err(ptr, format!("{rule}; got {}", describe(v)));
            return None;
        }
    };
    let mut points = Vec::with_capacity(items.len());
    let mut ok = true;
    let mut prev: Option<f64> = None;
    for (i, item) in items.iter().enumerate() {
        let iptr = index(ptr, i);
        let Some(pair) = item.as_array().filter(|a| a.len() == 2) else {
            cx.err(
                &iptr,
                format!(
                    "a table point must be a pair [r, μ], got {}",
                    describe(item)
                ),
            );
            ok = false;
            prev = None;
            continue;
        };
        let r = number(cx, &pair[0], &index(&iptr, 0), Range::NonNegative);
        let mu = number(cx, &pair[1], &index(&iptr, 1), Range::NonNegative);
        if let Some(r) = r {
            if i == 0 && r != 0.0 {
                cx.err(
                    &index(&iptr, 0),
                    format!("the table must start at r = 0, got r = {r}"),
                );
                ok = false;
            }
            if let Some(p) = prev {
                if r <= p {
                    cx.err(
                        &index(&iptr, 0),
                        format!(
                            "r must increase strictly along the table: r = {r} follows r = {p}"
                        ),
                    );
                    ok = false;
                }
            }
        }
        prev = r;
        match (r, mu) {
            (Some(r), Some(mu)) => points.push([r, mu]),
            _ => ok = false,
        }
    }
    ok.then_some(points)
}
