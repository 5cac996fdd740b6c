//! The map as an Arrow IPC file (`map.arrow`): the columns of `map.csv`, typed — text for the
//! print and the scheme, unsigned for the realisation count, float64 for the rest, null where
//! `map.csv` has nothing (the model's own noise) or NaN (a statistic no realisation defined) —
//! so pyarrow, polars or R read the map without parsing text.

use super::merge::{CellStats, Merged, STAT_NAMES};
use arrow_array::{ArrayRef, Float64Array, RecordBatch, StringArray, UInt64Array};
use arrow_schema::{DataType, Field, Schema};
use std::collections::HashMap;
use std::sync::Arc;

/// The Arrow IPC file of `merged` (one record batch, one row per cell, in `map.csv`'s order).
pub fn map_arrow(name: &str, merged: &Merged) -> Vec<u8> {
    let cells = &merged.cells;
    let mut fields = Vec::new();
    let mut columns: Vec<ArrayRef> = Vec::new();
    let mut text = |column: &str, value: &dyn Fn(&CellStats) -> String| {
        fields.push(Field::new(column, DataType::Utf8, false));
        columns.push(Arc::new(StringArray::from_iter_values(
            cells.iter().map(value),
        )));
    };
    text("print", &|c| c.task.print.label());
    text("scheme", &|c| c.task.scheme.name.clone());
    let finite = |v: f64| v.is_finite().then_some(v);
    let mut number = |column: &str, value: &dyn Fn(&CellStats) -> Option<f64>| {
        fields.push(Field::new(column, DataType::Float64, true));
        columns.push(Arc::new(Float64Array::from_iter(cells.iter().map(value))));
    };
    number("fill_x", &|c| Some(c.task.scheme.linear_fill_factor().0));
    number("fill_y", &|c| Some(c.task.scheme.linear_fill_factor().1));
    number("full_well_e", &|c| c.task.noise.map(|n| n.full_well_e));
    number("read_noise_e", &|c| c.task.noise.map(|n| n.read_noise_e));
    number("psf_sigma_px", &|c| Some(c.task.psf_sigma_px));
    number("aperture_x", &|c| c.task.aperture.map(|a| a[0]));
    number("aperture_y", &|c| c.task.aperture.map(|a| a[1]));
    number("subpixel_x_px", &|c| Some(c.task.subpixel_px[0]));
    number("subpixel_y_px", &|c| Some(c.task.subpixel_px[1]));
    fields.push(Field::new("n", DataType::UInt64, false));
    columns.push(Arc::new(UInt64Array::from_iter_values(
        cells.iter().map(|c| c.n as u64),
    )));
    for (i, stat) in STAT_NAMES.iter().enumerate() {
        for (suffix, part) in [("", 0), ("_lo", 1), ("_hi", 2)] {
            fields.push(Field::new(
                format!("{stat}{suffix}"),
                DataType::Float64,
                true,
            ));
            columns.push(Arc::new(Float64Array::from_iter(cells.iter().map(|c| {
                let (mean, [lo, hi]) = c.values[i];
                finite([mean, lo, hi][part])
            }))));
        }
    }
    let metadata = HashMap::from([
        ("ffdic.sweep".to_string(), name.to_string()),
        (
            "ffdic.interval".to_string(),
            "95 % Student-t interval of the mean over realisations (columns *_lo, *_hi)".into(),
        ),
    ]);
    let schema = Arc::new(Schema::new_with_metadata(fields, metadata));
    let batch = RecordBatch::try_new(schema.clone(), columns)
        .expect("one column per field, one row per cell");
    let mut out = Vec::new();
    {
        let mut writer = arrow_ipc::writer::FileWriter::try_new(&mut out, &schema)
            .expect("writing to memory cannot fail");
        writer.write(&batch).expect("writing to memory cannot fail");
        writer.finish().expect("writing to memory cannot fail");
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sweep::merge::CellStats;
    use crate::sweep::plan::TaskInput;
    use crate::sweep::spec::{NoiseLevel, PrintAxis};
    use arrow_array::Array;

    fn cell(print: f64, noise: Option<NoiseLevel>, u_std: f64) -> CellStats {
        CellStats {
            task: TaskInput {
                id: format!("{print}"),
                print: PrintAxis::DotDiameterPx(print),
                scheme: crate::reduce::Scheme::preset("ff50").unwrap(),
                noise,
                psf_sigma_px: 0.5,
                aperture: None,
                subpixel_px: [0.25, 0.0],
                realisation: 0,
                seed: 1,
            },
            n: 3,
            values: (0..STAT_NAMES.len())
                .map(|k| (u_std + k as f64, [u_std - 0.1, u_std + 0.1]))
                .collect(),
        }
    }

    #[test]
    fn the_arrow_reader_gets_back_every_column() {
        let noise = NoiseLevel {
            full_well_e: 30000.0,
            read_noise_e: 1.5,
            gain: 0.46,
        };
        let merged = Merged {
            cells: vec![cell(3.0, Some(noise), 0.002), cell(7.0, None, f64::NAN)],
            missing: Vec::new(),
        };
        let bytes = map_arrow("t", &merged);
        assert_eq!(&bytes[..6], b"ARROW1");
        let reader =
            arrow_ipc::reader::FileReader::try_new(std::io::Cursor::new(bytes), None).unwrap();
        assert_eq!(reader.schema().metadata()["ffdic.sweep"], "t");
        let batches: Vec<RecordBatch> = reader.map(Result::unwrap).collect();
        assert_eq!(batches.len(), 1);
        let b = &batches[0];
        assert_eq!(b.num_rows(), 2);
        assert_eq!(b.num_columns(), 12 + 3 * STAT_NAMES.len());
        let text = |name: &str| {
            b.column_by_name(name)
                .unwrap()
                .as_any()
                .downcast_ref::<StringArray>()
                .unwrap()
                .clone()
        };
        let float = |name: &str| {
            b.column_by_name(name)
                .unwrap()
                .as_any()
                .downcast_ref::<Float64Array>()
                .unwrap()
                .clone()
        };
        assert_eq!(text("print").value(1), "7");
        assert_eq!(text("scheme").value(0), "ff50");
        assert_eq!(float("fill_x").value(0), 0.5);
        assert_eq!(float("full_well_e").value(0), 30000.0);
        assert!(float("full_well_e").is_null(1), "the model's noise is null");
        assert_eq!(float("u_std_px").value(0), 0.002);
        assert_eq!(float("u_std_px_hi").value(0), 0.002 + 0.1);
        assert!(float("u_std_px").is_null(1), "NaN is null");
        assert_eq!(float("valid_fraction").value(0), 0.002 + 7.0);
        assert_eq!(float("subpixel_x_px").value(1), 0.25);
        let n = b
            .column_by_name("n")
            .unwrap()
            .as_any()
            .downcast_ref::<UInt64Array>()
            .unwrap()
            .clone();
        assert_eq!(n.values(), &[3, 3]);
    }
}
