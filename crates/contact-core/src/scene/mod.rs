//! The scene format: the JSON a user submits, and its validation into a [`Problem`].
//!
//! The format is documented field by field in `api/scene.schema.json` (a test keeps the two
//! in step). Validation walks the JSON tree by hand rather than through `serde` derives, so
//! that it can
//! - report **every** problem at once, each with an RFC 6901 pointer into the submitted
//!   document (`/boundary/2/to`, `/time/k`) and a sentence naming what is allowed;
//! - refuse unknown fields everywhere (a typo such as `"visocsity"` must not silently fall
//!   back to a default), suggesting the closest known name;
//! - accept the few convenient spellings (`"1/32"` for h and k, formulas for loads) without
//!   a zoo of untagged enums.
//!
//! The checks are the ones the numerics relies on and cannot check cheaply itself: positive
//! moduli, a mesh that tiles the rectangle exactly, a whole number of time steps, boundary
//! segments on the rectangle that do not overlap, at least one clamped segment (without Γ1
//! the velocity problem is singular, Korn's inequality fails), finite load formulas and an
//! initial damage in [0, 1]. Validation never panics, whatever the input.

mod boundary;
mod canonical;
#[cfg(test)]
mod hostile;
pub mod presets;
mod read;

pub use canonical::{canonical, content_hash, hex_sha256};

use std::fmt;

use serde::Serialize;
use serde_json::{Map, Value};

use crate::expr::Expr;
use crate::problem::{
    Damage, DamageSource, Elasticity, FieldSet, FrictionLaw, Material, MeshPattern, OutputSpec,
    Problem, ScalarField, Segment, SmallnessPolicy, VectorField, Viscosity,
};
use boundary::boundary;
use read::{
    choice, describe, index, integer, join, number, object, optional_number, ratio, required,
    required_number, variant_object, Cx, Range,
};

/// One problem found in a scene, located by an RFC 6901 JSON pointer into the submitted
/// document ("" is the document itself). A missing required field is reported at the pointer
/// it would have.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct FieldError {
    pub pointer: String,
    pub message: String,
}

/// All the problems found in a scene (never empty when returned as an error).
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct ValidationErrors(pub Vec<FieldError>);

impl fmt::Display for ValidationErrors {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let n = self.0.len();
        write!(
            f,
            "invalid scene ({n} problem{})",
            if n == 1 { "" } else { "s" }
        )?;
        for e in &self.0 {
            let at = if e.pointer.is_empty() {
                "(document)"
            } else {
                &e.pointer
            };
            write!(f, "\n  at {at}: {}", e.message)?;
        }
        Ok(())
    }
}

impl std::error::Error for ValidationErrors {}

/// Command-line (or request) overrides of the discretisation, applied to the JSON document
/// before validation so that their errors are reported at the usual pointers.
#[derive(Debug, Clone, Default)]
pub struct Overrides {
    /// Replaces `/mesh/h`.
    pub h: Option<Value>,
    /// Replaces `/time/k` and removes `/time/N` and `/time/steps`.
    pub k: Option<Value>,
    /// Replaces `/time/t_end` and removes its alias `/time/T`. With only this override and a
    /// scene that gives k, the number of steps follows from the new t_end; with a scene that
    /// gives N, the step k = t_end/N changes instead.
    pub t_end: Option<Value>,
}

/// Writes the overrides into the document. A document or section of the wrong type is left
/// alone: validation reports it.
pub fn apply_overrides(doc: &mut Value, o: &Overrides) {
    let Some(top) = doc.as_object_mut() else {
        return;
    };
    if let Some(h) = &o.h {
        if let Some(mesh) = section(top, "mesh") {
            mesh.insert("h".into(), h.clone());
        }
    }
    if let Some(k) = &o.k {
        if let Some(time) = section(top, "time") {
            time.remove("N");
            time.remove("steps");
            time.insert("k".into(), k.clone());
        }
    }
    if let Some(t_end) = &o.t_end {
        if let Some(time) = section(top, "time") {
            time.remove("T");
            time.insert("t_end".into(), t_end.clone());
        }
    }
}

fn section<'a>(top: &'a mut Map<String, Value>, key: &str) -> Option<&'a mut Map<String, Value>> {
    top.entry(key)
        .or_insert_with(|| Value::Object(Map::new()))
        .as_object_mut()
}

/// Reads a finite number (of any sign: callers check the range) given as a JSON number, a
/// numeric string ("0.25", "1e-3") or a ratio string "p/q" ("1/32"): mesh sizes and time steps
/// are naturally written as fractions, and 1/3 cannot be written exactly as a JSON number.
/// "inf", "NaN" and division by zero are refused.
pub fn parse_ratio(v: &Value) -> Result<f64, String> {
    match v {
        Value::Number(n) => n
            .as_f64()
            .filter(|x| x.is_finite())
            .ok_or_else(|| format!("{n} is not a finite number")),
        Value::String(s) => {
            let s = s.trim();
            let value = match s.split_once('/') {
                Some((p, q)) => {
                    let (p, q) = (decimal(p.trim(), s)?, decimal(q.trim(), s)?);
                    if q == 0.0 {
                        return Err(format!("\"{s}\" divides by zero"));
                    }
                    p / q
                }
                None => decimal(s, s)?,
            };
            if value.is_finite() {
                Ok(value)
            } else {
                Err(format!("\"{s}\" is not a finite number"))
            }
        }
        other => Err(format!(
            "expected a number or a ratio string like \"1/32\", got {}",
            describe(other)
        )),
    }
}

/// A plain decimal number: digits, '.', exponent and sign only (so "inf" and "NaN", which
/// Rust's float parser accepts, are not).
fn decimal(s: &str, whole: &str) -> Result<f64, String> {
    let plain = !s.is_empty()
        && s.chars()
            .all(|c| c.is_ascii_digit() || matches!(c, '.' | 'e' | 'E' | '+' | '-'));
    let value = if plain { s.parse::<f64>().ok() } else { None };
    match value {
        Some(v) if v.is_finite() => Ok(v),
        _ => Err(format!(
            "\"{whole}\" is not a number or a ratio of two numbers like \"1/32\""
        )),
    }
}

// ---------------------------------------------------------------------------------------------
// The accepted fields of each object. The schema drift test compares these with
// api/scene.schema.json.

const TOP_FIELDS: &[&str] = &[
    "$schema",
    "name",
    "domain",
    "mesh",
    "time",
    "boundary",
    "loads",
    "material",
    "friction",
    "smallness",
    "damage",
    "initial",
    "output",
    "error_estimate",
];
const DOMAIN_FIELDS: &[&str] = &["width", "height", "rectangle"];
const RECTANGLE_FIELDS: &[&str] = &["width", "height"];
const MESH_FIELDS: &[&str] = &["h", "pattern"];
const TIME_FIELDS: &[&str] = &["t_end", "T", "k", "N", "steps"];
const PART_VARIANTS: &[(&str, &[&str])] = &[
    ("clamped", &["type", "from", "to"]),
    ("traction", &["type", "from", "to", "f2"]),
    ("contact", &["type", "from", "to"]),
];
const LOADS_FIELDS: &[&str] = &["f0"];
const MATERIAL_FIELDS: &[&str] = &["viscosity", "elasticity"];
const VISCOSITY_FIELDS: &[&str] = &["eta", "xi"];
const ELASTICITY_VARIANTS: &[(&str, &[&str])] = &[
    ("linear", &["type", "mu", "lambda"]),
    ("von_mises", &["type", "eta_b", "sigma_y"]),
];
const FRICTION_VARIANTS: &[(&str, &[&str])] = &[
    ("tresca", &["law", "g"]),
    ("slip_weakening", &["law", "mu0", "mu1", "alpha"]),
    ("piecewise_linear", &["law", "points"]),
];
const DAMAGE_FIELDS: &[&str] = &["kappa", "source", "zeta0"];
const SOURCE_FIELDS: &[&str] = &["a", "b", "zeta_star"];
const INITIAL_FIELDS: &[&str] = &["u0"];
const OUTPUT_FIELDS: &[&str] = &["every", "last", "fields"];
const OUTPUT_FIELD_NAMES: &[&str] = &["u", "w", "zeta", "sigma", "von_mises", "contact"];
const PATTERNS: &[&str] = &["diagonal", "anti_diagonal", "cross"];
const SMALLNESS: &[&str] = &["refuse", "warn"];

/// The paper's friction bound j(ξ) = 20|ξ|, used when a scene with contact gives no friction.
pub const DEFAULT_FRICTION: FrictionLaw = FrictionLaw::Tresca { g: 20.0 };
/// The paper's damage source (4.2): a = 2, b = 20, ζ* = 0.2.
pub const DEFAULT_SOURCE: DamageSource = DamageSource {
    a: 2.0,
    b: 20.0,
    zeta_star: 0.2,
};

/// Longest scene name.
const MAX_NAME_LEN: usize = 200;
/// Most points in a piecewise-linear friction table.
const MAX_TABLE_POINTS: usize = 1000;
/// Most boundary parts (their overlap check is quadratic in the count).
const MAX_BOUNDARY_PARTS: usize = 1000;
/// Longest list of output field names (there are six; repeats are harmless).
const MAX_OUTPUT_FIELDS: usize = 64;
/// Representability guards (not resource limits, which belong to the service): counts stay
/// far inside the range where f64 holds integers exactly and `usize` conversions are safe.
const MAX_CELLS_PER_SIDE: f64 = 1.0e6;
const MAX_STEPS: f64 = 1.0e9;
/// Relative tolerance of "is a whole number" checks (t_end/k, 1/h, width/h).
const WHOLE_TOL: f64 = 1e-9;
/// Relative tolerance (times the rectangle's size) of "lies on a side" checks.
const SIDE_TOL: f64 = 1e-12;
/// Sample points per direction used to check formulas (values must be finite).
const SAMPLES: usize = 5;

/// Validates a scene document and turns it into a [`Problem`], or reports every problem found.
pub fn validate(doc: &Value) -> Result<Problem, ValidationErrors> {
    let mut cx = Cx::default();
    let problem = scene(&mut cx, doc);
    match problem {
        Some(p) if cx.errors.is_empty() => Ok(p),
        _ => {
            if cx.errors.is_empty() {
                cx.err("", "internal error: scene rejected without a reason");
            }
            Err(ValidationErrors(cx.finish()))
        }
    }
}

/// A formula whose values are checked once the domain and time interval are known.
struct Sampled {
    pointer: String,
    expr: Expr,
    /// Where to sample: the whole rectangle, or one boundary segment.
    on: Option<Segment>,
    /// Sample t over [0, T] (else t = 0 only).
    in_time: bool,
    /// Values must lie in [0, 1] (initial damage).
    unit_interval: bool,
}

fn scene(cx: &mut Cx, doc: &Value) -> Option<Problem> {
    let top = object(cx, doc, "", "a scene", TOP_FIELDS)?;
    let mut sampled = Vec::new();

    if let Some(v) = top.get("$schema") {
        if !v.is_string() {
            cx.err(
                "/$schema",
                format!(
                    "$schema must be a string (the schema's address, for editors), got {}",
                    describe(v)
                ),
            );
        }
    }
    let name = match top.get("name") {
        None => Some("scene".to_string()),
        Some(v) => scene_name(cx, v, "/name"),
    };
    let dims = required(cx, top, "", "domain", "the rectangle's width and height")
        .and_then(|v| domain(cx, v, "/domain"));
    let time = required(
        cx,
        top,
        "",
        "time",
        "t_end and the step k or the number of steps N",
    )
    .and_then(|v| time(cx, v, "/time"));
    let mesh =
        required(cx, top, "", "mesh", "the mesh size h").and_then(|v| mesh(cx, v, "/mesh", dims));
    let boundary = required(
        cx,
        top,
        "",
        "boundary",
        "the clamped, traction and contact segments",
    )
    .and_then(|v| boundary(cx, v, "/boundary", dims, &mut sampled));
    let body_force = match top.get("loads") {
        None => Some(VectorField::constant([0.0, 0.0])),
        Some(v) => loads(cx, v, "/loads", &mut sampled),
    };
    let material = required(cx, top, "", "material", "viscosity and elasticity")
        .and_then(|v| material(cx, v, "/material"));
    let friction = match top.get("friction") {
        None => Some(DEFAULT_FRICTION),
        Some(v) => friction(cx, v, "/friction"),
    };
    let smallness = match top.get("smallness") {
        None => Some(SmallnessPolicy::Refuse),
        Some(v) => {
            choice(cx, v, "/smallness", "smallness", SMALLNESS).map(|i| match SMALLNESS[i] {
                "warn" => SmallnessPolicy::Warn,
                _ => SmallnessPolicy::Refuse,
            })
        }
    };
    let damage = match top.get("damage") {
        None => Some(None),
        Some(v) => damage(cx, v, "/damage", &mut sampled).map(Some),
    };
    let u0 = match top.get("initial") {
        None => Some(VectorField::constant([0.0, 0.0])),
        Some(v) => initial(cx, v, "/initial", &mut sampled),
    };
    let output = match top.get("output") {
        None => Some(OutputSpec {
            every: 1,
            last: true,
            fields: all_fields(),
        }),
        Some(v) => output(cx, v, "/output"),
    };
    let error_estimate = match top.get("error_estimate") {
        None => Some(false),
        Some(Value::Bool(b)) => Some(*b),
        Some(v) => {
            cx.err(
                "/error_estimate",
                format!("error_estimate must be true or false, got {}", describe(v)),
            );
            None
        }
    };

    if let Some((width, height)) = dims {
        let t_end = time.map(|(t, _)| t);
        for s in &sampled {
            check_samples(cx, s, width, height, t_end);
        }
    }

    let (
        Some(name),
        Some((width, height)),
        Some((t_end, steps)),
        Some((cells_per_unit, pattern)),
        Some(boundary),
        Some(body_force),
        Some(material),
        Some(friction),
        Some(smallness),
        Some(damage),
        Some(u0),
        Some(output),
        Some(error_estimate),
    ) = (
        name,
        dims,
        time,
        mesh,
        boundary,
        body_force,
        material,
        friction,
        smallness,
        damage,
        u0,
        output,
        error_estimate,
    )
    else {
        return None;
    };
    let problem = Problem {
        name,
        width,
        height,
        cells_per_unit,
        pattern,
        t_end,
        steps,
        boundary,
        body_force,
        material,
        friction,
        smallness,
        damage,
        u0,
        output,
        error_estimate,
    };
    if problem.error_estimate {
        if let Some(why) = crate::estimate::unsupported(&problem) {
            cx.err("/error_estimate", format!("an error estimate {why}"));
            return None;
        }
    }
    Some(problem)
}

fn scene_name(cx: &mut Cx, v: &Value, ptr: &str) -> Option<String> {
    let rule = format!("1 to {MAX_NAME_LEN} characters, no control characters");
    match v.as_str() {
        Some(s)
            if !s.is_empty()
                && s.chars().count() <= MAX_NAME_LEN
                && !s.chars().any(char::is_control) =>
        {
            Some(s.to_string())
        }
        Some(_) => {
            cx.err(ptr, format!("name must be {rule}"));
            None
        }
        None => {
            cx.err(
                ptr,
                format!("name must be a string ({rule}), got {}", describe(v)),
            );
            None
        }
    }
}

fn domain(cx: &mut Cx, v: &Value, ptr: &str) -> Option<(f64, f64)> {
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

fn time(cx: &mut Cx, v: &Value, ptr: &str) -> Option<(f64, usize)> {
    let m = object(cx, v, ptr, "time", TIME_FIELDS)?;
    let t_end = match (m.get("t_end"), m.get("T")) {
        (Some(_), Some(_)) => {
            cx.err(&join(ptr, "T"), "give t_end or its alias T, not both");
            None
        }
        (Some(t), None) => ratio(cx, t, &join(ptr, "t_end"), Range::Positive),
        (None, Some(t)) => ratio(cx, t, &join(ptr, "T"), Range::Positive),
        (None, None) => {
            cx.err(
                &join(ptr, "t_end"),
                "missing required field 't_end' (the final time T > 0; alias T)",
            );
            None
        }
    };
    let given: Vec<&str> = ["k", "N", "steps"]
        .into_iter()
        .filter(|key| m.contains_key(*key))
        .collect();
    let steps = match given.as_slice() {
        [] => {
            cx.err(
                &join(ptr, "k"),
                "missing the time step: give k (e.g. \"1/32\") or the number of steps N",
            );
            None
        }
        ["k"] => {
            let kptr = join(ptr, "k");
            let k = ratio(cx, &m["k"], &kptr, Range::Positive)?;
            let t = t_end?;
            let q = t / k;
            let n = q.round();
            if q < 1.0 - WHOLE_TOL {
                cx.err(&kptr, format!("k = {k} is longer than t_end = {t}"));
                None
            } else if (q - n).abs() > WHOLE_TOL * q {
                cx.err(
                    &kptr,
                    format!(
                        "t_end/k = {t}/{k} = {q} must be a whole number of steps; \
                         choose k = t_end/N for a whole N"
                    ),
                );
                None
            } else if n > MAX_STEPS {
                cx.err(
                    &kptr,
                    format!("t_end/k = {n} steps is more than {MAX_STEPS}"),
                );
                None
            } else {
                Some(n as usize)
            }
        }
        [key] => {
            let nptr = join(ptr, key);
            let n = integer(cx, &m[*key], &nptr, 1)?;
            if n as f64 > MAX_STEPS {
                cx.err(&nptr, format!("{key} = {n} steps is more than {MAX_STEPS}"));
                None
            } else {
                Some(n as usize)
            }
        }
        [_, second, ..] => {
            cx.err(
                &join(ptr, second),
                format!(
                    "give exactly one of k, N (alias steps); this scene gives {}",
                    given.join(" and ")
                ),
            );
            None
        }
    };
    Some((t_end?, steps?))
}

fn mesh(
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
            // n = round(1/h) cells per unit length in both directions (the and
            // SCHEME.md's definition); the summary reports the effective h = 1/n.
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

fn loads(cx: &mut Cx, v: &Value, ptr: &str, sampled: &mut Vec<Sampled>) -> Option<VectorField> {
    let m = object(cx, v, ptr, "loads", LOADS_FIELDS)?;
    match m.get("f0") {
        None => Some(VectorField::constant([0.0, 0.0])),
        Some(f0) => vector_field(cx, f0, &join(ptr, "f0"), true, None, sampled),
    }
}

fn initial(cx: &mut Cx, v: &Value, ptr: &str, sampled: &mut Vec<Sampled>) -> Option<VectorField> {
    let m = object(cx, v, ptr, "initial", INITIAL_FIELDS)?;
    match m.get("u0") {
        None => Some(VectorField::constant([0.0, 0.0])),
        Some(u0) => vector_field(cx, u0, &join(ptr, "u0"), false, None, sampled),
    }
}

fn material(cx: &mut Cx, v: &Value, ptr: &str) -> Option<Material> {
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

fn friction(cx: &mut Cx, v: &Value, ptr: &str) -> Option<FrictionLaw> {
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

fn damage(cx: &mut Cx, v: &Value, ptr: &str, sampled: &mut Vec<Sampled>) -> Option<Damage> {
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

fn output(cx: &mut Cx, v: &Value, ptr: &str) -> Option<OutputSpec> {
    let m = object(cx, v, ptr, "output", OUTPUT_FIELDS)?;
    let every = match m.get("every") {
        None => Some(1),
        Some(e) => integer(cx, e, &join(ptr, "every"), 0).map(|n| n as usize),
    };
    let last = match m.get("last") {
        None => Some(true),
        Some(Value::Bool(b)) => Some(*b),
        Some(other) => {
            cx.err(
                &join(ptr, "last"),
                format!("last must be true or false, got {}", describe(other)),
            );
            None
        }
    };
    let fields = match m.get("fields") {
        None => Some(all_fields()),
        Some(f) => output_fields(cx, f, &join(ptr, "fields")),
    };
    Some(OutputSpec {
        every: every?,
        last: last?,
        fields: fields?,
    })
}

fn all_fields() -> FieldSet {
    FieldSet {
        u: true,
        w: true,
        zeta: true,
        sigma: true,
        von_mises: true,
        contact: true,
    }
}

fn output_fields(cx: &mut Cx, v: &Value, ptr: &str) -> Option<FieldSet> {
    let Some(items) = v.as_array() else {
        cx.err(
            ptr,
            format!(
                "fields must be an array of names from {}, got {}",
                OUTPUT_FIELD_NAMES.join(", "),
                describe(v)
            ),
        );
        return None;
    };
    if items.len() > MAX_OUTPUT_FIELDS {
        cx.err(
            ptr,
            format!(
                "fields must list at most {MAX_OUTPUT_FIELDS} names (from {}), got {}",
                OUTPUT_FIELD_NAMES.join(", "),
                describe(v)
            ),
        );
        return None;
    }
    let mut set = FieldSet::default();
    let mut ok = true;
    for (i, item) in items.iter().enumerate() {
        match choice(
            cx,
            item,
            &index(ptr, i),
            "an output field",
            OUTPUT_FIELD_NAMES,
        ) {
            Some(0) => set.u = true,
            Some(1) => set.w = true,
            Some(2) => set.zeta = true,
            Some(3) => set.sigma = true,
            Some(4) => set.von_mises = true,
            Some(_) => set.contact = true,
            None => ok = false,
        }
    }
    ok.then_some(set)
}

// ---------------------------------------------------------------------------------------------
// Formulas.

/// A number, or a formula string in x, y and (if `with_t`) t. Formulas without variables are
/// evaluated once here.
fn scalar_field(cx: &mut Cx, v: &Value, ptr: &str, with_t: bool) -> Option<ScalarField> {
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
fn vector_field(
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
fn check_samples(cx: &mut Cx, s: &Sampled, w: f64, h: f64, t_end: Option<f64>) {
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
        None => {
            let n = SAMPLES - 1;
            for i in 0..=n {
                for j in 0..=n {
                    points.push([w * i as f64 / n as f64, h * j as f64 / n as f64]);
                }
            }
        }
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::problem::BoundaryKind;
    use proptest::prelude::*;
    use serde_json::json;
    use std::collections::{BTreeMap, BTreeSet};

    /// The scene of the brief: paper experiment 3 with a ramped body force.
    fn example() -> Value {
        json!({
            "name": "paper-exp3",
            "domain": {"width": 2, "height": 1},
            "mesh": {"h": "1/32", "pattern": "diagonal"},
            "time": {"t_end": 1, "k": "1/32"},
            "boundary": [
                {"type": "clamped",  "from": [0, 0], "to": [0, 1]},
                {"type": "traction", "from": [0, 1], "to": [2, 1], "f2": [-1, -1]},
                {"type": "traction", "from": [2, 0], "to": [2, 1], "f2": [-1, -1]},
                {"type": "contact",  "from": [0, 0], "to": [2, 0]}
            ],
            "loads": {"f0": [0, "-0.2*min(t/0.1,1)"]},
            "material": {"viscosity": {"eta": 2, "xi": 2},
                         "elasticity": {"type": "linear", "mu": 4, "lambda": 4}},
            "friction": {"law": "tresca", "g": 20},
            "smallness": "refuse",
            "damage": {"kappa": 0.5, "source": {"a": 2, "b": 20, "zeta_star": 0.2}, "zeta0": 1},
            "initial": {"u0": [0, 0]},
            "output": {"every": 1, "last": true,
                       "fields": ["u", "w", "zeta", "sigma", "von_mises", "contact"]}
        })
    }

    #[test]
    fn h_is_rounded_to_whole_cells_per_unit_length() {
        let mut doc = minimal();
        doc["mesh"]["h"] = json!(0.3);
        assert_eq!(validate(&doc).unwrap().cells_per_unit, 3);
        doc["mesh"]["h"] = json!("1/7");
        assert_eq!(validate(&doc).unwrap().cells_per_unit, 7);
    }

    /// The smallest valid scene: everything optional left out.
    fn minimal() -> Value {
        json!({
            "domain": {"width": 1, "height": 1},
            "mesh": {"h": 0.25},
            "time": {"t_end": 1, "N": 4},
            "boundary": [{"type": "clamped", "from": [0, 0], "to": [0, 1]}],
            "material": {"viscosity": {"eta": 1, "xi": 0},
                         "elasticity": {"type": "linear", "mu": 1, "lambda": 0}}
        })
    }

    /// Sets the value at an RFC 6901 pointer (the parent must exist).
    fn set(doc: &mut Value, ptr: &str, v: Value) {
        *doc.pointer_mut(ptr).unwrap_or_else(|| panic!("no {ptr}")) = v;
    }

    fn remove(doc: &mut Value, ptr: &str) {
        let (parent, key) = ptr.rsplit_once('/').unwrap();
        doc.pointer_mut(parent)
            .and_then(Value::as_object_mut)
            .unwrap()
            .remove(key)
            .unwrap_or_else(|| panic!("no {ptr}"));
    }

    fn errors(doc: &Value) -> Vec<FieldError> {
        match validate(doc) {
            Ok(_) => panic!("expected errors for {doc}"),
            Err(e) => e.0,
        }
    }

    /// Asserts an error at `ptr` whose message contains `text`.
    #[track_caller]
    fn assert_error(doc: &Value, ptr: &str, text: &str) {
        let errs = errors(doc);
        assert!(
            errs.iter()
                .any(|e| e.pointer == ptr && e.message.contains(text)),
            "no error at {ptr:?} containing {text:?}; got {errs:#?}"
        );
    }

    #[test]
    fn the_example_validates() {
        let p = validate(&example()).unwrap();
        assert_eq!(p.name, "paper-exp3");
        assert_eq!((p.width, p.height), (2.0, 1.0));
        assert_eq!((p.cells_per_unit, p.steps, p.t_end), (32, 32, 1.0));
        assert_eq!(p.pattern, MeshPattern::Diagonal);
        assert_eq!(p.boundary.len(), 4);
        assert!(matches!(p.boundary[3].kind, BoundaryKind::Contact));
        assert_eq!(
            p.boundary[3].segment,
            Segment {
                a: [0.0, 0.0],
                b: [2.0, 0.0]
            }
        );
        assert_eq!(p.body_force.eval(0.3, 0.3, 0.05), [0.0, -0.1]);
        assert_eq!(p.body_force.eval(0.3, 0.3, 0.5), [0.0, -0.2]);
        assert!(p.body_force.is_constant_in_space());
        assert_eq!(
            p.material,
            Material {
                viscosity: Viscosity { eta: 2.0, xi: 2.0 },
                elasticity: Elasticity::Linear {
                    mu: 4.0,
                    lambda: 4.0
                }
            }
        );
        assert_eq!(p.friction, FrictionLaw::Tresca { g: 20.0 });
        assert_eq!(p.smallness, SmallnessPolicy::Refuse);
        let d = p.damage.unwrap();
        assert_eq!(d.kappa, 0.5);
        assert_eq!(d.source, DEFAULT_SOURCE);
        assert!(matches!(d.zeta0, ScalarField::Const(c) if c == 1.0));
        assert_eq!(p.output.fields, all_fields());
    }

    #[test]
    fn defaults_fill_the_minimal_scene() {
        let p = validate(&minimal()).unwrap();
        assert_eq!(p.name, "scene");
        assert_eq!((p.cells_per_unit, p.steps, p.k()), (4, 4, 0.25));
        assert_eq!(p.pattern, MeshPattern::Diagonal);
        assert!(p.body_force.is_zero() && p.u0.is_zero());
        assert_eq!(p.friction, DEFAULT_FRICTION);
        assert_eq!(p.smallness, SmallnessPolicy::Refuse);
        assert!(p.damage.is_none());
        assert_eq!(
            p.output,
            OutputSpec {
                every: 1,
                last: true,
                fields: all_fields()
            }
        );
        // Default damage source and initial damage.
        let mut doc = minimal();
        doc["damage"] = json!({"kappa": 1});
        let d = validate(&doc).unwrap().damage.unwrap();
        assert_eq!(d.source, DEFAULT_SOURCE);
        assert!(matches!(d.zeta0, ScalarField::Const(c) if c == 1.0));
        doc["damage"] = json!({"kappa": 1, "source": {"b": 5}});
        let d = validate(&doc).unwrap().damage.unwrap();
        assert_eq!(
            (d.source.a, d.source.b, d.source.zeta_star),
            (2.0, 5.0, 0.2)
        );
    }

    #[test]
    fn alternative_spellings() {
        let mut doc = minimal();
        doc["domain"] = json!({"rectangle": {"width": 3, "height": 0.5}});
        doc["mesh"] = json!({"h": "0.5", "pattern": "cross"});
        doc["time"] = json!({"T": "2", "steps": 8});
        doc["boundary"] = json!([{"type": "clamped", "from": [0, 0.5], "to": [0, 0]}]);
        doc["smallness"] = json!("warn");
        let p = validate(&doc).unwrap();
        assert_eq!((p.width, p.height, p.cells()), (3.0, 0.5, (6, 1)));
        assert_eq!(p.pattern, MeshPattern::Cross);
        assert_eq!((p.t_end, p.steps), (2.0, 8));
        assert_eq!(p.smallness, SmallnessPolicy::Warn);
        doc["mesh"]["pattern"] = json!("anti_diagonal");
        doc["time"] = json!({"t_end": 2, "N": 8.0});
        let p = validate(&doc).unwrap();
        assert_eq!((p.pattern, p.steps), (MeshPattern::AntiDiagonal, 8));
    }

    #[test]
    fn other_laws_validate() {
        let mut doc = example();
        doc["material"]["elasticity"] = json!({"type": "von_mises", "eta_b": 3, "sigma_y": 0.5});
        doc["friction"] = json!({"law": "slip_weakening", "mu0": 1, "mu1": 0.5, "alpha": 10});
        let p = validate(&doc).unwrap();
        assert_eq!(
            p.material.elasticity,
            Elasticity::VonMises {
                eta_b: 3.0,
                sigma_y: 0.5
            }
        );
        assert_eq!(
            p.friction,
            FrictionLaw::SlipWeakening {
                mu0: 1.0,
                mu1: 0.5,
                alpha: 10.0
            }
        );
        doc["friction"] =
            json!({"law": "piecewise_linear", "points": [[0, 1], [0.1, 0.5], [1, 0.4]]});
        let p = validate(&doc).unwrap();
        assert_eq!(
            p.friction,
            FrictionLaw::PiecewiseLinear {
                points: vec![[0.0, 1.0], [0.1, 0.5], [1.0, 0.4]]
            }
        );
    }

    #[test]
    fn formulas_become_fields() {
        let mut doc = example();
        doc["loads"]["f0"] = json!(["1/4", "x*t"]);
        doc["boundary"][1]["f2"] = json!(["sin(pi*x)", 0]);
        doc["initial"]["u0"] = json!(["0.01*x*y", "0"]);
        doc["damage"]["zeta0"] = json!("1 - 0.5*exp(-((x-1)^2 + (y-0.5)^2)/0.01)");
        let p = validate(&doc).unwrap();
        assert!(matches!(p.body_force.0[0], ScalarField::Const(c) if c == 0.25));
        assert_eq!(p.body_force.eval(2.0, 0.0, 0.5)[1], 1.0);
        assert!(!p.body_force.is_constant_in_space());
        assert!(p.u0.0[1].is_zero(), "constant formulas are folded");
        assert!((p.u0.eval(1.0, 1.0, 0.0)[0] - 0.01).abs() < 1e-15);
        let BoundaryKind::Traction(f2) = &p.boundary[1].kind else {
            panic!("traction expected")
        };
        assert!((f2.eval(0.5, 1.0, 0.0)[0] - 1.0).abs() < 1e-15);
        let zeta0 = p.damage.unwrap().zeta0;
        assert!((zeta0.eval(1.0, 0.5, 0.0) - 0.5).abs() < 1e-15);
    }

    #[test]
    fn malformed_documents_give_one_error_at_the_root() {
        for doc in [json!([1, 2]), json!("scene"), json!(null), json!(3)] {
            let errs = errors(&doc);
            assert_eq!(errs.len(), 1, "{errs:?}");
            assert_eq!(errs[0].pointer, "");
            assert!(errs[0].message.contains("must be an object"));
        }
        let errs = errors(&json!({}));
        let ptrs: BTreeSet<&str> = errs.iter().map(|e| e.pointer.as_str()).collect();
        let want: BTreeSet<&str> = ["/domain", "/mesh", "/time", "/boundary", "/material"].into();
        assert_eq!(ptrs, want);
        assert_error(
            &json!({"domain": 1}),
            "/domain",
            "must be an object, got the number 1",
        );
    }

    #[test]
    fn unknown_fields_are_reported_with_their_pointer() {
        let mut doc = example();
        doc["material"]["viscosity"]["etaa"] = json!(1);
        doc["frictoin"] = json!({});
        doc["boundary"][0]["f3"] = json!([0, 0]);
        doc["weird/key~"] = json!(0);
        assert_error(&doc, "/material/viscosity/etaa", "did you mean 'eta'?");
        assert_error(&doc, "/frictoin", "did you mean 'friction'?");
        assert_error(&doc, "/boundary/0/f3", "unknown field 'f3'");
        assert_error(&doc, "/weird~1key~0", "unknown field");
        assert_eq!(errors(&doc).len(), 4);
    }

    #[test]
    fn variant_fields_are_checked_against_their_variant() {
        let mut doc = example();
        doc["boundary"][0]["f2"] = json!([1, 0]);
        assert_error(
            &doc,
            "/boundary/0/f2",
            "belongs to type \"traction\", not to \"clamped\"",
        );
        let mut doc = example();
        doc["material"]["elasticity"] =
            json!({"type": "von_mises", "mu": 1, "eta_b": 1, "sigma_y": 1});
        assert_error(
            &doc,
            "/material/elasticity/mu",
            "belongs to type \"linear\"",
        );
        let mut doc = example();
        doc["friction"] = json!({"law": "tresa", "g": 1});
        let errs = errors(&doc);
        assert_eq!(errs.len(), 1, "a misspelt tag flags only itself: {errs:?}");
        assert_error(&doc, "/friction/law", "did you mean \"tresca\"?");
        let mut doc = example();
        doc["friction"] = json!({"g": 1});
        assert_error(&doc, "/friction/law", "missing required field 'law'");
    }

    #[test]
    fn bad_numbers_are_refused() {
        let cases: &[(&str, Value, &str)] = &[
            ("/material/viscosity/eta", json!(-2), "must be > 0, got -2"),
            (
                "/material/viscosity/eta",
                json!("NaN"),
                "expected a number > 0",
            ),
            ("/material/viscosity/xi", json!(-0.1), "≥ 0"),
            ("/material/elasticity/mu", json!(0), "> 0"),
            ("/material/elasticity/lambda", json!(null), "got null"),
            ("/domain/width", json!("inf"), "expected a number > 0"),
            ("/damage/kappa", json!(0), "> 0"),
            ("/damage/source/zeta_star", json!(0), "in (0, 1]"),
            ("/damage/source/a", json!(-1), "≥ 0"),
            ("/damage/zeta0", json!(1.5), "in [0, 1]"),
            ("/damage/zeta0", json!("2 - 1/2"), "in [0, 1]"),
            ("/friction/g", json!(-1), "≥ 0"),
            ("/output/every", json!(-1), "whole number ≥ 0"),
            ("/output/every", json!(1.5), "whole number ≥ 0"),
            ("/output/last", json!(1), "true or false"),
            ("/output/fields/1", json!("stress"), "must be one of"),
            (
                "/mesh/pattern",
                json!("diagonals"),
                "did you mean \"diagonal\"?",
            ),
            ("/smallness", json!("ignore"), "\"refuse\", \"warn\""),
            ("/name", json!(""), "1 to 200 characters"),
            (
                "/boundary/1/type",
                json!("free"),
                "\"clamped\", \"traction\", \"contact\"",
            ),
        ];
        for (ptr, v, text) in cases {
            let mut doc = example();
            set(&mut doc, ptr, v.clone());
            assert_error(&doc, ptr, text);
        }
    }

    #[test]
    fn mesh_and_time_steps_must_tile_exactly() {
        let cases: &[(&str, Value, &str)] = &[
            ("/mesh/h", json!("1/0"), "divides by zero"),
            ("/mesh/h", json!("inf"), "not a number"),
            ("/mesh/h", json!("abc"), "not a number"),
            ("/mesh/h", json!(-0.5), "> 0"),
            ("/mesh/h", json!(3), "at most 2"),
            ("/mesh/h", json!([1]), "expected a number or a ratio"),
            ("/time/k", json!("1/0"), "divides by zero"),
            ("/time/k", json!(0.3), "whole number of steps"),
            ("/time/k", json!(2), "longer than t_end"),
            ("/time/t_end", json!(0), "> 0"),
        ];
        for (ptr, v, text) in cases {
            let mut doc = example();
            set(&mut doc, ptr, v.clone());
            assert_error(&doc, ptr, text);
        }
        let mut doc = example();
        set(&mut doc, "/domain/width", json!(2.01));
        assert_error(
            &doc,
            "/mesh/h",
            "the width 2.01 is not a whole number of cells",
        );
        // Rounding noise is tolerated: 0.1 is 1/10 up to the last bit.
        let mut doc = minimal();
        set(&mut doc, "/mesh/h", json!(0.1));
        set(&mut doc, "/time", json!({"t_end": 0.3, "k": 0.1}));
        let p = validate(&doc).unwrap();
        assert_eq!((p.cells_per_unit, p.steps), (10, 3));
    }

    #[test]
    fn time_needs_one_end_and_one_step() {
        let mut doc = example();
        doc["time"] = json!({"t_end": 1, "k": "1/4", "N": 4});
        assert_error(&doc, "/time/N", "exactly one of k, N");
        doc["time"] = json!({"t_end": 1, "T": 1, "k": "1/4"});
        assert_error(&doc, "/time/T", "not both");
        doc["time"] = json!({"t_end": 1});
        assert_error(&doc, "/time/k", "missing the time step");
        doc["time"] = json!({"k": "1/4"});
        assert_error(&doc, "/time/t_end", "missing required field 't_end'");
        doc["time"] = json!({"t_end": 1, "N": 0});
        assert_error(&doc, "/time/N", "whole number ≥ 1");
        doc["time"] = json!({"t_end": 1, "steps": "4"});
        assert_error(&doc, "/time/steps", "whole number ≥ 1");
    }

    #[test]
    fn boundary_geometry_is_checked() {
        // Overlap: the error is at the second segment.
        let mut doc = example();
        doc["boundary"][2] = json!({"type": "traction", "from": [1, 1], "to": [1.5, 1]});
        assert_error(&doc, "/boundary/2", "overlaps /boundary/1 on the top side");
        // Overlap within parts of the same type, and at a later index.
        let mut doc = example();
        doc["boundary"]
            .as_array_mut()
            .unwrap()
            .push(json!({"type": "clamped", "from": [0, 0.5], "to": [0, 0.75]}));
        assert_error(
            &doc,
            "/boundary/4",
            "overlaps /boundary/0 on the left side x = 0, for y in [0.5, 0.75]",
        );
        // Touching at an end point is fine (experiment 2's bottom).
        assert!(validate(&presets::get("paper-exp2").unwrap()).is_ok());
        // Off the boundary, across a corner, zero length, outside a side's range.
        let cases: &[(Value, &str, &str)] = &[
            (
                json!({"type": "contact", "from": [0.5, 0.5], "to": [1, 0]}),
                "/boundary/3/from",
                "not on the boundary",
            ),
            (
                json!({"type": "contact", "from": [0, 0], "to": [3, 0]}),
                "/boundary/3/to",
                "not on the boundary",
            ),
            (
                json!({"type": "contact", "from": [0, 0.5], "to": [1, 0]}),
                "/boundary/3/to",
                "must lie on one side",
            ),
            (
                json!({"type": "contact", "from": [1, 0], "to": [1, 0]}),
                "/boundary/3/to",
                "zero length",
            ),
            (
                json!({"type": "contact", "from": [1], "to": [1, 0]}),
                "/boundary/3/from",
                "expected a point",
            ),
            (
                json!({"type": "contact", "from": [1, "0"], "to": [1, 0]}),
                "/boundary/3/from/1",
                "expected a number",
            ),
            (
                json!({"type": "contact", "to": [1, 0]}),
                "/boundary/3/from",
                "missing required field 'from'",
            ),
        ];
        for (part, ptr, text) in cases {
            let mut doc = example();
            doc["boundary"][3] = part.clone();
            assert_error(&doc, ptr, text);
        }
        // Points within round-off of a side are snapped onto it.
        let mut doc = example();
        doc["boundary"][2] =
            json!({"type": "traction", "from": [2.0000000000000004, 0], "to": [2, 1]});
        let p = validate(&doc).unwrap();
        assert_eq!(p.boundary[2].segment.a, [2.0, 0.0]);
    }

    #[test]
    fn a_clamped_part_is_required() {
        let mut doc = example();
        doc["boundary"][0]["type"] = json!("traction");
        assert_error(
            &doc,
            "/boundary",
            "at least one clamped segment is required",
        );
        doc["boundary"] = json!([]);
        assert_error(&doc, "/boundary", "Korn's inequality");
        doc["boundary"] = json!({"type": "clamped"});
        assert_error(&doc, "/boundary", "must be an array");
    }

    #[test]
    fn formulas_are_checked() {
        let cases: &[(&str, Value, &str)] = &[
            ("/loads/f0/1", json!("z*t"), "unknown variable 'z'"),
            (
                "/loads/f0/0",
                json!("1/x"),
                "evaluates to inf at (x, y, t) = (0, 0, 0)",
            ),
            (
                "/loads/f0/0",
                json!("sqrt(t - 0.75)"),
                "evaluates to NaN at (x, y, t) = (0, 0, 0)",
            ),
            ("/loads/f0/0", json!("1/0"), "evaluates to inf"),
            ("/loads/f0/0", json!("2x"), "invalid formula"),
            ("/loads/f0/0", json!(true), "expected a number or a formula"),
            ("/loads/f0", json!([1, 2, 3]), "expected a vector"),
            ("/initial/u0/0", json!("t"), "x and y only"),
            (
                "/damage/zeta0",
                json!("1 - x"),
                "evaluates to -0.5 at (x, y) = (1.5, 0)",
            ),
            ("/damage/zeta0", json!("t"), "x and y only"),
            ("/boundary/1/f2/0", json!("1/(y - 1)"), "evaluates to"),
        ];
        for (ptr, v, text) in cases {
            let mut doc = example();
            set(&mut doc, ptr, v.clone());
            assert_error(&doc, ptr, text);
        }
        // f2 is sampled on its own segment only: 1/(y - 0.5) is finite on the top side.
        let mut doc = example();
        doc["boundary"][1]["f2"] = json!(["1/(y - 0.5)", 0]);
        assert!(validate(&doc).is_ok());
        let mut doc = example();
        doc["loads"]["f0"][0] = json!("x".repeat(1001));
        assert_error(&doc, "/loads/f0/0", "too long");
    }

    #[test]
    fn friction_tables_are_checked() {
        let cases: &[(Value, &str, &str)] = &[
            (json!([[0.1, 1]]), "/friction/points/0/0", "start at r = 0"),
            (
                json!([[0, 1], [0.5, 1], [0.5, 2]]),
                "/friction/points/2/0",
                "increase strictly",
            ),
            (json!([[0, 1], [1, -1]]), "/friction/points/1/1", "≥ 0"),
            (json!([[0, 1], [1]]), "/friction/points/1", "a pair [r, μ]"),
            (json!([]), "/friction/points", "1 to 1000 points"),
            (json!("0,1"), "/friction/points", "got the string"),
        ];
        for (points, ptr, text) in cases {
            let mut doc = example();
            doc["friction"] = json!({"law": "piecewise_linear", "points": points});
            assert_error(&doc, ptr, text);
        }
        let mut doc = example();
        let many: Vec<Value> = (0..1001).map(|i| json!([i, 1])).collect();
        doc["friction"] = json!({"law": "piecewise_linear", "points": many});
        assert_error(&doc, "/friction/points", "got 1001 points");
    }

    #[test]
    fn friction_is_checked_even_without_contact() {
        let mut doc = presets::get("paper-exp1").unwrap();
        remove(&mut doc, "/friction");
        assert_eq!(validate(&doc).unwrap().friction, DEFAULT_FRICTION);
        doc["friction"] = json!({"law": "tresca", "g": -1});
        assert_error(&doc, "/friction/g", "≥ 0");
    }

    #[test]
    fn all_errors_are_collected() {
        let mut doc = example();
        set(&mut doc, "/material/viscosity/eta", json!(-1));
        set(&mut doc, "/time/k", json!(0.3));
        set(&mut doc, "/boundary/2/to", json!([5, 5]));
        set(&mut doc, "/output/fields/0", json!("U"));
        doc["extra"] = json!(1);
        let ptrs: BTreeSet<String> = errors(&doc).into_iter().map(|e| e.pointer).collect();
        for p in [
            "/material/viscosity/eta",
            "/time/k",
            "/boundary/2/to",
            "/output/fields/0",
            "/extra",
        ] {
            assert!(ptrs.contains(p), "{p} missing from {ptrs:?}");
        }
    }

    #[test]
    fn errors_display_and_serialize() {
        let mut doc = example();
        set(&mut doc, "/material/viscosity/eta", json!(-1));
        let err = validate(&doc).unwrap_err();
        let text = err.to_string();
        assert!(text.starts_with("invalid scene (1 problem)"), "{text}");
        assert!(text.contains("at /material/viscosity/eta: must be > 0, got -1"));
        let json = serde_json::to_value(&err).unwrap();
        assert_eq!(
            json,
            json!([{"pointer": "/material/viscosity/eta", "message": "must be > 0, got -1"}])
        );
        let root = validate(&json!(1)).unwrap_err().to_string();
        assert!(
            root.contains("at (document): a scene must be an object"),
            "{root}"
        );
    }

    #[test]
    fn ratios() {
        let ok: &[(Value, f64)] = &[
            (json!(0.25), 0.25),
            (json!(3), 3.0),
            (json!("1/32"), 1.0 / 32.0),
            (json!(" 1 / 3 "), 1.0 / 3.0),
            (json!("0.25"), 0.25),
            (json!("1e-2"), 0.01),
            (json!("-1/2"), -0.5),
            (json!(".5/2."), 0.25),
        ];
        for (v, want) in ok {
            assert_eq!(parse_ratio(v), Ok(*want), "{v}");
        }
        for bad in [
            json!("1/0"),
            json!("inf"),
            json!("NaN"),
            json!("infinity"),
            json!("1e400"),
            json!("1/2/3"),
            json!(""),
            json!("/"),
            json!("1/"),
            json!(null),
            json!([1, 32]),
        ] {
            assert!(parse_ratio(&bad).is_err(), "{bad} accepted");
        }
    }

    #[test]
    fn overrides_replace_the_discretisation() {
        let mut doc = example();
        apply_overrides(
            &mut doc,
            &Overrides {
                h: Some(json!("1/8")),
                k: Some(json!(0.25)),
                t_end: None,
            },
        );
        let p = validate(&doc).unwrap();
        assert_eq!((p.cells_per_unit, p.steps), (8, 4));

        // k replaces N; t_end replaces its alias T.
        let mut doc = minimal();
        doc["time"] = json!({"T": 1, "N": 4});
        apply_overrides(
            &mut doc,
            &Overrides {
                k: Some(json!("1/10")),
                t_end: Some(json!(2)),
                ..Overrides::default()
            },
        );
        assert_eq!(doc["time"], json!({"t_end": 2, "k": "1/10"}));
        let p = validate(&doc).unwrap();
        assert_eq!((p.t_end, p.steps), (2.0, 20));

        // Only t_end: with k given, N follows; with N given, k follows.
        let t2 = Overrides {
            t_end: Some(json!("1/2")),
            ..Overrides::default()
        };
        let mut doc = example();
        apply_overrides(&mut doc, &t2);
        assert_eq!(validate(&doc).unwrap().steps, 16);
        let mut doc = minimal();
        apply_overrides(&mut doc, &t2);
        let p = validate(&doc).unwrap();
        assert_eq!((p.steps, p.k()), (4, 0.125));

        // Missing sections are created; bad values are reported at the usual pointers.
        let mut doc = json!({});
        apply_overrides(
            &mut doc,
            &Overrides {
                h: Some(json!("1/0")),
                k: Some(json!(-1)),
                t_end: Some(json!(1)),
            },
        );
        assert_error(&doc, "/mesh/h", "divides by zero");
        assert_error(&doc, "/time/k", "> 0");
        // Documents of the wrong shape are left for validation to report.
        let mut doc = json!({"mesh": 5});
        apply_overrides(
            &mut doc,
            &Overrides {
                h: Some(json!(1)),
                ..Overrides::default()
            },
        );
        assert_eq!(doc["mesh"], json!(5));
        let mut doc = json!([1]);
        apply_overrides(&mut doc, &t2);
        assert_eq!(doc, json!([1]));
    }

    // -----------------------------------------------------------------------------------------
    // The schema drift test.

    const SCHEMA: &str = include_str!("../../../../api/scene.schema.json");

    fn schema() -> Value {
        serde_json::from_str(SCHEMA).expect("api/scene.schema.json is not valid JSON")
    }

    /// Follows local `$ref`s ("#/$defs/name").
    fn resolve<'a>(root: &'a Value, mut node: &'a Value) -> &'a Value {
        while let Some(r) = node.get("$ref").and_then(Value::as_str) {
            let ptr = r.strip_prefix('#').expect("only local $refs");
            node = root
                .pointer(ptr)
                .unwrap_or_else(|| panic!("dangling $ref {r}"));
        }
        node
    }

    /// The schema node reached through property names ("[]" steps into array items).
    fn at<'a>(root: &'a Value, path: &[&str]) -> &'a Value {
        let mut node = resolve(root, root);
        for step in path {
            node = if *step == "[]" {
                &node["items"]
            } else {
                &node["properties"][*step]
            };
            assert!(!node.is_null(), "schema lacks {path:?} at {step}");
            node = resolve(root, node);
        }
        node
    }

    fn props(node: &Value) -> BTreeSet<&str> {
        node["properties"]
            .as_object()
            .map(|m| m.keys().map(String::as_str).collect())
            .unwrap_or_default()
    }

    fn set_of<'a>(names: &[&'a str]) -> BTreeSet<&'a str> {
        names.iter().copied().collect()
    }

    /// The oneOf variants of a tagged object, by their tag's const: name → properties.
    fn variants<'a>(
        root: &'a Value,
        node: &'a Value,
        tag: &str,
    ) -> BTreeMap<&'a str, BTreeSet<&'a str>> {
        node["oneOf"]
            .as_array()
            .expect("tagged objects are a oneOf")
            .iter()
            .map(|v| {
                let v = resolve(root, v);
                let name = v["properties"][tag]["const"]
                    .as_str()
                    .expect("variant tag const");
                (name, props(v))
            })
            .collect()
    }

    fn rust_variants<'a>(list: &[(&'a str, &[&'a str])]) -> BTreeMap<&'a str, BTreeSet<&'a str>> {
        list.iter().map(|(n, f)| (*n, set_of(f))).collect()
    }

    fn enum_of(node: &Value) -> BTreeSet<&str> {
        node["enum"]
            .as_array()
            .expect("an enum")
            .iter()
            .map(|v| v.as_str().unwrap())
            .collect()
    }

    #[test]
    fn schema_lists_exactly_the_accepted_fields() {
        let root = schema();
        let s = &root;
        assert_eq!(
            s["$schema"],
            json!("https://json-schema.org/draft/2020-12/schema")
        );
        assert_eq!(props(at(s, &[])), set_of(TOP_FIELDS), "top level");
        let objects: &[(&[&str], &[&str])] = &[
            (&["domain"], DOMAIN_FIELDS),
            (&["domain", "rectangle"], RECTANGLE_FIELDS),
            (&["mesh"], MESH_FIELDS),
            (&["time"], TIME_FIELDS),
            (&["loads"], LOADS_FIELDS),
            (&["material"], MATERIAL_FIELDS),
            (&["material", "viscosity"], VISCOSITY_FIELDS),
            (&["damage"], DAMAGE_FIELDS),
            (&["damage", "source"], SOURCE_FIELDS),
            (&["initial"], INITIAL_FIELDS),
            (&["output"], OUTPUT_FIELDS),
        ];
        for (path, fields) in objects {
            assert_eq!(props(at(s, path)), set_of(fields), "{path:?}");
            assert_eq!(
                at(s, path)["additionalProperties"],
                json!(false),
                "{path:?}"
            );
        }
        let part = at(s, &["boundary", "[]"]);
        let all_part_fields: BTreeSet<&str> = PART_VARIANTS
            .iter()
            .flat_map(|(_, f)| f.iter().copied())
            .collect();
        assert_eq!(props(part), all_part_fields);
        let part_types: Vec<&str> = PART_VARIANTS.iter().map(|(n, _)| *n).collect();
        assert_eq!(enum_of(&part["properties"]["type"]), set_of(&part_types));
        assert_eq!(
            variants(s, at(s, &["material", "elasticity"]), "type"),
            rust_variants(ELASTICITY_VARIANTS)
        );
        assert_eq!(
            variants(s, at(s, &["friction"]), "law"),
            rust_variants(FRICTION_VARIANTS)
        );
        assert_eq!(enum_of(at(s, &["mesh", "pattern"])), set_of(PATTERNS));
        assert_eq!(enum_of(at(s, &["smallness"])), set_of(SMALLNESS));
        assert_eq!(
            enum_of(&at(s, &["output", "fields"])["items"]),
            set_of(OUTPUT_FIELD_NAMES)
        );
    }

    #[test]
    fn schema_required_fields_match_validation() {
        let root = schema();
        let required: BTreeSet<&str> = root["required"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_str().unwrap())
            .collect();
        let full = presets::get("paper-exp3").unwrap();
        for key in full.as_object().unwrap().keys() {
            let mut doc = full.clone();
            remove(&mut doc, &format!("/{key}"));
            let result = validate(&doc);
            if required.contains(key.as_str()) {
                let errs = result.expect_err(key).0;
                assert!(
                    errs.iter().any(|e| e.pointer == format!("/{key}")),
                    "{key}: {errs:?}"
                );
            } else {
                assert!(
                    result.is_ok(),
                    "{key} is optional in the schema: {result:?}"
                );
            }
        }
    }

    /// Every object key used in `doc` is a property the schema allows at that place.
    fn check_keys(root: &Value, node: &Value, doc: &Value, ptr: &str) {
        let node = resolve(root, node);
        let alternatives: Vec<&Value> = ["oneOf", "anyOf"]
            .iter()
            .filter_map(|k| node[*k].as_array())
            .flatten()
            .map(|v| resolve(root, v))
            .collect();
        match doc {
            Value::Object(m) => {
                // For tagged unions, the variant whose properties include every key.
                let candidates: Vec<&Value> = std::iter::once(node).chain(alternatives).collect();
                let chosen = candidates
                    .iter()
                    .find(|c| {
                        !props(c).is_empty() && m.keys().all(|k| props(c).contains(k.as_str()))
                    })
                    .unwrap_or_else(|| panic!("{ptr}: keys {:?} not in the schema", m.keys()));
                for (k, v) in m {
                    check_keys(root, &chosen["properties"][k], v, &join(ptr, k));
                }
            }
            Value::Array(items) => {
                for (i, item) in items.iter().enumerate() {
                    let item_schema = node["prefixItems"].get(i).unwrap_or(&node["items"]);
                    check_keys(root, item_schema, item, &index(ptr, i));
                }
            }
            _ => {}
        }
    }

    #[test]
    fn presets_use_only_schema_properties() {
        let root = schema();
        let top = props(&root);
        for name in presets::names() {
            let doc = presets::get(name).unwrap();
            for key in doc.as_object().unwrap().keys() {
                assert!(
                    top.contains(key.as_str()),
                    "{name}: /{key} not in the schema"
                );
            }
            check_keys(&root, &root, &doc, "");
        }
        check_keys(&root, &root, &example(), "");
    }

    // -----------------------------------------------------------------------------------------
    // No panics, whatever the input.

    fn known_keys() -> Vec<&'static str> {
        let mut keys: Vec<&str> = [
            TOP_FIELDS,
            DOMAIN_FIELDS,
            MESH_FIELDS,
            TIME_FIELDS,
            LOADS_FIELDS,
            MATERIAL_FIELDS,
            VISCOSITY_FIELDS,
            DAMAGE_FIELDS,
            SOURCE_FIELDS,
            INITIAL_FIELDS,
            OUTPUT_FIELDS,
        ]
        .concat();
        for (_, f) in PART_VARIANTS
            .iter()
            .chain(ELASTICITY_VARIANTS)
            .chain(FRICTION_VARIANTS)
        {
            keys.extend_from_slice(f);
        }
        keys.push("law");
        keys
    }

    fn arb_json() -> impl Strategy<Value = Value> {
        let leaf = prop_oneof![
            Just(Value::Null),
            any::<bool>().prop_map(Value::Bool),
            any::<i64>().prop_map(Value::from),
            any::<u64>().prop_map(Value::from),
            any::<f64>().prop_map(Value::from), // NaN and inf become null
            (-3.0f64..3.0).prop_map(Value::from),
            prop::sample::select(vec![
                "1/32",
                "1/0",
                "0/0",
                "NaN",
                "inf",
                "-1",
                "0",
                "1e308",
                "x",
                "t",
                "1/x",
                "x^y^t",
                "clamped",
                "traction",
                "contact",
                "linear",
                "von_mises",
                "tresca",
                "slip_weakening",
                "piecewise_linear",
                "diagonal",
                "warn",
                "zeta",
            ])
            .prop_map(Value::from),
            ".{0,12}".prop_map(Value::String),
        ];
        leaf.prop_recursive(5, 96, 6, |inner| {
            let key = prop_oneof![
                4 => prop::sample::select(known_keys()).prop_map(String::from),
                1 => ".{0,6}",
            ];
            prop_oneof![
                prop::collection::vec(inner.clone(), 0..6).prop_map(Value::Array),
                prop::collection::btree_map(key, inner, 0..8)
                    .prop_map(|m| Value::Object(m.into_iter().collect())),
            ]
        })
    }

    /// Every pointer in a document, the root excluded.
    fn pointers(v: &Value, ptr: &str, out: &mut Vec<String>) {
        match v {
            Value::Object(m) => {
                for (k, c) in m {
                    let p = join(ptr, k);
                    out.push(p.clone());
                    pointers(c, &p, out);
                }
            }
            Value::Array(a) => {
                for (i, c) in a.iter().enumerate() {
                    let p = index(ptr, i);
                    out.push(p.clone());
                    pointers(c, &p, out);
                }
            }
            _ => {}
        }
    }

    /// Replaces (or, in an object, sometimes removes) the value at a random place.
    fn mutate(doc: &mut Value, at: prop::sample::Index, with: Value, delete: bool) {
        let mut ptrs = Vec::new();
        pointers(doc, "", &mut ptrs);
        if ptrs.is_empty() {
            *doc = with;
            return;
        }
        let ptr = &ptrs[at.index(ptrs.len())];
        let (parent, key) = ptr.rsplit_once('/').unwrap();
        if delete {
            if let Some(Value::Object(m)) = doc.pointer_mut(parent) {
                m.remove(&key.replace("~1", "/").replace("~0", "~"));
                return;
            }
        }
        if let Some(slot) = doc.pointer_mut(ptr) {
            *slot = with;
        }
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(512))]

        #[test]
        fn arbitrary_json_never_panics(doc in arb_json()) {
            let _ = validate(&doc);
            let mut wrapped = example();
            if let Value::Object(m) = &doc {
                for (k, v) in m {
                    wrapped[k.as_str()] = v.clone();
                }
            }
            if let Err(e) = validate(&wrapped) {
                prop_assert!(!e.0.is_empty());
                for err in &e.0 {
                    prop_assert!(err.pointer.is_empty() || err.pointer.starts_with('/'));
                    prop_assert!(!err.message.is_empty() && !err.message.contains("internal error"));
                }
            }
        }

        #[test]
        fn mutated_presets_never_panic(
            which in prop::sample::select(presets::names()),
            edits in prop::collection::vec((any::<prop::sample::Index>(), arb_json(), any::<bool>()), 1..4),
        ) {
            let mut doc = presets::get(which).unwrap();
            for (at, with, delete) in edits {
                mutate(&mut doc, at, with, delete);
            }
            match validate(&doc) {
                Ok(p) => {
                    // Whatever passes is usable: counts are positive and data finite.
                    prop_assert!(p.steps >= 1 && p.cells_per_unit >= 1);
                    prop_assert!(p.k().is_finite() && p.k() > 0.0);
                    let (nx, ny) = p.cells();
                    prop_assert!(nx >= 1 && ny >= 1);
                }
                Err(e) => {
                    prop_assert!(!e.0.is_empty());
                    prop_assert!(e.0.iter().all(|err| !err.message.contains("internal error")), "{}", e);
                }
            }
        }

        #[test]
        fn overrides_never_panic(doc in arb_json(), h in arb_json(), k in arb_json(), t in arb_json()) {
            let mut doc = doc;
            apply_overrides(&mut doc, &Overrides { h: Some(h), k: Some(k), t_end: Some(t) });
            let _ = validate(&doc);
        }
    }
}
