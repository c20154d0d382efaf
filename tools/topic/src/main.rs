//! `mems-topic hz|echo SERVICE`: subscribe to a mems service and print its rate, lost and
//! duplicated sequence numbers and latency (`hz`), or its messages (`echo`).

use anyhow::{Result, bail};
use clap::{Parser, Subcommand};
use ipc_types::wake::{self, WaitMode};
use ipc_types::{
    CorrectedImuSample, Message, OdometryState, RawImuSample, clock::monotonic_ns, service,
};
use mems_topic::TopicStats;
use std::ops::ControlFlow;
use std::time::{Duration, Instant};

#[derive(Parser)]
#[command(version, about)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Print the rate, losses, duplicates and latency of a service.
    Hz(Args),
    /// Print every message of a service.
    Echo(Args),
}

#[derive(clap::Args)]
struct Args {
    /// Service name: mems/imu/raw, mems/imu/corrected or mems/odometry/state.
    service: String,
    /// Stop after this many seconds (default: until Ctrl-C).
    #[arg(long)]
    duration: Option<f64>,
    /// Machine-readable output (hz: one JSON summary at the end; echo: one JSON per message).
    #[arg(long)]
    json: bool,
    /// Namespace prefix for service names (default: $MEMS_NAMESPACE).
    #[arg(long)]
    namespace: Option<String>,
}

fn main() -> std::process::ExitCode {
    mems_log::init("mems-topic");
    mems_log::exit(topic(Cli::parse()))
}

fn topic(cli: Cli) -> Result<()> {
    let (args, echo) = match &cli.command {
        Command::Hz(a) => (a, false),
        Command::Echo(a) => (a, true),
    };
    match args.service.as_str() {
        service::RAW => run::<RawImuSample>(args, echo),
        service::CORRECTED => run::<CorrectedImuSample>(args, echo),
        service::ODOMETRY => run::<OdometryState>(args, echo),
        other => bail!(
            "unknown service {other:?}: expected {}, {} or {}",
            service::RAW,
            service::CORRECTED,
            service::ODOMETRY
        ),
    }
}

fn run<T: Message>(args: &Args, echo: bool) -> Result<()> {
    let ns = service::namespace(args.namespace.as_deref());
    let name = service::full_name(&ns, &args.service);
    // Before any port exists: a SIGINT/SIGTERM is kept from then on.
    ipc_types::stop::install()?;
    let node = service::node()?;
    let svc = service::open::<T>(&node, &name)?;
    let subscriber = service::subscriber(&svc)?;

    let start = Instant::now();
    let deadline = args.duration.map(Duration::from_secs_f64);
    let mut stats = TopicStats::new();
    let mut last_print = Instant::now();
    // Sleeps until the publisher's event (or a 100 ms tick for the report and the deadline);
    // returns on SIGINT/SIGTERM: print the summary and exit cleanly.
    let listener = wake::listener(&node, &name, WaitMode::Event)?;
    wake::serve_loop(&[listener], Duration::from_millis(100), || -> Result<_> {
        let mut any = false;
        while let Some(sample) = subscriber
            .receive()
            .map_err(|e| anyhow::anyhow!("receive on {name}: {e:?}"))?
        {
            any = true;
            let msg: &T = sample.payload();
            let now = monotonic_ns();
            stats.observe(
                msg.seq(),
                msg.stamps().sample_ns,
                msg.published_ns(),
                now,
                msg.is_revision(),
            );
            stats.lost_at_source(msg.lost_at_source());
            if echo {
                if args.json {
                    println!("{}", serde_json::to_string(msg)?);
                } else {
                    println!("{msg:?}");
                }
            }
        }
        if !echo && !args.json && last_print.elapsed() >= Duration::from_secs(1) {
            let r = stats.report();
            println!(
                "{name}: {:.1} Hz, received {}, lost {}, duplicated {}, latency p50 {:.0} us p99 {:.0} us max {:.0} us",
                r.rate_hz,
                r.received,
                r.lost,
                r.duplicated,
                r.latency_us.p50,
                r.latency_us.p99,
                r.latency_us.max
            );
            last_print = Instant::now();
        }
        if deadline.is_some_and(|d| start.elapsed() >= d) {
            return Ok(ControlFlow::Break(()));
        }
        Ok(ControlFlow::Continue(any))
    })?;
    if !echo {
        let r = stats.report();
        if args.json {
            println!("{}", serde_json::to_string(&r)?);
        } else {
            println!("{}", serde_json::to_string_pretty(&r)?);
        }
    }
    Ok(())
}
