//! The C client example (`ipc-types/examples/c/subscribe_odometry.c`) compiled with the
//! system's C compiler against `include/mems_client.h` and `libmems_client.so`, run as its own
//! process: it receives the states this test publishes (event-driven: each send notifies),
//! prints every live one ("not aligned yet" before alignment) and skips revisions, after one
//! line on stderr naming the service and namespace it waits on; SIGTERM ends a client that is waiting, exit 0.

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use iceoryx2::prelude::PortFactory;
use ipc_types::wake::Output;
use ipc_types::{OdometryState, odometry_flags, service};

const WAIT: Duration = Duration::from_secs(60);

/// `target/<profile>` with `libmems_client.so` built in it: `cargo test` builds this
/// package's library for the tests as an rlib only, so the shared library is built here (a
/// no-op when it is fresh).
fn lib_dir() -> PathBuf {
    let exe = std::env::current_exe().unwrap();
    let dir = exe.parent().and_then(Path::parent).unwrap().to_path_buf();
    let mut build = Command::new(env!("CARGO"));
    build.args(["build", "--quiet", "-p", "mems-client-c", "--lib"]);
    if dir.file_name().is_some_and(|n| n == "release") {
        build.arg("--release");
    }
    assert!(build.status().expect("cannot run cargo").success());
    assert!(
        dir.join("libmems_client.so").is_file(),
        "no libmems_client.so in {}",
        dir.display()
    );
    dir
}

/// The example compiled once per test binary (the tests run in parallel).
fn compile() -> PathBuf {
    static PROGRAM: std::sync::OnceLock<PathBuf> = std::sync::OnceLock::new();
    PROGRAM.get_or_init(compile_once).clone()
}

/// Compiles the example into this test's scratch directory.
fn compile_once() -> PathBuf {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).parent().unwrap();
    let out = Path::new(env!("CARGO_TARGET_TMPDIR")).join("subscribe_odometry");
    let lib = lib_dir();
    let status = Command::new("cc")
        .args(["-O2", "-Wall", "-Werror", "-I"])
        .arg(root.join("include"))
        .arg(root.join("examples/c/subscribe_odometry.c"))
        .arg("-L")
        .arg(&lib)
        .arg("-lmems_client")
        .arg(format!("-Wl,-rpath,{}", lib.display()))
        .arg("-o")
        .arg(&out)
        .status()
        .expect("cannot run cc: install gcc (CI: .ci/run)");
    assert!(status.success(), "cc failed");
    out
}

fn start(program: &Path, namespace: &str, count: &str) -> Child {
    Command::new(program)
        .arg(count)
        .env("MEMS_NAMESPACE", namespace)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap()
}

fn wait_exit(child: &mut Child) -> std::process::ExitStatus {
    let start = Instant::now();
    loop {
        if let Some(status) = child.try_wait().unwrap() {
            return status;
        }
        assert!(start.elapsed() < WAIT, "the C client did not exit");
        std::thread::sleep(Duration::from_millis(20));
    }
}

fn state(seq: u64, flags: u16) -> OdometryState {
    OdometryState {
        seq,
        position_m: [0.25 * seq as f64, -1.5, 0.125],
        position_sigma_m: [0.01, 0.02, 0.003 * seq as f64],
        attitude_wxyz: [1.0, 0.0, 0.0, 0.0],
        flags: odometry_flags::ALIGNED | flags,
        ..OdometryState::default()
    }
}

#[test]
fn the_c_client_prints_every_live_state() {
    let program = compile();
    let namespace = format!("test-c-client-{}", std::process::id());
    let mut client = start(&program, &namespace, "40");
    let node = service::node().unwrap();
    let name = service::full_name(&namespace, service::ODOMETRY);
    let svc = service::open::<OdometryState>(&node, &name).unwrap();
    let start = Instant::now();
    while svc.dynamic_config().number_of_subscribers() < 1 {
        assert!(start.elapsed() < WAIT, "the C client did not subscribe");
        std::thread::sleep(Duration::from_millis(10));
    }
    let mut out = Output::new(&node, &svc, &name).unwrap();
    let mut expected = String::new();
    for seq in 0..40 {
        let mut s = state(seq, 0);
        if seq < 3 {
            s.flags &= !odometry_flags::ALIGNED;
        }
        out.send(s);
        if seq % 10 == 9 {
            out.send(state(seq - 1, odometry_flags::REVISION));
        }
        out.end_of_input().unwrap();
        let (p, e) = (s.position_m, s.position_sigma_m);
        expected += &if seq < 3 {
            format!("seq {seq} not aligned yet\n")
        } else {
            format!(
                "seq {seq} position ({:+.3}, {:+.3}, {:+.3}) m +- ({:.3}, {:.3}, {:.3})\n",
                p[0], p[1], p[2], e[0], e[1], e[2]
            )
        };
        std::thread::sleep(Duration::from_millis(2));
    }
    let status = wait_exit(&mut client);
    let printed = std::io::read_to_string(client.stdout.take().unwrap()).unwrap();
    let said = std::io::read_to_string(client.stderr.take().unwrap()).unwrap();
    assert!(status.success(), "{status}");
    assert_eq!(printed, expected);
    assert_eq!(
        said,
        format!(
            "subscribe_odometry: waiting for states on {name} (namespace \"{namespace}\"; \
             start mems-stack with the same namespace)\n"
        )
    );
}

#[test]
fn sigterm_ends_a_waiting_c_client() {
    let program = compile();
    let namespace = format!("test-c-client-stop-{}", std::process::id());
    let mut client = start(&program, &namespace, "-1");
    let node = service::node().unwrap();
    let svc =
        service::open::<OdometryState>(&node, &service::full_name(&namespace, service::ODOMETRY))
            .unwrap();
    let start = Instant::now();
    while svc.dynamic_config().number_of_subscribers() < 1 {
        assert!(start.elapsed() < WAIT, "the C client did not subscribe");
        std::thread::sleep(Duration::from_millis(10));
    }
    // SAFETY: kill(2) on our own child, not yet reaped.
    assert_eq!(unsafe { libc::kill(client.id() as i32, libc::SIGTERM) }, 0);
    let status = wait_exit(&mut client);
    assert!(status.success(), "{status}");
}
