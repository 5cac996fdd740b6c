//! Experiments: a spec (patterns, moves, schemes, DIC settings), the bench actor that owns the
//! hardware, the runner that captures and analyses, simulated frames, the exported dataset, and
//! the fill-factor study run on it.

mod bench;
mod calibration_plan;
mod captures;
mod findings;
mod limits;
mod model_scene;
mod pool;
mod request;
mod runner;
mod simulate;
mod spec;
mod study;
mod study_files;

pub use bench::{
    BenchError, BenchHandle, BenchHardware, BenchLease, BenchStatus, CameraStatus, Owner,
    StageStatus, TargetMount,
};
pub use calibration_plan::{
    CalibrationPlan, PlanError, DEFAULT_LARGE_MOVE_FIELD_FRACTION, DEFAULT_MOVE_SIZE_RATIO,
};
pub use captures::{capture_plan, layout_seed, CaptureRun, TargetCapture};
pub use findings::{findings_text, paper_findings, Finding, Verdict};
pub use limits::{
    BenchLimits, OutOfTravel, StageAxis, DOT_DIAMETER_PX, EXPOSURE_US, MIN_DOT_SPACING_PX,
};
pub use model_scene::ModelScene;
pub use pool::pool_captures;
pub use request::{
    check_dic, check_run_name, check_schemes, is_hardware_scheme_name, ExperimentPlan,
    ExperimentRequest, FieldError, SchemeSpec, MAX_FRAMES_AVERAGED, MAX_MOVES, MAX_PATTERNS,
    MAX_REPEATS, MAX_RUN_NAME_CHARS, MAX_SCHEMES, MAX_SETTLE_MS, MAX_STATIC_FRAMES,
};
pub use runner::{
    run_experiment, BenchGeometry, BenchTimeouts, ExperimentOutcome, RunSink, RunnerError,
};
pub use simulate::{pattern_dots, render_stage_frame, simulate_dataset, SimulateError};
pub use spec::{ExperimentSpec, MoveSpec, PatternSpec, SpecError, StepSeries, PAPER_TOML};
pub use study::{
    analyze_dataset, analyze_dataset_with, Increase, ResultHook, StudyError, StudyRow,
};
pub use study_files::study_files;
