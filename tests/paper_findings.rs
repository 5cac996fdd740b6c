//! The paper's study at full size on the embedded bench (2560x2160 frames, patterns a, b, c, the
//! 5 mm x move with the stage's 6.15 mrad misalignment). Asserts the findings the physics of that
//! bench reproduces; where it disagrees with the paper (pattern a), the closing note of the issue
//! reports the numbers instead of a loosened assertion here.

use ffdic::dataset::Manifest;
use ffdic::experiment::{simulate_dataset, ExperimentSpec};
use ffdic::model::ModelConfig;
use ffdic::reduce::Scheme;
use ffdic::study::{analyze_dataset, StudyRow};
use std::path::Path;

fn study(bench: &str) -> Vec<StudyRow> {
    let spec = ExperimentSpec::paper();
    let model = ModelConfig::load(
        &Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("config/models")
            .join(bench),
    )
    .unwrap();
    let dir = tempfile::tempdir().unwrap();
    simulate_dataset(&spec, &model, spec.seed, dir.path(), &|_, _| {}).unwrap();
    let manifest = Manifest::read(dir.path()).unwrap();
    let schemes: Vec<Scheme> = spec
        .schemes
        .iter()
        .map(|s| Scheme::preset(s).unwrap())
        .collect();
    analyze_dataset(
        dir.path(),
        &manifest,
        &schemes,
        &spec.dic,
        &|_, _| true,
        &|| false,
    )
    .unwrap()
}

fn row<'a>(rows: &'a [StudyRow], pattern: &str, scheme: &str) -> &'a StudyRow {
    rows.iter()
        .find(|r| r.pattern == pattern && r.scheme == scheme)
        .unwrap()
}

#[test]
fn paper_study_on_the_noise_limited_bench() {
    let rows = study("paper-bench.toml");
    for r in &rows {
        println!(
            "{} {:>5}: std u {:.5} v {:.5} px, exx {:.1} eyy {:.1} µε, increase {:?}",
            r.pattern,
            r.scheme,
            r.summary.u.std,
            r.summary.v.std,
            r.summary.exx.std * 1e6,
            r.summary.eyy.std * 1e6,
            r.increase_pct
        );
        assert_eq!(
            r.summary.valid, r.summary.points,
            "{} {}",
            r.pattern, r.scheme
        );
        // The move: 5 mm at 13 px/mm in the reduced images, turned by the stage's 6.15 mrad.
        assert!((r.summary.u.mean - 65.0 * 0.00615f64.cos()).abs() < 0.01);
        assert!((r.summary.v.mean - 65.0 * 0.00615f64.sin()).abs() < 0.01);
    }
    for p in ["b", "c"] {
        let (full, quarter) = (row(&rows, p, "ff100"), row(&rows, p, "ff25"));
        // Paper: for b and c the errors at 25 % exceed those at 100 %.
        for (name, a, b) in [
            ("u", full.summary.u.std, quarter.summary.u.std),
            ("v", full.summary.v.std, quarter.summary.v.std),
            ("exx", full.summary.exx.std, quarter.summary.exx.std),
            ("eyy", full.summary.eyy.std, quarter.summary.eyy.std),
        ] {
            assert!(
                b > a,
                "pattern {p}: std {name} at 25 % ({b}) should exceed 100 % ({a})"
            );
        }
    }
    // Paper: the sub-pixel y component is affected more than the large x move. Each increase
    // carries its block-bootstrap 95 % interval; with print c's smooth speckle the two differ by
    // less than their intervals (x 102 % [92, 113], y 90 % [79, 103] in one realisation of the
    // shot noise; the paper's order in the realisation before it), so the finding is asked where
    // it is resolved: no print may contradict it beyond the intervals, and the sharp print b must
    // resolve it.
    let mut resolved = Vec::new();
    for p in ["a", "b", "c"] {
        let quarter = row(&rows, p, "ff25");
        let (inc, ci) = (
            quarter.increase_pct.unwrap(),
            quarter.increase_ci95.unwrap(),
        );
        println!(
            "{p} ff25 increase: x {:.0} % [{:.0}, {:.0}], y {:.0} % [{:.0}, {:.0}]",
            inc.u, ci.u[0], ci.u[1], inc.v, ci.v[0], ci.v[1]
        );
        assert!(
            ci.v[1] >= ci.u[0],
            "pattern {p}: y increase {:.0} % [{:.0}, {:.0}] below x {:.0} % [{:.0}, {:.0}]",
            inc.v,
            ci.v[0],
            ci.v[1],
            inc.u,
            ci.u[0],
            ci.u[1]
        );
        if ci.v[0] > ci.u[1] {
            resolved.push(p);
        }
    }
    assert!(
        resolved.contains(&"b"),
        "the y increase exceeds the x increase beyond their intervals only for {resolved:?}"
    );
}
