//! Validation by example: every field, default, alternative spelling and error message; the
//! schema `api/scene.schema.json` against the field tables and the accepted scenes.

use std::collections::{BTreeMap, BTreeSet};
use std::sync::OnceLock;

use serde_json::json;

use super::damage::DEFAULT_SOURCE;
use super::fields::*;
use super::*;
use crate::problem::{
    BoundaryKind, Elasticity, FrictionLaw, Material, MeshPattern, ScalarField, Segment, Support,
    Viscosity,
};

/// The scene of the brief: paper experiment 3 with a ramped body force.
pub(super) fn example() -> Value {
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
    assert!(matches!(
        p.boundary[3].support,
        Support::Segment(Segment {
            a: [0.0, 0.0],
            b: [2.0, 0.0]
        })
    ));
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
            fields: all_fields(),
            estimate: false,
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
    doc["friction"] = json!({"law": "piecewise_linear", "points": [[0, 1], [0.1, 0.5], [1, 0.4]]});
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
    // The mesh object is read twice (mesh and domain); its typo is reported once.
    let mut doc = example();
    doc["mesh"]["hh"] = json!("1/8");
    assert_error(&doc, "/mesh/hh", "did you mean 'h'?");
    assert_eq!(errors(&doc).len(), 1, "{:?}", errors(&doc));
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
    doc["material"]["elasticity"] = json!({"type": "von_mises", "mu": 1, "eta_b": 1, "sigma_y": 1});
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
    doc["boundary"][2] = json!({"type": "traction", "from": [2.0000000000000004, 0], "to": [2, 1]});
    let p = validate(&doc).unwrap();
    assert!(matches!(p.boundary[2].support, Support::Segment(s) if s.a == [2.0, 0.0]));
}

#[test]
fn a_clamped_part_is_required() {
    let mut doc = example();
    doc["boundary"][0]["type"] = json!("traction");
    assert_error(&doc, "/boundary", "at least one clamped part is required");
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

const SCHEMA: &str = include_str!(concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/../../api/scene.schema.json"
));

fn schema() -> Value {
    serde_json::from_str(SCHEMA).expect("api/scene.schema.json is not valid JSON")
}

/// `api/scene.schema.json` as a validator (JSON Schema 2020-12), built once.
pub(super) fn schema_validator() -> &'static jsonschema::Validator {
    static VALIDATOR: OnceLock<jsonschema::Validator> = OnceLock::new();
    VALIDATOR.get_or_init(|| {
        jsonschema::validator_for(&schema()).expect("api/scene.schema.json is not a valid schema")
    })
}

/// The schema's complaints about `doc` (empty when it conforms).
pub(super) fn schema_errors(doc: &Value) -> Vec<String> {
    schema_validator()
        .iter_errors(doc)
        .map(|e| format!("at {}: {e}", e.instance_path()))
        .collect()
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
    // On a rectangle (not an imported mesh) the schema's "else" branch applies too.
    let required: BTreeSet<&str> = root["required"]
        .as_array()
        .unwrap()
        .iter()
        .chain(root["else"]["required"].as_array().unwrap())
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

/// The example scene of the user guide's scene format chapter.
fn readme_example() -> Value {
    let section = include_str!(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../docs/src/reference/scene-format.md"
    ));
    let start = section.find("```json\n").expect("a JSON example") + "```json\n".len();
    let end = start + section[start..].find("```").expect("the example's end");
    serde_json::from_str(&section[start..end]).expect("the guide's example is JSON")
}

#[test]
fn presets_and_examples_conform_to_the_schema() {
    let mut docs: Vec<(String, Value)> = presets::names()
        .iter()
        .map(|name| (name.to_string(), presets::get(name).unwrap()))
        .collect();
    docs.push(("the guide's example".into(), readme_example()));
    docs.push(("example()".into(), example()));
    docs.push(("minimal()".into(), minimal()));
    for (name, doc) in docs {
        assert!(validate(&doc).is_ok(), "{name} is refused");
        let errs = schema_errors(&doc);
        assert!(errs.is_empty(), "{name} breaks the schema: {errs:#?}");
    }
    // The validator and the schema both refuse an unknown field.
    let mut doc = example();
    doc["material"]["viscosity"]["etaa"] = json!(1);
    assert!(validate(&doc).is_err() && !schema_errors(&doc).is_empty());
}

/// The body forms and part selections: each misuse is refused at its pointer.
#[test]
fn body_forms_and_part_selections_are_checked() {
    let plate = || presets::get("plate-with-hole").unwrap();
    let bracket = || presets::get("l-bracket").unwrap();
    let rect = || presets::get("paper-exp3").unwrap();
    let cases: Vec<(Value, &str, &str)> = vec![
        (
            {
                let mut d = rect();
                d["domain"]["mesh"] = json!("plate-with-hole.msh");
                d
            },
            "/domain",
            "one form",
        ),
        (
            {
                let mut d = rect();
                d["mesh"]["refine"] = json!(1);
                d
            },
            "/mesh/refine",
            "smaller h",
        ),
        (
            {
                let mut d = plate();
                d["mesh"] = json!({"h": "1/8"});
                d
            },
            "/mesh/h",
            "refine, not h",
        ),
        (
            {
                let mut d = plate();
                d["mesh"] = json!({"refine": 9});
                d
            },
            "/mesh/refine",
            "at most 8",
        ),
        (
            {
                let mut d = plate();
                d["domain"]["mesh"] = json!("../etc/passwd");
                d
            },
            "/domain/mesh",
            "no mesh",
        ),
        (
            {
                let mut d = rect();
                d["boundary"][0] = json!({"type": "clamped", "group": "x"});
                d
            },
            "/boundary/0/group",
            "imported mesh",
        ),
        (
            {
                let mut d = rect();
                d["boundary"][0] =
                    json!({"type": "clamped", "from": [0, 0], "to": [0, 1], "where": "x"});
                d
            },
            "/boundary/0/where",
            "on",
        ),
        (
            {
                let mut d = rect();
                d["boundary"][0] = json!({"type": "clamped", "on": "x", "group": "g"});
                d
            },
            "/boundary/0",
            "one way",
        ),
        (
            {
                let mut d = rect();
                d["boundary"][0] = json!({"type": "clamped", "on": "x + t"});
                d
            },
            "/boundary/0/on",
            "uses t",
        ),
        (
            {
                let mut d = bracket();
                d["domain"]["polygon"] = json!([[0, 0], [1, 1], [1, 0], [0, 1]]);
                d
            },
            "/domain/polygon/0",
            "intersects itself",
        ),
        (
            {
                let mut d = bracket();
                d["mesh"] = json!({"refine": 1});
                d
            },
            "/mesh/h",
            "the mesh size",
        ),
    ];
    for (doc, ptr, text) in cases {
        let errs = validate(&doc).unwrap_err().0;
        assert!(
            errs.iter()
                .any(|e| e.pointer == ptr && e.message.contains(text)),
            "{ptr} / {text}: {errs:?}"
        );
    }
}

/// A mesh that cannot be loaded is one error, at /domain/mesh: the boundary groups, the mesh
/// section and the vectors, all read against the body, are not read (before, a 3D scene on a
/// wrong id had 8 errors, 7 of them about 3-vectors on a "2D" body and groups of no mesh).
#[test]
fn a_mesh_that_cannot_be_loaded_is_the_only_error() {
    let mut doc = presets::get("standing-cylinder").unwrap();
    set(&mut doc, "/domain", json!({"mesh": "no-such-mesh"}));
    set(&mut doc, "/mesh", json!({"refine": 1}));
    let errs = errors(&doc);
    assert_eq!(errs.len(), 1, "{errs:#?}");
    assert_eq!(errs[0].pointer, "/domain/mesh");
    assert!(errs[0].message.contains("no-such-mesh"), "{errs:#?}");
    // Errors elsewhere than the body's sections are still reported beside it.
    set(&mut doc, "/material/viscosity/eta", json!(-1));
    let pointers: Vec<String> = errors(&doc).into_iter().map(|e| e.pointer).collect();
    assert_eq!(pointers.len(), 2, "{pointers:?}");
    assert!(pointers.contains(&"/domain/mesh".to_string()));
}

/// A 3D scene's vectors on a 2D mesh say that the body is 2D, as a 2D scene's on a 3D mesh
/// say that it is 3D.
#[test]
fn vectors_of_the_wrong_dimension_name_the_body_dimension() {
    let mut solid_on_plane = presets::get("standing-cylinder").unwrap();
    set(
        &mut solid_on_plane,
        "/domain",
        json!({"mesh": "plate-with-hole.msh"}),
    );
    assert_error(&solid_on_plane, "/loads/f0", "(the body is 2D)");
    assert_error(&solid_on_plane, "/initial/u0", "(the body is 2D)");
    let mut plane_on_solid = presets::get("plate-with-hole").unwrap();
    set(
        &mut plane_on_solid,
        "/domain",
        json!({"mesh": "standing-cylinder.msh"}),
    );
    assert_error(&plane_on_solid, "/loads/f0", "(the body is 3D)");
}
