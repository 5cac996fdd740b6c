//! Every integration test of the `ffdic` crate, one module per file, in one test binary.
//!
//! One binary instead of one per file (Cargo's default, `autotests = false` in Cargo.toml): the
//! crate and its dependencies link once instead of 35 times, the helpers in `common/` compile
//! once, and libtest spreads every test over the cores instead of running the files one after
//! another. A file's tests are named by its module: `cargo test --test integration store::`
//! runs `tests/store.rs`, `cargo test --test integration exec_camera_bench::` the exec camera's.

/// The binary's allocator (src/main.rs says why): the diagnosis tests are most of the suite.
#[global_allocator]
static GLOBAL: mimalloc::MiMalloc = mimalloc::MiMalloc;

mod common;

mod analysis_memo;
mod api_bounded;
mod api_dashboard;
mod api_deletion;
mod api_experiments;
mod api_models;
mod api_process;
mod api_robustness;
mod api_stage_unplugged;
mod api_sweeps;
mod aravis_fake_camera;
mod architecture;
mod browser_cross_origin;
mod build_sharing;
mod cli_analyze;
mod cli_calibrate;
mod cli_diagnose_on_bench;
mod cli_image_formats;
mod compare_foreign;
mod dashboard_browser;
mod dashboard_formatting;
mod dataset_init;
mod dic_deformation;
mod dic_sample3;
mod dic_synthetic;
mod disk_full;
mod exec_camera_aperture;
mod exec_camera_bench;
mod exec_camera_perpendicularity;
mod fuzz_parsers;
mod hidden_effect;
mod independent_diagnosis;
mod mock_bench;
mod model;
mod open_world_diagnosis;
mod paper_findings;
mod print_random_error;
mod properties;
mod store;
mod store_removal;
mod study;
mod sweep;
mod sweep_slurm;
