//! Experiments: a spec (patterns, moves, schemes, DIC settings), simulated or captured frames,
//! the exported dataset, and the fill-factor study run on it.

mod model_scene;
mod simulate;
mod spec;
mod study;

pub use model_scene::ModelScene;
pub use simulate::{
    derive_seed, pattern_dots, render_stage_frame, simulate_dataset, SimulateError,
};
pub use spec::{ExperimentSpec, MoveSpec, PatternSpec, SpecError, StepSeries, PAPER_TOML};
pub use study::{analyze_dataset, study_pair, Increase, StudyError, StudyRow};
