//! The on-disk measurement format `ffdic-dataset/1` (`docs/dataset-format.md`, its JSON Schema
//! beside it): a folder with `dataset.json` and grayscale TIFF frames at the camera's native
//! resolution. Experiments export it; `compare` and `diagnose` read it, whoever made it. Unknown
//! fields are kept and ignored; every mistake is named, all at once.

mod capture;
mod frame_check;
mod init;
mod manifest;
mod manifest_schema;
mod merge;
mod move_check;

pub use capture::sensor_readout;
pub use frame_check::{
    check_frames, check_pair, CheckedFrames, FrameCheckError, FrameLimits, PairCheck,
};
pub use init::{guess_reference, init_folder, FolderInit, Step, StepSeries};
pub use manifest::{
    is_plain_file_name, CameraInfo, DatasetError, DotProfile, Manifest, PatternInfo, Run,
    StageMove, FORMAT, MAX_EDGE_SOFTNESS_PX, MAX_PRINT_FEATURE_PX,
};
pub use manifest_schema::{schema_problems, SCHEMA_JSON};
pub use merge::merge_datasets;
pub use move_check::{
    check_stated_move, measure_move, MeasuredMove, MoveContradiction, MAX_RATIO, MAX_VECTOR_ERROR,
    MIN_DIFFERENCE_PX, MIN_NCC,
};
