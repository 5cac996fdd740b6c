//! Mock hardware that behaves like the real thing: a stage that takes time to travel and settle
//! and must be homed after power-up, and a camera that renders — through whatever [`Scene`] the
//! caller plugs in — what the sensor sees at the stage's position at the moment of exposure.
//! Faults are injectable. Depends on `ffdic-hw` only: the root crate wires the model in as a Scene.
//! [`serial_sim`] serves simulated serial stage controllers (SMC100, Zaber, APT) on a pty.

mod bench;
mod camera;
pub mod serial_sim;
mod stage;

pub use bench::{new_bench, BenchState, Motion, SharedBench};
pub use camera::{output_size, CameraFaults, MockCamera, Scene};
pub use serial_sim::{SimConfig, SimFaults, SimProtocol, StageSim};
pub use stage::{MockStage, StageFaults};
