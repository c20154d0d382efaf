//! `mems-bridge out|in|ros2 --service S [--service S ...]`: carries mems services to other
//! machines over Zenoh (see the library). Closed by default: without `--listen` or
//! `--connect`, `out` listens on and `in` and `ros2` connect to `tcp/127.0.0.1:7447`, this
//! machine only; an endpoint that other machines can reach needs `--auth FILE` (Zenoh's
//! user-password authentication, the same file on both hosts) or an explicit `--no-auth`. On
//! the robot: `mems-bridge out --service odometry --listen tcp/0.0.0.0:7447 --auth
//! bridge.auth`; on the base station: `mems-bridge in --service odometry --connect
//! tcp/ROBOT:7447 --auth bridge.auth`, whose iceoryx2 services any local client then reads.
//! `mems-bridge ros2 --service odometry --service corrected` publishes them as ROS 2 topics
//! (/odom, /imu/data) to a ROS 2 graph on rmw_zenoh (its router, `ros2 run rmw_zenoh_cpp
//! rmw_zenohd`, listens on 7447; `mems_bridge::ros2`). Stops on SIGINT/SIGTERM and prints, per
//! service, one line on stdout: `SERVICE carried N lost M` (and for `in` the latency from the
//! original publication, meaningful where both ends share a clock).

use std::path::PathBuf;

use anyhow::{Context as _, Result, anyhow, bail};
use clap::{Parser, ValueEnum};
use hdrhistogram::Histogram;
use ipc_types::wake;
use ipc_types::{CorrectedImuSample, Message, OdometryState, RawImuSample, RobotHint, service};
use mems_bridge::relay::{self, QUEUE, TICK};
use mems_bridge::ros2;
use mems_bridge::{
    Carried, Counts, Credentials, DEFAULT_ENDPOINT, from_bytes, is_loopback, key, missing,
    to_bytes, zenoh_config,
};
use zenoh::Wait;
use zenoh::handlers::FifoChannel;

/// Carries mems services between machines over Zenoh, and publishes them there on iceoryx2
/// again.
///
/// On the robot, `mems-bridge out --service odometry --listen tcp/0.0.0.0:7447 --auth
/// bridge.auth` puts its odometry states on Zenoh; on the base station, `mems-bridge in
/// --service odometry --connect tcp/ROBOT:7447 --auth bridge.auth` publishes them on its own
/// iceoryx2 service, which any local client reads. Without `--listen` or `--connect` it stays
/// on this machine (tcp/127.0.0.1:7447). `ros2` publishes them as ROS 2 topics over rmw_zenoh.
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
    /// Zenoh endpoint to listen on, e.g. `tcp/0.0.0.0:7447` (repeatable). Without `--listen`
    /// and `--connect`, `out` listens on `tcp/127.0.0.1:7447`.
    #[arg(long)]
    listen: Vec<String>,
    /// Zenoh endpoint of the other end, e.g. `tcp/robot.local:7447` (repeatable). Without
    /// `--listen` and `--connect`, `in` connects to `tcp/127.0.0.1:7447`.
    #[arg(long)]
    connect: Vec<String>,
    /// Credentials file, one `USER:PASSWORD` line per accepted user (the first is the one this
    /// end presents); give both hosts the same file. A peer without a user of the file is
    /// refused.
    #[arg(long, value_name = "FILE")]
    auth: Option<PathBuf>,
    /// Accept endpoints that other machines reach without `--auth`: any peer that reaches
    /// them can then read and publish the carried services.
    #[arg(long, conflicts_with = "auth")]
    no_auth: bool,
    /// Key prefix naming the robot, so that one Zenoh network carries several.
    #[arg(long, default_value = "")]
    prefix: String,
    /// iceoryx2 service namespace on this machine (default: $MEMS_NAMESPACE).
    #[arg(long)]
    namespace: Option<String>,
    /// `ros2`: the ROS 2 domain (default: $ROS_DOMAIN_ID, else 0).
    #[arg(long)]
    domain_id: Option<u32>,
    /// `ros2`: the ROS 2 node name the topics are published under.
    #[arg(long, default_value = "mems_bridge")]
    node_name: String,
}

#[derive(Clone, Copy, PartialEq, Eq, ValueEnum)]
enum Direction {
    Out,
    In,
    /// This machine's services as ROS 2 topics, as rmw_zenoh publishes them: `corrected` on
    /// /imu/data (sensor_msgs/Imu), `odometry` on /odom (nav_msgs/Odometry, live states).
    Ros2,
}

fn main() -> std::process::ExitCode {
    mems_log::init("mems-bridge");
    mems_log::exit(run(Cli::parse()))
}

/// The endpoints to listen on and connect to: those given, or by default this machine's
/// [`DEFAULT_ENDPOINT`] (`out` listens, `in` connects). One that other machines reach is
/// refused without `--auth`, unless `--no-auth` accepts it.
fn endpoints(cli: &Cli) -> Result<(Vec<String>, Vec<String>)> {
    let (mut listen, mut connect) = (cli.listen.clone(), cli.connect.clone());
    if listen.is_empty() && connect.is_empty() {
        match cli.direction {
            Direction::Out => listen.push(DEFAULT_ENDPOINT.into()),
            Direction::In | Direction::Ros2 => connect.push(DEFAULT_ENDPOINT.into()),
        }
    }
    let flagged = listen
        .iter()
        .map(|e| ("--listen", e))
        .chain(connect.iter().map(|e| ("--connect", e)));
    for (flag, endpoint) in flagged {
        if !is_loopback(endpoint) && cli.auth.is_none() && !cli.no_auth {
            bail!(
                "{flag} {endpoint} is reachable from other machines and no --auth is given: \
                 any peer that reaches it could read and publish the carried services; give \
                 --auth FILE (docs/latency.md, Off the robot), or --no-auth to accept that"
            );
        }
    }
    Ok((listen, connect))
}

fn run(cli: Cli) -> Result<()> {
    let (listen, connect) = endpoints(&cli)?;
    let auth = cli.auth.as_deref().map(Credentials::load).transpose()?;
    ipc_types::stop::install()?;
    if cli.direction == Direction::Ros2
        && let Some(s) = cli
            .services
            .iter()
            .find(|s| !matches!(s, Carried::Corrected | Carried::Odometry))
    {
        bail!(
            "no ROS 2 topic carries {}: ros2 takes corrected and odometry",
            s.base()
        );
    }
    let session = zenoh::open(zenoh_config(&listen, &connect, auth.as_ref())?)
        .wait()
        .map_err(|e| anyhow!("cannot open the Zenoh session: {e}"))?;
    let node = match cli.direction {
        Direction::Ros2 => Some(ros2::Node::declare(
            &session,
            domain(cli.domain_id)?,
            &cli.node_name,
        )?),
        _ => None,
    };
    let ends = Ends {
        direction: cli.direction,
        session: &session,
        namespace: service::namespace(cli.namespace.as_deref()),
        prefix: &cli.prefix,
        node: node.as_ref(),
    };
    let results: Vec<Result<String>> = std::thread::scope(|scope| {
        let threads: Vec<_> = (1..)
            .zip(&cli.services)
            .map(|(entity, &carried)| {
                let ends = &ends;
                scope.spawn(move || ends.carry(carried, entity))
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

/// The ROS 2 domain: `--domain-id`, else `$ROS_DOMAIN_ID`, else 0.
fn domain(given: Option<u32>) -> Result<u32> {
    match (given, std::env::var("ROS_DOMAIN_ID")) {
        (Some(domain), _) => Ok(domain),
        (None, Ok(value)) => value
            .parse()
            .with_context(|| format!("ROS_DOMAIN_ID={value:?} is not a domain id")),
        (None, Err(_)) => Ok(0),
    }
}

/// What every service's thread shares.
struct Ends<'a> {
    direction: Direction,
    session: &'a zenoh::Session,
    namespace: String,
    prefix: &'a str,
    /// `ros2`: the node the topics are published under.
    node: Option<&'a ros2::Node>,
}

impl Ends<'_> {
    /// Carries service `carried` until SIGINT/SIGTERM (`ros2`: as publisher `entity` of the
    /// node); returns its summary line.
    fn carry(&self, carried: Carried, entity: u32) -> Result<String> {
        let name = service::full_name(&self.namespace, carried.base());
        let counts = Counts::default();
        let latency = match (self.node, carried) {
            (Some(node), Carried::Corrected) => {
                ros2::publish::<CorrectedImuSample>(self.session, node, entity, &name, &counts)?;
                String::new()
            }
            (Some(node), Carried::Odometry) => {
                ros2::publish::<OdometryState>(self.session, node, entity, &name, &counts)?;
                String::new()
            }
            (Some(_), _) => bail!("no ROS 2 topic carries {}", carried.base()),
            (None, Carried::Raw) => self.bridge::<RawImuSample>(carried, &name, &counts)?,
            (None, Carried::Corrected) => {
                self.bridge::<CorrectedImuSample>(carried, &name, &counts)?
            }
            (None, Carried::Odometry) => self.bridge::<OdometryState>(carried, &name, &counts)?,
            (None, Carried::Hint) => self.bridge::<RobotHint>(carried, &name, &counts)?,
        };
        let (n, lost) = counts.get();
        Ok(format!(
            "{} carried {n} lost {lost}{latency}",
            carried.base()
        ))
    }

    /// `out` or `in` of service `name` carrying `T`; returns the latency part of the summary.
    fn bridge<T: Message + Send>(
        &self,
        carried: Carried,
        name: &str,
        counts: &Counts,
    ) -> Result<String> {
        let key = key::<T>(self.prefix, carried.base());
        match self.direction {
            Direction::In => tracing::info!("carrying Zenoh key {key} in to {name}"),
            _ => tracing::info!("carrying {name} out to Zenoh key {key}"),
        }
        match self.direction {
            Direction::In => into::<T>(self.session, &key, name, counts),
            _ => {
                let publisher = relay::publisher(self.session, &key)?;
                relay::drain::<T>(name, counts, |message| {
                    publisher
                        .put(to_bytes(&message))
                        .wait()
                        .map_err(|e| anyhow!("cannot put on {key}: {e}"))?;
                    Ok(true)
                })?;
                Ok(String::new())
            }
        }
    }
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
