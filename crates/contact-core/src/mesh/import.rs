//! Bodies made in gmsh: an MSH 4.1 or 2.2 file ([`crate::msh`]) turned into a checked [`Mesh`]
//! (docs/src/explanation/numerics.md#meshes): the cells are the elements of the highest dimension, the
//! physical groups of facet elements become named [`Group`]s of boundary facets, and the
//! mesh passes [`super::quality`]. [`summarize`] is what `POST /meshes` answers.

use serde::Serialize;

use super::quality::{figures, Figures, IndexMap, MeshError};
use super::{signed_measure, AnyMesh, Group, Mesh};
use crate::msh::{self, MshMesh};

/// Most nodes of an imported mesh (the structured generator's limit is of the same order).
pub const MAX_NODES: usize = 2_000_000;
/// Most cells of an imported mesh.
pub const MAX_CELLS: usize = 4_000_000;
/// Largest .msh file accepted.
pub const MAX_FILE_BYTES: usize = 256 << 20;

/// Why a file is not a usable body mesh.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ImportError {
    #[error("not a readable gmsh MSH file (version 4.1 or 2.2): {0}")]
    Format(#[from] msh::MshError),
    #[error("{0}")]
    Mesh(#[from] MeshError),
}

/// Reads an MSH 4.1 or 2.2 file of at most [`MAX_FILE_BYTES`].
fn read(bytes: &[u8]) -> Result<MshMesh, ImportError> {
    if bytes.len() > MAX_FILE_BYTES {
        return Err(MeshError::TooLarge {
            what: "bytes",
            count: bytes.len(),
            max: MAX_FILE_BYTES,
        }
        .into());
    }
    Ok(msh::read(bytes)?)
}

/// Reads, checks and converts an MSH 4.1 or 2.2 file (ASCII or binary) into a D-dimensional mesh.
pub fn import<const D: usize>(bytes: &[u8]) -> Result<Mesh<D>, ImportError> {
    Ok(from_msh(&read(bytes)?)?)
}

/// Reads, checks and converts an MSH 4.1 or 2.2 file of either dimension: tetrahedra make a
/// [`AnyMesh::Solid`], triangles (all z = 0) an [`AnyMesh::Plane`].
pub fn import_any(bytes: &[u8]) -> Result<AnyMesh, ImportError> {
    let m = read(bytes)?;
    Ok(match m.dim {
        2 => AnyMesh::Plane(from_msh::<2>(&m)?),
        _ => AnyMesh::Solid(from_msh::<3>(&m)?),
    })
}

/// The checked mesh of a read file (see the module doc).
pub fn from_msh<const D: usize>(m: &MshMesh) -> Result<Mesh<D>, MeshError> {
    if m.dim != D {
        return Err(MeshError::Dimension {
            found: m.dim,
            expected: D,
        });
    }
    for (what, count, max) in [
        ("nodes", m.nodes.len(), MAX_NODES),
        ("cells", m.cell_count(), MAX_CELLS),
    ] {
        if count > max {
            return Err(MeshError::TooLarge { what, count, max });
        }
    }
    if D == 2 {
        if let Some((node, p)) = m.nodes.iter().enumerate().find(|(_, p)| p[2] != 0.0) {
            return Err(MeshError::NotPlanar { node, z: p[2] });
        }
    }
    let nodes: Vec<[f64; D]> = m
        .nodes
        .iter()
        .map(|p| std::array::from_fn(|c| p[c]))
        .collect();
    let mut mesh = Mesh::<D>::from_cells(nodes, m.cell_nodes.clone())?;
    let index: IndexMap<[usize; D], usize> = mesh
        .facets
        .iter()
        .enumerate()
        .map(|(i, f)| {
            let mut k = f.nodes;
            k.sort_unstable();
            (k, i)
        })
        .collect();
    for g in &m.groups {
        let name = g.name.clone().unwrap_or_else(|| g.tag.to_string());
        let mut facets = Vec::with_capacity(g.len());
        let mut taken = vec![false; mesh.facets.len()];
        for (i, f) in g.facets().enumerate() {
            let mut key = [0; D];
            key.copy_from_slice(f);
            key.sort_unstable();
            let Some(&k) = index.get(&key) else {
                return Err(MeshError::NotOnBoundary {
                    group: name,
                    index: i,
                    nodes: f.to_vec(),
                });
            };
            if std::mem::replace(&mut taken[k], true) {
                return Err(MeshError::DuplicateFacet {
                    group: name,
                    index: i,
                    nodes: f.to_vec(),
                });
            }
            facets.push(k);
        }
        mesh.groups.push(Group { name, facets });
    }
    Ok(mesh)
}

/// What `POST /meshes` reports about an uploaded mesh.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct MeshSummary {
    pub dimension: usize,
    pub nodes: usize,
    pub cells: usize,
    pub boundary_facets: usize,
    /// Cells whose vertices the file lists in the negative orientation (clockwise in 2D,
    /// left-handed in 3D); accepted as they are.
    pub negatively_oriented_cells: usize,
    /// Physical groups of facets, in the file's tag order.
    pub groups: Vec<GroupSummary>,
    pub bounding_box: BoundingBox,
    #[serde(flatten)]
    pub figures: Figures,
}

#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct GroupSummary {
    pub name: String,
    pub facets: usize,
    /// Total length (2D) or area (3D) of the group's facets.
    pub measure: f64,
}

#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct BoundingBox {
    pub min: Vec<f64>,
    pub max: Vec<f64>,
}

/// The summary of a checked mesh.
pub fn summary<const D: usize>(mesh: &Mesh<D>) -> MeshSummary {
    let (lo, hi) = mesh.bounding_box();
    MeshSummary {
        dimension: D,
        nodes: mesh.n_nodes(),
        cells: mesh.n_cells(),
        boundary_facets: mesh.facets.len(),
        negatively_oriented_cells: mesh
            .cells()
            .filter(|c| {
                let p: Vec<[f64; D]> = c.iter().map(|&v| mesh.nodes[v]).collect();
                signed_measure(&p) < 0.0
            })
            .count(),
        groups: mesh
            .groups
            .iter()
            .map(|g| GroupSummary {
                name: g.name.clone(),
                facets: g.facets.len(),
                measure: g.facets.iter().map(|&f| mesh.facets[f].measure).sum(),
            })
            .collect(),
        bounding_box: BoundingBox {
            min: lo.to_vec(),
            max: hi.to_vec(),
        },
        figures: figures(mesh),
    }
}

/// Reads and checks an uploaded file of any supported dimension and summarises it.
pub fn summarize(bytes: &[u8]) -> Result<MeshSummary, ImportError> {
    Ok(summary_any(&import_any(bytes)?))
}

/// [`summary`] of a mesh of either dimension.
pub fn summary_any(mesh: &AnyMesh) -> MeshSummary {
    match mesh {
        AnyMesh::Plane(m) => summary(m),
        AnyMesh::Solid(m) => summary(m),
    }
}
