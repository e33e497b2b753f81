//! The direct path's predicted peak ([`memory::refine`]: the exact factor sizes of the
//! symbolic analyses) against the measured peak (VmHWM) of a run. The only test of this
//! file, so that the process's peak is the run's.

use contact_core::linalg::LinearPath;
use contact_core::memory;
use contact_core::scene::{self, presets};
use contact_core::solve::stepper::Simulation;
use contact_core::solve::SolverSettings;
use serde_json::json;

/// box-exp3 at h = 1/12 on the direct path, two steps: the prediction the set-up reports
/// is within 25 % of the process's peak.
#[test]
fn the_direct_paths_prediction_is_within_a_quarter_of_the_measured_peak() {
    let mut doc = presets::get("box-exp3").unwrap();
    doc["mesh"]["h"] = json!("1/12");
    doc["time"] = json!({"t_end": 1, "N": 2});
    doc["solver"] = json!({"linear": "direct"});
    let problem = scene::validate(&doc).unwrap();
    let mut sim = Simulation::<3>::new(problem, SolverSettings::default()).unwrap();
    assert_eq!(sim.linear, LinearPath::Direct);
    while !sim.finished() {
        sim.step().unwrap();
    }
    let predicted = sim.predicted_bytes as f64;
    let Some(peak) = memory::peak_bytes() else {
        eprintln!("no VmHWM on this system: nothing to compare");
        return;
    };
    let ratio = predicted / peak as f64;
    eprintln!("predicted {predicted:.0} bytes, peak {peak} bytes: {ratio:.3}");
    assert!((0.75..=1.25).contains(&ratio), "predicted / peak = {ratio}");
}
