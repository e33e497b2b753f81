//! The `material` section: the viscosity A and the elasticity B of (4.1) or (2.15–2.16).

use serde_json::Value;

use super::fields::{ELASTICITY_VARIANTS, MATERIAL_FIELDS, VISCOSITY_FIELDS};
use super::read::{join, object, required, required_number, variant_object, Cx, Range};
use crate::problem::{Elasticity, Material, Viscosity};

/// A's η, ξ and B (linear μ, λ or von Mises η_b, σ_Y).
pub(super) fn material(cx: &mut Cx, v: &Value, ptr: &str) -> Option<Material> {
    let m = object(cx, v, ptr, "material", MATERIAL_FIELDS)?;
    let viscosity = required(cx, m, ptr, "viscosity", "A of (4.1): {eta, xi}").and_then(|v| {
        let vptr = join(ptr, "viscosity");
        let m = object(cx, v, &vptr, "viscosity", VISCOSITY_FIELDS)?;
        let eta = required_number(
            cx,
            m,
            &vptr,
            "eta",
            Range::Positive,
            "η of A(τ) = 2ητ + ξ tr(τ) I",
        );
        let xi = required_number(
            cx,
            m,
            &vptr,
            "xi",
            Range::NonNegative,
            "ξ of A(τ) = 2ητ + ξ tr(τ) I",
        );
        Some(Viscosity { eta: eta?, xi: xi? })
    });
    let elasticity = required(
        cx,
        m,
        ptr,
        "elasticity",
        "B: {\"type\": \"linear\" or \"von_mises\", ...}",
    )
    .and_then(|v| {
        let eptr = join(ptr, "elasticity");
        let (ty, m) = variant_object(cx, v, &eptr, "elasticity", "type", ELASTICITY_VARIANTS)?;
        if ty == "linear" {
            let mu = required_number(cx, m, &eptr, "mu", Range::Positive, "Lamé μ of (4.1)");
            let lambda = required_number(
                cx,
                m,
                &eptr,
                "lambda",
                Range::NonNegative,
                "Lamé λ of (4.1)",
            );
            Some(Elasticity::Linear {
                mu: mu?,
                lambda: lambda?,
            })
        } else {
            let eta_b = required_number(cx, m, &eptr, "eta_b", Range::Positive, "η of (2.15)");
            let sigma_y = required_number(
                cx,
                m,
                &eptr,
                "sigma_y",
                Range::Positive,
                "yield limit σ_Y of (2.16)",
            );
            Some(Elasticity::VonMises {
                eta_b: eta_b?,
                sigma_y: sigma_y?,
            })
        }
    });
    Some(Material {
        viscosity: viscosity?,
        elasticity: elasticity?,
    })
}
