//! Convergence behaviour of the paper's test at coarse levels (fast enough for CI), in the
//! pattern of the paper's Tables 1–2: velocity order ≈ 1 in h and in k, damage order ≥ 1.

mod common;
use common::*;
use contact_core::study::{run_ladder, StudyError};

#[test]
fn orders_in_h_behave_as_table_1() {
    let base = problem("paper-convergence", 32, 32, &[]);
    let s = run_ladder(&base, &[(2, 32), (4, 32), (8, 32), (16, 32)], (64, 32)).unwrap();
    let ow: Vec<f64> = s.rows.iter().filter_map(|r| r.order_w).collect();
    let oz: Vec<f64> = s.rows.iter().filter_map(|r| r.order_zeta).collect();
    eprintln!("{}", s.text_table());
    // Errors decrease monotonically; the velocity order approaches 1 from below as in the
    // paper (0.66, 0.79, 0.81, 0.87), the damage order is above 1 (1.0, 1.34, 1.50, 1.52).
    assert!(s
        .rows
        .windows(2)
        .all(|w| w[1].err_w < w[0].err_w && w[1].err_zeta < w[0].err_zeta));
    assert!(
        ow.iter().all(|&o| (0.55..1.3).contains(&o)),
        "w orders {ow:?}"
    );
    assert!(ow[2] > ow[0], "w orders should increase towards 1: {ow:?}");
    assert!(oz.iter().all(|&o| o > 0.9), "zeta orders {oz:?}");
}

#[test]
fn orders_in_k_behave_as_table_2() {
    let base = problem("paper-convergence", 8, 8, &[]);
    let s = run_ladder(&base, &[(8, 4), (8, 8), (8, 16), (8, 32)], (8, 256)).unwrap();
    let ow: Vec<f64> = s.rows.iter().filter_map(|r| r.order_w).collect();
    let oz: Vec<f64> = s.rows.iter().filter_map(|r| r.order_zeta).collect();
    eprintln!("{}", s.text_table());
    assert!(
        ow.iter().all(|&o| (0.8..1.4).contains(&o)),
        "w orders {ow:?}"
    );
    assert!(
        oz.iter().all(|&o| (0.8..2.0).contains(&o)),
        "zeta orders {oz:?}"
    );
}

#[test]
fn reference_against_itself_is_exactly_zero_and_non_nested_is_refused() {
    let base = problem("paper-convergence", 8, 8, &[]);
    let s = run_ladder(&base, &[(8, 8)], (8, 8)).unwrap();
    assert_eq!((s.rows[0].err_w, s.rows[0].err_zeta), (0.0, 0.0));
    let err = run_ladder(&base, &[(3, 8)], (8, 8)).unwrap_err();
    assert!(matches!(err, StudyError::NotNested { .. }), "{err}");
}

/// k = 1/2 (kμ/η = 1): w^hk(T) = 0 exactly, so the relative error is exactly 1.
#[test]
fn k_one_half_gives_relative_error_exactly_one() {
    let base = problem("paper-convergence", 8, 8, &[]);
    let s = run_ladder(&base, &[(8, 2)], (8, 16)).unwrap();
    assert!((s.rows[0].err_w - 1.0).abs() < 1e-12, "{}", s.rows[0].err_w);
}

/// A study read from its document, then the same study with the reference taken from the
/// cache: identical tables; maxima over time are at least the errors at T.
#[test]
fn studies_share_a_cached_reference_with_identical_results() {
    use contact_core::study::{self, Execution, ReferenceCache};
    use std::ops::ControlFlow;
    let doc = serde_json::json!({"scene": "paper-convergence", "h": ["1/2", "1/4", "1/8"],
        "k": "1/8", "reference": {"h": "1/16", "k": "1/16"}});
    let (plan, _) = study::parse(&doc, "").unwrap();
    let cache = ReferenceCache::new(2);
    let calls = std::sync::atomic::AtomicUsize::new(0);
    let progress = |_: usize, _: usize| {
        calls.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        ControlFlow::Continue(())
    };
    let first = study::run(&plan, &cache, Execution::default(), &progress).unwrap();
    assert_eq!(
        calls.into_inner(),
        16 + 3 * 8,
        "one progress call per time step"
    );
    let second = study::run(&plan, &cache, Execution::default(), &|_, _| {
        ControlFlow::Continue(())
    })
    .unwrap();
    assert!(!first.reference.cached && second.reference.cached);
    for (a, b) in first.rows.iter().zip(&second.rows) {
        assert_eq!(
            (a.err_w, a.err_zeta, a.err_w_max),
            (b.err_w, b.err_zeta, b.err_w_max)
        );
        assert!(
            a.err_w_max >= a.err_w * (1.0 - 1e-12) && a.err_zeta_max >= a.err_zeta * (1.0 - 1e-12)
        );
        assert_eq!(a.compared_nodes, 8);
    }
    let lsq = first.lsq_order_w.unwrap();
    assert!((0.5..1.3).contains(&lsq), "least-squares order {lsq}");
    // Cancelling through the progress callback stops the study.
    let (plan2, _) = study::parse(
        &serde_json::json!({"scene": "paper-convergence", "h": "1/4",
        "k": "1/8", "reference": {"h": "1/32", "k": "1/16"}}),
        "",
    )
    .unwrap();
    let err = study::run(&plan2, &cache, Execution::default(), &|d, _| {
        if d > 3 {
            ControlFlow::Break(())
        } else {
            ControlFlow::Continue(())
        }
    })
    .unwrap_err();
    assert!(matches!(err, StudyError::Cancelled), "{err}");
}

/// The (2h, 2k) error bar of a simulation against its true error, measured by a study with
/// a fine reference: with observed orders near 0.85 the first-order estimate
/// |w_h − w_2h| / |w_h| lies within a factor 2 of the truth.
#[test]
fn error_estimate_brackets_the_true_error() {
    use contact_core::estimate::ErrorEstimator;
    let p = problem(
        "paper-convergence",
        16,
        16,
        &[("/error_estimate", serde_json::json!(true))],
    );
    let mut sim =
        contact_core::solve::stepper::Simulation::<2>::new(p.clone(), Default::default()).unwrap();
    let mut est = ErrorEstimator::new(&sim, Default::default()).unwrap();
    while !sim.finished() {
        sim.step().unwrap();
        est.after_step(&sim, sim.state.step.is_multiple_of(4))
            .unwrap();
    }
    let e = est.finish();
    let fin = e.final_.clone().unwrap();
    let truth = run_ladder(&p, &[(16, 16)], (64, 64)).unwrap().rows[0].clone();
    let (ew, ez) = (fin.w.unwrap(), fin.zeta.unwrap());
    eprintln!(
        "estimate w {ew:.4e} (true {:.4e}), zeta {ez:.4e} (true {:.4e}), orders {:?} {:?}",
        truth.err_w, truth.err_zeta, fin.observed_order_w, fin.observed_order_zeta
    );
    assert!(
        (0.5..2.0).contains(&(ew / truth.err_w)),
        "w: {ew} vs {}",
        truth.err_w
    );
    assert!(
        (0.3..3.0).contains(&(ez / truth.err_zeta)),
        "zeta: {ez} vs {}",
        truth.err_zeta
    );
    assert!(!fin.flagged, "{fin:?}");
    assert_eq!(
        e.steps.iter().map(|r| r.n).collect::<Vec<_>>(),
        [4, 8, 12, 16]
    );
}

/// Without damage in the scene there is no ζ estimate (ζ ≡ 1 in every run).
#[test]
fn error_estimate_without_damage_has_no_zeta() {
    use contact_core::estimate::ErrorEstimator;
    let p = problem(
        "paper-convergence",
        8,
        8,
        &[("/damage", serde_json::Value::Null)],
    );
    let mut sim =
        contact_core::solve::stepper::Simulation::<2>::new(p, Default::default()).unwrap();
    let mut est = ErrorEstimator::new(&sim, Default::default()).unwrap();
    while !sim.finished() {
        sim.step().unwrap();
        est.after_step(&sim, false).unwrap();
    }
    let fin = est.finish().final_.unwrap();
    assert!(fin.w.unwrap() > 0.0 && fin.zeta.is_none() && fin.observed_order_zeta.is_none());
}

/// Levels on one mesh share one factored velocity operator (it does not depend on k): the
/// table is bit-for-bit the one computed with a set-up per run.
#[test]
fn shared_set_up_changes_no_bit() {
    use contact_core::study::{self, Execution, ReferenceCache};
    let doc = serde_json::json!({"scene": "paper-convergence", "h": "1/8",
        "k": ["1/2", "1/4", "1/8"], "reference": {"h": "1/8", "k": "1/16"}});
    let (plan, _) = study::parse(&doc, "").unwrap();
    let shared = study::run(
        &plan,
        &ReferenceCache::new(1),
        Execution::default(),
        &|_, _| std::ops::ControlFlow::Continue(()),
    )
    .unwrap();
    let separate = run_ladder(&plan.base, &plan.levels, plan.reference).unwrap();
    for (a, b) in shared.rows.iter().zip(&separate.rows) {
        assert_eq!(a.err_w.to_bits(), b.err_w.to_bits());
        assert_eq!(a.err_zeta.to_bits(), b.err_zeta.to_bits());
        assert_eq!(a.err_w_max.to_bits(), b.err_w_max.to_bits());
    }
    assert_eq!(
        shared.reference.w_v.to_bits(),
        separate.reference.w_v.to_bits()
    );
}
