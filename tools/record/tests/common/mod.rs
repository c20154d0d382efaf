//! Helpers for the recorder's process tests: binaries, namespaces, samples, and the child
//! processes and polling of `integration_tests`.
#![allow(dead_code)] // Each test binary uses a different subset.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::OnceLock;
use std::time::Duration;

use iceoryx2::prelude::*;
use ipc_types::service;
use ipc_types::{RawImuSample, Stamps, raw_flags};

// The process helpers of the workspace's integration tests, one copy for both.
#[allow(unused_imports)] // Each test binary uses a different subset.
pub use integration_tests::{Proc, service_exists, wait_until};

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

/// Starts `program` with `args` (stdout captured, stderr passed through): an
/// [`integration_tests::Proc`], killed and reaped if the test ends without waiting for it.
pub fn spawn(program: &Path, args: &[&str]) -> Proc {
    let mut command = Command::new(program);
    command.args(args);
    Proc::start(&program.file_name().unwrap().to_string_lossy(), command)
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
