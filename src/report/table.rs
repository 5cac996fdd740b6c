//! Terminal tables and CSV.

/// A plain-text table; columns whose cells all look numeric are right-aligned.
pub fn text_table(headers: &[&str], rows: &[Vec<String>]) -> String {
    let n = headers.len();
    let mut width: Vec<usize> = headers.iter().map(|h| h.chars().count()).collect();
    for row in rows {
        for (w, cell) in width.iter_mut().zip(row) {
            *w = (*w).max(cell.chars().count());
        }
    }
    let numeric: Vec<bool> = (0..n)
        .map(|c| {
            rows.iter().all(|r| {
                r.get(c).is_some_and(|s| {
                    let t = s.trim_end_matches(" %").trim_start_matches(['+', '-', '−']);
                    t == "—" || t.parse::<f64>().is_ok() || t == "NaN"
                })
            })
        })
        .collect();
    let line = |cells: Vec<&str>| -> String {
        let parts: Vec<String> = cells
            .iter()
            .enumerate()
            .map(|(c, s)| {
                let pad = width[c].saturating_sub(s.chars().count());
                if numeric[c] {
                    format!("{}{s}", " ".repeat(pad))
                } else {
                    format!("{s}{}", " ".repeat(pad))
                }
            })
            .collect();
        parts.join("  ").trim_end().to_string() + "\n"
    };
    let mut out = line(headers.to_vec());
    out += &line(
        width
            .iter()
            .map(|&w| "-".repeat(w))
            .collect::<Vec<_>>()
            .iter()
            .map(|s| s.as_str())
            .collect(),
    );
    for row in rows {
        out += &line(row.iter().map(|s| s.as_str()).collect());
    }
    out
}

/// CSV with RFC 4180 quoting (fields holding commas, quotes or newlines are quoted).
pub fn csv(headers: &[&str], rows: &[Vec<String>]) -> String {
    let field = |s: &str| {
        if s.contains([',', '"', '\n', '\r']) {
            format!("\"{}\"", s.replace('"', "\"\""))
        } else {
            s.to_string()
        }
    };
    let mut out = headers
        .iter()
        .map(|h| field(h))
        .collect::<Vec<_>>()
        .join(",")
        + "\n";
    for row in rows {
        out += &(row.iter().map(|c| field(c)).collect::<Vec<_>>().join(",") + "\n");
    }
    out
}

/// "+0.0208 ± 0.0013": a signed value and its standard error, the error to two significant
/// digits and the value to the same decimal place (the digits the uncertainty supports; a
/// person reads no more into the number than it holds). Non-finite or zero errors fall back to
/// five decimals.
pub fn plus_minus(value: f64, se: f64) -> String {
    if !(se.is_finite() && se > 0.0 && value.is_finite()) {
        return format!("{value:+.5} ± {se:.5}");
    }
    let d = decimals_for(se);
    format!("{} ± {se:.d$}", signed(value, d))
}

/// `value` to `d` decimals, a value that rounds to zero without a minus sign.
fn fixed(value: f64, d: usize) -> String {
    let text = format!("{value:.d$}");
    match text.strip_prefix('-') {
        Some(rest) if rest.bytes().all(|b| b == b'0' || b == b'.') => rest.to_string(),
        _ => text,
    }
}

/// `value` (finite) signed to `d` decimals, a value that rounds to zero as "+0.000" (not
/// "-0.000"): [`fixed`] with its sign written out.
fn signed(value: f64, d: usize) -> String {
    let text = fixed(value, d);
    if text.starts_with('-') {
        text
    } else {
        format!("+{text}")
    }
}

/// A signed value to the decimal place its standard error supports, without the error:
/// "+30.75" (a column whose errors another column states).
pub fn rounded_to_error(value: f64, se: f64) -> String {
    if !(se.is_finite() && se > 0.0 && value.is_finite()) {
        return format!("{value:+.5}");
    }
    signed(value, decimals_for(se))
}

/// "0.00202 ± 0.00004": a length debiased for noise (a discrepancy or one of its parts) and its
/// standard error, as [`plus_minus`] without the sign; "< 0.00038" where the debiasing left
/// zero — the part is below its noise, and the bound is twice its standard error there (not
/// "0.00000", which reads as perfect agreement). "—" for a length that could not be measured.
pub fn length_pm(value: f64, se: f64) -> String {
    if !value.is_finite() {
        return "—".into();
    }
    if !(se.is_finite() && se > 0.0) {
        return format!("{value:.5}");
    }
    let d = decimals_for(se);
    if value <= 0.0 {
        return format!("< {:.d$}", 2.0 * se);
    }
    format!("{value:.d$} ± {se:.d$}")
}

/// A fitted parameter and its standard error to the digits the error supports: "0.525 ± 0.095",
/// or with a shared power of ten outside 0.001–9999: "(1.042 ± 0.026)e-4". Without a finite
/// error, the value to five significant digits.
pub fn value_pm(value: f64, se: f64) -> String {
    if !value.is_finite() {
        return "—".into();
    }
    if !(se.is_finite() && se > 0.0) {
        return format!("{value:.4e}");
    }
    let exponent = value.abs().max(se).log10().floor() as i32;
    if (-3..4).contains(&exponent) {
        let d = decimals_for(se);
        return format!("{} ± {se:.d$}", fixed(value, d));
    }
    let unit = 10f64.powi(exponent);
    let (v, s) = (value / unit, se / unit);
    let d = decimals_for(s);
    format!("({} ± {s:.d$})e{exponent}", fixed(v, d))
}

/// `name = value ± se, …` for fitted parameters, each to the digits its error supports
/// ([`value_pm`]); a parameter without an error to five significant digits.
pub fn parameters_text(
    params: &std::collections::BTreeMap<String, f64>,
    stderr: &std::collections::BTreeMap<String, f64>,
) -> String {
    params
        .iter()
        .map(|(k, v)| {
            let se = stderr.get(k).copied().unwrap_or(f64::NAN);
            format!("{k} = {}", value_pm(*v, se))
        })
        .collect::<Vec<_>>()
        .join(", ")
}

/// `x` to `digits` significant digits in fixed notation (a statistic whose own relative error
/// is a few per cent: three digits say all it holds). "—" for a value that could not be
/// measured.
pub fn significant(x: f64, digits: u32) -> String {
    if !x.is_finite() {
        return "—".into();
    }
    if x == 0.0 {
        return "0".into();
    }
    let d = (digits as i32 - 1 - x.abs().log10().floor() as i32).clamp(0, 12) as usize;
    format!("{x:.d$}")
}

/// Decimal places that show an error to two significant digits.
fn decimals_for(se: f64) -> usize {
    (1.0 - se.log10().floor()).clamp(0.0, 12.0) as usize
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn csv_quotes_what_it_must() {
        let s = csv(&["a", "b"], &[vec!["x,y".into(), "say \"hi\"".into()]]);
        assert_eq!(s, "a,b\n\"x,y\",\"say \"\"hi\"\"\"\n");
    }

    #[test]
    fn numbers_are_right_aligned() {
        let t = text_table(
            &["name", "value"],
            &[
                vec!["a".into(), "1.5".into()],
                vec!["bb".into(), "-10.25".into()],
            ],
        );
        let lines: Vec<&str> = t.lines().collect();
        assert_eq!(lines[2], "a        1.5");
        assert_eq!(lines[3], "bb    -10.25");
    }

    #[test]
    fn plus_minus_keeps_the_digits_the_error_supports() {
        assert_eq!(plus_minus(-0.020834, 0.0013), "-0.0208 ± 0.0013");
        assert_eq!(plus_minus(0.104127, 0.0019), "+0.1041 ± 0.0019");
        assert_eq!(plus_minus(12.3456, 0.25), "+12.35 ± 0.25");
        assert_eq!(plus_minus(1234.5, 37.0), "+1234 ± 37");
        assert_eq!(plus_minus(0.5, 0.0), "+0.50000 ± 0.00000");
        assert_eq!(plus_minus(-0.000001, 0.00012), "+0.00000 ± 0.00012");
    }

    #[test]
    fn a_length_below_its_noise_is_a_bound_not_zero() {
        assert_eq!(length_pm(0.00202, 0.000041), "0.002020 ± 0.000041");
        assert_eq!(length_pm(0.0, 0.00019), "< 0.00038");
        assert_eq!(length_pm(f64::NAN, 0.1), "—");
        assert_eq!(length_pm(0.5, f64::NAN), "0.50000");
        assert_eq!(rounded_to_error(30.7503, 0.0062), "+30.7503");
        assert_eq!(rounded_to_error(30.7503, 0.062), "+30.750");
    }

    #[test]
    fn a_parameter_keeps_the_digits_its_error_supports() {
        assert_eq!(value_pm(1.0419e-4, 2.5841e-6), "(1.042 ± 0.026)e-4");
        assert_eq!(value_pm(-1.7635e-4, 1.7969e-5), "(-1.76 ± 0.18)e-4");
        assert_eq!(value_pm(0.52484, 0.094965), "0.525 ± 0.095");
        assert_eq!(value_pm(-151.67, 311.39), "-152 ± 311");
        assert_eq!(value_pm(6.1532e-3, f64::NAN), "6.1532e-3");
        assert_eq!(value_pm(-4.1632e-9, 1.4492e-7), "(0.0 ± 1.4)e-7");
    }

    #[test]
    fn significant_digits_follow_the_magnitude() {
        assert_eq!(significant(0.0019534, 3), "0.00195");
        assert_eq!(significant(-5.48123, 3), "-5.48");
        assert_eq!(significant(18937.1, 3), "18937");
        assert_eq!(significant(0.0, 3), "0");
    }
}
