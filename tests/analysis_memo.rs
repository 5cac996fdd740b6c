//! The memo of analyses (`pairs::memo`, issue 37): a dataset's pairs correlated again — the same
//! frames under another folder — are recalled, identical to the first analyses; a frame rewritten
//! with other content is analysed anew, whatever its name.

use ffdic::dataset::{Manifest, Run};
use ffdic::dic::DicResult;
use ffdic::experiment::{simulate_dataset, ExperimentSpec};
use ffdic::model::ModelConfig;
use ffdic::pairs::memo::AnalysisMemo;
use ffdic::pairs::{correlate_pairs_in, PairError, PairVisitor, RunPair};
use ffdic::reduce::Scheme;
use std::path::Path;

/// Every analysis, as `run id / scheme` and the points' displacements' bits (an invalid point's
/// NaN equals itself).
#[derive(Default)]
struct Collected(Vec<(String, Vec<(u64, u64)>)>);

impl PairVisitor for Collected {
    type Error = PairError;

    fn result(
        &mut self,
        pair: &RunPair<'_>,
        scheme: &Scheme,
        r: DicResult,
    ) -> Result<(), PairError> {
        let uv = r
            .points
            .iter()
            .map(|p| (p.u.to_bits(), p.v.to_bits()))
            .collect();
        self.0
            .push((format!("{}/{}", pair.run.id, scheme.name), uv));
        Ok(())
    }
}

fn correlate(memo: &AnalysisMemo, dir: &Path, runs: &[Run], spec: &ExperimentSpec) -> Collected {
    let schemes: Vec<Scheme> = spec
        .schemes
        .iter()
        .map(|s| Scheme::preset(s).unwrap())
        .collect();
    let mut out = Collected::default();
    correlate_pairs_in(memo, dir, runs, &schemes, &spec.dic, &mut out).unwrap();
    out
}

#[test]
fn analyses_are_recalled_by_content_and_made_again_when_a_frame_changes() {
    let repo = Path::new(env!("CARGO_MANIFEST_DIR"));
    let spec = ExperimentSpec::load(&repo.join("tests/fixtures/small.toml")).unwrap();
    let model = ModelConfig::load(&repo.join("config/models/paper-bench.toml")).unwrap();
    let root = tempfile::tempdir().unwrap();
    let (a, b) = (root.path().join("a"), root.path().join("b"));
    simulate_dataset(&spec, &model, spec.seed, &a, &|_, _| {}).unwrap();
    let manifest = Manifest::read(&a).unwrap();
    // The x move of the first pattern and its three steps' first: two runs, one reference.
    let runs: Vec<Run> = manifest.runs.iter().take(2).cloned().collect();
    let memo = AnalysisMemo::new(ffdic::pairs::memo::BUDGET_BYTES);
    let first = correlate(&memo, &a, &runs, &spec);
    assert_eq!(first.0.len(), 2 * spec.schemes.len());
    assert_eq!(memo.len(), first.0.len(), "every analysis remembered");

    // The same frames in another folder: recalled (nothing new remembered), the same numbers.
    std::fs::create_dir_all(&b).unwrap();
    for entry in std::fs::read_dir(&a).unwrap() {
        let entry = entry.unwrap();
        std::fs::copy(entry.path(), b.join(entry.file_name())).unwrap();
    }
    let again = correlate(&memo, &b, &runs, &spec);
    assert_eq!(memo.len(), first.0.len(), "recalled, not made again");
    assert_eq!(first.0, again.0);

    // The first run's moved frame rewritten as its reference: the move is gone, so its analyses
    // are made again (one new analysis per scheme) and find no motion; the second run's recalled.
    std::fs::copy(b.join(&runs[0].reference), b.join(&runs[0].deformed)).unwrap();
    let changed = correlate(&memo, &b, &runs, &spec);
    assert_eq!(memo.len(), first.0.len() + spec.schemes.len());
    for ((name, before), (_, after)) in first.0.iter().zip(&changed.0) {
        let mean_u = |uv: &[(u64, u64)]| {
            let u: Vec<f64> = uv
                .iter()
                .map(|p| f64::from_bits(p.0))
                .filter(|u| u.is_finite())
                .collect();
            u.iter().sum::<f64>() / u.len() as f64
        };
        if name.starts_with(&format!("{}/", runs[0].id)) {
            assert!(
                mean_u(before) > 3.0,
                "{name}: the 1 mm move, {}",
                mean_u(before)
            );
            assert!(
                mean_u(after).abs() < 0.05,
                "{name}: no move, {}",
                mean_u(after)
            );
        } else {
            assert_eq!(before, after, "{name}: its frames did not change");
        }
    }
}
