//! Content keys of documents: equal scenes (whatever their key order) get equal hashes, which
//! is what result deduplication and the shared reference runs of studies are keyed by; and
//! the computation a document asks for, without the labels that change no number.

use serde_json::{Map, Value};
use sha2::{Digest, Sha256};

/// The document with object keys sorted recursively.
pub fn canonical(v: &Value) -> Value {
    match v {
        Value::Object(m) => {
            let mut keys: Vec<&String> = m.keys().collect();
            keys.sort();
            Value::Object(
                keys.into_iter()
                    .map(|k| (k.clone(), canonical(&m[k])))
                    .collect::<Map<_, _>>(),
            )
        }
        Value::Array(a) => Value::Array(a.iter().map(canonical).collect()),
        _ => v.clone(),
    }
}

/// The top-level fields of a scene that label it and change no number, no stored step and no
/// check: two scenes that differ only in these are one computation.
pub const LABEL_FIELDS: &[&str] = &["$schema", "name"];

/// The computation a stored job document asks for: a scene, or a study or sweep request
/// `{"study": {...}}`, `{"sweep": {...}}` (its `name` and its inline scene's labels), with the
/// [`LABEL_FIELDS`] removed, so that the same computation under another name gets the same
/// content key.
pub fn computation(doc: &Value) -> Value {
    let mut doc = doc.clone();
    let key = if doc.get("sweep").is_some() {
        "sweep"
    } else {
        "study"
    };
    match doc.get_mut(key).and_then(Value::as_object_mut) {
        Some(study) => {
            study.remove("name");
            if let Some(scene) = study.get_mut("scene") {
                strip_labels(scene);
            }
        }
        None => strip_labels(&mut doc),
    }
    doc
}

/// Removes a scene's [`LABEL_FIELDS`] (a preset name, a string, is left as it is).
fn strip_labels(scene: &mut Value) {
    if let Some(o) = scene.as_object_mut() {
        for k in LABEL_FIELDS {
            o.remove(*k);
        }
    }
}

/// Lower-case hex SHA-256 of the canonical JSON text of `v`.
pub fn content_hash(v: &Value) -> String {
    hex_sha256(canonical(v).to_string().as_bytes())
}

pub fn hex_sha256(bytes: &[u8]) -> String {
    Sha256::digest(bytes)
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    #[test]
    fn key_order_does_not_change_the_hash_but_values_do() {
        let a = json!({"b": 1, "a": {"y": [1, {"q": 2, "p": 3}], "x": null}});
        let b = json!({"a": {"x": null, "y": [1, {"p": 3, "q": 2}]}, "b": 1});
        assert_eq!(content_hash(&a), content_hash(&b));
        let c = json!({"a": {"x": null, "y": [{"p": 3, "q": 2}, 1]}, "b": 1});
        assert_ne!(content_hash(&a), content_hash(&c), "array order matters");
        assert_eq!(content_hash(&json!(1)).len(), 64);
    }

    #[test]
    fn labels_are_not_part_of_the_computation_but_everything_else_is() {
        let scene = crate::scene::presets::get("paper-exp2").unwrap();
        let key = |doc: &Value| content_hash(&computation(doc));
        let mut renamed = scene.clone();
        renamed["name"] = json!("my bracket");
        renamed["$schema"] = json!("https://example.org/scene.schema.json");
        assert_ne!(scene, renamed);
        assert_eq!(key(&scene), key(&renamed));
        let mut changed = scene.clone();
        changed["damage"]["kappa"] = json!(0.25);
        assert_ne!(key(&scene), key(&changed));
        let mut output = scene.clone();
        output["output"]["every"] = json!(2);
        assert_ne!(
            key(&scene),
            key(&output),
            "what is stored is part of the key"
        );

        // A study's name and its inline scene's name; its levels are not labels.
        let study = |name: &str, scene: &Value, k: &str| json!({"study": {"name": name, "scene": scene, "h": "1/2", "k": k}});
        assert_eq!(
            key(&study("a", &scene, "1/4")),
            key(&study("b", &renamed, "1/4"))
        );
        assert_ne!(
            key(&study("a", &scene, "1/4")),
            key(&study("a", &scene, "1/8"))
        );
        // A study of a preset by name keeps the name: it is the scene.
        assert_ne!(
            key(&json!({"study": {"scene": "paper-convergence"}})),
            key(&json!({"study": {"scene": "paper-exp2"}}))
        );
    }
}
