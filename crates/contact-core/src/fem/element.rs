//! The linear simplex (triangle in 2D, tetrahedron in 3D): measures and the constant
//! gradients of the barycentric basis functions, computed once per mesh.

#![allow(clippy::needless_range_loop)] // Index loops over vertices and components spell out the formulas.

use nalgebra::SMatrix;

use crate::mesh::cuboid::KUHN_PATHS;
use crate::mesh::Mesh;

/// Tetrahedra of a generated box's cube.
const KUHN: usize = KUHN_PATHS.len();

/// Per-cell data: |T| and ∇ψ_a (a = 0..=D), constant on T.
///
/// A generated box ([`Mesh::cuboid`]: its `lattice` set) is made of congruent cubes, each
/// split into the same [`KUHN_PATHS`] tetrahedra in the same order, so cell e has the
/// measure and gradients of cell e mod 6 of the first cube: those six are stored, not one
/// set per cell (80 bytes a cell, 31.5 MB of box-exp3 at 1/32). With the box's
/// coordinates i·l/n the cubes' edge vectors are the same bits wherever l/n is a power of
/// two (box-exp3 at 1/h = 2^m); elsewhere they differ from cube to cube by rounding, which
/// the stored six do not carry.
#[derive(Debug, Clone)]
pub struct Geometry<const D: usize = 2> {
    /// |T| (area or volume; positive whatever the cell's orientation), per cell or per Kuhn
    /// tetrahedron.
    measure: Vec<f64>,
    /// [`Geometry::STORED`] gradients per cell (or per Kuhn tetrahedron), flat (see
    /// [`Geometry::grads`]).
    grads: Vec<[f64; D]>,
    /// The cells are a generated box's: cell e reads slot e mod 6.
    kuhn: bool,
    n_cells: usize,
}

impl<const D: usize> Geometry<D> {
    /// Gradients stored per cell: ∇ψ_1..∇ψ_3 of a tetrahedron (the rows of J⁻¹), whose
    /// ∇ψ_0 = −Σ_a ∇ψ_a is formed again on reading, by the subtractions [`simplex`] makes,
    /// so the same bits (72 bytes a cell instead of 96: 10.6 MB of the 441k-cell part); all
    /// three of a triangle, each of which has its own formula.
    const STORED: usize = if D == 3 { 3 } else { D + 1 };
    /// The first gradient stored: ∇ψ_1 in 3D, ∇ψ_0 in 2D.
    const FIRST: usize = D + 1 - Self::STORED;

    pub fn new(mesh: &Mesh<D>) -> Geometry<D> {
        let n_cells = mesh.n_cells();
        let kuhn = D == 3
            && mesh.lattice.is_some()
            && n_cells.is_multiple_of(KUHN)
            && congruent_cubes(mesh);
        let slots = if kuhn { KUHN } else { n_cells };
        let mut measure = Vec::with_capacity(slots);
        let mut grads = Vec::with_capacity(slots * Self::STORED);
        for cell in mesh.cells().take(slots) {
            let (m, g) = simplex(cell, &mesh.nodes);
            measure.push(m);
            grads.extend_from_slice(&g[Self::FIRST..=D]);
        }
        Geometry {
            measure,
            grads,
            kuhn,
            n_cells,
        }
    }

    /// Where cell e's data are stored.
    #[inline]
    fn slot(&self, e: usize) -> usize {
        debug_assert!(e < self.n_cells);
        if self.kuhn {
            e % KUHN
        } else {
            e
        }
    }

    /// |T| of cell e.
    #[inline]
    pub fn measure(&self, e: usize) -> f64 {
        self.measure[self.slot(e)]
    }

    /// |T| of every cell, in cell order.
    pub fn measures(&self) -> impl ExactSizeIterator<Item = f64> + '_ {
        (0..self.n_cells).map(|e| self.measure(e))
    }

    /// ∇ψ_a (a = 0..=D) on cell e; entries past D are unused.
    #[inline]
    pub fn grads(&self, e: usize) -> [[f64; D]; 4] {
        let e = self.slot(e);
        let mut g = [[0.0; D]; 4];
        g[Self::FIRST..=D].copy_from_slice(&self.grads[Self::STORED * e..Self::STORED * (e + 1)]);
        if Self::FIRST == 1 {
            for a in 1..=D {
                for c in 0..D {
                    g[0][c] -= g[a][c];
                }
            }
        }
        g
    }

    /// ∇ψ_a on cell e alone.
    #[inline]
    pub fn grad(&self, e: usize, a: usize) -> [f64; D] {
        match a >= Self::FIRST {
            true => self.grads[Self::STORED * self.slot(e) + a - Self::FIRST],
            false => self.grads(e)[a],
        }
    }

    /// ε(v)|_T = sym(Σ_a v_a ⊗ ∇ψ_a) of a nodal vector field v (D components per node,
    /// interleaved).
    #[inline]
    pub fn strain(&self, mesh: &Mesh<D>, t: usize, v: &[f64]) -> SMatrix<f64, D, D> {
        let [e] = self.strains(mesh, t, [v]);
        e
    }

    /// [`Geometry::strain`] of several fields on cell t, the gradients read once: each the
    /// same bits as alone.
    #[inline]
    pub fn strains<const N: usize>(
        &self,
        mesh: &Mesh<D>,
        t: usize,
        vs: [&[f64]; N],
    ) -> [SMatrix<f64, D, D>; N] {
        let g = self.grads(t);
        let mut es = [SMatrix::<f64, D, D>::zeros(); N];
        for (a, &n) in mesh.cell(t).iter().enumerate() {
            for (e, v) in es.iter_mut().zip(vs) {
                let va = &v[D * n..D * n + D];
                for i in 0..D {
                    e[(i, i)] += va[i] * g[a][i];
                    for j in i + 1..D {
                        e[(i, j)] += 0.5 * (va[i] * g[a][j] + va[j] * g[a][i]);
                    }
                }
            }
        }
        for e in &mut es {
            for i in 0..D {
                for j in i + 1..D {
                    e[(j, i)] = e[(i, j)];
                }
            }
        }
        es
    }
}

/// Every cell of a generated box has its first cube's cell's measure and gradients to
/// 1e-12 relative: what [`Geometry::new`] checks before it stores six, since a box's nodes
/// can be moved after it is made (`Mesh::nodes` is public) without its `lattice` going.
fn congruent_cubes<const D: usize>(mesh: &Mesh<D>) -> bool {
    let first: Vec<_> = (0..KUHN)
        .map(|e| simplex(mesh.cell(e), &mesh.nodes))
        .collect();
    mesh.cells().enumerate().all(|(e, cell)| {
        let (m0, g0) = &first[e % KUHN];
        let (m, g) = simplex(cell, &mesh.nodes);
        let scale = g0[..=D]
            .iter()
            .flatten()
            .fold(0.0f64, |s, v| s.max(v.abs()));
        (m - m0).abs() <= 1e-12 * m0
            && g[..=D]
                .iter()
                .flatten()
                .zip(g0[..=D].iter().flatten())
                .all(|(a, b)| (a - b).abs() <= 1e-12 * scale)
    })
}

/// |T| and the gradients of the barycentric functions of one simplex (entries past D unused).
fn simplex<const D: usize>(cell: &[usize], nodes: &[[f64; D]]) -> (f64, [[f64; D]; 4]) {
    let mut g = [[0.0; D]; 4];
    match D {
        2 => {
            let p = [nodes[cell[0]], nodes[cell[1]], nodes[cell[2]]];
            let two_a = (p[1][0] - p[0][0]) * (p[2][1] - p[0][1])
                - (p[2][0] - p[0][0]) * (p[1][1] - p[0][1]);
            for (a, ga) in g.iter_mut().take(3).enumerate() {
                let (q, r) = (p[(a + 1) % 3], p[(a + 2) % 3]);
                ga[0] = (q[1] - r[1]) / two_a;
                ga[1] = (r[0] - q[0]) / two_a;
            }
            (0.5 * two_a.abs(), g)
        }
        _ => {
            // J's columns are x_a − x_0; the rows of J⁻¹ are ∇ψ_1..∇ψ_3 and ∇ψ_0 = −Σ ∇ψ_a.
            let j: [[f64; 3]; 3] = std::array::from_fn(|r| {
                std::array::from_fn(|c| nodes[cell[c + 1]][r] - nodes[cell[0]][r])
            });
            let cof = |r: usize, c: usize| {
                let (r1, r2, c1, c2) = ((r + 1) % 3, (r + 2) % 3, (c + 1) % 3, (c + 2) % 3);
                j[r1][c1] * j[r2][c2] - j[r1][c2] * j[r2][c1]
            };
            let det = j[0][0] * cof(0, 0) + j[0][1] * cof(0, 1) + j[0][2] * cof(0, 2);
            for a in 1..=3 {
                for c in 0..3 {
                    // (J⁻¹)[a−1][c] = cof(c, a−1) / det.
                    let v = cof(c, a - 1) / det;
                    g[a][c] = v;
                    g[0][c] -= v;
                }
            }
            (det.abs() / 6.0, g)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::MeshPattern;

    #[test]
    fn gradients_reproduce_linear_functions() {
        let mesh = Mesh::rectangle(2.0, 1.0, 3, 2, MeshPattern::Cross);
        let geo = Geometry::new(&mesh);
        for (t, tri) in mesh.triangles().iter().enumerate() {
            // f = 3x − 2y + 1: Σ f(x_a) ∇ψ_a = (3, −2).
            let mut g = [0.0; 2];
            for (a, &n) in tri.iter().enumerate() {
                let f = 3.0 * mesh.nodes[n][0] - 2.0 * mesh.nodes[n][1] + 1.0;
                g[0] += f * geo.grads(t)[a][0];
                g[1] += f * geo.grads(t)[a][1];
            }
            assert!((g[0] - 3.0).abs() < 1e-12 && (g[1] + 2.0).abs() < 1e-12);
        }
    }

    #[test]
    fn tetrahedron_gradients_and_volume() {
        // A skewed tetrahedron, either orientation: f = x − 2y + 3z has gradient (1, −2, 3).
        let nodes = vec![
            [0.1, 0.0, 0.2],
            [1.0, 0.1, 0.0],
            [0.2, 0.9, 0.1],
            [0.3, 0.2, 1.1],
        ];
        for cells in [vec![0, 1, 2, 3], vec![0, 2, 1, 3]] {
            let mesh = Mesh::<3>::from_cells(nodes.clone(), cells).unwrap();
            let geo = Geometry::new(&mesh);
            let v = crate::mesh::signed_measure(&nodes);
            assert!((geo.measure(0) - v.abs()).abs() < 1e-15);
            let mut g = [0.0; 3];
            for (a, &n) in mesh.cell(0).iter().enumerate() {
                let p = nodes[n];
                let f = p[0] - 2.0 * p[1] + 3.0 * p[2];
                (0..3).for_each(|c| g[c] += f * geo.grads(0)[a][c]);
            }
            assert!(
                (g[0] - 1.0).abs() < 1e-12
                    && (g[1] + 2.0).abs() < 1e-12
                    && (g[2] - 3.0).abs() < 1e-12
            );
        }
    }

    /// The gradients read back are those of `simplex` to the bit, the one it leaves out in
    /// 3D included, each alone as among the others, on a mesh of skewed cells of both
    /// orientations.
    fn read_back_as_computed<const D: usize>(mesh: &Mesh<D>) {
        let geo = Geometry::new(mesh);
        for (e, cell) in mesh.cells().enumerate() {
            let (m, g) = simplex(cell, &mesh.nodes);
            let got = geo.grads(e);
            assert_eq!(geo.measure(e).to_bits(), m.to_bits());
            for a in 0..=D {
                for c in 0..D {
                    assert_eq!(got[a][c].to_bits(), g[a][c].to_bits(), "cell {e}, ∇ψ_{a}");
                    assert_eq!(geo.grad(e, a)[c].to_bits(), g[a][c].to_bits());
                }
            }
        }
    }

    #[test]
    fn gradients_read_back_bit_for_bit_in_2d_and_3d() {
        let skew = |p: [f64; 3]| {
            [
                p[0] + 0.3 * p[1] * p[1],
                p[1] + 0.1 * p[2],
                p[2] + 0.2 * p[0] * p[1],
            ]
        };
        let mut solid = Mesh::<3>::cuboid(1.0, 0.7, 0.5, 3, 2, 2);
        solid.nodes.iter_mut().for_each(|p| *p = skew(*p));
        let mut cells = solid.cells_flat().to_vec();
        cells
            .chunks_exact_mut(4)
            .step_by(2)
            .for_each(|c| c.swap(1, 2));
        let solid = Mesh::<3>::from_cells(solid.nodes.clone(), cells).unwrap();
        read_back_as_computed(&solid);
        let mut plane = Mesh::rectangle(2.0, 1.0, 3, 2, MeshPattern::Cross);
        plane
            .nodes
            .iter_mut()
            .for_each(|p| p[0] += 0.2 * p[1] * p[1]);
        read_back_as_computed(&plane);
    }

    /// A generated box stores six cells' geometry: on a box whose cube edges are the same
    /// bits everywhere (lengths over cell counts by powers of two) every cell reads what
    /// `simplex` computes for it; on one whose coordinates round differently from cube to
    /// cube, within rounding of it; the measures add up to the volume either way.
    #[test]
    fn a_generated_box_reads_its_six_cells_geometry_for_every_cell() {
        let dyadic = Mesh::cuboid(2.0, 1.0, 1.0, 8, 4, 4);
        assert!(dyadic.lattice.is_some());
        read_back_as_computed(&dyadic);
        let rounded = Mesh::cuboid(1.0, 0.7, 0.3, 3, 5, 7);
        let geo = Geometry::new(&rounded);
        assert_eq!(geo.measure.len(), 6);
        for (e, cell) in rounded.cells().enumerate() {
            let (m, g) = simplex(cell, &rounded.nodes);
            assert!((geo.measure(e) - m).abs() <= 1e-14 * m, "cell {e}");
            let got = geo.grads(e);
            for a in 0..=3 {
                for c in 0..3 {
                    assert!((got[a][c] - g[a][c]).abs() <= 1e-13 * (1.0 + g[a][c].abs()));
                }
            }
        }
        let volume: f64 = geo.measures().sum();
        assert_eq!(geo.measures().len(), rounded.n_cells());
        assert!((volume - 0.21).abs() < 1e-14, "{volume}");
        // A box whose nodes were moved keeps its lattice but not its congruent cubes: its
        // geometry is stored per cell.
        let mut moved = Mesh::cuboid(2.0, 1.0, 1.0, 4, 2, 2);
        moved
            .nodes
            .iter_mut()
            .for_each(|p| p[2] += 0.1 * p[0] * p[0]);
        assert!(moved.lattice.is_some());
        assert_eq!(Geometry::new(&moved).measure.len(), moved.n_cells());
        read_back_as_computed(&moved);
    }
}
