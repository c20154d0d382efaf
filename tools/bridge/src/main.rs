//! `mems-bridge out|in --service S [--service S ...]`: carries mems services to other machines
//! over Zenoh (see the library). On the robot:
//! `mems-bridge out --service odometry --listen tcp/0.0.0.0:7447`; on the base station:
//! `mems-bridge in --service odometry --connect tcp/ROBOT:7447`, whose iceoryx2 services any
//! local client then reads. Stops on SIGINT/SIGTERM and prints, per service, one line on
//! stdout: `SERVICE carried N lost M` (and for `in` the latency from the original publication,
//! meaningful where both ends share a clock).

use std::ops::ControlFlow;
use std::time::Duration;

use anyhow::{Context as _, Result, anyhow};
use clap::{Parser, ValueEnum};
use hdrhistogram::Histogram;
use ipc_types::wake::{self, WaitMode};
use ipc_types::{CorrectedImuSample, Message, OdometryState, RawImuSample, RobotHint, service};
use mems_bridge::{Carried, Counts, from_bytes, key, missing, to_bytes, zenoh_config};
use zenoh::Wait;
use zenoh::handlers::FifoChannel;
use zenoh::qos::CongestionControl;

/// Messages buffered per service between iceoryx2 and Zenoh: 16 s at 1 kHz.
const QUEUE: usize = 16_384;
/// Longest wait between two checks for SIGINT/SIGTERM.
const TICK: Duration = Duration::from_millis(100);

/// Carries mems services between machines over Zenoh, and publishes them there on iceoryx2
/// again.
///
/// On the robot, `mems-bridge out --service odometry --listen tcp/0.0.0.0:7447` puts its
/// odometry states on Zenoh; on the base station, `mems-bridge in --service odometry --connect
/// tcp/ROBOT:7447` publishes them on its own iceoryx2 service, which any local client reads.
/// Stops on SIGINT or SIGTERM and prints one line per service: `SERVICE carried N lost M`
/// (with `in`, also the latency from the original publication, meaningful where both
/// machines share a clock).
#[derive(Parser)]
#[command(version)]
struct Cli {
    /// `out` carries this machine's iceoryx2 services onto Zenoh; `in` carries them from Zenoh
    /// onto this machine's iceoryx2 services.
    direction: Direction,
    /// A service to carry (repeat for several).
    #[arg(long = "service", required = true)]
    services: Vec<Carried>,
    /// Zenoh endpoint to listen on, e.g. `tcp/0.0.0.0:7447` (repeatable).
    #[arg(long)]
    listen: Vec<String>,
    /// Zenoh endpoint of the other end, e.g. `tcp/robot.local:7447` (repeatable).
    #[arg(long)]
    connect: Vec<String>,
    /// Key prefix naming the robot, so that one Zenoh network carries several.
    #[arg(long, default_value = "")]
    prefix: String,
    /// iceoryx2 service namespace on this machine (default: $MEMS_NAMESPACE).
    #[arg(long)]
    namespace: Option<String>,
}

#[derive(Clone, Copy, PartialEq, Eq, ValueEnum)]
enum Direction {
    Out,
    In,
}

fn main() -> std::process::ExitCode {
    mems_log::init("mems-bridge");
    mems_log::exit(run(Cli::parse()))
}

fn run(cli: Cli) -> Result<()> {
    ipc_types::stop::install()?;
    let session = zenoh::open(zenoh_config(&cli.listen, &cli.connect)?)
        .wait()
        .map_err(|e| anyhow!("cannot open the Zenoh session: {e}"))?;
    let namespace = service::namespace(cli.namespace.as_deref());
    let results: Vec<Result<String>> = std::thread::scope(|scope| {
        let threads: Vec<_> = cli
            .services
            .iter()
            .map(|&carried| {
                let (session, namespace, prefix) = (&session, &namespace, &cli.prefix);
                scope.spawn(move || match carried {
                    Carried::Raw => {
                        carry::<RawImuSample>(cli.direction, session, namespace, prefix, carried)
                    }
                    Carried::Corrected => carry::<CorrectedImuSample>(
                        cli.direction,
                        session,
                        namespace,
                        prefix,
                        carried,
                    ),
                    Carried::Odometry => {
                        carry::<OdometryState>(cli.direction, session, namespace, prefix, carried)
                    }
                    Carried::Hint => {
                        carry::<RobotHint>(cli.direction, session, namespace, prefix, carried)
                    }
                })
            })
            .collect();
        threads
            .into_iter()
            .map(|t| {
                t.join()
                    .unwrap_or_else(|_| Err(anyhow!("a bridge thread panicked")))
            })
            .collect()
    });
    for result in results {
        println!("{}", result?);
    }
    Ok(())
}

/// Carries service `carried` of payload `T` in `direction` until SIGINT/SIGTERM; returns its
/// summary line.
fn carry<T: Message + Send>(
    direction: Direction,
    session: &zenoh::Session,
    namespace: &str,
    prefix: &str,
    carried: Carried,
) -> Result<String> {
    let base = carried.base();
    let key = key::<T>(prefix, base);
    let name = service::full_name(namespace, base);
    let counts = Counts::default();
    match direction {
        Direction::Out => tracing::info!("carrying {name} out to Zenoh key {key}"),
        Direction::In => tracing::info!("carrying Zenoh key {key} in to {name}"),
    }
    let latency = match direction {
        Direction::Out => {
            out::<T>(session, &key, &name, &counts)?;
            String::new()
        }
        Direction::In => into::<T>(session, &key, &name, &counts)?,
    };
    let (carried, lost) = counts.get();
    Ok(format!("{base} carried {carried} lost {lost}{latency}"))
}

/// iceoryx2 -> Zenoh: the subscriber is drained at once into a bounded queue; a sender thread
/// puts each message on Zenoh.
fn out<T: Message + Send>(
    session: &zenoh::Session,
    key: &str,
    name: &str,
    counts: &Counts,
) -> Result<()> {
    let publisher = session
        .declare_publisher(key.to_string())
        .congestion_control(CongestionControl::Block)
        .wait()
        .map_err(|e| anyhow!("cannot declare a Zenoh publisher on {key}: {e}"))?;
    let node = service::node()?;
    let subscriber = service::subscriber(&service::open::<T>(&node, name)?)?;
    let listener = wake::listener(&node, name, WaitMode::Event)?;
    let (tx, rx) = std::sync::mpsc::sync_channel::<T>(QUEUE);
    std::thread::scope(|scope| {
        let sender = scope.spawn(|| -> Result<()> {
            for message in rx {
                publisher
                    .put(to_bytes(&message))
                    .wait()
                    .map_err(|e| anyhow!("cannot put on {key}: {e}"))?;
                counts.carry();
            }
            Ok(())
        });
        let step = || -> Result<ControlFlow<(), bool>> {
            let mut any = false;
            while let Some(sample) = subscriber.receive()? {
                any = true;
                if tx.try_send(*sample).is_err() {
                    counts.lose(1);
                }
            }
            Ok(ControlFlow::Continue(any))
        };
        let served = wake::serve_loop(&[listener], TICK, step);
        drop(tx);
        let sent = sender.join().map_err(|_| anyhow!("the sender panicked"))?;
        served.and(sent).map(|_| ())
    })
}

/// Zenoh -> iceoryx2: each message is published (and its subscribers woken) as it arrives;
/// returns the latency part of the summary.
fn into<T: Message + Send>(
    session: &zenoh::Session,
    key: &str,
    name: &str,
    counts: &Counts,
) -> Result<String> {
    let subscriber = session
        .declare_subscriber(key.to_string())
        .with(FifoChannel::new(QUEUE))
        .wait()
        .map_err(|e| anyhow!("cannot declare a Zenoh subscriber on {key}: {e}"))?;
    let node = service::node()?;
    let mut output = wake::Output::new(&node, &service::open::<T>(&node, name)?, name)?;
    let mut latency_us = Histogram::<u64>::new(3)?;
    let mut last = None;
    while !ipc_types::stop::requested() {
        let Some(sample) = subscriber
            .recv_timeout(TICK)
            .map_err(|e| anyhow!("{key}: {e}"))?
        else {
            continue;
        };
        let bytes = sample.payload().to_bytes();
        let message = from_bytes::<T>(&bytes)
            .with_context(|| format!("{key}: a sample of {} bytes", bytes.len()))?;
        output.send(message);
        output.end_of_input()?;
        counts.carry();
        if !message.is_revision() {
            counts.lose(missing(last, message.seq()));
            last = Some(message.seq());
        }
        let age_ns = ipc_types::clock::monotonic_ns().saturating_sub(message.published_ns());
        latency_us.saturating_record(age_ns / 1000);
    }
    Ok(format!(
        " latency_us p50 {} p99 {} p999 {} max {}",
        latency_us.value_at_quantile(0.5),
        latency_us.value_at_quantile(0.99),
        latency_us.value_at_quantile(0.999),
        latency_us.max()
    ))
}
