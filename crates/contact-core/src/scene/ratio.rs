//! Numbers written as ratios: "1/32" for a mesh size or time step.

use serde_json::Value;

use super::read::describe;

/// Reads a finite number (of any sign: callers check the range) given as a JSON number, a
/// numeric string ("0.25", "1e-3") or a ratio string "p/q" ("1/32"): mesh sizes and time steps
/// are naturally written as fractions, and 1/3 cannot be written exactly as a JSON number.
/// "inf", "NaN" and division by zero are refused.
pub fn parse_ratio(v: &Value) -> Result<f64, String> {
    match v {
        Value::Number(n) => n
            .as_f64()
            .filter(|x| x.is_finite())
            .ok_or_else(|| format!("{n} is not a finite number")),
        Value::String(s) => {
            let s = s.trim();
            let value = match s.split_once('/') {
                Some((p, q)) => {
                    let (p, q) = (decimal(p.trim(), s)?, decimal(q.trim(), s)?);
                    if q == 0.0 {
                        return Err(format!("\"{s}\" divides by zero"));
                    }
                    p / q
                }
                None => decimal(s, s)?,
            };
            if value.is_finite() {
                Ok(value)
            } else {
                Err(format!("\"{s}\" is not a finite number"))
            }
        }
        other => Err(format!(
            "expected a number or a ratio string like \"1/32\", got {}",
            describe(other)
        )),
    }
}

/// A plain decimal number: digits, '.', exponent and sign only (so "inf" and "NaN", which
/// Rust's float parser accepts, are not).
fn decimal(s: &str, whole: &str) -> Result<f64, String> {
    let plain = !s.is_empty()
        && s.chars()
            .all(|c| c.is_ascii_digit() || matches!(c, '.' | 'e' | 'E' | '+' | '-'));
    let value = if plain { s.parse::<f64>().ok() } else { None };
    match value {
        Some(v) if v.is_finite() => Ok(v),
        _ => Err(format!(
            "\"{whole}\" is not a number or a ratio of two numbers like \"1/32\""
        )),
    }
}
