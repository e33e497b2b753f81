//! A run on the direct path is checked against the per-job memory limit on its exact
//! prediction ([`memory::refine`]) before it factorises: refused below it, with the error
//! that names the field and both figures; run at it. (At this size the assembly's transient
//! sets the prediction, so the refusal comes from the check before the analyses.)

use contact_core::memory::{self, human, MemoryError};
use contact_core::problem::Problem;
use contact_core::scene::{self, presets};
use contact_core::solve::stepper::Simulation;
use contact_core::solve::{SolveError, SolverSettings};
use serde_json::json;

fn problem(linear: &str) -> Problem {
    let mut doc = presets::get("box-exp3").unwrap();
    doc["mesh"]["h"] = json!("1/6");
    doc["time"] = json!({"t_end": 1, "N": 1});
    doc["solver"] = json!({"linear": linear});
    scene::validate(&doc).unwrap()
}

fn set_up(limit: Option<u64>) -> Result<Simulation<3>, SolveError> {
    let settings = SolverSettings {
        memory_limit: limit,
        ..SolverSettings::default()
    };
    Simulation::<3>::new(problem("direct"), settings)
}

#[test]
fn a_direct_run_over_its_exact_prediction_is_refused_before_it_factorises() {
    let exact = set_up(None).unwrap().predicted_bytes;
    // What is certain before the analyses bounds the exact figure from below.
    let floor = memory::without_factors(&problem("direct")).direct;
    assert!(floor <= exact, "{floor} > {exact}");
    let limit = exact - 1;
    match set_up(Some(limit)) {
        Err(SolveError::Memory(e @ MemoryError::DirectTooLarge { .. })) => {
            let MemoryError::DirectTooLarge {
                predicted, allowed, ..
            } = e
            else {
                unreachable!()
            };
            assert_eq!((predicted, allowed), (exact, limit));
            assert_eq!(e.pointer(), "/solver/linear");
            let msg = e.to_string();
            assert!(
                msg.contains(&human(exact)) && msg.contains(&human(limit)),
                "{msg}"
            );
        }
        Err(e) => panic!("refused for another reason: {e}"),
        Ok(_) => panic!("a limit below the prediction of {exact} bytes was accepted"),
    }
    let sim = set_up(Some(exact)).unwrap();
    assert_eq!(sim.predicted_bytes, exact);
}
