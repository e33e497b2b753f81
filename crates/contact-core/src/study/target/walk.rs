//! Running a target study: the pilot ladders, the fit, and the walk from the cheapest
//! candidate up, each level checked by its (2h, 2k) error bar; the chosen run with its
//! stored steps.

use super::chosen::run_chosen;
use super::planner::{frontier, unreachable};
use super::*;
use crate::solve::SolverSettings;

/// |I f_c − f_f| / |f_f| at t = T between two runs of nested meshes (f_f on the finer or the
/// same mesh): w and u in |·|_V (the coarse strain taken on each fine cell's parent, exact),
/// ζ in |·|_Z0 (nodal interpolation, exact for P1). 0 when both vanish.
pub fn relative_difference<const D: usize>(
    coarse: &LevelRun<D>,
    fine: &LevelRun<D>,
    quantity: Quantity,
) -> f64 {
    let (diff, norm) = difference(coarse, fine, quantity);
    if diff == 0.0 {
        0.0
    } else if norm > 0.0 {
        diff / norm
    } else {
        f64::INFINITY
    }
}

/// |I f_c − f_f| and |f_f| at t = T (see [`relative_difference`]).
pub fn difference<const D: usize>(
    coarse: &LevelRun<D>,
    fine: &LevelRun<D>,
    quantity: Quantity,
) -> (f64, f64) {
    let (Some(c), Some(f)) = (coarse.snapshots.last(), fine.snapshots.last()) else {
        return (f64::NAN, f64::NAN);
    };
    let geo = Geometry::new(&fine.mesh);
    let (diff, norm) = match quantity {
        Quantity::W | Quantity::U => {
            let pick = |s: &Snapshot| -> Vec<f64> {
                if quantity == Quantity::W {
                    s.w.clone()
                } else {
                    s.u.clone()
                }
            };
            let parents = parent_cells(&coarse.mesh, &fine.mesh).expect("nested meshes");
            let coarse_geo = Geometry::new(&coarse.mesh);
            let sc = strains(&coarse.mesh, &coarse_geo, &pick(c));
            let sf = strains(&fine.mesh, &geo, &pick(f));
            let s = sym_len(D);
            let mut d = [0.0; 6];
            let (mut diff2, mut norm2) = (0.0, 0.0);
            for ((ef, &p), a) in sf.chunks_exact(s).zip(&parents).zip(geo.measures()) {
                let ec = &sc[s * p as usize..][..s];
                for ((d, x), y) in d.iter_mut().zip(ef).zip(ec) {
                    *d = x - y;
                }
                diff2 += a * double_dot::<D>(&d[..s]);
                norm2 += a * double_dot::<D>(ef);
            }
            (diff2.sqrt(), norm2.sqrt())
        }
        Quantity::Zeta => {
            let mass = assembly::mass(&fine.mesh, &geo);
            let mut scratch = vec![0.0; fine.mesh.n_nodes()];
            let z = prolongate(&coarse.mesh, &c.zeta, 1, &fine.mesh).expect("nested meshes");
            let dz: Vec<f64> = f.zeta.iter().zip(&z).map(|(a, b)| a - b).collect();
            (
                norms::mass_norm(&mass, &dz, &mut scratch),
                norms::mass_norm(&mass, &f.zeta, &mut scratch),
            )
        }
    };
    (diff, norm)
}

/// |f(T)| of a run in the quantity's norm.
fn norm_at_end<const D: usize>(run: &LevelRun<D>, quantity: Quantity) -> f64 {
    difference(run, run, quantity).1
}

/// [`run`] in dimension D.
pub(super) fn run_in<const D: usize>(
    planner: &Planner,
    progress: &(dyn Fn(usize, usize) -> ControlFlow<()> + Sync),
    sink: &mut dyn Sink,
) -> Result<TargetResult, StudyError> {
    let (spec, exec) = (planner.spec, planner.exec);
    let keep_u = spec.quantity == Quantity::U;
    let (n0, s0) = (spec.n0, PILOT_STEPS);
    let PilotLadders {
        h: mut h_ladder,
        k: mut k_ladder,
        n_k,
        s_h,
    } = spec.first_ladders();
    let done_steps = AtomicUsize::new(0);
    let total_steps = AtomicUsize::new(0);
    let tick = || {
        let d = done_steps.fetch_add(1, Ordering::Relaxed) + 1;
        progress(d, total_steps.load(Ordering::Relaxed).max(d))
    };
    let mut runs: BTreeMap<(usize, usize), LevelRun<D>> = BTreeMap::new();
    let (mut model, cost, choice, candidates, scale) = loop {
        let wanted: BTreeSet<(usize, usize)> = h_ladder
            .iter()
            .map(|&n| (n, s_h))
            .chain(k_ladder.iter().map(|&s| (n_k, s)))
            .filter(|l| !runs.contains_key(l))
            .collect();
        if !wanted.is_empty() {
            let jobs: Vec<Work> = wanted
                .iter()
                .map(|&(n, steps)| Work {
                    problem: planner.problem((n, steps)),
                    keep: BTreeSet::from([steps]),
                    is_reference: false,
                    // The k-ladder's runs share the mesh and its factored operator.
                    share: (wanted.iter().filter(|l| l.0 == n).count() > 1)
                        .then(|| ("target".to_string(), n)),
                    keep_u,
                })
                .collect();
            total_steps.fetch_add(wanted.iter().map(|l| l.1).sum(), Ordering::Relaxed);
            let tick2 = |_: usize, _: usize| tick();
            let done = run_all::<D>(jobs, exec, 0, &tick2)?;
            for (level, d) in wanted.iter().zip(done) {
                if let Done::Level(r) = d {
                    runs.insert(*level, r);
                }
            }
        }
        // One scale for every difference: the largest norm among the pilots (coarse runs
        // underestimate it: stiffer meshes, damped coarse steps), the nearest to the
        // solution's that the pilots know.
        let scale = runs
            .values()
            .map(|r| norm_at_end(r, spec.quantity))
            .fold(0.0, f64::max);
        let diffs = |levels: Vec<(usize, usize)>, x: &dyn Fn((usize, usize)) -> f64| {
            levels
                .windows(2)
                .map(|w| {
                    let (d, _) = difference(&runs[&w[0]], &runs[&w[1]], spec.quantity);
                    (x(w[0]), if d == 0.0 { 0.0 } else { d / scale })
                })
                .collect::<Vec<_>>()
        };
        let model = ErrorModel {
            h: plan::fit_part(&diffs(h_ladder.iter().map(|&n| (n, s_h)).collect(), &|l| {
                planner.h(l.0)
            })),
            k: plan::fit_part(&diffs(k_ladder.iter().map(|&s| (n_k, s)).collect(), &|l| {
                planner.k(l.1)
            })),
        };
        let timings: Vec<Timing> = runs
            .iter()
            .map(|(&l, r)| Timing {
                unknowns: planner.unknowns(l),
                steps: l.1,
                seconds: r.seconds,
            })
            .collect();
        let cost = plan::fit_cost(&timings);
        let candidates = planner.candidates(&model, &cost, &|l| runs.contains_key(&l));
        let feasible: Vec<Candidate> = candidates
            .iter()
            .filter(|c| c.1.is_none())
            .map(|c| c.0)
            .collect();
        let choice = plan::cheapest(&feasible, spec.error);
        let mut extended = false;
        // Within reach, the walk's own levels refine the fit. Out of reach by this fit, the
        // pilots are refined towards the most accurate run within the limits (a
        // pre-asymptotic fit may be what puts the target out of reach), but only by levels
        // costing at most 4 × the pilots so far: a refusal must stay cheap.
        let spent: f64 = runs.values().map(|r| r.seconds).sum();
        let allowed = match choice {
            Some(_) => None,
            None => plan::most_accurate(&feasible)
                .map(|c| (PILOT_SHARE * c.predicted_seconds).min(4.0 * spent)),
        };
        if let Some(allowed) = allowed {
            let affordable = |level: (usize, usize)| {
                cost.predict(planner.unknowns(level), level.1) <= allowed
                    && planner.breaks(level).is_none()
            };
            let next_h = (h_ladder.last().unwrap() * 2, s_h);
            if h_ladder.len() < MAX_PILOT_LEVELS && affordable(next_h) {
                h_ladder.push(next_h.0);
                extended = true;
            }
            let next_k = (n_k, k_ladder.last().unwrap() * 2);
            if k_ladder.len() < MAX_PILOT_LEVELS && affordable(next_k) {
                k_ladder.push(next_k.1);
                extended = true;
            }
        }
        if !extended {
            break (model, cost, choice, candidates, scale);
        }
    };
    let frontier = frontier(&candidates);
    if choice.is_none() {
        return Err(unreachable(planner, &model, &cost, &candidates));
    }

    // The walk: from the cheapest candidate up, each level checked by its (2h, 2k) error bar
    // and, while the bar is above the target, refined in h or in k, whichever the model says
    // buys more error per unit of cost. A level a pilot ran is checked on the pilot's fields
    // and run again (for its stored steps) only when it passes.
    let mut attempts: Vec<Attempt> = Vec::new();
    let mut made: BTreeMap<(usize, usize), LevelRun<D>> = BTreeMap::new();
    let mut level = (n0 << 1, s0 << 1);
    let mut previous: Option<(usize, usize)> = None;
    let (mut h_points, mut k_points) = (model.h.points.clone(), model.k.points.clone());
    // The (2h, 2k) companion run of a level, keeping its last step.
    let companion_work = |companion: (usize, usize)| Work {
        problem: planner.problem(companion),
        keep: BTreeSet::from([companion.1]),
        is_reference: false,
        share: None,
        keep_u,
    };
    let summary = loop {
        let companion_level = (level.0 / 2, level.1 / 2);
        let companion_reused =
            made.contains_key(&companion_level) || runs.contains_key(&companion_level);
        let pilot = runs.contains_key(&level);
        if !companion_reused && (pilot || exec.threads < 2) {
            total_steps.fetch_add(companion_level.1, Ordering::Relaxed);
            let work = companion_work(companion_level);
            let c = levels::run_level::<D>(&work, exec.settings, &tick, None)?;
            made.insert(companion_level, c);
        }
        if let (Some(from), true) = (previous, pilot) {
            let prev = made.get(&from).or_else(|| runs.get(&from)).expect("ran");
            learn(
                planner,
                scale,
                (from, prev),
                (level, &runs[&level]),
                &mut h_points,
                &mut k_points,
            );
            model = ErrorModel {
                h: plan::fit_part(&h_points),
                k: plan::fit_part(&k_points),
            };
        }
        let pilot_bar = pilot.then(|| {
            let c = made
                .get(&companion_level)
                .or_else(|| runs.get(&companion_level))
                .expect("the companion ran");
            relative_difference(c, &runs[&level], spec.quantity)
        });
        let next = next_level(planner, &model, &cost, level, &|l| {
            made.contains_key(&l) || runs.contains_key(&l)
        });
        let attempt = |model: &ErrorModel,
                       estimated: f64,
                       seconds: f64,
                       companion: &LevelRun<D>,
                       reused: bool| {
            let (h, k) = (planner.h(level.0), planner.k(level.1));
            Attempt {
                h,
                k,
                refine: spec.given_mesh().then(|| level.0.trailing_zeros() as usize),
                steps: level.1,
                unknowns: planner.unknowns(level) as usize,
                predicted_error: model.predict(h, k),
                estimated_error: estimated,
                check_passed: estimated <= spec.error,
                predicted_seconds: cost.predict(planner.unknowns(level), level.1),
                seconds,
                companion: Companion {
                    h: planner.h(companion_level.0),
                    k: planner.k(companion_level.1),
                    seconds: companion.seconds,
                    reused,
                },
            }
        };
        if let (Some(bar), Some(to)) = (pilot_bar, next) {
            if bar > spec.error {
                let c = made
                    .get(&companion_level)
                    .or_else(|| runs.get(&companion_level))
                    .expect("the companion ran");
                attempts.push(attempt(
                    &model,
                    bar,
                    runs[&level].seconds,
                    c,
                    companion_reused,
                ));
                previous = Some(level);
                level = to;
                continue;
            }
        }
        // The level is run with its stored steps (beside its companion, if that is new), and
        // estimated where an adaptive mesh may replace it.
        let mut problem = planner.problem(level);
        problem.output.estimate |= spec.meshes == Meshes::Auto;
        sink.restart().map_err(StudyError::Output)?;
        total_steps.fetch_add(level.1, Ordering::Relaxed);
        let (run, summary) = if made.contains_key(&companion_level)
            || runs.contains_key(&companion_level)
        {
            run_chosen::<D>(&problem, exec, keep_u, sink, &tick)?
        } else {
            total_steps.fetch_add(companion_level.1, Ordering::Relaxed);
            let work = companion_work(companion_level);
            // The two runs share the study's threads.
            let half = Execution {
                threads: (exec.threads / 2).max(1),
                ..exec
            };
            let companion_settings = SolverSettings {
                threads: half.threads,
                ..exec.settings
            };
            let (chosen, companion) = std::thread::scope(|s| {
                let c = s.spawn(|| levels::run_level::<D>(&work, companion_settings, &tick, None));
                let chosen = run_chosen::<D>(&problem, half, keep_u, sink, &tick);
                (chosen, c.join().expect("companion run panicked"))
            });
            made.insert(companion_level, companion?);
            chosen?
        };
        let companion = made
            .get(&companion_level)
            .or_else(|| runs.get(&companion_level))
            .expect("the companion ran");
        let estimated = relative_difference(companion, &run, spec.quantity);
        if let (Some(from), false) = (previous, pilot) {
            let prev = made.get(&from).or_else(|| runs.get(&from)).expect("ran");
            learn(
                planner,
                scale,
                (from, prev),
                (level, &run),
                &mut h_points,
                &mut k_points,
            );
            model = ErrorModel {
                h: plan::fit_part(&h_points),
                k: plan::fit_part(&k_points),
            };
        }
        attempts.push(attempt(
            &model,
            estimated,
            run.seconds,
            companion,
            companion_reused,
        ));
        let next = next_level(planner, &model, &cost, level, &|l| {
            made.contains_key(&l) || runs.contains_key(&l)
        });
        match next {
            Some(to) if estimated > spec.error => {
                made.insert(level, run);
                previous = Some(level);
                level = to;
            }
            _ => break summary,
        }
    };
    let (meshes, summary, final_mesh) = match spec.meshes {
        Meshes::Uniform => (MeshChoice::uniform(), summary, None),
        Meshes::Auto => {
            let grow = |n: usize| {
                total_steps.fetch_add(n, Ordering::Relaxed);
            };
            match super::adaptive::consider::<D>(planner, level, &summary, sink, &grow, &tick)? {
                (choice, Some((adaptive, mesh))) => (choice, adaptive, Some(mesh)),
                (choice, None) => (choice, summary, None),
            }
        }
    };
    let chosen = attempts.last().cloned().expect("one attempt");
    let pilots = runs
        .iter()
        .map(|(&(n, steps), r)| PilotRow {
            ladder: if steps == s_h { "h" } else { "k" },
            h: planner.h(n),
            k: planner.k(steps),
            unknowns: planner.unknowns((n, steps)) as usize,
            steps,
            seconds: r.seconds,
        })
        .collect();
    let last_level = ((1.0 / chosen.h).round() as usize, chosen.steps);
    Ok(TargetResult {
        kind: "target",
        name: spec.name.clone(),
        quantity: spec.quantity,
        target_error: spec.error,
        safety_factor: plan::SAFETY,
        budget_s: spec.budget_s,
        chosen,
        attempts,
        error_model: model,
        cost_model: cost,
        pilots,
        frontier,
        meshes,
        scene: spec.scene_at(last_level.0, last_level.1),
        run: summary,
        seconds: planner.started.elapsed().as_secs_f64(),
        threads: exec.threads,
        final_mesh,
    })
}

/// Adds what one step of the walk measured to the error model's points: when `to` halves h
/// (or k) of `from` alone, the relative difference of their fields (over the pilots' `scale`)
/// is a point of the h (or k) part at x = h (or k) of `from`, in place of any earlier point at
/// that x (a pilot's: the walk's levels are finer in the other parameter or equal). Points
/// stay coarsest first, so the fit takes its order from the finest differences known.
fn learn<const D: usize>(
    planner: &Planner,
    scale: f64,
    from: ((usize, usize), &LevelRun<D>),
    to: ((usize, usize), &LevelRun<D>),
    h_points: &mut Vec<(f64, f64)>,
    k_points: &mut Vec<(f64, f64)>,
) {
    let ((a, ra), (b, rb)) = (from, to);
    let (x, points) = if b == (a.0 * 2, a.1) {
        (planner.h(a.0), h_points)
    } else if b == (a.0, a.1 * 2) {
        (planner.k(a.1), k_points)
    } else {
        return;
    };
    let (d, _) = difference(ra, rb, planner.spec.quantity);
    let d = if d == 0.0 { 0.0 } else { d / scale };
    points.retain(|p| (p.0 - x).abs() > 1e-9 * x);
    points.push((x, d));
    points.sort_by(|p, q| q.0.partial_cmp(&p.0).unwrap_or(std::cmp::Ordering::Equal));
}

/// The next level of the walk from `level`: h or k halved, whichever the error model predicts
/// to reduce the error more per doubling of the work (unknowns × steps: deterministic, unlike
/// measured times, so the walk does not depend on the machine's load). Only levels within the
/// limits and the budget (time spent, the level's predicted time and its companion's unless
/// it ran) qualify; ties go to the cheaper level.
fn next_level(
    planner: &Planner,
    model: &ErrorModel,
    cost: &CostModel,
    level: (usize, usize),
    known: &dyn Fn((usize, usize)) -> bool,
) -> Option<(usize, usize)> {
    let (n0, s0) = (planner.spec.n0, PILOT_STEPS);
    let work = |l: (usize, usize)| planner.unknowns(l) * l.1 as f64;
    let error = |l: (usize, usize)| model.predict(planner.h(l.0), planner.k(l.1));
    let seconds = |l: (usize, usize)| cost.predict(planner.unknowns(l), l.1);
    let spent = planner.started.elapsed().as_secs_f64();
    [(level.0 * 2, level.1), (level.0, level.1 * 2)]
        .into_iter()
        .filter(|&(n, steps)| n <= n0 << MAX_DOUBLINGS && steps <= s0 << (2 * MAX_DOUBLINGS))
        .filter(|&to| planner.breaks(to).is_none())
        .filter(|&to| {
            let companion = (to.0 / 2, to.1 / 2);
            let more = seconds(to)
                + if known(companion) {
                    0.0
                } else {
                    seconds(companion)
                };
            planner.spec.budget_s.is_none_or(|b| spent + more <= b)
        })
        .map(|to| {
            let gain = (error(level) - error(to)) / (work(to) / work(level)).log2();
            (to, gain, work(to))
        })
        .max_by(|a, b| {
            a.1.partial_cmp(&b.1)
                .unwrap_or(std::cmp::Ordering::Equal)
                .then(b.2.partial_cmp(&a.2).unwrap_or(std::cmp::Ordering::Equal))
        })
        .map(|c| c.0)
}
