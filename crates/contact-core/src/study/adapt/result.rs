//! What an adaptive study returns: one row per cycle, the uniform line and the reference
//! beside it, the last cycle's summary and its mesh.

use crate::mesh::export;
use crate::mesh::AnyMesh;
use crate::output::Summary;
use serde::Serialize;
use std::fmt::Write as _;

/// Why the cycles ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Stop {
    /// The relative estimate met the target.
    Target,
    /// The next mesh would have had more than `max_nodes` nodes.
    MaxNodes,
    /// `max_cycles` cycles ran.
    MaxCycles,
    /// The estimate is above the target, but its time part is the larger (its square more
    /// than half of the whole): refining the mesh no longer reduces it much; k must.
    TimeStep,
    /// The next mesh's run would not fit the per-job memory limit.
    Memory,
    /// Every indicator is zero (w ≡ 0): refining cannot change the estimate.
    NothingToRefine,
}

impl Stop {
    fn sentence(self) -> &'static str {
        match self {
            Stop::Target => "the estimate met the target",
            Stop::MaxNodes => "the next mesh would pass max_nodes",
            Stop::MaxCycles => "max_cycles cycles ran",
            Stop::TimeStep => "the time part dominates the estimate: refine k, not the mesh",
            Stop::Memory => "the next mesh would not fit the memory limit",
            Stop::NothingToRefine => "every indicator is zero",
        }
    }
}

/// One run of the study: a cycle, a point of the uniform line or the reference.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Row {
    pub nodes: usize,
    pub cells: usize,
    /// Velocity unknowns (free DOFs).
    pub unknowns: usize,
    /// The most bisections of a cell since the initial mesh (the uniform line's: d per
    /// halving of h).
    pub generation: usize,
    /// The velocity's estimate over the run relative to (k Σ_n |w_n|²_V)^½
    /// (`summary.estimate.relative_w`).
    pub estimate: f64,
    /// The velocity's estimate over the run, (k Σ_n η_n²)^½.
    pub estimate_abs: f64,
    /// The time part's share of `estimate_abs` (what refining the mesh cannot reduce).
    pub time_share: f64,
    /// The true relative error against the reference (None without one, or for a mesh
    /// not nested in it).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub error: Option<f64>,
    /// Cells Dörfler's criterion marked after this cycle (None on the last cycle and off
    /// the cycles).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub marked: Option<usize>,
    /// Wall time of the run, set-up included.
    pub seconds: f64,
}

impl Row {
    pub(crate) fn new(
        summary: &Summary,
        generation: usize,
        seconds: f64,
        error: Option<f64>,
    ) -> Row {
        let estimate = summary
            .estimate
            .expect("an adaptive study's runs estimate their error");
        Row {
            nodes: summary.mesh.nodes,
            cells: summary
                .mesh
                .triangles
                .or(summary.mesh.tetrahedra)
                .unwrap_or(0),
            unknowns: summary.mesh.unknowns,
            generation,
            estimate: estimate.relative_w,
            estimate_abs: estimate.velocity.total,
            time_share: if estimate.velocity.total > 0.0 {
                estimate.velocity.time / estimate.velocity.total
            } else {
                0.0
            },
            error,
            marked: None,
            seconds,
        }
    }

    /// The spatial part of the relative estimate, √(estimate² − time part²): what refining
    /// the mesh reduces.
    pub fn space_estimate(&self) -> f64 {
        self.estimate * (1.0 - self.time_share * self.time_share).max(0.0).sqrt()
    }
}

/// A finished adaptive study.
#[derive(Debug, Clone, Serialize)]
pub struct AdaptResult {
    /// "adapt".
    pub kind: &'static str,
    pub name: String,
    pub quantity: &'static str,
    pub target: f64,
    pub theta: f64,
    pub max_nodes: usize,
    /// Whether the last cycle's estimate is at most the target.
    pub reached: bool,
    pub stopped: Stop,
    /// The reference run (with `reference.refine`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub reference: Option<Row>,
    pub cycles: Vec<Row>,
    /// The initial mesh bisected uniformly d, 2d, … times (h, h/2, …), its first row the first
    /// cycle's.
    pub uniform: Vec<Row>,
    /// The last cycle's run: the study's result run.
    pub summary: Summary,
    /// The study's scene document (its last cycle's run is this scene on `final_mesh`).
    #[serde(skip)]
    pub scene: serde_json::Value,
    #[serde(skip)]
    pub final_mesh: AnyMesh,
}

impl AdaptResult {
    /// The last cycle's mesh as a gmsh MSH 2.2 file ([`export::msh`]).
    pub fn final_msh(&self) -> String {
        export::any_msh(&self.final_mesh)
    }

    /// The cycles, the uniform line and the reference as text.
    pub fn text_table(&self) -> String {
        let mut s = String::new();
        let _ = writeln!(
            s,
            "{}: adaptive refinement, target {:.3e} (relative estimate of w), θ = {}; {} after {} cycles ({})",
            self.name,
            self.target,
            self.theta,
            if self.reached { "reached" } else { "not reached" },
            self.cycles.len(),
            self.stopped.sentence(),
        );
        let header = format!(
            "{:>10} {:>8} {:>9} {:>9} {:>5} {:>11} {:>6} {:>11} {:>8} {:>9}",
            "run",
            "nodes",
            "cells",
            "unknowns",
            "gen",
            "estimate",
            "t-part",
            "true error",
            "marked",
            "time (s)"
        );
        let line = |s: &mut String, what: String, r: &Row| {
            let err = r.error.map_or("—".to_string(), |e| format!("{e:.4e}"));
            let marked = r.marked.map_or("—".to_string(), |m| m.to_string());
            let _ = writeln!(
                s,
                "{:>10} {:>8} {:>9} {:>9} {:>5} {:>11.4e} {:>5.0}% {:>11} {:>8} {:>9.2}",
                what,
                r.nodes,
                r.cells,
                r.unknowns,
                r.generation,
                r.estimate,
                100.0 * r.time_share,
                err,
                marked,
                r.seconds
            );
        };
        let _ = writeln!(s, "{header}");
        for (i, r) in self.cycles.iter().enumerate() {
            line(&mut s, format!("cycle {i}"), r);
        }
        for (i, r) in self.uniform.iter().enumerate() {
            line(&mut s, format!("h/{}", 1 << i), r);
        }
        if let Some(r) = &self.reference {
            line(&mut s, "reference".into(), r);
        }
        s
    }
}
