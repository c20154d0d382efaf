//! Helpers for the multi-process integration tests: locating the workspace's binaries, unique
//! service namespaces, and child processes that are stopped when a test ends.

use std::path::PathBuf;
use std::process::{Child, Command, ExitStatus, Stdio};
use std::time::{Duration, Instant};

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

/// Calibrates the simulated datasheet-level MPU-9250 the way a user would: a `mems-sim`
/// six-position session (power-on `seed`) fitted with model 3 by `mems-calibrate fit`; returns
/// the calibration file written in `dir`.
pub fn calibrate_sim_part(dir: &std::path::Path, seed: u64) -> PathBuf {
    let six = dir.join("six.csv");
    let calib = dir.join("calib.toml");
    let seed = seed.to_string();
    run_ok(
        "mems-sim",
        &[
            "six-position",
            "--preset",
            "datasheet",
            "--seed",
            &seed,
            "--rate",
            "200",
            "--out",
            path_arg(&six),
        ],
    );
    run_ok(
        "mems-calibrate",
        &[
            "fit",
            "--input",
            path_arg(&six),
            "--model",
            "full",
            "--out",
            path_arg(&calib),
        ],
    );
    calib
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
        let child = Command::new(bin(name))
            .args(args)
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit())
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

    /// Sends `signal` (e.g. `libc::SIGTERM`).
    pub fn signal(&self, signal: i32) {
        // SAFETY: kill(2) with a pid we own; no memory is involved.
        let rc = unsafe { libc::kill(self.pid() as i32, signal) };
        assert_eq!(rc, 0, "kill({}, {signal}) failed", self.name);
    }

    /// Waits up to `timeout` for the process to exit and returns its status and stdout.
    pub fn wait(mut self, timeout: Duration) -> (ExitStatus, String) {
        let mut child = self.child.take().expect("running");
        let start = Instant::now();
        loop {
            if let Some(status) = child.try_wait().expect("try_wait") {
                let mut out = String::new();
                if let Some(mut stdout) = child.stdout.take() {
                    use std::io::Read;
                    stdout.read_to_string(&mut out).expect("read stdout");
                }
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
