//! The stack while it runs: the supervision loop, what it says of the children's exits and
//! restarts, and the live status line.

use std::io::IsTerminal;
use std::time::{Duration, Instant};

use anyhow::Result;

use crate::losses::RecorderLosses;
use crate::monitor::Monitor;
use crate::supervisor::{self, Event, Supervisor};

/// Supervises the children and shows the live status line until SIGINT/SIGTERM, the
/// `duration` (s) since `start`, or a child that keeps failing at start (returned: why).
pub fn supervise(
    supervisor: &mut Supervisor,
    monitor: &mut Monitor,
    recorder_losses: Option<&RecorderLosses>,
    duration: Option<f64>,
    start: Instant,
) -> Result<Option<String>> {
    let mut last_status = Instant::now();
    let tty = std::io::stderr().is_terminal();
    let deadline = duration.map(Duration::from_secs_f64);
    let mut gave_up: Option<String> = None;
    // SIGINT/SIGTERM ends the loop: the clean way out.
    while !ipc_types::stop::sleep(Duration::from_millis(20)) && gave_up.is_none() {
        monitor.drain()?;
        gave_up = announce(supervisor.poll(), tty);
        if last_status.elapsed() >= Duration::from_secs(1) {
            let line = monitor.status(recorder_losses);
            let elapsed = start.elapsed().as_secs_f64();
            let line = match duration {
                Some(total) => format!("{elapsed:.0}/{total:.0} s | {line}"),
                None => format!("{elapsed:.0} s | {line}"),
            };
            // On a terminal one status line, rewritten in place; otherwise a line each time.
            if tty {
                eprint!("\r{line}\x1b[K");
            } else {
                tracing::info!("{line}");
            }
            last_status = Instant::now();
        }
        if deadline.is_some_and(|d| start.elapsed() >= d) {
            break;
        }
    }
    if tty {
        eprintln!();
    }
    Ok(gave_up)
}

/// Says on stderr what the supervisor reports; returns why the stack must stop, if a child
/// keeps failing at start.
fn announce(events: Vec<Event>, tty: bool) -> Option<String> {
    let mut gave_up = None;
    for event in events {
        if tty {
            eprintln!();
        }
        match event {
            Event::Exited { name, status } => {
                tracing::warn!("{name} exited ({status}); restarting");
            }
            Event::Restarted { name, count } => {
                tracing::info!("{name} restarted ({count} so far)");
            }
            Event::GaveUp { name, status } => {
                let why = format!(
                    "{name} exited within {:?} of starting {} times in a row (last: {status}); \
                     not restarting it: see its error above",
                    supervisor::FAST_EXIT,
                    supervisor::MAX_FAST_EXITS
                );
                // The error itself is printed once, as the stack's exit error.
                tracing::info!("{name} keeps failing at start; stopping the stack");
                gave_up.get_or_insert(why);
            }
        }
    }
    gave_up
}
