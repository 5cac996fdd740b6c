//! `ffdic sweep slurm` on a real single-node Slurm cluster (Debian's slurmctld, slurmd and
//! munge, started here on localhost with a minimal slurm.conf, its own munge key and socket,
//! and free ports): the smoke sweep runs as an array job plus a dependent merge job, and the
//! merged map equals a local run's. Needs root and the packages (the test command installs
//! them); it fails, naming what is missing, without them.

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

struct Cluster {
    dir: PathBuf,
    children: Vec<Child>,
}

impl Drop for Cluster {
    fn drop(&mut self) {
        for c in self.children.iter_mut().rev() {
            let _ = c.kill();
            let _ = c.wait();
        }
    }
}

fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
}

fn have(program: &str) -> bool {
    Command::new("sh")
        .args(["-c", &format!("command -v {program}")])
        .output()
        .is_ok_and(|o| o.status.success())
}

impl Cluster {
    fn conf(&self) -> PathBuf {
        self.dir.join("slurm.conf")
    }

    fn command(&self, program: &str) -> Command {
        let mut c = Command::new(program);
        c.env("SLURM_CONF", self.conf());
        c
    }

    fn start(dir: &Path) -> Cluster {
        for program in ["munged", "slurmctld", "slurmd", "sbatch", "sinfo", "squeue"] {
            assert!(
                have(program),
                "{program} missing: apt-get install slurmctld slurmd munge (scripts/test-all.sh does)"
            );
        }
        assert_eq!(
            unsafe { libc::geteuid() },
            0,
            "slurmd runs jobs as root here: run as root"
        );
        let dir = dir.to_owned();
        for sub in ["state", "spool"] {
            std::fs::create_dir_all(dir.join(sub)).unwrap();
        }
        let key = dir.join("munge.key");
        let random: Vec<u8> = (0..1024u32)
            .map(|i| (i.wrapping_mul(2_654_435_761) >> 13) as u8 ^ std::process::id() as u8)
            .collect();
        std::fs::write(&key, random).unwrap();
        use std::os::unix::fs::PermissionsExt;
        std::fs::set_permissions(&key, std::fs::Permissions::from_mode(0o600)).unwrap();
        let socket = dir.join("munge.sock");
        let host = String::from_utf8(Command::new("hostname").arg("-s").output().unwrap().stdout)
            .unwrap()
            .trim()
            .to_string();
        let d = dir.display();
        // batch_sched_delay=0: Slurm 22.05 may hold a batch job up to 3 s before scheduling it
        // (its default, for clusters with a high submission rate); with two array tasks at a
        // time that was 28.4 s of the 30 s this test took, and the overhead per task it prints
        // was Slurm's wait, not ffdic's (10.5 s and 0.18 s per task without it).
        let conf = format!(
            "ClusterName=ffdictest\nSlurmctldHost={host}(127.0.0.1)\nSlurmUser=root\nSlurmdUser=root\n\
             SlurmctldPort={}\nSlurmdPort={}\nAuthInfo=socket={}\n\
             StateSaveLocation={d}/state\nSlurmdSpoolDir={d}/spool\n\
             SlurmctldPidFile={d}/slurmctld.pid\nSlurmdPidFile={d}/slurmd.pid\n\
             SlurmctldLogFile={d}/slurmctld.log\nSlurmdLogFile={d}/slurmd.log\n\
             ProctrackType=proctrack/linuxproc\nTaskPlugin=task/none\nSelectType=select/cons_tres\n\
             SelectTypeParameters=CR_Core\nReturnToService=2\nMpiDefault=none\n\
             JobAcctGatherType=jobacct_gather/none\nAccountingStorageType=accounting_storage/none\n\
             SchedulerParameters=batch_sched_delay=0\n\
             NodeName={host} NodeAddr=127.0.0.1 CPUs=2 State=UNKNOWN\n\
             PartitionName=debug Nodes=ALL Default=YES MaxTime=INFINITE State=UP\n",
            free_port(),
            free_port(),
            socket.display()
        );
        std::fs::write(dir.join("slurm.conf"), conf).unwrap();
        let mut cluster = Cluster {
            dir: dir.clone(),
            children: Vec::new(),
        };
        let quiet = |c: &mut Command| {
            c.stdout(Stdio::null()).stderr(Stdio::null());
        };
        let mut munged = Command::new("munged");
        munged
            .arg("-F")
            .arg("--force")
            .arg(format!("--socket={}", socket.display()))
            .arg(format!("--key-file={}", key.display()))
            .arg(format!("--pid-file={d}/munged.pid"))
            .arg(format!("--log-file={d}/munged.log"))
            .arg(format!("--seed-file={d}/munged.seed"));
        quiet(&mut munged);
        cluster.children.push(munged.spawn().unwrap());
        let started = Instant::now();
        while !socket.exists() && started.elapsed() < Duration::from_secs(10) {
            std::thread::sleep(Duration::from_millis(20));
        }
        for daemon in ["slurmctld", "slurmd"] {
            let mut c = cluster.command(daemon);
            c.arg("-D");
            quiet(&mut c);
            cluster.children.push(c.spawn().unwrap());
        }
        let started = Instant::now();
        loop {
            let out = cluster
                .command("sinfo")
                .args(["-h", "-o", "%T"])
                .output()
                .unwrap();
            let state = String::from_utf8_lossy(&out.stdout).trim().to_string();
            if state == "idle" {
                break;
            }
            assert!(
                started.elapsed() < Duration::from_secs(60),
                "the cluster did not come up (sinfo: {state:?} {}); logs in {d}: {}",
                String::from_utf8_lossy(&out.stderr),
                std::fs::read_to_string(dir.join("slurmctld.log")).unwrap_or_default()
            );
            std::thread::sleep(Duration::from_millis(200));
        }
        cluster
    }
}

fn ffdic() -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_ffdic"));
    c.env("RUST_LOG", "warn");
    c
}

fn ok(c: &mut Command) -> String {
    let out = c.output().unwrap();
    assert!(
        out.status.success(),
        "{c:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8(out.stdout).unwrap()
}

#[test]
fn the_smoke_sweep_as_a_slurm_array_job_merges_to_the_local_map() {
    let tmp = tempfile::tempdir().unwrap();
    let cluster = Cluster::start(&tmp.path().join("cluster"));
    let spec = Path::new(env!("CARGO_MANIFEST_DIR")).join("config/sweeps/smoke.toml");

    let local = tmp.path().join("local");
    ok(ffdic()
        .args(["sweep", "plan"])
        .arg(&spec)
        .arg("--out")
        .arg(&local));
    let started = Instant::now();
    ok(ffdic().args(["sweep", "run", "--threads", "2"]).arg(&local));
    let local_s = started.elapsed().as_secs_f64();
    ok(ffdic().args(["sweep", "merge"]).arg(&local));

    let dir = tmp.path().join("on-slurm");
    ok(ffdic()
        .args(["sweep", "plan"])
        .arg(&spec)
        .arg("--out")
        .arg(&dir));
    let started = Instant::now();
    let out = ok(ffdic()
        .args(["sweep", "slurm", "--array-max", "2", "--time", "10:00"])
        .arg(&dir)
        .env("SLURM_CONF", cluster.conf()));
    assert!(out.contains("submitted array job"), "{out}");
    let map = dir.join("map.csv");
    while !map.exists() {
        assert!(
            started.elapsed() < Duration::from_secs(300),
            "no map after 300 s; squeue: {}; logs: {:?}",
            String::from_utf8_lossy(&cluster.command("squeue").output().unwrap().stdout),
            std::fs::read_dir(dir.join("slurm")).map(|d| d.count())
        );
        std::thread::sleep(Duration::from_millis(200));
    }
    let slurm_s = started.elapsed().as_secs_f64();
    // The merge job writes map.csv atomically; wait for the queue to drain too.
    while !String::from_utf8_lossy(
        &cluster
            .command("squeue")
            .args(["-h", "-o", "%i"])
            .output()
            .unwrap()
            .stdout,
    )
    .trim()
    .is_empty()
    {
        std::thread::sleep(Duration::from_millis(100));
    }
    assert_eq!(
        std::fs::read_to_string(&map).unwrap(),
        std::fs::read_to_string(local.join("map.csv")).unwrap(),
        "the array job's map equals the local run's"
    );
    let shards = std::fs::read_dir(dir.join("slurm"))
        .unwrap()
        .filter(|e| {
            e.as_ref()
                .unwrap()
                .file_name()
                .to_string_lossy()
                .starts_with("run_")
        })
        .count();
    let plan: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.join("plan.json")).unwrap()).unwrap();
    let n_shards = plan["shards"].as_array().unwrap().len();
    let n_tasks: usize = plan["shards"]
        .as_array()
        .unwrap()
        .iter()
        .map(|s| s["tasks"].as_array().unwrap().len())
        .sum();
    assert_eq!(shards, n_shards, "one array task (log) per shard");
    println!(
        "smoke sweep, {n_tasks} tasks in {n_shards} shards: local (2 threads) {local_s:.1} s; \
         Slurm array (2 at once) + merge {slurm_s:.1} s from submission to map, \
         {:.3} s of overhead per task",
        (slurm_s - local_s) / n_tasks as f64
    );
}
