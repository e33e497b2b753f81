//! Hostile input: property tests of [`super::validate`] over arbitrary and adversarial JSON
//! (extreme numbers, "NaN"/"Inf"/"1e400" strings, deep nesting, giant arrays, formulas that
//! divide by zero, very long formulas). Validation must answer Ok or Err — never panic — in
//! bounded time; whatever it accepts must set up and take a step without panicking, and
//! without NaN results (bad data is refused at its field). Arbitrary JSON and randomly edited
//! presets: no panic, and every scene accepted conforms to `api/scene.schema.json`.

use super::boundary::MAX_BOUNDARY_PARTS;
use super::fields::*;
use super::friction::MAX_TABLE_POINTS;
use super::output::MAX_OUTPUT_FIELDS;
use super::read::{index, join, MAX_ERRORS};
use super::tests::{example, schema_errors};
use super::*;
use crate::solve::stepper::Simulation;
use crate::solve::{SolveError, SolverSettings};
use proptest::prelude::*;
use serde_json::json;
use std::time::{Duration, Instant};

/// A small scene with every section present (so that edits have somewhere to go).
fn template(width: u32, n: u32, steps: u32) -> Value {
    json!({
        "domain": {"width": width, "height": 1},
        "mesh": {"h": format!("1/{n}")},
        "time": {"t_end": 1, "N": steps},
        "boundary": [
            {"type": "clamped", "from": [0, 0], "to": [0, 1]},
            {"type": "contact", "from": [0, 0], "to": [width, 0]},
            {"type": "traction", "from": [0, 1], "to": [width, 1], "f2": [-1, -1]}
        ],
        "loads": {"f0": [0, -0.2]},
        "material": {"viscosity": {"eta": 2, "xi": 2},
                     "elasticity": {"type": "linear", "mu": 4, "lambda": 4}},
        "friction": {"law": "tresca", "g": 1},
        "damage": {"kappa": 0.5, "source": {"a": 2, "b": 20, "zeta_star": 0.2}, "zeta0": 1},
        "initial": {"u0": [0, 0]}
    })
}

/// Where the edits go.
const SLOTS: &[&str] = &[
    "/domain/width",
    "/domain/height",
    "/mesh/h",
    "/time/t_end",
    "/time/N",
    "/material/viscosity/eta",
    "/material/viscosity/xi",
    "/material/elasticity/mu",
    "/material/elasticity/lambda",
    "/friction/g",
    "/friction",
    "/smallness",
    "/damage/kappa",
    "/damage/source/a",
    "/damage/source/b",
    "/damage/source/zeta_star",
    "/damage/zeta0",
    "/loads/f0/0",
    "/loads/f0/1",
    "/boundary/2/f2/0",
    "/boundary/2/f2/1",
    "/boundary/1/to",
    "/initial/u0/0",
    "/initial/u0/1",
];

fn extreme_number() -> impl Strategy<Value = Value> {
    prop_oneof![
        prop::sample::select(vec![
            0.0,
            -0.0,
            1.0,
            -1.0,
            0.5,
            2.0,
            5e-324,
            1e-308,
            1e-300,
            1e-12,
            1e12,
            1e300,
            1e308,
            -1e308,
            f64::MAX,
            f64::MIN,
            f64::EPSILON,
        ])
        .prop_map(Value::from),
        any::<i64>().prop_map(Value::from),
        any::<u64>().prop_map(Value::from),
        any::<f64>().prop_map(Value::from),
    ]
}

fn hostile_string() -> impl Strategy<Value = Value> {
    prop_oneof![
        prop::sample::select(vec![
            "NaN",
            "nan",
            "Inf",
            "-inf",
            "infinity",
            "1e400",
            "-1e400",
            "1e-400",
            "1/0",
            "0/0",
            "-1/0",
            "1/3",
            "1/1e-320",
            "1e308*10",
            "1/x",
            "1/(x - 0.5)",
            "1/(t - 0.5)",
            "1/(t - 0.25)",
            "1/(x - 0.25)",
            "1/(y - 1)",
            "log(x)",
            "sqrt(-x)",
            "sqrt(x - 0.3)",
            "x^1e308",
            "exp(1000*t)",
            "exp(710*t)",
            "tan(pi/2*x)",
            "1/sin(pi*x)",
            "0^-1",
            "(-1)^0.5",
            "1 + 0.5*sin(8*pi*x)",
            "min(1, 0.05 + abs(x - 1))",
            "1e308*x*y",
            "-1e300*t",
            "1/(1 - floor(4*x))",
        ])
        .prop_map(Value::from),
        "[-+*/^(),.0-9eExyt pimnaxsqrtlogfloor]{0,40}".prop_map(Value::String),
        (1usize..600).prop_map(|n| Value::String("x+".repeat(n) + "1")),
        (1usize..120).prop_map(|n| Value::String("(".repeat(n) + "x" + &")".repeat(n))),
        (1usize..400).prop_map(|n| Value::String("-".repeat(n) + "x")),
        (1usize..200).prop_map(|n| Value::String("2^".repeat(n) + "2")),
    ]
}

fn hostile_value() -> impl Strategy<Value = Value> {
    let leaf = prop_oneof![
        3 => extreme_number(),
        3 => hostile_string(),
        1 => Just(Value::Null),
        1 => any::<bool>().prop_map(Value::Bool),
        1 => prop::sample::select(vec![
            json!({"law": "slip_weakening", "mu0": 1e308, "mu1": 0, "alpha": 1e308}),
            json!({"law": "slip_weakening", "mu0": 1.2, "mu1": 0.4, "alpha": 3}),
            json!({"law": "piecewise_linear", "points": [[0, 1e308], [1e-300, 0]]}),
            json!({"law": "piecewise_linear", "points": [[0, 1], [5e-324, 0]]}),
            json!({"law": "tresca", "g": 1e308}),
            json!("warn"),
            json!([2, 0]),
        ]),
    ];
    leaf.prop_recursive(3, 24, 4, |inner| {
        prop_oneof![
            prop::collection::vec(inner.clone(), 0..4).prop_map(Value::Array),
            prop::collection::btree_map(".{0,4}", inner, 0..4)
                .prop_map(|m| Value::Object(m.into_iter().collect())),
        ]
    })
}

/// Positive numbers from tiny to huge: valid where a positive number is expected.
fn extreme_positive() -> impl Strategy<Value = Value> {
    prop::sample::select(vec![
        5e-324,
        1e-308,
        1e-300,
        1e-12,
        1e-4,
        0.5,
        1.0,
        2.0,
        1e4,
        1e12,
        1e300,
        1e308,
        f64::MAX,
    ])
    .prop_map(Value::from)
}

/// Slots that take numbers, and slots that take formulas.
const NUMBER_SLOTS: &[&str] = &[
    "/domain/width",
    "/mesh/h",
    "/time/t_end",
    "/material/viscosity/eta",
    "/material/viscosity/xi",
    "/material/elasticity/mu",
    "/material/elasticity/lambda",
    "/friction/g",
    "/damage/kappa",
    "/damage/source/a",
    "/damage/source/b",
    "/damage/source/zeta_star",
];
const FORMULA_SLOTS: &[&str] = &[
    "/damage/zeta0",
    "/loads/f0/0",
    "/loads/f0/1",
    "/boundary/2/f2/0",
    "/boundary/2/f2/1",
    "/initial/u0/0",
    "/initial/u0/1",
];

fn edit() -> impl Strategy<Value = (&'static str, Value)> {
    prop_oneof![
        3 => (prop::sample::select(NUMBER_SLOTS.to_vec()), extreme_positive()),
        3 => (prop::sample::select(FORMULA_SLOTS.to_vec()), hostile_string()),
        1 => (prop::sample::select(SLOTS.to_vec()), hostile_value()),
    ]
}

fn hostile_scene() -> impl Strategy<Value = Value> {
    (
        prop::sample::select(vec![1u32, 2]),
        prop::sample::select(vec![1u32, 2, 4, 16]),
        prop::sample::select(vec![1u32, 2, 4, 8]),
        any::<bool>(),
        prop::collection::vec(edit(), 1..4),
    )
        .prop_map(|(w, n, steps, warn, edits)| {
            let mut doc = template(w, n, steps);
            if warn {
                doc["smallness"] = json!("warn");
            }
            for (ptr, v) in edits {
                if let Some(slot) = doc.pointer_mut(ptr) {
                    *slot = v;
                } else if let Some((parent, key)) = ptr.rsplit_once('/') {
                    if let Some(Value::Object(m)) = doc.pointer_mut(parent) {
                        m.insert(key.to_string(), v);
                    }
                }
            }
            doc
        })
}

/// Validation, and (for small accepted scenes) set-up and one step: never a panic, never a
/// NaN result, always within `limit`; what is accepted conforms to the schema.
fn exercise(doc: &Value, limit: Duration) -> Result<(), TestCaseError> {
    let start = Instant::now();
    let result = validate(doc);
    prop_assert!(
        start.elapsed() < limit,
        "validation took {:?}",
        start.elapsed()
    );
    let p = match result {
        Err(e) => {
            prop_assert!(!e.0.is_empty());
            for err in &e.0 {
                prop_assert!(err.pointer.is_empty() || err.pointer.starts_with('/'));
                prop_assert!(!err.message.contains("internal error"), "{}", err.message);
            }
            return Ok(());
        }
        Ok(p) => p,
    };
    let errs = schema_errors(doc);
    prop_assert!(
        errs.is_empty(),
        "accepted, but the schema refuses {}: {:?}",
        doc,
        errs
    );
    if p.n_nodes() > 2000 {
        return Ok(());
    }
    match p.dim() {
        2 => first_step::<2>(p),
        _ => first_step::<3>(p),
    }
}

/// The set-up and first step of an accepted scene: finite results, or a clean error.
fn first_step<const D: usize>(p: crate::problem::Problem) -> Result<(), TestCaseError> {
    let mut sim = match Simulation::<D>::new(p, SolverSettings::default()) {
        Ok(sim) => sim,
        Err(_) => return Ok(()),
    };
    match sim.step() {
        Ok(r) => {
            prop_assert!(r.w_v.is_finite() && r.u_v.is_finite() && r.zeta_l2.is_finite());
            prop_assert!(sim.w.iter().all(|v| v.is_finite()), "NaN velocity accepted");
            prop_assert!(sim.state.zeta.iter().all(|z| (0.0..=1.0).contains(z)));
        }
        Err(SolveError::Data { pointer, message }) => {
            prop_assert!(pointer.starts_with('/') && !message.is_empty());
        }
        Err(_) => {}
    }
    Ok(())
}

#[test]
fn the_template_is_valid() {
    for w in [1, 2] {
        for n in [1, 2, 4] {
            if let Err(e) = validate(&template(w, n, 4)) {
                panic!("{e}");
            }
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(400))]

    #[test]
    fn hostile_scenes_are_answered_without_panic(doc in hostile_scene()) {
        exercise(&doc, Duration::from_secs(2))?;
    }
}

/// A scene with `parts` boundary parts (all but the first are tiny traction pieces of the
/// top side), `fields` output field names and `points` friction-table points.
fn giant(parts: usize, fields: usize, points: usize) -> Value {
    let mut doc = template(1, 4, 4);
    let mut boundary = vec![json!({"type": "clamped", "from": [0, 0], "to": [0, 1]})];
    for i in 1..parts {
        let (a, b) = ((i - 1) as f64 / parts as f64, i as f64 / parts as f64);
        boundary.push(json!({"type": "traction", "from": [a, 1], "to": [b, 1], "f2": ["x*t", 0]}));
    }
    doc["boundary"] = Value::Array(boundary);
    // Fine enough that every part holds a facet of the top side.
    doc["mesh"]["h"] = json!(format!("1/{}", parts.max(4)));
    doc["output"] = json!({"fields": vec!["u"; fields]});
    let table: Vec<Value> = (0..points).map(|i| json!([i, 1])).collect();
    doc["friction"] = json!({"law": "piecewise_linear", "points": table});
    doc
}

#[test]
fn giant_arrays_are_refused_quickly_at_their_pointer() {
    let doc = giant(100_000, 100_000, 100_000);
    let start = Instant::now();
    let errs = validate(&doc).unwrap_err().0;
    assert!(
        start.elapsed() < Duration::from_secs(2),
        "took {:?}",
        start.elapsed()
    );
    for (ptr, text) in [
        ("/boundary", "at most"),
        ("/output/fields", "at most"),
        ("/friction/points", "got 100000 points"),
    ] {
        assert!(
            errs.iter()
                .any(|e| e.pointer == ptr && e.message.contains(text)),
            "{ptr}: {errs:?}"
        );
    }
    // At the limits they are accepted.
    let doc = giant(MAX_BOUNDARY_PARTS, MAX_OUTPUT_FIELDS, MAX_TABLE_POINTS);
    validate(&doc).unwrap_or_else(|e| panic!("{e}"));
}

#[test]
fn errors_are_capped() {
    // A million unknown fields: the list of errors stays bounded and says so.
    let mut doc = template(1, 4, 4);
    for i in 0..100_000 {
        doc[format!("unknown{i}")] = json!(i);
    }
    let errs = validate(&doc).unwrap_err().0;
    assert_eq!(errs.len(), MAX_ERRORS + 1);
    assert!(
        errs[MAX_ERRORS].message.contains("more problems"),
        "{:?}",
        errs[MAX_ERRORS]
    );
}

#[test]
fn deep_nesting_is_refused_without_recursion() {
    // Deeply nested values where a number, an object or a formula is expected.
    let mut deep = json!(1);
    for _ in 0..2000 {
        deep = Value::Array(vec![deep]);
    }
    for ptr in [
        "/mesh/h",
        "/loads/f0/0",
        "/material",
        "/boundary/0",
        "/damage/zeta0",
    ] {
        let mut doc = template(1, 4, 4);
        *doc.pointer_mut(ptr).unwrap_or_else(|| panic!("{ptr}")) = deep.clone();
        let errs = validate(&doc).unwrap_err().0;
        assert!(errs.iter().any(|e| e.pointer == ptr), "{ptr}: {errs:?}");
    }
    // The service parses request bodies with serde_json, which stops at depth 128.
    let text = "[".repeat(10_000) + &"]".repeat(10_000);
    assert!(serde_json::from_str::<Value>(&text).is_err());
}

#[test]
fn non_numbers_in_strings_are_refused() {
    for s in [
        "NaN", "nan", "Inf", "-inf", "infinity", "1e400", "-1e400", "1/0", "0/0",
    ] {
        for ptr in ["/mesh/h", "/time/t_end"] {
            let mut doc = template(1, 4, 4);
            *doc.pointer_mut(ptr).unwrap() = json!(s);
            let errs = validate(&doc).unwrap_err().0;
            assert!(
                errs.iter().any(|e| e.pointer == ptr),
                "{s} at {ptr}: {errs:?}"
            );
        }
        let mut doc = template(1, 4, 4);
        doc["loads"]["f0"][0] = json!(s);
        assert!(validate(&doc).is_err(), "{s} as a formula");
    }
    // "1e-400" underflows to 0: a valid number, but not a valid mesh size.
    let mut doc = template(1, 4, 4);
    doc["mesh"]["h"] = json!("1e-400");
    assert!(validate(&doc).is_err());
}

/// The error of set-up or of the first step for a scene that validation accepts.
fn first_error(doc: &Value) -> SolveError {
    let p = validate(doc).unwrap_or_else(|e| panic!("validation should pass: {e}"));
    let mut sim = match Simulation::<2>::new(p, SolverSettings::default()) {
        Ok(sim) => sim,
        Err(e) => return e,
    };
    sim.step().expect_err("the first step must fail")
}

#[track_caller]
fn assert_data_error(doc: &Value, ptr: &str, text: &str) {
    match first_error(doc) {
        SolveError::Data { pointer, message } => {
            assert_eq!(pointer, ptr, "{message}");
            assert!(message.contains(text), "{message}");
        }
        other => panic!("expected a data error at {ptr}, got {other}"),
    }
}

/// Regressions: validation samples formulas on a 5 × 5 grid at t = 0, T/2, T only, so a
/// formula that is infinite at a time node, a quadrature point or a node in between used to
/// reach the scheme: non-finite loads ended in "non-finite value in the velocity" (no field
/// named), and an initial damage above 1 between the samples ran silently. Now each is
/// refused at its field, with the point.
#[test]
fn formulas_bad_between_the_samples_are_refused_at_their_field() {
    // Infinite at the time node t_1 = 0.25 (samples t = 0, 0.5, 1 are finite).
    let mut doc = template(1, 4, 4);
    doc["loads"]["f0"] = json!(["1/(t - 0.25)", 0]);
    assert_data_error(
        &doc,
        "/loads/f0/0",
        "evaluates to inf at (x, y, t) = (0, 0, 0.25)",
    );
    // Infinite at a 2-point Gauss point of a top edge, on x in (0.55, 0.6) only.
    let mut doc = template(1, 16, 4);
    doc["boundary"][2]["f2"] = json!(["1/(1 - max(0, sign(x - 0.55)*sign(0.6 - x)))", 0]);
    assert_data_error(&doc, "/boundary/2/f2/0", "evaluates to inf");
    // ζ0 = 1.5 at the node x = 1/16 (the samples x = 0, 1/4, ... give 1).
    let mut doc = template(1, 16, 4);
    doc["damage"]["zeta0"] = json!("1 + 0.5*sin(8*pi*x)");
    assert_data_error(
        &doc,
        "/damage/zeta0",
        "evaluates to 1.5 at the node (x, y) = (0.0625, 0)",
    );
    // u0 infinite at the node x = 1/16.
    let mut doc = template(1, 16, 4);
    doc["initial"]["u0"] = json!(["1/(x - 0.0625)", 0]);
    assert_data_error(&doc, "/initial/u0/0", "evaluates to inf");
}

/// Regression (found by the property test below): a damage source that overflows (a =
/// 1e308) made the damage QP's iterates NaN, and the step's |ζ|_Z0 hid them as 0 (f64::max
/// turns NaN into 0), so the step was accepted with ζ = NaN everywhere. Each coefficient
/// that overflows is now refused at its field.
#[test]
fn a_damage_source_that_overflows_is_refused_at_its_coefficient() {
    let mut doc = template(1, 2, 1);
    // a (1 − ζ*)/ζ* = 4e308 where ζ0 = 0.1 < ζ*.
    doc["damage"]["source"]["a"] = json!(1e308);
    doc["damage"]["zeta0"] = json!(0.1);
    assert_data_error(&doc, "/damage/source/a", "a = 100000000");
    let mut doc = template(1, 2, 1);
    doc["damage"]["source"]["b"] = json!(1e308);
    // b |ε(u0)|² = 1e310 with ε_xx = 10.
    doc["initial"]["u0"] = json!(["10*x", 0]);
    assert_data_error(&doc, "/damage/source/b", "not finite in step 1");
}

// -----------------------------------------------------------------------------------------
// Arbitrary JSON and mutated presets: no panics, and whatever is accepted conforms to
// api/scene.schema.json.

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
        SOLVER_FIELDS,
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
        match validate(&wrapped) {
            Ok(_) => {
                let errs = schema_errors(&wrapped);
                prop_assert!(errs.is_empty(), "accepted, but the schema refuses {}: {:?}", wrapped, errs);
            }
            Err(e) => {
                prop_assert!(!e.0.is_empty());
                for err in &e.0 {
                    prop_assert!(err.pointer.is_empty() || err.pointer.starts_with('/'));
                    prop_assert!(!err.message.is_empty() && !err.message.contains("internal error"));
                }
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
                prop_assert!(p.steps >= 1 && (p.body.is_some() || p.cells_per_unit >= 1));
                prop_assert!(p.k().is_finite() && p.k() > 0.0);
                prop_assert!(p.n_nodes() >= 3);
                let errs = schema_errors(&doc);
                prop_assert!(errs.is_empty(), "accepted, but the schema refuses {}: {:?}", doc, errs);
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
