//! `mems-foxglove [--listen HOST:PORT] [--namespace NS] [--parameter NAME=VALUE]...`: serves
//! the live topics over Foxglove's WebSocket protocol (see the library for the channels), so
//! the Foxglove app, Lichtblick or any client of the protocol (`foxglove.websocket.v1` or
//! `foxglove.sdk.v1`) shows the running robot ("Open connection", `ws://HOST:PORT`), takes
//! robot hints published from the app (`mems_foxglove::hints`) and shows the stack's settings
//! as read-only parameters. Loopback only unless told otherwise; port 0 picks a free port.
//! Prints `mems-foxglove: serving ws://HOST:PORT` on stderr once listening; stops on
//! SIGINT/SIGTERM.

use std::net::{Ipv4Addr, SocketAddr};
use std::sync::Arc;

use anyhow::{Context as _, Result};
use clap::Parser;
use foxglove::websocket::Capability;
use ipc_types::service;
use mems_foxglove::parameters::Settings;
use mems_foxglove::subprotocol::Front;
use mems_foxglove::{View, WallClock, hints, live};

/// Serves the live mems topics to the Foxglove app over WebSocket.
#[derive(Parser)]
#[command(version, about)]
struct Cli {
    /// Address to listen on, HOST:PORT (port 0: any free port).
    #[arg(long, default_value = "127.0.0.1:8765")]
    listen: String,
    /// Service namespace (default: $MEMS_NAMESPACE).
    #[arg(long)]
    namespace: Option<String>,
    /// A read-only parameter shown to clients, NAME=VALUE (repeatable; `mems-stack` passes
    /// its settings).
    #[arg(long = "parameter", value_name = "NAME=VALUE")]
    parameters: Vec<String>,
}

fn main() -> std::process::ExitCode {
    mems_log::init("mems-foxglove");
    mems_log::exit(run(Cli::parse()))
}

fn run(cli: Cli) -> Result<()> {
    ipc_types::stop::install()?;
    let (host, port) = cli
        .listen
        .rsplit_once(':')
        .and_then(|(h, p)| Some((h, p.parse::<u16>().ok()?)))
        .with_context(|| format!("--listen {:?}: expected HOST:PORT", cli.listen))?;
    let settings = Settings::parse(&cli.parameters)?;
    let (listener, inbox) = hints::channel();
    let ctx = foxglove::Context::new();
    // The SDK's server on a private loopback port, behind the front (`subprotocol`).
    let server = foxglove::WebSocketServer::new()
        .name("mems-odometry")
        .bind(Ipv4Addr::LOCALHOST.to_string(), 0)
        .capabilities([Capability::ClientPublish])
        .supported_encodings([hints::ENCODING])
        .listener(Arc::new(listener))
        .parameter_handler(Arc::new(settings))
        .context(&ctx)
        .start_blocking()
        .context("cannot start the WebSocket server")?;
    let front = Front::bind(
        host,
        port,
        SocketAddr::from((Ipv4Addr::LOCALHOST, server.port())),
    )?;
    let mut view = View::new(&ctx, WallClock::now())?;
    tracing::info!("serving ws://{host}:{}", front.port()?);
    front.spawn()?;
    live::serve(
        &mut view,
        &inbox,
        &service::namespace(cli.namespace.as_deref()),
    )?;
    server.stop().wait_blocking();
    Ok(())
}
