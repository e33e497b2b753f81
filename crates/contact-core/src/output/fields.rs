//! Fields as JSON: the mesh once (nodes, cells, boundary facets with their parts), then one
//! document per stored step with the requested nodal (u, w, ζ) and element (σ, von Mises)
//! fields.

use super::surface::Surface;
use crate::mesh::{AnyMesh, Mesh};
use crate::problem::{BoundaryKind, BoundaryPart, Support};
use serde::Serialize;

/// The mesh of a job: in 2D `nodes` (x, y), `triangles` and `boundary_edges`; in 3D
/// `nodes` (x, y, z), `tetrahedra` and `boundary_faces`.
#[derive(Debug, Serialize)]
#[serde(untagged)]
pub enum MeshJson<'a> {
    Plane(PlaneMeshJson<'a>),
    Solid(SolidMeshJson<'a>),
    Surface(SurfaceMeshJson<'a>),
}

#[derive(Debug, Serialize)]
pub struct PlaneMeshJson<'a> {
    pub dim: usize,
    pub nodes: &'a [[f64; 2]],
    pub triangles: &'a [[usize; 3]],
    /// Boundary edges with the index of their part (null: traction-free).
    pub boundary_edges: Vec<([usize; 2], Option<usize>)>,
    /// The scene's boundary parts, in its order (the indices in `boundary_edges`): what kind
    /// of condition each is, and the physical group it was selected by, if any. Lets a
    /// client colour the boundary by kind without the scene.
    pub parts: Vec<PartJson<'a>>,
}

#[derive(Debug, Serialize)]
pub struct SolidMeshJson<'a> {
    pub dim: usize,
    pub nodes: &'a [[f64; 3]],
    pub tetrahedra: Vec<[usize; 4]>,
    /// Boundary triangles (counter-clockwise seen from outside) with the index of their part
    /// (null: traction-free) and of the tetrahedron they bound (for cell fields).
    pub boundary_faces: Vec<([usize; 3], Option<usize>, usize)>,
    pub parts: Vec<PartJson<'a>>,
}

/// The boundary surface of a 3D mesh ([`Surface`]): `surface` is true, `nodes` (x, y, z)
/// are the surface nodes, `node_ids` their ids in the whole mesh, `triangles` (in the
/// surface numbering, counter-clockwise seen from outside) with `triangle_parts` (null:
/// traction-free) and `cells`, the tetrahedron each is a face of. Element fields served with
/// it have one value per triangle (its tetrahedron's).
#[derive(Debug, Serialize)]
pub struct SurfaceMeshJson<'a> {
    pub dim: usize,
    pub surface: bool,
    pub nodes: Vec<[f64; 3]>,
    pub node_ids: &'a [usize],
    pub triangles: &'a [[usize; 3]],
    pub triangle_parts: Vec<Option<usize>>,
    pub cells: &'a [usize],
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
    pub fn new(mesh: &'a AnyMesh, parts: &'a [BoundaryPart]) -> Self {
        match mesh {
            AnyMesh::Plane(m) => MeshJson::Plane(PlaneMeshJson {
                dim: 2,
                nodes: &m.nodes,
                triangles: m.triangles(),
                boundary_edges: m.facets.iter().map(|e| (e.nodes, e.part)).collect(),
                parts: part_list(parts),
            }),
            AnyMesh::Solid(m) => MeshJson::Solid(SolidMeshJson {
                dim: 3,
                nodes: &m.nodes,
                tetrahedra: m.cells().map(|c| [c[0], c[1], c[2], c[3]]).collect(),
                boundary_faces: faces_with_cells(m),
                parts: part_list(parts),
            }),
        }
    }

    /// The boundary surface `surface` of the 3D mesh `m`, with the boundary parts.
    pub fn surface(m: &Mesh<3>, surface: &'a Surface, parts: &'a [BoundaryPart]) -> Self {
        MeshJson::Surface(SurfaceMeshJson {
            dim: 3,
            surface: true,
            nodes: surface.nodes(m),
            node_ids: &surface.node_ids,
            triangles: &surface.triangles,
            triangle_parts: surface.parts(m),
            cells: &surface.cells,
            parts: part_list(parts),
        })
    }
}

fn part_list(parts: &[BoundaryPart]) -> Vec<PartJson<'_>> {
    parts
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
        .collect()
}

/// Every boundary facet with its part and the tetrahedron it is a face of.
fn faces_with_cells(m: &Mesh<3>) -> Vec<([usize; 3], Option<usize>, usize)> {
    let key = |mut f: [usize; 3]| {
        f.sort_unstable();
        f
    };
    let mut owner = std::collections::HashMap::with_capacity(m.facets.len());
    for f in &m.facets {
        owner.insert(key(f.nodes), usize::MAX);
    }
    for (e, c) in m.cells().enumerate() {
        for skip in 0..4 {
            let mut face = [0; 3];
            let mut k = 0;
            for (a, &n) in c.iter().enumerate() {
                if a != skip {
                    face[k] = n;
                    k += 1;
                }
            }
            if let Some(o) = owner.get_mut(&key(face)) {
                *o = e;
            }
        }
    }
    m.facets
        .iter()
        .map(|f| (f.nodes, f.part, owner[&key(f.nodes)]))
        .collect()
}
