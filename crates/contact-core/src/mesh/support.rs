//! Which boundary facets a boundary part selects (docs/src/explanation/numerics.md#boundary-tagging): a facet
//! belongs to a part when all its vertices lie on the part's support — a closed segment, or
//! the zero set of a formula where an optional second formula is ≥ 0 — within 1e-9 × the
//! diagonal of the body's bounding box, or when it is in the physical group the part names.
//! A facet in two parts, a part without facets and a group the mesh lacks are errors.

use super::{Mesh, Segment};
use crate::expr::Expr;

/// The set a boundary part's facets are taken from.
#[derive(Debug, Clone)]
pub enum Support {
    /// A closed straight segment (2D).
    Segment(Segment),
    /// A physical group of an imported mesh, by name.
    Group(String),
    /// The zero set of `on`, where `within` is ≥ 0 if given; both formulas in x, y.
    Zero { on: Expr, within: Option<Expr> },
}

/// Relative tolerance (times the bounding-box diagonal) of "lies on the support".
pub const ON_TOL: f64 = 1e-9;

/// Why a set of supports does not tag a mesh.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum TagError {
    #[error("boundary facet {facet} (nodes {nodes:?}) is selected by parts {first} and {second}; a facet belongs to one part")]
    Overlap {
        facet: usize,
        nodes: Vec<usize>,
        first: usize,
        second: usize,
    },
    #[error("part {part} selects no boundary facet")]
    Empty { part: usize },
    #[error(
        "part {part} names the group \"{name}\", which the mesh does not have (it has: {known})"
    )]
    UnknownGroup {
        part: usize,
        name: String,
        known: String,
    },
}

impl TagError {
    /// The boundary part the error is about.
    pub fn part(&self) -> usize {
        match self {
            TagError::Overlap { second, .. } => *second,
            TagError::Empty { part } | TagError::UnknownGroup { part, .. } => *part,
        }
    }
}

/// Sets [`super::Facet::part`] of every boundary facet of `mesh` from `supports` (one per part).
pub fn tag<const D: usize>(mesh: &mut Mesh<D>, supports: &[Support]) -> Result<(), TagError> {
    let tol = ON_TOL * mesh.diameter();
    let mut selected: Vec<Option<usize>> = vec![None; mesh.facets.len()];
    for (part, support) in supports.iter().enumerate() {
        let mut claim = |facet: usize| match selected[facet] {
            Some(first) if first != part => Err(TagError::Overlap {
                facet,
                nodes: mesh.facets[facet].nodes.to_vec(),
                first,
                second: part,
            }),
            _ => {
                selected[facet] = Some(part);
                Ok(())
            }
        };
        let mut any = false;
        match support {
            Support::Group(name) => {
                let Some(g) = mesh.groups.iter().find(|g| &g.name == name) else {
                    let known: Vec<_> = mesh
                        .groups
                        .iter()
                        .map(|g| format!("\"{}\"", g.name))
                        .collect();
                    return Err(TagError::UnknownGroup {
                        part,
                        name: name.clone(),
                        known: if known.is_empty() {
                            "no physical groups of facets".into()
                        } else {
                            known.join(", ")
                        },
                    });
                };
                for &f in &g.facets {
                    claim(f)?;
                    any = true;
                }
            }
            _ => {
                for (f, facet) in mesh.facets.iter().enumerate() {
                    let on = facet
                        .nodes
                        .iter()
                        .all(|&i| support.contains(&mesh.nodes[i], tol));
                    if on {
                        claim(f)?;
                        any = true;
                    }
                }
            }
        }
        if !any {
            return Err(TagError::Empty { part });
        }
    }
    for (facet, part) in mesh.facets.iter_mut().zip(selected) {
        facet.part = part;
    }
    Ok(())
}

impl Support {
    /// Does the point lie on the support (within `tol`)? Groups contain no point as such.
    pub fn contains<const D: usize>(&self, p: &[f64; D], tol: f64) -> bool {
        match self {
            Support::Segment(s) => D == 2 && super::on_segment([p[0], p[1]], s, tol),
            Support::Zero { on, within } => {
                let (x, y, z) = (p[0], p[1], if D > 2 { p[2] } else { 0.0 });
                on.eval3(x, y, z, 0.0).abs() <= tol
                    && within.as_ref().is_none_or(|w| w.eval3(x, y, z, 0.0) >= 0.0)
            }
            Support::Group(_) => false,
        }
    }
}
