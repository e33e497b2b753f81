//! The study document and its validation into a [`Plan`].
//!
//! ```json
//! {"name": "table 1", "scene": {...} | "paper-convergence",
//!  "h": ["1/2", "1/4", "1/8"] | "1/8", "k": "1/128" | [...],
//!  "reference": {"h": "1/128", "k": "1/128"}}
//! ```
//! or `{"preset": "paper-table-1"}`. A list in `h` (at fixed k) or in `k` (at fixed h) is a
//! ladder; lists in both, of equal length, refine h and k together. Every level must be
//! nested in the reference: its cells unions of reference cells, its time nodes reference
//! time nodes. Errors name the offending entry by JSON pointer (`/study/h/2`).

use crate::problem::{MeshPattern, Problem};
use crate::scene::{self, apply_overrides, content_hash, FieldError, Overrides, ValidationErrors};
use crate::solve::SolverSettings;
use serde::Serialize;
use serde_json::{json, Map, Value};

/// Longest ladder accepted.
pub const MAX_LEVELS: usize = 16;

/// Which discretisation parameter the ladder refines (and orders are computed in).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub enum Vary {
    #[serde(rename = "h")]
    H,
    #[serde(rename = "k")]
    K,
    /// h and k together (orders in h).
    #[serde(rename = "hk")]
    Both,
}

/// A validated study: the scene and the (cells per unit length, time steps) of every level
/// and of the reference.
#[derive(Debug, Clone)]
pub struct Plan {
    pub name: String,
    /// The scene at the reference resolution.
    pub base: Problem,
    pub levels: Vec<(usize, usize)>,
    pub reference: (usize, usize),
    pub vary: Vary,
    /// Content hash of what determines the reference run (scene physics, resolution, solver,
    /// version); "" for an unshared reference.
    pub reference_key: String,
    /// Where each level's (h or refine, k) is set in the request, for errors about one run
    /// (the limits of [`super::request`]) ...
    pub level_pointers: Vec<[String; 2]>,
    /// ... and the reference's.
    pub reference_pointers: [String; 2],
}

const FIELDS: &[&str] = &["name", "scene", "h", "refine", "k", "reference", "preset"];

/// A level's spatial resolution as one number: n = round(1/h) on a rectangle, and on a given
/// mesh n = 2^refine (so that "nested" is "n divides the reference's n" in both cases, and
/// the tables' h = 1/n is the mesh size relative to the mesh as given).
pub fn resolution(p: &Problem) -> usize {
    match &p.body {
        Some(b) => 1 << b.refine,
        None => p.cells_per_unit,
    }
}

/// Reads the study object `doc`, located at JSON pointer `at` in the request (errors are
/// reported there). Returns the plan and the expanded document (presets resolved), which is
/// what a job stores.
pub fn parse(doc: &Value, at: &str) -> Result<(Plan, Value), ValidationErrors> {
    parse_with(doc, at, &scene::Bundled)
}

/// [`parse`], with the meshes a scene names (`domain.mesh`) looked up in `files`.
pub fn parse_with(
    doc: &Value,
    at: &str,
    files: &dyn scene::MeshFiles,
) -> Result<(Plan, Value), ValidationErrors> {
    let err = |p: &str, m: String| field_error(at, p, m);
    let Some(obj) = doc.as_object() else {
        return Err(err(
            "",
            "a study must be an object with scene, h, k and reference".into(),
        ));
    };
    for k in obj.keys() {
        if !FIELDS.contains(&k.as_str()) {
            return Err(err(
                &format!("/{k}"),
                format!(
                    "unknown field {k:?} in a study (allowed: {})",
                    FIELDS.join(", ")
                ),
            ));
        }
    }
    if let Some(p) = obj.get("preset") {
        if obj.len() > 1 {
            return Err(err(
                "/preset",
                "a study preset takes no other fields".into(),
            ));
        }
        let name = p.as_str().unwrap_or_default();
        let expanded = super::presets::get(name).ok_or_else(|| {
            err(
                "/preset",
                format!(
                    "unknown study preset {p}; known: {}",
                    super::presets::names().join(", ")
                ),
            )
        })?;
        return parse_with(&expanded, at, files);
    }
    let name = study_name(obj, at)?;
    let scene_doc = scene_document(obj, at)?;
    let list = |key: &str| -> Result<(Vec<Value>, bool), ValidationErrors> {
        match obj.get(key) {
            None => Err(err(
                &format!("/{key}"),
                format!("missing: {key} (a value like \"1/32\" or a list of them)"),
            )),
            Some(Value::Array(a)) if a.is_empty() || a.len() > MAX_LEVELS => Err(err(
                &format!("/{key}"),
                format!("a ladder has 1 to {MAX_LEVELS} levels, got {}", a.len()),
            )),
            Some(Value::Array(a)) => Ok((a.clone(), true)),
            Some(v) => Ok((vec![v.clone()], false)),
        }
    };
    // A given mesh is refined by `refine` (whole numbers), a rectangle by `h`.
    if obj.contains_key("h") && obj.contains_key("refine") {
        return Err(err(
            "/refine",
            "give h (a rectangle) or refine (an imported or polygon mesh), not both".into(),
        ));
    }
    let hkey = if obj.contains_key("refine") {
        "refine"
    } else {
        "h"
    };
    let (hs, h_list) = list(hkey)?;
    let (ks, k_list) = list("k")?;
    if hs.len() > 1 && ks.len() > 1 && hs.len() != ks.len() {
        return Err(err(
            "/k",
            format!(
                "h and k ladders refined together must have equal lengths ({} and {})",
                hs.len(),
                ks.len()
            ),
        ));
    }
    let vary = match (hs.len() > 1, ks.len() > 1) {
        (true, true) => Vary::Both,
        (false, true) => Vary::K,
        _ => Vary::H,
    };
    let reference = obj
        .get("reference")
        .and_then(Value::as_object)
        .ok_or_else(|| err("/reference", "missing: reference {\"h\": ..., \"k\": ...} (the finest run, taken as the true solution)".into()))?;
    for key in reference.keys() {
        if key != hkey && key != "k" {
            return Err(err(
                &format!("/reference/{key}"),
                format!("unknown field {key:?} (allowed: {hkey}, k)"),
            ));
        }
    }
    let (Some(ref_h), Some(ref_k)) = (reference.get(hkey), reference.get("k")) else {
        return Err(err(
            "/reference",
            format!("the reference needs both {hkey} and k"),
        ));
    };

    // Every level is the scene with (h, k) overridden, validated as a scene, so each value
    // gets exactly the checks (and messages) a scene's mesh.h and time.k get.
    let mut errors: Vec<FieldError> = Vec::new();
    let at_scene = format!("{at}/scene");
    let mut resolve = |h: &Value, k: &Value, h_ptr: String, k_ptr: String| -> Option<Problem> {
        let mut d = scene_doc.clone();
        apply_overrides(
            &mut d,
            &Overrides {
                h: (hkey == "h").then(|| h.clone()),
                k: Some(k.clone()),
                t_end: None,
            },
        );
        if hkey == "refine" {
            if let Some(o) = d.as_object_mut() {
                let mesh = o.entry("mesh").or_insert_with(|| json!({}));
                if let Some(m) = mesh.as_object_mut() {
                    m.insert("refine".into(), h.clone());
                }
            }
        }
        match scene::validate_with(&d, files) {
            Ok(p) => Some(p),
            Err(ValidationErrors(es)) => {
                for e in es {
                    let pointer = match e.pointer.as_str() {
                        "/mesh/h" | "/mesh/refine" => h_ptr.clone(),
                        "/time/k" | "/time/N" => k_ptr.clone(),
                        p => format!("{at_scene}{p}"),
                    };
                    let fe = FieldError {
                        pointer,
                        message: e.message,
                    };
                    if !errors.contains(&fe) {
                        errors.push(fe);
                    }
                }
                None
            }
        }
    };
    let reference_pointers = [
        format!("{at}/reference/{hkey}"),
        format!("{at}/reference/k"),
    ];
    let base = resolve(
        ref_h,
        ref_k,
        reference_pointers[0].clone(),
        reference_pointers[1].clone(),
    );
    let n_levels = hs.len().max(ks.len());
    let ptr = |key: &str, is_list: bool, i: usize| {
        if is_list {
            format!("{at}/{key}/{i}")
        } else {
            format!("{at}/{key}")
        }
    };
    let mut levels = Vec::with_capacity(n_levels);
    for i in 0..n_levels {
        let (h, k) = (&hs[i.min(hs.len() - 1)], &ks[i.min(ks.len() - 1)]);
        let (hp, kp) = (ptr(hkey, h_list, i), ptr("k", k_list, i));
        if let Some(p) = resolve(h, k, hp.clone(), kp.clone()) {
            levels.push((resolution(&p), p.steps, hp, kp));
        }
    }
    let Some(base) = base.filter(|_| errors.is_empty()) else {
        return Err(ValidationErrors(errors));
    };
    if base.pattern == MeshPattern::Cross {
        return Err(err(
            "/scene/mesh/pattern",
            "the cross pattern's meshes are not nested (its cell-centre nodes are not nodes of the finer mesh); use diagonal or anti_diagonal".into(),
        ));
    }
    let (ref_n, ref_steps) = (resolution(&base), base.steps);
    for (n, steps, hp, kp) in &levels {
        if ref_n % n != 0 {
            errors.push(FieldError {
                pointer: hp.clone(),
                message: if base.body.is_some() {
                    format!(
                        "refine = {} is finer than the reference's refine = {}: the reference mesh must refine every level's",
                        n.trailing_zeros(),
                        ref_n.trailing_zeros()
                    )
                } else {
                    format!(
                        "h = 1/{n} is not nested in the reference h = 1/{ref_n}: the reference mesh must refine it (1/h must divide {ref_n})"
                    )
                },
            });
        }
        if ref_steps % steps != 0 {
            errors.push(FieldError {
                pointer: kp.clone(),
                message: format!(
                    "{steps} time steps are not nested in the reference's {ref_steps}: every time node of the level must be one of the reference (N must divide {ref_steps})"
                ),
            });
        }
    }
    if !errors.is_empty() {
        return Err(ValidationErrors(errors));
    }
    let mut physics = scene_doc.clone();
    if let Some(o) = physics.as_object_mut() {
        for k in scene::LABEL_FIELDS
            .iter()
            .chain(&["output", "error_estimate", "mesh", "time"])
        {
            o.remove(*k);
        }
    }
    // What determines the reference run: the scene's physics (not its name or outputs), the
    // mesh pattern and the resolution, the solver settings, the code version.
    let reference_key = content_hash(&json!({
        "physics": physics,
        "pattern": format!("{:?}", base.pattern),
        "t_end": base.t_end,
        "cells_per_unit": ref_n,
        "steps": ref_steps,
        "solver": SolverSettings::default(),
        "version": env!("CARGO_PKG_VERSION"),
    }));
    let mut expanded = Map::new();
    if let Some(n) = &name {
        expanded.insert("name".into(), json!(n));
    }
    expanded.insert("scene".into(), scene_doc);
    expanded.insert(hkey.into(), obj[hkey].clone());
    expanded.insert("k".into(), obj["k"].clone());
    expanded.insert("reference".into(), json!({hkey: ref_h, "k": ref_k}));
    let plan = Plan {
        name: name.unwrap_or_else(|| format!("study of {}", base.name)),
        levels: levels.iter().map(|l| (l.0, l.1)).collect(),
        level_pointers: levels.into_iter().map(|l| [l.2, l.3]).collect(),
        reference: (ref_n, ref_steps),
        reference_pointers,
        vary,
        reference_key,
        base,
    };
    Ok((plan, Value::Object(expanded)))
}

/// One error at `{at}{p}`.
pub(super) fn field_error(at: &str, p: &str, message: String) -> ValidationErrors {
    ValidationErrors(vec![FieldError {
        pointer: format!("{at}{p}"),
        message,
    }])
}

/// A study's optional `name`: a string of 1 to 200 characters.
pub(super) fn study_name(
    obj: &serde_json::Map<String, Value>,
    at: &str,
) -> Result<Option<String>, ValidationErrors> {
    match obj.get("name") {
        None => Ok(None),
        Some(Value::String(s)) if !s.is_empty() && s.len() <= 200 => Ok(Some(s.clone())),
        Some(_) => Err(field_error(
            at,
            "/name",
            "name must be a string of 1 to 200 characters".into(),
        )),
    }
}

/// The scene a study (ladder or target) runs: its `scene` field, a scene object or a preset
/// name expanded; errors point at `{at}/scene`.
pub(super) fn scene_document(
    obj: &serde_json::Map<String, Value>,
    at: &str,
) -> Result<Value, ValidationErrors> {
    let err = |m: String| field_error(at, "/scene", m);
    match obj.get("scene") {
        None => Err(err(
            "missing: the scene to study (an object or a preset name)".into(),
        )),
        Some(Value::String(s)) => scene::presets::get(s).ok_or_else(|| {
            err(format!(
                "unknown preset {s:?}; known: {}",
                scene::presets::names().join(", ")
            ))
        }),
        Some(v @ Value::Object(_)) => Ok(v.clone()),
        Some(_) => Err(err("scene must be a scene object or a preset name".into())),
    }
}

/// The scene of a study document, validated as given (its `error_estimate`, which a study
/// replaces, left out) with the meshes it names looked up in `files`; errors point into
/// `{at}/scene`.
pub(super) fn given_scene(
    scene_doc: &Value,
    at: &str,
    files: &dyn scene::MeshFiles,
) -> Result<Problem, ValidationErrors> {
    let mut given = scene_doc.clone();
    if let Some(o) = given.as_object_mut() {
        o.remove("error_estimate");
    }
    scene::validate_with(&given, files).map_err(|ValidationErrors(es)| {
        ValidationErrors(
            es.into_iter()
                .map(|e| FieldError {
                    pointer: format!("{at}/scene{}", e.pointer),
                    message: e.message,
                })
                .collect(),
        )
    })
}

/// A study's scene document run on a stored mesh called `mesh` (an adaptive mesh, uploaded):
/// the same scene with `domain` that mesh, unrefined, its output estimating, without the
/// (2h, 2k) error estimate; its time grid is the document's.
pub fn scene_on_mesh(scene: &Value, mesh: &str) -> Value {
    let mut d = scene.clone();
    if let Some(o) = d.as_object_mut() {
        o.remove("error_estimate");
        o.insert("domain".into(), json!({"mesh": mesh}));
        o.insert("mesh".into(), json!({"refine": 0}));
        let output = o.entry("output").or_insert_with(|| json!({}));
        if let Some(out) = output.as_object_mut() {
            out.insert("estimate".into(), json!(true));
        }
    }
    d
}

#[cfg(test)]
mod tests {
    use super::*;

    fn study(h: Value, k: Value) -> Value {
        json!({"scene": "paper-convergence", "h": h, "k": k,
               "reference": {"h": "1/16", "k": "1/16"}})
    }

    fn pointers(r: Result<(Plan, Value), ValidationErrors>) -> Vec<String> {
        r.unwrap_err().0.into_iter().map(|e| e.pointer).collect()
    }

    #[test]
    fn a_ladder_in_h_becomes_levels_at_fixed_k() {
        let (plan, doc) = parse(
            &study(json!(["1/2", "1/4", 0.125]), json!("1/16")),
            "/study",
        )
        .unwrap();
        assert_eq!(plan.levels, vec![(2, 16), (4, 16), (8, 16)]);
        assert_eq!(plan.reference, (16, 16));
        assert_eq!(plan.vary, Vary::H);
        assert_eq!(plan.reference_key.len(), 64);
        assert!(
            doc["scene"].is_object(),
            "the preset name is expanded: {doc}"
        );
        let (plan, _) = parse(&study(json!("1/16"), json!(["1/2", "1/4"])), "").unwrap();
        assert_eq!((plan.levels, plan.vary), (vec![(16, 2), (16, 4)], Vary::K));
        let (plan, _) = parse(&study(json!(["1/4", "1/8"]), json!(["1/4", "1/8"])), "").unwrap();
        assert_eq!((plan.levels, plan.vary), (vec![(4, 4), (8, 8)], Vary::Both));
    }

    #[test]
    fn a_box_study_is_planned_on_nested_boxes() {
        let mut doc = study(json!(["1/2", "1/4"]), json!("1/4"));
        doc["scene"] = json!("box-convergence");
        doc["reference"] = json!({"h": "1/8", "k": "1/4"});
        let (plan, _) = parse(&doc, "/study").unwrap();
        assert_eq!(plan.base.dim(), 3);
        assert_eq!(
            (plan.levels, plan.reference),
            (vec![(2, 4), (4, 4)], (8, 4))
        );
    }

    #[test]
    fn non_nested_levels_are_refused_at_the_entry() {
        let e = parse(
            &study(json!(["1/2", "1/3"]), json!(["1/4", "1/5"])),
            "/study",
        )
        .unwrap_err();
        let ps: Vec<&str> = e.0.iter().map(|e| e.pointer.as_str()).collect();
        assert_eq!(ps, ["/study/h/1", "/study/k/1"], "{e}");
        assert!(e.0[0].message.contains("not nested"), "{e}");
    }

    #[test]
    fn bad_values_are_reported_where_they_were_given() {
        assert_eq!(
            pointers(parse(&study(json!(["1/2", -1]), json!("1/16")), "/s")),
            ["/s/h/1"]
        );
        assert_eq!(
            pointers(parse(&study(json!("1/4"), json!("abc")), "/s")),
            ["/s/k"]
        );
        assert_eq!(
            pointers(parse(&study(json!([]), json!("1/4")), "/s")),
            ["/s/h"]
        );
        let mut d = study(json!("1/4"), json!("1/4"));
        d["reference"]["h"] = json!("1/0");
        assert_eq!(pointers(parse(&d, "/s")), ["/s/reference/h"]);
        d["scene"] = json!({"domain": [1, 1]});
        assert!(pointers(parse(&d, "/s"))
            .iter()
            .all(|p| p.starts_with("/s/scene") || p.starts_with("/s/reference")));
        let mut d = study(json!("1/4"), json!("1/4"));
        d["extra"] = json!(1);
        assert_eq!(pointers(parse(&d, "/s")), ["/s/extra"]);
        let mut d = study(json!(["1/2", "1/4"]), json!(["1/2", "1/4", "1/8"]));
        assert_eq!(pointers(parse(&d, "")), ["/k"]);
        d = json!({"preset": "nope"});
        assert_eq!(pointers(parse(&d, "/study")), ["/study/preset"]);
    }

    #[test]
    fn the_reference_key_ignores_names_and_outputs_but_not_physics() {
        let key = |scene: Value| {
            parse(
                &json!({"scene": scene, "h": "1/2", "k": "1/4",
            "reference": {"h": "1/4", "k": "1/4"}}),
                "",
            )
            .unwrap()
            .0
            .reference_key
        };
        let base = scene::presets::get("paper-convergence").unwrap();
        let mut renamed = base.clone();
        renamed["name"] = json!("another name");
        assert_eq!(key(base.clone()), key(renamed));
        let mut changed = base.clone();
        changed["damage"]["kappa"] = json!(0.25);
        assert_ne!(key(base), key(changed));
    }
}
