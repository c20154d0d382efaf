//! A mutation fuzzer for the file readers that runs on stable Rust: seed files of each format
//! ([`seeds`]) are mutated ([`mutate`]) and read back by the project's own readers
//! ([`Parser::read`]) under `catch_unwind`, with every single allocation capped
//! (`alloc_count::set_limit`). Every execution is reproducible from the campaign's seed and its
//! index.
//!
//! A run passes when every input gives `Ok` or a one-line error naming its file: no panic, no
//! abort, no allocation over the cap. The binary `parser-fuzz` runs campaigns; `tests/short_run.rs` runs
//! a short one in CI. See `docs/input-checks.md` for the commands and the current figures.

pub mod mutate;
pub mod seeds;

use std::panic::{AssertUnwindSafe, catch_unwind};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering};
use std::time::{Duration, Instant};

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

/// The readers under test.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Parser {
    /// `recording::load_raw_with` on canonical and thesis time-series CSV (strict and repair).
    Csv,
    /// `recording::mcap::read_all` on MCAP recordings (a reported truncation counts as
    /// refused).
    Mcap,
    /// `calibrate::calibfile::CalibrationFile::load` on calibration TOML.
    Calib,
    /// `recording::load_six_position` on six-position means CSV.
    Means,
}

impl Parser {
    /// Every parser, in campaign order.
    pub const ALL: [Parser; 4] = [Parser::Csv, Parser::Mcap, Parser::Calib, Parser::Means];

    /// Its name on the command line.
    pub fn name(self) -> &'static str {
        match self {
            Parser::Csv => "csv",
            Parser::Mcap => "mcap",
            Parser::Calib => "calib",
            Parser::Means => "means",
        }
    }

    /// Reads `path` with the reader under test; `Err` holds the reader's message. `variant`
    /// picks between the reader's modes where it has several (CSV: strict or repair).
    pub fn read(self, path: &Path, variant: u64) -> Result<(), String> {
        let text = |e: &dyn std::fmt::Display| e.to_string();
        match self {
            Parser::Csv => {
                let policy = if variant.is_multiple_of(2) {
                    recording::LogPolicy::Strict
                } else {
                    recording::LogPolicy::Repair
                };
                recording::load_raw_with(path, policy)
                    .map(drop)
                    .map_err(|e| text(&e))
            }
            // A damaged or cut file reads up to the damage and reports it: counted as refused.
            Parser::Mcap => match recording::mcap::read_all(path) {
                Ok(contents) => match contents.truncation {
                    Some(cut) => Err(format!("{}: {cut}", path.display())),
                    None => Ok(()),
                },
                Err(e) => Err(text(&e)),
            },
            Parser::Calib => calibrate::calibfile::CalibrationFile::load(path)
                .map(drop)
                .map_err(|e| text(&e)),
            Parser::Means => recording::load_six_position(path)
                .map(drop)
                .map_err(|e| text(&e)),
        }
    }
}

/// What a campaign found.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Report {
    /// Inputs read.
    pub executions: u64,
    /// Inputs the reader accepted.
    pub accepted: u64,
    /// Inputs refused with an error naming the file, on one line.
    pub refused: u64,
    /// Panics (each a crash), with the first few as `(index, message)`.
    pub panics: u64,
    /// Errors that do not name the file or take more than one line.
    pub unnamed_errors: u64,
    /// The first few failures (panics and unnamed errors): index and message.
    pub failures: Vec<(u64, String)>,
    /// The largest single allocation request, bytes.
    pub largest_allocation: usize,
    /// The slowest execution.
    pub slowest: Duration,
    /// Wall time of the campaign.
    pub wall: Duration,
}

impl Report {
    /// Whether nothing failed.
    pub fn clean(&self) -> bool {
        self.panics == 0 && self.unnamed_errors == 0
    }
}

/// Failures kept in [`Report::failures`].
const KEPT_FAILURES: usize = 5;

/// The execution under way, for the allocation hook's message.
static CURRENT_INDEX: AtomicU64 = AtomicU64::new(0);
static CURRENT_SEED: AtomicU64 = AtomicU64::new(0);
static CURRENT_PARSER: AtomicUsize = AtomicUsize::new(0);

/// Says which input asked for too much before the allocation fails and the process aborts.
fn report_refused_allocation(size: usize) {
    let parser = Parser::ALL[CURRENT_PARSER.load(Ordering::Relaxed)].name();
    tracing::warn!(
        "{parser} input {} of seed {} asked for {size} bytes in one allocation; \
         reproduce with: parser-fuzz --parser {parser} --seed {} --start {} --runs 1 --keep",
        CURRENT_INDEX.load(Ordering::Relaxed),
        CURRENT_SEED.load(Ordering::Relaxed),
        CURRENT_SEED.load(Ordering::Relaxed),
        CURRENT_INDEX.load(Ordering::Relaxed),
    );
}

/// The random source of execution `index` of a campaign with `seed` on `parser`: the same for
/// any campaign that reaches that index, so one input can be replayed alone.
pub fn rng_for(parser: Parser, seed: u64, index: u64) -> ChaCha8Rng {
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ ((parser as u64) << 56));
    rng.set_stream(index);
    rng
}

/// A campaign's settings.
#[derive(Debug, Clone)]
pub struct Campaign {
    /// The reader under test.
    pub parser: Parser,
    /// Seed of the mutations.
    pub seed: u64,
    /// Index of the first execution.
    pub start: u64,
    /// Number of executions.
    pub runs: u64,
    /// Cap on a single allocation, bytes (the process aborts beyond it, after saying which
    /// input asked).
    pub allocation_limit: usize,
    /// Directory for the input file (a tmpfs such as /dev/shm is fastest).
    pub dir: PathBuf,
}

impl Campaign {
    /// Runs the campaign. Panics inside the reader are caught and counted; the panic hook is
    /// silenced for the duration and restored after.
    pub fn run(&self) -> std::io::Result<Report> {
        mems_files::create_dir(&self.dir, Some("--dir")).map_err(|e| e.io)?;
        let path = self.dir.join(format!("input-{}.bin", self.parser.name()));
        // Created here (0600, never through a symbolic link), rewritten for each input.
        match std::fs::remove_file(&path) {
            Err(e) if e.kind() != std::io::ErrorKind::NotFound => return Err(e),
            _ => {}
        }
        let file = mems_files::create_new(&path, None).map_err(|e| e.io)?;
        let seeds = seeds::for_parser(self.parser, &self.dir)?;
        let mut report = Report::default();
        let previous_hook = std::panic::take_hook();
        std::panic::set_hook(Box::new(|_| {}));
        alloc_count::on_refusal(report_refused_allocation);
        CURRENT_SEED.store(self.seed, Ordering::Relaxed);
        CURRENT_PARSER.store(self.parser as usize, Ordering::Relaxed);
        alloc_count::reset_largest();
        let started = Instant::now();
        let mut largest = 0;
        for index in self.start..self.start + self.runs {
            let mut rng = rng_for(self.parser, self.seed, index);
            let input = mutate::mutate(&seeds, &mut rng);
            file.set_len(0)?;
            std::os::unix::fs::FileExt::write_all_at(&file, &input, 0)?;
            CURRENT_INDEX.store(index, Ordering::Relaxed);
            let t0 = Instant::now();
            alloc_count::set_limit(self.allocation_limit);
            let outcome = catch_unwind(AssertUnwindSafe(|| self.parser.read(&path, index)));
            alloc_count::set_limit(usize::MAX);
            report.slowest = report.slowest.max(t0.elapsed());
            largest = largest.max(alloc_count::largest_request());
            alloc_count::reset_largest();
            report.executions += 1;
            let failure = match outcome {
                Ok(Ok(())) => {
                    report.accepted += 1;
                    None
                }
                Ok(Err(message))
                    if message.contains(path.to_str().unwrap_or("")) && !message.contains('\n') =>
                {
                    report.refused += 1;
                    None
                }
                Ok(Err(message)) => {
                    report.unnamed_errors += 1;
                    Some(format!(
                        "error without the file's name or not on one line: {message}"
                    ))
                }
                Err(payload) => {
                    report.panics += 1;
                    let message = payload
                        .downcast_ref::<String>()
                        .cloned()
                        .or_else(|| payload.downcast_ref::<&str>().map(|s| s.to_string()))
                        .unwrap_or_default();
                    Some(format!("panic: {message}"))
                }
            };
            if let Some(failure) = failure
                && report.failures.len() < KEPT_FAILURES
            {
                report.failures.push((index, failure));
            }
        }
        report.wall = started.elapsed();
        report.largest_allocation = largest;
        std::panic::set_hook(previous_hook);
        Ok(report)
    }

    /// The input of execution `index`, as the campaign reads it.
    pub fn input(&self, index: u64) -> std::io::Result<Vec<u8>> {
        let seeds = seeds::for_parser(self.parser, &self.dir)?;
        Ok(mutate::mutate(
            &seeds,
            &mut rng_for(self.parser, self.seed, index),
        ))
    }
}
