//! Shared SVG pieces: escaping, axis ticks, number formatting, the series palette.

/// The opening of a standalone SVG document `w` x `h` px on white, with `title` centred on top.
pub fn start_document(w: f64, h: f64, title: &str) -> String {
    format!(
        r#"<svg xmlns="http://www.w3.org/2000/svg" viewBox="0 0 {w} {h}" width="{w}" height="{h}" font-family="sans-serif" font-size="12"><rect x="0" y="0" width="{w}" height="{h}" fill="white"/><text x="{}" y="22" text-anchor="middle" font-size="15" font-weight="bold">{}</text>"#,
        w / 2.0,
        escape(title)
    )
}

/// Escapes text for SVG content and attributes.
pub fn escape(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

/// "Nice" ticks (steps of 1, 2 or 5 × 10^k) from 0 or below `lo` to at least `hi`, about `n` of them.
pub fn nice_ticks(lo: f64, hi: f64, n: usize) -> Vec<f64> {
    let (lo, hi) = if hi > lo {
        (lo, hi)
    } else {
        (lo - 1.0, lo + 1.0)
    };
    let raw = (hi - lo) / n.max(1) as f64;
    let mag = 10f64.powf(raw.log10().floor());
    let step = [1.0, 2.0, 5.0, 10.0]
        .iter()
        .map(|m| m * mag)
        .find(|s| *s >= raw)
        .unwrap_or(10.0 * mag);
    let start = (lo / step).floor() as i64;
    let end = (hi / step).ceil() as i64;
    (start..=end).map(|k| k as f64 * step).collect()
}

/// A tick label: few significant digits, scientific only for very small or large values.
pub fn format_tick(v: f64) -> String {
    if v == 0.0 {
        return "0".into();
    }
    let a = v.abs();
    if !(1e-3..1e5).contains(&a) {
        return format!("{v:.1e}");
    }
    let decimals = (2.0 - a.log10().floor()).clamp(0.0, 6.0) as usize;
    let s = format!("{v:.decimals$}");
    if s.contains('.') {
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        s
    }
}

/// At least three "nice" ticks inside [lo, hi] (a colour bar's or an axis's own range, which
/// the ticks may not widen), labelled with as many decimals as their step needs so that no two
/// read the same. `nice_ticks` alone can leave one: a range of ±4.5 gets steps of 5, and only
/// the 0 falls inside.
pub fn ticks_inside(lo: f64, hi: f64) -> Vec<(f64, String)> {
    if !(lo.is_finite() && hi.is_finite() && hi > lo) {
        return vec![(lo, format_tick(lo))];
    }
    let eps = 1e-9 * (hi - lo);
    let mut ticks = Vec::new();
    for n in 4..=12 {
        ticks = nice_ticks(lo, hi, n)
            .into_iter()
            .filter(|t| *t >= lo - eps && *t <= hi + eps)
            .collect();
        if ticks.len() >= 3 {
            break;
        }
    }
    let step = match ticks.as_slice() {
        [a, b, ..] => b - a,
        _ => hi - lo,
    };
    ticks
        .into_iter()
        .map(|t| {
            let t = if t.abs() < 1e-9 * step { 0.0 } else { t };
            (t, format_tick_with_step(t, step))
        })
        .collect()
}

/// `format_tick`, with at least the decimals that `step` needs (32.499, 32.5, 32.501 rather
/// than three times 32.5).
fn format_tick_with_step(v: f64, step: f64) -> String {
    let plain = format_tick(v);
    let a = v.abs();
    if v == 0.0 || !(1e-3..1e5).contains(&a) || !(step > 0.0) {
        return plain;
    }
    let needed = (-step.log10().floor()).max(0.0) as usize;
    let shown = plain.split('.').nth(1).map_or(0, str::len);
    if shown >= needed {
        plain
    } else {
        format!("{v:.needed$}")
    }
}

/// Colour-blind-safe series colours (Okabe & Ito).
pub const PALETTE: [&str; 6] = [
    "#0072B2", "#E69F00", "#009E73", "#CC79A7", "#56B4E9", "#D55E00",
];

/// Estimated width of a text in px (no font metrics are available or needed).
pub fn text_width(s: &str, font_px: f64) -> f64 {
    0.6 * font_px * s.chars().count() as f64
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ticks_cover_the_range_in_nice_steps() {
        let t = nice_ticks(0.0, 0.0137, 5);
        assert_eq!(t.first(), Some(&0.0));
        assert!(*t.last().unwrap() >= 0.0137);
        let step = t[1] - t[0];
        assert!(
            (step - 0.005).abs() < 1e-12
                || (step - 0.002).abs() < 1e-12
                || (step - 0.003).abs() > 1.0
        );
        assert_eq!(format_tick(0.0025), "0.0025");
        assert_eq!(format_tick(150.0), "150");
        assert_eq!(escape("a<b & \"c\""), "a&lt;b &amp; &quot;c&quot;");
    }

    #[test]
    fn at_least_three_distinct_ticks_inside_any_range() {
        for (lo, hi) in [
            (-4.5, 4.5),
            (-4.2e-6, 4.2e-6),
            (-0.0049, 0.0049),
            (32.4985, 32.5012),
            (0.0, 1.0),
            (-1.0, 7.3),
            (1e-7, 3e-7),
        ] {
            let t = ticks_inside(lo, hi);
            assert!(t.len() >= 3, "[{lo}, {hi}]: {t:?}");
            assert!(
                t.iter().all(|(v, _)| *v >= lo - 1e-12 && *v <= hi + 1e-12),
                "{t:?}"
            );
            let labels: std::collections::BTreeSet<&String> = t.iter().map(|(_, l)| l).collect();
            assert_eq!(labels.len(), t.len(), "[{lo}, {hi}]: labels repeat: {t:?}");
        }
        assert_eq!(ticks_inside(-4.5, 4.5)[1].1, "-2");
    }
}
