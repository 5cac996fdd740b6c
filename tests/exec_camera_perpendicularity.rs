//! The perpendicularity check (issue 33's live setup aid) against the independent generator's
//! hidden tilt, through the `exec` camera on the paper's bench (2560x2160 at 26 px/mm, the
//! working distance stated): a move back and forth along x, the tilt read from the two fields
//! within 0.05° for tilts of 0.2–2°, and nothing heavy kept.

use crate::common::daemon;
use crate::exec_camera_bench::{config_sized, frame_command};

use ffdic::diagnose::PerpendicularityReading;
use ffdic::experiment::PerpendicularityCheck;
use ffdic::service::job::PerpendicularityJob;
use ffdic::service::{open_bench, JobResult, Service};
use serde_json::{json, Value};
use std::path::Path;
use std::time::{Duration, Instant};

const SCALE_PX_PER_MM: f64 = 26.0;
const WORKING_DISTANCE_MM: f64 = 300.0;
/// The generator's stage: turned 4 mrad, landing within 1 µm (one σ).
const STAGE_RAD: f64 = 0.004;
const REPEATABILITY_MM: f64 = 0.001;

/// The paper's bench in the generator, its print `a` the paper's (0.2 mm dots, 0.3 mm apart),
/// the target tilted by (θx, θy) rad at the stated working distance.
fn tilted_bench(seed: u64, (theta_x, theta_y): (f64, f64)) -> Value {
    json!({
        "name": "perpendicularity", "seed": seed,
        "width": 2560, "height": 2160, "scale_px_per_mm": SCALE_PX_PER_MM, "bit_depth": 16,
        "white_level_dn": 30000.0, "gain_e_per_dn": 0.5, "read_noise_dn": 20.0,
        "patterns": [{"label": "a", "profile": "gaussian", "dot_diameter_mm": 0.2, "dot_spacing_mm": 0.3, "contrast": 0.5}],
        "moves": [], "step_series": [], "repeats": 1,
        "frame_travel_mm": [-5.0, 5.0, -5.0, 5.0],
        "working_distance_mm": WORKING_DISTANCE_MM, "state_working_distance": true,
        "stage": {"misalign_rad": STAGE_RAD, "repeatability_um": REPEATABILITY_MM * 1000.0},
        "effects": {"tilt_about_x_rad": theta_x, "tilt_about_y_rad": theta_y}
    })
}

/// One check on `service`: its reading, and what its run's folder kept.
fn check(service: &Service) -> (PerpendicularityReading, Vec<String>) {
    let job = PerpendicularityJob::plan(service, PerpendicularityCheck::default()).unwrap();
    let (record, _) = service.submit(job, None).unwrap();
    let record = daemon::succeeded(service, &record.id);
    let Some(JobResult::Perpendicularity(reading)) = service.jobs.take_result(&record.id) else {
        panic!("a perpendicularity check's result");
    };
    let dir = service.store.run_dir(&record.id);
    let mut kept: Vec<String> = walk(&dir)
        .into_iter()
        .map(|p| p.strip_prefix(&dir).unwrap().display().to_string())
        .collect();
    kept.sort();
    (*reading, kept)
}

fn walk(dir: &Path) -> Vec<std::path::PathBuf> {
    let mut out = Vec::new();
    for entry in std::fs::read_dir(dir).unwrap() {
        let path = entry.unwrap().path();
        if path.is_dir() {
            out.extend(walk(&path));
        } else {
            out.push(path);
        }
    }
    out
}

#[test]
fn the_check_reads_the_generators_hidden_tilt_within_five_hundredths_of_a_degree() {
    let root = tempfile::tempdir().unwrap();
    let deg = f64::to_radians;
    let cases = [(0.0, deg(0.2)), (deg(2.0), 0.0), (deg(0.6), deg(-1.0))];
    let command = frame_command(&tilted_bench(4401, cases[0]), root.path());
    let mut config = config_sized(
        &root.path().join("data"),
        &command,
        (2560, 2160),
        SCALE_PX_PER_MM,
    );
    config.bench.working_distance_mm = Some(WORKING_DISTANCE_MM);
    let (service, _) = Service::start(config.clone(), open_bench(&config).unwrap()).unwrap();
    service.jobs.keep_results();
    let tolerance = deg(0.05);
    for (k, tilt) in cases.into_iter().enumerate() {
        // The camera's command reads its spec at every frame: the next bench, the same daemon.
        frame_command(&tilted_bench(4401 + k as u64, tilt), root.path());
        let started = Instant::now();
        let (r, kept) = check(&service);
        eprintln!(
            "hidden tilt (x, y) ({:.4}°, {:.4}°): read ({:.4} ± {:.4}°, {:.4} ± {:.4}°), stage {:.6} ± {:.6} rad (truth {STAGE_RAD}), {} points, {:.4} px about the fit, {:.1} s",
            tilt.0.to_degrees(), tilt.1.to_degrees(),
            r.tilt_about_x_rad.to_degrees(), r.tilt_about_x_se_rad.to_degrees(),
            r.tilt_about_y_rad.to_degrees(), r.tilt_about_y_se_rad.to_degrees(),
            r.stage_angle_rad, r.stage_angle_se_rad, r.points, r.residual_px,
            started.elapsed().as_secs_f64()
        );
        assert!(
            (r.tilt_about_x_rad - tilt.0).abs() < tolerance
                && (r.tilt_about_y_rad - tilt.1).abs() < tolerance,
            "hidden {tilt:?} rad, read ({}, {}) rad",
            r.tilt_about_x_rad,
            r.tilt_about_y_rad
        );
        assert!(r.significant && r.working_distance_stated, "{r:?}");
        // One landing per run: the stage's 1 µm scatter over the 2 x 4.62 mm stroke bounds
        // the angle beside the DIC's own error.
        let landing_rad = std::f64::consts::SQRT_2 * REPEATABILITY_MM / (2.0 * 4.62);
        assert!(
            (r.stage_angle_rad - STAGE_RAD).abs() < 3.0 * (r.stage_angle_se_rad + landing_rad),
            "stage {} ± {} rad against {STAGE_RAD}",
            r.stage_angle_rad,
            r.stage_angle_se_rad
        );
        // A setup aid pressed again and again keeps its reading, not its frames nor a study.
        assert!(
            kept.iter()
                .all(|f| !f.starts_with("frames") && !f.starts_with("plots"))
                && kept.contains(&"results/perpendicularity.json".to_string()),
            "{kept:?}"
        );
    }
    assert!(
        service.store.list_datasets().unwrap().is_empty(),
        "a check registers no dataset"
    );
    service.stop(Duration::from_secs(5));
}

/// A camera that fails on the check's third frame (the move to −x): the check fails with the
/// camera's words and keeps none of the frames it had; the next check, on a camera that works
/// again, reads.
#[test]
fn a_check_whose_camera_fails_keeps_no_frames_and_the_next_one_reads() {
    let root = tempfile::tempdir().unwrap();
    let spec = json!({
        "name": "failing", "seed": 4411,
        "width": 640, "height": 540, "scale_px_per_mm": 13.0, "bit_depth": 16,
        "white_level_dn": 30000.0, "read_noise_dn": 20.0,
        "patterns": [{"label": "a", "dot_diameter_mm": 0.3, "dot_spacing_mm": 0.45, "contrast": 0.7}],
        "moves": [], "step_series": [], "repeats": 1,
        "frame_travel_mm": [-5.0, 5.0, -5.0, 5.0],
        "effects": {"tilt_about_y_rad": 0.01}
    });
    let generator = frame_command(&spec, root.path());
    let flag = root.path().join("fail");
    std::fs::write(&flag, "").unwrap();
    let command: Vec<String> = vec![
        "sh".into(),
        "-c".into(),
        format!(
            "if [ -e '{}' ] && [ \"$FFDIC_FRAME\" -ge 2 ]; then echo 'lamp failed' >&2; exit 2; fi; exec \"$@\"",
            flag.display()
        ),
        "camera".into(),
    ]
    .into_iter()
    .chain(generator)
    .collect();
    let config = config_sized(&root.path().join("data"), &command, (640, 540), 13.0);
    let (service, _) = Service::start(config.clone(), open_bench(&config).unwrap()).unwrap();
    service.jobs.keep_results();
    let job = PerpendicularityJob::plan(&service, PerpendicularityCheck::default()).unwrap();
    let (record, _) = service.submit(job, None).unwrap();
    let record = daemon::ended(&service, &record.id);
    assert_eq!(record.status, ffdic::store::RunStatus::Failed, "{record:?}");
    assert!(record.message.contains("lamp failed"), "{}", record.message);
    let dir = service.store.run_dir(&record.id);
    assert!(!dir.join("frames").exists() && !dir.join("results/perpendicularity.json").exists());
    std::fs::remove_file(&flag).unwrap();
    let (reading, _) = check(&service);
    assert!(
        reading.significant && !reading.working_distance_stated,
        "{reading:?}"
    );
    service.stop(Duration::from_secs(5));
}
