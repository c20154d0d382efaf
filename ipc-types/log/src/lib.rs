//! Diagnostics of every mems-odometry process, in one format on stderr.
//!
//! A process's `main` calls [`init`] with its name first; its diagnostics (progress notes,
//! warnings, refused inputs) are then `tracing` events. Results a user reads as the program's
//! output (summaries, tables, JSON) stay on stdout. [`exit`] ends `main`: a fatal error is
//! printed once and the exit status is 1.
//!
//! Format, one line per event, no timestamps (the stack supervisor passes its children's
//! stderr through, and `journald` or a terminal adds its own times):
//!
//! ```text
//! mems-odometry: aligned at 6.0 s
//! mems-odometry: warning: ../run.csv: truncated after 1200 rows; using what was read
//! mems-odometry: error: cannot load calibration: calib.toml: No such file or directory (os error 2)
//! ```
//!
//! Colour (tracing-subscriber's ANSI styling of field names) is used only when stderr is a
//! terminal, so a file, a pipe or the journal receives plain text.
//!
//! Info lines carry the program's name only; other levels add `warning:`, `error:`, `debug:`
//! or `trace:`; an event's fields follow its message as `key=value`. The level is `info`
//! unless `RUST_LOG` sets another (`RUST_LOG=warn` keeps warnings and errors; per-crate
//! directives such as `RUST_LOG=info,odometry=debug` work as `tracing-subscriber`'s
//! `EnvFilter` documents).
//!
//! A fatal error is `<program>: error: <message>: <cause>: <cause>...` (anyhow's chain on one
//! line), written by [`exit`] whatever `RUST_LOG` says, without a backtrace: the error names
//! the file, line or device at fault, and a backtrace would only bury it.

pub mod progress;

use std::fmt;
use std::io::IsTerminal as _;
use std::process::ExitCode;
use std::sync::OnceLock;

use tracing::{Event, Level, Subscriber};
use tracing_subscriber::EnvFilter;
use tracing_subscriber::fmt::format::Writer;
use tracing_subscriber::fmt::{FmtContext, FormatEvent, FormatFields};
use tracing_subscriber::registry::LookupSpan;

/// The process's name, as [`init`] was given it.
static PROGRAM: OnceLock<&'static str> = OnceLock::new();

/// Installs the stderr subscriber for process `program` (e.g. `"mems-odometry"`): level
/// `info` unless `RUST_LOG` says otherwise. A second call keeps the first subscriber.
pub fn init(program: &'static str) {
    let _ = PROGRAM.set(program);
    let filter = EnvFilter::try_from_default_env().unwrap_or_else(|_| EnvFilter::new("info"));
    let _ = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        .with_ansi(std::io::stderr().is_terminal())
        .event_format(Line { program })
        .try_init();
}

/// The exit status of `main` for `result`: success, or status 1 after printing the error once
/// as `<program>: error: <message>: <causes>`.
pub fn exit(result: anyhow::Result<()>) -> ExitCode {
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            // Not an event: a fatal error is printed whatever the filter.
            eprintln!("{}", fatal_line(program(), &e));
            ExitCode::FAILURE
        }
    }
}

/// The name given to [`init`], or the executable's file name.
fn program() -> &'static str {
    PROGRAM.get_or_init(|| {
        let name = std::env::args_os()
            .next()
            .and_then(|a| {
                std::path::Path::new(&a)
                    .file_name()
                    .map(|n| n.to_string_lossy().into_owned())
            })
            .unwrap_or_default();
        Box::leak(name.into_boxed_str())
    })
}

/// The one line a fatal error is printed as.
fn fatal_line(program: &str, e: &anyhow::Error) -> String {
    format!("{program}: error: {e:#}")
}

/// The event format: `<program>: [<level>: ]<message>[ key=value...]`.
struct Line {
    program: &'static str,
}

impl<S, N> FormatEvent<S, N> for Line
where
    S: Subscriber + for<'a> LookupSpan<'a>,
    N: for<'a> FormatFields<'a> + 'static,
{
    fn format_event(
        &self,
        ctx: &FmtContext<'_, S, N>,
        mut writer: Writer<'_>,
        event: &Event<'_>,
    ) -> fmt::Result {
        write!(writer, "{}: ", self.program)?;
        match *event.metadata().level() {
            Level::INFO => {}
            Level::WARN => write!(writer, "warning: ")?,
            Level::ERROR => write!(writer, "error: ")?,
            Level::DEBUG => write!(writer, "debug: ")?,
            Level::TRACE => write!(writer, "trace: ")?,
        }
        ctx.field_format().format_fields(writer.by_ref(), event)?;
        writeln!(writer)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_fatal_error_is_one_line_with_its_causes() {
        let e = anyhow::anyhow!("No such file or directory (os error 2)")
            .context("cannot load calibration: calib.toml");
        assert_eq!(
            fatal_line("mems-odometry", &e),
            "mems-odometry: error: cannot load calibration: calib.toml: No such file or directory (os error 2)"
        );
    }
}
