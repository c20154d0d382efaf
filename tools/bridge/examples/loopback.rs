//! The bridge measured on loopback: `mems-bridge out` and `mems-bridge in` as two hosts (two
//! iceoryx2 namespaces, one Zenoh TCP link), odometry states published at a fixed rate on the
//! robot's side and read on the other's. Prints what arrived and lost, the rate, and the
//! bridge's latency (publication to republication, one clock) from `mems-bridge in`.
//!
//! `cargo build --release -p mems-bridge && cargo run --release -p mems-bridge --example
//! loopback -- [--seconds 60] [--rate 1000]`

use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use anyhow::{Context, Result, bail};
use integration_tests::{free_port, odometry_state};
use ipc_types::wake::Output;
use ipc_types::{OdometryState, service};

fn arg(name: &str, default: f64) -> Result<f64> {
    let args: Vec<String> = std::env::args().collect();
    match args.iter().position(|a| a == name) {
        Some(i) => Ok(args.get(i + 1).context("a value")?.parse()?),
        None => Ok(default),
    }
}

fn main() -> Result<()> {
    let (seconds, rate) = (arg("--seconds", 60.0)?, arg("--rate", 1000.0)?);
    let bin = std::env::current_exe()?
        .parent()
        .and_then(std::path::Path::parent)
        .context("the example lives in target/<profile>/examples")?
        .join("mems-bridge");
    let pid = std::process::id();
    let (robot, station) = (format!("bench-a-{pid}"), format!("bench-b-{pid}"));
    let endpoint = format!("tcp/127.0.0.1:{}", free_port());
    let spawn = |args: &[&str]| {
        Command::new(&bin)
            .args(args)
            .stdout(Stdio::piped())
            .spawn()
            .with_context(|| format!("cannot start {} (build it first)", bin.display()))
    };
    let out = spawn(&[
        "out",
        "--service",
        "odometry",
        "--listen",
        &endpoint,
        "--namespace",
        &robot,
    ])?;
    let into = spawn(&[
        "in",
        "--service",
        "odometry",
        "--connect",
        &endpoint,
        "--namespace",
        &station,
    ])?;

    let node = service::node()?;
    let robot_name = service::full_name(&robot, service::ODOMETRY);
    let mut publisher = Output::new(
        &node,
        &service::open::<OdometryState>(&node, &robot_name)?,
        &robot_name,
    )?;
    let station_svc =
        service::open::<OdometryState>(&node, &service::full_name(&station, service::ODOMETRY))?;
    let subscriber = service::subscriber(&station_svc)?;
    // Warm-up: until one state crosses (the link and the subscription are up).
    let mut seq = 0;
    let start = Instant::now();
    while subscriber.receive()?.is_none() {
        if start.elapsed() > Duration::from_secs(60) {
            bail!("nothing crossed the bridge in 60 s");
        }
        publisher.send(odometry_state(seq));
        publisher.end_of_input()?;
        seq += 1;
        std::thread::sleep(Duration::from_millis(10));
    }
    while subscriber.receive()?.is_some() {}
    let (first, n) = (seq, (seconds * rate) as u64);
    let period = Duration::from_secs_f64(1.0 / rate);
    let (mut received, mut last) = (0u64, None);
    let start = Instant::now();
    for k in 0..n {
        let due = start + period * k as u32;
        if let Some(wait) = due.checked_duration_since(Instant::now()) {
            std::thread::sleep(wait);
        }
        publisher.send(odometry_state(first + k));
        publisher.end_of_input()?;
        while let Some(s) = subscriber.receive()? {
            received += u64::from(s.seq >= first);
            last = Some(s.seq);
        }
    }
    let sent_s = start.elapsed().as_secs_f64();
    let deadline = Instant::now() + Duration::from_secs(10);
    while last != Some(first + n - 1) && Instant::now() < deadline {
        while let Some(s) = subscriber.receive()? {
            received += u64::from(s.seq >= first);
            last = Some(s.seq);
        }
        std::thread::sleep(Duration::from_millis(1));
    }
    for child in [&out, &into] {
        // SAFETY: kill(2) on our own child, not yet reaped.
        unsafe { libc::kill(child.id() as i32, libc::SIGTERM) };
    }
    let summary = |child: std::process::Child| -> Result<String> {
        let output = child.wait_with_output()?;
        Ok(String::from_utf8_lossy(&output.stdout).trim().to_string())
    };
    println!(
        "sent {n} states at {:.0} Hz in {sent_s:.1} s; received {received}, lost {}",
        n as f64 / sent_s,
        n - received
    );
    println!("mems-bridge out: {}", summary(out)?);
    println!("mems-bridge in:  {}", summary(into)?);
    Ok(())
}
