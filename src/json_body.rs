//! JSON request bodies, read into a [`Value`] with every object's keys unique.
//!
//! `serde_json` keeps the last of repeated keys (`{"preset": "a", "preset": "b"}` reads as
//! `"b"`). A proxy, a validator or a client library that keeps the first one would see
//! another document than the one the service acts on, so a repeated key is refused with 422
//! at its JSON pointer. Keys are compared after unescaping (`"a"` and `"\u0061"` are the same
//! key), as every JSON reader does.
//!
//! The check is part of the one parse (a `serde` visitor building the `Value`): linear in
//! the body (one hash lookup per key), no second pass over the text, and nesting bounded by
//! `serde_json`'s own recursion limit (128), as for a plain `serde_json::from_slice`. The
//! pointer of a duplicate is assembled only on the way out of an error, so a body without
//! duplicates costs what `from_slice` costs plus the lookups.

use crate::problem::Problem;
use serde::de::{self, DeserializeSeed, Deserializer, MapAccess, SeqAccess, Visitor};
use serde_json::{Map, Number, Value};
use std::cell::RefCell;
use std::fmt;

/// Why a body is not a JSON document with unique keys.
#[derive(Debug)]
pub enum BodyError {
    /// Not JSON (syntax, trailing characters, nesting beyond `serde_json`'s limit).
    Malformed(serde_json::Error),
    /// A key repeated in one object: the RFC 6901 pointer of its second occurrence's
    /// member (`/loads/f0` for a second `"f0"` in `loads`) and the key.
    Duplicate { pointer: String, key: String },
}

impl fmt::Display for BodyError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            BodyError::Malformed(e) => write!(f, "malformed JSON: {e}"),
            BodyError::Duplicate { pointer, key } => write!(
                f,
                "the key {key:?} appears more than once in one object (at {pointer:?}); \
                 readers disagree on which one counts, so each key may appear only once"
            ),
        }
    }
}

impl From<BodyError> for Problem {
    /// 400 for text that is not JSON, 422 at the pointer of a repeated key.
    fn from(e: BodyError) -> Problem {
        match &e {
            BodyError::Malformed(_) => Problem::bad_request(e.to_string()),
            BodyError::Duplicate { pointer, .. } => Problem::invalid_field(pointer, e.to_string()),
        }
    }
}

/// Parses `body` as one JSON document whose objects have unique keys.
pub fn parse(body: &[u8]) -> Result<Value, BodyError> {
    let ctx = Ctx::default();
    let mut de = serde_json::Deserializer::from_slice(body);
    let parsed = Seed(&ctx).deserialize(&mut de).and_then(|v| {
        de.end()?;
        Ok(v)
    });
    match (parsed, ctx.duplicate.into_inner()) {
        (Ok(v), _) => Ok(v),
        (Err(_), Some(key)) => {
            let trail = ctx.trail.into_inner();
            let pointer = trail.iter().rev().fold(String::new(), |mut p, t| {
                p.push('/');
                p.push_str(t);
                p
            });
            Err(BodyError::Duplicate { pointer, key })
        }
        (Err(e), None) => Err(BodyError::Malformed(e)),
    }
}

/// State shared by the visitors of one parse; only written once a duplicate is found.
#[derive(Default)]
struct Ctx {
    /// The repeated key, once found.
    duplicate: RefCell<Option<String>>,
    /// Pointer tokens (escaped), innermost first, added by each level the error leaves.
    trail: RefCell<Vec<String>>,
}

impl Ctx {
    /// Adds this level's token to the pointer if the error passing through is a duplicate.
    fn unwind(&self, token: impl FnOnce() -> String) {
        if self.duplicate.borrow().is_some() {
            self.trail.borrow_mut().push(token());
        }
    }
}

/// RFC 6901 escaping of one reference token.
fn escape(key: &str) -> String {
    key.replace('~', "~0").replace('/', "~1")
}

struct Seed<'c>(&'c Ctx);

impl<'de> DeserializeSeed<'de> for Seed<'_> {
    type Value = Value;
    fn deserialize<D: Deserializer<'de>>(self, d: D) -> Result<Value, D::Error> {
        d.deserialize_any(self)
    }
}

impl<'de> Visitor<'de> for Seed<'_> {
    type Value = Value;

    fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("any JSON value")
    }

    fn visit_bool<E>(self, b: bool) -> Result<Value, E> {
        Ok(Value::Bool(b))
    }

    fn visit_i64<E>(self, n: i64) -> Result<Value, E> {
        Ok(Value::Number(n.into()))
    }

    fn visit_u64<E>(self, n: u64) -> Result<Value, E> {
        Ok(Value::Number(n.into()))
    }

    fn visit_f64<E>(self, x: f64) -> Result<Value, E> {
        // serde_json's own Value does the same (JSON text has no NaN or infinity).
        Ok(Number::from_f64(x).map_or(Value::Null, Value::Number))
    }

    fn visit_str<E>(self, s: &str) -> Result<Value, E> {
        Ok(Value::String(s.to_owned()))
    }

    fn visit_string<E>(self, s: String) -> Result<Value, E> {
        Ok(Value::String(s))
    }

    fn visit_unit<E>(self) -> Result<Value, E> {
        Ok(Value::Null)
    }

    fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<Value, A::Error> {
        let mut items = Vec::with_capacity(seq.size_hint().unwrap_or(0).min(4096));
        loop {
            match seq.next_element_seed(Seed(self.0)) {
                Ok(Some(v)) => items.push(v),
                Ok(None) => return Ok(Value::Array(items)),
                Err(e) => {
                    let i = items.len();
                    self.0.unwind(|| i.to_string());
                    return Err(e);
                }
            }
        }
    }

    fn visit_map<A: MapAccess<'de>>(self, mut map: A) -> Result<Value, A::Error> {
        let mut members = Map::new();
        while let Some(key) = map.next_key::<String>()? {
            if members.contains_key(&key) {
                self.0.trail.borrow_mut().push(escape(&key));
                let message = format!("duplicate key {key:?}");
                *self.0.duplicate.borrow_mut() = Some(key);
                return Err(de::Error::custom(message));
            }
            match map.next_value_seed(Seed(self.0)) {
                Ok(v) => {
                    members.insert(key, v);
                }
                Err(e) => {
                    self.0.unwind(|| escape(&key));
                    return Err(e);
                }
            }
        }
        Ok(Value::Object(members))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn duplicate(text: &str) -> (String, String) {
        match parse(text.as_bytes()) {
            Err(BodyError::Duplicate { pointer, key }) => (pointer, key),
            other => panic!("{text}: expected a duplicate, got {other:?}"),
        }
    }

    #[test]
    fn same_value_as_serde_json_without_duplicates() {
        let text = r#"{"a": [1, -2, 3.5, 1e300, 0.1, 18446744073709551615, -0.0],
            "b": {"c": null, "d": true, "e": "x\u00e9\n"}, "z": [], "y": {},
            "n": 12345678901234567890123}"#;
        let ours = parse(text.as_bytes()).unwrap();
        let theirs: Value = serde_json::from_str(text).unwrap();
        assert_eq!(ours, theirs);
        // Key order is kept (preserve_order), as serde_json's.
        let keys: Vec<&String> = ours.as_object().unwrap().keys().collect();
        assert_eq!(keys, ["a", "b", "z", "y", "n"]);
    }

    #[test]
    fn a_repeated_key_is_found_at_its_pointer() {
        assert_eq!(
            duplicate(r#"{"preset": "a", "preset": "b"}"#),
            ("/preset".into(), "preset".into())
        );
        assert_eq!(
            duplicate(r#"{"name": "x", "loads": {"f0": [0, 1], "f2": 0, "f0": [1, 1]}}"#),
            ("/loads/f0".into(), "f0".into())
        );
        // Inside arrays: the index of the element is part of the pointer.
        assert_eq!(
            duplicate(r#"{"boundary": [{"part": 1}, {"part": 2, "kind": "x", "kind": "y"}]}"#),
            ("/boundary/1/kind".into(), "kind".into())
        );
        assert_eq!(
            duplicate(r#"[[0], [1, {"a/b~": 1, "a/b~": 2}]]"#),
            ("/1/1/a~1b~0".into(), "a/b~".into())
        );
    }

    #[test]
    fn keys_are_compared_unescaped() {
        assert_eq!(
            duplicate(r#"{"a": 1, "\u0061": 2}"#),
            ("/a".into(), "a".into())
        );
        assert_eq!(
            duplicate(r#"{"x": {"\/": 1, "/": 2}}"#),
            ("/x/~1".into(), "/".into())
        );
        // Equal only after unescaping both: still one key.
        assert_eq!(
            duplicate(r#"{"\u00e9t\u00e9": 1, "été": 2}"#),
            ("/été".into(), "été".into())
        );
    }

    #[test]
    fn the_same_key_in_different_objects_is_fine() {
        let v = parse(br#"{"a": {"a": 1}, "b": [{"a": 1}, {"a": 2}]}"#).unwrap();
        assert_eq!(v["b"][1]["a"], 2);
    }

    #[test]
    fn malformed_text_stays_malformed() {
        for text in ["", "{", r#"{"a": 1,}"#, r#"{"a": 1} x"#, "[1, 2"] {
            assert!(
                matches!(parse(text.as_bytes()), Err(BodyError::Malformed(_))),
                "{text:?}"
            );
        }
        // A syntax error after a duplicate-free prefix is not reported as a duplicate.
        assert!(matches!(
            parse(br#"{"a": {"b": 1, "c": }}"#),
            Err(BodyError::Malformed(_))
        ));
    }

    #[test]
    fn deep_nesting_is_refused_without_overflow() {
        // Beyond serde_json's recursion limit: an error, not a stack overflow.
        let deep = "[".repeat(100_000) + &"]".repeat(100_000);
        assert!(matches!(
            parse(deep.as_bytes()),
            Err(BodyError::Malformed(_))
        ));
        let deep_objects = "{\"a\":".repeat(100_000) + "1" + &"}".repeat(100_000);
        assert!(matches!(
            parse(deep_objects.as_bytes()),
            Err(BodyError::Malformed(_))
        ));
        // Within the limit, a duplicate at depth 100 has a 100-token pointer.
        let text = "{\"k\":".repeat(99) + r#"{"d": 1, "d": 2}"# + &"}".repeat(99);
        let (pointer, _) = duplicate(&text);
        assert_eq!(pointer, "/k".repeat(99) + "/d");
    }

    #[test]
    fn many_keys_take_linear_time() {
        // 200k distinct keys, then one repeat of the first: found, and quickly (a quadratic
        // check would take minutes).
        let mut text = String::from("{");
        for i in 0..200_000 {
            text.push_str(&format!("\"k{i}\": {i},"));
        }
        text.push_str("\"k0\": 0}");
        let t = std::time::Instant::now();
        assert_eq!(duplicate(&text), ("/k0".into(), "k0".into()));
        assert!(
            t.elapsed() < std::time::Duration::from_secs(5),
            "{:?}",
            t.elapsed()
        );
    }
}
