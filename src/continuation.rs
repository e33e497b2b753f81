//! `POST /jobs {"continue": {"job": ID, "t_end": T2, "scene": S}}`: the continuation of a
//! finished simulation job from the state after its last step (the `state.bin` every
//! succeeded simulation keeps, [`crate::jobs::STATE_FILE`]) to a later final time, with its
//! scene or with a changed one (other loads, friction, output or final time on the same mesh
//! and body: [`SAME_BODY`]).
//!
//! The job it makes is an ordinary simulation of the child scene, its time the parent's step
//! k to T2, whose stored document carries [`CONTINUED_FROM`]: the parent's id, computation
//! hash and last step. The worker starts it from the parent's state and steps, so its steps
//! and times are numbered from the parent's start; its content hash covers the parent's
//! computation hash and the child scene (not the parent's id), so the same continuation
//! submitted twice answers the first job. Blocking (validation meshes, reads the store).

use crate::auth::Caller;
use crate::jobs::{is_study, STATE_FILE};
pub use crate::jobs::{parent_id, parent_of, scene_of, CONTINUED_FROM};
use crate::problem::Problem;
use crate::state::AppState;
use crate::store::JobStatus;
use crate::submission::Validated;
use contact_core::scene::{self, canonical};
use serde_json::{json, Map, Value};
use uuid::Uuid;

/// Scene members a continuation keeps from its parent: the mesh and the body (its material,
/// damage law, boundary parts and initial data); loads, friction, output, solver and the
/// final time may change.
pub const SAME_BODY: &[&str] = &[
    "domain", "mesh", "boundary", "material", "damage", "initial",
];

/// The members of a continue request.
const FIELDS: &[&str] = &["job", "t_end", "scene"];

/// A continue request as validated: the child's document to store (its scene with the
/// parent link), or why it is refused (422 at `/continue/...`).
pub fn validated(doc: Value, state: &AppState, caller: &Caller) -> Result<Validated, Problem> {
    let top = doc.as_object().expect("a continue request is an object");
    if let Some(k) = top.keys().find(|k| *k != "continue") {
        return Err(Problem::invalid_field(
            &format!("/{k}"),
            format!(
                "unknown field {k:?} next to continue (a continue request is {{\"continue\": {{\"job\": ID, \"t_end\": T2}}}})"
            ),
        ));
    }
    let c = top["continue"].as_object().ok_or_else(|| {
        Problem::invalid_field(
            "/continue",
            "continue must be an object {\"job\": ID, \"t_end\": T2, \"scene\": optional}",
        )
    })?;
    if let Some(k) = c.keys().find(|k| !FIELDS.contains(&k.as_str())) {
        return Err(Problem::invalid_field(
            &format!("/continue/{k}"),
            format!(
                "unknown field {k:?} in continue (allowed: {})",
                FIELDS.join(", ")
            ),
        ));
    }
    let job = c.get("job").ok_or_else(|| {
        Problem::invalid_field("/continue/job", "give the job to continue: its id")
    })?;
    let id: Uuid = job
        .as_str()
        .and_then(|s| s.parse().ok())
        .ok_or_else(|| Problem::invalid_field("/continue/job", "job must be a job id (a UUID)"))?;
    let parent = state
        .store()
        .get(id)?
        .filter(|r| caller.sees(&r.owner))
        .ok_or_else(|| Problem::invalid_field("/continue/job", format!("no job with id {id}")))?;
    if is_study(&parent.scene) {
        return Err(Problem::invalid_field(
            "/continue/job",
            format!("job {id} is a study; only a simulation can be continued"),
        ));
    }
    if parent.status != JobStatus::Succeeded {
        return Err(Problem::invalid_field(
            "/continue/job",
            format!(
                "job {id} is {}; only a simulation that succeeded has stored its last state",
                parent.status.as_str()
            ),
        ));
    }
    let has_state = state
        .rt
        .results
        .path(id, STATE_FILE)
        .is_some_and(|p| p.is_file());
    if !has_state {
        return Err(Problem::invalid_field(
            "/continue/job",
            format!(
                "job {id} has not stored its last state (it finished before this version kept it); run it again to continue it"
            ),
        ));
    }
    let parent_scene = scene_of(&parent.scene).into_owned();
    let parent_problem = scene::validate_with(&parent_scene, &*state.rt.meshes).map_err(|e| {
        crate::meshes::store_outage(&e).unwrap_or_else(|| {
            Problem::invalid_field(
                "/continue/job",
                format!("job {id}'s scene no longer validates: {e}"),
            )
        })
    })?;
    let given = c.get("scene");
    let mut child = match given {
        None => parent_scene.clone(),
        Some(s) => {
            let s = s.as_object().ok_or_else(|| {
                Problem::invalid_field("/continue/scene", "scene must be a scene object")
            })?;
            for field in SAME_BODY {
                let (a, b) = (s.get(*field), parent_scene.get(*field));
                if a.map(canonical) != b.map(canonical) {
                    return Err(Problem::invalid_field(
                        &format!("/continue/scene/{field}"),
                        format!(
                            "a continuation keeps the parent's mesh and body: {field} must be the parent's ({}); change loads, friction, output or the final time",
                            b.map_or("absent".into(), Value::to_string)
                        ),
                    ));
                }
            }
            if s.contains_key(CONTINUED_FROM) {
                return Err(Problem::invalid_field(
                    &format!("/continue/scene/{CONTINUED_FROM}"),
                    "continued_from is set by the service; leave it out",
                ));
            }
            Value::Object(s.clone())
        }
    };
    // The final time: continue.t_end, else the given scene's time.t_end. A continuation keeps
    // the parent's step k: the scene's time may give nothing else.
    let scene_time = given.and_then(|s| s.get("time"));
    if let Some(t) = scene_time {
        let t = t.as_object().ok_or_else(|| {
            Problem::invalid_field("/continue/scene/time", "time must be an object")
        })?;
        // The parent's k itself may stay in a scene copied from the parent's.
        let same_k = |v: &Value| {
            let parent_k = parent_problem.k();
            scene::parse_ratio(v).is_ok_and(|k| k.to_bits() == parent_k.to_bits())
                || parent_scene["time"].get("k") == Some(v)
        };
        if let Some(k) = t
            .iter()
            .find(|(k, v)| *k != "t_end" && !(*k == "k" && same_k(v)))
            .map(|(k, _)| k)
        {
            return Err(Problem::invalid_field(
                &format!("/continue/scene/time/{k}"),
                format!(
                    "a continuation keeps the parent's step k = {}; give only the final time t_end (and k, if the parent's)",
                    parent_problem.k()
                ),
            ));
        }
    }
    // A scene copied from the parent's keeps the parent's final time: not a second one.
    let parents_t = |v: &Value| {
        parent_scene["time"].get("t_end") == Some(v)
            || scene::parse_ratio(v).is_ok_and(|t| t == parent_problem.t_end)
    };
    let scene_t_end = scene_time
        .and_then(|t| t.get("t_end"))
        .filter(|v| !(c.contains_key("t_end") && parents_t(v)));
    let (t_end, t_pointer) = match (c.get("t_end"), scene_t_end) {
        (Some(_), Some(_)) => {
            return Err(Problem::invalid_field(
                "/continue/scene/time/t_end",
                "give the final time once: continue.t_end, or the scene's time.t_end (a scene copied from the parent's may keep the parent's)",
            ))
        }
        (Some(t), None) => (t.clone(), "/continue/t_end"),
        (None, Some(t)) => (t.clone(), "/continue/scene/time/t_end"),
        (None, None) => {
            return Err(Problem::invalid_field(
                "/continue/t_end",
                format!(
                    "give the final time t_end of the continuation, after the parent's t = {}",
                    parent_problem.t_end
                ),
            ))
        }
    };
    // The parent's step k as the parent gave it ("1/32" stays the same ratio).
    let k = parent_scene["time"]
        .get("k")
        .cloned()
        .unwrap_or_else(|| json!(parent_problem.k()));
    child["time"] = json!({"t_end": t_end, "k": k});
    let map = |mut p: Problem| {
        for err in p.errors.iter_mut().flatten() {
            err.pointer = if err.pointer.starts_with("/time") {
                t_pointer.to_string()
            } else if given.is_some() {
                format!("/continue/scene{}", err.pointer)
            } else {
                "/continue/job".to_string()
            };
        }
        p
    };
    let problem = match scene::validate_with(&child, &*state.rt.meshes) {
        Ok(p) => p,
        Err(errors) => {
            if let Some(outage) = crate::meshes::store_outage(&errors) {
                return Err(outage);
            }
            return Err(map(Problem::invalid_scene(&errors)));
        }
    };
    let done = parent_problem.steps;
    if problem.k().to_bits() != parent_problem.k().to_bits() {
        return Err(Problem::invalid_field(
            t_pointer,
            format!(
                "t_end {} is not a whole number of the parent's steps k = {} from t = 0",
                problem.t_end,
                parent_problem.k()
            ),
        ));
    }
    if problem.steps <= done {
        return Err(Problem::invalid_field(
            t_pointer,
            format!(
                "t_end {} must come after the parent's final time {}",
                problem.t_end, parent_problem.t_end
            ),
        ));
    }
    if problem.error_estimate {
        return Err(Problem::invalid_field(
            if given.is_some() {
                "/continue/scene/error_estimate"
            } else {
                "/continue/job"
            },
            "a continuation has no error estimate: the (2h, 2k) companion runs are not kept; leave error_estimate out",
        ));
    }
    let (stored_bytes, memory) =
        crate::submission::check_limits(&problem, state, false, &child).map_err(map)?;
    if let Some(o) = child.as_object_mut() {
        let mut link = Map::new();
        link.insert("job".into(), json!(id));
        link.insert("step".into(), json!(done));
        link.insert("t".into(), json!(parent_problem.t_end));
        link.insert("scene_hash".into(), json!(parent.scene_hash));
        o.insert(CONTINUED_FROM.into(), Value::Object(link));
    }
    Ok(Validated {
        doc: child,
        steps: problem.steps,
        stored_bytes,
        memory: Some(memory),
    })
}
