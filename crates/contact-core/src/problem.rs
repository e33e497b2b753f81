//! The validated, typed problem: what the numerics consumes.
//!
//! A scene (user JSON) is turned into a [`Problem`] by [`crate::scene::validate`]; every
//! value here has already been checked (positive moduli, boundary segments on the rectangle,
//! non-overlapping parts, ...), so the numerics never re-validates. Units are whatever the user's are, consistently (the paper's data is
//! dimensionless).

use std::sync::Arc;

use crate::expr::Expr;
pub use crate::mesh::support::Support;
use crate::mesh::support::TagError;
use crate::mesh::Mesh;
pub use crate::mesh::{MeshPattern, Segment};

/// A scalar datum f(x, y, t): a constant or a user formula parsed once.
#[derive(Debug, Clone)]
pub enum ScalarField {
    Const(f64),
    Expr(Expr),
}

impl ScalarField {
    /// Value at the point (x, y) and time t.
    #[inline]
    pub fn eval(&self, x: f64, y: f64, t: f64) -> f64 {
        match self {
            ScalarField::Const(c) => *c,
            ScalarField::Expr(e) => e.eval(x, y, t),
        }
    }

    /// True when the value does not depend on x or y (load vectors then integrate exactly).
    pub fn is_constant_in_space(&self) -> bool {
        match self {
            ScalarField::Const(_) => true,
            ScalarField::Expr(e) => !e.uses_x() && !e.uses_y(),
        }
    }

    pub fn is_zero(&self) -> bool {
        matches!(self, ScalarField::Const(c) if *c == 0.0)
    }
}

/// A vector datum (f_x, f_y)(x, y, t).
#[derive(Debug, Clone)]
pub struct VectorField(pub [ScalarField; 2]);

impl VectorField {
    pub fn constant(v: [f64; 2]) -> Self {
        VectorField([ScalarField::Const(v[0]), ScalarField::Const(v[1])])
    }

    #[inline]
    pub fn eval(&self, x: f64, y: f64, t: f64) -> [f64; 2] {
        [self.0[0].eval(x, y, t), self.0[1].eval(x, y, t)]
    }

    pub fn is_zero(&self) -> bool {
        self.0[0].is_zero() && self.0[1].is_zero()
    }

    pub fn is_constant_in_space(&self) -> bool {
        self.0[0].is_constant_in_space() && self.0[1].is_constant_in_space()
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
}

impl OutputSpec {
    /// Is step n (1..=steps) stored?
    pub fn stores(&self, n: usize, steps: usize) -> bool {
        (self.every > 0 && n.is_multiple_of(self.every)) || (self.last && n == steps)
    }
}

/// A fully validated problem (Problem 3.1 of the paper plus discretisation choices).
#[derive(Debug, Clone)]
pub struct Problem {
    pub name: String,
    /// The body when it is not a rectangle: a given mesh. None: the rectangle below.
    pub body: Option<Arc<Body>>,
    /// Rectangle [0, width] × [0, height] (for a [`Body`], its bounding box's extents).
    pub width: f64,
    pub height: f64,
    /// n = round(1/h) cells per unit length; width·n and height·n are integers (checked).
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
#[derive(Debug, Clone)]
pub struct Body {
    /// Where it came from, for summaries: `mesh <id or file>` or `polygon`.
    pub source: String,
    pub base: Mesh,
    pub refine: usize,
}

impl Body {
    /// The mesh the scheme runs on: `base` after `refine` red refinements.
    pub fn mesh(&self) -> Mesh {
        (0..self.refine).fold(self.base.clone(), |m, _| m.refine())
    }

    /// Its node count, without refining: each refinement adds one node per edge.
    pub fn n_nodes(&self) -> usize {
        let (mut n, mut e, mut c) = (self.base.n_nodes(), edges(&self.base), self.base.n_cells());
        for _ in 0..self.refine {
            // A triangle's red refinement: every edge splits in two, each cell adds 3 edges.
            n += e;
            e = 2 * e + 3 * c;
            c *= 4;
        }
        n
    }
}

/// Edges of a triangulation from Euler's formula: E = (3C + B)/2 with B boundary edges.
fn edges(m: &Mesh) -> usize {
    (3 * m.n_cells() + m.facets.len()) / 2
}

impl Problem {
    /// The mesh the scheme runs on, boundary facets tagged. Validation has tagged the same
    /// mesh already (except rectangles too large to mesh during validation), so an error here
    /// is a part that selects no facet, or a facet two parts select, on such a rectangle.
    pub fn mesh(&self) -> Result<Mesh, TagError> {
        match &self.body {
            Some(b) => Ok(b.mesh()),
            None => {
                let (nx, ny) = self.cells();
                let mut mesh = Mesh::rectangle(self.width, self.height, nx, ny, self.pattern);
                let supports: Vec<_> = self.boundary.iter().map(|p| p.support.clone()).collect();
                mesh.tag_boundary(&supports)?;
                Ok(mesh)
            }
        }
    }

    /// Nodes of [`Problem::mesh`], without building it.
    pub fn n_nodes(&self) -> usize {
        match &self.body {
            Some(b) => b.n_nodes(),
            None => {
                let (nx, ny) = self.cells();
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

    /// Cells along x and along y.
    pub fn cells(&self) -> (usize, usize) {
        let n = self.cells_per_unit as f64;
        (
            (self.width * n).round() as usize,
            (self.height * n).round() as usize,
        )
    }
}
