//! The linear triangle: areas and the constant gradients of the barycentric basis functions,
//! computed once per mesh.

use crate::laws::Tensor2;
use crate::mesh::Mesh;

/// Per-triangle data: |T| and ∇ψ_a (a = 0, 1, 2), constant on T.
#[derive(Debug, Clone)]
pub struct Geometry {
    pub area: Vec<f64>,
    pub grads: Vec<[[f64; 2]; 3]>,
}

impl Geometry {
    pub fn new(mesh: &Mesh) -> Geometry {
        let mut area = Vec::with_capacity(mesh.triangles.len());
        let mut grads = Vec::with_capacity(mesh.triangles.len());
        for tri in &mesh.triangles {
            let p = tri.map(|i| mesh.nodes[i]);
            let two_a = (p[1][0] - p[0][0]) * (p[2][1] - p[0][1])
                - (p[2][0] - p[0][0]) * (p[1][1] - p[0][1]);
            let g = |a: usize| {
                let (q, r) = (p[(a + 1) % 3], p[(a + 2) % 3]);
                [(q[1] - r[1]) / two_a, (r[0] - q[0]) / two_a]
            };
            area.push(0.5 * two_a);
            grads.push([g(0), g(1), g(2)]);
        }
        Geometry { area, grads }
    }

    /// ε(v)|_T = sym(Σ_a v_a ⊗ ∇ψ_a) of a nodal vector field v (interleaved x, y per node).
    #[inline]
    pub fn strain(&self, mesh: &Mesh, t: usize, v: &[f64]) -> Tensor2<f64> {
        let g = &self.grads[t];
        let (mut xx, mut yy, mut xy) = (0.0, 0.0, 0.0);
        for (a, &n) in mesh.triangles[t].iter().enumerate() {
            let (vx, vy) = (v[2 * n], v[2 * n + 1]);
            xx += vx * g[a][0];
            yy += vy * g[a][1];
            xy += 0.5 * (vx * g[a][1] + vy * g[a][0]);
        }
        Tensor2::new(xx, xy, xy, yy)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::problem::MeshPattern;

    #[test]
    fn gradients_reproduce_linear_functions() {
        let mesh = Mesh::rectangle(2.0, 1.0, 3, 2, MeshPattern::Cross);
        let geo = Geometry::new(&mesh);
        for (t, tri) in mesh.triangles.iter().enumerate() {
            // f = 3x − 2y + 1: Σ f(x_a) ∇ψ_a = (3, −2).
            let mut g = [0.0; 2];
            for (a, &n) in tri.iter().enumerate() {
                let f = 3.0 * mesh.nodes[n][0] - 2.0 * mesh.nodes[n][1] + 1.0;
                g[0] += f * geo.grads[t][a][0];
                g[1] += f * geo.grads[t][a][1];
            }
            assert!((g[0] - 3.0).abs() < 1e-12 && (g[1] + 2.0).abs() < 1e-12);
        }
    }
}
