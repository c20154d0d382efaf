//! Helpers for the recorder's process tests: binaries, child processes, namespaces, polling.
#![allow(dead_code)] // Each test binary uses a different subset.

use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitStatus, Stdio};
use std::sync::OnceLock;
use std::time::{Duration, Instant};

use iceoryx2::prelude::*;
use ipc_types::service;
use ipc_types::{RawImuSample, Stamps, raw_flags};

/// A namespace no other test (or test run) uses.
pub fn namespace(test: &str) -> String {
    format!("t{}-{test}", std::process::id())
}

/// A fresh path for a test file in cargo's per-target scratch space.
pub fn tmp(name: &str) -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("record-tests");
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join(name);
    let _ = std::fs::remove_file(&path);
    path
}

/// The `mems-record` binary of this package.
pub fn mems_record() -> PathBuf {
    PathBuf::from(env!("CARGO_BIN_EXE_mems-record"))
}

/// The `mems-replay` binary, built once per test binary (see [`workspace_bin`]).
pub fn mems_replay() -> PathBuf {
    static PATH: OnceLock<PathBuf> = OnceLock::new();
    PATH.get_or_init(|| workspace_bin("mems-replay", "mems-replay"))
        .clone()
}

/// A binary of another workspace package, built (if stale) with the profile this test was
/// built with. Cargo only provides `CARGO_BIN_EXE_*` for the test's own package, so the path is
/// derived from this test executable's: `target/<profile>/deps/<test>` -> `target/<profile>/<bin>`.
pub fn workspace_bin(package: &str, bin: &str) -> PathBuf {
    let exe = std::env::current_exe().unwrap();
    let profile_dir = exe.parent().and_then(Path::parent).unwrap().to_path_buf();
    let mut build = Command::new(env!("CARGO"));
    build.args(["build", "--quiet", "-p", package, "--bin", bin]);
    if profile_dir.file_name().is_some_and(|n| n == "release") {
        build.arg("--release");
    }
    let status = build.status().expect("cannot run cargo");
    assert!(
        status.success(),
        "cargo build -p {package} --bin {bin} failed"
    );
    let path = profile_dir.join(bin);
    assert!(path.is_file(), "{} was not built", path.display());
    path
}

/// A child process that is SIGKILLed and reaped if the test ends without waiting for it.
pub struct Proc {
    child: Option<Child>,
    name: String,
}

impl Proc {
    /// Starts `program` with `args`, stdout captured, stderr passed through.
    pub fn spawn(program: &Path, args: &[&str]) -> Self {
        let child = Command::new(program)
            .args(args)
            .stdout(Stdio::piped())
            .spawn()
            .unwrap_or_else(|e| panic!("cannot start {}: {e}", program.display()));
        Self {
            child: Some(child),
            name: program.file_name().unwrap().to_string_lossy().into_owned(),
        }
    }

    /// The process id.
    pub fn pid(&self) -> i32 {
        self.child.as_ref().unwrap().id() as i32
    }

    /// Sends `signal` (a libc signal number).
    pub fn signal(&self, signal: i32) {
        // SAFETY: kill(2) on our own child's pid, which is not reaped yet.
        let rc = unsafe { libc::kill(self.pid(), signal) };
        assert_eq!(rc, 0, "kill({}, {signal}) failed", self.name);
    }

    /// Waits for the process (at most `timeout`) and returns its status and stdout.
    pub fn wait(mut self, timeout: Duration) -> (ExitStatus, String) {
        let mut child = self.child.take().unwrap();
        let start = Instant::now();
        loop {
            if let Some(status) = child.try_wait().unwrap() {
                let output = child.wait_with_output().unwrap();
                return (status, String::from_utf8_lossy(&output.stdout).into_owned());
            }
            if start.elapsed() > timeout {
                let _ = child.kill();
                let _ = child.wait();
                panic!("{} did not exit within {timeout:?}", self.name);
            }
            std::thread::sleep(Duration::from_millis(5));
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

/// Polls `condition` every 10 ms until it holds; panics with `what` after `timeout`.
pub fn wait_until(timeout: Duration, what: &str, mut condition: impl FnMut() -> bool) {
    let start = Instant::now();
    while !condition() {
        assert!(
            start.elapsed() < timeout,
            "timed out after {timeout:?} waiting for {what}"
        );
        std::thread::sleep(Duration::from_millis(10));
    }
}

/// A node for the test process itself.
pub fn node() -> Node<ipc::Service> {
    NodeBuilder::new().create::<ipc::Service>().unwrap()
}

/// Waits until the service `base` under `namespace` has at least `n` subscribers (the
/// recorder's), opening it from `node`.
pub fn wait_for_subscribers<T: core::fmt::Debug + ZeroCopySend>(
    node: &Node<ipc::Service>,
    namespace: &str,
    base: &str,
    n: usize,
) {
    let svc = service::open::<T>(node, &service::full_name(namespace, base)).unwrap();
    wait_until(
        Duration::from_secs(5),
        &format!("{n} subscribers on {base}"),
        || svc.dynamic_config().number_of_subscribers() >= n,
    );
}

/// Whether the publish-subscribe service `base` under `namespace` still exists anywhere.
pub fn service_exists(namespace: &str, base: &str) -> bool {
    let name: ServiceName = service::full_name(namespace, base)
        .as_str()
        .try_into()
        .unwrap();
    ipc::Service::does_exist(
        &name,
        Config::global_config(),
        MessagingPattern::PublishSubscribe,
    )
    .unwrap()
}

/// Raw samples at `rate_hz` from sequence number `first_seq`, with values that exercise every
/// field (negative counts, fractional g, flags).
pub fn raw_samples(n: usize, first_seq: u64, rate_hz: u64) -> Vec<RawImuSample> {
    let period_ns = 1_000_000_000 / rate_hz;
    (0..n as u64)
        .map(|i| {
            let seq = first_seq + i;
            let c = |k: i64| (((seq as i64 * 7919 + k * 104_729) % 65_536) - 32_768) as i16;
            let accel_counts = [c(1), c(2), c(3)];
            let gyro_counts = [c(4), c(5), c(6)];
            RawImuSample {
                stamps: Stamps {
                    sample_ns: 5_000_000_000 + seq * period_ns,
                    ..Stamps::default()
                },
                seq,
                accel_g: accel_counts.map(|v| f64::from(v) / 16384.0),
                gyro_dps: gyro_counts.map(|v| f64::from(v) / 131.0),
                temp_c: f64::from(c(7)) / 333.87 + 21.0,
                accel_counts,
                gyro_counts,
                temp_counts: c(7),
                flags: raw_flags::GYRO_VALID | raw_flags::TEMP_VALID,
                lost_before: 0,
                undelivered: 0,
            }
        })
        .collect()
}

/// Sample equality on every field but `stamps.acquired_ns` (which a replay sets), comparing
/// floats bit for bit.
pub fn same_but_acquired(a: &RawImuSample, b: &RawImuSample) -> bool {
    let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
    let mut a2 = *a;
    a2.stamps.acquired_ns = b.stamps.acquired_ns;
    a2 == *b
        && bits(&a.accel_g) == bits(&b.accel_g)
        && bits(&a.gyro_dps) == bits(&b.gyro_dps)
        && a.temp_c.to_bits() == b.temp_c.to_bits()
}
