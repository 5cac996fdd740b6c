//! Issue 12: the parsers that read what clients send — TIFF frames, `dataset.json` manifests,
//! experiment requests (JSON) and files (TOML), model files (TOML) — fed mutated and random
//! inputs for a bounded number of cases each. No case may panic (an abort would end the test
//! process, a panic is caught and counted) and the peak memory of a process that runs the parser
//! alone stays under 1 GiB (each test runs in a process of its own: [`in_own_process`]).
//!
//! cargo-fuzz needs a nightly toolchain this machine lacks, so this is a seeded havoc mutator in
//! the manner of AFL (bit and byte flips, interesting values, block deletes, duplicates and
//! splices, truncation) over valid seeds, plus purely random inputs. `FFDIC_FUZZ_CASES` sets the
//! cases per parser (default 5000); the seed is fixed, so a failure reproduces.

use ffdic::bench::BenchLimits;
use ffdic::dataset::Manifest;
use ffdic::experiment::{ExperimentRequest, ExperimentSpec, PAPER_TOML};
use ffdic::image::{read_tiff, tiff_u16_bytes};
use ffdic::model::ModelConfig;
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::path::Path;

fn cases() -> usize {
    std::env::var("FFDIC_FUZZ_CASES")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(5000)
}

/// Values that sit on type and size boundaries, written at random offsets.
const INTERESTING: [u64; 10] = [
    0,
    1,
    0x7F,
    0xFF,
    0x7FFF,
    0xFFFF,
    0x7FFF_FFFF,
    0xFFFF_FFFF,
    0x8000_0000_0000_0000,
    u64::MAX,
];

/// One havoc round: a few stacked mutations of `seed`.
fn mutate(rng: &mut StdRng, seed: &[u8], others: &[&[u8]]) -> Vec<u8> {
    let mut v = seed.to_vec();
    for _ in 0..rng.gen_range(1..=8) {
        let len = v.len();
        match rng.gen_range(0..8) {
            0 if len > 0 => {
                let i = rng.gen_range(0..len);
                v[i] ^= 1 << rng.gen_range(0..8);
            }
            1 if len > 0 => {
                let i = rng.gen_range(0..len);
                v[i] = rng.gen();
            }
            2 if len > 0 => {
                let width = [1usize, 2, 4, 8][rng.gen_range(0..4)];
                let value = INTERESTING[rng.gen_range(0..INTERESTING.len())];
                let bytes = if rng.gen() {
                    value.to_le_bytes()
                } else {
                    value.to_be_bytes()
                };
                let at = rng.gen_range(0..len);
                for (k, b) in bytes.iter().take(width).enumerate() {
                    if at + k < len {
                        v[at + k] = *b;
                    }
                }
            }
            3 if len > 1 => {
                let a = rng.gen_range(0..len);
                let b = (a + rng.gen_range(1..=len.min(64))).min(len);
                v.drain(a..b);
            }
            4 if len > 1 => {
                let a = rng.gen_range(0..len);
                let b = (a + rng.gen_range(1..=len.min(64))).min(len);
                let block = v[a..b].to_vec();
                let at = rng.gen_range(0..=v.len());
                v.splice(at..at, block);
            }
            5 if len > 0 => v.truncate(rng.gen_range(0..len)),
            6 => {
                let other = others[rng.gen_range(0..others.len())];
                if !other.is_empty() {
                    let a = rng.gen_range(0..other.len());
                    let b = (a + rng.gen_range(1..=other.len().min(256))).min(other.len());
                    let at = rng.gen_range(0..=v.len());
                    v.splice(at..at, other[a..b].iter().copied());
                }
            }
            _ => {
                let at = rng.gen_range(0..=v.len());
                let n = rng.gen_range(1..32);
                let noise: Vec<u8> = (0..n).map(|_| rng.gen()).collect();
                v.splice(at..at, noise);
            }
        }
    }
    v
}

/// Runs `parse` on `cases()` inputs: mutations of the seeds, and one in ten random bytes.
/// Returns (cases, accepted); panics, if any, fail the test with the first input's bytes.
fn fuzz(name: &str, seeds: &[Vec<u8>], mut parse: impl FnMut(&[u8]) -> bool) -> (usize, usize) {
    let mut rng = StdRng::seed_from_u64(0xF0_22 ^ name.len() as u64);
    let refs: Vec<&[u8]> = seeds.iter().map(Vec::as_slice).collect();
    let (mut accepted, mut panics) = (0usize, Vec::new());
    let n = cases();
    for case in 0..n {
        let input = if case % 10 == 9 {
            let len = rng.gen_range(0..2048);
            (0..len).map(|_| rng.gen()).collect()
        } else {
            mutate(&mut rng, refs[case % refs.len()], &refs)
        };
        match catch_unwind(AssertUnwindSafe(|| parse(&input))) {
            Ok(true) => accepted += 1,
            Ok(false) => {}
            Err(_) => panics.push(input),
        }
    }
    println!(
        "{name}: {n} cases, {accepted} accepted, {} panics",
        panics.len()
    );
    assert!(
        panics.is_empty(),
        "{name}: {} of {n} inputs panicked; the first: {:?}",
        panics.len(),
        String::from_utf8_lossy(&panics[0][..panics[0].len().min(400)])
    );
    (n, accepted)
}

/// Peak resident memory of this process, kB (Linux `VmHWM`).
fn peak_rss_kb() -> u64 {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("VmHWM:"))
                .and_then(|l| l.split_whitespace().nth(1)?.parse().ok())
        })
        .unwrap_or(0)
}

/// Set in the process [`in_own_process`] starts.
const OWN_PROCESS: &str = "FFDIC_FUZZ_OWN_PROCESS";

/// Runs `body` in a process of its own — this test binary again, filtered to `test` alone — so
/// that the peak memory `body` asserts is the parser's: in the shared integration binary the
/// process's high-water mark also holds the diagnoses that ran beside it (1,041 MiB in a CI run of
/// 2026-12-07, the parsers' own far below).
fn in_own_process(test: &str, body: fn()) {
    if std::env::var_os(OWN_PROCESS).is_some() {
        body();
        return;
    }
    let out = std::process::Command::new(std::env::current_exe().expect("the test binary"))
        .args([test, "--exact", "--nocapture", "--test-threads", "1"])
        .env(OWN_PROCESS, "1")
        .output()
        .expect("run the test binary again");
    let stdout = String::from_utf8_lossy(&out.stdout);
    println!("{stdout}{}", String::from_utf8_lossy(&out.stderr));
    assert!(out.status.success(), "{test} failed in its own process");
    assert!(
        stdout.contains("test result: ok. 1 passed"),
        "{test}: its own process ran no test"
    );
}

fn assert_memory_bounded(what: &str) {
    let kb = peak_rss_kb();
    println!("{what}: peak RSS {} MiB", kb / 1024);
    assert!(kb < 1024 * 1024, "{what}: peak RSS {kb} kB");
}

#[test]
fn tiff_frames() {
    in_own_process("fuzz_parsers::tiff_frames", tiff_frames_alone);
}

fn tiff_frames_alone() {
    let dir = tempfile::tempdir().unwrap();
    let data: Vec<u16> = (0..64 * 48u32)
        .map(|k| (k.wrapping_mul(2_654_435_761) >> 16) as u16)
        .collect();
    let mut seeds = vec![tiff_u16_bytes(64, 48, &data).unwrap()];
    // Every TIFF fixture the other tests read (8/16/32-bit, float, palette, strips, tiles…).
    let fixtures = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/tiff");
    if let Ok(entries) = std::fs::read_dir(&fixtures) {
        for e in entries.flatten() {
            let bytes = std::fs::read(e.path()).unwrap();
            if bytes.len() < 200_000 {
                seeds.push(bytes);
            }
        }
    }
    let path = dir.path().join("case.tif");
    let (n, ok) = fuzz("tiff", &seeds, |bytes| {
        std::fs::write(&path, bytes).unwrap();
        read_tiff(&path).is_ok()
    });
    assert!(
        ok > 0 && ok < n,
        "{ok} of {n}: the mutations reach both outcomes"
    );
    assert_memory_bounded("tiff");
}

#[test]
fn dataset_manifests() {
    in_own_process("fuzz_parsers::dataset_manifests", dataset_manifests_alone);
}

fn dataset_manifests_alone() {
    let dir = tempfile::tempdir().unwrap();
    let seeds: Vec<Vec<u8>> = [
        r#"{"format": "ffdic-dataset/1", "name": "bench", "scale_px_per_mm": 26.0,
            "camera": {"width": 2560, "height": 2160, "bit_depth": 16},
            "stage_repeatability_um": 1.5,
            "runs": [{"id": "a-x", "pattern": {"label": "a", "dot_diameter_mm": 0.5,
                      "dot_spacing_mm": 0.75, "contrast": 0.85},
                      "reference": "a_ref.tif", "deformed": "a_x.tif",
                      "stage": {"dx_mm": 5.0, "dy_mm": 0.0}, "repeat": ["a_ref_r1.tif"],
                      "exposure_us": 10000.0, "repeat_of": "a-x"}]}"#,
        r#"{"format":"ffdic-dataset/1","name":"n","scale_px_per_mm":13,"runs":[{"id":"r","reference":"r.tif","deformed":"d.tif","stage":{"dx_mm":1e308,"dy_mm":-0.0}}]}"#,
    ]
    .iter()
    .map(|s| s.as_bytes().to_vec())
    .collect();
    let (n, ok) = fuzz("manifest", &seeds, |bytes| {
        std::fs::write(dir.path().join("dataset.json"), bytes).unwrap();
        Manifest::read(dir.path()).is_ok()
    });
    assert!(ok > 0 && ok < n, "{ok} of {n}");
    assert_memory_bounded("manifest");
}

#[test]
fn experiment_requests_and_files() {
    in_own_process(
        "fuzz_parsers::experiment_requests_and_files",
        experiment_requests_and_files_alone,
    );
}

fn experiment_requests_and_files_alone() {
    let limits = BenchLimits {
        target_field_mm: Some((-75.0, -68.0, 75.0, 68.0)),
        travel_x_mm: Some((-25.0, 25.0)),
        travel_y_mm: Some((-25.0, 25.0)),
        stage_resolution_mm: None,
        ..BenchLimits::analysis_only(26.0)
    };
    let json_seeds: Vec<Vec<u8>> = [
        "{}",
        r#"{"name":"x","patterns":["a",{"label":"z","dot_diameter_mm":0.3,"dot_spacing_mm":0.5,"contrast":0.8}],
            "moves":[{"id":"m","dx_mm":1.0,"dy_mm":-0.5}],
            "step_series":[{"id":"s","dx_step_mm":0.002,"count":5}],
            "static_frames":2,"repeats":3,"new_layout_per_repeat":true,"frames_averaged":4,
            "settle_ms":10,"exposure_us":5000.0,
            "schemes":["ff50",{"name":"c","x":{"block":3,"first":1,"active":1},"y":{"block":3,"first":0,"active":3}}],
            "dic":{"subset_px":31,"step_px":10,"strain_window":5},"seed":7}"#,
    ]
    .iter()
    .map(|s| s.as_bytes().to_vec())
    .collect();
    let (n, ok) = fuzz("experiment request", &json_seeds, |bytes| {
        serde_json::from_slice::<ExperimentRequest>(bytes)
            .ok()
            .is_some_and(|r| r.plan(&limits).is_ok())
    });
    assert!(ok > 0 && ok < n, "{ok} of {n}");
    let toml_seeds = vec![PAPER_TOML.as_bytes().to_vec()];
    fuzz("experiment file", &toml_seeds, |bytes| {
        std::str::from_utf8(bytes)
            .ok()
            .is_some_and(|t| ExperimentSpec::from_toml(t, Path::new("fuzz.toml")).is_ok())
    });
    assert_memory_bounded("experiment");
}

#[test]
fn model_files() {
    in_own_process("fuzz_parsers::model_files", model_files_alone);
}

fn model_files_alone() {
    let models = Path::new(env!("CARGO_MANIFEST_DIR")).join("config/models");
    let seeds: Vec<Vec<u8>> = std::fs::read_dir(&models)
        .unwrap()
        .flatten()
        .filter(|e| e.path().extension().is_some_and(|x| x == "toml"))
        .map(|e| std::fs::read(e.path()).unwrap())
        .collect();
    assert!(!seeds.is_empty());
    let (n, ok) = fuzz("model file", &seeds, |bytes| {
        std::str::from_utf8(bytes)
            .ok()
            .is_some_and(|t| ModelConfig::from_toml(t, Path::new("fuzz.toml")).is_ok())
    });
    assert!(ok < n, "{ok} of {n}");
    assert_memory_bounded("model");
}
