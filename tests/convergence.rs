//! Convergence behaviour of the paper's test at coarse levels (fast enough for CI), in the
//! pattern of the paper's Tables 1–2: velocity order ≈ 1 in h and in k, damage order ≥ 1.

mod common;
use common::*;
use contact_sim::study::{run_ladder, StudyError};

#[test]
fn orders_in_h_behave_as_table_1() {
    let base = problem("paper-convergence", 32, 32, &[]);
    let s = run_ladder(&base, &[(2, 32), (4, 32), (8, 32), (16, 32)], (64, 32)).unwrap();
    let ow: Vec<f64> = s.rows.iter().filter_map(|r| r.order_w).collect();
    let oz: Vec<f64> = s.rows.iter().filter_map(|r| r.order_zeta).collect();
    eprintln!("{}", s.text_table("h"));
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
    eprintln!("{}", s.text_table("k"));
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
