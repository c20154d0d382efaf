//! Supervision of the stack's child processes: start in pipeline order, restart a child that
//! dies (with back-off, or at once if it asks so and ran for [`FAST_EXIT`]), clean up what a
//! killed child left in shared memory, give up on a child that keeps failing right after it
//! starts (a configuration error, such as SCHED_FIFO refused, that no restart can fix), and
//! stop everything in source-first order so that downstream stages drain what is in flight.
//! Every child is killed by the kernel when the stack dies, however it dies
//! (`PR_SET_PDEATHSIG`), so no stage outlives a kill -9'd stack.

use std::io::BufRead;
use std::path::PathBuf;
use std::process::{Child, Command, Stdio};
use std::sync::Arc;
use std::time::{Duration, Instant};

/// Receives each line a child prints on its standard output (from a thread of its own).
pub type LineSink = Arc<dyn Fn(&str) + Send + Sync>;

/// How one child is started.
#[derive(Clone)]
pub struct ChildSpec {
    /// Short name for messages (e.g. "calibrate").
    pub name: String,
    /// The executable.
    pub program: PathBuf,
    /// Its arguments.
    pub args: Vec<String>,
    /// Restart it at once when it dies after running for [`FAST_EXIT`] (the back-off still
    /// applies to fast exits). For the recorder, whose downtime is a gap in the recording;
    /// a publishing stage waits for the back-off, so that the recorder sees its publisher
    /// gone before the new one appears.
    pub restart_at_once: bool,
    /// Where its standard output goes, line by line; `None` discards it.
    pub stdout: Option<LineSink>,
}

/// A supervised child and its restart bookkeeping.
struct Supervised {
    spec: ChildSpec,
    child: Option<Child>,
    started: Instant,
    restarts: u32,
    /// Consecutive exits within [`FAST_EXIT`] of starting.
    fast_exits: u32,
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
    /// A child exited within [`FAST_EXIT`] of starting [`MAX_FAST_EXITS`] times in a row: it is
    /// not restarted again.
    GaveUp {
        /// The child's name.
        name: String,
        /// How its last run ended (exit code or signal).
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
/// An exit this soon after starting counts as a failure to start (a child that ran longer and
/// then crashed is restarted however often that happens).
pub const FAST_EXIT: Duration = Duration::from_secs(2);
/// Consecutive fast exits after which a child is given up on. With the back-off of 0.2 s and
/// 0.4 s between them, a child that cannot start is given up on within about 5 s.
pub const MAX_FAST_EXITS: u32 = 3;

fn spawn(spec: &ChildSpec) -> std::io::Result<Child> {
    use std::os::unix::process::CommandExt;
    let mut command = Command::new(&spec.program);
    command
        .args(&spec.args)
        .stdin(Stdio::null())
        .stdout(if spec.stdout.is_some() {
            Stdio::piped()
        } else {
            Stdio::null()
        })
        .stderr(Stdio::inherit());
    // SAFETY: the closure runs in the forked child before exec and calls only prctl(2) and
    // getppid(2), which are async-signal-safe; it touches no memory of the parent.
    unsafe { command.pre_exec(die_with_parent(std::process::id())) };
    let mut child = command.spawn()?;
    if let (Some(sink), Some(out)) = (spec.stdout.clone(), child.stdout.take()) {
        // Ends when the child's end of the pipe closes (it exited).
        std::thread::spawn(move || {
            for line in std::io::BufReader::new(out).lines() {
                let Ok(line) = line else { break };
                sink(&line);
            }
        });
    }
    Ok(child)
}

/// The child's side of "dies with the stack": SIGKILL (not SIGTERM: a stopped or blocked child
/// must die too) when the thread that forked it exits, which for the stack is its main thread
/// and so the stack itself (prctl(2), PR_SET_PDEATHSIG). If the stack died between the fork and
/// the prctl, the child has already been re-parented and must not start at all.
fn die_with_parent(parent: u32) -> impl FnMut() -> std::io::Result<()> + Send + Sync + 'static {
    move || {
        // SAFETY: prctl(PR_SET_PDEATHSIG) and getppid have no memory-safety preconditions.
        unsafe {
            if libc::prctl(libc::PR_SET_PDEATHSIG, libc::SIGKILL) != 0 {
                return Err(std::io::Error::last_os_error());
            }
            if libc::getppid() as u32 != parent {
                return Err(std::io::Error::other(
                    "mems-stack died before its child started",
                ));
            }
        }
        Ok(())
    }
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
                fast_exits: 0,
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
    /// has passed; a child that exited within [`FAST_EXIT`] of starting [`MAX_FAST_EXITS`]
    /// times in a row is given up on instead ([`Event::GaveUp`], never restarted). Returns what
    /// happened.
    pub fn poll(&mut self) -> Vec<Event> {
        let mut events = Vec::new();
        let mut any_died = false;
        for c in &mut self.children {
            if let Some(child) = c.child.as_mut()
                && let Ok(Some(status)) = child.try_wait()
            {
                c.child = None;
                any_died = true;
                let ran = c.started.elapsed();
                if ran >= HEALTHY_AFTER {
                    c.backoff = INITIAL_BACKOFF;
                }
                c.fast_exits = if ran < FAST_EXIT { c.fast_exits + 1 } else { 0 };
                let (name, status) = (c.spec.name.clone(), describe(status));
                if c.fast_exits >= MAX_FAST_EXITS {
                    events.push(Event::GaveUp { name, status });
                    continue;
                }
                if ran >= FAST_EXIT && c.spec.restart_at_once {
                    c.restart_at = Some(Instant::now());
                } else {
                    c.restart_at = Some(Instant::now() + c.backoff);
                    c.backoff = (c.backoff * 2).min(MAX_BACKOFF);
                }
                events.push(Event::Exited { name, status });
            }
        }
        if any_died && let Err(e) = ipc_types::service::remove_dead_nodes() {
            tracing::warn!("{e}");
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
                        tracing::warn!("cannot restart {}: {e}", c.spec.name);
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
                        tracing::warn!("{} did not stop in {grace:?}; killing it", c.spec.name);
                        let _ = child.kill();
                        let _ = child.wait();
                        break;
                    }
                }
            }
        }
        if let Err(e) = ipc_types::service::remove_dead_nodes() {
            tracing::warn!("{e}");
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Polls until `done` says so or `limit` passes, collecting every event.
    fn poll_until(
        s: &mut Supervisor,
        limit: Duration,
        done: impl Fn(&[Event]) -> bool,
    ) -> Vec<Event> {
        let start = Instant::now();
        let mut events = Vec::new();
        while start.elapsed() < limit && !done(&events) {
            events.extend(s.poll());
            std::thread::sleep(Duration::from_millis(10));
        }
        events
    }

    fn shell(name: &str, script: &str) -> ChildSpec {
        ChildSpec {
            name: name.into(),
            program: "/bin/sh".into(),
            args: vec!["-c".into(), script.into()],
            restart_at_once: false,
            stdout: None,
        }
    }

    #[test]
    fn a_child_that_fails_at_once_every_time_is_given_up_after_three_tries() {
        let mut s = Supervisor::start(vec![shell("broken", "exit 3")]).unwrap();
        let events = poll_until(&mut s, Duration::from_secs(8), |e| {
            e.iter().any(|e| matches!(e, Event::GaveUp { .. }))
        });
        let exited = |status: &str| Event::Exited {
            name: "broken".into(),
            status: status.into(),
        };
        let restarted = |count| Event::Restarted {
            name: "broken".into(),
            count,
        };
        assert_eq!(
            events,
            vec![
                exited("exit code 3"),
                restarted(1),
                exited("exit code 3"),
                restarted(2),
                Event::GaveUp {
                    name: "broken".into(),
                    status: "exit code 3".into()
                },
            ]
        );
        // Given up means never started again, however long the back-off would have been.
        let later = poll_until(&mut s, MAX_BACKOFF + Duration::from_millis(500), |_| false);
        assert!(later.is_empty(), "{later:?}");
        assert_eq!(s.restarts(), vec![("broken", 2)]);
        s.shutdown(Duration::from_secs(1));
    }

    #[test]
    fn a_healthy_peer_keeps_running_while_another_child_is_given_up() {
        let mut s = Supervisor::start(vec![
            shell("healthy", "sleep 30"),
            shell("broken", "exit 1"),
        ])
        .unwrap();
        let events = poll_until(&mut s, Duration::from_secs(8), |e| {
            e.iter().any(|e| matches!(e, Event::GaveUp { .. }))
        });
        assert!(
            events.iter().all(|e| !format!("{e:?}").contains("healthy")),
            "{events:?}"
        );
        assert!(
            s.children[0].child.is_some(),
            "the healthy child still runs"
        );
        assert_eq!(s.restarts(), vec![("healthy", 0), ("broken", 2)]);
        s.shutdown(Duration::from_secs(1));
    }
}
