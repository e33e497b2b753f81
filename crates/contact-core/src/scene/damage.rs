//! The `damage` section: κ, the source φ of (4.2) and the initial damage ζ0.

use serde_json::Value;

use super::fields::{DAMAGE_FIELDS, SOURCE_FIELDS};
use super::formulas::{scalar_field, Sampled};
use super::read::{join, object, optional_number, required_number, Cx, Range};
use crate::problem::{Damage, DamageSource, ScalarField};

/// The paper's damage source (4.2): a = 2, b = 20, ζ* = 0.2.
pub const DEFAULT_SOURCE: DamageSource = DamageSource {
    a: 2.0,
    b: 20.0,
    zeta_star: 0.2,
};

/// κ > 0, φ's constants and ζ0 in [0, 1] (a formula is queued for sampling).
pub(super) fn damage(
    cx: &mut Cx,
    v: &Value,
    ptr: &str,
    sampled: &mut Vec<Sampled>,
) -> Option<Damage> {
    let m = object(cx, v, ptr, "damage", DAMAGE_FIELDS)?;
    let kappa = required_number(
        cx,
        m,
        ptr,
        "kappa",
        Range::Positive,
        "the damage diffusion κ of (2.2)",
    );
    let source = match m.get("source") {
        None => Some(DEFAULT_SOURCE),
        Some(s) => damage_source(cx, s, &join(ptr, "source")),
    };
    let zeta0 = match m.get("zeta0") {
        None => Some(ScalarField::Const(1.0)),
        Some(z) => {
            let zptr = join(ptr, "zeta0");
            match scalar_field(cx, z, &zptr, false)? {
                ScalarField::Const(c) if !Range::ClosedUnit.holds(c) => {
                    cx.err(
                        &zptr,
                        format!("zeta0 must be in [0, 1] (1 = intact), got {c}"),
                    );
                    None
                }
                ScalarField::Expr(e) => {
                    sampled.push(Sampled {
                        pointer: zptr,
                        expr: e.clone(),
                        on: None,
                        in_time: false,
                        unit_interval: true,
                    });
                    Some(ScalarField::Expr(e))
                }
                c => Some(c),
            }
        }
    };
    Some(Damage {
        kappa: kappa?,
        source: source?,
        zeta0: zeta0?,
    })
}

/// φ's constants; each defaults to the paper's value.
fn damage_source(cx: &mut Cx, v: &Value, ptr: &str) -> Option<DamageSource> {
    let m = object(cx, v, ptr, "source", SOURCE_FIELDS)?;
    let a = optional_number(cx, m, ptr, "a", Range::NonNegative, DEFAULT_SOURCE.a);
    let b = optional_number(cx, m, ptr, "b", Range::NonNegative, DEFAULT_SOURCE.b);
    let zeta_star = optional_number(
        cx,
        m,
        ptr,
        "zeta_star",
        Range::OpenUnit,
        DEFAULT_SOURCE.zeta_star,
    );
    Some(DamageSource {
        a: a?,
        b: b?,
        zeta_star: zeta_star?,
    })
}
