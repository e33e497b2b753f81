//! The validated, typed problem: what the numerics consumes.
//!
//! A scene (user JSON) is turned into a [`Problem`] by [`crate::scene::validate`]; every
//! value here has already been checked (positive moduli, boundary segments on the rectangle,
//! non-overlapping parts, ...), so the numerics never re-validates. Units are whatever the user's are, consistently (the paper's data is
//! dimensionless).

use std::sync::Arc;

use crate::expr::Expr;
use crate::mesh::locality::Numbering;
pub use crate::mesh::support::Support;
use crate::mesh::support::TagError;
use crate::mesh::{AnyMesh, Mesh, SharedMesh};
pub use crate::mesh::{MeshPattern, Segment};

/// A scalar datum f(x, y, z, t): a constant or a user formula parsed once (z = 0 in 2D).
#[derive(Debug, Clone)]
pub enum ScalarField {
    Const(f64),
    Expr(Expr),
}

impl ScalarField {
    /// Value at the point (x, y) (z = 0) and time t.
    #[inline]
    pub fn eval(&self, x: f64, y: f64, t: f64) -> f64 {
        match self {
            ScalarField::Const(c) => *c,
            ScalarField::Expr(e) => e.eval(x, y, t),
        }
    }

    /// Value at the point p of R^D (D = 2 or 3) and time t.
    #[inline]
    pub fn at<const D: usize>(&self, p: &[f64; D], t: f64) -> f64 {
        match self {
            ScalarField::Const(c) => *c,
            ScalarField::Expr(e) if D == 2 => e.eval(p[0], p[1], t),
            ScalarField::Expr(e) => e.eval3(p[0], p[1], p[D - 1], t),
        }
    }

    /// True when the value does not depend on x, y or z (load vectors then integrate exactly).
    pub fn is_constant_in_space(&self) -> bool {
        match self {
            ScalarField::Const(_) => true,
            ScalarField::Expr(e) => !e.uses_x() && !e.uses_y() && !e.uses_z(),
        }
    }

    pub fn is_zero(&self) -> bool {
        matches!(self, ScalarField::Const(c) if *c == 0.0)
    }
}

/// A vector datum (f_x, f_y, f_z)(x, y, z, t); in 2D only the first two components are read
/// (the third is the constant 0).
#[derive(Debug, Clone)]
pub struct VectorField(pub [ScalarField; 3]);

impl VectorField {
    /// The constant plane vector (v_x, v_y, 0).
    pub fn constant(v: [f64; 2]) -> Self {
        VectorField::constant3([v[0], v[1], 0.0])
    }

    pub fn constant3(v: [f64; 3]) -> Self {
        VectorField(v.map(ScalarField::Const))
    }

    /// A plane vector field (f_x, f_y, 0).
    pub fn plane(x: ScalarField, y: ScalarField) -> Self {
        VectorField([x, y, ScalarField::Const(0.0)])
    }

    #[inline]
    pub fn eval(&self, x: f64, y: f64, t: f64) -> [f64; 2] {
        [self.0[0].eval(x, y, t), self.0[1].eval(x, y, t)]
    }

    /// Its first D components at the point p of R^D and time t.
    #[inline]
    pub fn at<const D: usize>(&self, p: &[f64; D], t: f64) -> [f64; D] {
        std::array::from_fn(|c| self.0[c].at(p, t))
    }

    pub fn is_zero(&self) -> bool {
        self.0.iter().all(ScalarField::is_zero)
    }

    pub fn is_constant_in_space(&self) -> bool {
        self.0.iter().all(ScalarField::is_constant_in_space)
    }
}

/// What a boundary part imposes.
#[derive(Debug, Clone)]
pub enum BoundaryKind {
    /// Γ1: u = 0 (hence w = 0).
    Clamped,
    /// Γ2: σν = f2.
    Traction(VectorField),
    /// Γ3: bilateral contact u_ν = 0 with friction −σ_τ ∈ ∂j(w_τ) (law in [`Problem::friction`]).
    Contact,
}

#[derive(Debug, Clone)]
pub struct BoundaryPart {
    pub kind: BoundaryKind,
    /// Which boundary facets the part holds.
    pub support: Support,
}

/// Viscosity operator A(τ) = 2η τ + ξ tr(τ) I of (4.1).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Viscosity {
    pub eta: f64,
    pub xi: f64,
}

/// Elasticity operator B(ε, ζ).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Elasticity {
    /// (4.1): B(ε, ζ) = ζ (2μ ε + λ tr(ε) I).
    Linear { mu: f64, lambda: f64 },
    /// (2.15–2.16): B(ε, ζ) = η_B (ε − P_K(ζ) ε), K(ζ) = {τ : |τ^D| ≤ ζ σ_Y}.
    VonMises { eta_b: f64, sigma_y: f64 },
}

#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Material {
    pub viscosity: Viscosity,
    pub elasticity: Elasticity,
}

/// The friction potential j(ξ) = ∫_0^|ξ| μ(r) dr on Γ3, given by its bound μ(r) ≥ 0.
#[derive(Debug, Clone, PartialEq)]
pub enum FrictionLaw {
    /// μ(r) = g (the paper's j(ξ) = 20|ξ| has g = 20). Convex.
    Tresca { g: f64 },
    /// μ(r) = μ1 + (μ0 − μ1) e^(−α r). Non-convex when μ0 > μ1.
    SlipWeakening { mu0: f64, mu1: f64, alpha: f64 },
    /// μ(r) linear between the table points (r_i, μ_i), r_0 = 0 < r_1 < ...; constant beyond
    /// the last point. Non-convex where it decreases.
    PiecewiseLinear { points: Vec<[f64; 2]> },
}

/// What to do when the smallness condition (2.31) fails for the scene.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum SmallnessPolicy {
    /// Refuse to run (the HVI may have several solutions).
    #[default]
    Refuse,
    /// Run, and report the violation in the summary.
    Warn,
}

/// Damage source φ of (4.2) with its constants as parameters:
/// φ(τ, ζ) = a (1 − ζ)/ζ − b |τ|² for ζ ≥ ζ*, and a (1 − ζ*)/ζ* − b |τ|² for ζ < ζ*.
/// The paper has a = 2, b = 20, ζ* = 0.2.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DamageSource {
    pub a: f64,
    pub b: f64,
    pub zeta_star: f64,
}

/// The damage equation (2.2): ζ̇ − κΔζ + ∂I_\[0,1\](ζ) ∋ φ(ε(u), ζ).
#[derive(Debug, Clone)]
pub struct Damage {
    pub kappa: f64,
    pub source: DamageSource,
    /// Initial damage ζ_0(x, y) (evaluated at t = 0), values in [0, 1].
    pub zeta0: ScalarField,
}

/// Which per-step fields are kept.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct FieldSet {
    pub u: bool,
    pub w: bool,
    pub zeta: bool,
    pub sigma: bool,
    pub von_mises: bool,
    pub contact: bool,
}

/// Which steps' fields are kept: every `every`-th step (0 = none), and the last one if `last`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct OutputSpec {
    pub every: usize,
    pub last: bool,
    pub fields: FieldSet,
    /// Compute the a posteriori estimate of every step ([`crate::a_posteriori`]): its parts
    /// in the step reports and the summary, its cell indicators in the stored steps.
    pub estimate: bool,
}

impl OutputSpec {
    /// Does the run keep B_{n−1} (3.8) of every cell after its step? The stress fields
    /// (σ_n = A ε(w_n) + B_{n−1}) and the a posteriori estimate read it once the state has
    /// moved to t_n; without them the step forms each cell's B_{n−1} where it is used.
    pub fn keeps_history_stress(&self) -> bool {
        self.fields.sigma || self.fields.von_mises || self.estimate
    }

    /// Is step n (1..=steps) stored?
    pub fn stores(&self, n: usize, steps: usize) -> bool {
        (self.every > 0 && n.is_multiple_of(self.every)) || (self.last && n == steps)
    }

    /// How many of the steps 1..=steps are stored ([`OutputSpec::stores`]), in O(1).
    pub fn stored_steps(&self, steps: usize) -> usize {
        let every = steps.checked_div(self.every).unwrap_or(0);
        every + usize::from(self.last && steps > 0 && !self.stores_every(steps))
    }

    /// Step n is a multiple of `every`.
    fn stores_every(&self, n: usize) -> bool {
        self.every > 0 && n.is_multiple_of(self.every)
    }
}

/// A fully validated problem (Problem 3.1 of the paper plus discretisation choices).
#[derive(Debug, Clone)]
pub struct Problem {
    pub name: String,
    /// The body when it is not a rectangle: a given mesh. None: the rectangle below.
    pub body: Option<Arc<Body>>,
    /// Rectangle [0, width] × [0, height], or with `depth` the box [0, width] × [0, height] ×
    /// [0, depth] (for a [`Body`], its bounding box's extents).
    pub width: f64,
    pub height: f64,
    /// Some: a box (d = 3); None: a rectangle, or the given body's dimension.
    pub depth: Option<f64>,
    /// n = round(1/h) cells per unit length; width·n, height·n (and depth·n) are integers
    /// (checked).
    /// Unused for a [`Body`].
    pub cells_per_unit: usize,
    pub pattern: MeshPattern,
    pub t_end: f64,
    /// N: k = t_end / N.
    pub steps: usize,
    pub boundary: Vec<BoundaryPart>,
    /// Body force f0(x, y, t).
    pub body_force: VectorField,
    pub material: Material,
    /// Friction law on Γ3 (ignored when there is no contact part).
    pub friction: FrictionLaw,
    pub smallness: SmallnessPolicy,
    /// The path of the linear solves (`solver.linear`): `Auto` is decided per job from the
    /// predicted memory.
    pub linear: LinearPath,
    /// The multigrid path's level operators in f32 or f64 (`solver.precision`).
    pub precision: Precision,
    /// None: ζ ≡ 1, no damage solve.
    pub damage: Option<Damage>,
    /// Initial displacement u_0(x, y).
    pub u0: VectorField,
    pub output: OutputSpec,
    /// Also run (2h, 2k) (and (4h, 4k)) to estimate the discretisation error
    /// ([`crate::estimate`]).
    pub error_estimate: bool,
}

/// A body given as a mesh (imported from gmsh or meshed from a polygon), its boundary
/// facets already tagged with the problem's parts, refined `refine` times before use.
///
/// The mesh is held once, renumbered for locality ([`Mesh::ordered_for_locality`]), in the
/// order every run on it computes in: an unrefined body's run shares it
/// ([`Body::mesh_and_numbering`]), and outputs are given in the file's numbering through
/// `numbering` ([`Body::output_mesh`]).
#[derive(Debug, Clone)]
pub struct Body {
    /// Where it came from, for summaries: `mesh <id or file>` or `polygon`.
    pub source: String,
    /// The mesh as given, renumbered where [`Mesh::ordered_for_locality`] renumbers it.
    pub base: Arc<AnyMesh>,
    /// How `base` relates to the mesh as given, where it was renumbered.
    pub numbering: Option<Arc<Numbering>>,
    pub refine: usize,
}

impl Body {
    /// The body of the mesh `given` (tagged), refined `refine` times before use.
    pub fn new(source: String, given: AnyMesh, refine: usize) -> Body {
        let (base, numbering) = match given {
            AnyMesh::Plane(m) => {
                let (m, n) = m.into_ordered_for_locality();
                (AnyMesh::Plane(m), n)
            }
            AnyMesh::Solid(m) => {
                let (m, n) = m.into_ordered_for_locality();
                (AnyMesh::Solid(m), n)
            }
        };
        Body {
            source,
            base: Arc::new(base),
            numbering: numbering.map(Arc::new),
            refine,
        }
    }

    /// The mesh the scheme runs on (its dimension is D; panics on the other one, a
    /// programming error since [`Problem::dim`] tells which): `base` after `refine` red
    /// refinements.
    pub fn mesh<const D: usize>(&self) -> Mesh<D> {
        (*self.mesh_and_numbering::<D>().0).clone()
    }

    /// [`Body::mesh`], shared with the body where it is not refined, and, where its
    /// numbering differs from [`Body::output_mesh`]'s (an unrefined base that was
    /// renumbered), how the two relate.
    pub fn mesh_and_numbering<const D: usize>(&self) -> (SharedMesh<D>, Option<Arc<Numbering>>) {
        match self.refine {
            0 => (SharedMesh::of(self.base.clone()), self.numbering.clone()),
            r => (SharedMesh::new(refined(self.base.get::<D>(), r)), None),
        }
    }

    /// The mesh outputs are given on: the mesh as given when it is not refined (fields in
    /// the numbering of the uploaded file), else [`Body::mesh`].
    pub fn output_mesh<const D: usize>(&self) -> Mesh<D> {
        match (self.refine, &self.numbering) {
            (0, Some(numbering)) => numbering.mesh_back(self.base.get::<D>()),
            (0, None) => self.base.get::<D>().clone(),
            _ => self.mesh(),
        }
    }

    /// Its node count, without refining: each refinement adds one node per edge. Admission
    /// and the memory prediction ask for it before any run, so the edges (a sort of the 6
    /// per tetrahedron) are counted only when there is a refinement to count them for.
    pub fn n_nodes(&self) -> usize {
        if self.refine == 0 {
            return self.base.n_nodes();
        }
        let (mut n, mut e, mut c) = (
            self.base.n_nodes(),
            self.base.n_edges(),
            self.base.n_cells(),
        );
        // 3D: faces F = (4C + B)/2, B boundary faces.
        let mut f = match &*self.base {
            AnyMesh::Plane(_) => 0,
            AnyMesh::Solid(m) => (4 * c + m.facets.len()) / 2,
        };
        for _ in 0..self.refine {
            n += e;
            match *self.base {
                // A triangle's red refinement: every edge splits in two, each cell adds 3 edges.
                AnyMesh::Plane(_) => {
                    e = 2 * e + 3 * c;
                    c *= 4;
                }
                // Bey's refinement: every edge splits in two, each face adds 3 edges and each
                // cell 1 (the octahedron's diagonal); each face splits in 4 and each cell adds
                // 8 interior faces.
                AnyMesh::Solid(_) => {
                    e = 2 * e + 3 * f + c;
                    f = 4 * f + 8 * c;
                    c *= 8;
                }
            }
        }
        n
    }
}

fn refined<const D: usize>(m: &Mesh<D>, levels: usize) -> Mesh<D> {
    (0..levels).fold(m.clone(), |m, _| m.refine())
}

impl Problem {
    /// The dimension d of the body: 2 or 3.
    pub fn dim(&self) -> usize {
        match (&self.body, self.depth) {
            (Some(b), _) => b.base.dim(),
            (None, Some(_)) => 3,
            (None, None) => 2,
        }
    }

    /// The mesh the scheme runs on, boundary facets tagged; D must be [`Problem::dim`].
    /// Validation has tagged the same mesh already (except rectangles and boxes too large to
    /// mesh during validation), so an error here is a part that selects no facet, or a facet
    /// two parts select, on such a mesh.
    pub fn mesh<const D: usize>(&self) -> Result<Mesh<D>, TagError> {
        assert_eq!(D, self.dim(), "mesh of the problem's dimension");
        match &self.body {
            Some(b) => Ok(b.mesh()),
            None => {
                let supports: Vec<_> = self.boundary.iter().map(|p| p.support.clone()).collect();
                let any: Box<dyn std::any::Any> = match self.depth {
                    None => {
                        let (nx, ny) = self.cells();
                        let mut mesh =
                            Mesh::rectangle(self.width, self.height, nx, ny, self.pattern);
                        mesh.tag_boundary(&supports)?;
                        Box::new(mesh)
                    }
                    Some(depth) => {
                        let (nx, ny) = self.cells();
                        let nz = self.depth_cells().unwrap_or(1);
                        let mut mesh = Mesh::cuboid(self.width, self.height, depth, nx, ny, nz);
                        mesh.tag_boundary(&supports)?;
                        Box::new(mesh)
                    }
                };
                Ok(*any.downcast::<Mesh<D>>().expect("dimension checked above"))
            }
        }
    }

    /// [`Problem::mesh`] and, where outputs are given on another numbering of it
    /// ([`Body::mesh_and_numbering`]), how the two relate.
    pub fn mesh_and_numbering<const D: usize>(
        &self,
    ) -> Result<(SharedMesh<D>, Option<Arc<Numbering>>), TagError> {
        match &self.body {
            Some(b) => {
                assert_eq!(D, self.dim(), "mesh of the problem's dimension");
                Ok(b.mesh_and_numbering())
            }
            None => Ok((SharedMesh::new(self.mesh()?), None)),
        }
    }

    /// The mesh outputs are given on, in whichever dimension the problem has: the mesh the
    /// scheme runs on, except that an unrefined body keeps the numbering it was given
    /// ([`Body::output_mesh`]).
    pub fn any_mesh(&self) -> Result<AnyMesh, TagError> {
        Ok(match (&self.body, self.dim()) {
            (Some(b), 2) => AnyMesh::Plane(b.output_mesh::<2>()),
            (Some(b), _) => AnyMesh::Solid(b.output_mesh::<3>()),
            (None, 2) => AnyMesh::Plane(self.mesh::<2>()?),
            (None, _) => AnyMesh::Solid(self.mesh::<3>()?),
        })
    }

    /// Nodes of [`Problem::mesh`], without building it.
    pub fn n_nodes(&self) -> usize {
        match &self.body {
            Some(b) => b.n_nodes(),
            None => {
                let (nx, ny) = self.cells();
                if let Some(nz) = self.depth_cells() {
                    return (nx + 1) * (ny + 1) * (nz + 1);
                }
                let centres = if self.pattern == MeshPattern::Cross {
                    nx * ny
                } else {
                    0
                };
                (nx + 1) * (ny + 1) + centres
            }
        }
    }

    /// Time step k = T/N.
    pub fn k(&self) -> f64 {
        self.t_end / self.steps as f64
    }

    /// Cells along z of a box (None for a rectangle or a given mesh).
    pub fn depth_cells(&self) -> Option<usize> {
        match (&self.body, self.depth) {
            (None, Some(d)) => Some((d * self.cells_per_unit as f64).round() as usize),
            _ => None,
        }
    }

    /// Cells along x and along y.
    pub fn cells(&self) -> (usize, usize) {
        let n = self.cells_per_unit as f64;
        (
            (self.width * n).round() as usize,
            (self.height * n).round() as usize,
        )
    }
}

/// The precision of the multigrid V-cycle's level operators (the scene's
/// `solver.precision`): the operators of the scheme, the residuals and conjugate gradients
/// are f64 either way ([`crate::linalg::block_csr`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Precision {
    /// Mixed for 3D bodies, where it is faster; double in 2D, where it is not.
    #[default]
    Auto,
    Double,
    Mixed,
}

impl Precision {
    pub const NAMES: &'static [&'static str] = &["auto", "double", "mixed"];

    pub fn name(self) -> &'static str {
        match self {
            Precision::Auto => "auto",
            Precision::Double => "double",
            Precision::Mixed => "mixed",
        }
    }

    pub fn parse(s: &str) -> Option<Precision> {
        match s {
            "auto" => Some(Precision::Auto),
            "double" => Some(Precision::Double),
            "mixed" => Some(Precision::Mixed),
            _ => None,
        }
    }

    /// Whether a body of dimension `dim` takes single-precision level operators.
    pub fn mixed(self, dim: usize) -> bool {
        match self {
            Precision::Auto => dim == 3,
            Precision::Double => false,
            Precision::Mixed => true,
        }
    }
}

/// Which path a job's linear systems take (the scene's `solver.linear`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum LinearPath {
    /// The faster path whose predicted memory fits the per-job limit.
    #[default]
    Auto,
    Direct,
    Multigrid,
}

impl LinearPath {
    pub const NAMES: &'static [&'static str] = &["auto", "direct", "multigrid"];

    pub fn name(self) -> &'static str {
        match self {
            LinearPath::Auto => "auto",
            LinearPath::Direct => "direct",
            LinearPath::Multigrid => "multigrid",
        }
    }

    pub fn parse(s: &str) -> Option<LinearPath> {
        match s {
            "auto" => Some(LinearPath::Auto),
            "direct" => Some(LinearPath::Direct),
            "multigrid" => Some(LinearPath::Multigrid),
            _ => None,
        }
    }
}
