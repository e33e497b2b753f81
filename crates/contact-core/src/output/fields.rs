//! Fields as JSON: the mesh once (nodes, triangles, Γ3 nodes), then one document per stored
//! step with the requested nodal (u, w, ζ) and element (σ, von Mises) fields.

use crate::mesh::Mesh;
use crate::problem::{BoundaryKind, BoundaryPart, Support};
use serde::Serialize;

#[derive(Debug, Serialize)]
pub struct MeshJson<'a> {
    pub nodes: &'a [[f64; 2]],
    pub triangles: &'a [[usize; 3]],
    /// Boundary edges with the index of their part (null: traction-free).
    pub boundary_edges: Vec<([usize; 2], Option<usize>)>,
    /// The scene's boundary parts, in its order (the indices in `boundary_edges`): what kind
    /// of condition each is, and the physical group it was selected by, if any. Lets a
    /// client colour the boundary by kind without the scene.
    pub parts: Vec<PartJson<'a>>,
}

/// One boundary part of [`MeshJson`].
#[derive(Debug, Serialize)]
pub struct PartJson<'a> {
    /// `clamped`, `traction` or `contact`.
    #[serde(rename = "type")]
    pub kind: &'static str,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub group: Option<&'a str>,
}

impl<'a> MeshJson<'a> {
    /// The mesh with the boundary parts it was tagged with (`Problem::boundary`).
    pub fn new(mesh: &'a Mesh, parts: &'a [BoundaryPart]) -> Self {
        MeshJson {
            nodes: &mesh.nodes,
            triangles: mesh.triangles(),
            boundary_edges: mesh.facets.iter().map(|e| (e.nodes, e.part)).collect(),
            parts: parts
                .iter()
                .map(|p| PartJson {
                    kind: match p.kind {
                        BoundaryKind::Clamped => "clamped",
                        BoundaryKind::Traction(_) => "traction",
                        BoundaryKind::Contact => "contact",
                    },
                    group: match &p.support {
                        Support::Group(name) => Some(name.as_str()),
                        _ => None,
                    },
                })
                .collect(),
        }
    }
}
