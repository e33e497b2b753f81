//! The boundary surface of a 3D tetrahedral mesh, and a step's fields restricted to it: what
//! a client draws of a solid body (its outside), without the interior that makes up almost
//! all of a fine mesh (a 64³ Kuhn box: 274,625 nodes and 1,572,864 tetrahedra, of which
//! 24,578 nodes and 49,152 boundary triangles are on its surface).
//!
//! The surface is found from the cells (the boundary facets only narrow the search): the
//! faces that belong to exactly one tetrahedron, each oriented counter-clockwise seen from
//! outside (away from the owning tetrahedron's fourth vertex, whatever the cell's own
//! orientation). Its nodes are numbered compactly (0..) in the order of their original ids, and [`Surface::node_ids`] maps them
//! back. On the surface, nodal fields are those of the mapped nodes and element fields (σ,
//! von Mises) take the value of the face's owning tetrahedron.
//!
//! A plane (2D) mesh has no surface in this sense: its picture is the whole mesh, so
//! [`Surface::of`] answers `None` for it (not applicable), and the service serves a 2D
//! job's fields whole.

use crate::mesh::{signed_measure, AnyMesh, Mesh};
use crate::solve::stepper::{StepFields, Stress};
use std::collections::HashMap;

/// The boundary surface of a tetrahedral mesh (see the module docs).
#[derive(Debug, Clone, PartialEq)]
pub struct Surface {
    /// The original node id of each surface node, ascending.
    pub node_ids: Vec<usize>,
    /// Boundary triangles in the surface's node numbering, counter-clockwise seen from
    /// outside, ordered by owning tetrahedron and then by the local index of the vertex
    /// opposite the face.
    pub triangles: Vec<[usize; 3]>,
    /// The tetrahedron each triangle is a face of.
    pub cells: Vec<usize>,
}

/// A field whose length does not match the mesh the surface was taken from.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("field {field}: {found} values, but the mesh needs {expected}")]
pub struct FieldMismatch {
    pub field: &'static str,
    pub expected: usize,
    pub found: usize,
}

impl Surface {
    /// The surface of a solid mesh; `None` for a plane one (whose picture is the whole mesh).
    pub fn of(mesh: &AnyMesh) -> Option<Surface> {
        match mesh {
            AnyMesh::Plane(_) => None,
            AnyMesh::Solid(m) => Some(Surface::of_solid(m)),
        }
    }

    /// The faces of `m` that belong to exactly one tetrahedron (a conforming mesh, as
    /// [`Mesh::from_cells`] checks, has no face in more than two). One pass over the cells
    /// keeps only the faces seen an odd number of times, so the map holds the current front
    /// of unmatched faces, not every face: expected O(cells) time, and memory O(surface)
    /// besides the output for cells ordered as generators and mesh files order them.
    ///
    /// Only faces whose three nodes are nodes of the mesh's boundary facets are counted
    /// (all nodes when it has none): a face of one tetrahedron has its nodes on the
    /// boundary, and every cell of a face so filtered is still counted, so the answer is the
    /// same, while only the boundary's faces (and the few interior ones spanning its edges)
    /// are hashed, not all 12.6 M faces of the 64³ box.
    pub fn of_solid(m: &Mesh<3>) -> Surface {
        let mut candidate = vec![m.facets.is_empty(); m.n_nodes()];
        for f in &m.facets {
            for &n in &f.nodes {
                candidate[n] = true;
            }
        }
        let mut open: HashMap<[usize; 3], (usize, u8)> = HashMap::new();
        for (e, c) in m.cells().enumerate() {
            if c.iter().filter(|&&n| candidate[n]).count() < 3 {
                continue;
            }
            for skip in 0..4u8 {
                let mut key = face(c, skip);
                if !key.iter().all(|&n| candidate[n]) {
                    continue;
                }
                key.sort_unstable();
                if open.remove(&key).is_none() {
                    open.insert(key, (e, skip));
                }
            }
        }
        let mut owned: Vec<(usize, u8)> = open.into_values().collect();
        // Deterministic output whatever the hash map's order.
        owned.sort_unstable();

        let mut on_surface = vec![false; m.n_nodes()];
        let mut triangles: Vec<[usize; 3]> = Vec::with_capacity(owned.len());
        let mut cells = Vec::with_capacity(owned.len());
        for &(e, skip) in &owned {
            let c = m.cell(e);
            let mut tri = face(c, skip);
            let p = |n: usize| m.nodes[n];
            // Right-handed (tri, opposite) means the counter-clockwise normal of tri points
            // towards the opposite vertex, into the cell: turn the face round.
            if signed_measure(&[p(tri[0]), p(tri[1]), p(tri[2]), p(c[skip as usize])]) > 0.0 {
                tri.swap(1, 2);
            }
            for &n in &tri {
                on_surface[n] = true;
            }
            triangles.push(tri);
            cells.push(e);
        }
        let node_ids: Vec<usize> = (0..m.n_nodes()).filter(|&n| on_surface[n]).collect();
        let mut compact = vec![usize::MAX; m.n_nodes()];
        for (i, &n) in node_ids.iter().enumerate() {
            compact[n] = i;
        }
        for tri in &mut triangles {
            for n in tri.iter_mut() {
                *n = compact[*n];
            }
        }
        Surface {
            node_ids,
            triangles,
            cells,
        }
    }

    /// The coordinates of the surface nodes, in the surface numbering.
    pub fn nodes(&self, m: &Mesh<3>) -> Vec<[f64; 3]> {
        self.node_ids.iter().map(|&n| m.nodes[n]).collect()
    }

    /// The boundary part of each triangle (`None`: traction-free), from the mesh's tagged
    /// facets; a triangle that is not among them (it cannot be, for a mesh built by
    /// [`Mesh::from_cells`] or the generators) counts as traction-free.
    pub fn parts(&self, m: &Mesh<3>) -> Vec<Option<usize>> {
        let key = |mut f: [usize; 3]| {
            f.sort_unstable();
            f
        };
        let tagged: HashMap<[usize; 3], Option<usize>> =
            m.facets.iter().map(|f| (key(f.nodes), f.part)).collect();
        self.triangles
            .iter()
            .map(|t| {
                let original = [
                    self.node_ids[t[0]],
                    self.node_ids[t[1]],
                    self.node_ids[t[2]],
                ];
                tagged.get(&key(original)).copied().flatten()
            })
            .collect()
    }

    /// The surface index of original node `n`, if it is on the surface.
    pub fn index_of(&self, n: usize) -> Option<usize> {
        self.node_ids.binary_search(&n).ok()
    }

    /// `f` on the surface: u and w (3 components per node) and ζ at the surface nodes, σ and
    /// von Mises of each triangle's tetrahedron, and the contact nodes renumbered to the
    /// surface (a contact node off the surface, which a Γ3 node cannot be, is left out).
    /// `n_nodes` and `n_cells` are the sizes of the mesh the surface was taken from; a field
    /// of another length is an error.
    pub fn restrict(
        &self,
        f: StepFields,
        n_nodes: usize,
        n_cells: usize,
    ) -> Result<StepFields, FieldMismatch> {
        let check = |field: &'static str, found: usize, expected: usize| {
            if found == expected {
                Ok(())
            } else {
                Err(FieldMismatch {
                    field,
                    expected,
                    found,
                })
            }
        };
        let vector = |field: &'static str, v: Option<Vec<f64>>| -> Result<_, FieldMismatch> {
            v.map(|v| {
                check(field, v.len(), 3 * n_nodes)?;
                Ok(self
                    .node_ids
                    .iter()
                    .flat_map(|&n| [v[3 * n], v[3 * n + 1], v[3 * n + 2]])
                    .collect())
            })
            .transpose()
        };
        let u = vector("u", f.u)?;
        let w = vector("w", f.w)?;
        let zeta = f
            .zeta
            .map(|z| {
                check("zeta", z.len(), n_nodes)?;
                Ok(self.node_ids.iter().map(|&n| z[n]).collect())
            })
            .transpose()?;
        let sigma = f
            .sigma
            .map(|s| {
                check("sigma", s.len(), n_cells)?;
                Ok(match s {
                    Stress::Solid(s) => Stress::Solid(self.cells.iter().map(|&e| s[e]).collect()),
                    Stress::Plane(s) => Stress::Plane(self.cells.iter().map(|&e| s[e]).collect()),
                })
            })
            .transpose()?;
        let von_mises = f
            .von_mises
            .map(|v| {
                check("von_mises", v.len(), n_cells)?;
                Ok(self.cells.iter().map(|&e| v[e]).collect())
            })
            .transpose()?;
        let estimate = f
            .estimate
            .map(|v| {
                check("estimate", v.len(), n_cells)?;
                Ok(self.cells.iter().map(|&e| v[e]).collect())
            })
            .transpose()?;
        let contact = f.contact.map(|c| {
            c.into_iter()
                .filter_map(|mut node| {
                    node.node = self.index_of(node.node)?;
                    Some(node)
                })
                .collect()
        });
        Ok(StepFields {
            n: f.n,
            t: f.t,
            u,
            w,
            zeta,
            sigma,
            von_mises,
            contact,
            estimate,
        })
    }
}

/// The face of tetrahedron `c` opposite its vertex `skip`, the others in cell order.
fn face(c: &[usize], skip: u8) -> [usize; 3] {
    let mut f = [0; 3];
    let mut k = 0;
    for (a, &n) in c.iter().enumerate() {
        if a != skip as usize {
            f[k] = n;
            k += 1;
        }
    }
    f
}

#[cfg(test)]
mod tests;
