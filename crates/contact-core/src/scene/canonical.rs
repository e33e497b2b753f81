//! Content keys of documents: equal scenes (whatever their key order) get equal hashes, which
//! is what result deduplication and the shared reference runs of studies are keyed by.

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
}
