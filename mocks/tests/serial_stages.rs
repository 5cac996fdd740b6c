//! Each serial stage driver against its simulator over a real pseudo-terminal: homing, moves,
//! refusals, stop, limit switch, and the faults the daemon must survive (silence, noise, a pulled
//! cable). The Zaber simulator is also driven by the independent `zproto` client.

use ffdic_hw::{HwError, Stage, StagePosition};
use ffdic_mocks::{new_bench, SimConfig, SimFaults, SimProtocol, StageSim};
use ffdic_stage::{
    open_stage, AptConfig, AptStage, Smc100Config, Smc100Stage, StageConfig, ZaberConfig,
    ZaberStage,
};
use std::time::{Duration, Instant};

/// Fast travel keeps the file quick; 100 mm/s still leaves ~80 ms to stop a long move.
const SPEED_MM_PER_S: f64 = 100.0;
const REPLY_TIMEOUT_MS: u64 = 150;
const WAIT: Duration = Duration::from_secs(2);
/// The brief: position within 1 µm of the target.
const TOLERANCE_MM: f64 = 1e-3;

fn sim_config(protocol: SimProtocol, two_axes: bool) -> SimConfig {
    let mut c = SimConfig::new(protocol);
    c.speed_mm_per_s = SPEED_MM_PER_S;
    c.settle = Duration::from_millis(5);
    c.x_travel_mm = (0.0, 25.0);
    if two_axes {
        c.y_travel_mm = Some((0.0, 25.0));
    }
    if protocol == SimProtocol::Apt {
        // Frequent unprompted status updates, so they interleave with every reply.
        c.status_interval = Some(Duration::from_millis(2));
        if two_axes {
            (c.x_address, c.y_address) = (0x21, 0x22);
        }
    }
    c
}

fn smc100(sim: &StageSim) -> Smc100Stage {
    Smc100Stage::open(&Smc100Config {
        port: sim.path().into(),
        timeout_ms: REPLY_TIMEOUT_MS,
        y_address: Some(2),
        x_travel_mm: (0.0, 25.0),
        y_travel_mm: (0.0, 25.0),
        ..Smc100Config::default()
    })
    .expect("open SMC100")
}

fn zaber(sim: &StageSim) -> ZaberStage {
    ZaberStage::open(&ZaberConfig {
        port: sim.path().into(),
        timeout_ms: REPLY_TIMEOUT_MS,
        ..ZaberConfig::default()
    })
    .expect("open Zaber")
}

fn apt(sim: &StageSim) -> AptStage {
    AptStage::open(&AptConfig {
        port: sim.path().into(),
        timeout_ms: REPLY_TIMEOUT_MS,
        x_address: 0x21,
        y_address: Some(0x22),
        ..AptConfig::default()
    })
    .expect("open APT")
}

fn at(x_mm: f64, y_mm: f64) -> StagePosition {
    StagePosition { x_mm, y_mm }
}

fn assert_near(p: StagePosition, x_mm: f64, y_mm: f64, what: &str) {
    assert!(
        (p.x_mm - x_mm).abs() < TOLERANCE_MM && (p.y_mm - y_mm).abs() < TOLERANCE_MM,
        "{what}: at {p:?}, expected ({x_mm}, {y_mm})"
    );
}

/// Whether `cond` holds within `limit`, checked every millisecond.
fn eventually(limit: Duration, cond: impl Fn() -> bool) -> bool {
    let t0 = Instant::now();
    while t0.elapsed() < limit {
        if cond() {
            return true;
        }
        std::thread::sleep(Duration::from_millis(1));
    }
    cond()
}

/// Home, moves, refusals, stop and limit switch: the same story for every protocol.
fn exercise_motion(stage: &mut dyn Stage, sim: &StageSim) {
    let two = stage.info().axes == 2;
    let y = |v: f64| if two { v } else { 0.0 };

    // Power-up: not referenced, so moves are refused with a clear message.
    match stage.move_absolute(at(1.0, y(1.0))) {
        Err(HwError::NotReferenced(m)) => assert!(m.contains("home first"), "{m}"),
        other => panic!("move before homing: {other:?}"),
    }
    assert!(!sim.busy(), "the refused move must not have started");

    stage.home(WAIT).unwrap();
    assert!(sim.homed());
    assert_near(stage.position().unwrap(), 0.0, 0.0, "after homing");

    stage.move_absolute(at(5.25, y(2.5))).unwrap();
    // APT moves have no reply: the simulator may see the command a moment after it was sent.
    assert!(
        eventually(Duration::from_millis(30), || sim.busy()),
        "the move must take time"
    );
    let p = stage.wait_settled(WAIT).unwrap();
    assert_near(p, 5.25, y(2.5), "move absolute");
    let (sx, sy) = sim.position_mm();
    assert_near(
        at(sx, sy),
        5.25,
        y(2.5),
        "simulated stage after move absolute",
    );

    stage.move_relative(-1.125, y(0.75)).unwrap();
    let p = stage.wait_settled(WAIT).unwrap();
    assert_near(p, 4.125, y(3.25), "move relative");

    match stage.move_absolute(at(25.5, y(3.25))) {
        // The maximum may be the device's limit, rounded to whole microsteps or counts.
        Err(HwError::OutOfRange { value, max, .. }) => {
            assert!(
                value == 25.5 && (max - 25.0).abs() < TOLERANCE_MM,
                "{value} {max}"
            )
        }
        other => panic!("move beyond travel: {other:?}"),
    }
    assert!(stage.move_relative(-5.0, 0.0).is_err(), "below the travel");
    assert!(!sim.busy());

    // Stop mid-move: 4.125 → 20 mm takes ~160 ms at 100 mm/s.
    stage.move_absolute(at(20.0, y(3.25))).unwrap();
    std::thread::sleep(Duration::from_millis(30));
    stage.stop().unwrap();
    let p = stage.wait_settled(WAIT).unwrap();
    assert!(
        p.x_mm > 4.125 + 0.5 && p.x_mm < 20.0 - 0.5,
        "stopped mid-way: {p:?}"
    );
    let (sx, _) = sim.position_mm();
    assert!(
        (sx - p.x_mm).abs() < TOLERANCE_MM,
        "driver {p:?} vs sim {sx}"
    );

    // A limit switch at 15 mm stops a move to 18 mm: wait_settled reports it.
    sim.set_faults(SimFaults {
        x_limit_switch_mm: Some(15.0),
        ..SimFaults::default()
    });
    stage.move_absolute(at(18.0, y(3.25))).unwrap();
    match stage.wait_settled(WAIT) {
        Err(HwError::Protocol(m)) => assert!(m.contains("limit switch"), "{m}"),
        other => panic!("limit switch: {other:?}"),
    }
    assert!((sim.position_mm().0 - 15.0).abs() < TOLERANCE_MM);
    sim.set_faults(SimFaults::default());
    stage.move_absolute(at(10.0, y(3.25))).unwrap();
    assert_near(
        stage.wait_settled(WAIT).unwrap(),
        10.0,
        y(3.25),
        "after limit",
    );
}

/// Silence, noise and a pulled cable give typed errors, never a hang or a panic.
fn exercise_faults(stage: &mut dyn Stage, sim: &mut StageSim) {
    sim.set_faults(SimFaults {
        silent: true,
        ..SimFaults::default()
    });
    let t0 = Instant::now();
    let r = stage.position();
    let elapsed = t0.elapsed();
    assert!(matches!(r, Err(HwError::Timeout { .. })), "{r:?}");
    assert!(
        elapsed >= Duration::from_millis(REPLY_TIMEOUT_MS - 10)
            && elapsed < Duration::from_millis(REPLY_TIMEOUT_MS + 250),
        "timed out after {elapsed:?}"
    );
    sim.set_faults(SimFaults::default());
    stage.position().expect("answers again after the silence");

    sim.set_faults(SimFaults {
        garbage: true,
        ..SimFaults::default()
    });
    let r = stage.position();
    assert!(matches!(r, Err(HwError::Protocol(_))), "{r:?}");
    sim.set_faults(SimFaults::default());
    stage.position().expect("answers again after the noise");

    sim.disconnect();
    let r = stage.position();
    assert!(matches!(r, Err(HwError::Disconnected(_))), "{r:?}");
    let r = stage.move_absolute(at(1.0, 0.0));
    assert!(matches!(r, Err(HwError::Disconnected(_))), "{r:?}");
}

#[test]
fn smc100_two_axes_over_a_pty() {
    let mut sim = StageSim::spawn(sim_config(SimProtocol::Smc100, true), None).unwrap();
    let mut stage = smc100(&sim);
    assert_eq!(stage.info().axes, 2);
    assert!(
        stage.info().model.contains("SMC100"),
        "{}",
        stage.info().model
    );
    exercise_motion(&mut stage, &sim);
    exercise_faults(&mut stage, &mut sim);
}

#[test]
fn zaber_one_axis_over_a_pty() {
    let mut sim = StageSim::spawn(sim_config(SimProtocol::Zaber, false), None).unwrap();
    let mut stage = zaber(&sim);
    assert_eq!(stage.info().axes, 1);
    let (lo, hi) = stage.info().travel_x_mm;
    assert!(
        lo == 0.0 && (hi - 25.0).abs() < 1e-4,
        "narrowed to the device's limit.max"
    );
    exercise_motion(&mut stage, &sim);
    exercise_faults(&mut stage, &mut sim);
}

#[test]
fn apt_two_bays_with_unprompted_status_updates() {
    let mut sim = StageSim::spawn(sim_config(SimProtocol::Apt, true), None).unwrap();
    let mut stage = apt(&sim);
    exercise_motion(&mut stage, &sim);
    // The motion story ran with status updates arriving every 2 ms between the replies.
    assert!(
        sim.unprompted_sent() > 50,
        "only {} unprompted updates: the interleaving was not exercised",
        sim.unprompted_sent()
    );
    exercise_faults(&mut stage, &mut sim);
}

#[test]
fn open_stage_picks_the_protocol_from_toml() {
    let sim = StageSim::spawn(sim_config(SimProtocol::Zaber, false), None).unwrap();
    let config: StageConfig = toml::from_str(&format!(
        "protocol = \"zaber\"\nport = \"{}\"\ntimeout_ms = {REPLY_TIMEOUT_MS}",
        sim.path()
    ))
    .unwrap();
    let mut stage = open_stage(&config).unwrap();
    stage.home(WAIT).unwrap();
    stage.move_absolute(at(2.0, 0.0)).unwrap();
    assert_near(
        stage.wait_settled(WAIT).unwrap(),
        2.0,
        0.0,
        "via open_stage",
    );
}

/// Issue 36 (7): a port that was pulled was never opened again. Here the configured path is a
/// link (as udev's /dev/serial/by-id names are) that a second simulator takes over.
#[test]
fn a_pulled_port_is_opened_again_once_it_is_back() {
    let dir = std::env::temp_dir().join(format!("ffdic-reopen-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let link = dir.join("stage-port");
    let _ = std::fs::remove_file(&link);
    let mut first = StageSim::spawn(sim_config(SimProtocol::Zaber, false), None).unwrap();
    std::os::unix::fs::symlink(first.path(), &link).unwrap();
    let config = StageConfig::Zaber(ZaberConfig {
        port: link.display().to_string(),
        timeout_ms: REPLY_TIMEOUT_MS,
        ..ZaberConfig::default()
    });
    let mut stage = open_stage(&config).unwrap();
    stage.home(WAIT).unwrap();
    assert!(stage.position().is_ok());
    first.disconnect();
    // Gone: every call says so, and trying again does not hang.
    for _ in 0..2 {
        let r = stage.position();
        assert!(matches!(r, Err(HwError::Disconnected(_))), "{r:?}");
    }
    // Plugged in again (a new pty behind the same name): the next call reopens it.
    let second = StageSim::spawn(sim_config(SimProtocol::Zaber, false), None).unwrap();
    std::fs::remove_file(&link).unwrap();
    std::os::unix::fs::symlink(second.path(), &link).unwrap();
    stage.home(WAIT).unwrap();
    stage.move_absolute(at(3.0, 0.0)).unwrap();
    assert_near(
        stage.wait_settled(WAIT).unwrap(),
        3.0,
        0.0,
        "after reopening",
    );
    assert!((second.position_mm().0 - 3.0).abs() < TOLERANCE_MM);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn opening_a_missing_port_or_a_silent_controller_fails_typed() {
    let missing = StageConfig::Smc100(Smc100Config {
        port: "/dev/ffdic-no-such-port".into(),
        ..Smc100Config::default()
    });
    assert!(matches!(
        open_stage(&missing).err(),
        Some(HwError::Disconnected(_))
    ));
    let sim = StageSim::spawn(sim_config(SimProtocol::Apt, false), None).unwrap();
    sim.set_faults(SimFaults {
        silent: true,
        ..SimFaults::default()
    });
    let silent = StageConfig::Apt(AptConfig {
        port: sim.path().into(),
        timeout_ms: 50,
        ..AptConfig::default()
    });
    assert!(matches!(
        open_stage(&silent).err(),
        Some(HwError::Timeout { .. })
    ));
}

#[test]
fn simulator_moves_the_shared_bench() {
    let bench = new_bench();
    bench.lock().unwrap().resting = at(1.5, 0.0);
    let sim = StageSim::spawn(sim_config(SimProtocol::Smc100, false), Some(bench.clone())).unwrap();
    assert!(
        (sim.position_mm().0 - 1.5).abs() < 1e-12,
        "starts where the bench is"
    );
    let mut stage = Smc100Stage::open(&Smc100Config {
        port: sim.path().into(),
        timeout_ms: REPLY_TIMEOUT_MS,
        x_travel_mm: (0.0, 25.0),
        ..Smc100Config::default()
    })
    .unwrap();
    stage.home(WAIT).unwrap();
    stage.move_absolute(at(6.0, 0.0)).unwrap();
    std::thread::sleep(Duration::from_millis(20));
    let mid = bench.lock().unwrap().position_at(Instant::now());
    assert!(mid.x_mm > 0.2 && mid.x_mm < 5.8, "bench mid-move: {mid:?}");
    stage.wait_settled(WAIT).unwrap();
    let end = bench.lock().unwrap().position_at(Instant::now());
    assert!(
        (end.x_mm - 6.0).abs() < TOLERANCE_MM,
        "bench at rest: {end:?}"
    );
}

/// The Zaber simulator speaks the real protocol: an independent client homes, moves and reads it.
#[test]
fn zproto_drives_the_zaber_simulator() {
    use zproto::ascii::{response::check, Port};
    let config = sim_config(SimProtocol::Zaber, false);
    let microsteps_per_mm = config.units_per_mm;
    let sim = StageSim::spawn(config, None).unwrap();
    let mut port = Port::open_serial(sim.path()).expect("zproto opens the pty");
    let reply = port.command_reply((1, 1, "")).unwrap().flag_ok().unwrap();
    assert_eq!(reply.warning().to_string(), "WR", "not homed at power-up");
    port.command_reply((1, 1, "home"))
        .unwrap()
        .flag_ok()
        .unwrap();
    port.poll_until_idle((1, 1), check::flag_ok()).unwrap();
    assert!(sim.homed());
    port.command_reply((1, 1, "move abs 100000"))
        .unwrap()
        .flag_ok()
        .unwrap();
    port.poll_until_idle((1, 1), check::flag_ok()).unwrap();
    let reply = port
        .command_reply((1, 1, "get pos"))
        .unwrap()
        .flag_ok()
        .unwrap();
    assert_eq!(reply.data(), "100000");
    let expected_mm = 100_000.0 / microsteps_per_mm;
    assert!((sim.position_mm().0 - expected_mm).abs() < TOLERANCE_MM);
    let rejected = port.command_reply((1, 1, "move abs 99999999")).unwrap();
    assert!(rejected.flag_ok().is_err(), "beyond travel is rejected");
}
