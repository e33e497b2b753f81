//! The `time` section: the final time T and a whole number N of steps k = T/N.

use serde_json::Value;

use super::fields::TIME_FIELDS;
use super::read::{integer, join, object, ratio, Cx, Range};
use super::WHOLE_TOL;

/// Most time steps: a representability guard (not a resource limit, which belongs to the
/// service), far inside the range where f64 holds integers exactly.
const MAX_STEPS: f64 = 1.0e9;

/// (T, N) from t_end (alias T) and either k (T/k must be whole) or N (alias steps).
pub(super) fn time(cx: &mut Cx, v: &Value, ptr: &str) -> Option<(f64, usize)> {
    let m = object(cx, v, ptr, "time", TIME_FIELDS)?;
    let t_end = match (m.get("t_end"), m.get("T")) {
        (Some(_), Some(_)) => {
            cx.err(&join(ptr, "T"), "give t_end or its alias T, not both");
            None
        }
        (Some(t), None) => ratio(cx, t, &join(ptr, "t_end"), Range::Positive),
        (None, Some(t)) => ratio(cx, t, &join(ptr, "T"), Range::Positive),
        (None, None) => {
            cx.err(
                &join(ptr, "t_end"),
                "missing required field 't_end' (the final time T > 0; alias T)",
            );
            None
        }
    };
    let given: Vec<&str> = ["k", "N", "steps"]
        .into_iter()
        .filter(|key| m.contains_key(*key))
        .collect();
    let steps = match given.as_slice() {
        [] => {
            cx.err(
                &join(ptr, "k"),
                "missing the time step: give k (e.g. \"1/32\") or the number of steps N",
            );
            None
        }
        ["k"] => {
            let kptr = join(ptr, "k");
            let k = ratio(cx, &m["k"], &kptr, Range::Positive)?;
            let t = t_end?;
            let q = t / k;
            let n = q.round();
            if q < 1.0 - WHOLE_TOL {
                cx.err(&kptr, format!("k = {k} is longer than t_end = {t}"));
                None
            } else if (q - n).abs() > WHOLE_TOL * q {
                cx.err(
                    &kptr,
                    format!(
                        "t_end/k = {t}/{k} = {q} must be a whole number of steps; \
                         choose k = t_end/N for a whole N"
                    ),
                );
                None
            } else if n > MAX_STEPS {
                cx.err(
                    &kptr,
                    format!("t_end/k = {n} steps is more than {MAX_STEPS}"),
                );
                None
            } else {
                Some(n as usize)
            }
        }
        [key] => {
            let nptr = join(ptr, key);
            let n = integer(cx, &m[*key], &nptr, 1)?;
            if n as f64 > MAX_STEPS {
                cx.err(&nptr, format!("{key} = {n} steps is more than {MAX_STEPS}"));
                None
            } else {
                Some(n as usize)
            }
        }
        [_, second, ..] => {
            cx.err(
                &join(ptr, second),
                format!(
                    "give exactly one of k, N (alias steps); this scene gives {}",
                    given.join(" and ")
                ),
            );
            None
        }
    };
    Some((t_end?, steps?))
}
