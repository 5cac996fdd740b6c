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
    let decimals = (1.0 - se.log10().floor()).clamp(0.0, 12.0) as usize;
    format!("{value:+.decimals$} ± {se:.decimals$}")
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
    }
}
