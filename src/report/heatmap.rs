//! A heatmap of a scalar field on a regular grid (residual maps, mean-intensity maps): one cell per
//! grid point, a diverging colour scale symmetric about zero (or a sequential one), a colour-scale
//! legend with its unit, and axis labels with units.

use super::svg::{escape, start_document, ticks_inside};
use std::fmt::Write;

#[derive(Clone, Debug, PartialEq)]
pub struct Heatmap {
    pub title: String,
    /// Axis labels with units, e.g. "x [px]".
    pub x_label: String,
    pub y_label: String,
    /// Label of the colour scale with its unit, e.g. "Δu [px]".
    pub value_label: String,
    /// Cell centres along x and y (data units); `values` is row-major, `ys.len()` rows.
    pub xs: Vec<f64>,
    pub ys: Vec<f64>,
    /// NaN draws a grey cell.
    pub values: Vec<f64>,
    /// Symmetric about zero (blue–white–red) when true; white-to-dark otherwise.
    pub diverging: bool,
    /// Text at given positions instead of numeric ticks (categorical axes); empty = numbers.
    pub x_tick_labels: Vec<(f64, String)>,
    pub y_tick_labels: Vec<(f64, String)>,
    /// Labelled points drawn over the cells (e.g. a paper's measurements), data units.
    pub markers: Vec<HeatmapMarker>,
}

/// A labelled point over a heat map.
#[derive(Clone, Debug, PartialEq)]
pub struct HeatmapMarker {
    pub x: f64,
    pub y: f64,
    pub label: String,
}

/// Blue–white–red for t in [-1, 1].
fn diverging_colour(t: f64) -> String {
    let t = t.clamp(-1.0, 1.0);
    let (r, g, b) = if t < 0.0 {
        let a = -t;
        (
            255.0 * (1.0 - a) + 33.0 * a,
            255.0 * (1.0 - a) + 102.0 * a,
            255.0 * (1.0 - a) + 172.0 * a,
        )
    } else {
        (
            255.0 * (1.0 - t) + 178.0 * t,
            255.0 * (1.0 - t) + 24.0 * t,
            255.0 * (1.0 - t) + 43.0 * t,
        )
    };
    format!("#{:02x}{:02x}{:02x}", r as u8, g as u8, b as u8)
}

/// White to dark blue for t in [0, 1].
fn sequential_colour(t: f64) -> String {
    let t = t.clamp(0.0, 1.0);
    let (r, g, b) = (
        255.0 * (1.0 - t) + 8.0 * t,
        255.0 * (1.0 - t) + 48.0 * t,
        255.0 * (1.0 - t) + 107.0 * t,
    );
    format!("#{:02x}{:02x}{:02x}", r as u8, g as u8, b as u8)
}

impl Heatmap {
    /// The value range the colours span: ±max|v| when diverging, [min, max] otherwise.
    pub fn range(&self) -> (f64, f64) {
        let finite = self.values.iter().copied().filter(|v| v.is_finite());
        if self.diverging {
            let m = finite.fold(0.0f64, |a, v| a.max(v.abs()));
            let m = if m > 0.0 { m } else { 1.0 };
            (-m, m)
        } else {
            let (lo, hi) = finite.fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
                (a.min(v), b.max(v))
            });
            if lo.is_finite() && hi > lo {
                (lo, hi)
            } else if lo.is_finite() {
                (lo - 1.0, lo + 1.0)
            } else {
                (0.0, 1.0)
            }
        }
    }

    fn colour(&self, v: f64, (lo, hi): (f64, f64)) -> String {
        if !v.is_finite() {
            return "#bbbbbb".into();
        }
        if self.diverging {
            diverging_colour(v / hi)
        } else {
            sequential_colour((v - lo) / (hi - lo))
        }
    }

    /// The map as a standalone SVG document. Every cell is a `<rect class="cell">` carrying its
    /// value in `data-value`.
    pub fn to_svg(&self, width_px: u32, height_px: u32) -> String {
        let (w, h) = (width_px as f64, height_px as f64);
        let (left, right, top, bottom) = (70.0, 110.0, 40.0, 48.0);
        let (pw, ph) = (w - left - right, h - top - bottom);
        let (nx, ny) = (self.xs.len().max(1), self.ys.len().max(1));
        let range = self.range();
        let span = |v: &[f64]| -> (f64, f64) {
            let step = if v.len() > 1 {
                (v[v.len() - 1] - v[0]) / (v.len() - 1) as f64
            } else {
                1.0
            };
            let (a, b) = (
                v.first().copied().unwrap_or(0.0),
                v.last().copied().unwrap_or(1.0),
            );
            (a - step / 2.0, b + step / 2.0)
        };
        let (x0, x1) = span(&self.xs);
        let (y0, y1) = span(&self.ys);
        let sx = |x: f64| left + pw * (x - x0) / (x1 - x0);
        let sy = |y: f64| top + ph * (y - y0) / (y1 - y0);
        let (cw, ch) = (pw / nx as f64, ph / ny as f64);
        let mut s = start_document(w, h, &self.title);
        for (j, &y) in self.ys.iter().enumerate() {
            for (i, &x) in self.xs.iter().enumerate() {
                let v = self.values.get(j * nx + i).copied().unwrap_or(f64::NAN);
                let _ = write!(
                    s,
                    r#"<rect class="cell" data-value="{v}" x="{:.2}" y="{:.2}" width="{:.2}" height="{:.2}" fill="{}"/>"#,
                    sx(x) - cw / 2.0,
                    sy(y) - ch / 2.0,
                    cw + 0.3,
                    ch + 0.3,
                    self.colour(v, range)
                );
            }
        }
        // Axes: image convention, y grows downwards.
        let _ = write!(
            s,
            r##"<rect x="{left}" y="{top}" width="{pw}" height="{ph}" fill="none" stroke="#333"/>"##
        );
        for (t, text) in ticks(&self.x_tick_labels, x0, x1) {
            let _ = write!(
                s,
                r##"<line x1="{0:.1}" x2="{0:.1}" y1="{1:.1}" y2="{2:.1}" stroke="#333"/><text x="{0:.1}" y="{3:.1}" text-anchor="middle">{4}</text>"##,
                sx(t),
                top + ph,
                top + ph + 4.0,
                top + ph + 17.0,
                escape(&text)
            );
        }
        for (t, text) in ticks(&self.y_tick_labels, y0, y1) {
            let _ = write!(
                s,
                r##"<line x1="{0:.1}" x2="{1:.1}" y1="{2:.1}" y2="{2:.1}" stroke="#333"/><text x="{3:.1}" y="{4:.1}" text-anchor="end">{5}</text>"##,
                left - 4.0,
                left,
                sy(t),
                left - 6.0,
                sy(t) + 4.0,
                escape(&text)
            );
        }
        for m in &self.markers {
            write_marker(&mut s, m, sx(m.x), sy(m.y));
        }
        let _ = write!(
            s,
            r#"<text x="{:.1}" y="{:.1}" text-anchor="middle">{}</text><text transform="translate(16,{:.1}) rotate(-90)" text-anchor="middle">{}</text>"#,
            left + pw / 2.0,
            h - 10.0,
            escape(&self.x_label),
            top + ph / 2.0,
            escape(&self.y_label)
        );
        // Colour-scale legend right of the map.
        self.write_colour_scale(&mut s, range, left + pw + 24.0, (top, ph), w);
        s.push_str("</svg>\n");
        s
    }

    /// The colour scale at `lx`: a vertical bar of 40 steps over the plot's height (`top`, `ph`)
    /// with ticks, and the value's label at the right edge of a `w` px wide document.
    fn write_colour_scale(
        &self,
        s: &mut String,
        range: (f64, f64),
        lx: f64,
        (top, ph): (f64, f64),
        w: f64,
    ) {
        let lw = 16.0;
        let steps = 40;
        for k in 0..steps {
            let t = 1.0 - (k as f64 + 0.5) / steps as f64;
            let v = range.0 + t * (range.1 - range.0);
            let _ = write!(
                s,
                r#"<rect x="{lx:.1}" y="{:.2}" width="{lw}" height="{:.2}" fill="{}"/>"#,
                top + ph * k as f64 / steps as f64,
                ph / steps as f64 + 0.3,
                self.colour(v, range)
            );
        }
        let _ = write!(
            s,
            r##"<rect class="legend" x="{lx:.1}" y="{top}" width="{lw}" height="{ph}" fill="none" stroke="#333"/>"##
        );
        for (t, label) in ticks_inside(range.0, range.1) {
            let y = top + ph * (1.0 - (t - range.0) / (range.1 - range.0));
            let _ = write!(
                s,
                r##"<line x1="{:.1}" x2="{:.1}" y1="{y:.1}" y2="{y:.1}" stroke="#333"/><text x="{:.1}" y="{:.1}">{}</text>"##,
                lx + lw,
                lx + lw + 4.0,
                lx + lw + 6.0,
                y + 4.0,
                label
            );
        }
        let _ = write!(
            s,
            r#"<text transform="translate({:.1},{:.1}) rotate(-90)" text-anchor="middle">{}</text>"#,
            w - 10.0,
            top + ph / 2.0,
            escape(&self.value_label)
        );
    }
}

/// A marker (a ring and its label) at (`x`, `y`) px.
fn write_marker(s: &mut String, m: &HeatmapMarker, x: f64, y: f64) {
    let _ = write!(
        s,
        r##"<g class="marker"><circle cx="{x:.1}" cy="{y:.1}" r="5" fill="none" stroke="#D55E00" stroke-width="2"/><text x="{:.1}" y="{:.1}" fill="#D55E00" font-weight="bold">{}</text></g>"##,
        x + 7.0,
        y - 6.0,
        escape(&m.label)
    );
}

/// The given labels inside [lo, hi], or numeric ticks when there are none.
fn ticks(labels: &[(f64, String)], lo: f64, hi: f64) -> Vec<(f64, String)> {
    if labels.is_empty() {
        ticks_inside(lo, hi)
    } else {
        labels
            .iter()
            .filter(|(t, _)| *t >= lo && *t <= hi)
            .cloned()
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn one_cell_per_value_and_a_legend() {
        let m = Heatmap {
            title: "Δu".into(),
            x_label: "x [px]".into(),
            y_label: "y [px]".into(),
            value_label: "Δu [px]".into(),
            xs: vec![10.0, 20.0, 30.0],
            ys: vec![5.0, 15.0],
            values: vec![-0.1, 0.0, 0.1, f64::NAN, 0.05, -0.02],
            diverging: true,
            x_tick_labels: Vec::new(),
            y_tick_labels: vec![(5.0, "first".into()), (15.0, "second".into())],
            markers: vec![HeatmapMarker {
                x: 20.0,
                y: 5.0,
                label: "paper".into(),
            }],
        };
        let svg = m.to_svg(500, 360);
        assert!(svg.contains(">first<") && svg.contains(">second<") && svg.contains(">20<"));
        assert_eq!(svg.matches(r#"class="marker""#).count(), 1);
        assert_eq!(svg.matches(r#"class="cell""#).count(), 6);
        assert!(svg.contains(r#"class="legend""#));
        assert!(svg.contains("x [px]") && svg.contains("Δu [px]"));
        assert_eq!(m.range(), (-0.1, 0.1));
    }
}
