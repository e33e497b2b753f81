//! Fields as JSON: the mesh once (nodes, triangles, Γ3 nodes), then one document per stored
//! step with the requested nodal (u, w, ζ) and element (σ, von Mises) fields.

use crate::mesh::Mesh;
use serde::Serialize;

#[derive(Debug, Serialize)]
pub struct MeshJson<'a> {
    pub nodes: &'a [[f64; 2]],
    pub triangles: &'a [[usize; 3]],
    /// Boundary edges with the index of their part (null: traction-free).
    pub boundary_edges: Vec<([usize; 2], Option<usize>)>,
}

impl<'a> MeshJson<'a> {
    pub fn new(mesh: &'a Mesh) -> Self {
        MeshJson {
            nodes: &mesh.nodes,
            triangles: mesh.triangles(),
            boundary_edges: mesh.facets.iter().map(|e| (e.nodes, e.part)).collect(),
        }
    }
}
