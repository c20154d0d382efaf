//! Supervision of the stack's child processes: start in pipeline order, restart a child that
//! dies (with back-off), clean up what a killed child left in shared memory, and stop
//! everything in source-first order so that downstream stages drain what is in flight.

use std::path::PathBuf;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

/// How one child is started.
#[derive(Debug, Clone)]
pub struct ChildSpec {
    /// Short name for messages (e.g. "calibrate").
    pub name: String,
    /// The executable.
    pub program: PathBuf,
    /// Its arguments.
    pub args: Vec<String>,
}

/// A supervised child and its restart bookkeeping.
struct Supervised {
    spec: ChildSpec,
    child: Option<Child>,
    started: Instant,
    restarts: u32,
    backoff: Duration,
    restart_at: Option<Instant>,
}

/// What a supervision pass saw.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Event {
    /// A child exited; it will be restarted.
    Exited {
        /// The child's name.
        name: String,
        /// How it ended (exit code or signal).
        status: String,
    },
    /// A child was started again.
    Restarted {
        /// The child's name.
        name: String,
        /// Restarts so far.
        count: u32,
    },
}

/// The supervised children, kept in start order.
pub struct Supervisor {
    children: Vec<Supervised>,
}

const INITIAL_BACKOFF: Duration = Duration::from_millis(200);
const MAX_BACKOFF: Duration = Duration::from_secs(5);
/// A child that ran this long is considered healthy again: its back-off resets.
const HEALTHY_AFTER: Duration = Duration::from_secs(10);

fn spawn(spec: &ChildSpec) -> std::io::Result<Child> {
    Command::new(&spec.program)
        .args(&spec.args)
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::inherit())
        .spawn()
}

fn describe(status: std::process::ExitStatus) -> String {
    use std::os::unix::process::ExitStatusExt;
    match (status.code(), status.signal()) {
        (Some(code), _) => format!("exit code {code}"),
        (None, Some(signal)) => format!("signal {signal}"),
        _ => "unknown status".to_string(),
    }
}

impl Supervisor {
    /// Starts every child in the given order.
    pub fn start(specs: Vec<ChildSpec>) -> std::io::Result<Self> {
        let mut children = Vec::with_capacity(specs.len());
        for spec in specs {
            let child = spawn(&spec).map_err(|e| {
                std::io::Error::new(
                    e.kind(),
                    format!(
                        "cannot start {} ({}): {e}",
                        spec.name,
                        spec.program.display()
                    ),
                )
            })?;
            children.push(Supervised {
                spec,
                child: Some(child),
                started: Instant::now(),
                restarts: 0,
                backoff: INITIAL_BACKOFF,
                restart_at: None,
            });
        }
        Ok(Self { children })
    }

    /// Restart counts by child name, in start order.
    pub fn restarts(&self) -> Vec<(&str, u32)> {
        self.children
            .iter()
            .map(|c| (c.spec.name.as_str(), c.restarts))
            .collect()
    }

    /// Reaps children that exited, cleans up after them, and restarts those whose back-off
    /// has passed. Returns what happened.
    pub fn poll(&mut self) -> Vec<Event> {
        let mut events = Vec::new();
        let mut any_died = false;
        for c in &mut self.children {
            if let Some(child) = c.child.as_mut()
                && let Ok(Some(status)) = child.try_wait()
            {
                c.child = None;
                any_died = true;
                if c.started.elapsed() >= HEALTHY_AFTER {
                    c.backoff = INITIAL_BACKOFF;
                }
                c.restart_at = Some(Instant::now() + c.backoff);
                c.backoff = (c.backoff * 2).min(MAX_BACKOFF);
                events.push(Event::Exited {
                    name: c.spec.name.clone(),
                    status: describe(status),
                });
            }
        }
        if any_died && let Err(e) = ipc_types::service::remove_dead_nodes() {
            eprintln!("mems-stack: {e}");
        }
        for c in &mut self.children {
            if c.child.is_none() && c.restart_at.is_some_and(|t| Instant::now() >= t) {
                match spawn(&c.spec) {
                    Ok(child) => {
                        c.child = Some(child);
                        c.started = Instant::now();
                        c.restart_at = None;
                        c.restarts += 1;
                        events.push(Event::Restarted {
                            name: c.spec.name.clone(),
                            count: c.restarts,
                        });
                    }
                    Err(e) => {
                        eprintln!("mems-stack: cannot restart {}: {e}", c.spec.name);
                        c.restart_at = Some(Instant::now() + c.backoff);
                    }
                }
            }
        }
        events
    }

    /// Stops every child, the last started first (the source is started last, so it stops
    /// first and the stages behind it drain): SIGTERM, then SIGKILL after `grace`.
    pub fn shutdown(mut self, grace: Duration) {
        for c in self.children.iter_mut().rev() {
            let Some(mut child) = c.child.take() else {
                continue;
            };
            // SAFETY: kill(2) on our own child's pid; no memory is involved.
            unsafe {
                libc::kill(child.id() as i32, libc::SIGTERM);
            }
            let deadline = Instant::now() + grace;
            loop {
                match child.try_wait() {
                    Ok(Some(_)) => break,
                    Ok(None) if Instant::now() < deadline => {
                        std::thread::sleep(Duration::from_millis(20));
                    }
                    _ => {
                        eprintln!(
                            "mems-stack: {} did not stop in {grace:?}; killing it",
                            c.spec.name
                        );
                        let _ = child.kill();
                        let _ = child.wait();
                        break;
                    }
                }
            }
        }
        if let Err(e) = ipc_types::service::remove_dead_nodes() {
            eprintln!("mems-stack: {e}");
        }
    }
}
