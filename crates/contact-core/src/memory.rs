//! A job's peak memory, predicted before any numeric work, and the choice of the linear
//! path that fits (the scene's `solver.linear`, [`LinearPath`]).
//!
//! The prediction is made twice. [`choose`] is the cheap check at submission (the service,
//! `contact-sim run`): it needs no mesh, only the mesh's node and cell counts. When a run is
//! set up, the direct path is decided on the exact factor sizes instead
//! ([`refine`]: the symbolic analyses' [`CholeskyPlan::factor_bytes`] in place of the count
//! model's fill), made on the operators' patterns before anything is assembled; [`choose_with`]
//! decides on that figure. The run's solver backend is chosen on these figures, once, by
//! [`crate::solve::backend::choose`]. A demanded direct path is checked before the analyses only
//! against [`without_factors`], since the count model over-estimates the factors where
//! nested dissection wins (3D boxes from a few thousand unknowns on); `auto` picks its path
//! on the count model, and a direct pick that the exact figure does not fit moves to the
//! multigrid path when that fits. The multigrid path keeps the count prediction.
//!
//! What is counted: the mesh and its geometry, the assembled operators (K on the free DOFs,
//! M, L and H = M/k + κL), the per-cell and per-node state, the element triplets of the
//! direct path's assembly (the multigrid path assembles every matrix into its pattern), and
//! then
//! - the direct path: the factors of K_II and of H; the count model takes their fill from
//!   the measured growth of the AMD-ordered supernodal factor (3D: nnz(L) ≈ 1.8 n^1.58; 2D:
//!   5 n log₂ n, n the unknowns; docs/src/speed/speed.md compares it with the exact sizes);
//! - the multigrid path: the hierarchies of K_II and H (coarse operators, prolongators and
//!   their transposes, smoother blocks, a small coarse factor, and the set-up's products) as
//!   multiples of the fine operators, fitted to measured peaks of box-exp3: geometric levels
//!   (refined bodies, generated meshes with even cell counts) at 1/8–1/32, smoothed
//!   aggregation at 1/15 and 1/31 (odd cell counts) and on an imported gmsh part
//!   (`benches/part`) at 20k and 82k nodes; a refined body's levels stop at its base mesh,
//!   whose factors (K's twice with a Γ3, H's) are sized by the direct path's fill model
//!   (tests/memory_prediction.rs checks boxes and imported meshes, as given and refined).
//!
//! With a Γ3, the multigrid path also builds K's hierarchy on all free DOFs for the
//! semismooth Newton method of a slipping step (sharing K itself) with its truncated
//! preconditioner; it is counted whether or not the run slips. A slipping step on the direct
//! path holds the dense Schur complement onto Γ3 (m² values, m the tangential contact DOFs),
//! which is not counted: it depends on the Γ3 part of the boundary, known only once the mesh
//! is tagged.

use crate::fem::multilevel::FACTORED_DOFS;
use crate::linalg::projection::{SolutionSpace, CAPACITY};
use crate::linalg::{CholeskyPlan, LinearPath};
use crate::problem::Problem;

/// Predicted peak bytes of one run on each path.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Prediction {
    pub direct: u64,
    pub multigrid: u64,
}

/// Counts the prediction works from.
#[derive(Debug, Clone, Copy)]
struct Counts {
    d: f64,
    nodes: f64,
    cells: f64,
    /// Nodes coupled to a node (itself included): the rows of a nodal operator.
    stencil: f64,
    damage: bool,
    /// The multigrid path coarsens geometrically ([`crate::fem::multilevel`]): a refined
    /// body, or a generated rectangle or box with even cell counts.
    geometric: bool,
    /// The boundary has a Γ3 part.
    contact: bool,
    /// The run computes the a posteriori estimate ([`crate::a_posteriori`]).
    estimate: bool,
    /// The run keeps B_{n−1} per cell ([`crate::problem::OutputSpec::keeps_history_stress`]).
    history_stress: bool,
    /// Nodes of the coarsest geometric level when it is a given mesh (a refined body's
    /// base); 0 when the levels go down to a few cells (generated meshes).
    coarse_nodes: f64,
    /// A generated box: its geometry is six cells' ([`crate::fem::Geometry`]).
    kuhn: bool,
}

fn counts(p: &Problem) -> Counts {
    let d = p.dim();
    let nodes = p.n_nodes() as f64;
    let cells = match (&p.body, p.depth_cells()) {
        (None, Some(nz)) => {
            let (nx, ny) = p.cells();
            (6 * nx * ny * nz) as f64
        }
        (None, None) => {
            let (nx, ny) = p.cells();
            let per = if p.pattern == crate::mesh::MeshPattern::Cross {
                4
            } else {
                2
            };
            (per * nx * ny) as f64
        }
        (Some(_), _) if d == 2 => 2.0 * nodes,
        (Some(_), _) => 5.5 * nodes,
    };
    Counts {
        d: d as f64,
        nodes,
        cells,
        stencil: if d == 2 { 7.0 } else { 15.0 },
        damage: p.damage.is_some(),
        estimate: p.output.estimate,
        history_stress: p.output.keeps_history_stress(),
        coarse_nodes: match &p.body {
            Some(b) if b.refine > 0 => b.base.n_nodes() as f64,
            _ => 0.0,
        },
        kuhn: p.body.is_none() && p.depth_cells().is_some(),
        contact: p
            .boundary
            .iter()
            .any(|b| matches!(b.kind, crate::problem::BoundaryKind::Contact)),
        geometric: match (&p.body, p.depth_cells()) {
            (Some(b), _) => b.refine > 0,
            (None, Some(nz)) => {
                let (nx, ny) = p.cells();
                [nx, ny, nz].iter().all(|c| c % 2 == 0)
            }
            (None, None) => {
                let (nx, ny) = p.cells();
                p.pattern != crate::mesh::MeshPattern::Cross && nx % 2 == 0 && ny % 2 == 0
            }
        },
    }
}

/// Factor entries of an SPD operator with `n` unknowns from a mesh of dimension `d`.
fn factor_entries(d: f64, n: f64) -> f64 {
    if d == 2.0 {
        5.0 * n * n.max(2.0).log2()
    } else {
        1.8 * n.powf(1.58)
    }
}

/// The geometric hierarchies of K and H as a multiple of K's bytes (H's finest level shares
/// H's storage with the damage step): fitted to the measured peaks of box-exp3, g = 20, at
/// 1/16, 1/24 and 1/32 (`contact-sim bench --linear-solver multigrid`: 60, 184 and 410 MiB;
/// predicted 73, 217 and 493 MiB with FULL_SPACE_GEOMETRIC below) and 1/64 (3,338 MiB before
/// H was shared; 3.7 GiB predicted). Lowered from 0.8 when the binary began to map blocks
/// of 128 KiB and more for themselves (the allocator's slack left the peaks): box-exp3 at
/// 1/32, two threads, 321 MiB for 32 steps, predicted 1.18×.
const GEOMETRIC_HIERARCHY: f64 = 0.5;

/// With a Γ3 the multigrid path's hierarchy is K's on all free DOFs (K shared, K_II never
/// copied), plus the truncated cycles (K_II's, and the slipping steps') and the Newton
/// vectors, as a multiple of K's bytes beside the terms above. Counted whether or not the
/// run slips. The cycles share the finest block diagonal and keep the levels they rebuild
/// in f32 only ([`crate::linalg::multigrid::Hierarchy::shed_operators`]); fitted to
/// box-exp3 on one thread, release: 1/32 sticking (g = 20) 442 MiB, predicted 1.19×;
/// slipping (g = 2) 480 MiB, 1.07×; 1/64 sticking, two steps, 3,205 MiB, 1.23×. Since the
/// cycles widen A₁ from its f32 copy instead of holding it in f64, 0.13 less (1/32: 14.5 MB
/// of K's 115 MB; 386 MiB on two threads, predicted 1.14×).
const FULL_SPACE_GEOMETRIC: f64 = 0.22;

/// The same with smoothed aggregation: the truncated cycles' updates of the first coarse
/// operator and the levels rebuilt below it (no copy of P: its rows are masked). Fitted to
/// `benches/part` (82k nodes, one thread): 604 MiB sticking, predicted 1.15×; 661 MiB
/// slipping (g = 0.5, T = 8/32), 1.05×; with K in node blocks since, 571 MiB sticking,
/// 1.15×, and 643 MiB slipping all 32 steps, 1.02×. Since A₁ is widened from its f32 copy
/// when a cycle is made (20.5 MB of K's 123 MB on the part), 0.17 less.
const FULL_SPACE_AGGREGATION: f64 = 0.08;

/// Smoothed aggregation's hierarchy of K as a multiple of K's bytes, beside 25 vectors: with
/// the finest level aggregated on the distance-two graph the coarse operators are small; P
/// is held, Pᵀ is not (restriction by pieces), and the Galerkin product's A·P is formed a
/// piece at a time. Fitted with the full-space term (then 1.6 × K in all) to four measured
/// peaks that the prediction met within ±25 % (one thread, release): box-exp3 at 1/15 and
/// 1/31 (85 and 580 MiB, predicted 0.93× and 1.01×) and the gmsh part of `benches/part` at
/// 21k and 82k nodes (168 MiB for the whole run and 600 MiB for its first step, predicted
/// 1.15× and 1.23×); [`FULL_SPACE_AGGREGATION`] has since fallen with the cycles' copies.
/// Lowered from 1.1 when the part's run stopped holding its mesh twice and A₁ in f64 (39 MB
/// of its peak): the part, one thread, 450 MiB sticking and 536 MiB slipping (32 steps),
/// predicted 1.20× and 1.01×; its first step 1.23×. Lowered from 0.9 when the binary began
/// to map blocks of 128 KiB and more for themselves: the part, one thread, 403 MiB sticking
/// and 448 MiB slipping (T = 8/32), predicted 1.15× and 1.04×; its first step 1.20×.
const AGGREGATION_HIERARCHY: f64 = 0.45;

/// The smoothed-aggregation P of the finest level, part of [`AGGREGATION_HIERARCHY`], as a
/// multiple of K's bytes (the part of `benches/part`: 52 MB against K's 121 MB). With mixed
/// precision it is held in f32 node blocks (3D: 76 bytes per 3 × 6 block against 216 in
/// scalar CSR; [`crate::linalg::multigrid::prolongator`]), which saves this share of it.
const AGGREGATION_P: f64 = 0.43;
const P_IN_F32_BLOCKS_SAVES: f64 = 0.65;

/// Mixed precision ([`crate::problem::Precision`]) adds a single-precision block copy of every
/// level operator of K and H: f32 entries in node blocks with one index per block (3D:
/// 40 bytes per 9 entries; 2D: 24 per 4; H: 8 per entry), counted as this multiple of the
/// finest levels' copies: the coarse levels' copies are small, and the peak grew by 0.6–1.3×
/// the finest copies on box-exp3 at 1/16–1/32 and the part of `benches/part` at 23k and 82k
/// nodes (docs/src/speed/speed.md#mixed-precision-levels).
const MIXED_LEVELS: f64 = 1.0;

/// The resident size of the process before a run (code, allocator, runtime), counted on the
/// multigrid path whose small runs it dominates.
const PROCESS: f64 = 8.0 * (1u64 << 20) as f64;

/// CSR bytes of `nnz` entries (value and 32-bit index) in `rows` rows.
fn csr(nnz: f64, rows: f64) -> f64 {
    12.0 * nnz + 8.0 * rows
}

/// The terms of a prediction that do not depend on how the direct factors are sized.
struct Terms {
    /// Unknowns of K (D per node).
    n: f64,
    nnz_k: f64,
    /// Everything both paths hold (see the module doc).
    base: f64,
    /// The element triplets of the direct path's assembly.
    assembly: f64,
}

fn terms(c: &Counts) -> Terms {
    let n = c.d * c.nodes;
    let nnz_k = c.d * c.d * c.nodes * c.stencil;
    let nnz_h = c.nodes * c.stencil;
    // Vertices, gradients (d of a tetrahedron, fem::Geometry, all three of a triangle) and
    // measure (none per cell on a generated box), B per cell where outputs read it (its
    // upper triangle, fem::CellTensors), and the cells around each node that the step's
    // element scatters gather over (fem::NodeCells: a u32 per cell and vertex, an offset
    // per node).
    let geometry = match (c.kuhn, c.d == 3.0) {
        (true, _) => 0.0,
        (false, true) => 9.0 + 1.0,
        (false, false) => 6.0 + 1.0,
    };
    let history = match c.history_stress {
        true => c.d * (c.d + 1.0) / 2.0,
        false => 0.0,
    };
    let per_cell = 8.0 * ((c.d + 1.0) + geometry + history) + 4.0 * (c.d + 1.0);
    // The a posteriori estimate: (d + 1)/2 interior facets per cell (two cells, a normal,
    // |F| and h_F) with the hash map that pairs them at set-up, h_T, the step's per-cell σ,
    // ∇ζ, |ε(w)|² and eight indicators, the cell indicators with their stored copy and
    // their velocity parts;
    // w_{n−1} and the checkpoint's w per node.
    let (estimate_cell, estimate_node) = match c.estimate {
        true => (
            (c.d + 1.0) / 2.0 * (32.0 + 8.0 * c.d + 60.0)
                + 8.0
                + 8.0 * (c.d * c.d + c.d + 9.0)
                + 24.0,
            16.0 * c.d,
        ),
        false => (0.0, 0.0),
    };
    // Element matrices (D(D+1))² per cell as (row, col, value) triplets while assembling,
    // 24 bytes each, beside their (col, value) copy bucketed by row in Csr::from_triplets.
    let assembly = 40.0 * c.cells * (c.d * (c.d + 1.0)).powi(2);
    let vectors = 8.0 * (30.0 * n + 12.0 * c.nodes);
    let scalar = if c.damage { 3.0 } else { 1.0 };
    // K (full free operator) and its K_II and K_CI blocks; M, L and H.
    let operators = 2.0 * csr(nnz_k, n) + scalar * csr(nnz_h, c.nodes);
    Terms {
        n,
        nnz_k,
        base: (8.0 * (c.d + 1.0) + estimate_node) * c.nodes
            + (per_cell + estimate_cell) * c.cells
            + vectors
            + operators,
        assembly,
    }
}

/// The direct path's peak when its factors hold `factors` bytes: beside them, K_II's lower
/// triangle handed to the factorisation (faer's CSC copy); or the assembly's triplets.
fn direct_peak(t: &Terms, factors: f64) -> u64 {
    let factoring = t.base + factors + 0.5 * csr(t.nnz_k, t.n);
    factoring.max(t.assembly + t.base) as u64
}

/// The prediction for a validated problem, from counts alone.
pub fn predict(p: &Problem) -> Prediction {
    let c = counts(p);
    let t = terms(&c);
    let Terms { n, nnz_k, base, .. } = t;
    let nnz_h = c.nodes * c.stencil;
    let direct_factors = 8.0
        * 1.25
        * (factor_entries(c.d, n)
            + if c.damage {
                factor_entries(c.d, c.nodes)
            } else {
                0.0
            });
    let mixed_precision = p.precision.mixed(c.d as usize);
    // Smoothed aggregation: AGGREGATION_HIERARCHY. Geometric levels: P has ≤ 2 nodes per
    // row and the coarse operators are an eighth of the finer ones (3D), so the hierarchy of
    // K and H is GEOMETRIC_HIERARCHY × K's bytes.
    let hierarchy_k = if c.geometric {
        GEOMETRIC_HIERARCHY * csr(nnz_k, n)
    } else {
        let p_saved = match mixed_precision {
            true => P_IN_F32_BLOCKS_SAVES * AGGREGATION_P,
            false => 0.0,
        };
        (AGGREGATION_HIERARCHY - p_saved) * csr(nnz_k, n) + 8.0 * 25.0 * n
    };
    let hierarchy_h = if c.damage && !c.geometric {
        1.0 * csr(nnz_h, c.nodes) + 8.0 * 25.0 * c.nodes
    } else {
        0.0
    };
    // A refined body's geometric levels stop at its base mesh, whose operators are factored
    // (K's a second time with a Γ3, for the truncated cycle of slipping steps), or, above
    // `multilevel::FACTORED_DOFS` unknowns, aggregated further: then the base level's
    // operator with its aggregation hierarchy (the base K's bytes, scaled by its nodes).
    let coarsest = if c.geometric && c.coarse_nodes > 0.0 {
        let base_k = csr(nnz_k * c.coarse_nodes / c.nodes, c.d * c.coarse_nodes);
        let copies_k = if c.contact { 2.0 } else { 1.0 };
        let k = if c.d * c.coarse_nodes > FACTORED_DOFS as f64 {
            copies_k * AGGREGATION_HIERARCHY * base_k
        } else {
            8.0 * 1.25 * copies_k * factor_entries(c.d, c.d * c.coarse_nodes)
        };
        let h = match (c.damage, c.coarse_nodes > FACTORED_DOFS as f64) {
            (false, _) => 0.0,
            (true, false) => 8.0 * 1.25 * factor_entries(c.d, c.coarse_nodes),
            (true, true) => AGGREGATION_HIERARCHY * base_k / (c.d * c.d),
        };
        k + h
    } else {
        0.0
    };
    let full_space = match (c.contact, c.geometric) {
        (false, _) => 0.0,
        (true, true) => FULL_SPACE_GEOMETRIC * csr(nnz_k, n),
        (true, false) => FULL_SPACE_AGGREGATION * csr(nnz_k, n),
    };
    // The multigrid path holds K once (K_II is solved through K's own hierarchy, or is K
    // without a Γ3), and with mixed precision in f64 node blocks
    // ([`crate::linalg::Sparse::Blocks`]): d × d blocks with one 32-bit index each.
    let k_held = if mixed_precision {
        (8.0 + 4.0 / (c.d * c.d)) * nnz_k
    } else {
        csr(nnz_k, n)
    };
    let k_not_held = 2.0 * csr(nnz_k, n) - k_held;
    // The earlier steps' solutions whose projection starts each K_II solve, and with damage
    // each masked H solve.
    let damage_nodes = if c.damage { c.nodes } else { 0.0 };
    let solution_space = 8.0 * SolutionSpace::vectors(CAPACITY) as f64 * (n + damage_nodes);
    let mixed = if mixed_precision {
        let per_entry = if c.d == 3.0 { 40.0 / 9.0 } else { 6.0 };
        let h = if c.damage { 8.0 * nnz_h } else { 0.0 };
        MIXED_LEVELS * (per_entry * nnz_k + h)
    } else {
        0.0
    };
    let multigrid = PROCESS + base - k_not_held
        + hierarchy_k
        + hierarchy_h
        + coarsest
        + full_space
        + solution_space
        + mixed;
    Prediction {
        direct: direct_peak(&t, direct_factors),
        multigrid: multigrid as u64,
    }
}

/// [`predict`] with the direct path's factors left out: what is certain of the direct path's
/// peak before its symbolic analyses (a lower bound).
pub fn without_factors(p: &Problem) -> Prediction {
    Prediction {
        direct: direct_peak(&terms(&counts(p)), 0.0),
        ..predict(p)
    }
}

/// [`predict`] with the direct path's factors sized exactly: `factors` are the symbolic
/// analyses of the direct path's factors (K_II's and, with damage, H's).
pub fn refine(p: &Problem, factors: &[&CholeskyPlan]) -> Prediction {
    let bytes: u64 = factors.iter().map(|f| f.factor_bytes()).sum();
    Prediction {
        direct: direct_peak(&terms(&counts(p)), bytes as f64),
        ..predict(p)
    }
}

/// Why no path fits.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum MemoryError {
    #[error("the direct solver needs about {} of memory (predicted), more than this node's per-job limit of {}; use \"solver\": {{\"linear\": \"multigrid\"}} (about {}) or \"auto\"", human(*predicted), human(*allowed), human(*multigrid))]
    DirectTooLarge {
        predicted: u64,
        allowed: u64,
        multigrid: u64,
    },
    #[error("this run needs about {} of memory (predicted, on the {path} path), more than this node's per-job limit of {}; choose a coarser mesh", human(*predicted), human(*allowed))]
    TooLarge {
        predicted: u64,
        allowed: u64,
        path: &'static str,
    },
}

impl MemoryError {
    /// The scene field to blame: the solver choice, or the mesh.
    pub fn pointer(&self) -> &'static str {
        match self {
            MemoryError::DirectTooLarge { .. } => "/solver/linear",
            MemoryError::TooLarge { .. } => "/mesh",
        }
    }
}

/// Bytes as a short human figure ("3.2 GiB").
pub fn human(bytes: u64) -> String {
    let b = bytes as f64;
    if b >= (1u64 << 30) as f64 {
        format!("{:.1} GiB", b / (1u64 << 30) as f64)
    } else {
        format!("{:.0} MiB", (b / (1u64 << 20) as f64).ceil())
    }
}

/// Unknowns below which `auto` keeps the direct path when it fits: a sparse Cholesky
/// factor is at its floor there (all 2D paper sizes, 3D up to a few 10⁴ unknowns).
const DIRECT_3D_UNKNOWNS: f64 = 60_000.0;

/// The path a problem takes under a per-job memory limit (None: no limit), with its
/// prediction. `auto`: 2D and small 3D bodies take the direct path, larger 3D bodies
/// multigrid; either falls back to the other when only the other fits.
pub fn choose(p: &Problem, limit: Option<u64>) -> Result<(LinearPath, u64), MemoryError> {
    choose_with(p, limit, predict(p))
}

/// [`choose`] on the prediction `pred` ([`predict`], or [`refine`] once the direct path's
/// factors are analysed).
pub fn choose_with(
    p: &Problem,
    limit: Option<u64>,
    pred: Prediction,
) -> Result<(LinearPath, u64), MemoryError> {
    let fits = |b: u64| limit.is_none_or(|l| b <= l);
    let allowed = limit.unwrap_or(u64::MAX);
    let c = counts(p);
    match p.linear {
        LinearPath::Direct if fits(pred.direct) => Ok((LinearPath::Direct, pred.direct)),
        LinearPath::Direct => Err(MemoryError::DirectTooLarge {
            predicted: pred.direct,
            allowed,
            multigrid: pred.multigrid,
        }),
        LinearPath::Multigrid if fits(pred.multigrid) => {
            Ok((LinearPath::Multigrid, pred.multigrid))
        }
        LinearPath::Multigrid => Err(MemoryError::TooLarge {
            predicted: pred.multigrid,
            allowed,
            path: "multigrid",
        }),
        LinearPath::Auto => {
            let prefer_direct = c.d == 2.0 || c.d * c.nodes <= DIRECT_3D_UNKNOWNS;
            let order = if prefer_direct {
                [
                    (LinearPath::Direct, pred.direct),
                    (LinearPath::Multigrid, pred.multigrid),
                ]
            } else {
                [
                    (LinearPath::Multigrid, pred.multigrid),
                    (LinearPath::Direct, pred.direct),
                ]
            };
            order
                .into_iter()
                .find(|&(_, b)| fits(b))
                .ok_or(MemoryError::TooLarge {
                    predicted: pred.multigrid.min(pred.direct),
                    allowed,
                    path: "multigrid",
                })
        }
    }
}

/// The process's peak resident memory (VmHWM), where the OS reports it.
pub fn peak_bytes() -> Option<u64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kb: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb * 1024)
}

/// `80 %` of physical memory (MemTotal), where the OS reports it.
pub fn default_limit(share: usize) -> Option<u64> {
    let info = std::fs::read_to_string("/proc/meminfo").ok()?;
    let line = info.lines().find(|l| l.starts_with("MemTotal:"))?;
    let kb: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb * 1024 / 10 * 8 / share.max(1) as u64)
}

/// Parses a byte count with an optional K/M/G/T suffix (powers of 1024): "4G", "512M".
pub fn parse_bytes(s: &str) -> Result<u64, String> {
    let s = s.trim();
    let (num, mult) = match s.char_indices().last() {
        Some((i, c)) if c.is_ascii_alphabetic() => {
            let m = match c.to_ascii_uppercase() {
                'K' => 1u64 << 10,
                'M' => 1 << 20,
                'G' => 1 << 30,
                'T' => 1 << 40,
                _ => return Err(format!("unknown suffix {c:?} in {s:?}: use K, M, G or T")),
            };
            (&s[..i], m)
        }
        _ => (s, 1),
    };
    let v: f64 = num
        .trim()
        .parse()
        .map_err(|_| format!("{s:?} is not a byte count (e.g. 4G, 512M, 1000000)"))?;
    if !(v.is_finite() && v > 0.0) {
        return Err(format!("{s:?}: the limit must be positive"));
    }
    Ok((v * mult as f64) as u64)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_a_posteriori_estimate_is_counted_only_when_asked() {
        let mut doc = crate::scene::presets::get("box-exp3").unwrap();
        doc["mesh"]["h"] = serde_json::json!("1/8");
        let plain = crate::scene::validate(&doc).unwrap();
        let mut asked = plain.clone();
        asked.output.estimate = true;
        let (a, b) = (predict(&plain), predict(&asked));
        // box-exp3 at 1/8 has 6 · 16 · 8 · 8 cells and 17 · 9 · 9 nodes; in 3D the estimate holds
        // 2 · (32 + 24 + 60) + 8 + 8 · 21 + 24 = 432 bytes a cell and 48 a node.
        let (cells, nodes) = (6.0 * 16.0 * 8.0 * 8.0, 17.0 * 9.0 * 9.0);
        let extra = 432.0 * cells + 48.0 * nodes;
        for (x, y) in [(a.direct, b.direct), (a.multigrid, b.multigrid)] {
            assert!(((y - x) as f64 - extra).abs() < 1.0, "{x} → {y}, {extra}");
        }
    }

    /// B_{n−1} (six numbers a tetrahedron) is counted where the stress fields or the estimate
    /// read it after the step, and not otherwise.
    #[test]
    fn b_per_cell_is_counted_only_where_outputs_read_it() {
        let mut doc = crate::scene::presets::get("box-exp3").unwrap();
        doc["mesh"]["h"] = serde_json::json!("1/8");
        let mut none = crate::scene::validate(&doc).unwrap();
        none.output.fields = Default::default();
        none.output.estimate = false;
        let cells = 6.0 * 16.0 * 8.0 * 8.0;
        for fields in [
            crate::problem::FieldSet {
                sigma: true,
                ..Default::default()
            },
            crate::problem::FieldSet {
                von_mises: true,
                ..Default::default()
            },
        ] {
            let mut stress = none.clone();
            stress.output.fields = fields;
            let (a, b) = (predict(&none), predict(&stress));
            for (x, y) in [(a.direct, b.direct), (a.multigrid, b.multigrid)] {
                assert!(((y - x) as f64 - 48.0 * cells).abs() < 1.0, "{x} → {y}");
            }
        }
        let mut others = none.clone();
        others.output.fields = crate::problem::FieldSet {
            u: true,
            w: true,
            zeta: true,
            contact: true,
            ..Default::default()
        };
        assert_eq!(predict(&none).multigrid, predict(&others).multigrid);
    }

    #[test]
    fn byte_counts_parse_with_suffixes() {
        assert_eq!(parse_bytes("4G").unwrap(), 4 << 30);
        assert_eq!(parse_bytes("512m").unwrap(), 512 << 20);
        assert_eq!(parse_bytes("1000").unwrap(), 1000);
        assert_eq!(parse_bytes("1.5K").unwrap(), 1536);
        assert!(
            parse_bytes("4Q").is_err() && parse_bytes("-1G").is_err() && parse_bytes("").is_err()
        );
    }
}
