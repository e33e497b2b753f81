//! Multigrid V-cycle preconditioner for the SPD operators of a run (the velocity operator K
//! on the free DOFs, the damage matrix H = M/k + κL), in the AMGCL manner: the coarsening
//! ([`Coarsening`]: smoothed aggregation, or prolongators given by a nested mesh hierarchy),
//! the smoother ([`smoother::Chebyshev`] over point-block Jacobi) and the coarsest solve (a
//! sparse Cholesky factor) are separate parts.
//!
//! Set-up, per level l: A_{l+1} = P_lᵀ A_l P_l (Galerkin, [`super::galerkin`]), so the
//! constraints built into the fine DOFs hold on every level. Apply (one V-cycle, x = B r):
//! pre-smooth from 0, restrict the residual, recurse, prolongate and add, post-smooth with
//! the same polynomial — B is symmetric positive definite, fit for conjugate gradients.

pub mod aggregation;
pub mod prolongator;
pub mod smoother;
pub mod truncated;

use super::block_csr::BlockCsr32;
use super::block_products;
use super::cholesky::{Cholesky, FactorError};
use super::csr::TRANSPOSE_PIECES;
use super::galerkin::{add, galerkin, transpose};
use super::par;
use super::pcg::Preconditioner;
use super::{Csr, LinearOperator};
use prolongator::Prolongator;
use smoother::Chebyshev;
use std::borrow::Cow;
use std::sync::Arc;

/// The DOFs of each node block (a node's free velocity components; an aggregate's coarse
/// DOFs; a single DOF for scalar problems), CSR-style.
#[derive(Debug, Clone, PartialEq)]
pub struct Blocks {
    ptr: Vec<usize>,
    dofs: Vec<usize>,
}

impl Blocks {
    /// Blocks from the block of each DOF (`u32::MAX`: no block, not allowed here).
    pub fn from_block_of(block_of: &[u32], n_blocks: usize) -> Blocks {
        let mut ptr = vec![0usize; n_blocks + 1];
        for &b in block_of {
            ptr[b as usize + 1] += 1;
        }
        for b in 0..n_blocks {
            ptr[b + 1] += ptr[b];
        }
        let mut next = ptr.clone();
        let mut dofs = vec![0; block_of.len()];
        for (i, &b) in block_of.iter().enumerate() {
            dofs[next[b as usize]] = i;
            next[b as usize] += 1;
        }
        let mut blocks = Blocks { ptr, dofs };
        blocks.drop_empty();
        blocks
    }

    /// Consecutive DOF ranges ptr[b]..ptr[b+1].
    pub fn contiguous(ptr: &[usize]) -> Blocks {
        Blocks {
            ptr: ptr.to_vec(),
            dofs: (0..*ptr.last().unwrap_or(&0)).collect(),
        }
    }

    /// One DOF per block.
    pub fn scalar(n: usize) -> Blocks {
        Blocks::contiguous(&(0..=n).collect::<Vec<_>>())
    }

    /// The bounds of consecutive DOF ranges covering 0..n: each block whose DOFs are a
    /// consecutive increasing range, single DOFs elsewhere (the block rows of a level's
    /// [`BlockCsr32`]).
    pub fn consecutive_bounds(&self, n: usize) -> Vec<usize> {
        let mut len = vec![0usize; n];
        for b in 0..self.len() {
            let dofs = self.dofs(b);
            let consecutive = dofs.windows(2).all(|w| w[1] == w[0] + 1);
            match dofs.first() {
                Some(&first) if consecutive && dofs.iter().all(|&d| d < n) => {
                    len[first] = dofs.len()
                }
                _ => {}
            }
        }
        let mut ptr = vec![0];
        let mut i = 0;
        while i < n {
            i += len[i].max(1);
            ptr.push(i.min(n));
        }
        ptr
    }

    fn drop_empty(&mut self) {
        let mut ptr = vec![0];
        for b in 0..self.len() {
            if self.ptr[b + 1] > self.ptr[b] {
                ptr.push(self.ptr[b + 1]);
            }
        }
        self.ptr = ptr;
    }

    pub fn len(&self) -> usize {
        self.ptr.len() - 1
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    pub fn n_dofs(&self) -> usize {
        self.dofs.len()
    }

    pub fn dofs(&self, b: usize) -> &[usize] {
        &self.dofs[self.ptr[b]..self.ptr[b + 1]]
    }

    /// The block of each of the n DOFs.
    pub fn block_of(&self, n: usize) -> Vec<u32> {
        let mut of = vec![u32::MAX; n];
        for b in 0..self.len() {
            for &i in self.dofs(b) {
                of[i] = b as u32;
            }
        }
        of
    }
}

/// How the levels are made.
#[derive(Debug, Clone)]
pub enum Coarsening {
    /// Smoothed aggregation with the near-nullspace B (n × k, row-major).
    Aggregation { nullspace: Vec<f64>, k: usize },
    /// The prolongators of a nested mesh hierarchy, finest first: P_0 is n_0 × n_1, …;
    /// each coarse level's blocks are its nodes (`blocks[l]` for level l + 1). With `below`,
    /// the coarsest of these levels is aggregated further rather than factored (a large
    /// base mesh refined).
    Geometric {
        prolongators: Vec<Csr>,
        blocks: Vec<Blocks>,
        below: Option<Below>,
    },
}

/// The near-nullspace on the coarsest level of a nested mesh hierarchy (n × k, row-major),
/// for smoothed aggregation below it.
#[derive(Debug, Clone)]
pub struct Below {
    pub nullspace: Vec<f64>,
    pub k: usize,
}

/// Settings of the hierarchy.
#[derive(Debug, Clone, Copy)]
pub struct Params {
    /// A level with at most this many DOFs is factored directly.
    pub coarse_size: usize,
    pub max_levels: usize,
    /// Chebyshev degree of the pre- and post-smoother.
    pub degree: usize,
    /// The smoother damps [λ/ratio, 1.1 λ].
    pub ratio: f64,
    /// Strength threshold θ of aggregation on the finest level.
    pub theta: f64,
    /// 3D elasticity (six rigid modes) aggregates the distance-two strength graph on the
    /// finest level ([`aggregation::squared`]); 2D keeps the plain graph, whose coarse
    /// operators are small enough and whose two-grid factor stays lower.
    pub square_finest: bool,
    /// Mixed precision: each level's smoother and residual products use a single-precision
    /// block copy of its operator ([`BlockCsr32`]); the operators themselves stay f64.
    pub mixed: bool,
}

impl Default for Params {
    fn default() -> Self {
        Params {
            coarse_size: 2000,
            max_levels: 12,
            // Degree 2 over [λ/7, 1.1λ]: measured on box-exp3 at 1/16 and 1/32 against degree
            // 3 and 4 and ratios 4–30, the fewest products per step (a few more iterations).
            degree: 2,
            ratio: 7.0,
            theta: 0.08,
            square_finest: true,
            mixed: false,
        }
    }
}

/// One level above the coarsest.
#[derive(Debug)]
struct Level {
    /// The operator in f64: `None` once shed ([`Hierarchy::shed_operators`]), when the
    /// V-cycle reads only `a32`.
    a: Option<Arc<Csr>>,
    /// The operator's rows and entries, for the sizes and the operator complexity.
    n: usize,
    nnz: usize,
    /// `a` in f32 node blocks, with [`Params::mixed`].
    a32: Option<BlockCsr32>,
    smoother: Chebyshev,
    /// To the next coarser level, with its restriction.
    p: Prolongator,
}

impl Level {
    /// The level of `a` (node `blocks`) with prolongator `p` to the `coarse` blocks, and the
    /// next coarser operator PᵀAP.
    fn new(
        a: Arc<Csr>,
        blocks: &Blocks,
        coarse: &Blocks,
        smoother: Chebyshev,
        mut p: Csr,
        params: Params,
    ) -> (Level, Arc<Csr>) {
        // Pᵀ is formed only where it is kept: a P that restricts by pieces has its Galerkin
        // product summed from its rows too. A wide P (smoothed aggregation) takes the
        // product in node blocks where their sizes allow, and with mixed precision is held
        // in f32 node blocks, its entries rounded before the product.
        let bounds = blocks.consecutive_bounds(a.nrows);
        let coarse_bounds = coarse.consecutive_bounds(p.ncols);
        let by_pieces = restricts_by_pieces(&p);
        let in_f32 = params.mixed && by_pieces;
        if in_f32 {
            p.values.iter_mut().for_each(|v| *v = *v as f32 as f64);
        }
        let pt = (!by_pieces).then(|| transpose(&p));
        let in_blocks = (p.nnz() > 2 * p.nrows)
            .then(|| block_products::galerkin(&a, &p, &bounds, &coarse_bounds))
            .flatten();
        let coarse = Arc::new(in_blocks.unwrap_or_else(|| galerkin(&a, &p, pt.as_ref())));
        let a32 = params.mixed.then(|| BlockCsr32::new(&a, &bounds));
        let p = match in_f32 {
            true => Prolongator::Blocks(BlockCsr32::rectangular(&p, &bounds, &coarse_bounds)),
            false => Prolongator::Scalar { p, pt },
        };
        let level = Level {
            n: a.nrows,
            nnz: a.nnz(),
            a: Some(a),
            a32,
            smoother,
            p,
        };
        (level, coarse)
    }
}

/// Whether Pᵀ is applied by pieces rather than stored: a wide P (more than two entries a row:
/// smoothed aggregation) whose pieces' scratch ([`TRANSPOSE_PIECES`] coarse vectors, in each
/// V-cycle's work space) holds fewer numbers than P has entries, and so than a stored Pᵀ.
/// Measured on the 82k-node part: the coarser velocity levels and the damage hierarchy
/// (8,819 coarse unknowns under 81,738) held 15 MB of transposes that this rule removes,
/// for 1.1 MB of scratch a work space.
fn restricts_by_pieces(p: &Csr) -> bool {
    p.nnz() > 2 * p.nrows && TRANSPOSE_PIECES * p.ncols <= p.nnz()
}

/// The multigrid hierarchy of one operator: the fine operator, the coarser Galerkin
/// operators, smoothers and the factored coarsest operator. Immutable once built; shared
/// between solvers (each has its own [`VCycle`] work space).
#[derive(Debug)]
pub struct Hierarchy {
    levels: Vec<Level>,
    coarse_a: Csr,
    coarse_blocks: Blocks,
    coarse: Cholesky,
    kind: &'static str,
    params: Params,
}

impl Hierarchy {
    /// Builds the levels of `a` (the finest operator) with node `blocks`.
    pub fn new(
        a: Arc<Csr>,
        blocks: Blocks,
        coarsening: Coarsening,
        params: Params,
    ) -> Result<Hierarchy, FactorError> {
        let mut levels = Vec::new();
        let mut a = a;
        let mut blocks = blocks;
        let (kind, aggregate) = match coarsening {
            Coarsening::Aggregation { nullspace, k } => {
                ("smoothed aggregation", Some((nullspace, k)))
            }
            Coarsening::Geometric {
                prolongators,
                blocks: coarse_blocks,
                below,
            } => {
                let most = params.max_levels.saturating_sub(1);
                for (p, cb) in prolongators.into_iter().zip(coarse_blocks).take(most) {
                    let smoother = Chebyshev::new(&a, &blocks, params.degree, params.ratio);
                    let (level, coarse) = Level::new(a, &blocks, &cb, smoother, p, params);
                    levels.push(level);
                    a = coarse;
                    blocks = cb;
                }
                match below {
                    Some(b) if levels.len() + 1 < params.max_levels => (
                        "geometric, then smoothed aggregation",
                        Some((b.nullspace, b.k)),
                    ),
                    _ => ("geometric", None),
                }
            }
        };
        if let Some((mut nullspace, k)) = aggregate {
            let first = levels.len();
            let mut theta = params.theta;
            while a.nrows > params.coarse_size && levels.len() + 1 < params.max_levels {
                let smoother = Chebyshev::new(&a, &blocks, params.degree, params.ratio);
                // The strength graph is dropped once aggregated: it is not to be held beside
                // the prolongator and the Galerkin product, the set-up's peak.
                let (agg, count) = {
                    let (mut ptr, mut list) = aggregation::strength(&a, &blocks, theta);
                    // 3D elasticity aggregates the distance-two graph on its first aggregated
                    // level (see `aggregation::squared`): on the 80k-node gmsh part it cut the
                    // first coarse operator from 9.4 M to 1.1 M entries, set-up by half and
                    // the peak by 40 %, for 1.7× the Krylov iterations of cheaper cycles.
                    if levels.len() == first && k >= 6 && params.square_finest {
                        (ptr, list) = aggregation::squared(&ptr, &list);
                    }
                    aggregation::aggregates(&ptr, &list)
                };
                let (t, coarse_blocks, coarse_null) =
                    aggregation::tentative(&blocks, &agg, count, &nullspace, k);
                if t.ncols == 0 || t.ncols * 10 > a.nrows * 9 {
                    break; // no longer coarsening: factor this level
                }
                let p = aggregation::smooth_prolongator(
                    &a,
                    &smoother.jacobi,
                    smoother.lambda_hi() / 1.1,
                    &t,
                    &blocks.consecutive_bounds(a.nrows),
                    &coarse_blocks.consecutive_bounds(t.ncols),
                );
                let (level, coarse) = Level::new(a, &blocks, &coarse_blocks, smoother, p, params);
                levels.push(level);
                a = coarse;
                blocks = coarse_blocks;
                nullspace = coarse_null;
                theta *= 0.5;
            }
        }
        let coarse_a = Arc::try_unwrap(a).unwrap_or_else(|a| (*a).clone());
        let coarse = Cholesky::new(coarse_a.lower_csc().as_ref())?;
        Ok(Hierarchy {
            levels,
            coarse_a,
            coarse_blocks: blocks,
            coarse,
            kind,
            params,
        })
    }

    /// The Galerkin changes that a change Δ of level `level`'s operator makes on that level
    /// and every one below, the coarsest's last:
    ///   P_lᵀ (A_l + Δ_l) P_l = A_{l+1} + Δ_{l+1},   Δ_{l+1} = P_lᵀ Δ_l P_l,
    /// each product formed from P's rows that meet Δ_l's, so that a change on a few nodes
    /// (the truncated cycle's Γ3) costs work on those only, not the whole product
    /// P_lᵀ A_l' P_l again. Δ symmetric; each Δ_{l+1} is made exactly so.
    pub fn changes_below(&self, level: usize, mut delta: Csr) -> Vec<Csr> {
        let mut changes = Vec::with_capacity(self.levels.len() + 1 - level);
        for old in self.levels.iter().skip(level) {
            let below = old.p.galerkin_of(&delta);
            changes.push(std::mem::replace(&mut delta, below));
        }
        changes.push(delta);
        changes
    }

    /// The hierarchy of A_l + Δ_l on the levels l = `level`, `level` + 1, … of this one down
    /// to the coarsest (`changes[l − level]`, as [`Hierarchy::changes_below`] makes them),
    /// with the same DOFs, blocks and prolongators, and fresh smoothers and coarsest factor.
    /// The operators A_l are this hierarchy's, widened from their f32 copies where shed (a
    /// preconditioner's rounding, as the V-cycle applies them).
    pub fn updated(&self, level: usize, changes: &[Csr]) -> Result<Hierarchy, FactorError> {
        assert_eq!(
            changes.len(),
            self.levels.len() + 1 - level,
            "a change per level from `level` to the coarsest"
        );
        let mut levels = Vec::with_capacity(self.levels.len().saturating_sub(level));
        for ((l, old), delta) in self.levels.iter().enumerate().skip(level).zip(changes) {
            let a = self
                .operator_in_f64(l)
                .expect("a level above the coarsest has an operator")
                .into_owned();
            let blocks = old.smoother.jacobi.blocks();
            let (a, smoother, a32) =
                changed_operator(a, delta, blocks, old.a32.is_some(), self.params);
            levels.push(Level {
                n: a.nrows,
                nnz: a.nnz(),
                a: Some(Arc::new(a)),
                a32,
                smoother,
                p: old.p.clone(),
            });
        }
        let (coarse_a, coarse) = changed_coarsest(
            self.coarse_a.clone(),
            changes.last().expect("the coarsest's"),
        )?;
        Ok(Hierarchy {
            levels,
            coarse_a,
            coarse_blocks: self.coarse_blocks.clone(),
            coarse,
            kind: self.kind,
            params: self.params,
        })
    }

    /// This hierarchy with `changes` (one per level, the coarsest's last, as
    /// [`Hierarchy::changes_below`] makes them from level 0) added to its operators in place,
    /// and the smoothers of the changed levels and the coarsest factor made again. A shed
    /// level takes its change into its f32 blocks ([`BlockCsr32::add_in_place`], each changed
    /// entry rounded again: 2⁻²⁴ relative, a preconditioner's rounding) and its smoother
    /// from them; where the blocks do not hold the change, it is widened, changed and
    /// rounded afresh. Each level holds one f64 copy of its operator at a time, and the old
    /// coarsest factor goes before the new one is made.
    pub fn with_changes(self, changes: &[Csr]) -> Result<Hierarchy, FactorError> {
        assert_eq!(
            changes.len(),
            self.levels.len() + 1,
            "a change per level and the coarsest's"
        );
        let Hierarchy {
            mut levels,
            coarse_a,
            coarse_blocks,
            coarse,
            kind,
            params,
        } = self;
        drop(coarse);
        for (level, delta) in levels.iter_mut().zip(changes) {
            if delta.nnz() == 0 {
                continue;
            }
            // A level kept in f32 only takes the change into its blocks where they hold it,
            // instead of being widened, summed and rounded afresh.
            if let (None, Some(a32)) = (&level.a, &mut level.a32) {
                if a32.add_in_place(delta) {
                    let blocks = level.smoother.jacobi.blocks();
                    level.smoother = Chebyshev::of_single(a32, blocks, params.degree, params.ratio);
                    continue;
                }
            }
            let (shed, single) = (level.a.is_none(), level.a32.is_some());
            let a = match level.a.take() {
                Some(a) => Arc::unwrap_or_clone(a),
                None => level
                    .a32
                    .take()
                    .expect("a shed level has its f32 copy")
                    .to_csr(),
            };
            let blocks = level.smoother.jacobi.blocks();
            let (a, smoother, a32) = changed_operator(a, delta, blocks, single, params);
            level.smoother = smoother;
            level.a32 = a32;
            level.nnz = a.nnz();
            level.a = (!shed).then(|| Arc::new(a));
        }
        let (coarse_a, coarse) =
            changed_coarsest(coarse_a, changes.last().expect("the coarsest's"))?;
        Ok(Hierarchy {
            levels,
            coarse_a,
            coarse_blocks,
            coarse,
            kind,
            params,
        })
    }

    /// Level l's prolongator to level l + 1 (l below the coarsest).
    pub fn prolongator(&self, l: usize) -> Option<&Prolongator> {
        self.levels.get(l).map(|level| &level.p)
    }

    /// y ← P_lᵀ x, the restriction from level l to l + 1, with `scratch` of
    /// [`Hierarchy::restriction_scratch`] entries.
    pub fn restrict(&self, l: usize, x: &[f64], y: &mut [f64], scratch: &mut [f64]) {
        self.levels[l].p.restrict(x, y, scratch);
    }

    /// The scratch entries that [`Hierarchy::restrict`] on level l needs.
    pub fn restriction_scratch(&self, l: usize) -> usize {
        self.levels.get(l).map_or(0, |level| level.p.scratch_len())
    }

    /// Level l's single-precision operator, with [`Params::mixed`].
    pub fn level_f32(&self, l: usize) -> Option<&BlockCsr32> {
        self.levels.get(l).and_then(|v| v.a32.as_ref())
    }

    /// Level l's smoother and prolongator to level l + 1 (l below the coarsest).
    pub fn level(&self, l: usize) -> Option<(&Chebyshev, &Prolongator)> {
        self.levels.get(l).map(|v| (&v.smoother, &v.p))
    }

    /// Level l's operator in f64 (the coarsest's for l = the number of levels above it);
    /// `None` where it was shed or l is past the coarsest.
    pub fn operator_at(&self, l: usize) -> Option<&Csr> {
        match self.levels.get(l) {
            Some(level) => level.a.as_deref(),
            None => (l == self.levels.len()).then_some(&self.coarse_a),
        }
    }

    /// Level l's operator in f64: the one kept, or where it was shed its f32 copy widened
    /// (a preconditioner's rounding of it, 2⁻²⁴ relative); `None` past the coarsest.
    pub fn operator_in_f64(&self, l: usize) -> Option<Cow<'_, Csr>> {
        match (self.operator_at(l), self.level_f32(l)) {
            (Some(a), _) => Some(Cow::Borrowed(a)),
            (None, Some(a32)) => Some(Cow::Owned(a32.to_csr())),
            (None, None) => None,
        }
    }

    /// Drops the f64 operators of the levels not in `keep` that have a single-precision
    /// copy ([`Params::mixed`]), which is all the V-cycle reads there. The finest operator
    /// is kept where its owner reads it from here (the damage step's H), not where the owner
    /// holds it in another storage (the velocity step's K in f64 node blocks). The truncated
    /// cycles, which update A₁ = P₀ᵀ A P₀ of K's hierarchy for each Jacobian, read it
    /// widened from its f32 copy ([`Hierarchy::operator_in_f64`]): a preconditioner's
    /// rounding, for 20 MB on the 82k-node part.
    pub fn shed_operators(&mut self, keep: &[usize]) {
        for (l, level) in self.levels.iter_mut().enumerate() {
            if level.a32.is_some() && !keep.contains(&l) {
                level.a = None;
            }
        }
    }

    /// Number of levels, the coarsest included.
    pub fn n_levels(&self) -> usize {
        self.levels.len() + 1
    }

    /// "smoothed aggregation", "geometric", or "geometric, then smoothed aggregation".
    pub fn kind(&self) -> &'static str {
        self.kind
    }

    /// What a summary says of it: "multigrid (smoothed aggregation, 4 levels)".
    pub fn describe(&self) -> String {
        let precision = if self.params.mixed {
            ", mixed precision"
        } else {
            ""
        };
        format!(
            "multigrid ({}, {} levels{precision})",
            self.kind,
            self.n_levels()
        )
    }

    /// Sizes (rows) of every level, finest first.
    pub fn sizes(&self) -> Vec<usize> {
        self.levels
            .iter()
            .map(|l| l.n)
            .chain(std::iter::once(self.coarse_a.nrows))
            .collect()
    }

    /// Operator complexity Σ_l nnz(A_l) / nnz(A_0): the storage and the work of one
    /// application of every level's operator, relative to the finest operator's.
    pub fn operator_complexity(&self) -> f64 {
        let nnz: Vec<usize> = self
            .levels
            .iter()
            .map(|l| l.nnz)
            .chain(std::iter::once(self.coarse_a.nnz()))
            .collect();
        nnz.iter().sum::<usize>() as f64 / nnz[0].max(1) as f64
    }

    /// The finest operator, where it was not shed ([`Hierarchy::shed_operators`]).
    pub fn operator(&self) -> &Csr {
        self.operator_at(0).expect("the finest operator is kept")
    }

    /// A fresh work space for V-cycles on this hierarchy.
    pub fn vcycle(self: &Arc<Self>) -> VCycle {
        let work = self
            .sizes()
            .into_iter()
            .enumerate()
            .map(|(l, n)| LevelWork {
                b: vec![0.0; n],
                x: vec![0.0; n],
                r: vec![0.0; n],
                d: vec![0.0; n],
                t: vec![0.0; n],
                pieces: vec![0.0; self.restriction_scratch(l)],
            })
            .collect();
        VCycle {
            coarse: self.coarse.clone(),
            hierarchy: self.clone(),
            work,
        }
    }
}

#[derive(Debug, Clone)]
struct LevelWork {
    b: Vec<f64>,
    x: Vec<f64>,
    r: Vec<f64>,
    d: Vec<f64>,
    t: Vec<f64>,
    /// The restriction's scratch ([`Hierarchy::restriction_scratch`]).
    pieces: Vec<f64>,
}

/// One V-cycle x = B r on a shared [`Hierarchy`], with its own work vectors.
pub struct VCycle {
    hierarchy: Arc<Hierarchy>,
    coarse: Cholesky,
    work: Vec<LevelWork>,
}

impl Clone for VCycle {
    fn clone(&self) -> Self {
        self.hierarchy.vcycle()
    }
}

impl VCycle {
    pub fn hierarchy(&self) -> &Arc<Hierarchy> {
        &self.hierarchy
    }

    /// The hierarchy, this cycle's work vectors and factor freed.
    pub fn into_hierarchy(self) -> Arc<Hierarchy> {
        self.hierarchy
    }

    fn cycle(&mut self, l: usize) {
        let h = self.hierarchy.clone();
        if l == h.levels.len() {
            let w = &mut self.work[l];
            par::copy(&mut w.x, &w.b);
            self.coarse.solve_in_place(&mut w.x);
            return;
        }
        let level = &h.levels[l];
        let a: &dyn LinearOperator = match (&level.a32, &level.a) {
            (Some(a32), _) => a32,
            (None, Some(a)) => a.as_ref(),
            (None, None) => unreachable!("only an operator with an f32 copy is shed"),
        };
        {
            let w = &mut self.work[l];
            par::fill(&mut w.x, 0.0);
            let LevelWork { b, x, r, d, t, .. } = w;
            level.smoother.smooth(a, b, x, r, d, t, true);
            // t ← b − A x, restricted into the next level's right-hand side.
            a.apply(x, t);
            par::zip_apply(t, b, |t, b| b - t);
        }
        let (fine, coarse) = self.work.split_at_mut(l + 1);
        let w = &mut fine[l];
        level.p.restrict(&w.t, &mut coarse[0].b, &mut w.pieces);
        self.cycle(l + 1);
        let (fine, coarse) = self.work.split_at_mut(l + 1);
        let w = &mut fine[l];
        level.p.mul_vec(&coarse[0].x, &mut w.t);
        par::zip_apply(&mut w.x, &w.t, |x, t| x + t);
        let LevelWork { b, x, r, d, t, .. } = w;
        level.smoother.smooth(a, b, x, r, d, t, false);
    }
}

impl Preconditioner for VCycle {
    fn apply(&mut self, r: &[f64], z: &mut [f64]) {
        par::copy(&mut self.work[0].b, r);
        self.cycle(0);
        par::copy(z, &self.work[0].x);
    }
}

/// A level's operator `a` (f64, owned) plus `delta`, with a fresh smoother over the level's
/// `blocks` and, where the level has one (`single`), a fresh f32 copy.
fn changed_operator(
    mut a: Csr,
    delta: &Csr,
    blocks: &Blocks,
    single: bool,
    params: Params,
) -> (Csr, Chebyshev, Option<BlockCsr32>) {
    add_in_place(&mut a, delta);
    let smoother = Chebyshev::new(&a, blocks, params.degree, params.ratio);
    let a32 = single.then(|| BlockCsr32::new(&a, &blocks.consecutive_bounds(a.nrows)));
    (a, smoother, a32)
}

/// The coarsest operator plus `delta`, and its factor.
fn changed_coarsest(mut a: Csr, delta: &Csr) -> Result<(Csr, Cholesky), FactorError> {
    add_in_place(&mut a, delta);
    let factor = Cholesky::new(a.lower_csc().as_ref())?;
    Ok((a, factor))
}

/// a ← a + delta, in a's pattern where it holds delta's, else into a new one.
fn add_in_place(a: &mut Csr, delta: &Csr) {
    let position = |i: usize, j: u32| {
        let row = a.indptr[i]..a.indptr[i + 1];
        a.indices[row.clone()]
            .binary_search(&j)
            .ok()
            .map(|k| row.start + k)
    };
    let positions: Option<Vec<usize>> = (0..delta.nrows)
        .flat_map(|i| (delta.indptr[i]..delta.indptr[i + 1]).map(move |k| (i, k)))
        .map(|(i, k)| position(i, delta.indices[k]))
        .collect();
    match positions {
        Some(positions) => {
            for (p, v) in positions.into_iter().zip(&delta.values) {
                a.values[p] += v;
            }
        }
        None => *a = add(1.0, a, 1.0, delta),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fem::{assembly, multilevel, Geometry};
    use crate::mesh::Mesh;
    use crate::problem::MeshPattern;

    fn dot(a: &[f64], b: &[f64]) -> f64 {
        a.iter().zip(b).map(|(x, y)| x * y).sum()
    }

    #[test]
    fn consecutive_bounds_keep_consecutive_blocks_and_split_the_others() {
        let blocks = Blocks::from_block_of(&[1, 0, 0, 1, 2, 2, 0, 1, 3, 3, 3], 4);
        // Blocks 0 ({1, 2, 6}) and 1 ({0, 3, 7}) are not ranges: single DOFs.
        assert_eq!(
            blocks.consecutive_bounds(11),
            vec![0, 1, 2, 3, 4, 6, 7, 8, 11]
        );
        assert_eq!(Blocks::scalar(4).consecutive_bounds(4), vec![0, 1, 2, 3, 4]);
        let nodes = Blocks::contiguous(&[0, 3, 5, 8]);
        assert_eq!(nodes.consecutive_bounds(8), vec![0, 3, 5, 8]);
    }

    /// H = 64 M + L of a square mesh with the levels the damage step would get.
    fn hierarchy(pattern: MeshPattern) -> Arc<Hierarchy> {
        let mesh = Mesh::rectangle(1.0, 1.0, 32, 32, pattern);
        let geo = Geometry::new(&mesh);
        let m = assembly::mass_in_pattern(&mesh, &geo);
        let l = assembly::laplacian_in_pattern_of(&mesh, &geo, &m);
        let h = assembly::combine(64.0, &m, 1.0, &l);
        let (blocks, levels) = multilevel::scalar_levels(&mesh, h.nrows);
        Arc::new(Hierarchy::new(Arc::new(h), blocks, levels, Params::default()).unwrap())
    }

    /// The V-cycle B is symmetric, xᵀ B y = yᵀ B x, and positive, for geometric levels (a
    /// halved diagonal grid) and smoothed aggregation (the cross grid, not nested).
    #[test]
    fn v_cycles_are_symmetric_and_positive() {
        for (pattern, kind) in [
            (MeshPattern::Diagonal, "geometric"),
            (MeshPattern::Cross, "smoothed aggregation"),
        ] {
            let h = hierarchy(pattern);
            assert!(h.describe().contains(kind), "{}", h.describe());
            let n = h.operator().nrows;
            let x: Vec<f64> = (0..n).map(|i| (1.3 * i as f64).sin()).collect();
            let y: Vec<f64> = (0..n).map(|i| (0.7 * i as f64 + 2.0).cos()).collect();
            let mut b = h.vcycle();
            let (mut bx, mut by) = (vec![0.0; n], vec![0.0; n]);
            b.apply(&x, &mut bx);
            b.apply(&y, &mut by);
            let (l, r) = (dot(&y, &bx), dot(&x, &by));
            assert!(
                (l - r).abs() <= 1e-12 * l.abs().max(r.abs()),
                "{kind}: {l} vs {r}"
            );
            assert!(dot(&x, &bx) > 0.0 && dot(&y, &by) > 0.0);
        }
    }

    /// Operator complexity: 1 without coarse levels; on the halved 2D grid each level has
    /// a quarter of the nodes of the one above and the same stencil, so the sum is below
    /// 1 + 1/4 + 1/16 + … = 4/3 (plus the boundary's share).
    #[test]
    fn operator_complexity_counts_every_level() {
        let h = hierarchy(MeshPattern::Diagonal);
        let c = h.operator_complexity();
        assert!(
            h.n_levels() >= 2 && c > 1.2 && c < 1.4,
            "{} levels, {c}",
            h.n_levels()
        );
        let coarsest = h.operator_at(h.n_levels() - 1).unwrap();
        let single = Hierarchy::new(
            Arc::new(coarsest.clone()),
            Blocks::scalar(coarsest.nrows),
            Coarsening::Geometric {
                prolongators: vec![],
                blocks: vec![],
                below: None,
            },
            Params::default(),
        )
        .unwrap();
        assert_eq!(single.operator_complexity(), 1.0);
    }

    /// Shedding the f64 operators of levels with an f32 copy leaves the V-cycle the same bits
    /// and the sizes and operator complexity as they were; without f32 copies nothing goes.
    #[test]
    fn shed_operators_leave_the_v_cycle_and_the_counts_unchanged() {
        let build = |mixed: bool| {
            let mesh = Mesh::rectangle(1.0, 1.0, 32, 32, MeshPattern::Cross);
            let geo = Geometry::new(&mesh);
            let m = assembly::mass_in_pattern(&mesh, &geo);
            let l = assembly::laplacian_in_pattern_of(&mesh, &geo, &m);
            let h = assembly::combine(64.0, &m, 1.0, &l);
            let (blocks, levels) = multilevel::scalar_levels(&mesh, h.nrows);
            let params = Params {
                mixed,
                coarse_size: 100,
                ..Params::default()
            };
            Hierarchy::new(Arc::new(h), blocks, levels, params).unwrap()
        };
        let whole = Arc::new(build(true));
        assert!(whole.n_levels() >= 3, "{:?}", whole.sizes());
        let mut shed = build(true);
        shed.shed_operators(&[1]);
        assert!(shed.operator_at(1).is_some());
        for l in (0..shed.n_levels() - 1).filter(|&l| l != 1) {
            assert!(shed.operator_at(l).is_none(), "level {l}");
        }
        assert!(
            shed.operator_at(shed.n_levels() - 1).is_some(),
            "the coarsest"
        );
        assert_eq!(shed.sizes(), whole.sizes());
        assert_eq!(shed.operator_complexity(), whole.operator_complexity());
        let n = whole.sizes()[0];
        let r: Vec<f64> = (0..n).map(|i| (0.9 * i as f64).sin()).collect();
        let apply = |h: &Arc<Hierarchy>| {
            let mut z = vec![0.0; n];
            h.vcycle().apply(&r, &mut z);
            z
        };
        assert_eq!(apply(&Arc::new(shed)), apply(&whole));
        // What the velocity step keeps of K's hierarchy: no level's f64 operator (K is held
        // in node blocks); A₁ read back for the truncated cycles is each entry rounded to f32.
        let mut none = build(true);
        none.shed_operators(&[]);
        assert!(none.operator_at(1).is_none());
        let widened = none.operator_in_f64(1).expect("level 1");
        let kept = whole.operator_at(1).expect("kept");
        let rows = |a: &Csr| -> Vec<Vec<(u32, f64)>> {
            (0..a.nrows)
                .map(|i| {
                    let row = a.indptr[i]..a.indptr[i + 1];
                    let entries = a.indices[row.clone()].iter().zip(&a.values[row]);
                    entries
                        .map(|(&j, &v)| (j, v as f32 as f64))
                        .filter(|&(_, v)| v != 0.0)
                        .collect()
                })
                .collect()
        };
        assert_eq!(rows(&widened), rows(kept));
        assert!(matches!(whole.operator_in_f64(1), Some(Cow::Borrowed(_))));
        let mut plain = build(false);
        plain.shed_operators(&[]);
        assert!((0..plain.n_levels()).all(|l| plain.operator_at(l).is_some()));
    }
}
