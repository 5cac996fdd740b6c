//! Scatter and line plots of (x, y) series: residual against position, residual against sub-pixel
//! fraction, power spectra, noise against mean, the history of a discrepancy. Linear or
//! logarithmic axes, a legend, axis labels with units.

use super::svg::{escape, format_tick, nice_ticks, start_document, PALETTE};
use std::fmt::Write;

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Mark {
    Points,
    Line,
    LinePoints,
}

#[derive(Clone, Debug, PartialEq)]
pub struct XySeries {
    pub name: String,
    /// Non-finite points (and non-positive ones on a log axis) are skipped.
    pub points: Vec<(f64, f64)>,
    pub mark: Mark,
    /// Half-widths of each point's error bar on the y axis, in y's units (empty: no bars;
    /// otherwise one per point, drawn as `<line class="error-bar">`, a non-finite one skipped).
    pub y_err: Vec<f64>,
}

#[derive(Clone, Debug, PartialEq)]
pub struct XyPlot {
    pub title: String,
    /// Axis labels with units, e.g. "sub-pixel fraction of u [px]".
    pub x_label: String,
    pub y_label: String,
    pub series: Vec<XySeries>,
    pub log_x: bool,
    pub log_y: bool,
    /// Draw a horizontal line at y = 0 (residual plots).
    pub zero_line: bool,
    /// Optional text under each x tick instead of numbers (categorical x: index -> label).
    pub x_tick_labels: Vec<(f64, String)>,
}

impl XyPlot {
    pub fn new(title: &str, x_label: &str, y_label: &str) -> Self {
        Self {
            title: title.into(),
            x_label: x_label.into(),
            y_label: y_label.into(),
            series: Vec::new(),
            log_x: false,
            log_y: false,
            zero_line: false,
            x_tick_labels: Vec::new(),
        }
    }

    fn usable(&self, (x, y): (f64, f64)) -> bool {
        x.is_finite() && y.is_finite() && (!self.log_x || x > 0.0) && (!self.log_y || y > 0.0)
    }

    /// The plot as a standalone SVG document. Every point is a `<circle class="point">`, every
    /// line a `<polyline class="line">`.
    pub fn to_svg(&self, width_px: u32, height_px: u32) -> String {
        let (w, h) = (width_px as f64, height_px as f64);
        let legend_h = 16.0 * self.series.len() as f64 + 6.0;
        let axes = self.axes(w, h, legend_h);
        let mut s = start_document(w, h, &self.title);
        self.write_grid(&mut s, &axes);
        self.write_series(&mut s, &axes, h - legend_h);
        s.push_str("</svg>\n");
        s
    }

    /// The data range (on the axes' scales, log10 where logarithmic) widened to whole ticks.
    fn axes(&self, w: f64, h: f64, legend_h: f64) -> Axes {
        let (left, right, top, bottom) = (78.0, 20.0, 40.0, 48.0 + legend_h);
        let (log_x, log_y) = (self.log_x, self.log_y);
        let pts: Vec<(f64, f64)> = self
            .series
            .iter()
            .flat_map(|s| {
                // The error bars' ends are inside the axes too.
                let bars = s
                    .points
                    .iter()
                    .zip(&s.y_err)
                    .filter(|(_, e)| e.is_finite())
                    .flat_map(|(&(x, y), &e)| [(x, y - e), (x, y + e)]);
                s.points.iter().copied().chain(bars)
            })
            .filter(|p| self.usable(*p))
            .map(|(x, y)| (scale(x, log_x), scale(y, log_y)))
            .collect();
        let bounds = |it: &mut dyn Iterator<Item = f64>| {
            it.fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
                (a.min(v), b.max(v))
            })
        };
        let (mut x0, mut x1) = bounds(&mut pts.iter().map(|p| p.0));
        let zero = (self.zero_line && !log_y).then_some(0.0);
        let (mut y0, mut y1) = bounds(&mut pts.iter().map(|p| p.1).chain(zero));
        if !x0.is_finite() {
            (x0, x1) = (0.0, 1.0);
        }
        if !y0.is_finite() {
            (y0, y1) = (0.0, 1.0);
        }
        let ticks = |lo: f64, hi: f64, log: bool, n: usize| -> Vec<f64> {
            if log {
                (lo.floor() as i64..=hi.ceil() as i64)
                    .map(|k| k as f64)
                    .collect()
            } else {
                nice_ticks(lo, hi, n)
            }
        };
        let (xt, yt) = (ticks(x0, x1, log_x, 6), ticks(y0, y1, log_y, 5));
        let (x0, x1) = (xt[0].min(x0), xt[xt.len() - 1].max(x1));
        let (y0, y1) = (yt[0].min(y0), yt[yt.len() - 1].max(y1));
        Axes {
            left,
            top,
            pw: w - left - right,
            ph: h - top - bottom,
            x: (x0, if x1 > x0 { x1 } else { x0 + 1.0 }),
            y: (y0, if y1 > y0 { y1 } else { y0 + 1.0 }),
            xt,
            yt,
        }
    }

    /// Grid lines with their tick labels, the zero line, the frame and the axis labels.
    fn write_grid(&self, s: &mut String, a: &Axes) {
        let (left, top, pw, ph) = (a.left, a.top, a.pw, a.ph);
        for &t in &a.yt {
            let y = a.sy(t);
            let _ = write!(
                s,
                r##"<line x1="{left}" x2="{:.1}" y1="{y:.1}" y2="{y:.1}" stroke="#e4e4e4"/><text x="{:.1}" y="{:.1}" text-anchor="end">{}</text>"##,
                left + pw,
                left - 6.0,
                y + 4.0,
                tick_label(t, self.log_y)
            );
        }
        if self.x_tick_labels.is_empty() {
            for &t in &a.xt {
                let x = a.sx(t);
                let _ = write!(
                    s,
                    r##"<line x1="{x:.1}" x2="{x:.1}" y1="{top}" y2="{:.1}" stroke="#e4e4e4"/><text x="{x:.1}" y="{:.1}" text-anchor="middle">{}</text>"##,
                    top + ph,
                    top + ph + 16.0,
                    tick_label(t, self.log_x)
                );
            }
        } else {
            for (t, text) in &self.x_tick_labels {
                let _ = write!(
                    s,
                    r#"<text x="{:.1}" y="{:.1}" text-anchor="middle" font-size="10">{}</text>"#,
                    a.sx(scale(*t, self.log_x)),
                    top + ph + 16.0,
                    escape(text)
                );
            }
        }
        if self.zero_line && !self.log_y && a.y.0 < 0.0 && a.y.1 > 0.0 {
            let _ = write!(
                s,
                r##"<line x1="{left}" x2="{:.1}" y1="{1:.1}" y2="{1:.1}" stroke="#888" stroke-dasharray="4 3"/>"##,
                left + pw,
                a.sy(0.0)
            );
        }
        let _ = write!(
            s,
            r##"<rect x="{left}" y="{top}" width="{pw}" height="{ph}" fill="none" stroke="#333"/>"##
        );
        let _ = write!(
            s,
            r#"<text x="{:.1}" y="{:.1}" text-anchor="middle">{}</text><text transform="translate(16,{:.1}) rotate(-90)" text-anchor="middle">{}</text>"#,
            left + pw / 2.0,
            top + ph + 34.0,
            escape(&self.x_label),
            top + ph / 2.0,
            escape(&self.y_label)
        );
    }

    /// A vertical bar from y − e to y + e at each point of `series` that has a finite e.
    fn write_error_bars(&self, s: &mut String, a: &Axes, series: &XySeries, colour: &str) {
        for (&(x, y), &e) in series.points.iter().zip(&series.y_err) {
            let (lo, hi) = ((x, y - e), (x, y + e));
            if !(e.is_finite() && self.usable(lo) && self.usable(hi)) {
                continue;
            }
            let sx = a.sx(scale(x, self.log_x));
            let _ = write!(
                s,
                r#"<line class="error-bar" x1="{sx:.1}" x2="{sx:.1}" y1="{:.1}" y2="{:.1}" stroke="{colour}" stroke-width="1"/>"#,
                a.sy(scale(lo.1, self.log_y)),
                a.sy(scale(hi.1, self.log_y))
            );
        }
    }

    /// Each series' line and points, and its legend entry from `legend_top` down.
    fn write_series(&self, s: &mut String, a: &Axes, legend_top: f64) {
        let left = a.left;
        for (k, series) in self.series.iter().enumerate() {
            let colour = PALETTE[k % PALETTE.len()];
            let p: Vec<(f64, f64)> = series
                .points
                .iter()
                .copied()
                .filter(|p| self.usable(*p))
                .map(|(x, y)| (a.sx(scale(x, self.log_x)), a.sy(scale(y, self.log_y))))
                .collect();
            self.write_error_bars(s, a, series, colour);
            if matches!(series.mark, Mark::Line | Mark::LinePoints) && p.len() > 1 {
                let path: Vec<String> = p.iter().map(|(x, y)| format!("{x:.1},{y:.1}")).collect();
                let _ = write!(
                    s,
                    r#"<polyline class="line" points="{}" fill="none" stroke="{colour}" stroke-width="1.6"/>"#,
                    path.join(" ")
                );
            }
            if matches!(series.mark, Mark::Points | Mark::LinePoints) {
                for (x, y) in &p {
                    let _ = write!(
                        s,
                        r#"<circle class="point" cx="{x:.1}" cy="{y:.1}" r="2.6" fill="{colour}"/>"#
                    );
                }
            }
            let ly = legend_top + 2.0 + 16.0 * k as f64;
            let _ = write!(
                s,
                r#"<rect x="{left}" y="{ly:.1}" width="12" height="10" fill="{colour}"/><text x="{:.1}" y="{:.1}">{}</text>"#,
                left + 18.0,
                ly + 9.0,
                escape(&series.name)
            );
        }
    }
}

/// A value on its axis' scale: log10 on a logarithmic axis.
fn scale(v: f64, log: bool) -> f64 {
    if log {
        v.log10()
    } else {
        v
    }
}

/// A tick's text: the value itself, not its logarithm, on a logarithmic axis.
fn tick_label(v: f64, log: bool) -> String {
    if log {
        format_tick(10f64.powf(v))
    } else {
        format_tick(v)
    }
}

/// The plot area (from `left`, `top`, `pw` x `ph` px) and the ranges and ticks it spans, on the
/// axes' scales.
struct Axes {
    left: f64,
    top: f64,
    pw: f64,
    ph: f64,
    x: (f64, f64),
    y: (f64, f64),
    xt: Vec<f64>,
    yt: Vec<f64>,
}

impl Axes {
    fn sx(&self, x: f64) -> f64 {
        self.left + self.pw * (x - self.x.0) / (self.x.1 - self.x.0)
    }

    fn sy(&self, y: f64) -> f64 {
        self.top + self.ph * (1.0 - (y - self.y.0) / (self.y.1 - self.y.0))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn points_lines_and_log_axes() {
        let mut p = XyPlot::new("PSD", "f [cycles/px]", "P [1/px]");
        p.log_y = true;
        p.series.push(XySeries {
            name: "measured".into(),
            points: vec![(0.1, 1.0), (0.2, 0.1), (0.3, -1.0)],
            mark: Mark::LinePoints,
            y_err: Vec::new(),
        });
        let svg = p.to_svg(600, 400);
        assert_eq!(svg.matches(r#"class="point""#).count(), 2);
        assert_eq!(svg.matches(r#"class="line""#).count(), 1);
        assert!(svg.contains("f [cycles/px]"));
    }

    #[test]
    fn error_bars_are_drawn_and_inside_the_axes() {
        let mut p = XyPlot::new("S-curve", "commanded [px]", "bias [px]");
        p.series.push(XySeries {
            name: "bias".into(),
            points: vec![(0.1, 0.001), (0.2, 0.002), (0.3, 0.0)],
            mark: Mark::Points,
            y_err: vec![0.01, f64::NAN, 0.004],
        });
        let svg = p.to_svg(600, 400);
        assert_eq!(svg.matches(r#"class="error-bar""#).count(), 2, "{svg}");
        // The first bar reaches 0.011, beyond every point: the y axis is widened to hold it.
        let axes = p.axes(600.0, 400.0, 22.0);
        assert!(axes.y.1 >= 0.011 && axes.y.0 <= -0.009, "{:?}", axes.y);
    }
}
