//! A mesh of either dimension, for code that handles both without being generic: the given
//! body of a problem, and the service's outputs (mesh JSON, VTU) of a stored job.

use super::Mesh;
use std::ops::Deref;
use std::sync::Arc;

/// Triangles (d = 2) or tetrahedra (d = 3).
#[derive(Debug, Clone)]
pub enum AnyMesh {
    Plane(Mesh<2>),
    Solid(Mesh<3>),
}

impl AnyMesh {
    pub fn dim(&self) -> usize {
        match self {
            AnyMesh::Plane(_) => 2,
            AnyMesh::Solid(_) => 3,
        }
    }

    pub fn n_nodes(&self) -> usize {
        match self {
            AnyMesh::Plane(m) => m.n_nodes(),
            AnyMesh::Solid(m) => m.n_nodes(),
        }
    }

    pub fn n_cells(&self) -> usize {
        match self {
            AnyMesh::Plane(m) => m.n_cells(),
            AnyMesh::Solid(m) => m.n_cells(),
        }
    }

    /// Boundary facets (edges in 2D, triangles in 3D).
    pub fn n_facets(&self) -> usize {
        match self {
            AnyMesh::Plane(m) => m.facets.len(),
            AnyMesh::Solid(m) => m.facets.len(),
        }
    }

    /// Edges: 2D from Euler's formula, E = (3C + B)/2 with B boundary edges; 3D counted.
    pub fn n_edges(&self) -> usize {
        match self {
            AnyMesh::Plane(m) => (3 * m.n_cells() + m.facets.len()) / 2,
            AnyMesh::Solid(m) => {
                let mut edges: Vec<(usize, usize)> = m
                    .cells()
                    .flat_map(|c| {
                        (0..4).flat_map(move |a| {
                            (a + 1..4).map(move |b| (c[a].min(c[b]), c[a].max(c[b])))
                        })
                    })
                    .collect();
                edges.sort_unstable();
                edges.dedup();
                edges.len()
            }
        }
    }

    /// The mesh as `Mesh<D>`; panics when D is not its dimension (a programming error:
    /// [`AnyMesh::dim`] tells which).
    pub fn get<const D: usize>(&self) -> &Mesh<D> {
        let any: &dyn std::any::Any = match self {
            AnyMesh::Plane(m) => m,
            AnyMesh::Solid(m) => m,
        };
        any.downcast_ref::<Mesh<D>>()
            .expect("the mesh has the requested dimension")
    }

    /// Wraps a `Mesh<D>` (D = 2 or 3).
    pub fn from_mesh<const D: usize>(mesh: Mesh<D>) -> AnyMesh {
        let any: Box<dyn std::any::Any> = Box::new(mesh);
        match any.downcast::<Mesh<2>>() {
            Ok(m) => AnyMesh::Plane(*m),
            Err(any) => AnyMesh::Solid(
                *any.downcast::<Mesh<3>>()
                    .expect("a mesh of dimension 2 or 3"),
            ),
        }
    }

    /// Every refinement of the mesh `levels` times (red in 2D, Bey's in 3D).
    pub fn refined(&self, levels: usize) -> AnyMesh {
        match self {
            AnyMesh::Plane(m) => AnyMesh::Plane((0..levels).fold(m.clone(), |m, _| m.refine())),
            AnyMesh::Solid(m) => AnyMesh::Solid((0..levels).fold(m.clone(), |m, _| m.refine())),
        }
    }
}

/// A `Mesh<D>` shared, not copied: a given body's mesh is held once, by its problem
/// ([`crate::problem::Body`]), and read through this by the run that computes on it.
#[derive(Debug, Clone)]
pub struct SharedMesh<const D: usize>(Arc<AnyMesh>);

impl<const D: usize> SharedMesh<D> {
    /// A mesh of its own (a rectangle, a box, a refined body).
    pub fn new(mesh: Mesh<D>) -> SharedMesh<D> {
        SharedMesh(Arc::new(AnyMesh::from_mesh(mesh)))
    }

    /// `any`, shared; panics when its dimension is not D (a programming error).
    pub fn of(any: Arc<AnyMesh>) -> SharedMesh<D> {
        assert_eq!(any.dim(), D, "a mesh of dimension {D}");
        SharedMesh(any)
    }
}

impl<const D: usize> Deref for SharedMesh<D> {
    type Target = Mesh<D>;

    fn deref(&self) -> &Mesh<D> {
        self.0.get::<D>()
    }
}
