//! How studies write numbers in tables, plots and messages: resolutions as fractions,
//! errors and times to three significant digits.

/// h or k as "1/n" when it is the reciprocal of a whole number, else a decimal.
pub fn fraction(v: f64) -> String {
    let inv = 1.0 / v;
    if (inv - inv.round()).abs() < 1e-9 * inv.abs().max(1.0) {
        format!("1/{:.0}", inv)
    } else {
        format!("{v:.4}")
    }
}

/// Three significant digits.
pub fn sig(x: f64) -> String {
    if x == 0.0 || !x.is_finite() {
        return format!("{x}");
    }
    let digits = (2 - x.abs().log10().floor() as i32).max(0) as usize;
    format!("{x:.digits$}")
}

#[cfg(test)]
mod tests {
    #[test]
    fn reciprocals_of_whole_numbers_are_fractions() {
        assert_eq!(super::fraction(0.125), "1/8");
        assert_eq!(super::fraction(1.0 / 24.0), "1/24");
        assert_eq!(super::fraction(1.0), "1/1");
        assert_eq!(super::fraction(0.3), "0.3000");
    }
}
