//! The stability suite's quick subset (`contact-sim stress --quick`): every hard scene either
//! runs to t = T with residuals at tolerance and every invariant intact after every step, or
//! is refused up front with the expected reason. Scenes beyond the smallness condition (2.31)
//! must be refused, never silently solved.

use contact_core::harness::stress::{self, Expect, Outcome};

#[test]
fn quick_suite_completes_or_refuses_as_required() {
    let report = stress::run(true);
    println!("{}", report.text_table());
    assert!(report.cases.len() >= 20, "the quick subset shrank");
    let tol = report.tolerance;
    for c in &report.cases {
        assert!(c.as_expected, "{}: {:?}", c.name, c.reason);
        match &c.expect {
            Expect::Complete => {
                assert_eq!(c.outcome, Outcome::Completed, "{}", c.name);
                assert!(
                    c.velocity_residual_max.is_some_and(|r| r <= tol),
                    "{}",
                    c.name
                );
                assert!(c.damage_residual_max.is_none_or(|r| r <= tol), "{}", c.name);
            }
            Expect::Refused(why) => {
                assert_eq!(c.outcome, Outcome::Refused, "{}", c.name);
                let reason = c.reason.as_deref().unwrap_or("");
                assert!(
                    reason.contains(why.as_str()) && reason.contains("(2.31)"),
                    "{}: {reason}",
                    c.name
                );
                assert!(
                    c.velocity_iterations.is_none(),
                    "{}: refused cases take no step",
                    c.name
                );
            }
        }
    }
    // Both ends of the friction range, and a refusal, are really in the table.
    let names: Vec<&str> = report.cases.iter().map(|c| c.name.as_str()).collect();
    for name in [
        "tresca-g0",
        "tresca-g1e4",
        "slipweak-beyond",
        "pwlinear-beyond",
        "damage-total",
    ] {
        assert!(names.contains(&name), "{name} missing");
    }
}

/// Regression: on a 20:1 cantilever (K's condition grows like (length/height)^4) the rounding
/// of K w alone is 3e-10 of ‖f‖∞, so the velocity step "did not converge" at step 1 with the
/// exact solution in hand. Refinement, then the residual relative to ‖|K||w|‖∞, fix it.
#[test]
fn slender_cantilever_reaches_the_tolerance() {
    let case = stress::cases()
        .into_iter()
        .find(|c| c.name == "beam-20:1")
        .expect("case");
    let r = stress::run_case(&case, true).expect("in the quick subset");
    assert_eq!(r.outcome, Outcome::Completed, "{:?}", r.reason);
    assert!(r.velocity_residual_max.unwrap() <= 1e-10);
}

/// The friction cases of the quick subset on the multigrid path (slip by the semismooth
/// Newton method on all DOFs): the same outcome as on the direct path, residuals at
/// tolerance, the invariants after every step, and the same slip fraction.
#[test]
fn friction_cases_behave_the_same_on_the_multigrid_path() {
    let friction = ["tresca", "slipweak", "pwlinear"];
    let mut ran = 0;
    for case in stress::cases() {
        if !friction.iter().any(|f| case.name.starts_with(f)) {
            continue;
        }
        let Some(direct) = stress::run_case_on(&case, true, Some("direct")) else {
            continue;
        };
        let multi = stress::run_case_on(&case, true, Some("multigrid")).expect("quick case");
        assert!(multi.as_expected, "{}: {:?}", case.name, multi.reason);
        assert_eq!(multi.outcome, direct.outcome, "{}", case.name);
        if multi.outcome == Outcome::Completed {
            assert!(
                multi.velocity_residual_max.unwrap() <= 1e-10,
                "{}",
                case.name
            );
            assert_eq!(multi.slip_fraction, direct.slip_fraction, "{}", case.name);
        }
        ran += 1;
    }
    assert!(ran >= 8, "only {ran} friction cases");
}
