//! u, v and strain maps of one analysed pair as SVG heat maps, for people reading a run: where the
//! displacement varies over the field and where the strain error sits. Points the DIC rejected are
//! grey. Coordinates are those of the reduced image the DIC saw.

use super::Heatmap;
use crate::dic::{DicResult, PoiResult};

/// One map: which field, its label with units, how to read it from a point, and whether the map
/// shows the variation about the mean (a displacement of a rigid move is nearly constant: its
/// mean is in the title and the colours show what varies).
struct Field {
    key: &'static str,
    name: &'static str,
    unit: &'static str,
    value: fn(&PoiResult) -> f64,
    about_mean: bool,
}

const FIELDS: [Field; 5] = [
    Field {
        key: "u",
        name: "u",
        unit: "px",
        value: |p| p.u,
        about_mean: true,
    },
    Field {
        key: "v",
        name: "v",
        unit: "px",
        value: |p| p.v,
        about_mean: true,
    },
    Field {
        key: "exx",
        name: "εxx",
        unit: "µε",
        value: |p| p.exx * 1e6,
        about_mean: false,
    },
    Field {
        key: "eyy",
        name: "εyy",
        unit: "µε",
        value: |p| p.eyy * 1e6,
        about_mean: false,
    },
    Field {
        key: "exy",
        name: "εxy",
        unit: "µε",
        value: |p| p.exy * 1e6,
        about_mean: false,
    },
];

/// The file name of a map: `map_{pattern}_{scheme}_{u|v|exx|eyy|exy}.svg`, a hardware scheme's
/// `:` written as `-` (`map_b_hw-bin2x2-average_u.svg`).
pub fn map_file_name(pattern: &str, scheme: &str, field: &str) -> String {
    format!("map_{pattern}_{}_{field}.svg", scheme.replace(':', "-"))
}

/// The u, v, εxx, εyy and εxy maps of `result` (run `run` of `pattern`, reduced with `scheme`):
/// `(file name, svg)` for each.
pub fn field_map_svgs(
    result: &DicResult,
    run: &str,
    pattern: &str,
    scheme: &str,
) -> Vec<(String, String)> {
    let xs: Vec<f64> = result.grid.xs.iter().map(|&x| x as f64).collect();
    let ys: Vec<f64> = result.grid.ys.iter().map(|&y| y as f64).collect();
    FIELDS
        .iter()
        .map(|f| {
            let mut values: Vec<f64> = result
                .points
                .iter()
                .map(|p| {
                    if p.status.is_valid() {
                        (f.value)(p)
                    } else {
                        f64::NAN
                    }
                })
                .collect();
            let finite: Vec<f64> = values.iter().copied().filter(|v| v.is_finite()).collect();
            let mean = finite.iter().sum::<f64>() / finite.len().max(1) as f64;
            let (title, value_label) = if f.about_mean && !finite.is_empty() {
                for v in &mut values {
                    *v -= mean;
                }
                (
                    format!(
                        "{} − mean ({mean:.4} {}) — pattern {pattern}, {scheme}, run {run}",
                        f.name, f.unit
                    ),
                    format!("{} − mean [{}]", f.name, f.unit),
                )
            } else {
                (
                    format!("{} — pattern {pattern}, {scheme}, run {run}", f.name),
                    format!("{} [{}]", f.name, f.unit),
                )
            };
            let map = Heatmap {
                title,
                x_label: "x in the reduced image [px]".into(),
                y_label: "y [px]".into(),
                value_label,
                xs: xs.clone(),
                ys: ys.clone(),
                values,
                diverging: true,
                x_tick_labels: Vec::new(),
                y_tick_labels: Vec::new(),
                markers: Vec::new(),
            };
            (map_file_name(pattern, scheme, f.key), map.to_svg(520, 400))
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::dic::{DicSettings, PreparedReference};
    use crate::image::Image;

    #[test]
    fn five_maps_with_one_cell_per_point_and_units() {
        // A smooth random-ish texture shifted by 0.5 px.
        let (w, h) = (96usize, 80usize);
        let tex = |x: f64, y: f64| {
            1000.0
                + 400.0 * (0.37 * x).sin() * (0.23 * y).cos()
                + 300.0 * (0.11 * x + 0.29 * y).sin()
        };
        let mk = |dx: f64| Image::from_fn(w, h, |x, y| tex(x as f64 - dx, y as f64) as f32);
        let dic = DicSettings {
            subset_px: 21,
            step_px: 10,
            strain_window: 3,
            ..DicSettings::default()
        };
        let result = PreparedReference::new(&mk(0.0), &dic)
            .unwrap()
            .correlate(&mk(0.5), None)
            .unwrap();
        let maps = field_map_svgs(&result, "a-x1", "a", "ff100");
        let names: Vec<&str> = maps.iter().map(|(n, _)| n.as_str()).collect();
        assert_eq!(
            names,
            [
                "map_a_ff100_u.svg",
                "map_a_ff100_v.svg",
                "map_a_ff100_exx.svg",
                "map_a_ff100_eyy.svg",
                "map_a_ff100_exy.svg"
            ]
        );
        let cells = result.grid.xs.len() * result.grid.ys.len();
        for (_, svg) in &maps {
            assert_eq!(svg.matches(r#"class="cell""#).count(), cells);
            assert!(svg.contains(r#"class="legend""#));
            assert!(svg.contains("[px]"));
        }
        assert!(maps[0].1.contains("u − mean [px]"));
        assert!(maps[2].1.contains("εxx [µε]"));
        assert!(maps[3].1.contains("εyy [µε]"));
        assert!(maps[4].1.contains("εxy [µε]"));
    }
}
