//! What a step stores and reports beyond its norms: the requested fields (u, w, ζ, σ, the
//! von Mises stress, the Γ3 contact state), the initial fields of t_0, and the solvers'
//! diagnostics for the summary and the benchmarks.

use super::{history_stress, Simulation};
use crate::fem::{CellTensors, Geometry};
use crate::laws::constitutive::{viscous_stress, von_mises};
use crate::laws::Tensor;
use crate::linalg::Sparse;
use crate::mesh::locality::Numbering;
use crate::mesh::{AnyMesh, Mesh};
use crate::problem::Problem;
use crate::solve::SolveError;
use std::time::Instant;

/// Contact state at a Γ3 node.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct ContactNode {
    pub node: usize,
    /// Tangential velocity w_τ: in 2D its signed component along the node's tangent, in 3D
    /// its length |w_τ|.
    pub slip_velocity: f64,
    /// Friction traction density (the discrete friction force divided by ω_i): in 2D signed
    /// along the tangent, in 3D its length.
    pub friction_traction: f64,
    /// The bound μ(|w_τ|) the traction is compared with.
    pub bound: f64,
    pub slipping: bool,
    /// 3D only: w_τ and the friction traction density as Cartesian vectors.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub tangential_velocity: Option<[f64; 3]>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub traction: Option<[f64; 3]>,
}

/// Per-element stresses of a stored step, symmetric: (σ_xx, σ_yy, σ_xy) in 2D and
/// (σ_xx, σ_yy, σ_zz, σ_xy, σ_yz, σ_xz) in 3D (the order of VTK's symmetric tensors).
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
#[serde(untagged)]
pub enum Stress {
    Plane(Vec<[f64; 3]>),
    Solid(Vec<[f64; 6]>),
}

impl FromIterator<[f64; 3]> for Stress {
    fn from_iter<I: IntoIterator<Item = [f64; 3]>>(iter: I) -> Self {
        Stress::Plane(iter.into_iter().collect())
    }
}

impl Stress {
    /// Every component of every element, in storage order.
    pub fn values(&self) -> Box<dyn Iterator<Item = f64> + '_> {
        match self {
            Stress::Plane(s) => Box::new(s.iter().flatten().copied()),
            Stress::Solid(s) => Box::new(s.iter().flatten().copied()),
        }
    }

    /// The 6 components (xx, yy, zz, xy, yz, xz) of element e (zero out-of-plane in 2D).
    pub fn six(&self, e: usize) -> [f64; 6] {
        match self {
            Stress::Plane(s) => [s[e][0], s[e][1], 0.0, s[e][2], 0.0, 0.0],
            Stress::Solid(s) => s[e],
        }
    }

    pub fn len(&self) -> usize {
        match self {
            Stress::Plane(s) => s.len(),
            Stress::Solid(s) => s.len(),
        }
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

/// The fields of one stored step (only the requested ones are `Some`).
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct StepFields {
    pub n: usize,
    pub t: f64,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub u: Option<Vec<f64>>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub w: Option<Vec<f64>>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub zeta: Option<Vec<f64>>,
    /// Per element, see [`Stress`].
    #[serde(skip_serializing_if = "Option::is_none")]
    pub sigma: Option<Stress>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub von_mises: Option<Vec<f64>>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub contact: Option<Vec<ContactNode>>,
    /// The a posteriori cell indicators η_T ([`crate::a_posteriori`]), per element.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub estimate: Option<Vec<f64>>,
}

impl StepFields {
    /// The fields of a run on a renumbered mesh ([`Numbering`]) on the mesh it was made
    /// from: nodal fields (`dim` values per node for u and w) and cell fields permuted, Γ3
    /// nodes renamed and listed by increasing node as on that mesh.
    fn numbered_back(self, numbering: &Numbering, dim: usize) -> StepFields {
        let nodes = |v: Vec<f64>, width: usize| numbering.nodes_back(&v, width);
        let cells = |v: Vec<f64>| numbering.cells_back(&v);
        StepFields {
            u: self.u.map(|v| nodes(v, dim)),
            w: self.w.map(|v| nodes(v, dim)),
            zeta: self.zeta.map(|v| nodes(v, 1)),
            sigma: self.sigma.map(|s| match s {
                Stress::Plane(s) => Stress::Plane(numbering.cells_back(&s)),
                Stress::Solid(s) => Stress::Solid(numbering.cells_back(&s)),
            }),
            von_mises: self.von_mises.map(cells),
            contact: self.contact.map(|mut c| {
                c.iter_mut().for_each(|n| n.node = numbering.node[n.node]);
                c.sort_by_key(|n| n.node);
                c
            }),
            estimate: self.estimate.map(cells),
            ..self
        }
    }
}

impl<const D: usize> Simulation<D> {
    /// The requested fields of the step just computed, on the output mesh
    /// ([`crate::problem::Problem::any_mesh`]) (σ_n = A ε(w_n) + B_{n−1}, (3.8)).
    pub fn fields(&self) -> StepFields {
        let sel = self.problem.output.fields;
        let n = self.state.step;
        let need_sigma = sel.sigma || sel.von_mises;
        let sigma: Vec<Tensor<D>> = if need_sigma {
            let b = self.b.as_ref().expect("stress fields keep B_{n−1}");
            (0..self.mesh.n_cells())
                .map(|e| {
                    viscous_stress(
                        &self.problem.material.viscosity,
                        &self.geo.strain(&self.mesh, e, &self.w),
                    ) + b.get(e)
                })
                .collect()
        } else {
            Vec::new()
        };
        let (sigma, von_mises) = stress_fields(&self.problem, &sigma);
        let fields = StepFields {
            n,
            t: n as f64 * self.problem.k(),
            u: sel.u.then(|| self.state.u.clone()),
            w: sel.w.then(|| self.w.clone()),
            zeta: sel.zeta.then(|| self.state.zeta.clone()),
            sigma,
            von_mises,
            contact: sel.contact.then(|| self.contact_state()),
            estimate: self.estimate.as_ref().map(|e| e.cells.clone()),
        };
        match &self.numbering {
            Some(numbering) => fields.numbered_back(numbering, D),
            None => fields,
        }
    }

    /// The mesh outputs are given on ([`crate::problem::Problem::any_mesh`]): the run's
    /// mesh, or the body as given where the run renumbered it.
    pub fn output_mesh(&self) -> Mesh<D> {
        match &self.numbering {
            Some(numbering) => numbering.mesh_back(&self.mesh),
            None => (*self.mesh).clone(),
        }
    }

    /// Per-node values of the run (`width` per node) in the numbering of the output mesh.
    pub fn nodes_out(&self, v: &[f64], width: usize) -> Vec<f64> {
        match &self.numbering {
            Some(numbering) => numbering.nodes_back(v, width),
            None => v.to_vec(),
        }
    }

    /// Per-cell values of the run in the numbering of the output mesh.
    pub fn cells_out(&self, v: &[f64]) -> Vec<f64> {
        match &self.numbering {
            Some(numbering) => numbering.cells_back(v),
            None => v.to_vec(),
        }
    }

    /// Stick/slip state of every Γ3 node after the last step (in the run's numbering).
    pub fn contact_state(&self) -> Vec<ContactNode> {
        let x = self.velocity.solver.contact_velocity();
        let force = self.velocity.solver.contact_force();
        let nd = D - 1;
        self.dofs
            .contact
            .chunks(nd)
            .enumerate()
            .map(|(i, c)| {
                let (xi, fi) = (&x[nd * i..nd * (i + 1)], &force[nd * i..nd * (i + 1)]);
                let weight = c[0].weight;
                let speed = xi.iter().map(|v| v * v).sum::<f64>().sqrt();
                let mut node = ContactNode {
                    node: c[0].node,
                    slip_velocity: xi[0],
                    friction_traction: fi[0] / weight,
                    bound: self.problem.friction.mu(speed),
                    slipping: xi.iter().any(|v| *v != 0.0),
                    tangential_velocity: None,
                    traction: None,
                };
                if D == 3 {
                    // Cartesian vectors from the tangent directions of the node's DOFs.
                    let cartesian = |v: &[f64]| -> [f64; 3] {
                        let mut out = [0.0; 3];
                        for (cd, &vi) in c.iter().zip(v) {
                            let t = self.dofs.direction(cd);
                            (0..D).for_each(|k| out[k] += vi * t[k]);
                        }
                        out
                    };
                    let f: Vec<f64> = fi.iter().map(|v| v / weight).collect();
                    node.slip_velocity = speed;
                    node.friction_traction = f.iter().map(|v| v * v).sum::<f64>().sqrt();
                    node.tangential_velocity = Some(cartesian(xi));
                    node.traction = Some(cartesian(&f));
                }
                node
            })
            .collect()
    }

    /// "direct (Cholesky)" or "multigrid (smoothed aggregation, 4 levels)": how the
    /// velocity (and damage) systems are solved.
    pub fn linear_solver(&self) -> String {
        self.velocity.solver.linear_solver().describe()
    }

    /// |ζ|_{L²} = (ζᵀ M ζ)^½ with the run's mass matrix M (n_nodes long).
    pub fn zeta_l2(&self, zeta: &[f64]) -> f64 {
        let mut scratch = vec![0.0; zeta.len()];
        crate::fem::norms::mass_norm(&self.mass, zeta, &mut scratch)
    }

    /// The velocity hierarchy's operator complexity (multigrid path only).
    pub fn operator_complexity(&self) -> Option<f64> {
        let solver = self.velocity.solver.linear_solver();
        solver.hierarchy().map(|h| h.operator_complexity())
    }

    /// Krylov iterations of the last step's velocity and damage solves.
    pub fn krylov_iterations(&self) -> (usize, usize) {
        (
            self.velocity.solver.krylov_iterations(),
            self.damage
                .as_ref()
                .map_or(0, |d| d.solver.krylov_iterations()),
        )
    }

    /// Dimension and factor size of the velocity system (interior DOFs).
    pub fn velocity_factor_size(&self) -> (usize, usize) {
        self.velocity.solver.factor_size()
    }

    /// How a slipping velocity step is (or was) solved.
    pub fn slip_solver(&self) -> crate::solve::velocity::ContactSolver {
        self.velocity.solver.slip_solver()
    }

    /// How the velocity step forms its Schur complement onto Γ3.
    pub fn schur_path(&self) -> crate::linalg::SchurPath {
        match self.slip_solver() {
            crate::solve::velocity::ContactSolver::DenseSchur(path) => path,
            _ => crate::linalg::SchurPath::default(),
        }
    }

    /// The free-DOF velocity operator K (interior DOFs first) and the number of interior
    /// DOFs (for benchmarks of its factorisation).
    pub fn velocity_operator(&self) -> (&Sparse, usize) {
        self.velocity.solver.operator()
    }

    /// One forward+backward substitution with the velocity factor on a copy of the current
    /// load (the unit of the benchmark's per-step ratio).
    pub fn time_one_substitution(&mut self) -> f64 {
        let mut v = self.velocity.load_free[..self.dofs.n_interior].to_vec();
        let start = Instant::now();
        self.velocity.solver.substitute(&mut v);
        start.elapsed().as_secs_f64()
    }

    /// `count` products with the free-DOF velocity operator K on the current load, each timed
    /// alone into one output buffer written once before (so no page faults are timed): the
    /// unit of the benchmark's matvec-equivalents.
    pub fn time_products(&self, count: usize) -> Vec<f64> {
        let (k, _) = self.velocity.solver.operator();
        let x = &self.velocity.load_free;
        let mut y = vec![0.0; k.nrows()];
        k.mul_vec(x, &mut y);
        (0..count)
            .map(|_| {
                let start = Instant::now();
                k.mul_vec(x, &mut y);
                let secs = start.elapsed().as_secs_f64();
                std::hint::black_box(&y);
                secs
            })
            .collect()
    }

    /// Damage refactorisations so far (0 without damage).
    pub fn damage_refactorizations(&self) -> usize {
        self.damage
            .as_ref()
            .map_or(0, |d| d.solver.refactorizations())
    }
}

/// The initial state (t_0 = 0) as the fields of step 0, for output: the requested ones of
/// u_0 and ζ_0 (the nodal interpolants the run starts from, (3.11)), w_0 = 0 (the velocity
/// before the first step; the scheme never uses it) and σ_0 = A ε(w_0) + B(ε(u_0), ζ̄_0) =
/// B_0, the history stress the first step reads ((3.8) with w_0 = 0), with its von Mises
/// stress. There is no contact state before the first step: `contact` is `None` even when
/// requested. Needs no factorisation: cheap enough to derive on request.
pub fn initial_fields<const D: usize>(
    problem: &Problem,
    mesh: &Mesh<D>,
) -> Result<StepFields, SolveError> {
    let (u, zeta) = super::setup::initial_values(problem, mesh);
    super::setup::check_initial(problem, mesh, &u, &zeta)?;
    let sel = problem.output.fields;
    let (sigma, von_mises) = if sel.sigma || sel.von_mises {
        let nt = mesh.n_cells();
        let mut b = CellTensors::zeros(nt);
        history_stress(problem, mesh, &Geometry::new(mesh), &u, &zeta, Some(&mut b));
        let b: Vec<Tensor<D>> = (0..nt).map(|e| b.get(e)).collect();
        stress_fields(problem, &b)
    } else {
        (None, None)
    };
    Ok(StepFields {
        n: 0,
        t: 0.0,
        w: sel.w.then(|| vec![0.0; u.len()]),
        u: sel.u.then_some(u),
        zeta: sel.zeta.then_some(zeta),
        sigma,
        von_mises,
        contact: None,
        estimate: None,
    })
}

/// [`initial_fields`] on a mesh of either dimension.
pub fn initial_fields_of(problem: &Problem, mesh: &AnyMesh) -> Result<StepFields, SolveError> {
    match mesh {
        AnyMesh::Plane(m) => initial_fields(problem, m),
        AnyMesh::Solid(m) => initial_fields(problem, m),
    }
}

/// The requested `sigma` ([`Stress`]) and `von_mises` of per-element stresses.
fn stress_fields<const D: usize>(
    problem: &Problem,
    sigma: &[Tensor<D>],
) -> (Option<Stress>, Option<Vec<f64>>) {
    let sel = problem.output.fields;
    (
        sel.sigma.then(|| match D {
            2 => Stress::Plane(
                sigma
                    .iter()
                    .map(|s| [s[(0, 0)], s[(1, 1)], s[(0, 1)]])
                    .collect(),
            ),
            _ => Stress::Solid(
                sigma
                    .iter()
                    .map(|s| {
                        [
                            s[(0, 0)],
                            s[(1, 1)],
                            s[(2, 2)],
                            s[(0, 1)],
                            s[(1, 2)],
                            s[(0, 2)],
                        ]
                    })
                    .collect(),
            ),
        }),
        sel.von_mises.then(|| sigma.iter().map(von_mises).collect()),
    )
}
