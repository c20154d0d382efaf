//! `mems-foxglove [--listen HOST:PORT] [--namespace NS]`: serves the live odometry and
//! corrected samples over Foxglove's WebSocket protocol (see the library for the channels), so
//! the Foxglove app shows the running robot ("Open connection", `ws://HOST:PORT`). Loopback
//! only unless told otherwise; port 0 picks a free port. Prints `mems-foxglove: serving
//! ws://HOST:PORT` on stderr once listening; stops on SIGINT/SIGTERM.

use std::ops::ControlFlow;
use std::time::Duration;

use anyhow::{Context as _, Result};
use clap::Parser;
use ipc_types::wake::{self, WaitMode};
use ipc_types::{CorrectedImuSample, OdometryState, service};
use mems_foxglove::{View, WallClock};

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
    let ctx = foxglove::Context::new();
    let server = foxglove::WebSocketServer::new()
        .name("mems-odometry")
        .bind(host, port)
        .context(&ctx)
        .start_blocking()
        .with_context(|| format!("cannot serve on {}", cli.listen))?;
    let mut view = View::new(&ctx, WallClock::now())?;

    let namespace = service::namespace(cli.namespace.as_deref());
    let node = service::node()?;
    let odometry_name = service::full_name(&namespace, service::ODOMETRY);
    let corrected_name = service::full_name(&namespace, service::CORRECTED);
    let odometry = service::subscriber(&service::open::<OdometryState>(&node, &odometry_name)?)?;
    let corrected = service::subscriber(&service::open::<CorrectedImuSample>(
        &node,
        &corrected_name,
    )?)?;
    let listeners = [
        wake::listener(&node, &odometry_name, WaitMode::Event)?,
        wake::listener(&node, &corrected_name, WaitMode::Event)?,
    ];
    tracing::info!("serving ws://{host}:{}", server.port());
    let step = || -> Result<ControlFlow<(), bool>> {
        let mut any = false;
        while let Some(c) = corrected.receive()? {
            view.corrected(&c)?;
            any = true;
        }
        while let Some(s) = odometry.receive()? {
            view.state(&s)?;
            any = true;
        }
        Ok(ControlFlow::Continue(any))
    };
    wake::serve_loop(&listeners, Duration::from_millis(100), step)?;
    server.stop().wait_blocking();
    Ok(())
}
