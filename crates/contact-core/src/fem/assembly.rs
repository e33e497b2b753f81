//! Global matrices of the scheme, assembled once per job:
//! - the velocity operator (A ε(w), ε(v)) on the free DOFs (constant in time: A does not
//!   depend on damage), factored once;
//! - the P1 mass M and stiffness (Laplacian) K of the damage equation (3.10).

#![allow(clippy::needless_range_loop)] // Index loops over vertices and components spell out the formulas.

use super::{DofMap, Geometry, Slot};
use crate::linalg::{par, Csr};
use crate::mesh::Mesh;
use std::ops::Range;

/// (A ε(w), ε(v)) with A(τ) = 2η τ + ξ tr(τ) I on the free DOFs (3.13):
/// K[(a,c),(b,d)] = |T| [η (δ_cd ∇ψ_a·∇ψ_b + ∂_d ψ_a ∂_c ψ_b) + ξ ∂_c ψ_a ∂_d ψ_b],
/// rotated into the contact frames of [`DofMap`] (K_loc = Qᵀ K Q on the cells that touch one).
/// With η = 1/2, ξ = 0 it is the Gram matrix of the V-norm ‖ε(·)‖_L2.
pub fn viscous_stiffness<const D: usize>(
    mesh: &Mesh<D>,
    geo: &Geometry<D>,
    dofs: &DofMap<D>,
    eta: f64,
    xi: f64,
) -> Csr {
    let n = dofs.n_free();
    let nd = (D + 1) * D;
    let mut t = Vec::with_capacity(mesh.n_cells() * nd * nd);
    viscous_entries(mesh, geo, dofs, eta, xi, |i, j, v| t.push((i, j, v)));
    Csr::from_triplets(n, n, t)
}

/// [`viscous_stiffness`] assembled into its sparsity pattern, built first from the node
/// adjacency, so that no list of element entries is held: memory is the matrix alone (the
/// triplet lists take 24 (D(D+1))² bytes per cell, 1.4 GB for the 1/32 box). Equal to
/// [`viscous_stiffness`] up to the order in which each entry's element contributions are
/// summed (the multigrid path uses it; the direct path keeps the triplet order bit for bit).
pub fn viscous_stiffness_in_pattern<const D: usize>(
    mesh: &Mesh<D>,
    geo: &Geometry<D>,
    dofs: &DofMap<D>,
    eta: f64,
    xi: f64,
) -> Csr {
    let (start, cells_of) = cells_of_nodes(mesh);
    let owner = dofs.owners();
    let mut k = free_pattern_with(mesh, dofs, &owner, &start, &cells_of);
    let nd = (D + 1) * D;
    // A node's free DOFs are consecutive rows with one pattern: they are formed together, so
    // that the cells around the node, their gradients and the columns' slots are read once
    // for all of them. Each entry still sums its cells in increasing order.
    let groups: Vec<usize> = (0..owner.len())
        .filter(|&r| r == 0 || owner[r].0 != owner[r - 1].0)
        .chain([owner.len()])
        .collect();
    add_by_row_groups(&mut k, &groups, |rows, add| {
        let node = owner[rows.start].0;
        let comps = &owner[rows.clone()];
        let mut ke = Vec::new();
        for (e, cell, a) in around(mesh, &start, &cells_of, node) {
            let (g, m) = (geo.grads(e), geo.measure(e));
            if cell.iter().all(|&v| dofs.frame(v).is_none()) {
                for b in 0..=D {
                    let gab = gradient_dot(&g, a, b);
                    for d in 0..D {
                        if let Slot::Free(j) = dofs.slot[D * cell[b] + d] {
                            let mut v = [0.0; D];
                            for (v, &(_, c)) in v.iter_mut().zip(comps) {
                                *v = entry_from_dot(&g, m, eta, xi, gab, (a, c), (b, d));
                            }
                            add(j, &v[..comps.len()]);
                        }
                    }
                }
                continue;
            }
            // A cell touching a rotated frame: its whole element matrix, rotated, of which
            // the node's rows are taken (the rotation mixes the node's components).
            ke.resize(nd * nd, 0.0);
            for a in 0..=D {
                for c in 0..D {
                    for b in 0..=D {
                        for d in 0..D {
                            ke[(a * D + c) * nd + b * D + d] =
                                stiffness_entry(&g, m, eta, xi, (a, c), (b, d));
                        }
                    }
                }
            }
            rotate(&mut ke, nd, cell, dofs);
            for b in 0..=D {
                for d in 0..D {
                    if let Slot::Free(j) = dofs.slot[D * cell[b] + d] {
                        let mut v = [0.0; D];
                        for (v, &(_, c)) in v.iter_mut().zip(comps) {
                            *v = ke[(a * D + c) * nd + b * D + d];
                        }
                        add(j, &v[..comps.len()]);
                    }
                }
            }
        }
    });
    k
}

/// Adds into the values of `k` (its pattern fixed) what `row(r, add)` gives for each row r:
/// `add(j, v)` adds v at (r, j). Blocks of rows are filled on the pool's threads; a row's sum
/// is formed in the order `row` adds, whatever the split.
fn add_by_rows(k: &mut Csr, row: impl Fn(usize, &mut dyn FnMut(usize, f64)) + Sync + Send) {
    let groups: Vec<usize> = (0..=k.nrows).collect();
    add_by_row_groups(k, &groups, |rows, add| {
        row(rows.start, &mut |j, v| add(j, &[v]))
    });
}

/// Most rows of a group of [`add_by_row_groups`] (a node's DOFs).
const GROUP_ROWS: usize = 8;

/// [`add_by_rows`] for groups of consecutive rows with one pattern, formed together: group g
/// is the rows `groups[g]..groups[g + 1]` (at most [`GROUP_ROWS`]), and `group(rows, add)`
/// adds with `add(j, v)` v[i] at (rows.start + i, j) for each row. Each entry's sum is formed
/// in the order `group` adds to it, whatever the split; chunks of about [`par::ROW_CHUNK`]
/// rows end at group ends.
fn add_by_row_groups(
    k: &mut Csr,
    groups: &[usize],
    group: impl Fn(Range<usize>, &mut dyn FnMut(usize, &[f64])) + Sync + Send,
) {
    let Csr {
        nrows,
        indptr,
        indices,
        values,
        ..
    } = k;
    assert!(groups.first() == Some(&0) && groups.last() == Some(nrows));
    // Chunk boundaries: the first group end at least ROW_CHUNK rows past the previous
    // boundary (for one-row groups, the multiples of ROW_CHUNK), and the last row.
    let mut rows = vec![0];
    for &g in &groups[1..] {
        if g == *nrows || g >= rows.last().expect("0 first") + par::ROW_CHUNK {
            rows.push(g);
        }
    }
    rows.dedup();
    let bounds: Vec<usize> = rows.iter().map(|&r| indptr[r]).collect();
    par::for_each_segment_mut(values, &bounds, |seg, vals| {
        let base = bounds[seg];
        let (first, end) = (rows[seg], rows[seg + 1]);
        // Each column's place in the current group's rows, over the columns this chunk
        // reaches: one store per stored entry, then one load per added column (a binary
        // search per value cost 3.5 % of a 1/32 box run).
        let reach = &indices[indptr[first]..indptr[end]];
        let lo = reach.iter().min().map_or(0, |&c| c as usize);
        let hi = reach.iter().max().map_or(0, |&c| c as usize + 1);
        let mut place = vec![u32::MAX; hi.saturating_sub(lo)];
        let g0 = groups.partition_point(|&g| g < first);
        for w in groups[g0..].windows(2).take_while(|w| w[0] < end) {
            let (r0, r1) = (w[0], w[1]);
            assert!(
                r1 - r0 <= GROUP_ROWS,
                "a group of at most {GROUP_ROWS} rows"
            );
            let cols = &indices[indptr[r0]..indptr[r0 + 1]];
            for r in r0 + 1..r1 {
                assert!(
                    &indices[indptr[r]..indptr[r + 1]] == cols,
                    "rows {r0} and {r} of a group have one pattern"
                );
            }
            for (p, &c) in cols.iter().enumerate() {
                place[c as usize - lo] = p as u32;
            }
            let mut at = [0usize; GROUP_ROWS];
            for (at, r) in at.iter_mut().zip(r0..r1) {
                *at = indptr[r] - base;
            }
            group(r0..r1, &mut |j, v| {
                // A stale place (another group's) or none fails the check.
                let p = j
                    .checked_sub(lo)
                    .and_then(|i| place.get(i))
                    .map_or(usize::MAX, |&p| p as usize);
                assert!(
                    cols.get(p).is_some_and(|&c| c as usize == j),
                    "entry ({r0}, {j}) in the pattern"
                );
                for (&at, v) in at.iter().zip(v) {
                    vals[at + p] += v;
                }
            });
        }
    });
}

/// Entry ((a, c), (b, d)) of a cell's (A ε(ψ_(b,d)), ε(ψ_(a,c))) for its barycentric
/// gradients `g` and measure `m`.
#[inline]
fn stiffness_entry<const D: usize>(
    g: &[[f64; D]],
    m: f64,
    eta: f64,
    xi: f64,
    (a, c): (usize, usize),
    (b, d): (usize, usize),
) -> f64 {
    entry_from_dot(g, m, eta, xi, gradient_dot(g, a, b), (a, c), (b, d))
}

/// ∇ψ_a · ∇ψ_b.
#[inline]
fn gradient_dot<const D: usize>(g: &[[f64; D]], a: usize, b: usize) -> f64 {
    let mut gab = g[a][0] * g[b][0];
    for k in 1..D {
        gab += g[a][k] * g[b][k];
    }
    gab
}

/// [`stiffness_entry`] with ∇ψ_a · ∇ψ_b given.
#[inline]
fn entry_from_dot<const D: usize>(
    g: &[[f64; D]],
    m: f64,
    eta: f64,
    xi: f64,
    gab: f64,
    (a, c): (usize, usize),
    (b, d): (usize, usize),
) -> f64 {
    let delta = if c == d { gab } else { 0.0 };
    m * (eta * (delta + g[a][d] * g[b][c]) + xi * g[a][c] * g[b][d])
}

/// The free-DOF pattern of a P1 vector operator: row (i, c) couples to every free DOF of the
/// nodes that share a cell with node i. Values zero.
///
/// Built from the node pattern: free DOFs are numbered interior first, then contact, each
/// class in node order with a node's components together ([`DofMap`]), so a row's columns
/// are its neighbour nodes' interior DOFs then their contact DOFs, already sorted (a sort per
/// DOF row of its cells' vertices cost 4.6 % of a 1/32 box run).
pub fn free_pattern<const D: usize>(mesh: &Mesh<D>, dofs: &DofMap<D>) -> Csr {
    let (start, cells_of) = cells_of_nodes(mesh);
    free_pattern_with(mesh, dofs, &dofs.owners(), &start, &cells_of)
}

/// [`free_pattern`] from the free DOFs' owners ([`DofMap::owners`]) and the cells of the
/// nodes ([`cells_of_nodes`]), where the caller needs them too.
fn free_pattern_with<const D: usize>(
    mesh: &Mesh<D>,
    dofs: &DofMap<D>,
    owner: &[(usize, usize)],
    start: &[usize],
    cells_of: &[usize],
) -> Csr {
    let nodes = node_pattern_with(mesh, start, cells_of);
    let n = dofs.n_free();
    let n_interior = dofs.n_interior;
    let free_of = |node: usize| {
        dofs.slot[D * node..D * (node + 1)]
            .iter()
            .filter_map(|s| match s {
                Slot::Free(f) => Some(*f as u32),
                Slot::Fixed => None,
            })
    };
    pattern_by_rows(n, |r, cols| {
        let (i, first) = (owner[r].0, cols.len());
        let around = &nodes.indices[nodes.indptr[i]..nodes.indptr[i + 1]];
        for interior in [true, false] {
            for &j in around {
                cols.extend(free_of(j as usize).filter(|&f| (f < n_interior as u32) == interior));
            }
        }
        debug_assert!(cols[first..].windows(2).all(|w| w[0] < w[1]));
    })
}

/// The square pattern (values zero) whose row r is what `row(r, cols)` appends to `cols`
/// ([`par::sorted_rows`]).
fn pattern_by_rows(n: usize, row: impl Fn(usize, &mut Vec<u32>) + Sync + Send) -> Csr {
    let (indptr, indices) = par::sorted_rows(n, row);
    Csr {
        nrows: n,
        ncols: n,
        indptr,
        values: vec![0.0; indices.len()],
        indices,
    }
}

/// The cells around `node` in cell order, from [`cells_of_nodes`]'s (start, cells_of): each
/// as (cell index, its vertices, the node's place among them).
fn around<'a, const D: usize>(
    mesh: &'a Mesh<D>,
    start: &'a [usize],
    cells_of: &'a [usize],
    node: usize,
) -> impl Iterator<Item = (usize, &'a [usize], usize)> + 'a {
    cells_of[start[node]..start[node + 1]]
        .iter()
        .map(move |&e| {
            let cell = mesh.cell(e);
            let a = cell
                .iter()
                .position(|&v| v == node)
                .expect("a node of its cell");
            (e, cell, a)
        })
}

/// The cells of each node as CSR (offsets, cell indices), in cell order.
fn cells_of_nodes<const D: usize>(mesh: &Mesh<D>) -> (Vec<usize>, Vec<usize>) {
    let nn = mesh.n_nodes();
    let mut start = vec![0usize; nn + 1];
    for cell in mesh.cells() {
        for &v in cell {
            start[v + 1] += 1;
        }
    }
    for i in 0..nn {
        start[i + 1] += start[i];
    }
    let mut fill = start.clone();
    let mut cells_of = vec![0usize; start[nn]];
    for (e, cell) in mesh.cells().enumerate() {
        for &v in cell {
            cells_of[fill[v]] = e;
            fill[v] += 1;
        }
    }
    (start, cells_of)
}

/// The pattern of a P1 scalar operator on all nodes: node i couples to every node that shares
/// a cell with it. Values zero.
pub fn node_pattern<const D: usize>(mesh: &Mesh<D>) -> Csr {
    let (start, cells_of) = cells_of_nodes(mesh);
    node_pattern_with(mesh, &start, &cells_of)
}

/// [`node_pattern`] from [`cells_of_nodes`]'s (start, cells_of).
fn node_pattern_with<const D: usize>(mesh: &Mesh<D>, start: &[usize], cells_of: &[usize]) -> Csr {
    let nn = mesh.n_nodes();
    pattern_by_rows(nn, |i, cols| {
        for &e in &cells_of[start[i]..start[i + 1]] {
            cols.extend(mesh.cell(e).iter().map(|&v| v as u32));
        }
    })
}

/// Every element contribution (free row, free column, value) of [`viscous_stiffness`], cell
/// by cell.
fn viscous_entries<const D: usize>(
    mesh: &Mesh<D>,
    geo: &Geometry<D>,
    dofs: &DofMap<D>,
    eta: f64,
    xi: f64,
    mut emit: impl FnMut(usize, usize, f64),
) {
    let nd = (D + 1) * D;
    let mut ke = vec![0.0; nd * nd];
    for (e, cell) in mesh.cells().enumerate() {
        let (g, m) = (geo.grads(e), geo.measure(e));
        let entry = |a: usize, c: usize, b: usize, d: usize| {
            stiffness_entry(&g, m, eta, xi, (a, c), (b, d))
        };
        if cell.iter().all(|&v| dofs.frame(v).is_none()) {
            for a in 0..=D {
                for c in 0..D {
                    let Slot::Free(i) = dofs.slot[D * cell[a] + c] else {
                        continue;
                    };
                    for b in 0..=D {
                        for d in 0..D {
                            let Slot::Free(j) = dofs.slot[D * cell[b] + d] else {
                                continue;
                            };
                            emit(i, j, entry(a, c, b, d));
                        }
                    }
                }
            }
            continue;
        }
        for a in 0..=D {
            for c in 0..D {
                for b in 0..=D {
                    for d in 0..D {
                        ke[(a * D + c) * nd + b * D + d] = entry(a, c, b, d);
                    }
                }
            }
        }
        rotate(&mut ke, nd, cell, dofs);
        for a in 0..=D {
            for c in 0..D {
                let Slot::Free(i) = dofs.slot[D * cell[a] + c] else {
                    continue;
                };
                for b in 0..=D {
                    for d in 0..D {
                        if let Slot::Free(j) = dofs.slot[D * cell[b] + d] {
                            emit(i, j, ke[(a * D + c) * nd + b * D + d]);
                        }
                    }
                }
            }
        }
    }
}

/// Ke ← Qᵀ Ke Q for the element matrix of `cell` (row-major, nd × nd), with Q the
/// block-diagonal map from each vertex's frame components to Cartesian ones.
fn rotate<const D: usize>(ke: &mut [f64], nd: usize, cell: &[usize], dofs: &DofMap<D>) {
    for (a, &v) in cell.iter().enumerate() {
        let Some(q) = dofs.frame(v) else { continue };
        // Rows of block a: (Q_a Ke)[r] = Σ_c q[r][c] Ke[c].
        for col in 0..nd {
            let old: [f64; D] = std::array::from_fn(|c| ke[(a * D + c) * nd + col]);
            for r in 0..D {
                ke[(a * D + r) * nd + col] = (0..D).map(|c| q[r][c] * old[c]).sum();
            }
        }
        // Columns of block a.
        for row in 0..nd {
            let old: [f64; D] = std::array::from_fn(|c| ke[row * nd + a * D + c]);
            for r in 0..D {
                ke[row * nd + a * D + r] = (0..D).map(|c| q[r][c] * old[c]).sum();
            }
        }
    }
}

/// Consistent P1 mass matrix M_ab = ∫ ψ_a ψ_b = |T| (1 + δ_ab) / ((D + 1)(D + 2)).
pub fn mass<const D: usize>(mesh: &Mesh<D>, geo: &Geometry<D>) -> Csr {
    scalar_matrix(mesh, mass_entry(geo))
}

/// P1 stiffness (Laplacian) K_ab = ∫ ∇ψ_a·∇ψ_b.
pub fn laplacian<const D: usize>(mesh: &Mesh<D>, geo: &Geometry<D>) -> Csr {
    scalar_matrix(mesh, laplacian_entry(geo))
}

/// [`mass`] assembled into the node pattern: no element triplets are held (they take
/// 24 (D + 1)² bytes per cell, 600 MB at the 1/64 box, plus as much again while bucketed).
/// Equal to [`mass`] up to the order in which each entry's element contributions are summed;
/// the multigrid path uses it, the direct path keeps the triplet order bit for bit.
pub fn mass_in_pattern<const D: usize>(mesh: &Mesh<D>, geo: &Geometry<D>) -> Csr {
    scalar_in_pattern(mesh, node_pattern(mesh), mass_entry(geo))
}

/// [`laplacian`] assembled into the pattern of `like`, a P1 scalar operator on the same mesh
/// (the mass matrix: (3.10) adds the two entrywise).
pub fn laplacian_in_pattern_of<const D: usize>(
    mesh: &Mesh<D>,
    geo: &Geometry<D>,
    like: &Csr,
) -> Csr {
    let pattern = Csr {
        nrows: like.nrows,
        ncols: like.ncols,
        indptr: like.indptr.clone(),
        indices: like.indices.clone(),
        values: vec![0.0; like.nnz()],
    };
    scalar_in_pattern(mesh, pattern, laplacian_entry(geo))
}

fn mass_entry<const D: usize>(geo: &Geometry<D>) -> impl Fn(usize, usize, usize) -> f64 + '_ {
    let denom = ((D + 1) * (D + 2)) as f64;
    move |e, a, b| geo.measure(e) / denom * if a == b { 2.0 } else { 1.0 }
}

fn laplacian_entry<const D: usize>(geo: &Geometry<D>) -> impl Fn(usize, usize, usize) -> f64 + '_ {
    move |e, a, b| {
        let g = geo.grads(e);
        let mut dot = g[a][0] * g[b][0];
        for k in 1..D {
            dot += g[a][k] * g[b][k];
        }
        geo.measure(e) * dot
    }
}

fn scalar_matrix<const D: usize>(
    mesh: &Mesh<D>,
    entry: impl Fn(usize, usize, usize) -> f64,
) -> Csr {
    let n = mesh.n_nodes();
    let mut t = Vec::with_capacity(mesh.n_cells() * (D + 1) * (D + 1));
    for (e, cell) in mesh.cells().enumerate() {
        for a in 0..=D {
            for b in 0..=D {
                t.push((cell[a], cell[b], entry(e, a, b)));
            }
        }
    }
    Csr::from_triplets(n, n, t)
}

/// Adds every element entry into `pattern` (which holds each pair of nodes sharing a cell).
fn scalar_in_pattern<const D: usize>(
    mesh: &Mesh<D>,
    mut pattern: Csr,
    entry: impl Fn(usize, usize, usize) -> f64 + Sync + Send,
) -> Csr {
    let (start, cells_of) = cells_of_nodes(mesh);
    add_by_rows(&mut pattern, |node, add| {
        for (e, cell, a) in around(mesh, &start, &cells_of, node) {
            for b in 0..=D {
                add(cell[b], entry(e, a, b));
            }
        }
    });
    pattern
}

/// a·x + b·y for two matrices with the same pattern (M/k + κK of (3.10)).
pub fn combine(a: f64, x: &Csr, b: f64, y: &Csr) -> Csr {
    assert_eq!(x.indices, y.indices, "patterns differ");
    let mut out = x.clone();
    for (o, v) in out.values.iter_mut().zip(&y.values) {
        *o = a * *o + b * v;
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::MeshPattern;

    fn meshes() -> Vec<Mesh> {
        [
            MeshPattern::Diagonal,
            MeshPattern::AntiDiagonal,
            MeshPattern::Cross,
        ]
        .into_iter()
        .map(|p| Mesh::rectangle(2.0, 1.0, 6, 3, p))
        .collect()
    }

    /// The pattern-first assembly gives the triplet assembly's matrix (same pattern, values
    /// to round-off), on a box with rotated frames on a curved-free but clamped and contact
    /// boundary and on a rectangle.
    #[test]
    fn assembly_on_threads_is_the_same_bits() {
        let mesh = Mesh::cuboid(2.0, 1.0, 1.0, 6, 3, 3);
        let geo = Geometry::new(&mesh);
        let dofs = DofMap::all_free(&mesh);
        let all = |_: ()| {
            let k = viscous_stiffness_in_pattern(&mesh, &geo, &dofs, 1.0, 0.5);
            let m = mass_in_pattern(&mesh, &geo);
            let l = laplacian_in_pattern_of(&mesh, &geo, &m);
            [k, m, l].map(|a| {
                (
                    a.indptr,
                    a.indices,
                    a.values.iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
                )
            })
        };
        let one = all(());
        assert!(
            one[0].0.len() > 4 * par::ROW_CHUNK,
            "the mesh splits into several row blocks"
        );
        for t in [2, 3] {
            assert!(
                one == crate::linalg::par::Threads::new(t).install(|| all(())),
                "{t} threads"
            );
        }
    }

    #[test]
    fn assembly_into_the_pattern_equals_the_triplet_assembly() {
        let mesh = Mesh::cuboid(2.0, 1.0, 1.0, 4, 2, 2);
        let geo = Geometry::new(&mesh);
        let dofs = DofMap::all_free(&mesh);
        let a = viscous_stiffness(&mesh, &geo, &dofs, 2.0, 2.0);
        let b = viscous_stiffness_in_pattern(&mesh, &geo, &dofs, 2.0, 2.0);
        assert_eq!((&a.indptr, &a.indices), (&b.indptr, &b.indices));
        for (x, y) in a.values.iter().zip(&b.values) {
            assert!((x - y).abs() <= 1e-14 * x.abs().max(1.0));
        }
        for m in meshes() {
            let geo = Geometry::new(&m);
            let dofs = DofMap::all_free(&m);
            let a = viscous_stiffness(&m, &geo, &dofs, 1.0, 0.5);
            let b = viscous_stiffness_in_pattern(&m, &geo, &dofs, 1.0, 0.5);
            assert_eq!(a.indices, b.indices);
        }
    }

    /// With clamped, interior and contact DOFs (contact numbered last, rotated frames on the
    /// arch's curved Γ3): the pattern built from the node pattern is the triplet assembly's,
    /// its rows sorted, and the values agree to round-off.
    #[test]
    fn the_free_pattern_with_contact_dofs_is_the_triplet_assemblys() {
        fn check<const D: usize>(preset: &str, h: Option<&str>) {
            let mut doc = crate::scene::presets::get(preset).unwrap();
            if let Some(h) = h {
                doc["mesh"]["h"] = serde_json::json!(h);
            }
            let p = crate::scene::validate(&doc).unwrap();
            let mesh = p.mesh::<D>().unwrap();
            let geo = Geometry::new(&mesh);
            let dofs = DofMap::new(&mesh, &p.boundary);
            assert!(
                dofs.n_contact() > 0 && dofs.n_free() < D * mesh.n_nodes(),
                "{preset}"
            );
            let a = viscous_stiffness(&mesh, &geo, &dofs, 1.0, 0.5);
            let b = viscous_stiffness_in_pattern(&mesh, &geo, &dofs, 1.0, 0.5);
            assert_eq!((&a.indptr, &a.indices), (&b.indptr, &b.indices), "{preset}");
            for (x, y) in a.values.iter().zip(&b.values) {
                assert!((x - y).abs() <= 1e-14 * x.abs().max(1.0), "{preset}");
            }
            if preset == "arch-on-support" {
                assert!(!dofs.frames.is_empty(), "rotated frames");
            }
        }
        check::<2>("arch-on-support", None);
        check::<2>("plate-with-hole", None);
        check::<3>("box-exp3", Some("1/4"));
        check::<3>("standing-cylinder", None);
    }

    /// The same for the scalar matrices of the damage step, on a box and the rectangles.
    #[test]
    fn scalar_matrices_into_the_pattern_equal_the_triplet_assembly() {
        fn same(a: &Csr, b: &Csr) {
            assert_eq!((&a.indptr, &a.indices), (&b.indptr, &b.indices));
            for (x, y) in a.values.iter().zip(&b.values) {
                assert!((x - y).abs() <= 1e-14 * x.abs().max(1.0), "{x} vs {y}");
            }
        }
        let cube = Mesh::cuboid(2.0, 1.0, 1.0, 4, 2, 2);
        let geo = Geometry::new(&cube);
        let m = mass_in_pattern(&cube, &geo);
        same(&mass(&cube, &geo), &m);
        same(
            &laplacian(&cube, &geo),
            &laplacian_in_pattern_of(&cube, &geo, &m),
        );
        for r in meshes() {
            let geo = Geometry::new(&r);
            let m = mass_in_pattern(&r, &geo);
            same(&mass(&r, &geo), &m);
            same(&laplacian(&r, &geo), &laplacian_in_pattern_of(&r, &geo, &m));
        }
    }

    #[test]
    fn rigid_body_modes_are_in_the_kernel() {
        for mesh in meshes() {
            let geo = Geometry::new(&mesh);
            let dofs = DofMap::all_free(&mesh);
            let k = viscous_stiffness(&mesh, &geo, &dofs, 2.0, 3.0);
            let n = dofs.n_free();
            // Translations in x and y, and the infinitesimal rotation (−y, x).
            let modes: [fn([f64; 2]) -> [f64; 2]; 3] =
                [|_| [1.0, 0.0], |_| [0.0, 1.0], |p| [-p[1], p[0]]];
            for m in modes {
                let v: Vec<f64> = mesh.nodes.iter().flat_map(|&p| m(p)).collect();
                let mut r = vec![0.0; n];
                k.mul_vec(&v, &mut r);
                let scale = k.values.iter().fold(0.0f64, |s, x| s.max(x.abs()));
                assert!(
                    r.iter().all(|x| x.abs() < 1e-12 * scale),
                    "rigid mode not in kernel"
                );
            }
        }
    }

    #[test]
    fn patch_test_linear_displacement() {
        // u = (0.1x + 0.3y, −0.2x + 0.05y): constant strain, so the interior residual vanishes
        // and the boundary residual equals ∫_∂Ω σν·ψ.  We check that the energy equals |Ω| σ:ε.
        for mesh in meshes() {
            let geo = Geometry::new(&mesh);
            let dofs = DofMap::all_free(&mesh);
            let (eta, xi) = (2.0, 3.0);
            let k = viscous_stiffness(&mesh, &geo, &dofs, eta, xi);
            let u: Vec<f64> = mesh
                .nodes
                .iter()
                .flat_map(|p| [0.1 * p[0] + 0.3 * p[1], -0.2 * p[0] + 0.05 * p[1]])
                .collect();
            let mut r = vec![0.0; u.len()];
            k.mul_vec(&u, &mut r);
            for (i, p) in mesh.nodes.iter().enumerate() {
                let interior =
                    p[0] > 1e-12 && p[0] < 2.0 - 1e-12 && p[1] > 1e-12 && p[1] < 1.0 - 1e-12;
                if interior {
                    assert!(r[2 * i].abs() < 1e-12 && r[2 * i + 1].abs() < 1e-12);
                }
            }
            let energy: f64 = u.iter().zip(&r).map(|(a, b)| a * b).sum();
            let (exx, eyy, exy) = (0.1, 0.05, 0.5 * (0.3 - 0.2));
            let tr = exx + eyy;
            let sig_eps = 2.0 * eta * (exx * exx + eyy * eyy + 2.0 * exy * exy) + xi * tr * tr;
            assert!((energy - 2.0 * sig_eps).abs() < 1e-12);
            // Each element's strain is the exact one.
            for t in 0..mesh.n_cells() {
                let e = geo.strain(&mesh, t, &u);
                assert!((e[(0, 0)] - exx).abs() < 1e-13 && (e[(0, 1)] - exy).abs() < 1e-13);
            }
        }
    }

    #[test]
    fn mass_sums_to_area_and_laplacian_kills_constants() {
        for mesh in meshes() {
            let geo = Geometry::new(&mesh);
            let m = mass(&mesh, &geo);
            assert!((m.values.iter().sum::<f64>() - 2.0).abs() < 1e-13);
            let k = laplacian(&mesh, &geo);
            let ones = vec![1.0; mesh.n_nodes()];
            let mut r = vec![0.0; mesh.n_nodes()];
            k.mul_vec(&ones, &mut r);
            assert!(r.iter().all(|x| x.abs() < 1e-12));
            // xᵀ K x = ∫|∇x|² = |Ω| for the linear function x.
            let x: Vec<f64> = mesh.nodes.iter().map(|p| p[0]).collect();
            k.mul_vec(&x, &mut r);
            let e: f64 = x.iter().zip(&r).map(|(a, b)| a * b).sum();
            assert!((e - 2.0).abs() < 1e-12);
        }
    }
}
