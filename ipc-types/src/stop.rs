//! Termination that is never forgotten. SIGINT and SIGTERM set a flag that nothing clears
//! ([`install`], [`requested`]); every process loop checks it, and waits with [`sleep`].
//!
//! iceoryx2's own record is not enough: `SignalHandler::last_signal` (iceoryx2-bb-posix 0.10)
//! keeps only the last of the signals it captures (SIGCONT among them), and reading it clears
//! it. Standard signals pending together are delivered lowest number first, so a SIGTERM (15)
//! and a SIGCONT (18) sent to a stopped process arrive in that order and the SIGCONT replaces
//! the request. `Node::wait` also fails on any captured signal interrupting its sleep (a
//! SIGCONT too), which reads as a termination to a loop that stops on its error.

use core::sync::atomic::{AtomicBool, Ordering};
use core::time::Duration;
use std::sync::OnceLock;

use iceoryx2_bb_posix::signal::{NonFatalFetchableSignal, SignalHandler};

use crate::service::ServiceError;

/// Set by the SIGINT/SIGTERM handlers; never cleared.
static REQUESTED: AtomicBool = AtomicBool::new(false);

/// The outcome of the one installation.
static INSTALLED: OnceLock<Result<(), String>> = OnceLock::new();

/// Longest sleep between two looks at the flag in [`sleep`] (a handler does not shorten a
/// sleep: `std::thread::sleep` resumes after EINTR).
const SLICE: Duration = Duration::from_millis(10);

/// Installs the SIGINT/SIGTERM handlers once per process (later calls return the first
/// outcome). iceoryx2 installs its handlers the first time its `SignalHandler` is used, with
/// `sigaction`, replacing whatever was there: it is made to do so first, then signal-hook
/// installs ours over them and chains to them, so iceoryx2 still sees every signal.
pub fn install() -> Result<(), ServiceError> {
    INSTALLED
        .get_or_init(|| {
            // Also keeps a request that arrived before this call.
            if matches!(
                SignalHandler::last_signal(),
                Some(NonFatalFetchableSignal::Interrupt | NonFatalFetchableSignal::Terminate)
            ) {
                REQUESTED.store(true, Ordering::SeqCst);
            }
            for signal in [signal_hook::consts::SIGINT, signal_hook::consts::SIGTERM] {
                signal_hook::flag::register(signal, &REQUESTED)
                    .map_err(|e| format!("cannot install the handler of signal {signal}: {e}"))?;
            }
            Ok(())
        })
        .clone()
        .map_err(ServiceError)
}

/// Whether SIGINT or SIGTERM arrived since [`install`].
pub fn requested() -> bool {
    REQUESTED.load(Ordering::SeqCst)
}

/// Sleeps for `duration`, or until termination is requested (within 10 ms of it); returns
/// whether it was.
pub fn sleep(duration: Duration) -> bool {
    let end = std::time::Instant::now() + duration;
    loop {
        if requested() {
            return true;
        }
        let left = end.saturating_duration_since(std::time::Instant::now());
        if left.is_zero() {
            return false;
        }
        std::thread::sleep(left.min(SLICE));
    }
}
