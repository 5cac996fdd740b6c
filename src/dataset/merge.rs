//! Two datasets of one bench as one: the runs a bench captured later (`added`) appended to a
//! dataset (`base`), their ids and frame files prefixed so nothing collides — what
//! `ffdic diagnose --on-bench` diagnoses after capturing the runs that separate its candidates.
//! The base's runs and files keep their names; neither folder is changed. The added runs'
//! patterns are prefixed too: a later session's reference is its own (the target placed anew,
//! its static frames taken against it), so its print is calibrated on it.

use super::manifest::{DatasetError, Manifest, PatternInfo, Run};
use std::path::Path;

/// Writes into `out` (an empty or new folder) the manifest of `base`'s runs followed by
/// `added`'s, each added id and frame file prefixed with `prefix`, and the frames (hard links
/// where the filesystem allows, copies elsewhere). The two must share the scale and, where they
/// state it, the camera's frame size and bit depth: one bench.
pub fn merge_datasets(
    base_dir: &Path,
    added_dir: &Path,
    prefix: &str,
    out: &Path,
) -> Result<Manifest, DatasetError> {
    let base = Manifest::read(base_dir)?;
    let added = Manifest::read(added_dir)?;
    let invalid = |message: String| DatasetError::Invalid {
        path: added_dir.join("dataset.json"),
        message,
    };
    let rel = (base.scale_px_per_mm - added.scale_px_per_mm).abs() / base.scale_px_per_mm;
    if !(rel < 1e-9) {
        return Err(invalid(format!(
            "scale {} px/mm against the dataset's {}: not the same bench",
            added.scale_px_per_mm, base.scale_px_per_mm
        )));
    }
    if let (Some(a), Some(b)) = (&base.camera, &added.camera) {
        if (a.width, a.height, a.bit_depth) != (b.width, b.height, b.bit_depth) {
            return Err(invalid(format!(
                "frames of {}x{} px at {} bit against the dataset's {}x{} px at {} bit: not the same camera",
                b.width, b.height, b.bit_depth, a.width, a.height, a.bit_depth
            )));
        }
    }
    std::fs::create_dir_all(out).map_err(|source| DatasetError::Write {
        path: out.to_owned(),
        source,
    })?;
    for file in base.frame_files() {
        link_or_copy(&base_dir.join(&file), &out.join(&file))?;
    }
    for file in added.frame_files() {
        link_or_copy(&added_dir.join(&file), &out.join(format!("{prefix}{file}")))?;
    }
    let with_prefix = |s: &String| format!("{prefix}{s}");
    let mut merged = base.clone();
    merged.name = format!("{} + {}", base.name, added.name);
    merged.runs.extend(added.runs.iter().map(|r| Run {
        id: with_prefix(&r.id),
        reference: with_prefix(&r.reference),
        deformed: with_prefix(&r.deformed),
        repeat: r.repeat.iter().map(with_prefix).collect(),
        repeat_of: r.repeat_of.as_ref().map(with_prefix),
        twin_of: r.twin_of.as_ref().map(with_prefix),
        // A later session's target is its own pattern: the diagnosis calibrates its print on
        // its own reference (and that reference's static frames), placed anew. The same label
        // is the same print, so what the base states of it (a characterised print's profile,
        // contrast and MTF) holds for the added frames too: a bench records a preset only
        // nominally, and the print would otherwise be calibrated again, absorbing any blur.
        pattern: r.pattern.as_ref().map(|p| PatternInfo {
            label: with_prefix(&p.label),
            ..stated_by(&base, &p.label).unwrap_or(p).clone()
        }),
        ..r.clone()
    }));
    if let Some(dup) = merged
        .runs
        .iter()
        .enumerate()
        .find(|(i, r)| merged.runs[..*i].iter().any(|o| o.id == r.id))
    {
        return Err(invalid(format!(
            "run id {} twice after the prefix '{prefix}'",
            dup.1.id
        )));
    }
    merged.write(out)?;
    Ok(merged)
}

/// What `manifest`'s runs state of the print labelled `label` (the first run's statement).
fn stated_by<'a>(manifest: &'a Manifest, label: &str) -> Option<&'a PatternInfo> {
    manifest
        .runs
        .iter()
        .filter_map(|r| r.pattern.as_ref())
        .find(|p| p.label == label)
}

fn link_or_copy(from: &Path, to: &Path) -> Result<(), DatasetError> {
    if let Some(parent) = to.parent() {
        std::fs::create_dir_all(parent).map_err(|source| DatasetError::Write {
            path: parent.to_owned(),
            source,
        })?;
    }
    crate::atomic_write::link_or_copy(from, to)
        .map_err(|(path, source)| DatasetError::Write { path, source })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::dataset::manifest::StageMove;

    fn dataset(dir: &Path, name: &str, scale: f64, runs: &[(&str, f64)]) {
        std::fs::create_dir_all(dir).unwrap();
        let mut m = Manifest::new(name, scale);
        for (id, dx) in runs {
            let (reference, deformed) = ("ref.tif".to_string(), format!("{id}.tif"));
            for f in [&reference, &deformed] {
                std::fs::write(dir.join(f), format!("{name}/{f}")).unwrap();
            }
            m.runs.push(Run {
                id: id.to_string(),
                pattern: Some(PatternInfo {
                    label: "a".into(),
                    ..Default::default()
                }),
                reference,
                deformed,
                stage: StageMove {
                    dx_mm: *dx,
                    dy_mm: 0.0,
                },
                repeat: Vec::new(),
                exposure_us: None,
                repeat_of: None,
                capture: None,
                twin_of: None,
                extra: Default::default(),
            });
        }
        m.write(dir).unwrap();
    }

    #[test]
    fn the_added_runs_follow_the_base_under_their_prefix() {
        let tmp = tempfile::tempdir().unwrap();
        let [base, added, out] = ["base", "added", "out"].map(|d| tmp.path().join(d));
        dataset(&base, "paper", 26.0, &[("x5", 5.0)]);
        dataset(&added, "bench", 26.0, &[("x5", 5.0), ("x1", 1.0)]);
        let m = merge_datasets(&base, &added, "bench-", &out).unwrap();
        let ids: Vec<&str> = m.runs.iter().map(|r| r.id.as_str()).collect();
        assert_eq!(ids, ["x5", "bench-x5", "bench-x1"]);
        assert_eq!(m.runs[2].reference, "bench-ref.tif");
        let label = |i: usize| m.runs[i].pattern.as_ref().unwrap().label.clone();
        assert_eq!(
            (label(0), label(1)),
            ("a".to_string(), "bench-a".to_string())
        );
        // The frames are the ones each manifest named, under their new names.
        let read = |f: &str| std::fs::read_to_string(out.join(f)).unwrap();
        assert_eq!(read("ref.tif"), "paper/ref.tif");
        assert_eq!(read("bench-ref.tif"), "bench/ref.tif");
        assert_eq!(read("bench-x1.tif"), "bench/x1.tif");
        assert_eq!(Manifest::read(&out).unwrap(), m);
        // Another scale is another bench.
        dataset(&tmp.path().join("other"), "other", 13.0, &[("x1", 1.0)]);
        let e = merge_datasets(
            &base,
            &tmp.path().join("other"),
            "b-",
            &tmp.path().join("o2"),
        );
        assert!(e.unwrap_err().to_string().contains("not the same bench"));
    }

    /// The base's statement of a print holds for the added runs of the same label (a bench
    /// records its preset only nominally); another label keeps the added manifest's own.
    #[test]
    fn the_added_runs_take_the_bases_statement_of_the_same_print() {
        let tmp = tempfile::tempdir().unwrap();
        let [base, added, out] = ["base", "added", "out"].map(|d| tmp.path().join(d));
        dataset(&base, "paper", 26.0, &[("x5", 5.0)]);
        let mut m = Manifest::read(&base).unwrap();
        let stated = PatternInfo {
            label: "a".into(),
            dot_diameter_mm: Some(0.18),
            profile: Some(crate::dataset::DotProfile::Gaussian),
            contrast: Some(0.7),
            ..Default::default()
        };
        m.runs[0].pattern = Some(stated.clone());
        m.write(&base).unwrap();
        dataset(&added, "bench", 26.0, &[("x1", 1.0), ("y1", 0.0)]);
        let mut a = Manifest::read(&added).unwrap();
        a.runs[0].pattern.as_mut().unwrap().dot_diameter_mm = Some(0.2);
        a.runs[1].pattern.as_mut().unwrap().label = "b".into();
        a.write(&added).unwrap();
        let merged = merge_datasets(&base, &added, "bench-", &out).unwrap();
        let pattern = |i: usize| merged.runs[i].pattern.clone().unwrap();
        assert_eq!(
            pattern(1),
            PatternInfo {
                label: "bench-a".into(),
                ..stated
            }
        );
        assert_eq!(
            pattern(2),
            PatternInfo {
                label: "bench-b".into(),
                ..Default::default()
            }
        );
    }
}
