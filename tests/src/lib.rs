//! Helpers for the multi-process integration tests: locating the workspace's binaries, unique
//! service namespaces, and child processes that are stopped when a test ends.

pub mod foxglove;

use std::path::PathBuf;
use std::process::{Child, Command, ExitStatus, Stdio};
use std::time::{Duration, Instant};

/// `mems-topic hz mems/imu/raw --json` in namespace `ns` for `seconds`, given half a second to
/// subscribe before it returns, so that a publisher started next is seen from its first
/// sample.
pub fn raw_topic_hz(ns: &str, seconds: &str) -> Proc {
    let topic = Proc::spawn(
        "mems-topic",
        &[
            "hz",
            "mems/imu/raw",
            "--namespace",
            ns,
            "--duration",
            seconds,
            "--json",
        ],
    );
    std::thread::sleep(Duration::from_millis(500));
    topic
}

/// The path of workspace binary `name`, built in the same profile as the running test.
///
/// `cargo test --workspace` builds every binary of a package that has integration tests before
/// running any test, so the binaries exist; a missing one is a clear failure, not a skip.
pub fn bin(name: &str) -> PathBuf {
    let exe = std::env::current_exe().expect("current test executable");
    // target/<profile>/deps/<test> -> target/<profile>/<name>
    let dir = exe
        .parent()
        .and_then(|deps| deps.parent())
        .expect("test executable lives in target/<profile>/deps");
    let path = dir.join(name);
    assert!(
        path.exists(),
        "binary {} not found: run `cargo build --workspace` (same profile) first",
        path.display()
    );
    path
}

/// Runs binary `name` with `args` to completion (at most 3 minutes), asserts that it
/// succeeded, and returns its standard output.
pub fn run_ok(name: &str, args: &[&str]) -> String {
    let (status, out) = Proc::spawn(name, args).wait(Duration::from_secs(180));
    assert!(status.success(), "{name} {args:?} failed: {status}");
    out
}

/// A path as a command-line argument (test paths are UTF-8).
pub fn path_arg(p: &std::path::Path) -> &str {
    p.to_str().expect("UTF-8 path")
}

/// `mems-odometry offline --input INPUT --json FLAGS` run to completion: its JSON summary.
pub fn offline_json(input: &std::path::Path, flags: &[&str]) -> serde_json::Value {
    let args = [&["offline", "--input", path_arg(input), "--json"], flags].concat();
    let out = run_ok("mems-odometry", &args);
    serde_json::from_str(out.trim()).expect("offline --json prints one JSON document")
}

/// `mems-sim` arguments of a small robot with wheel encoders (speed hints) at 50 Hz, 60 s of
/// driving with turns and turns on the spot, its IMU yawed 78 deg on the base (seed not given).
pub const SPINNING_ROBOT: [&str; 14] = [
    "drive",
    "--duration",
    "60",
    "--turns",
    "on",
    "--in-place-turns",
    "on",
    "--hints",
    "encoders",
    "--mount-deg",
    "0,0,78",
    "--rate",
    "50",
    "--seed",
];

/// Runs `mems-sim ARGS --out DIR/FILE` (the file's extension picks CSV or MCAP) and returns
/// the recording's path.
pub fn simulate(dir: &std::path::Path, file: &str, args: &[&str]) -> PathBuf {
    let out = dir.join(file);
    run_ok("mems-sim", &[args, &["--out", path_arg(&out)][..]].concat());
    out
}

/// A scratch directory for `tag` (in the system's temporary directory, named as
/// [`unique_namespace`] names services) and [`simulate`] run in it: the directory and the
/// recording's path.
pub fn simulate_in_scratch(tag: &str, file: &str, args: &[&str]) -> (PathBuf, PathBuf) {
    let dir = std::env::temp_dir().join(unique_namespace(tag));
    std::fs::create_dir_all(&dir).unwrap();
    let out = simulate(&dir, file, args);
    (dir, out)
}

/// Times (s) of the truth's rests in a `mems-sim` CSV: `(start, end)` of each run of rows with
/// `truth_rest` set.
pub fn truth_rests(csv: &std::path::Path) -> Vec<(f64, f64)> {
    let text = std::fs::read_to_string(csv).unwrap();
    let mut lines = text.lines().filter(|l| !l.starts_with('#'));
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let column = |name: &str| header.iter().position(|h| *h == name).unwrap();
    let (t_col, rest_col) = (column("t_s"), column("truth_rest"));
    let (mut rests, mut start, mut last_t) = (Vec::new(), None, 0.0);
    for line in lines {
        let cells: Vec<&str> = line.split(',').collect();
        let t: f64 = cells[t_col].parse().unwrap();
        let rest = matches!(cells[rest_col], "1" | "true");
        match (rest, start) {
            (true, None) => start = Some(t),
            (false, Some(s)) => {
                rests.push((s, t));
                start = None;
            }
            _ => {}
        }
        last_t = t;
    }
    rests.extend(start.map(|s| (s, last_t)));
    rests
}

/// Calibrates the simulated datasheet-level MPU-9250 of power-on `seed` the way a user would,
/// and as `mems-stack` does: the commands of [`mems_sim::calibration::recipe`] (a six-position
/// session fitted with model 3, then the gyro's scale and misalignment from 16 orientations),
/// each given 3 minutes; returns the calibration file written in `dir` (beside the sessions'
/// `six-position.csv` and `orientations.csv`).
pub fn calibrate_sim_part(dir: &std::path::Path, seed: u64) -> PathBuf {
    let recipe = mems_sim::calibration::recipe(dir, seed);
    for step in &recipe.steps {
        let mut command = Command::new(bin(step.program));
        command.args(&step.args);
        let (status, _) = Proc::start(step.program, command).wait(Duration::from_secs(180));
        assert!(
            status.success(),
            "{} {:?} failed: {status}",
            step.program,
            step.args
        );
    }
    recipe.calib
}

/// A namespace for service names that no other test (or stack) on the machine uses.
pub fn unique_namespace(tag: &str) -> String {
    let nanos = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.subsec_nanos());
    format!("test-{tag}-{}-{nanos}", std::process::id())
}

/// A child process that is killed (SIGKILL) and reaped when dropped, unless it was waited for.
pub struct Proc {
    name: String,
    child: Option<Child>,
}

impl Proc {
    /// Starts binary `name` with `args`, stdout captured, stderr inherited.
    pub fn spawn(name: &str, args: &[&str]) -> Self {
        let mut command = Command::new(bin(name));
        command.args(args);
        Self::start(name, command)
    }

    /// Starts binary `name` with `args`, stdout captured, stderr written to the file `log`.
    pub fn spawn_logged(name: &str, args: &[&str], log: &std::path::Path) -> Self {
        let file = std::fs::File::create(log)
            .unwrap_or_else(|e| panic!("cannot create {}: {e}", log.display()));
        let mut command = Command::new(bin(name));
        command.args(args);
        Self::start_with(name, command, file.into())
    }

    /// Starts `command` (stdout captured, stderr inherited); `name` is for messages.
    pub fn start(name: &str, command: Command) -> Self {
        Self::start_with(name, command, Stdio::inherit())
    }

    /// Starts `command` with stdout captured and stderr to `stderr`.
    fn start_with(name: &str, mut command: Command, stderr: Stdio) -> Self {
        let child = command
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(stderr)
            .spawn()
            .unwrap_or_else(|e| panic!("cannot start {name}: {e}"));
        Self {
            name: name.to_string(),
            child: Some(child),
        }
    }

    /// The process id.
    pub fn pid(&self) -> u32 {
        self.child.as_ref().expect("running").id()
    }

    /// The exit status if the process has exited (reaping it), else `None`.
    pub fn exited(&mut self) -> Option<ExitStatus> {
        let child = self.child.as_mut().expect("running");
        child.try_wait().expect("try_wait")
    }

    /// The name it was started under.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// Sends `signal` (e.g. `libc::SIGTERM`).
    pub fn signal(&self, signal: i32) {
        // SAFETY: kill(2) with a pid we own; no memory is involved.
        let rc = unsafe { libc::kill(self.pid() as i32, signal) };
        assert_eq!(rc, 0, "kill({}, {signal}) failed", self.name);
    }

    /// Waits up to `timeout` for the process to exit and returns its status and stdout.
    pub fn wait(mut self, timeout: Duration) -> (ExitStatus, String) {
        let mut child = self.child.take().expect("running");
        // Read while it runs: a child that fills the pipe (64 KiB) would block for ever.
        let stdout = child.stdout.take().map(|mut stdout| {
            std::thread::spawn(move || {
                use std::io::Read;
                let mut out = String::new();
                stdout.read_to_string(&mut out).expect("read stdout");
                out
            })
        });
        let start = Instant::now();
        loop {
            if let Some(status) = child.try_wait().expect("try_wait") {
                let out = stdout.map_or_else(String::new, |r| r.join().expect("stdout reader"));
                return (status, out);
            }
            if start.elapsed() > timeout {
                let _ = child.kill();
                let _ = child.wait();
                panic!("{} did not exit within {timeout:?}", self.name);
            }
            std::thread::sleep(Duration::from_millis(20));
        }
    }
}

impl Drop for Proc {
    fn drop(&mut self) {
        if let Some(mut child) = self.child.take() {
            let _ = child.kill();
            let _ = child.wait();
        }
    }
}

/// Polls `condition` every 20 ms until it holds; panics naming `what` after `timeout`.
pub fn wait_until(timeout: Duration, what: &str, mut condition: impl FnMut() -> bool) {
    let start = Instant::now();
    while !condition() {
        assert!(
            start.elapsed() < timeout,
            "timed out after {timeout:?} waiting for {what}"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// The child processes of `pid` as (pid, executable file name), from
/// `/proc/PID/task/PID/children` and each child's `/proc/CHILD/cmdline`.
pub fn children(pid: u32) -> Vec<(u32, String)> {
    let list =
        std::fs::read_to_string(format!("/proc/{pid}/task/{pid}/children")).unwrap_or_default();
    list.split_whitespace()
        .filter_map(|c| c.parse::<u32>().ok())
        .filter_map(|c| {
            let cmdline = std::fs::read(format!("/proc/{c}/cmdline")).ok()?;
            let exe = cmdline.split(|&b| b == 0).next()?;
            let exe = std::path::Path::new(std::str::from_utf8(exe).ok()?);
            Some((c, exe.file_name()?.to_str()?.to_string()))
        })
        .collect()
}

/// The pid of `pid`'s child running executable `name`, if there is exactly one.
pub fn child_named(pid: u32, name: &str) -> Option<u32> {
    let found: Vec<u32> = children(pid)
        .into_iter()
        .filter(|(_, exe)| exe == name)
        .map(|(c, _)| c)
        .collect();
    (found.len() == 1).then(|| found[0])
}

/// What iceoryx2 keeps on disk for one node: its id (the name of its directory under
/// `<root>/nodes`) and the ids of its ports (the `*.port_tag` files in that directory, which
/// also name the `/dev/shm` segments of the ports' data and connections).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct NodeFootprint {
    /// The node's unique id, as its directory is named.
    pub id: u128,
    /// The ids of the node's ports, as they appear in file names.
    pub port_ids: Vec<String>,
}

/// iceoryx2's directory of node records (`<root_path>/nodes` of the global config).
pub fn iceoryx_nodes_dir() -> PathBuf {
    use iceoryx2::prelude::Config;
    PathBuf::from(Config::global_config().global.root_path().to_string()).join("nodes")
}

/// The iceoryx2 nodes (alive or dead) whose process is `pid`, with their ports.
pub fn nodes_of(pid: u32) -> Vec<NodeFootprint> {
    use iceoryx2::identifiers::UniqueNodeId;
    use iceoryx2::node::{NodeDetails, NodeState, NodeView};
    use iceoryx2::prelude::*;
    set_log_level_from_env_or(LogLevel::Error);
    let mut ids = Vec::new();
    Node::<ipc::Service>::list(Config::global_config(), |state| {
        let view: Option<(&UniqueNodeId, &Option<NodeDetails>)> = match &state {
            NodeState::Alive(v) => Some((v.id(), v.details())),
            NodeState::Dead(v) => Some((v.id(), v.details())),
            _ => None,
        };
        if let Some((id, Some(details))) = view
            && details.process_id().value() as u32 == pid
        {
            ids.push(id.value());
        }
        CallbackProgression::Continue
    })
    .expect("list iceoryx2 nodes");
    ids.into_iter()
        .map(|id| {
            let dir = iceoryx_nodes_dir().join(id.to_string());
            let port_ids = std::fs::read_dir(&dir)
                .map(|entries| {
                    entries
                        .filter_map(|e| e.ok()?.file_name().into_string().ok())
                        .filter_map(|f| {
                            Some(
                                f.strip_suffix(".port_tag")?
                                    .trim_start_matches("iox2_")
                                    .into(),
                            )
                        })
                        .collect()
                })
                .unwrap_or_default();
            NodeFootprint { id, port_ids }
        })
        .collect()
}

/// Files left behind by `node`: its directory under [`iceoryx_nodes_dir`], its monitor files
/// there, and every `/dev/shm` segment whose name carries one of its port ids.
pub fn leftovers(node: &NodeFootprint) -> Vec<PathBuf> {
    let mut found = Vec::new();
    let id = node.id.to_string();
    let scan = |dir: &std::path::Path, hit: &dyn Fn(&str) -> bool, found: &mut Vec<PathBuf>| {
        if let Ok(entries) = std::fs::read_dir(dir) {
            for e in entries.flatten() {
                if e.file_name().to_str().is_some_and(hit) {
                    found.push(e.path());
                }
            }
        }
    };
    scan(&iceoryx_nodes_dir(), &|f| f.contains(&id), &mut found);
    scan(
        std::path::Path::new("/dev/shm"),
        &|f| f.starts_with("iox2_") && node.port_ids.iter().any(|p| f.contains(p.as_str())),
        &mut found,
    );
    found
}

/// Whether the publish-subscribe service `base` under `namespace` still exists anywhere.
pub fn service_exists(namespace: &str, base: &str) -> bool {
    use iceoryx2::prelude::*;
    let name: ServiceName = ipc_types::service::full_name(namespace, base)
        .as_str()
        .try_into()
        .expect("valid service name");
    ipc::Service::does_exist(
        &name,
        Config::global_config(),
        MessagingPattern::PublishSubscribe,
    )
    .expect("iceoryx2 service lookup")
}

/// The sequence numbers missing from `seqs` (ascending, from its first to its last) as
/// inclusive ranges.
pub fn missing_ranges(seqs: &[u64]) -> Vec<(u64, u64)> {
    seqs.windows(2)
        .filter(|w| w[1] > w[0] + 1)
        .map(|w| (w[0] + 1, w[1] - 1))
        .collect()
}

/// The path of example `name` of workspace package `package`, built first (cargo builds only
/// the tested package's targets) in the profile of the running test.
pub fn example(package: &str, name: &str) -> PathBuf {
    let exe = std::env::current_exe().expect("current test executable");
    let profile_dir = exe
        .parent()
        .and_then(|deps| deps.parent())
        .expect("test executable lives in target/<profile>/deps");
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    let mut build = Command::new(cargo);
    build.args(["build", "--quiet", "-p", package, "--example", name]);
    if profile_dir.file_name().is_some_and(|n| n == "release") {
        build.arg("--release");
    }
    let status = build.status().expect("cannot run cargo");
    assert!(
        status.success(),
        "cargo build -p {package} --example {name} failed"
    );
    let path = profile_dir.join("examples").join(name);
    assert!(path.is_file(), "{} was not built", path.display());
    path
}

/// The workspace's root directory (where `ipc-types/python/` lives).
pub fn workspace_root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("tests/ sits in the workspace root")
        .to_path_buf()
}

/// The identity calibration the real-data bench uses (bias 0, S = I, standard gravity): the
/// simulated `calibrated` preset needs no correction.
pub fn identity_calibration() -> PathBuf {
    workspace_root().join("tools/parser-fuzz/corpus/calib/identity-bench.toml")
}

/// Whether `python3` can import the iceoryx2 Python package. When it cannot, the tests that
/// need it print why, loudly, and skip; `.ci/run` installs it.
pub fn python_iceoryx2() -> bool {
    let ok = Command::new("python3")
        .args(["-c", "import iceoryx2"])
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status()
        .is_ok_and(|s| s.success());
    if !ok {
        eprintln!(
            "\n********************************************************************\n\
             SKIPPED: python3 cannot import the iceoryx2 Python package (0.10).\n\
             Install it: python3 -m pip install 'iceoryx2==0.10.*' (.ci/run does).\n\
             ********************************************************************\n"
        );
    }
    ok
}

/// An aligned odometry state numbered `seq`, stamped now (sample and publication), with a
/// position and 1-sigma that differ per state: what the transport tests carry.
pub fn odometry_state(seq: u64) -> ipc_types::OdometryState {
    let t = ipc_types::clock::monotonic_ns();
    ipc_types::OdometryState {
        stamps: ipc_types::Stamps {
            sample_ns: t,
            odometry_ns: t,
            ..ipc_types::Stamps::default()
        },
        seq,
        position_m: [seq as f64 * 1e-3, -0.5, 0.125],
        position_sigma_m: [0.01, 0.02 + seq as f64 * 1e-6, 0.03],
        attitude_wxyz: [1.0, 0.0, 0.0, 0.0],
        flags: ipc_types::odometry_flags::ALIGNED,
        ..ipc_types::OdometryState::default()
    }
}

/// A TCP port on the loopback interface that was free a moment ago.
pub fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .and_then(|l| l.local_addr())
        .expect("a free loopback port")
        .port()
}
