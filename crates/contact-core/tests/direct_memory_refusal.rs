//! A run on the direct path is checked against the per-job memory limit on its exact
//! prediction ([`memory::refine`]) before it factorises: refused below it, with the error
//! that names the field and both figures; run at it.

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

/// A whole set-up (box-exp3, h = 1/6). At this size the assembly's transient sets the
/// prediction, so the refusal comes from the check before the analyses.
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

/// Where the factors set the direct path's peak (2D, h = 1/256: the assembly's transient is
/// smaller than K_II's and H's factors with the operators beside them), a limit between what
/// is certain before the analyses and the exact figure is refused on the exact figure, the
/// same error as the count check's; the exact figure itself fits. The analyses are made on
/// the operators' patterns as the set-up makes them (assembled here into the pattern, which
/// the set-up's triplet assembly shares, to keep the test's memory small).
#[test]
fn the_exact_figure_decides_where_the_factors_set_the_peak() {
    use contact_core::fem::{assembly, DofMap, Geometry};
    use contact_core::linalg::LinearPath;
    use contact_core::solve::backend::direct;
    let mut doc = presets::get("paper-convergence").unwrap();
    doc["mesh"]["h"] = json!("1/256");
    doc["time"] = json!({"T": 1, "N": 1});
    doc["solver"] = json!({"linear": "direct"});
    let p = scene::validate(&doc).unwrap();
    let mesh = p.mesh::<2>().unwrap();
    let geo = Geometry::new(&mesh);
    let dofs = DofMap::new(&mesh, &p.boundary);
    let visc = p.material.viscosity;
    let k = assembly::viscous_stiffness_in_pattern(&mesh, &geo, &dofs, visc.eta, visc.xi);
    let n_i = dofs.n_interior;
    let lower = k.block(0..n_i, 0..n_i).lower_csc();
    let k_ii = direct::plan::<2>(lower.as_ref()).unwrap();
    let h = direct::damage_plan(&assembly::mass_in_pattern(&mesh, &geo)).unwrap();
    let exact = memory::refine(&p, &[&k_ii, &h]).direct;
    let floor = memory::without_factors(&p).direct;
    assert!(
        floor < exact,
        "the factors do not set the peak: {floor} ≥ {exact}"
    );
    let limit = floor + (exact - floor) / 2;
    match memory::choose_with(&p, Some(limit), memory::refine(&p, &[&k_ii, &h])) {
        Err(e @ MemoryError::DirectTooLarge { .. }) => {
            let msg = e.to_string();
            assert!(
                msg.contains(&human(exact)) && msg.contains(&human(limit)),
                "{msg}"
            );
        }
        other => panic!("{other:?}"),
    }
    let fits = memory::choose_with(&p, Some(exact), memory::refine(&p, &[&k_ii, &h]));
    assert_eq!(fits, Ok((LinearPath::Direct, exact)));
}
