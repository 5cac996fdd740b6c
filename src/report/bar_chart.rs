//! Grouped bar charts, as in the paper's Figures 5 and 6: groups are speckle patterns, series are
//! fill factors, and a label over each bar gives its change against the first series.

use super::svg::{escape, format_tick, nice_ticks, start_document, text_width, PALETTE};
use std::fmt::Write;

#[derive(Clone, Debug, PartialEq)]
pub struct Series {
    pub name: String,
    /// One value per group; NaN draws no bar.
    pub values: Vec<f64>,
    /// Text over each bar (e.g. "+13.2 %"), one per group.
    pub labels: Vec<Option<String>>,
    /// A 95 % interval drawn as an error bar on each bar, one per group (empty: none).
    pub errors: Vec<Option<[f64; 2]>>,
}

impl Series {
    /// The finite ends of the error bar of group `gi`.
    fn error(&self, gi: usize) -> Option<[f64; 2]> {
        self.errors
            .get(gi)
            .copied()
            .flatten()
            .filter(|[lo, hi]| lo.is_finite() && hi.is_finite())
    }
}

#[derive(Clone, Debug, PartialEq)]
pub struct BarChart {
    pub title: String,
    /// Axis label with units, e.g. "std(u) [px]".
    pub y_label: String,
    pub groups: Vec<String>,
    pub series: Vec<Series>,
}

impl BarChart {
    /// The chart as a standalone SVG document. Every bar is a `<rect class="bar">` with
    /// `data-group` and `data-series` attributes, so tests and pages can find them.
    pub fn to_svg(&self, width_px: u32, height_px: u32) -> String {
        self.to_svg_up_to(width_px, height_px, self.value_range().1)
    }

    /// The chart with its value axis reaching at least `max` (small multiples share one).
    fn to_svg_up_to(&self, width_px: u32, height_px: u32, max: f64) -> String {
        let (w, h) = (width_px as f64, height_px as f64);
        let legend_h = 18.0 * self.series.len() as f64 + 8.0;
        let (left, right, top, bottom) = (78.0, 16.0, 40.0, 40.0 + legend_h);
        let (min, own_max) = self.value_range();
        let max = max.max(own_max);
        // Headroom for the labels over the bars.
        let ticks = nice_ticks(min, if max > 0.0 { max * 1.12 } else { 1.0 }, 5);
        let plot = Plot {
            top,
            pw: w - left - right,
            ph: h - top - bottom,
            y0: ticks[0],
            y1: *ticks.last().expect("ticks"),
        };
        let (pw, ph) = (plot.pw, plot.ph);

        let mut s = start_document(w, h, &self.title);
        for t in &ticks {
            let y = plot.y_of(*t);
            let _ = write!(
                s,
                r##"<line x1="{left}" x2="{}" y1="{y:.1}" y2="{y:.1}" stroke="#ddd"/><text x="{}" y="{:.1}" text-anchor="end">{}</text>"##,
                left + pw,
                left - 6.0,
                y + 4.0,
                format_tick(*t)
            );
        }
        let _ = write!(
            s,
            r#"<text transform="translate(16,{:.1}) rotate(-90)" text-anchor="middle">{}</text>"#,
            top + ph / 2.0,
            escape(&self.y_label)
        );
        let group_w = pw / self.groups.len().max(1) as f64;
        let bar_w = group_w * 0.8 / self.series.len().max(1) as f64;
        for (gi, g) in self.groups.iter().enumerate() {
            let gx = left + gi as f64 * group_w;
            let _ = write!(
                s,
                r#"<text x="{:.1}" y="{:.1}" text-anchor="middle">{}</text>"#,
                gx + group_w / 2.0,
                top + ph + 18.0,
                escape(g)
            );
            for si in 0..self.series.len() {
                let x = gx + group_w * 0.1 + si as f64 * bar_w;
                self.write_bar(&mut s, &plot, gi, si, x, bar_w);
            }
        }
        let zero = plot.y_of(0.0f64.clamp(plot.y0, plot.y1));
        let _ = write!(
            s,
            r##"<line x1="{left}" x2="{left}" y1="{top}" y2="{:.1}" stroke="#333"/><line x1="{left}" x2="{:.1}" y1="{zero:.1}" y2="{zero:.1}" stroke="#333"/>"##,
            top + ph,
            left + pw,
        );
        for (si, series) in self.series.iter().enumerate() {
            let y = h - legend_h + 4.0 + 18.0 * si as f64;
            let _ = write!(
                s,
                r#"<rect x="{left}" y="{y:.1}" width="12" height="12" fill="{}"/><text x="{}" y="{:.1}">{}</text>"#,
                PALETTE[si % PALETTE.len()],
                left + 18.0,
                y + 10.0,
                escape(&series.name)
            );
        }
        s.push_str("</svg>\n");
        s
    }

    /// The lowest value (at most 0) and the highest value or error-bar top (at least 0).
    fn value_range(&self) -> (f64, f64) {
        let max = self
            .series
            .iter()
            .flat_map(|s| {
                let tops = (0..s.values.len()).filter_map(|gi| s.error(gi).map(|e| e[1]));
                s.values.iter().copied().chain(tops)
            })
            .filter(|v| v.is_finite())
            .fold(0.0f64, f64::max);
        let min = self
            .series
            .iter()
            .flat_map(|s| s.values.iter().copied())
            .filter(|v| v.is_finite())
            .fold(0.0f64, f64::min);
        (min, max)
    }

    /// The bar of series `si` in group `gi` at `x`, `bar_w` wide, with its error bar and label.
    fn write_bar(&self, s: &mut String, plot: &Plot, gi: usize, si: usize, x: f64, bar_w: f64) {
        let series = &self.series[si];
        let v = series.values.get(gi).copied().unwrap_or(f64::NAN);
        if !v.is_finite() {
            return;
        }
        let (ya, yb) = (plot.y_of(v.max(0.0)), plot.y_of(v.min(0.0)));
        let _ = write!(
            s,
            r#"<rect class="bar" data-group="{}" data-series="{}" data-value="{v}" x="{x:.2}" y="{ya:.2}" width="{:.2}" height="{:.2}" fill="{}"><title>{}: {}</title></rect>"#,
            escape(&self.groups[gi]),
            escape(&series.name),
            bar_w * 0.92,
            yb - ya,
            PALETTE[si % PALETTE.len()],
            escape(&series.name),
            format_tick(v)
        );
        let mut label_y = ya - 4.0;
        if let Some([lo, hi]) = series.error(gi) {
            let (yl, yh) = (plot.y_of(lo), plot.y_of(hi));
            let xc = x + bar_w * 0.46;
            let cap = (bar_w * 0.2).min(6.0);
            let _ = write!(
                s,
                r##"<path class="error-bar" data-lo="{lo}" data-hi="{hi}" d="M{xc:.2},{yl:.2}V{yh:.2}M{:.2},{yl:.2}H{:.2}M{:.2},{yh:.2}H{:.2}" stroke="#222" fill="none"/>"##,
                xc - cap,
                xc + cap,
                xc - cap,
                xc + cap
            );
            label_y = label_y.min(yh - 4.0);
        }
        if let Some(Some(label)) = series.labels.get(gi) {
            let fs = if text_width(label, 11.0) > bar_w {
                9
            } else {
                11
            };
            let _ = write!(
                s,
                r#"<text class="bar-label" x="{:.1}" y="{:.1}" text-anchor="middle" font-size="{fs}">{}</text>"#,
                x + bar_w * 0.46,
                label_y,
                escape(label)
            );
        }
    }
}

/// Bar charts as small multiples (Tufte, The Visual Display of Quantitative Information, 1983):
/// panels of `panel_w` x `panel_h` px, `columns` a row, on one value axis so that their bars
/// compare across panels, under one `title`. Each panel is a `<g class="panel">`.
pub fn small_multiples(
    title: &str,
    panels: &[BarChart],
    columns: usize,
    panel_w: u32,
    panel_h: u32,
) -> String {
    let columns = columns.max(1);
    let rows = panels.len().div_ceil(columns);
    let top = 34.0;
    let (w, h) = (
        (columns as u32 * panel_w) as f64,
        top + (rows as u32 * panel_h) as f64,
    );
    let max = panels
        .iter()
        .map(|p| p.value_range().1)
        .fold(0.0f64, f64::max);
    let mut s = start_document(w, h, title);
    for (k, panel) in panels.iter().enumerate() {
        let (x, y) = (
            (k % columns) as f64 * panel_w as f64,
            top + (k / columns) as f64 * panel_h as f64,
        );
        let _ = write!(
            s,
            r#"<g class="panel" data-panel="{}" transform="translate({x},{y})">{}</g>"#,
            escape(&panel.title),
            panel.to_svg_up_to(panel_w, panel_h, max)
        );
    }
    s.push_str("</svg>\n");
    s
}

/// The plot area (from `top`, `pw` x `ph` px) and the value range it spans.
struct Plot {
    top: f64,
    pw: f64,
    ph: f64,
    y0: f64,
    y1: f64,
}

impl Plot {
    fn y_of(&self, v: f64) -> f64 {
        self.top + self.ph * (1.0 - (v - self.y0) / (self.y1 - self.y0))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn chart() -> BarChart {
        BarChart {
            title: "Figure <5>".into(),
            y_label: "std(u) [px]".into(),
            groups: vec!["a".into(), "b".into(), "c".into()],
            series: (0..3)
                .map(|k| Series {
                    name: format!("s{k}"),
                    values: vec![
                        0.01 * (k + 1) as f64,
                        0.02,
                        if k == 2 { f64::NAN } else { 0.005 },
                    ],
                    labels: vec![None, Some("+13.2 %".into()), None],
                    errors: vec![None, Some([0.015, 0.03]), Some([f64::NAN, 0.01])],
                })
                .collect(),
        }
    }

    /// The height of every bar, in document order.
    fn bar_heights(svg: &str) -> Vec<f64> {
        svg.split(r#"class="bar""#)
            .skip(1)
            .map(|part| {
                let h = part.split("height=\"").nth(1).unwrap();
                h[..h.find('"').unwrap()].parse().unwrap()
            })
            .collect()
    }

    #[test]
    fn one_rect_per_finite_value_with_heights_proportional() {
        let svg = chart().to_svg(720, 420);
        assert_eq!(svg.matches(r#"class="bar""#).count(), 8);
        assert!(svg.contains("Figure &lt;5&gt;"));
        assert_eq!(svg.matches("+13.2 %").count(), 3);
        let heights = bar_heights(&svg);
        // Group a: s0 = 0.01, s1 = 0.02 → the second bar is twice the first.
        // Order: group a (s0, s1, s2), group b (s0, s1, s2), group c (s0, s1).
        assert!((heights[1] / heights[0] - 2.0).abs() < 1e-3, "{heights:?}");
        assert!((heights[2] / heights[0] - 3.0).abs() < 1e-3);
        assert_eq!(svg.matches("<svg").count(), svg.matches("</svg>").count());
    }

    #[test]
    fn small_multiples_share_one_value_axis() {
        let tall = chart();
        let mut low = chart();
        for series in &mut low.series {
            series.values.iter_mut().for_each(|v| *v /= 10.0);
            series.errors.clear();
        }
        let svg = small_multiples("both", &[tall, low], 2, 400, 300);
        assert_eq!(svg.matches(r#"<g class="panel""#).count(), 2);
        assert_eq!(svg.matches("<svg").count(), svg.matches("</svg>").count());
        // A bar of the low panel is a tenth of the same bar in the tall one: one axis.
        let heights = bar_heights(&svg);
        assert_eq!(heights.len(), 16);
        assert!((heights[0] / heights[8] - 10.0).abs() < 0.05, "{heights:?}");
    }

    #[test]
    fn error_bars_span_their_interval_and_stay_in_the_plot() {
        let svg = chart().to_svg(720, 420);
        // Group b of every series has [0.015, 0.03]; group c's interval has a NaN end: none.
        assert_eq!(svg.matches(r#"class="error-bar""#).count(), 3);
        let y_of = |part: &str, key: &str| -> f64 {
            let v = part.split(key).nth(1).unwrap();
            v[..v.find(|c: char| c != '.' && !c.is_ascii_digit()).unwrap()]
                .parse()
                .unwrap()
        };
        for part in svg.split(r#"class="error-bar""#).skip(1) {
            let d = part.split("d=\"M").nth(1).unwrap();
            let (y_lo, y_hi) = (y_of(d, ","), y_of(d, "V"));
            // SVG y grows downwards: the upper end (0.03) is above the lower (0.015), and the
            // 0.03 top fits in the plot (the axis grew to hold it).
            assert!(y_hi < y_lo && y_hi > 40.0, "{y_lo} {y_hi}");
        }
    }
}
