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
//!
//! The pipeline ([`validate`]): the top-level object is checked against the tables of
//! `fields.rs`, then each section is read by its own module (`domain`, `time`, `mesh`,
//! `boundary`, `loads` with `initial`, `material`, `friction`, `damage`, `output`), each
//! reporting its problems into one context and going on; formulas are sampled on the
//! rectangle and [0, T] once both are known (`formulas.rs`); the [`Problem`] is assembled only
//! if no section failed. `overrides.rs` and `ratio.rs` serve the callers that replace h, k or
//! T before validation.

mod boundary;
mod canonical;
mod damage;
mod domain;
mod errors;
mod fields;
mod formulas;
mod friction;
#[cfg(test)]
mod hostile;
mod loads;
mod material;
mod mesh;
mod output;
mod overrides;
pub mod presets;
mod ratio;
mod read;
#[cfg(test)]
mod tests;
mod time;

pub use canonical::{canonical, computation, content_hash, hex_sha256, LABEL_FIELDS};
pub use damage::DEFAULT_SOURCE;
pub use errors::{FieldError, ValidationErrors};
pub use friction::DEFAULT_FRICTION;
pub use overrides::{apply_overrides, Overrides};
pub use ratio::parse_ratio;

use std::sync::Arc;

use serde_json::Value;

use crate::linalg::LinearPath;
use crate::mesh::{AnyMesh, Mesh};
use crate::problem::{Body, OutputSpec, Precision, Problem, SmallnessPolicy};
use boundary::boundary;
use damage::damage;
use domain::domain;
use domain::Shape;
use fields::{SMALLNESS, SOLVER_FIELDS, TOP_FIELDS};
use formulas::check_samples;
use friction::friction;
use loads::{vector_section, INITIAL, LOADS};
use material::material;
use mesh::mesh_section;
use output::{all_fields, output};
use read::{choice, describe, object, required, Cx};
use time::time;

/// Longest scene name.
const MAX_NAME_LEN: usize = 200;
/// Relative tolerance of "is a whole number" checks (t_end/k, 1/h, width/h).
const WHOLE_TOL: f64 = 1e-9;

/// Where the names of `domain.mesh` come from: the CLI reads files next to the scene, the
/// service looks up uploaded meshes by id. Both also know the meshes bundled with the
/// presets ([`presets::bundled_mesh`]).
pub trait MeshFiles {
    /// The checked mesh (triangles or tetrahedra) called `name`, or a sentence saying why
    /// there is none.
    fn load(&self, name: &str) -> Result<AnyMesh, String>;
}

/// Only the meshes bundled with the presets.
pub struct Bundled;

impl MeshFiles for Bundled {
    fn load(&self, name: &str) -> Result<AnyMesh, String> {
        match presets::bundled_mesh(name) {
            Some(bytes) => crate::mesh::import::import_any(bytes).map_err(|e| format!("mesh \"{name}\": {e}")),
            None => Err(format!(
                "no mesh \"{name}\" here: give the id of a mesh uploaded with POST /meshes, or (from the command line) a .msh file next to the scene"
            )),
        }
    }
}

/// Validates a scene document and turns it into a [`Problem`], or reports every problem found.
/// `domain.mesh` may name only the meshes bundled with the presets ([`validate_with`]).
pub fn validate(doc: &Value) -> Result<Problem, ValidationErrors> {
    validate_with(doc, &Bundled)
}

/// [`validate`], with the meshes of `domain.mesh` looked up in `files`.
pub fn validate_with(doc: &Value, files: &dyn MeshFiles) -> Result<Problem, ValidationErrors> {
    let mut cx = Cx::default();
    let problem = scene(&mut cx, doc, files);
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

/// Reads every section (reporting into `cx`), samples the formulas, assembles the problem.
fn scene(cx: &mut Cx, doc: &Value, files: &dyn MeshFiles) -> Option<Problem> {
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
    let shape = required(
        cx,
        top,
        "",
        "domain",
        "the body: width and height, a mesh or a polygon",
    )
    .and_then(|v| domain(cx, v, "/domain", files));
    cx.solid = shape.as_ref().is_some_and(|s| s.dim() == 3);
    // A mesh that could not be loaded (a wrong id, say) leaves the body unknown, its
    // dimension and groups included: the sections read against it — the mesh section, the
    // boundary parts, the vectors — are not read, since their errors would all follow from
    // the one at /domain/mesh. (Other domain errors leave the dimension known.)
    let body_known = shape.is_some() || top.get("domain").and_then(|d| d.get("mesh")).is_none();
    let time = required(
        cx,
        top,
        "",
        "time",
        "t_end and the step k or the number of steps N",
    )
    .and_then(|v| time(cx, v, "/time"));
    let mesh = body_known
        .then(|| mesh_section(cx, top.get("mesh"), "/mesh", shape.as_ref()))
        .flatten();
    let boundary = body_known
        .then(|| {
            required(
                cx,
                top,
                "",
                "boundary",
                "the clamped, traction and contact segments",
            )
            .and_then(|v| boundary(cx, v, "/boundary", shape.as_ref(), &mut sampled))
        })
        .flatten();
    let dim = shape.as_ref().map_or(2, Shape::dim);
    let body_force = body_known
        .then(|| vector_section(cx, top, &LOADS, &mut sampled, dim))
        .flatten();
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
    let solver = match top.get("solver") {
        None => Some((LinearPath::Auto, Precision::Auto)),
        Some(v) => solver(cx, v, "/solver"),
    };
    let damage = match top.get("damage") {
        None => Some(None),
        Some(v) => damage(cx, v, "/damage", &mut sampled).map(Some),
    };
    let u0 = body_known
        .then(|| vector_section(cx, top, &INITIAL, &mut sampled, dim))
        .flatten();
    let output = match top.get("output") {
        None => Some(OutputSpec {
            every: 1,
            last: true,
            fields: all_fields(),
            estimate: false,
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

    // The mesh as given (before refinement), its boundary tagged with the parts.
    let base = match (&shape, &mesh, &boundary) {
        (Some(shape), Some(spec), Some(parts)) => base_mesh(cx, shape, spec, parts),
        _ => None,
    };
    if let Some(shape) = &shape {
        let points = sample_points(shape, base.as_ref());
        let t_end = time.map(|(t, _)| t);
        for s in &sampled {
            check_samples(cx, s, &points, t_end);
        }
    }

    // Every section has reported its errors by now; the problem exists only if none failed.
    let (shape, (t_end, steps), spec, base) = (shape?, time?, mesh?, base?);
    let ([x0, y0, _], [x1, y1, _]) = shape.bounds();
    let depth = match shape {
        Shape::Cuboid { depth, .. } => Some(depth),
        _ => None,
    };
    let body = match shape {
        Shape::Rectangle { .. } | Shape::Cuboid { .. } => None,
        Shape::Mesh { name, .. } => Some(format!("mesh {name}")),
        Shape::Polygon { .. } => Some("polygon".to_string()),
    }
    .map(|source| Arc::new(Body::new(source, base, spec.refine)));
    let problem = Problem {
        name: name?,
        body,
        width: x1 - x0,
        height: y1 - y0,
        depth,
        cells_per_unit: spec.cells_per_unit,
        pattern: spec.pattern,
        t_end,
        steps,
        boundary: boundary?,
        body_force: body_force?,
        material: material?,
        friction: friction?,
        smallness: smallness?,
        linear: solver?.0,
        precision: solver?.1,
        damage: damage?,
        u0: u0?,
        output: output?,
        error_estimate: error_estimate?,
    };
    if problem.error_estimate {
        if let Some(why) = crate::estimate::unsupported(&problem) {
            cx.err("/error_estimate", format!("an error estimate {why}"));
            return None;
        }
    }
    Some(problem)
}

/// The `solver` section: `{"linear": "auto" | "direct" | "multigrid", "precision": "auto" |
/// "double" | "mixed"}`.
fn solver(cx: &mut Cx, v: &Value, ptr: &str) -> Option<(LinearPath, Precision)> {
    let m = object(cx, v, ptr, "the solver choice", SOLVER_FIELDS)?;
    let linear = match m.get("linear") {
        None => Some(LinearPath::Auto),
        Some(l) => choice(
            cx,
            l,
            &format!("{ptr}/linear"),
            "linear solver",
            LinearPath::NAMES,
        )
        .and_then(|i| LinearPath::parse(LinearPath::NAMES[i])),
    };
    let precision = match m.get("precision") {
        None => Some(Precision::Auto),
        Some(l) => choice(
            cx,
            l,
            &format!("{ptr}/precision"),
            "multigrid precision",
            Precision::NAMES,
        )
        .and_then(|i| Precision::parse(Precision::NAMES[i])),
    };
    Some((linear?, precision?))
}

/// The run's label: 1 to [`MAX_NAME_LEN`] characters, no control characters.
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

/// The body's mesh before refinement, tagged with the parts: the rectangle's structured mesh,
/// the imported mesh, or the polygon meshed at h. Tagging errors (a part without facets, a
/// facet in two parts, an unknown group) are reported at the part's pointer.
fn base_mesh(
    cx: &mut Cx,
    shape: &Shape,
    spec: &mesh::MeshSpec,
    parts: &[crate::problem::BoundaryPart],
) -> Option<AnyMesh> {
    let supports: Vec<_> = parts.iter().map(|p| p.support.clone()).collect();
    let tagged = |cx: &mut Cx, mut m: AnyMesh| {
        let tag = match &mut m {
            AnyMesh::Plane(m) => m.tag_boundary(&supports),
            AnyMesh::Solid(m) => m.tag_boundary(&supports),
        };
        match tag {
            Ok(()) => Some(m),
            Err(e) => {
                cx.err(&format!("/boundary/{}", e.part()), e.to_string());
                None
            }
        }
    };
    let m = match shape {
        Shape::Cuboid {
            width,
            height,
            depth,
        } => {
            let n = spec.cells_per_unit as f64;
            let cells = [*width, *height, *depth].map(|l| (l * n).round() as usize);
            let nodes = cells
                .iter()
                .map(|c| c + 1)
                .fold(1usize, usize::saturating_mul);
            if nodes > MAX_VALIDATION_NODES {
                // As for a large rectangle: the run tags the box it meshes.
                return Some(AnyMesh::Solid(Mesh::cuboid(
                    *width, *height, *depth, 1, 1, 1,
                )));
            }
            let [nx, ny, nz] = cells;
            return tagged(
                cx,
                AnyMesh::Solid(Mesh::cuboid(*width, *height, *depth, nx, ny, nz)),
            );
        }
        Shape::Mesh { mesh, .. } => return tagged(cx, (**mesh).clone()),
        Shape::Rectangle { width, height } => {
            let n = spec.cells_per_unit as f64;
            let (nx, ny) = ((width * n).round() as usize, (height * n).round() as usize);
            if (nx + 1).saturating_mul(ny + 1) > MAX_VALIDATION_NODES {
                // Too large to mesh here (the service's node limit refuses it anyway): segment
                // parts were checked on the rectangle's sides, and the run reports a part
                // that selects nothing ([`Problem::mesh`]). The base mesh of a rectangle is
                // not kept.
                return Some(AnyMesh::Plane(Mesh::rectangle(
                    *width,
                    *height,
                    1,
                    1,
                    spec.pattern,
                )));
            }
            Mesh::rectangle(*width, *height, nx, ny, spec.pattern)
        }
        Shape::Polygon { outer, holes } => {
            let h = spec.h?;
            match crate::mesh::polygon::triangulate(outer, holes, h, MAX_VALIDATION_NODES) {
                Ok(t) => match Mesh::from_cells(t.nodes, t.triangles.concat()) {
                    Ok(m) => m,
                    Err(e) => {
                        cx.err(
                            "/domain/polygon",
                            format!("the polygon's mesh is not usable: {e}"),
                        );
                        return None;
                    }
                },
                Err(e) => {
                    use crate::mesh::polygon::Ring;
                    let ptr = match e.place() {
                        Some((Ring::Outer, v)) => format!("/domain/polygon{}", at_vertex(v)),
                        Some((Ring::Hole(i), v)) => format!("/domain/holes/{i}{}", at_vertex(v)),
                        None if matches!(
                            e,
                            crate::mesh::polygon::PolygonError::MeshingFailed { .. }
                        ) =>
                        {
                            "/domain".into()
                        }
                        None => "/mesh/h".into(),
                    };
                    cx.err(&ptr, e.to_string());
                    return None;
                }
            }
        }
    };
    tagged(cx, AnyMesh::Plane(m))
}

/// "/3" for vertex 3 of a ring, "" for the whole ring.
fn at_vertex(v: Option<usize>) -> String {
    v.map(|v| format!("/{v}")).unwrap_or_default()
}

/// Most nodes of a mesh built during validation.
const MAX_VALIDATION_NODES: usize = 4_000_000;

/// Where formulas are sampled: the rectangle's or box's grid, or (at most ~4,000 of) the
/// body's nodes (z = 0 in 2D).
fn sample_points(shape: &Shape, base: Option<&AnyMesh>) -> Vec<[f64; 3]> {
    match (shape, base) {
        (Shape::Rectangle { width, height }, _) => formulas::grid_points(*width, *height, None),
        (
            Shape::Cuboid {
                width,
                height,
                depth,
            },
            _,
        ) => formulas::grid_points(*width, *height, Some(*depth)),
        (_, Some(AnyMesh::Plane(m))) => {
            let stride = m.n_nodes().div_ceil(4000).max(1);
            m.nodes
                .iter()
                .step_by(stride)
                .map(|p| [p[0], p[1], 0.0])
                .collect()
        }
        (_, Some(AnyMesh::Solid(m))) => {
            let stride = m.n_nodes().div_ceil(4000).max(1);
            m.nodes.iter().step_by(stride).copied().collect()
        }
        (_, None) => Vec::new(),
    }
}
