//! Adaptive studies on whole runs ([`contact_core::study::adapt`]): on the l-bracket, whose
//! re-entrant corner at (1, 0.5) costs uniform refinement its order, the cycles reach the
//! uniform line's true error with at most a third of its unknowns and recover the order
//! N^(−1/2) of a smooth solution.

use contact_core::admission::Limits;
use contact_core::scene::{self, presets};
use contact_core::study::adapt::{self, AdaptResult, Row};
use contact_core::study::target::Discard;
use contact_core::study::Execution;
use serde_json::json;
use std::ops::ControlFlow;

fn study(doc: serde_json::Value) -> AdaptResult {
    let (spec, _) = adapt::parse_with(&doc, "/study", &scene::Bundled).unwrap();
    let exec = Execution {
        threads: 2,
        settings: Default::default(),
    };
    let r = adapt::run(
        &spec,
        exec,
        Limits::default(),
        &|_, _| ControlFlow::Continue(()),
        &mut Discard,
    )
    .unwrap();
    eprintln!("{}", r.text_table());
    r
}

/// Least-squares slope of log(error) against log(unknowns).
fn slope(rows: &[&Row]) -> f64 {
    let pts: Vec<(f64, f64)> = rows
        .iter()
        .map(|r| ((r.unknowns as f64).ln(), r.error.unwrap().ln()))
        .collect();
    let n = pts.len() as f64;
    let (mx, my) = (
        pts.iter().map(|p| p.0).sum::<f64>() / n,
        pts.iter().map(|p| p.1).sum::<f64>() / n,
    );
    let sxy: f64 = pts.iter().map(|p| (p.0 - mx) * (p.1 - my)).sum();
    let sxx: f64 = pts.iter().map(|p| (p.0 - mx).powi(2)).sum();
    sxy / sxx
}

#[test]
fn adaptivity_pays_on_the_l_bracket() {
    let mut scene = presets::get("l-bracket").unwrap();
    scene["mesh"]["h"] = json!("1/2");
    scene["time"] = json!({"t_end": 0.25, "k": "1/64"});
    scene["output"] = json!({"every": 0, "last": true, "fields": []});
    let r = study(json!({
        "scene": scene,
        "adapt": {"target": 1e-4, "theta": 0.5, "max_nodes": 12000, "max_cycles": 30},
        "reference": {"refine": 7}
    }));
    // The finest point of the uniform line whose true error a cycle nested in the reference
    // reaches (h/16 or finer), and the first cycle as accurate.
    let (uniform, cycle) = r
        .uniform
        .iter()
        .rev()
        .find_map(|u| {
            let e = u.error?;
            let c = r.cycles.iter().find(|c| c.error.is_some_and(|x| x <= e))?;
            Some((u, c))
        })
        .unwrap();
    assert!(uniform.generation >= 8, "{uniform:?}");
    assert!(
        3 * cycle.unknowns <= uniform.unknowns,
        "the cycles reach {:.3e} with {} unknowns, uniform refinement with {}",
        uniform.error.unwrap(),
        cycle.unknowns,
        uniform.unknowns
    );
    // Orders in N over the last four points with a true error of each: the cycles' near the
    // smooth solution's 1/2, uniform refinement's clearly below.
    let cycles: Vec<&Row> = r.cycles.iter().filter(|c| c.error.is_some()).collect();
    let uniform: Vec<&Row> = r.uniform.iter().filter(|u| u.error.is_some()).collect();
    let (adaptive, plain) = (
        -slope(&cycles[cycles.len() - 6..]),
        -slope(&uniform[uniform.len() - 3..]),
    );
    eprintln!("orders in N: adaptive {adaptive:.3}, uniform {plain:.3}");
    assert!(
        adaptive > 0.45 && adaptive > plain + 0.05,
        "{adaptive} against {plain}"
    );
}
