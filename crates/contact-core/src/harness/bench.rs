//! Speed figures of a preset at h = k = 1/L on either linear path: end-to-end time, time per
//! step, and per-step time divided by one solve with K_II (a substitution pair with the
//! direct factor, a multigrid-CG solve on the other path) and by one product with K — ratios
//! that are stable on a noisy shared machine, measured in the same run — with the Krylov
//! iterations and the predicted and measured peak memory of each run.

use crate::linalg::LinearPath;
use crate::run::{Hooks, Run};
use crate::scene::{self, presets, Overrides};
use crate::solve::stepper::Simulation;
use crate::solve::SolverSettings;
use serde::Serialize;
use std::ops::ControlFlow;
use std::time::Instant;

/// Products with K timed before each step (the matvec figure is the median of all of them
/// and of 21 after the run).
const PRODUCTS_PER_STEP: usize = 3;

#[derive(Debug, Clone, Serialize)]
pub struct BenchLevel {
    pub level: usize,
    pub nodes: usize,
    pub unknowns: usize,
    pub steps: usize,
    /// Validation + meshing + assembly + factorisations.
    pub setup_s: f64,
    pub solve_s: f64,
    pub total_s: f64,
    pub per_step_s: f64,
    /// Median time of one forward+backward substitution with the K_II factor.
    pub substitution_s: f64,
    pub step_over_substitution: f64,
    /// Median time of one product with the free-DOF velocity operator K.
    pub matvec_s: f64,
    /// Time per step in products with K (the "matvec-equivalents").
    pub step_over_matvec: f64,
    /// "direct (Cholesky)", "multigrid (geometric, 4 levels)", ...
    pub linear_solver: String,
    /// The Tresca bound g the scene's friction was replaced with (None: the scene's law).
    pub friction_g: Option<f64>,
    /// Steps in which some Γ3 node slipped, the most slipping nodes of a step and the most
    /// iterations of one step's friction solver (Newton iterations on the multigrid path).
    pub steps_with_slip: usize,
    pub max_slip_nodes: usize,
    pub velocity_max_iterations: usize,
    /// Total time against the first friction bound's run at the same level (1 for it).
    pub time_over_first_g: f64,
    /// Threads of the run ([`SolverSettings::threads`]).
    pub threads: usize,
    /// Total time of the first thread count's run at the same level and bound divided by
    /// this run's (1 for it): the speed-up, measured in the same process.
    pub speedup: f64,
    /// Most Krylov iterations of one step's velocity and damage solves (0 on the direct path).
    pub velocity_max_krylov_iterations: usize,
    pub damage_max_krylov_iterations: usize,
    /// Mean Krylov iterations of a step's velocity solves (0 on the direct path).
    pub velocity_mean_krylov_iterations: f64,
    pub w_v: f64,
    pub zeta_l2: f64,
    /// The peak predicted before the run ([`crate::memory::predict`]), MiB.
    pub predicted_mib: f64,
    /// Peak resident memory of this run (VmHWM, reset before it), MiB; None off Linux.
    pub peak_rss_mib: Option<f64>,
    /// `peak_rss_mib` in bytes per velocity unknown.
    pub bytes_per_unknown: Option<f64>,
    /// The velocity hierarchy's operator complexity (multigrid path only).
    pub operator_complexity: Option<f64>,
}

#[derive(Debug, Clone, Serialize)]
pub struct BenchReport {
    pub preset: String,
    pub repeat: usize,
    pub levels: Vec<BenchLevel>,
}

impl BenchReport {
    /// A plain-text table for humans.
    pub fn table(&self) -> String {
        let mut s = String::from("  1/h       g thr speedup   nodes  unknowns steps  setup_s  solve_s  total_s  vs_g0  step_ms  subst_ms  step/subst  matvec_ms  step/matvec  slip_steps  slip_max  newton  its_v  its_v_mean  its_d  pred_MiB  peak_MiB  B/unknown  op_cx  solver\n");
        for l in &self.levels {
            s += &format!(
                "{:5} {:>7} {:3} {:7.2} {:7} {:9} {:5} {:8.4} {:8.4} {:8.4} {:6.2} {:8.3} {:9.3} {:11.2} {:10.3} {:12.1} {:11} {:9} {:7} {:6} {:11.2} {:6} {:9.0} {:9} {:10} {:6}  {}\n",
                l.level,
                l.friction_g.map_or("-".into(), |g| format!("{g}")),
                l.threads,
                l.speedup,
                l.nodes,
                l.unknowns,
                l.steps,
                l.setup_s,
                l.solve_s,
                l.total_s,
                l.time_over_first_g,
                1e3 * l.per_step_s,
                1e3 * l.substitution_s,
                l.step_over_substitution,
                1e3 * l.matvec_s,
                l.step_over_matvec,
                l.steps_with_slip,
                l.max_slip_nodes,
                l.velocity_max_iterations,
                l.velocity_max_krylov_iterations,
                l.velocity_mean_krylov_iterations,
                l.damage_max_krylov_iterations,
                l.predicted_mib,
                l.peak_rss_mib.map_or("-".into(), |m| format!("{m:.0}")),
                l.bytes_per_unknown.map_or("-".into(), |b| format!("{b:.0}")),
                l.operator_complexity.map_or("-".into(), |c| format!("{c:.2}")),
                l.linear_solver,
            );
        }
        s
    }
}

/// The preset of README's speed table.
pub const DEFAULT_PRESET: &str = "paper-convergence";

/// Runs `preset` (2D or 3D) at each level, each `repeat` times (fastest end-to-end run
/// reported), on the path `linear` (None: the scene's own `solver.linear`), once per Tresca
/// bound in `friction_g` (empty: the scene's own friction law), with each thread count of
/// `threads` in turn.
pub fn run(
    preset: &str,
    levels: &[usize],
    repeat: usize,
    linear: Option<LinearPath>,
    friction_g: &[f64],
    threads: &[usize],
) -> Result<BenchReport, Box<dyn std::error::Error>> {
    let mut out = Vec::new();
    let bounds: Vec<Option<f64>> = if friction_g.is_empty() {
        vec![None]
    } else {
        friction_g.iter().map(|&g| Some(g)).collect()
    };
    for &level in levels {
        let mut first = None;
        for &g in &bounds {
            let mut one_thread_count = None;
            for &t in threads {
                let mut best: Option<BenchLevel> = None;
                for _ in 0..repeat {
                    let r = one(preset, level, linear, g, t)?;
                    if best.as_ref().is_none_or(|b| r.total_s < b.total_s) {
                        best = Some(r);
                    }
                }
                let mut best = best.expect("repeat ≥ 1");
                let t0 = *first.get_or_insert(best.total_s);
                let t1 = *one_thread_count.get_or_insert(best.total_s);
                best.time_over_first_g = best.total_s / t0;
                best.speedup = t1 / best.total_s;
                out.push(best);
            }
        }
    }
    Ok(BenchReport {
        preset: preset.to_string(),
        repeat,
        levels: out,
    })
}

fn one(
    preset: &str,
    level: usize,
    linear: Option<LinearPath>,
    friction_g: Option<f64>,
    threads: usize,
) -> Result<BenchLevel, Box<dyn std::error::Error>> {
    reset_peak_rss();
    let start = Instant::now();
    let mut problem = leveled(preset, level)?;
    // A benchmark stores no fields, so its run keeps nothing for them.
    problem.output.fields = crate::problem::FieldSet::default();
    if let Some(path) = linear {
        problem.linear = path;
    }
    if let Some(g) = friction_g {
        problem.friction = crate::problem::FrictionLaw::Tresca { g };
    }
    match problem.dim() {
        2 => measure::<2>(problem, level, start, threads),
        _ => measure::<3>(problem, level, start, threads),
    }
}

/// `preset` validated at h = k = 1/`level`.
fn leveled(
    preset: &str,
    level: usize,
) -> Result<crate::problem::Problem, Box<dyn std::error::Error>> {
    let mut doc = presets::get(preset).ok_or("unknown preset")?;
    let frac = serde_json::Value::String(format!("1/{level}"));
    scene::apply_overrides(
        &mut doc,
        &Overrides {
            h: Some(frac.clone()),
            k: Some(frac),
            t_end: None,
        },
    );
    Ok(scene::validate(&doc)?)
}

/// A measured run's figures, gathered by its hooks: products with K timed before every
/// step, under the load the steps ran under, not only after the run (the machines are
/// shared and one product's time drifts by ±30 % over a run); the steps' times and solver
/// figures.
#[derive(Default)]
struct Tally {
    products: Vec<f64>,
    solve_s: f64,
    last: Option<crate::solve::stepper::StepReport>,
    its_v: usize,
    its_d: usize,
    its_v_sum: usize,
    slip_steps: usize,
    slip_max: usize,
    newton: usize,
}

impl<const D: usize> Hooks<D> for Tally {
    type Stop = std::convert::Infallible;

    fn before_step(&mut self, run: &Run<D>) -> ControlFlow<Self::Stop> {
        self.products
            .extend(run.in_pool(|sim| sim.time_products(PRODUCTS_PER_STEP)));
        ControlFlow::Continue(())
    }

    fn after_step(
        &mut self,
        run: &Run<D>,
        record: &crate::solve::stepper::StepReport,
    ) -> ControlFlow<Self::Stop> {
        self.solve_s += run.last_step_seconds();
        self.slip_steps += usize::from(record.slip_nodes > 0);
        self.slip_max = self.slip_max.max(record.slip_nodes);
        self.newton = self.newton.max(record.velocity.iterations);
        self.its_v = self.its_v.max(record.velocity.krylov_iterations);
        self.its_v_sum += record.velocity.krylov_iterations;
        self.its_d = self
            .its_d
            .max(record.damage.map_or(0, |d| d.krylov_iterations));
        self.last = Some(record.clone());
        ControlFlow::Continue(())
    }
}

/// Runs a validated problem to the end and measures it (the clock started at `start`).
fn measure<const D: usize>(
    problem: crate::problem::Problem,
    level: usize,
    start: Instant,
    threads: usize,
) -> Result<BenchLevel, Box<dyn std::error::Error>> {
    let settings = SolverSettings {
        threads,
        ..SolverSettings::default()
    };
    let mut run = Run::<D>::new(problem, settings)?;
    let setup_s = start.elapsed().as_secs_f64();
    let mut tally = Tally::default();
    let ControlFlow::Continue(()) = run.drive(&mut tally)?;
    let Tally {
        mut products,
        solve_s,
        last,
        its_v,
        its_d,
        its_v_sum,
        slip_steps,
        slip_max,
        newton,
    } = tally;
    let total_s = setup_s + solve_s;
    let mut subs: Vec<f64> =
        run.in_pool_mut(|sim| (0..21).map(|_| sim.time_one_substitution()).collect());
    subs.sort_by(f64::total_cmp);
    let substitution_s = subs[subs.len() / 2];
    products.extend(run.in_pool(|sim| sim.time_products(21)));
    let sim = run.sim();
    products.sort_by(f64::total_cmp);
    let matvec_s = products[products.len() / 2];
    let steps = sim.problem.steps;
    let last = last.ok_or("no steps")?;
    let peak = peak_rss_mib();
    Ok(BenchLevel {
        level,
        nodes: sim.mesh.n_nodes(),
        unknowns: sim.dofs.n_free(),
        steps,
        setup_s,
        solve_s,
        total_s,
        per_step_s: solve_s / steps as f64,
        substitution_s,
        step_over_substitution: solve_s / steps as f64 / substitution_s,
        matvec_s,
        step_over_matvec: solve_s / steps as f64 / matvec_s,
        linear_solver: sim.linear_solver(),
        friction_g: match &sim.problem.friction {
            crate::problem::FrictionLaw::Tresca { g } => Some(*g),
            _ => None,
        },
        steps_with_slip: slip_steps,
        max_slip_nodes: slip_max,
        velocity_max_iterations: newton,
        time_over_first_g: 1.0,
        threads,
        speedup: 1.0,
        velocity_max_krylov_iterations: its_v,
        velocity_mean_krylov_iterations: its_v_sum as f64 / steps as f64,
        damage_max_krylov_iterations: its_d,
        w_v: last.w_v,
        zeta_l2: last.zeta_l2,
        predicted_mib: sim.predicted_bytes as f64 / (1u64 << 20) as f64,
        peak_rss_mib: peak,
        bytes_per_unknown: peak.map(|m| m * (1u64 << 20) as f64 / sim.dofs.n_free() as f64),
        operator_complexity: sim.operator_complexity(),
    })
}

/// Resets VmHWM to the current resident size (Linux `clear_refs` 5), so that each run's
/// peak is its own; without it the figure is the process's peak so far.
fn reset_peak_rss() {
    let _ = std::fs::write("/proc/self/clear_refs", "5");
}

fn peak_rss_mib() -> Option<f64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kb: f64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb / 1024.0)
}

/// The two ways of forming the Schur complement S onto the contact DOFs
/// ([`crate::linalg::bordered`]), measured on one scene's velocity operator.
#[derive(Debug, Clone, Serialize)]
pub struct SchurLevel {
    pub level: usize,
    pub unknowns: usize,
    pub contact_dofs: usize,
    /// The factorisation of K_II every run makes (for scale).
    pub factor_s: f64,
    pub factor_nnz: usize,
    /// S from m solves with that factor, in blocks.
    pub blocked_s: f64,
    /// S as L_CC L_CCᵀ from a factor of K with the contact DOFs last.
    pub trailing_s: f64,
    /// max |S_trailing − S_blocked| / max |S_blocked|.
    pub relative_difference: f64,
}

/// [`SchurLevel`] of `preset` at each 1/h = 1/k in `levels` (fastest of `repeat`).
pub fn schur(
    preset: &str,
    levels: &[usize],
    repeat: usize,
) -> Result<Vec<SchurLevel>, Box<dyn std::error::Error>> {
    use crate::linalg::{schur_complement, Cholesky, SchurPath};
    let mut out = Vec::new();
    for &level in levels {
        let problem = leveled(preset, level)?;
        let (k, n_i) = velocity_operator(problem)?;
        let t0 = Instant::now();
        let k_ii = Cholesky::new(k.block(0..n_i, 0..n_i).lower_csc().as_ref())?;
        let factor_s = t0.elapsed().as_secs_f64();
        let best = |path: SchurPath| {
            let mut fastest: Option<(f64, nalgebra::DMatrix<f64>)> = None;
            for _ in 0..repeat {
                let t = Instant::now();
                let (s, taken) = schur_complement(&k, n_i, &k_ii, path);
                let secs = t.elapsed().as_secs_f64();
                assert_eq!(taken, path, "no fallback on a velocity operator");
                if fastest.as_ref().is_none_or(|f| secs < f.0) {
                    fastest = Some((secs, s));
                }
            }
            fastest.expect("repeat ≥ 1")
        };
        let (blocked_s, s_b) = best(SchurPath::BlockedSolves);
        let (trailing_s, s_t) = best(SchurPath::TrailingBlock);
        let scale = s_b.amax().max(f64::MIN_POSITIVE);
        out.push(SchurLevel {
            level,
            unknowns: k.nrows,
            contact_dofs: k.nrows - n_i,
            factor_s,
            factor_nnz: k_ii.nnz_l(),
            blocked_s,
            trailing_s,
            relative_difference: (&s_t - &s_b).amax() / scale,
        });
    }
    Ok(out)
}

/// The factor of K_II under one ordering: its fill and times.
#[derive(Debug, Clone, Serialize)]
pub struct OrderingFigures {
    pub ordering: crate::linalg::cholesky::Ordering,
    /// Stored entries of L.
    pub nnz_l: usize,
    /// Ordering, symbolic analysis and first numeric factorisation.
    pub analyse_and_factor_s: f64,
    /// One numeric factorisation on the analysed pattern (fastest of `repeat`).
    pub numeric_s: f64,
}

/// AMD against nested dissection on K_II of one level.
#[derive(Debug, Clone, Serialize)]
pub struct OrderingLevel {
    pub level: usize,
    pub unknowns: usize,
    pub amd: OrderingFigures,
    pub nested_dissection: OrderingFigures,
    /// nnz(L) of AMD over that of nested dissection.
    pub fill_ratio: f64,
    /// Numeric factor time of AMD over that of nested dissection.
    pub numeric_ratio: f64,
}

/// The free-DOF velocity operator K of a problem's set-up and its interior count n_I.
fn velocity_operator(
    problem: crate::problem::Problem,
) -> Result<(crate::linalg::Csr, usize), Box<dyn std::error::Error>> {
    let (k, n_i) = match problem.dim() {
        2 => {
            let sim = Simulation::<2>::new(problem, SolverSettings::default())?;
            let (k, n_i) = sim.velocity_operator();
            (k.to_csr().into_owned(), n_i)
        }
        _ => {
            let sim = Simulation::<3>::new(problem, SolverSettings::default())?;
            let (k, n_i) = sim.velocity_operator();
            (k.to_csr().into_owned(), n_i)
        }
    };
    Ok((k, n_i))
}

/// [`OrderingLevel`] of `preset` at each 1/h = 1/k in `levels` (numeric times the fastest
/// of `repeat`). The scene is set up on the multigrid path, so no factor is made before.
pub fn orderings(
    preset: &str,
    levels: &[usize],
    repeat: usize,
) -> Result<Vec<OrderingLevel>, Box<dyn std::error::Error>> {
    use crate::linalg::cholesky::{Cholesky, Ordering};
    let mut out = Vec::new();
    for &level in levels {
        let mut problem = leveled(preset, level)?;
        problem.linear = LinearPath::Multigrid;
        let (k, n_i) = velocity_operator(problem)?;
        let lower = k.block(0..n_i, 0..n_i).lower_csc();
        let figures = |ordering: Ordering| -> Result<OrderingFigures, Box<dyn std::error::Error>> {
            let t = Instant::now();
            let mut chol = Cholesky::by(lower.as_ref(), ordering)?;
            let analyse_and_factor_s = t.elapsed().as_secs_f64();
            let mut numeric_s = f64::INFINITY;
            for _ in 0..repeat {
                let t = Instant::now();
                chol.refactor(lower.as_ref())?;
                numeric_s = numeric_s.min(t.elapsed().as_secs_f64());
            }
            Ok(OrderingFigures {
                ordering,
                nnz_l: chol.nnz_l(),
                analyse_and_factor_s,
                numeric_s,
            })
        };
        let amd = figures(Ordering::Amd)?;
        let nested_dissection = figures(Ordering::NestedDissection)?;
        out.push(OrderingLevel {
            level,
            unknowns: n_i,
            fill_ratio: amd.nnz_l as f64 / nested_dissection.nnz_l as f64,
            numeric_ratio: amd.numeric_s / nested_dissection.numeric_s,
            amd,
            nested_dissection,
        });
    }
    Ok(out)
}

/// The paper's Tables 1 and 2 computed together (one shared h = k = 1/128 reference, a
/// fresh cache each repetition), against the reference run alone measured in the same
/// process: the ratio says what the ten ladder levels and all the error evaluations add to
/// the one run a user would make anyway.
#[derive(Debug, Clone, Serialize)]
pub struct TablesBench {
    pub threads: usize,
    /// Best end-to-end time of both tables (validation, every run, errors, tabulation).
    pub tables_s: f64,
    /// Best time of the reference run alone (h = k = 1/128, end to end).
    pub reference_alone_s: f64,
    pub tables_over_reference: f64,
    /// Repetitions (the fastest of each is reported).
    pub runs: usize,
}

pub fn tables(repeat: usize, threads: usize) -> Result<TablesBench, Box<dyn std::error::Error>> {
    use crate::study;
    let plans: Vec<study::Plan> = ["paper-table-1", "paper-table-2"]
        .iter()
        .map(|n| study::presets::get(n).ok_or("preset"))
        .map(|d| Ok(study::parse(&d?, "")?.0))
        .collect::<Result<_, Box<dyn std::error::Error>>>()?;
    let exec = study::Execution {
        threads,
        ..Default::default()
    };
    let (mut tables_s, mut reference_alone_s) = (f64::INFINITY, f64::INFINITY);
    for _ in 0..repeat {
        reference_alone_s =
            reference_alone_s.min(one("paper-convergence", 128, None, None, 1)?.total_s);
        let start = Instant::now();
        let cache = study::ReferenceCache::new(1);
        study::run_many(&plans, &cache, exec, &|_, _| {
            std::ops::ControlFlow::Continue(())
        })?;
        tables_s = tables_s.min(start.elapsed().as_secs_f64());
    }
    Ok(TablesBench {
        threads,
        tables_s,
        reference_alone_s,
        tables_over_reference: tables_s / reference_alone_s,
        runs: repeat,
    })
}
