//! Experiments: a spec (patterns, moves, schemes, DIC settings) and the request the daemon takes,
//! the calibration plan, the runner that captures on the bench and analyses, and simulated
//! frames. The bench itself is `bench/`; the study the runner runs is `study/`.

mod calibration_plan;
mod captures;
mod perpendicularity_check;
mod request;
mod runner;
mod simulate;
mod spec;

pub use calibration_plan::{
    CalibrationPlan, PlanError, DEFAULT_LARGE_MOVE_FIELD_FRACTION, DEFAULT_MOVE_SIZE_RATIO,
};
pub use captures::{capture_plan, layout_seed, CaptureRun, TargetCapture};
pub use perpendicularity_check::PerpendicularityCheck;
pub(crate) use request::field_error;
pub use request::{
    check_dic, check_run_name, check_schemes, is_hardware_scheme_name, ExperimentPlan,
    ExperimentRequest, FieldError, SchemeSpec, MAX_FRAMES_AVERAGED, MAX_MOVES, MAX_PATTERNS,
    MAX_REPEATS, MAX_RUN_NAME_CHARS, MAX_SCHEMES, MAX_SETTLE_MS, MAX_STATIC_FRAMES,
};
pub use runner::{
    capture_experiment, run_experiment, BenchGeometry, BenchTimeouts, ExperimentOutcome, RunSink,
    RunnerError,
};
pub use simulate::{pattern_dots, render_stage_frame, simulate_dataset, SimulateError};
pub use spec::{ExperimentSpec, MoveSpec, PatternSpec, SpecError, StepSeries, PAPER_TOML};
