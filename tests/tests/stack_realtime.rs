//! `mems-stack`'s real-time options reach its acquire process, and a configuration error that
//! makes acquire fail at every start stops the stack with a clear error instead of a restart
//! loop.
//!
//! - `--cpu 0 --mlock`: the running `mems-acquire` child is pinned to CPU 0
//!   (`Cpus_allowed_list` in `/proc/PID/status`) and has locked memory (`VmLck` > 0), and it
//!   published samples (its own summary on stderr);
//! - `--cpu 999` (no such core): acquire's own error is on stderr, the stack gives up on it
//!   after three fast failures, says so, and exits with a failure status within seconds.

use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use integration_tests::{bin, child_named, unique_namespace, wait_until};

/// Runs `mems-stack` with `args` in its own namespace, stderr to a file; `during` is called
/// with the stack's pid while it runs. Returns (exit success, stdout, stderr, run time).
fn run_stack(
    tag: &str,
    args: &[&str],
    during: impl FnOnce(u32),
) -> (bool, String, String, Duration) {
    let ns = unique_namespace(tag);
    let err_path = std::env::temp_dir().join(format!("{ns}.stderr"));
    let err_file = std::fs::File::create(&err_path).unwrap();
    let start = Instant::now();
    let child = Command::new(bin("mems-stack"))
        .args(args)
        .args(["--namespace", &ns])
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(err_file)
        .spawn()
        .expect("mems-stack starts");
    during(child.id());
    let out = child.wait_with_output().expect("mems-stack ends");
    let elapsed = start.elapsed();
    let stderr = std::fs::read_to_string(&err_path).unwrap();
    let _ = std::fs::remove_file(&err_path);
    (
        out.status.success(),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        stderr,
        elapsed,
    )
}

/// The value of `field` in `/proc/PID/status`, trimmed.
fn proc_status(pid: u32, field: &str) -> Option<String> {
    let status = std::fs::read_to_string(format!("/proc/{pid}/status")).ok()?;
    status
        .lines()
        .find_map(|l| l.strip_prefix(field)?.strip_prefix(':'))
        .map(|v| v.trim().to_string())
}

#[test]
fn cpu_and_mlock_reach_the_acquire_process() {
    let (ok, stdout, stderr, _) = run_stack(
        "stack-rt",
        &["--duration", "4", "--cpu", "0", "--mlock"],
        |stack| {
            let mut acquire = 0;
            wait_until(
                Duration::from_secs(10),
                "mems-acquire pinned to CPU 0",
                || {
                    acquire = child_named(stack, "mems-acquire").unwrap_or(0);
                    acquire != 0
                        && proc_status(acquire, "Cpus_allowed_list").as_deref() == Some("0")
                },
            );
            let locked = proc_status(acquire, "VmLck").expect("VmLck in /proc/PID/status");
            let kib: u64 = locked.trim_end_matches(" kB").parse().unwrap();
            assert!(kib > 0, "acquire has no locked memory: VmLck {locked}");
        },
    );
    assert!(ok, "mems-stack failed:\n{stderr}");
    assert!(stdout.contains("acquire 0"), "acquire restarted: {stdout}");
    let published: u64 = stderr
        .lines()
        .find_map(|l| l.strip_prefix("mems-acquire: published "))
        .and_then(|rest| rest.split_whitespace().next()?.parse().ok())
        .unwrap_or_else(|| panic!("no acquire summary in:\n{stderr}"));
    assert!(
        published > 1000,
        "acquire published only {published} samples"
    );
}

#[test]
fn an_acquire_option_the_machine_refuses_stops_the_stack_with_its_error() {
    let (ok, stdout, stderr, elapsed) = run_stack(
        "stack-rt-bad",
        &["--duration", "30", "--cpu", "999"],
        |_| {},
    );
    assert!(
        !ok,
        "mems-stack succeeded although acquire cannot start:\n{stderr}"
    );
    assert!(
        stderr.contains("cannot pin to CPU 999: no such core"),
        "acquire's own error is missing:\n{stderr}"
    );
    assert!(
        stderr.contains("acquire exited within 2s of starting 3 times in a row")
            && stderr.contains("not restarting it"),
        "the stack does not say it gave up:\n{stderr}"
    );
    assert!(
        stdout.contains("acquire 2"),
        "two restarts, then given up: {stdout}"
    );
    assert!(
        elapsed < Duration::from_secs(15),
        "giving up took {elapsed:?} (the run was to last 30 s)"
    );
}
