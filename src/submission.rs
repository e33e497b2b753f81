//! The submission language of `POST /jobs`: a scene, a preset request (`{"preset", "overrides"}`)
//! or a study request (`{"study": {...}}`, read and limited by the core's
//! [`contact_core::study::request`]); each validated, checked against this node's per-job
//! limits ([`contact_core::admission`]) and turned into the document a job stores, or
//! refused with a 422 problem at the offending member. Blocking (validation meshes).

use crate::problem::Problem;
use crate::state::AppState;
use crate::store::MemoryPrediction;
use contact_core::admission::{self, Pointers};
use contact_core::scene::{self, presets, Overrides};
use contact_core::study;
use contact_core::study::presets as study_presets;
use serde_json::{json, Value};

pub use crate::jobs::scene_hash;

/// A preset request: `{"preset": NAME, "overrides": {...}}`.
enum PresetRequest {
    /// Not a preset request: the document is a scene or a study.
    None,
    /// A scene preset expanded with its overrides, and the key the final time was given by
    /// (`t_end` or its alias `T`), for the pointers of errors.
    Scene(Value, &'static str),
    /// A study preset's name (the paper's tables): runs as `{"study": {"preset": NAME}}`.
    Study(String),
}

/// Reads a preset request; any other document is a scene or a study.
fn expand(doc: &Value) -> Result<PresetRequest, Problem> {
    let Some(obj) = doc.as_object().filter(|o| o.contains_key("preset")) else {
        return Ok(PresetRequest::None);
    };
    for k in obj.keys() {
        if k != "preset" && k != "overrides" {
            return Err(Problem::invalid_field(
                &format!("/{k}"),
                format!("unknown field {k:?} in a preset request (allowed: preset, overrides)"),
            ));
        }
    }
    let name = obj["preset"]
        .as_str()
        .ok_or_else(|| Problem::invalid_field("/preset", "preset must be a string"))?;
    if study_presets::get(name).is_some() {
        if obj.contains_key("overrides") {
            return Err(Problem::invalid_field(
                "/overrides",
                format!(
                    "{name:?} is a study preset, which takes no overrides; \
                     edit its study document (GET /presets/{name}) and submit that"
                ),
            ));
        }
        return Ok(PresetRequest::Study(name.to_string()));
    }
    let mut scene = presets::get(name).ok_or_else(|| {
        Problem::invalid_field(
            "/preset",
            format!(
                "unknown preset {name:?}; known: {}",
                presets::names()
                    .iter()
                    .chain(study_presets::names())
                    .copied()
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
        )
    })?;
    let mut o = Overrides::default();
    let mut t_key = "t_end";
    if let Some(ov) = obj.get("overrides") {
        let ov = ov
            .as_object()
            .ok_or_else(|| Problem::invalid_field("/overrides", "overrides must be an object"))?;
        if ov.contains_key("t_end") && ov.contains_key("T") {
            return Err(Problem::invalid_field(
                "/overrides/T",
                "give the final time once: t_end or its alias T, not both",
            ));
        }
        for (k, v) in ov {
            match k.as_str() {
                "h" => o.h = Some(v.clone()),
                "k" => o.k = Some(v.clone()),
                "t_end" => o.t_end = Some(v.clone()),
                "T" => {
                    o.t_end = Some(v.clone());
                    t_key = "T";
                }
                _ => {
                    return Err(Problem::invalid_field(
                        &format!("/overrides/{k}"),
                        format!("unknown override {k:?} (allowed: h, k, T or its alias t_end)"),
                    ))
                }
            }
        }
    }
    scene::apply_overrides(&mut scene, &o);
    Ok(PresetRequest::Scene(scene, t_key))
}

/// Maps pointers of an expanded preset back to the request's `overrides` (`t_key`: the key
/// the request gave the final time by).
fn map_override_pointers(mut p: Problem, t_key: &str) -> Problem {
    for err in p.errors.iter_mut().flatten() {
        let mapped = match err.pointer.as_str() {
            "/mesh/h" => "/overrides/h".to_string(),
            "/time/k" | "/time/N" => "/overrides/k".to_string(),
            "/time/t_end" => format!("/overrides/{t_key}"),
            _ => continue,
        };
        err.pointer = mapped;
    }
    p
}

/// A simulation against the per-job limits ([`admission::check_run`]), reported at the field
/// that sets what is too large; its estimated stored bytes (what the owner's quota counts)
/// and its predicted memory on the path the run takes.
pub(crate) fn check_limits(
    p: &contact_core::problem::Problem,
    state: &AppState,
    is_preset: bool,
    doc: &Value,
) -> Result<(u64, MemoryPrediction), Problem> {
    let (mut mesh, steps) = if is_preset {
        ("/overrides/h", "/overrides/k")
    } else {
        ("/mesh/h", "/time/k")
    };
    // An imported mesh's size is the file's and its refinements'.
    if !is_preset && doc["domain"].get("mesh").is_some() {
        mesh = if doc["mesh"].get("refine").is_some() {
            "/mesh/refine"
        } else {
            "/domain/mesh"
        };
    }
    let at = Pointers {
        mesh: mesh.into(),
        steps: steps.into(),
        output: "/output".into(),
        solver: Some("/solver/linear".into()),
    };
    let fit = admission::check_run(p, &state.rt.config.job_limits(), &at)
        .map_err(|e| Problem::over_limit(&e))?;
    Ok((
        fit.stored_bytes,
        MemoryPrediction {
            linear_path: fit.path,
            predicted_bytes: fit.memory_bytes,
        },
    ))
}

/// A submission as validated: what is stored and counted.
pub struct Validated {
    /// The document to store.
    pub doc: Value,
    /// Its number of time steps (a study's: its progress scale).
    pub steps: usize,
    /// Estimated stored bytes; a study's summary counts as nothing.
    pub stored_bytes: u64,
    /// The predicted memory of the run, or of a study's largest run, on its path.
    pub memory: Option<MemoryPrediction>,
}

/// The submission to store, or why it is refused (422 at the offending field). Blocking.
pub fn validated(doc: Value, state: &AppState) -> Result<Validated, Problem> {
    let doc = match expand(&doc)? {
        PresetRequest::Study(name) => json!({"study": {"preset": name}}),
        PresetRequest::Scene(scene_doc, t_key) => {
            return validated_scene(scene_doc, Some(t_key), state)
        }
        PresetRequest::None => doc,
    };
    if doc.get("study").is_some() {
        validated_study(&doc, "study", state)
    } else if doc.get("sweep").is_some() {
        validated_study(&doc, "sweep", state)
    } else {
        validated_scene(doc, None, state)
    }
}

/// A study request `{"study": {...}}` (a ladder or a target) or a sweep request
/// `{"sweep": {...}}` ([`contact_core::study::sweep`]), read by the one study request
/// ([`study::request`]): every run validated (422 at its pointer under `/{key}`) and admitted
/// under the per-job limits (the largest run decides the memory, the steps of all count).
fn validated_study(doc: &Value, key: &str, state: &AppState) -> Result<Validated, Problem> {
    if let Some(k) = doc.as_object().and_then(|o| o.keys().find(|k| *k != key)) {
        return Err(Problem::invalid_field(
            &format!("/{k}"),
            format!(
                "unknown field {k:?} next to a {key} (a {key} request is {{\"{key}\": {{...}}}})"
            ),
        ));
    }
    let parse = if key == "sweep" {
        // The body is the scene's: an uploaded mesh is checked against its owner once,
        // before the sweep is read (members on other meshes are separate jobs).
        if let Some(pointer) = doc["sweep"]["vary"].as_object().and_then(|v| {
            v.keys()
                .find(|p| *p == "/domain" || p.starts_with("/domain/mesh"))
        }) {
            return Err(Problem::invalid_field(
                &format!("/sweep/vary/{}", study::sweep::escape(pointer)),
                "a sweep runs on its scene's body: vary loads, friction, damage, material, mesh.h or time, not domain.mesh",
            ));
        }
        study::request::parse_sweep
    } else {
        study::request::parse
    };
    let (request, expanded) =
        parse(&doc[key], &format!("/{key}"), &*state.rt.meshes).map_err(|e| {
            crate::meshes::store_outage(&e).unwrap_or_else(|| Problem::invalid_scene(&e))
        })?;
    let admitted = request
        .admit(&state.rt.config.job_limits())
        .map_err(|e| Problem::over_limit(&e))?;
    Ok(Validated {
        doc: json!({ key: expanded }),
        steps: admitted.steps,
        stored_bytes: 0,
        memory: Some(MemoryPrediction {
            linear_path: admitted.largest.path,
            predicted_bytes: admitted.largest.memory_bytes,
        }),
    })
}

/// A scene document (`preset`: the key of the final time when it was expanded from a preset
/// request, whose errors then point into `overrides`) as validated, or why it is refused.
fn validated_scene(
    scene_doc: Value,
    preset: Option<&str>,
    state: &AppState,
) -> Result<Validated, Problem> {
    let problem = match scene::validate_with(&scene_doc, &*state.rt.meshes) {
        Ok(p) => p,
        Err(errors) => {
            if let Some(outage) = crate::meshes::store_outage(&errors) {
                return Err(outage);
            }
            let e = Problem::invalid_scene(&errors);
            return Err(match preset {
                Some(t_key) => map_override_pointers(e, t_key),
                None => e,
            });
        }
    };
    let (stored_bytes, memory) = check_limits(&problem, state, preset.is_some(), &scene_doc)?;
    Ok(Validated {
        doc: scene_doc,
        steps: problem.steps,
        stored_bytes,
        memory: Some(memory),
    })
}
