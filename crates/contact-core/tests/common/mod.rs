//! Shared helpers of the whole-run tests: scenes from presets with edits, and runs.
#![allow(dead_code)]

use contact_core::problem::Problem;
use contact_core::scene::{self, presets, Overrides};
use contact_core::solve::stepper::{Simulation, StepReport};
use contact_core::solve::SolverSettings;
use serde_json::Value;

pub mod dirichlet;

/// A preset at resolution h = 1/nh, k = 1/nk, with JSON edits (pointer, value) applied
/// (a null value removes the field).
pub fn problem(preset: &str, nh: usize, nk: usize, edits: &[(&str, Value)]) -> Problem {
    let mut doc = presets::get(preset).expect("preset");
    for (ptr, v) in edits {
        let (parent, key) = ptr.rsplit_once('/').expect("a JSON pointer");
        let obj = doc
            .pointer_mut(parent)
            .and_then(Value::as_object_mut)
            .unwrap_or_else(|| panic!("no object at {parent:?} in {preset}"));
        // null removes a field; a new key is added.
        if v.is_null() {
            obj.remove(key);
        } else {
            obj.insert(key.to_string(), v.clone());
        }
    }
    let o = Overrides {
        h: Some(Value::String(format!("1/{nh}"))),
        k: Some(Value::String(format!("1/{nk}"))),
        t_end: None,
    };
    scene::apply_overrides(&mut doc, &o);
    scene::validate(&doc).unwrap_or_else(|e| panic!("{preset}: {e}"))
}

/// Runs to the end, calling `check` after every step.
pub fn run_checked(p: Problem, mut check: impl FnMut(&Simulation, &StepReport)) -> Simulation {
    let mut sim = Simulation::<2>::new(p, SolverSettings::default()).expect("set-up");
    while !sim.finished() {
        let r = sim.step().expect("step");
        check(&sim, &r);
    }
    sim
}

pub fn run(p: Problem) -> Simulation {
    run_checked(p, |_, _| {})
}

pub fn rel(a: f64, b: f64) -> f64 {
    (a - b).abs() / b.abs()
}
