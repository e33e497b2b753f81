//! Study presets: the paper's Tables 1 and 2 (convergence test, reference h = k = 1/128).

use serde_json::{json, Value};

const LADDER: [&str; 5] = ["1/2", "1/4", "1/8", "1/16", "1/32"];

pub fn names() -> &'static [&'static str] {
    &["paper-table-1", "paper-table-2"]
}

pub fn description(name: &str) -> Option<&'static str> {
    match name {
        "paper-table-1" => {
            Some("Table 1: errors in h = 1/2 … 1/32 at k = 1/128, reference h = k = 1/128")
        }
        "paper-table-2" => {
            Some("Table 2: errors in k = 1/2 … 1/32 at h = 1/128, reference h = k = 1/128")
        }
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
        _ => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn presets_parse_and_share_one_reference() {
        let plans: Vec<_> = names()
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
}
