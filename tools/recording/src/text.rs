//! Shared machinery of the CSV readers: a row iterator that knows its file and line numbers,
//! cell parsers that report the column, the exact seconds-to-nanoseconds conversion, and the
//! construction of raw samples from values in sensor units.

use std::fs::File;
use std::io::BufReader;
use std::path::{Path, PathBuf};

use ::csv::{ReaderBuilder, StringRecord, Trim};
use ipc_types::limits;
use ipc_types::stream::{HoleAt, Holes, Step, TimeLine};
use ipc_types::units::{self, AccelRange, GyroRange};
use ipc_types::{RawImuSample, Stamps, raw_flags};

use crate::error::{Error, ErrorKind, Result};
use crate::{LogPolicy, LogRepairs, Truth};

/// Reads a CSV file row by row. Lines starting with `#` are comments and blank lines are
/// skipped; fields are trimmed; rows may have any number of fields (the callers check widths
/// against their headers so that they can name the missing or extra column).
pub(crate) struct Rows {
    path: PathBuf,
    reader: ::csv::Reader<BufReader<File>>,
    record: StringRecord,
}

impl Rows {
    /// Opens `path` for reading.
    pub(crate) fn open(path: &Path) -> Result<Self> {
        let file = File::open(path).map_err(|e| Error::io(path, e))?;
        let reader = ReaderBuilder::new()
            .has_headers(false)
            .flexible(true)
            .trim(Trim::All)
            .comment(Some(b'#'))
            .from_reader(BufReader::new(file));
        Ok(Self {
            path: path.to_path_buf(),
            reader,
            record: StringRecord::new(),
        })
    }

    /// The file being read.
    pub(crate) fn path(&self) -> &Path {
        &self.path
    }

    /// The next row and the 1-based line it starts on, or `None` at the end of the file.
    pub(crate) fn next_row(&mut self) -> Result<Option<(u64, &StringRecord)>> {
        match self.reader.read_record(&mut self.record) {
            Ok(true) => {
                let line = self.record.position().map_or(0, |p| p.line());
                Ok(Some((line, &self.record)))
            }
            Ok(false) => Ok(None),
            Err(e) => {
                let line = e.position().map(|p| p.line());
                let kind = match e.into_kind() {
                    ::csv::ErrorKind::Io(io) => ErrorKind::Io(io),
                    ::csv::ErrorKind::Utf8 { err, .. } => ErrorKind::Invalid(format!(
                        "invalid UTF-8 in field {} (not a text file?)",
                        err.field() + 1
                    )),
                    other => ErrorKind::Invalid(format!("malformed CSV: {other:?}")),
                };
                Err(match line {
                    Some(line) => Error::line(&self.path, line, None, kind),
                    None => Error::file(&self.path, kind),
                })
            }
        }
    }
}

/// Checks that a row has exactly one field per header column, naming the first missing column
/// or the first extra field.
pub(crate) fn check_width(
    path: &Path,
    line: u64,
    row: &StringRecord,
    columns: &[&str],
) -> Result<()> {
    let (expected, found) = (columns.len(), row.len());
    if found < expected {
        let kind = ErrorKind::MissingField { expected, found };
        return Err(Error::line(path, line, Some(columns[found]), kind));
    }
    if found > expected {
        let text = row[expected].to_owned();
        let kind = ErrorKind::ExtraField {
            text,
            expected,
            found,
        };
        return Err(Error::line(path, line, None, kind));
    }
    Ok(())
}

/// Parses a cell as a finite `f64`, naming the column on failure.
pub(crate) fn parse_f64(path: &Path, line: u64, column: &str, text: &str) -> Result<f64> {
    let fail = |kind| Error::line(path, line, Some(column), kind);
    let value: f64 = text.parse().map_err(|_| {
        fail(ErrorKind::Parse {
            text: text.to_owned(),
            expected: "a number",
        })
    })?;
    if value.is_finite() {
        Ok(value)
    } else {
        Err(fail(ErrorKind::NotFinite {
            text: text.to_owned(),
        }))
    }
}

/// Parses a cell as an unsigned integer of type `T`; `expected` describes it for the message.
pub(crate) fn parse_uint<T: std::str::FromStr>(
    path: &Path,
    line: u64,
    column: &str,
    text: &str,
    expected: &'static str,
) -> Result<T> {
    text.parse().map_err(|_| {
        let kind = ErrorKind::Parse {
            text: text.to_owned(),
            expected,
        };
        Error::line(path, line, Some(column), kind)
    })
}

/// Converts a time in seconds (a cell's text) to integer nanoseconds.
///
/// Plain decimals such as `12.345678901` are converted exactly, rounding half up after the
/// ninth fractional digit. This is hand-written because going through `f64` loses whole
/// nanoseconds beyond 2^53 ns (104 days of `CLOCK_MONOTONIC`), and the canonical CSV must
/// round-trip every `u64` time. Other spellings (`1e-3`, `+2.5`) go through `f64` and are
/// rounded to the nearest nanosecond. Negative, non-finite and out-of-range times are errors.
pub(crate) fn parse_seconds(path: &Path, line: u64, column: &str, text: &str) -> Result<u64> {
    let fail = |kind| Error::line(path, line, Some(column), kind);
    let out_of_range = || fail(ErrorKind::Invalid(format!("time {text} s is out of range")));
    let (int, frac) = text.split_once('.').unwrap_or((text, ""));
    let plain = !(int.is_empty() && frac.is_empty())
        && int.bytes().all(|b| b.is_ascii_digit())
        && frac.bytes().all(|b| b.is_ascii_digit());
    if plain {
        let whole: u64 = if int.is_empty() {
            0
        } else {
            int.parse().map_err(|_| out_of_range())?
        };
        let digits = frac.as_bytes();
        let mut nanos = 0u64;
        for i in 0..9 {
            nanos = nanos * 10 + digits.get(i).map_or(0, |d| u64::from(d - b'0'));
        }
        let round_up = u64::from(digits.get(9).is_some_and(|&d| d >= b'5'));
        return whole
            .checked_mul(1_000_000_000)
            .and_then(|ns| ns.checked_add(nanos + round_up))
            .ok_or_else(out_of_range);
    }
    let value = parse_f64(path, line, column, text)?;
    if value < 0.0 {
        return Err(fail(ErrorKind::Invalid(format!(
            "time {text} s is negative"
        ))));
    }
    let ns = (value * 1e9).round();
    // 2^64 as f64 is exact; every smaller non-negative f64 converts without saturating.
    if ns >= 18_446_744_073_709_551_616.0 {
        return Err(out_of_range());
    }
    Ok(ns as u64)
}

/// Builds the raw samples of a recording from rows in sensor units, numbering them and
/// enforcing strictly increasing time, or repairing a real log's repeats and times
/// ([`LogPolicy`]).
pub(crate) struct SampleBuilder {
    samples: Vec<RawImuSample>,
    policy: LogPolicy,
    repeats_dropped: u64,
    /// The time line of the rows so far, and its holes ([`ipc_types::stream`]).
    time: TimeLine,
    holes: Holes,
}

/// The column names a reader reports a row's errors under.
pub(crate) struct Columns<'a> {
    /// The time column.
    pub time: &'a str,
    /// The accelerometer's columns, x, y, z.
    pub accel: [&'a str; 3],
    /// The gyroscope's columns (unused when the file has none).
    pub gyro: [&'a str; 3],
    /// The temperature column (unused when the file has none).
    pub temp: &'a str,
}

impl Columns<'_> {
    /// The column of a field named by [`ipc_types::limits::check_raw`].
    fn of(&self, field: &str) -> &str {
        match field {
            "accel_g[0]" => self.accel[0],
            "accel_g[1]" => self.accel[1],
            "accel_g[2]" => self.accel[2],
            "gyro_dps[0]" => self.gyro[0],
            "gyro_dps[1]" => self.gyro[1],
            "gyro_dps[2]" => self.gyro[2],
            _ => self.temp,
        }
    }
}

/// One row of a raw recording in sensor units, before counts are derived.
pub(crate) struct Row {
    /// Sample time, ns.
    pub t_ns: u64,
    /// Specific force, g, sensor frame.
    pub accel_g: [f64; 3],
    /// Angular rate, deg/s, sensor frame, when the file has it.
    pub gyro_dps: Option<[f64; 3]>,
    /// Die temperature, degC, when the file has it.
    pub temp_c: Option<f64>,
    /// Flags as stored in the file; `None` derives them (validity bits, saturation).
    pub flags: Option<u16>,
    /// Samples lost before this one, as stored in the file (0 when absent).
    pub lost_before: u32,
}

impl SampleBuilder {
    /// An empty recording read with `policy`.
    pub(crate) fn new(policy: LogPolicy) -> Self {
        Self {
            samples: Vec::new(),
            policy,
            repeats_dropped: 0,
            time: TimeLine::default(),
            holes: Holes::default(),
        }
    }

    /// Appends a row read from `line` of `path` (the line and `columns` are used for errors
    /// only); `false` when [`LogPolicy::Repair`] dropped it as a repeat.
    ///
    /// Refuses values the sensor cannot produce ([`ipc_types::limits::check_raw`]) and a time
    /// more than [`ipc_types::limits::MAX_STEP_S`] after the previous row's, whatever the
    /// policy: no repair makes them a measurement.
    ///
    /// Counts are derived from the values at the ranges the thesis and the defaults use:
    /// accel at +-2 g (16384 counts/g), gyro at +-250 deg/s (131 counts/(deg/s)), temperature
    /// by the datasheet formula. Without stored flags, `GYRO_VALID` / `TEMP_VALID` are set when
    /// the row has those values; `SATURATED` is not (the file's range is the caller's to know
    /// or infer: `ipc_types::stream::range`).
    pub(crate) fn push(
        &mut self,
        path: &Path,
        line: u64,
        columns: &Columns,
        row: Row,
    ) -> Result<bool> {
        let time_column = columns.time;
        if let Err(bad) = limits::check_raw(&row.accel_g, row.gyro_dps.as_ref(), row.temp_c) {
            let kind = ErrorKind::OutOfRange(bad);
            return Err(Error::line(path, line, Some(columns.of(bad.field)), kind));
        }
        if let Some(previous) = self.samples.last() {
            let previous_ns = previous.stamps.sample_ns;
            let repair = self.policy == LogPolicy::Repair;
            if row.t_ns > previous_ns.saturating_add(limits::MAX_STEP_NS) {
                let kind = ErrorKind::TimeStep {
                    t_ns: row.t_ns,
                    previous_ns,
                };
                return Err(Error::line(path, line, Some(time_column), kind));
            }
            if repair && is_repeat(previous, &row) {
                self.repeats_dropped += 1;
                return Ok(false);
            }
            let max_back_ns = (crate::MAX_TIME_REPAIR_S * 1e9) as u64;
            let kind =
                if row.t_ns < previous_ns && (!repair || previous_ns - row.t_ns > max_back_ns) {
                    Some(ErrorKind::TimeBackwards {
                        t_ns: row.t_ns,
                        previous_ns,
                    })
                } else if row.t_ns == previous_ns && !repair {
                    Some(ErrorKind::DuplicateTime { t_ns: row.t_ns })
                } else {
                    None
                };
            if let Some(kind) = kind {
                return Err(Error::line(path, line, Some(time_column), kind));
            }
        }
        self.measure_time(line, &row);
        let accel_lsb = AccelRange::G2.lsb_per_g();
        let gyro_lsb = GyroRange::Dps250.lsb_per_dps();
        let accel_counts = row.accel_g.map(|g| units::quantize(g * accel_lsb));
        let gyro_dps = row.gyro_dps.unwrap_or_default();
        let gyro_counts = gyro_dps.map(|w| units::quantize(w * gyro_lsb));
        let temp_c = row.temp_c.unwrap_or_default();
        let temp_counts = row.temp_c.map_or(0, units::temp_counts_from_c);
        // Without stored flags nothing says a value was clipped: the file's range is not the
        // +-2 g and +-250 deg/s the counts are derived at, so the caller marks clipping from
        // the range it knows or infers (`ipc_types::stream::range`).
        let flags = row.flags.unwrap_or_else(|| {
            let mut flags = 0;
            if row.gyro_dps.is_some() {
                flags |= raw_flags::GYRO_VALID;
            }
            if row.temp_c.is_some() {
                flags |= raw_flags::TEMP_VALID;
            }
            flags
        });
        self.samples.push(RawImuSample {
            stamps: Stamps {
                sample_ns: row.t_ns,
                ..Stamps::default()
            },
            seq: self.samples.len() as u64,
            accel_g: row.accel_g,
            gyro_dps,
            temp_c,
            accel_counts,
            gyro_counts,
            temp_counts,
            flags,
            lost_before: row.lost_before,
            undelivered: 0,
        });
        Ok(true)
    }

    /// Measures the row's time against the time line: an unmarked hole before it is counted
    /// with its line.
    fn measure_time(&mut self, line: u64, row: &Row) {
        if let Step::Hole { dt_ns } = self.time.step(row.t_ns)
            && row.lost_before == 0
            && row.flags.is_none_or(|f| f & raw_flags::GAP_BEFORE == 0)
        {
            self.holes.record_at(HoleAt {
                seq: self.samples.len() as u64,
                line: Some(line),
                t_ns: row.t_ns,
                dt_ns,
            });
        }
        if self.time.prev_ns().is_none_or(|p| row.t_ns > p) {
            self.time.accept(row.t_ns);
        }
    }

    /// The finished samples and what was repaired: times that did not increase are rebuilt
    /// from the nominal period (the median, over consecutive distinct times, of their step per
    /// row), in the samples and in `truth` (one per sample) alike.
    pub(crate) fn finish(
        mut self,
        path: &Path,
        truth: Option<&mut Vec<Truth>>,
    ) -> Result<(Vec<RawImuSample>, LogRepairs)> {
        let mut repairs = LogRepairs {
            repeats_dropped: self.repeats_dropped,
            holes: self.holes,
            ..LogRepairs::default()
        };
        let times: Vec<u64> = self.samples.iter().map(|s| s.stamps.sample_ns).collect();
        if times.windows(2).all(|w| w[1] > w[0]) {
            return Ok((self.samples, repairs));
        }
        // The period between consecutive distinct times, per row: a host clock quantised to
        // twice the sample period stamps two rows alike and then steps two periods, so the
        // plain median step would be twice the period.
        let mut steps: Vec<f64> = Vec::new();
        let mut last = (0usize, times[0]);
        for (i, &t) in times.iter().enumerate().skip(1) {
            if t > last.1 {
                steps.push((t - last.1) as f64 / (i - last.0) as f64);
                last = (i, t);
            }
        }
        if steps.is_empty() {
            let kind = ErrorKind::Invalid(
                "no two samples have increasing times: no sample rate to rebuild them from".into(),
            );
            return Err(Error::file(path, kind));
        }
        let mid = steps.len() / 2;
        repairs.period_ns = steps.select_nth_unstable_by(mid, f64::total_cmp).1.round() as u64;
        let mut truth = truth;
        for i in 1..self.samples.len() {
            let previous = self.samples[i - 1].stamps.sample_ns;
            if self.samples[i].stamps.sample_ns <= previous {
                let t_ns = previous + repairs.period_ns;
                self.samples[i].stamps.sample_ns = t_ns;
                if let Some(truth) = truth.as_deref_mut() {
                    truth[i].t_ns = t_ns;
                }
                repairs.times_rebuilt += 1;
            }
        }
        Ok((self.samples, repairs))
    }
}

/// Whether `row` holds exactly the values of `previous` (a repeated read).
fn is_repeat(previous: &RawImuSample, row: &Row) -> bool {
    let gyro_same = match row.gyro_dps {
        Some(g) => previous.flags & raw_flags::GYRO_VALID != 0 && g == previous.gyro_dps,
        None => previous.flags & raw_flags::GYRO_VALID == 0,
    };
    let temp_same = match row.temp_c {
        Some(t) => previous.flags & raw_flags::TEMP_VALID != 0 && t == previous.temp_c,
        None => previous.flags & raw_flags::TEMP_VALID == 0,
    };
    row.accel_g == previous.accel_g && gyro_same && temp_same
}
