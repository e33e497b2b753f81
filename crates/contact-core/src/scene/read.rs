//! Generic readers for the hand-written JSON walk of [`super::validate`].
//!
//! Each reader checks one value, reports its own error (with the value's JSON pointer and a
//! sentence naming what is allowed) into the [`Cx`], and returns `None` on failure, so that
//! validation can go on and collect every problem of a scene.

use serde_json::{Map, Value};

use super::{parse_ratio, FieldError};

/// Most errors reported for one scene: a hostile document (a million unknown fields) must
/// not produce a million messages. The rest are counted.
pub(super) const MAX_ERRORS: usize = 100;

/// The errors collected so far.
#[derive(Default)]
pub(super) struct Cx {
    pub(super) errors: Vec<FieldError>,
    /// Errors beyond [`MAX_ERRORS`], counted but not kept.
    dropped: usize,
    /// The body is 3D (set once the domain is read): formulas may use z.
    pub(super) solid: bool,
}

impl Cx {
    pub(super) fn err(&mut self, pointer: &str, message: impl Into<String>) {
        let message = message.into();
        // A field read by two readers (e.g. the mesh by its own reader and by the domain's)
        // is reported once.
        if self
            .errors
            .iter()
            .any(|e| e.pointer == pointer && e.message == message)
        {
            return;
        }
        if self.errors.len() >= MAX_ERRORS {
            self.dropped += 1;
            return;
        }
        self.errors.push(FieldError {
            pointer: pointer.to_string(),
            message,
        });
    }

    /// The errors, with a last entry counting those not kept.
    pub(super) fn finish(mut self) -> Vec<FieldError> {
        if self.dropped > 0 {
            self.errors.push(FieldError {
                pointer: String::new(),
                message: format!(
                    "... and {} more problems (only the first {MAX_ERRORS} are listed)",
                    self.dropped
                ),
            });
        }
        self.errors
    }
}

#[derive(Clone, Copy)]
pub(super) enum Range {
    Any,
    Positive,
    NonNegative,
    /// [0, 1]
    ClosedUnit,
    /// (0, 1]
    OpenUnit,
}

impl Range {
    pub(super) fn holds(self, x: f64) -> bool {
        x.is_finite()
            && match self {
                Range::Any => true,
                Range::Positive => x > 0.0,
                Range::NonNegative => x >= 0.0,
                Range::ClosedUnit => (0.0..=1.0).contains(&x),
                Range::OpenUnit => x > 0.0 && x <= 1.0,
            }
    }

    pub(super) fn describe(self) -> &'static str {
        match self {
            Range::Any => "finite",
            Range::Positive => "> 0",
            Range::NonNegative => "≥ 0",
            Range::ClosedUnit => "in [0, 1]",
            Range::OpenUnit => "in (0, 1]",
        }
    }
}

pub(super) fn number(cx: &mut Cx, v: &Value, ptr: &str, range: Range) -> Option<f64> {
    match v.as_f64() {
        Some(x) if range.holds(x) => Some(x),
        Some(x) => {
            cx.err(ptr, format!("must be {}, got {x}", range.describe()));
            None
        }
        None => {
            cx.err(
                ptr,
                format!(
                    "expected a number {}, got {}",
                    range.describe(),
                    describe(v)
                ),
            );
            None
        }
    }
}

/// A number or ratio string (see [`parse_ratio`]) in `range`.
pub(super) fn ratio(cx: &mut Cx, v: &Value, ptr: &str, range: Range) -> Option<f64> {
    match parse_ratio(v) {
        Ok(x) if range.holds(x) => Some(x),
        Ok(x) => {
            cx.err(ptr, format!("must be {}, got {x}", range.describe()));
            None
        }
        Err(msg) => {
            cx.err(
                ptr,
                format!("{msg} (expected a number {})", range.describe()),
            );
            None
        }
    }
}

/// A whole number ≥ `min` (1.0 is accepted as 1).
pub(super) fn integer(cx: &mut Cx, v: &Value, ptr: &str, min: u64) -> Option<u64> {
    let n = v.as_u64().or_else(|| {
        v.as_f64()
            .filter(|x| x.fract() == 0.0 && *x >= 0.0 && *x <= 9.0e15)
            .map(|x| x as u64)
    });
    match n {
        Some(n) if n >= min => Some(n),
        _ => {
            cx.err(
                ptr,
                format!("expected a whole number ≥ {min}, got {}", describe(v)),
            );
            None
        }
    }
}

pub(super) fn point(cx: &mut Cx, v: &Value, ptr: &str) -> Option<[f64; 2]> {
    let Some(items) = v.as_array().filter(|a| a.len() == 2) else {
        cx.err(ptr, format!("expected a point [x, y], got {}", describe(v)));
        return None;
    };
    let x = number(cx, &items[0], &index(ptr, 0), Range::Any);
    let y = number(cx, &items[1], &index(ptr, 1), Range::Any);
    Some([x?, y?])
}

/// One of the strings in `allowed`; returns its index.
pub(super) fn choice(
    cx: &mut Cx,
    v: &Value,
    ptr: &str,
    what: &str,
    allowed: &[&str],
) -> Option<usize> {
    let found = v
        .as_str()
        .and_then(|s| allowed.iter().position(|a| *a == s));
    if found.is_none() {
        let hint = v
            .as_str()
            .and_then(|s| suggest(s, allowed.iter().copied()))
            .map(|s| format!(" (did you mean \"{s}\"?)"))
            .unwrap_or_default();
        cx.err(
            ptr,
            format!(
                "{what} must be one of {}, got {}{hint}",
                quoted(allowed),
                describe(v)
            ),
        );
    }
    found
}

pub(super) fn required<'a>(
    cx: &mut Cx,
    m: &'a Map<String, Value>,
    ptr: &str,
    key: &str,
    what: &str,
) -> Option<&'a Value> {
    let v = m.get(key);
    if v.is_none() {
        cx.err(
            &join(ptr, key),
            format!("missing required field '{key}' ({what})"),
        );
    }
    v
}

pub(super) fn required_number(
    cx: &mut Cx,
    m: &Map<String, Value>,
    ptr: &str,
    key: &str,
    range: Range,
    what: &str,
) -> Option<f64> {
    let v = m.get(key);
    let kptr = join(ptr, key);
    match v {
        None => {
            cx.err(
                &kptr,
                format!(
                    "missing required field '{key}' ({what}, a number {})",
                    range.describe()
                ),
            );
            None
        }
        Some(v) => number(cx, v, &kptr, range),
    }
}

pub(super) fn optional_number(
    cx: &mut Cx,
    m: &Map<String, Value>,
    ptr: &str,
    key: &str,
    range: Range,
    default: f64,
) -> Option<f64> {
    match m.get(key) {
        None => Some(default),
        Some(v) => number(cx, v, &join(ptr, key), range),
    }
}

/// Checks that `v` is an object and that all its fields are in `allowed`.
pub(super) fn object<'a>(
    cx: &mut Cx,
    v: &'a Value,
    ptr: &str,
    what: &str,
    allowed: &[&str],
) -> Option<&'a Map<String, Value>> {
    let Some(m) = v.as_object() else {
        cx.err(
            ptr,
            format!("{what} must be an object, got {}", describe(v)),
        );
        return None;
    };
    for key in m.keys() {
        if !allowed.contains(&key.as_str()) {
            let hint = suggest(key, allowed.iter().copied())
                .map(|s| format!("did you mean '{s}'? "))
                .unwrap_or_default();
            cx.err(
                &join(ptr, key),
                format!(
                    "unknown field '{key}'; {hint}allowed here: {}",
                    allowed.join(", ")
                ),
            );
        }
    }
    Some(m)
}

/// An object whose allowed fields depend on a tag field (`type` or `law`). Returns the tag
/// and the object. When the tag is missing or unknown, only fields unknown to every variant are
/// reported (a typo in the tag should not also flag all the variant's fields).
pub(super) fn variant_object<'a, 'v>(
    cx: &mut Cx,
    v: &'a Value,
    ptr: &str,
    what: &str,
    tag: &str,
    variants: &'v [(&'v str, &'v [&'v str])],
) -> Option<(&'v str, &'a Map<String, Value>)> {
    let Some(m) = v.as_object() else {
        cx.err(
            ptr,
            format!("{what} must be an object, got {}", describe(v)),
        );
        return None;
    };
    let names: Vec<&str> = variants.iter().map(|(n, _)| *n).collect();
    let tptr = join(ptr, tag);
    let variant = match m.get(tag) {
        None => {
            cx.err(
                &tptr,
                format!("missing required field '{tag}' (one of {})", quoted(&names)),
            );
            None
        }
        Some(t) => choice(cx, t, &tptr, tag, &names).map(|i| variants[i]),
    };
    for key in m.keys() {
        let known = |fields: &[&str]| fields.contains(&key.as_str());
        match variant {
            Some((name, fields)) if !known(fields) => {
                let owners: Vec<&str> = variants
                    .iter()
                    .filter(|(_, f)| known(f))
                    .map(|(n, _)| *n)
                    .collect();
                let msg = if owners.is_empty() {
                    let hint = suggest(key, fields.iter().copied())
                        .map(|s| format!("did you mean '{s}'? "))
                        .unwrap_or_default();
                    format!(
                        "unknown field '{key}'; {hint}allowed for {tag} \"{name}\": {}",
                        fields.join(", ")
                    )
                } else {
                    format!(
                        "field '{key}' belongs to {tag} {}, not to \"{name}\" (allowed here: {})",
                        quoted(&owners),
                        fields.join(", ")
                    )
                };
                cx.err(&join(ptr, key), msg);
            }
            None if !variants.iter().any(|(_, f)| known(f)) => {
                cx.err(&join(ptr, key), format!("unknown field '{key}' for {what}"));
            }
            _ => {}
        }
    }
    variant.map(|(name, _)| (name, m))
}

/// The closest known name within edit distance 2, for "did you mean" hints.
pub(super) fn suggest<'a>(key: &str, known: impl Iterator<Item = &'a str>) -> Option<&'a str> {
    known
        .map(|k| (edit_distance(key, k), k))
        .filter(|(d, _)| *d <= 2)
        .min_by_key(|(d, _)| *d)
        .map(|(_, k)| k)
}

pub(super) fn edit_distance(a: &str, b: &str) -> usize {
    let (a, b): (Vec<char>, Vec<char>) = (a.chars().take(64).collect(), b.chars().collect());
    let mut prev: Vec<usize> = (0..=b.len()).collect();
    for (i, ca) in a.iter().enumerate() {
        let mut cur = vec![i + 1; b.len() + 1];
        for (j, cb) in b.iter().enumerate() {
            cur[j + 1] = (prev[j] + usize::from(ca != cb))
                .min(prev[j + 1] + 1)
                .min(cur[j] + 1);
        }
        prev = cur;
    }
    prev[b.len()]
}

pub(super) fn quoted(names: &[&str]) -> String {
    names
        .iter()
        .map(|n| format!("\"{n}\""))
        .collect::<Vec<_>>()
        .join(", ")
}

/// A short description of a JSON value for messages.
pub(super) fn describe(v: &Value) -> String {
    match v {
        Value::Null => "null".to_string(),
        Value::Bool(b) => format!("the boolean {b}"),
        Value::Number(n) => format!("the number {n}"),
        Value::String(s) => {
            let short: String = s.chars().take(40).collect();
            let more = if s.chars().count() > 40 { "…" } else { "" };
            format!("the string \"{short}{more}\"")
        }
        Value::Array(a) => format!(
            "an array of {} element{}",
            a.len(),
            if a.len() == 1 { "" } else { "s" }
        ),
        Value::Object(_) => "an object".to_string(),
    }
}

/// `ptr` extended by an object key, escaped as RFC 6901 requires (~ → ~0, / → ~1).
pub(super) fn join(ptr: &str, key: &str) -> String {
    format!("{ptr}/{}", key.replace('~', "~0").replace('/', "~1"))
}

pub(super) fn index(ptr: &str, i: usize) -> String {
    format!("{ptr}/{i}")
}
