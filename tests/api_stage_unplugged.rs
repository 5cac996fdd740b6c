//! Issue 36 (7): `/health` said `ok` while the stage was unplugged and `GET /stage` kept
//! `homed: true`. A stage whose cable can be pulled and put back, under the daemon.

use crate::common::daemon;

use daemon::{get, post, small_bench, small_config, TestServer};
use ffdic_hw::{HwError, HwResult, Stage, StageInfo, StagePosition};
use serde_json::{json, Value};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Duration;

/// The mock stage behind a cable: unplugged, every call is `Disconnected`, as a driver whose
/// port is gone answers.
struct Cabled {
    stage: Box<dyn Stage>,
    plugged: Arc<AtomicBool>,
}

impl Cabled {
    fn check(&self) -> HwResult<()> {
        if self.plugged.load(Ordering::SeqCst) {
            Ok(())
        } else {
            Err(HwError::Disconnected("the cable is out".into()))
        }
    }
}

impl Stage for Cabled {
    fn info(&self) -> &StageInfo {
        self.stage.info()
    }
    fn home(&mut self, timeout: Duration) -> HwResult<()> {
        self.check()?;
        self.stage.home(timeout)
    }
    fn move_absolute(&mut self, target: StagePosition) -> HwResult<()> {
        self.check()?;
        self.stage.move_absolute(target)
    }
    fn position(&mut self) -> HwResult<StagePosition> {
        self.check()?;
        self.stage.position()
    }
    fn wait_settled(&mut self, timeout: Duration) -> HwResult<StagePosition> {
        self.check()?;
        self.stage.wait_settled(timeout)
    }
    fn stop(&mut self) -> HwResult<()> {
        self.check()?;
        self.stage.stop()
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_unplugged_stage_is_reported_unhomed_and_degraded_until_it_answers_again() {
    let tmp = tempfile::tempdir().unwrap();
    let config = small_config(tmp.path());
    let mut hardware = small_bench(&config);
    let plugged = Arc::new(AtomicBool::new(true));
    hardware.stage = hardware.stage.map(|stage| {
        Box::new(Cabled {
            stage,
            plugged: plugged.clone(),
        }) as Box<dyn Stage>
    });
    let server = TestServer::start_on(config, hardware).await;
    let health = || async { get(&server.url("/health")).await };
    let stage = || async { daemon::get_json::<Value>(&server.url("/stage")).await };
    let home_and_check = || async {
        let r = post(&server.url("/stage/moves"), &json!({"home": true})).await;
        assert_eq!(r.status(), 200);
        assert_eq!(stage().await["homed"], true);
    };

    home_and_check().await;
    assert_eq!(health().await.status(), 200);

    plugged.store(false, Ordering::SeqCst);
    let s = stage().await;
    assert_eq!(s["homed"], false, "{s}");
    assert!(s["error"].as_str().unwrap().contains("cable"), "{s}");
    let r = health().await;
    assert_eq!(r.status(), 503);
    let h: Value = r.json().await.unwrap();
    assert_eq!(h["status"], "degraded");
    assert_eq!(h["stopped"], json!(["stage"]), "{h}");
    let r = post(&server.url("/stage/moves"), &json!({"dx_mm": 1.0})).await;
    assert_eq!(r.status(), 503);

    // Back: healthy at its next answer, but it must be homed again.
    plugged.store(true, Ordering::SeqCst);
    let s = stage().await;
    assert_eq!(s["homed"], false, "{s}");
    assert!(s["position"].is_object(), "{s}");
    assert_eq!(health().await.status(), 200);
    home_and_check().await;
    server.stop().await;
}
