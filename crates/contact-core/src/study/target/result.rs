//! What a target study reports: its pilots, attempts, models and the chosen run, as JSON and
//! as a text table.

use super::*;
use crate::mesh::{export, AnyMesh};
use crate::study::adapt;

/// A pilot run as reported.
#[derive(Debug, Clone, Serialize)]
pub struct PilotRow {
    /// "h" or "k": the ladder it belongs to (the run where they cross is "h").
    pub ladder: &'static str,
    pub h: f64,
    pub k: f64,
    /// d × nodes (the cost model's N).
    pub unknowns: usize,
    pub steps: usize,
    pub seconds: f64,
}

/// The (2h, 2k) companion of a chosen run.
#[derive(Debug, Clone, Serialize)]
pub struct Companion {
    pub h: f64,
    pub k: f64,
    pub seconds: f64,
    /// It was a pilot run or the previous attempt (not run again).
    pub reused: bool,
}

/// One run at a chosen (h, k).
#[derive(Debug, Clone, Serialize)]
pub struct Attempt {
    pub h: f64,
    pub k: f64,
    /// Refinements of the given mesh (given meshes only).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub refine: Option<usize>,
    pub steps: usize,
    /// d × nodes.
    pub unknowns: usize,
    pub predicted_error: f64,
    /// The (2h, 2k) error bar: |f − I f_2h| / |f| at t = T.
    pub estimated_error: f64,
    /// estimated_error ≤ the target.
    pub check_passed: bool,
    pub predicted_seconds: f64,
    /// Wall time of the run, set-up included.
    pub seconds: f64,
    pub companion: Companion,
}

/// Which meshes the chosen run is on, and why.
#[derive(Debug, Clone, Serialize)]
pub struct MeshChoice {
    /// The request's `target.meshes`.
    pub policy: Meshes,
    /// "uniform" (the chosen attempt's level) or "adaptive" (the last of `cycles`).
    pub taken: &'static str,
    /// Why, in a sentence.
    pub reason: String,
    /// The spatial part of the chosen uniform run's relative estimate of w (policy auto).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub uniform_estimate: Option<f64>,
    /// The chosen uniform run's nodes (policy auto).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub uniform_nodes: Option<usize>,
    /// The adaptive cycles at the chosen k (policy auto), from the coarsest pilot mesh.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub cycles: Vec<adapt::Row>,
    /// Why the cycles ended (policy auto).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub stopped: Option<adapt::Stop>,
}

impl MeshChoice {
    /// Policy uniform: nothing else was tried.
    pub fn uniform() -> MeshChoice {
        MeshChoice {
            policy: Meshes::Uniform,
            taken: "uniform",
            reason: "uniform meshes were asked for (target.meshes)".into(),
            uniform_estimate: None,
            uniform_nodes: None,
            cycles: Vec::new(),
            stopped: None,
        }
    }
}

#[derive(Debug, Clone, Serialize)]
pub struct TargetResult {
    pub kind: &'static str,
    pub name: String,
    pub quantity: Quantity,
    pub target_error: f64,
    pub safety_factor: f64,
    pub budget_s: Option<f64>,
    /// The last attempt: the run whose fields are served.
    pub chosen: Attempt,
    /// Every run at a chosen (h, k), in order (two when the first failed its check).
    pub attempts: Vec<Attempt>,
    pub error_model: ErrorModel,
    pub cost_model: CostModel,
    pub pilots: Vec<PilotRow>,
    /// Predicted work–precision frontier of the grid within the limits: the candidates no
    /// other beats in both predicted time and error, cheapest first.
    pub frontier: Vec<Candidate>,
    /// Which meshes the chosen run is on (`run`, `scene` and the served fields are the
    /// adaptive mesh's when `meshes.taken` is "adaptive"; `chosen` stays the uniform level
    /// that passed the check).
    pub meshes: MeshChoice,
    /// The chosen run's scene document (on an adaptive mesh: the uniform level's, whose mesh
    /// the service replaces by the uploaded [`TargetResult::final_msh`]).
    pub scene: Value,
    /// The chosen run's simulation summary.
    pub run: Summary,
    /// Wall time of the whole study (pilots, plan, chosen runs and companions).
    pub seconds: f64,
    pub threads: usize,
    /// The adaptive mesh taken (`meshes.taken` "adaptive").
    #[serde(skip)]
    pub final_mesh: Option<AnyMesh>,
}

impl TargetResult {
    /// The adaptive mesh taken, as a gmsh MSH 2.2 file.
    pub fn final_msh(&self) -> Option<String> {
        self.final_mesh.as_ref().map(export::any_msh)
    }

    /// A short text report: the choice, the check, the fit and the pilots.
    pub fn text_table(&self) -> String {
        let frac = crate::study::format::fraction;
        let opt = |o: Option<f64>| o.map_or("–".to_string(), |v| format!("{v:.3}"));
        let c = &self.chosen;
        let mut s = format!(
            "{}: target {} in {} (safety factor {})\nchosen h = {}, k = {} ({} unknowns, {} steps): predicted error {:.4}, estimated {:.4} ({}); predicted {:.3} s, measured {:.3} s\n",
            self.name,
            self.target_error,
            self.quantity.name(),
            self.safety_factor,
            frac(c.h),
            frac(c.k),
            c.unknowns,
            c.steps,
            c.predicted_error,
            c.estimated_error,
            if c.check_passed { "check passed" } else { "check FAILED" },
            c.predicted_seconds,
            c.seconds,
        );
        let mc = &self.meshes;
        s += &format!("meshes: {} ({})\n", mc.taken, mc.reason);
        if self.attempts.len() > 1 {
            s += "walk:";
            for a in &self.attempts {
                s += &format!(
                    " ({}, {}) bar {:.4}{};",
                    frac(a.h),
                    frac(a.k),
                    a.estimated_error,
                    if a.check_passed { " passed" } else { "" }
                );
            }
            s += "\n";
        }
        let m = &self.error_model;
        s += &format!(
            "error model e = {:.4}·h^{} + {:.4}·k^{} (observed orders {}, {}); cost t = {:.3e}·N^{:.2}·steps\n",
            m.h.coefficient,
            opt(m.h.order),
            m.k.coefficient,
            opt(m.k.order),
            opt(m.h.observed_order),
            opt(m.k.observed_order),
            self.cost_model.c,
            self.cost_model.alpha,
        );
        for note in [&m.h.note, &m.k.note, &self.cost_model.note]
            .into_iter()
            .flatten()
        {
            s += &format!("  note: {note}\n");
        }
        s += &format!(
            "{:>7} {:>7} {:>7} {:>9} {:>6} {:>9}\n",
            "ladder", "h", "k", "unknowns", "steps", "seconds"
        );
        for p in &self.pilots {
            s += &format!(
                "{:>7} {:>7} {:>7} {:>9} {:>6} {:>9.4}\n",
                p.ladder,
                frac(p.h),
                frac(p.k),
                p.unknowns,
                p.steps,
                p.seconds
            );
        }
        s += &format!(
            "study {:.3} s on {} thread(s)\n",
            self.seconds, self.threads
        );
        s
    }
}
