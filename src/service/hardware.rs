//! Opens the camera and the stage the configuration names and hands them to the bench actor.
//! The mock bench wires the imaging model in as the mock camera's scene, with a target changer
//! that swaps the speckle pattern in front of it.

use super::config::{
    load_bench_model, CameraConfig, ConfigError, DaemonConfig, MockReduction, StageConfig,
};
use crate::bench::{BenchHardware, ModelScene, TargetMount};
use crate::model::{Camera as ModelCamera, ModelConfig, SpecklePattern};
use ffdic_hw::{Camera, HardwareScheme, HwError, Stage, StagePosition};
use ffdic_mocks::{new_bench, MockCamera, MockStage, Scene, SharedBench};
use std::sync::{Arc, Mutex, RwLock};
use std::time::Duration;

#[derive(Debug, thiserror::Error)]
pub enum HardwareError {
    #[error(transparent)]
    Config(#[from] ConfigError),
    #[error("camera: {0}")]
    Camera(HwError),
    #[error("stage: {0}")]
    Stage(HwError),
    /// The mock camera's field of view is too large for a target layout.
    #[error("mock camera: {0}")]
    MockTarget(#[from] crate::model::TooManyDots),
    #[error("this ffdic was built without the `{0}` feature (cargo build --features {0})")]
    FeatureMissing(&'static str),
}

/// How far the mock target extends beyond the field of view on every side, mm: the stage's
/// travel, so every reachable position shows speckle.
const MOCK_TARGET_MARGIN_MM: f64 = 26.0;

/// The mock scene behind a lock, so the target changer can swap the pattern the camera sees.
#[derive(Clone)]
pub struct SwappableScene(Arc<RwLock<ModelScene>>);

impl Scene for SwappableScene {
    fn size(&self) -> (usize, usize) {
        self.0.read().expect("scene lock").size()
    }

    fn render(
        &self,
        p: StagePosition,
        exposure_us: f64,
        bit_depth: u8,
        index: u64,
        readout: Option<&HardwareScheme>,
    ) -> Vec<u16> {
        self.0
            .read()
            .expect("scene lock")
            .render(p, exposure_us, bit_depth, index, readout)
    }
}

struct MockTargets {
    scene: SwappableScene,
}

impl TargetMount for MockTargets {
    fn mount(&mut self, _label: &str, pattern: &SpecklePattern, seed: u64) -> Result<(), HwError> {
        let mut s = self.scene.0.write().expect("scene lock");
        let dots = pattern
            .dots(s.camera.field_mm(MOCK_TARGET_MARGIN_MM), seed)
            .map_err(|e| HwError::OutOfRange {
                what: format!("target {} dots", e.dots),
                value: pattern.dot_spacing_mm,
                min: e.min_spacing_mm,
                max: f64::INFINITY,
            })?;
        s.mount(dots, seed);
        Ok(())
    }

    fn field_mm(&self) -> (f64, f64, f64, f64) {
        let s = self.scene.0.read().expect("scene lock");
        s.camera.field_mm(MOCK_TARGET_MARGIN_MM)
    }
}

/// The mock bench: model geometry, the bench's truth, a stage and camera sharing one position.
pub fn mock_bench(
    geometry: ModelCamera,
    truth: ModelConfig,
    reduction: MockReduction,
    speed_mm_s: f64,
    settle: Duration,
) -> Result<BenchHardware, HardwareError> {
    let bench = new_bench();
    let (camera, targets) = mock_camera(geometry, truth, reduction, bench.clone())?;
    Ok(BenchHardware {
        camera,
        stage: Some(Box::new(MockStage::new(bench, speed_mm_s, settle))),
        targets: Some(targets),
    })
}

/// A camera and the target changer that swaps what it sees.
type MockCameraAndTargets = (Box<dyn Camera>, Box<dyn TargetMount>);

fn mock_camera(
    geometry: ModelCamera,
    truth: ModelConfig,
    reduction: MockReduction,
    bench: SharedBench,
) -> Result<MockCameraAndTargets, HardwareError> {
    let pattern = SpecklePattern::preset("b").expect("preset b exists");
    let scene = SwappableScene(Arc::new(RwLock::new(ModelScene::new(
        geometry,
        truth,
        &pattern,
        MOCK_TARGET_MARGIN_MM,
        1,
    )?)));
    Ok((
        Box::new(MockCamera::new(scene.clone(), bench).with_reduction(reduction.caps())),
        Box::new(MockTargets { scene }),
    ))
}

/// Opens what `config` names.
pub fn open_bench(config: &DaemonConfig) -> Result<BenchHardware, HardwareError> {
    let shared = new_bench();
    let (stage, position) = open_stage(config, shared.clone())?;
    let (camera, targets): (Box<dyn Camera>, Option<Box<dyn TargetMount>>) = match &config.camera {
        CameraConfig::Mock { bench_model, .. } => {
            let geometry = config.mock_geometry().expect("mock camera has a geometry");
            let reduction = config.mock_reduction().unwrap_or_default();
            let truth = load_bench_model(bench_model)?;
            let (c, t) = mock_camera(geometry, truth, reduction, shared)?;
            (c, Some(t))
        }
        CameraConfig::Aravis(aravis) => (open_aravis(aravis)?, None),
        CameraConfig::V4l2(v4l2) => (open_v4l2(v4l2)?, None),
        CameraConfig::Exec(exec) => {
            let (c, t) = open_exec(exec, config.bench.scale_px_per_mm, position)?;
            (c, Some(t))
        }
    };
    Ok(BenchHardware {
        camera,
        stage,
        targets,
    })
}

/// Where the stage is, for a camera that must know (the exec camera's command is told).
type PositionSource = Box<dyn Fn() -> StagePosition + Send>;

/// The stage `config` names, and a source of its position: the mock bench's shared state, or
/// what a real stage last reported ([`PositionTap`]).
fn open_stage(
    config: &DaemonConfig,
    shared: SharedBench,
) -> Result<(Option<Box<dyn Stage>>, PositionSource), HardwareError> {
    let stage: Option<Box<dyn Stage>> = match &config.stage {
        StageConfig::Mock {
            speed_mm_s,
            settle_ms,
        } => Some(Box::new(MockStage::new(
            shared.clone(),
            *speed_mm_s,
            Duration::from_millis(*settle_ms),
        ))),
        StageConfig::Smc100(c) => Some(open_serial_stage(ffdic_stage::StageConfig::Smc100(
            c.clone(),
        ))?),
        StageConfig::Zaber(c) => Some(open_serial_stage(ffdic_stage::StageConfig::Zaber(
            c.clone(),
        ))?),
        StageConfig::Apt(c) => Some(open_serial_stage(ffdic_stage::StageConfig::Apt(c.clone()))?),
        StageConfig::None => None,
    };
    Ok(match (stage, &config.stage) {
        (Some(s), StageConfig::Mock { .. }) => {
            let at = move || {
                shared
                    .lock()
                    .expect("bench lock")
                    .position_at(std::time::Instant::now())
            };
            (Some(s), Box::new(at))
        }
        (Some(s), _) => {
            let (tapped, at) = PositionTap::new(s);
            (Some(Box::new(tapped)), Box::new(at))
        }
        (None, _) => (None, Box::new(StagePosition::default)),
    })
}

/// A stage whose last known position (after a move settles, or when asked) others can read.
struct PositionTap {
    stage: Box<dyn Stage>,
    last: Arc<Mutex<StagePosition>>,
}

impl PositionTap {
    fn new(stage: Box<dyn Stage>) -> (Self, impl Fn() -> StagePosition + Send) {
        let last = Arc::new(Mutex::new(StagePosition::default()));
        let read = last.clone();
        (Self { stage, last }, move || {
            *read.lock().expect("position lock")
        })
    }

    fn seen(&self, p: StagePosition) -> StagePosition {
        *self.last.lock().expect("position lock") = p;
        p
    }
}

impl Stage for PositionTap {
    fn info(&self) -> &ffdic_hw::StageInfo {
        self.stage.info()
    }
    fn home(&mut self, timeout: Duration) -> Result<(), HwError> {
        self.stage.home(timeout)?;
        self.position().map(|_| ())
    }
    fn move_absolute(&mut self, target: StagePosition) -> Result<(), HwError> {
        self.stage.move_absolute(target)
    }
    fn move_relative(&mut self, dx_mm: f64, dy_mm: f64) -> Result<(), HwError> {
        self.stage.move_relative(dx_mm, dy_mm)
    }
    fn position(&mut self) -> Result<StagePosition, HwError> {
        let p = self.stage.position()?;
        Ok(self.seen(p))
    }
    fn wait_settled(&mut self, timeout: Duration) -> Result<StagePosition, HwError> {
        let p = self.stage.wait_settled(timeout)?;
        Ok(self.seen(p))
    }
    fn stop(&mut self) -> Result<(), HwError> {
        self.stage.stop()
    }
}

/// The exec camera (`ffdic_exec`) and its target changer: a mount tells the command which
/// target is in front of it.
fn open_exec(
    config: &ffdic_exec::ExecCameraConfig,
    scale_px_per_mm: f64,
    position: PositionSource,
) -> Result<MockCameraAndTargets, HardwareError> {
    let mount = ffdic_exec::SharedMount::default();
    let camera = ffdic_exec::ExecCamera::open(
        config.clone(),
        ffdic_exec::ExecBench {
            position,
            mount: mount.clone(),
        },
    )
    .map_err(HardwareError::Camera)?;
    let field = ModelCamera {
        width: config.width as usize,
        height: config.height as usize,
        scale_px_per_mm,
        exposure_level: 0.5,
        principal_dx_px: 0.0,
        principal_dy_px: 0.0,
    }
    .field_mm(MOCK_TARGET_MARGIN_MM);
    Ok((Box::new(camera), Box::new(ExecTargets { mount, field })))
}

/// Tells the exec camera's command which target is mounted (it renders or replays it).
struct ExecTargets {
    mount: ffdic_exec::SharedMount,
    /// The field of view plus the stage's travel, mm: what a pattern's layout must cover.
    field: (f64, f64, f64, f64),
}

impl TargetMount for ExecTargets {
    fn mount(&mut self, label: &str, _pattern: &SpecklePattern, _seed: u64) -> Result<(), HwError> {
        let mut m = self.mount.lock().expect("mount lock");
        m.label = label.to_string();
        m.generation += 1;
        Ok(())
    }

    fn field_mm(&self) -> (f64, f64, f64, f64) {
        self.field
    }
}

fn open_serial_stage(config: ffdic_stage::StageConfig) -> Result<Box<dyn Stage>, HardwareError> {
    ffdic_stage::open_stage(&config).map_err(HardwareError::Stage)
}

#[cfg(feature = "aravis")]
fn open_aravis(config: &ffdic_aravis::AravisConfig) -> Result<Box<dyn Camera>, HardwareError> {
    Ok(Box::new(
        ffdic_aravis::AravisCamera::open_with(config).map_err(HardwareError::Camera)?,
    ))
}

#[cfg(not(feature = "aravis"))]
fn open_aravis(_: &ffdic_aravis::AravisConfig) -> Result<Box<dyn Camera>, HardwareError> {
    Err(HardwareError::FeatureMissing("aravis"))
}

#[cfg(feature = "v4l2")]
fn open_v4l2(config: &ffdic_v4l2::V4l2Config) -> Result<Box<dyn Camera>, HardwareError> {
    Ok(Box::new(
        ffdic_v4l2::V4l2Camera::open(config).map_err(HardwareError::Camera)?,
    ))
}

#[cfg(not(feature = "v4l2"))]
fn open_v4l2(_: &ffdic_v4l2::V4l2Config) -> Result<Box<dyn Camera>, HardwareError> {
    Err(HardwareError::FeatureMissing("v4l2"))
}
