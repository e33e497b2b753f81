//! Adaptive against uniform refinement at equal true error (`contact-sim bench --adapt`):
//! an adaptive study ([`crate::study::adapt`]) with its uniform line and a reference, on
//! scenes where the solution is not uniform — the l-bracket's re-entrant corner, the plate
//! with a hole (Γ1 meets Γ3, a hole), paper-exp3 (stick–slip) — and on the smooth
//! paper-convergence scene, where adaptivity should cost no more than uniform refinement.
//!
//! For the finest point of the uniform line whose true error some cycle reaches, the row
//! gives the first such cycle's unknowns and run time beside the uniform run's, and the time
//! of all cycles up to it (what the adaptive process cost).

use crate::admission::Limits;
use crate::scene::{self, presets};
use crate::study::adapt::{self, AdaptResult};
use crate::study::target::Discard;
use crate::study::{Execution, StudyError};
use serde::Serialize;
use serde_json::{json, Value};
use std::ops::ControlFlow;

/// One scene's comparison.
#[derive(Debug, Clone, Serialize)]
pub struct Gain {
    pub scene: &'static str,
    /// The uniform run's true error that the cycle reaches.
    pub error: f64,
    pub uniform_unknowns: usize,
    pub uniform_s: f64,
    /// The first cycle at least as accurate, its run time and the time of all cycles up to
    /// and including it.
    pub cycle: usize,
    pub adaptive_unknowns: usize,
    pub adaptive_error: f64,
    pub adaptive_s: f64,
    pub cycles_s: f64,
    /// adaptive ÷ uniform unknowns.
    pub unknowns_ratio: f64,
    /// The reference's unknowns.
    pub reference_unknowns: usize,
    /// The whole study's table.
    #[serde(skip)]
    pub table: String,
}

/// The scenes of the comparison: a preset's mesh, T, k and the reference's refinements.
fn scenes() -> Vec<(&'static str, Value, usize)> {
    let edit = |preset: &str, mesh: Value, k: &str| {
        let mut doc = presets::get(preset).expect("a preset");
        doc["mesh"] = mesh;
        doc["time"] = json!({"t_end": 0.25, "k": k});
        doc["output"] = json!({"every": 0, "last": true, "fields": []});
        doc
    };
    vec![
        (
            "l-bracket",
            edit("l-bracket", json!({"h": "1/2"}), "1/64"),
            7,
        ),
        (
            "plate-with-hole",
            edit("plate-with-hole", json!({"refine": 0}), "1/64"),
            4,
        ),
        (
            "paper-exp3",
            edit("paper-exp3", json!({"h": "1/4"}), "1/64"),
            6,
        ),
        (
            "paper-convergence",
            edit("paper-convergence", json!({"h": "1/4"}), "1/64"),
            6,
        ),
    ]
}

/// The comparison on each scene with `threads` threads.
pub fn gains(threads: usize) -> Result<Vec<Gain>, StudyError> {
    let exec = Execution {
        threads,
        settings: Default::default(),
    };
    let mut out = Vec::new();
    for (name, scene, refine) in scenes() {
        let doc = json!({"name": name, "scene": scene,
            "adapt": {"target": 1e-6, "max_cycles": 40, "max_nodes": 200_000},
            "reference": {"refine": refine}});
        let (spec, _) =
            adapt::parse_with(&doc, "", &scene::Bundled).unwrap_or_else(|e| panic!("{name}: {e}"));
        let r = adapt::run(
            &spec,
            exec,
            Limits::default(),
            &|_, _| ControlFlow::Continue(()),
            &mut Discard,
        )?;
        if let Some(g) = gain(name, &r) {
            out.push(g);
        }
    }
    Ok(out)
}

/// The finest uniform point whose true error a cycle reaches, and that cycle.
fn gain(scene: &'static str, r: &AdaptResult) -> Option<Gain> {
    r.uniform.iter().skip(1).rev().find_map(|u| {
        let e = u.error?;
        let i = r
            .cycles
            .iter()
            .position(|c| c.error.is_some_and(|x| x <= e))?;
        let c = &r.cycles[i];
        Some(Gain {
            scene,
            error: e,
            uniform_unknowns: u.unknowns,
            uniform_s: u.seconds,
            cycle: i,
            adaptive_unknowns: c.unknowns,
            adaptive_error: c.error.unwrap_or(e),
            adaptive_s: c.seconds,
            cycles_s: r.cycles[..=i].iter().map(|c| c.seconds).sum(),
            unknowns_ratio: c.unknowns as f64 / u.unknowns as f64,
            reference_unknowns: r.reference.as_ref().map_or(0, |r| r.unknowns),
            table: r.text_table(),
        })
    })
}

/// The rows as a text table.
pub fn table(gains: &[Gain]) -> String {
    let mut s = format!(
        "{:>18} {:>10} {:>9} {:>9} {:>6} {:>9} {:>9} {:>9} {:>9} {:>7}\n",
        "scene",
        "error",
        "uniform N",
        "uniform s",
        "cycle",
        "adapt N",
        "adapt s",
        "cycles s",
        "N ratio",
        "ref N"
    );
    for g in gains {
        s.push_str(&format!(
            "{:>18} {:>10.3e} {:>9} {:>9.3} {:>6} {:>9} {:>9.3} {:>9.3} {:>9.3} {:>7}\n",
            g.scene,
            g.error,
            g.uniform_unknowns,
            g.uniform_s,
            g.cycle,
            g.adaptive_unknowns,
            g.adaptive_s,
            g.cycles_s,
            g.unknowns_ratio,
            g.reference_unknowns
        ));
    }
    s
}
