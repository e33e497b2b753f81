//! The `domain` section: the body. Four forms (docs/src/explanation/numerics.md#meshes):
//! - the rectangle `{width, height}` (or `{"rectangle": {width, height}}`), meshed by the
//!   structured generator at `mesh.h`;
//! - the box `{width, height, depth}` (d = 3), meshed at `mesh.h` into cubes of 6 Kuhn
//!   tetrahedra;
//! - `{"mesh": NAME}`: a gmsh MSH 4.1 file, looked up through [`MeshFiles`] (the CLI reads
//!   it relative to the scene file, the service takes the id of an uploaded mesh);
//! - `{"polygon": [[x, y], ...], "holes": [[[x, y], ...], ...]}`: meshed in-process at
//!   `mesh.h` ([`crate::mesh::polygon`]).

use serde_json::Value;

use super::fields::{DOMAIN_FIELDS, RECTANGLE_FIELDS};
use super::read::{describe, index, join, object, point, required_number, Cx, Range};
use super::MeshFiles;
use crate::mesh::AnyMesh;

/// Most vertices of a polygon, over all its rings.
pub(super) const MAX_POLYGON_VERTICES: usize = 100_000;

/// The body a scene describes, before it is meshed and tagged.
pub(super) enum Shape {
    Rectangle {
        width: f64,
        height: f64,
    },
    /// [0, width] × [0, height] × [0, depth].
    Cuboid {
        width: f64,
        height: f64,
        depth: f64,
    },
    /// An imported mesh (triangles or tetrahedra), checked, and the name it was given by.
    Mesh {
        name: String,
        mesh: Box<AnyMesh>,
    },
    Polygon {
        outer: Vec<[f64; 2]>,
        holes: Vec<Vec<[f64; 2]>>,
    },
}

impl Shape {
    /// The body's dimension d.
    pub(super) fn dim(&self) -> usize {
        match self {
            Shape::Cuboid { .. } => 3,
            Shape::Mesh { mesh, .. } => mesh.dim(),
            Shape::Rectangle { .. } | Shape::Polygon { .. } => 2,
        }
    }

    /// The bounding box [lo, hi] of the body (z = 0 in 2D).
    pub(super) fn bounds(&self) -> ([f64; 3], [f64; 3]) {
        let plane = |(lo, hi): ([f64; 2], [f64; 2])| ([lo[0], lo[1], 0.0], [hi[0], hi[1], 0.0]);
        match self {
            Shape::Rectangle { width, height } => ([0.0; 3], [*width, *height, 0.0]),
            Shape::Cuboid {
                width,
                height,
                depth,
            } => ([0.0; 3], [*width, *height, *depth]),
            Shape::Mesh { mesh, .. } => match &**mesh {
                AnyMesh::Plane(m) => plane(m.bounding_box()),
                AnyMesh::Solid(m) => m.bounding_box(),
            },
            Shape::Polygon { outer, .. } => plane(outer.iter().fold(
                ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]),
                |(lo, hi), p| {
                    (
                        [lo[0].min(p[0]), lo[1].min(p[1])],
                        [hi[0].max(p[0]), hi[1].max(p[1])],
                    )
                },
            )),
        }
    }
}

pub(super) fn domain(cx: &mut Cx, v: &Value, ptr: &str, files: &dyn MeshFiles) -> Option<Shape> {
    let m = object(cx, v, ptr, "domain", DOMAIN_FIELDS)?;
    let forms = ["rectangle", "mesh", "polygon"]
        .into_iter()
        .filter(|k| m.contains_key(*k))
        .chain(
            m.contains_key("width")
                .then_some("width")
                .or(m.contains_key("height").then_some("height")),
        )
        .collect::<Vec<_>>();
    if forms.len() > 1 {
        cx.err(
            ptr,
            format!(
                "give one form of the domain: width and height, a rectangle, a mesh or a polygon; got {}",
                forms.join(" and ")
            ),
        );
        return None;
    }
    if m.contains_key("depth") && !(m.contains_key("width") || m.contains_key("height")) {
        cx.err(
            &join(ptr, "depth"),
            "depth belongs to a box {width, height, depth}",
        );
        return None;
    }
    if let Some(name) = m.get("mesh") {
        if m.contains_key("holes") {
            cx.err(&join(ptr, "holes"), "holes belong to a polygon domain");
            return None;
        }
        let mptr = join(ptr, "mesh");
        let Some(name) = name.as_str().filter(|s| !s.is_empty()) else {
            cx.err(
                &mptr,
                format!(
                    "mesh must be the name of a mesh file or the id of an uploaded mesh, got {}",
                    describe(name)
                ),
            );
            return None;
        };
        return match files.load(name) {
            Ok(mesh) => Some(Shape::Mesh {
                name: name.to_string(),
                mesh: Box::new(mesh),
            }),
            Err(why) => {
                cx.err(&mptr, why);
                None
            }
        };
    }
    if let Some(outer) = m.get("polygon") {
        let outer = ring(cx, outer, &join(ptr, "polygon"));
        let holes = match m.get("holes") {
            None => Some(Vec::new()),
            Some(Value::Array(hs)) => {
                let hptr = join(ptr, "holes");
                let rings: Vec<_> = hs
                    .iter()
                    .enumerate()
                    .map(|(i, h)| ring(cx, h, &index(&hptr, i)))
                    .collect();
                rings.into_iter().collect::<Option<Vec<_>>>()
            }
            Some(other) => {
                cx.err(
                    &join(ptr, "holes"),
                    format!(
                        "holes must be an array of rings [[x, y], ...], got {}",
                        describe(other)
                    ),
                );
                None
            }
        };
        let (outer, holes) = (outer?, holes?);
        let total = outer.len() + holes.iter().map(Vec::len).sum::<usize>();
        if total > MAX_POLYGON_VERTICES {
            cx.err(
                ptr,
                format!(
                    "the polygon has {total} vertices; at most {MAX_POLYGON_VERTICES} are allowed"
                ),
            );
            return None;
        }
        return Some(Shape::Polygon { outer, holes });
    }
    if m.contains_key("holes") {
        cx.err(&join(ptr, "holes"), "holes belong to a polygon domain");
        return None;
    }
    let (m, ptr) = match m.get("rectangle") {
        Some(r) => {
            let rptr = join(ptr, "rectangle");
            (object(cx, r, &rptr, "rectangle", RECTANGLE_FIELDS)?, rptr)
        }
        None => (m, ptr.to_string()),
    };
    let w = required_number(cx, m, &ptr, "width", Range::Positive, "length along x");
    let h = required_number(cx, m, &ptr, "height", Range::Positive, "length along y");
    if m.contains_key("depth") {
        let d = required_number(cx, m, &ptr, "depth", Range::Positive, "length along z");
        return Some(Shape::Cuboid {
            width: w?,
            height: h?,
            depth: d?,
        });
    }
    Some(Shape::Rectangle {
        width: w?,
        height: h?,
    })
}

/// A ring of at least 3 points [x, y].
fn ring(cx: &mut Cx, v: &Value, ptr: &str) -> Option<Vec<[f64; 2]>> {
    let Some(items) = v.as_array().filter(|a| a.len() >= 3) else {
        cx.err(
            ptr,
            format!(
                "expected a ring of at least 3 points [[x, y], ...], got {}",
                describe(v)
            ),
        );
        return None;
    };
    if items.len() > MAX_POLYGON_VERTICES {
        cx.err(
            ptr,
            format!(
                "a ring has at most {MAX_POLYGON_VERTICES} points, got {}",
                items.len()
            ),
        );
        return None;
    }
    let pts: Vec<_> = items
        .iter()
        .enumerate()
        .map(|(i, p)| point(cx, p, &index(ptr, i)))
        .collect();
    pts.into_iter().collect()
}
