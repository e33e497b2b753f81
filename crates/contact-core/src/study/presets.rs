//! Study presets: the paper's Tables 1 and 2 (convergence test, reference h = k = 1/128), an
//! adaptive study and a target study that may take adaptive meshes, both of the l-bracket.

use serde_json::{json, Value};

const LADDER: [&str; 5] = ["1/2", "1/4", "1/8", "1/16", "1/32"];

pub fn names() -> &'static [&'static str] {
    &[
        "paper-table-1",
        "paper-table-2",
        "l-bracket-adaptive",
        "l-bracket-target",
    ]
}

pub fn description(name: &str) -> Option<&'static str> {
    match name {
        "paper-table-1" => {
            Some("Table 1: errors in h = 1/2 … 1/32 at k = 1/128, reference h = k = 1/128")
        }
        "paper-table-2" => {
            Some("Table 2: errors in k = 1/2 … 1/32 at h = 1/128, reference h = k = 1/128")
        }
        "l-bracket-adaptive" => Some(
            "Adaptive study of the l-bracket: meshes bisected where the a posteriori estimate is, until the relative estimate of w is 0.15, beside uniform refinement",
        ),
        "l-bracket-target" => Some(
            "Target study of the l-bracket: the cheapest run with an error in w below 0.05, on an adaptive mesh where that has fewer nodes than the uniform level",
        ),
        _ => None,
    }
}

/// The study document of a preset.
pub fn get(name: &str) -> Option<Value> {
    let reference = json!({"h": "1/128", "k": "1/128"});
    match name {
        "paper-table-1" => Some(json!({"name": name, "scene": "paper-convergence",
            "h": LADDER, "k": "1/128", "reference": reference})),
        "paper-table-2" => Some(json!({"name": name, "scene": "paper-convergence",
            "h": "1/128", "k": LADDER, "reference": reference})),
        "l-bracket-adaptive" => Some(json!({"name": name, "scene": "l-bracket",
            "adapt": {"target": 0.15, "max_nodes": 20000}})),
        "l-bracket-target" => Some(json!({"name": name, "scene": "l-bracket",
            "target": {"error": 0.05, "quantity": "w", "meshes": "auto"}})),
        _ => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn presets_parse_and_share_one_reference() {
        let plans: Vec<_> = ["paper-table-1", "paper-table-2"]
            .iter()
            .map(|n| super::super::parse(&get(n).unwrap(), "").unwrap().0)
            .collect();
        assert_eq!(
            plans[0].levels,
            [(2, 128), (4, 128), (8, 128), (16, 128), (32, 128)]
        );
        assert_eq!(
            plans[1].levels,
            [(128, 2), (128, 4), (128, 8), (128, 16), (128, 32)]
        );
        assert_eq!(plans[0].reference_key, plans[1].reference_key);
        assert!(names().iter().all(|n| description(n).is_some()));
    }

    /// Each preset is read as the kind of study its name says, and `{"preset": name}` reads
    /// as its document does.
    #[test]
    fn every_preset_is_a_study_of_its_kind() {
        use super::super::request::{parse, Request};
        let files = crate::scene::Bundled;
        for n in names() {
            let (by_doc, doc) = parse(&get(n).unwrap(), "/study", &files).unwrap();
            let (_, by_name) = parse(&json!({"preset": n}), "/study", &files).unwrap();
            assert_eq!(doc, by_name, "{n}");
            let kind = match by_doc {
                Request::Ladder(_) => "table",
                Request::Adapt { .. } => "adaptive",
                Request::Target { .. } => "target",
                Request::Sweep(_) => "sweep",
            };
            assert!(
                n.ends_with(kind) || n.contains(kind),
                "{n} is a {kind} study"
            );
        }
    }
}
