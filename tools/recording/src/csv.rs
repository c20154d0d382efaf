//! The canonical CSV for raw samples.
//!
//! Header (any column order; `#` lines are comments):
//! - required: `t_s,ax_g,ay_g,az_g`: the sample time in seconds and the specific force in g,
//!   sensor frame;
//! - optional, all three or none: `gx_dps,gy_dps,gz_dps`: angular rate, deg/s, sensor frame;
//! - optional: `temp_c`: die temperature, degC;
//! - optional: `flags` ([`ipc_types::raw_flags`] bits, decimal) and `lost_before` (samples lost
//!   before this one);
//! - optional, all or none: the ground truth of a simulated session ([`TRUTH_COLUMNS`], see
//!   [`Truth`] for frames): `truth_p*_m` position (m), `truth_v*_mps` velocity (m/s),
//!   `truth_q*` attitude quaternion (w, x, y, z), `truth_f*_mps2` ideal specific force (m/s^2),
//!   `truth_w*_rps` ideal angular rate (rad/s), `truth_rest` (0 or 1).
//!
//! `t_s` is `stamps.sample_ns` in seconds, on the same clock and from the same origin as the
//! samples it was written from (`CLOCK_MONOTONIC` for live data, the scenario start for
//! simulations). Times must strictly increase.
//!
//! Reading derives what the file does not hold: `seq` is the row index (from 0); counts are
//! computed from the values at +-2 g and +-250 deg/s (the file holds g and deg/s, the counts are
//! the nearest integers); without a `flags` column, `GYRO_VALID` / `TEMP_VALID` are set when
//! those columns exist (`SATURATED` is not: the counts are derived at a range that need not be
//! the file's; the caller marks clipping, `ipc_types::stream::range`). Stamps other
//! than `sample_ns` are not stored and read back as 0.

use std::io::{BufWriter, Write};
use std::path::Path;

use ipc_types::{RawImuSample, raw_flags};

use crate::error::{Error, ErrorKind, Result};
use crate::text::{self, Columns, Row, Rows, SampleBuilder};
use crate::{Format, LogPolicy, Recording, Truth};

/// Names of the ground-truth columns, in the order the writer puts them.
pub const TRUTH_COLUMNS: [&str; 17] = [
    "truth_px_m",
    "truth_py_m",
    "truth_pz_m",
    "truth_vx_mps",
    "truth_vy_mps",
    "truth_vz_mps",
    "truth_qw",
    "truth_qx",
    "truth_qy",
    "truth_qz",
    "truth_fx_mps2",
    "truth_fy_mps2",
    "truth_fz_mps2",
    "truth_wx_rps",
    "truth_wy_rps",
    "truth_wz_rps",
    "truth_rest",
];

const TIME: &str = "t_s";
const ACCEL: [&str; 3] = ["ax_g", "ay_g", "az_g"];
const GYRO: [&str; 3] = ["gx_dps", "gy_dps", "gz_dps"];
const TEMP: &str = "temp_c";
const FLAGS: &str = "flags";
const LOST: &str = "lost_before";

/// The columns the sample builder names in its errors.
const NAMES: Columns = Columns {
    time: TIME,
    accel: ACCEL,
    gyro: GYRO,
    temp: TEMP,
};

/// Every column the canonical CSV defines.
fn known_columns() -> impl Iterator<Item = &'static str> {
    [TIME]
        .into_iter()
        .chain(ACCEL)
        .chain(GYRO)
        .chain([TEMP, FLAGS, LOST])
        .chain(TRUTH_COLUMNS)
}

/// Whether a header row is the canonical CSV's (it names `t_s`).
pub(crate) fn is_canonical_header(row: &::csv::StringRecord) -> bool {
    row.iter().any(|name| name == TIME)
}

/// Column indices of a canonical CSV's header.
struct Layout {
    names: Vec<String>,
    time: usize,
    accel: [usize; 3],
    gyro: Option<[usize; 3]>,
    temp: Option<usize>,
    flags: Option<usize>,
    lost: Option<usize>,
    truth: Option<[usize; 17]>,
}

impl Layout {
    fn parse(path: &Path, line: u64, header: &::csv::StringRecord) -> Result<Self> {
        let names: Vec<String> = header.iter().map(str::to_owned).collect();
        let at_line = |field: &str, kind| Error::line(path, line, Some(field), kind);
        for (i, name) in names.iter().enumerate() {
            if !known_columns().any(|known| known == name) {
                let known = known_columns().collect::<Vec<_>>().join(",");
                return Err(at_line(name, ErrorKind::UnknownColumn { known }));
            }
            if names[..i].contains(name) {
                return Err(at_line(name, ErrorKind::DuplicateColumn));
            }
        }
        let find = |name: &str| names.iter().position(|n| n == name);
        let require = |name: &str, context| {
            find(name).ok_or_else(|| at_line(name, ErrorKind::MissingColumn { context }))
        };
        // A group of columns must be complete when any of its members is present.
        let group = |group: &[&str], context| -> Result<Option<Vec<usize>>> {
            if group.iter().all(|name| find(name).is_none()) {
                return Ok(None);
            }
            group
                .iter()
                .map(|name| require(name, context))
                .collect::<Result<_>>()
                .map(Some)
        };
        let gyro = group(&GYRO, " (gyro columns are all three or none)")?;
        let truth = group(&TRUTH_COLUMNS, " (truth columns are all or none)")?;
        Ok(Self {
            time: require(TIME, "")?,
            accel: [
                require(ACCEL[0], "")?,
                require(ACCEL[1], "")?,
                require(ACCEL[2], "")?,
            ],
            gyro: gyro.map(|g| [g[0], g[1], g[2]]),
            temp: find(TEMP),
            flags: find(FLAGS),
            lost: find(LOST),
            truth: truth.map(|t| t.try_into().expect("the group has 17 columns")),
            names,
        })
    }
}

/// Reads the rows after a canonical header (already read from `rows` at `header_line`).
pub(crate) fn read_body(
    rows: &mut Rows,
    header_line: u64,
    header: &::csv::StringRecord,
    policy: LogPolicy,
) -> Result<Recording> {
    let path = rows.path().to_path_buf();
    let layout = Layout::parse(&path, header_line, header)?;
    let columns: Vec<&str> = layout.names.iter().map(String::as_str).collect();
    let mut samples = SampleBuilder::new(policy);
    let mut truth = layout.truth.map(|_| Vec::new());
    while let Some((line, row)) = rows.next_row()? {
        text::check_width(&path, line, row, &columns)?;
        let cells = Cells {
            path: &path,
            line,
            columns: &columns,
            row,
        };
        let parsed = cells.sample(&layout)?;
        let t_ns = parsed.t_ns;
        if !samples.push(&path, line, &NAMES, parsed)? {
            continue;
        }
        if let (Some(idx), Some(truth)) = (layout.truth, truth.as_mut()) {
            truth.push(cells.truth(&idx, t_ns)?);
        }
    }
    let (samples, repairs) = samples.finish(&path, truth.as_mut())?;
    Ok(Recording {
        source: path,
        format: Format::CanonicalCsv,
        samples,
        truth,
        truncation: None,
        repairs,
    })
}

/// One data row of a canonical CSV: its cells parsed, errors naming the file, the line and the
/// column.
struct Cells<'a> {
    path: &'a Path,
    line: u64,
    columns: &'a [&'a str],
    row: &'a ::csv::StringRecord,
}

impl Cells<'_> {
    /// The column name and text of cell `i`.
    fn cell(&self, i: usize) -> (&str, &str) {
        (self.columns[i], &self.row[i])
    }

    fn number(&self, i: usize) -> Result<f64> {
        let (column, text) = self.cell(i);
        text::parse_f64(self.path, self.line, column, text)
    }

    fn vector(&self, idx: [usize; 3]) -> Result<[f64; 3]> {
        Ok([
            self.number(idx[0])?,
            self.number(idx[1])?,
            self.number(idx[2])?,
        ])
    }

    /// The row's sample: time, flags, losses, then the values.
    fn sample(&self, layout: &Layout) -> Result<Row> {
        let (time_column, time_text) = self.cell(layout.time);
        let t_ns = text::parse_seconds(self.path, self.line, time_column, time_text)?;
        let flags = layout.flags.map(|i| self.flags(i, layout)).transpose()?;
        let lost_before = match layout.lost {
            Some(i) => {
                let (column, text) = self.cell(i);
                text::parse_uint(
                    self.path,
                    self.line,
                    column,
                    text,
                    "a count (an integer 0..=4294967295)",
                )?
            }
            None => 0,
        };
        Ok(Row {
            t_ns,
            accel_g: self.vector(layout.accel)?,
            gyro_dps: layout.gyro.map(|idx| self.vector(idx)).transpose()?,
            temp_c: layout.temp.map(|i| self.number(i)).transpose()?,
            flags,
            lost_before,
        })
    }

    /// The flags in cell `i`, refused when they mark valid a sensor the file has no columns
    /// for.
    fn flags(&self, i: usize, layout: &Layout) -> Result<u16> {
        let (column, text) = self.cell(i);
        let flags: u16 = text::parse_uint(
            self.path,
            self.line,
            column,
            text,
            "flags (an integer 0..=65535)",
        )?;
        let claims = |bit: u16, present: bool, what: &str| {
            if flags & bit != 0 && !present {
                let message =
                    format!("flags {flags} mark {what} valid, but the file has no {what} columns");
                return Err(Error::line(
                    self.path,
                    self.line,
                    Some(column),
                    ErrorKind::Invalid(message),
                ));
            }
            Ok(())
        };
        claims(raw_flags::GYRO_VALID, layout.gyro.is_some(), "gyro")?;
        claims(raw_flags::TEMP_VALID, layout.temp.is_some(), "temperature")?;
        Ok(flags)
    }

    /// The row's truth, from the cells `idx` of the truth columns.
    fn truth(&self, idx: &[usize; 17], t_ns: u64) -> Result<Truth> {
        let v = |k: usize| self.number(idx[k]);
        let (rest_column, rest_text) = self.cell(idx[16]);
        let at_rest = match rest_text {
            "0" => false,
            "1" => true,
            _ => {
                let kind = ErrorKind::Parse {
                    text: rest_text.to_owned(),
                    expected: "0 or 1",
                };
                return Err(Error::line(self.path, self.line, Some(rest_column), kind));
            }
        };
        Ok(Truth {
            t_ns,
            position_m: [v(0)?, v(1)?, v(2)?],
            velocity_mps: [v(3)?, v(4)?, v(5)?],
            attitude_wxyz: [v(6)?, v(7)?, v(8)?, v(9)?],
            specific_force_mps2: [v(10)?, v(11)?, v(12)?],
            angular_rate_rps: [v(13)?, v(14)?, v(15)?],
            at_rest,
        })
    }
}

/// Reads a canonical CSV file (see the module documentation for the format).
///
/// [`crate::load_raw`] reads this and every other raw format; this function accepts only the
/// canonical CSV.
pub fn read_raw(path: impl AsRef<Path>) -> Result<Recording> {
    let path = path.as_ref();
    let mut rows = Rows::open(path)?;
    let Some((line, header)) = rows.next_row()? else {
        return Err(Error::file(
            path,
            ErrorKind::Invalid("empty file: no header".into()),
        ));
    };
    if !is_canonical_header(header) {
        let kind = ErrorKind::UnknownFormat(format!(
            "the header does not name {TIME:?} (not the canonical CSV)"
        ));
        return Err(Error::line(path, line, None, kind));
    }
    let header = header.clone();
    read_body(&mut rows, line, &header, LogPolicy::Strict)
}

/// Writes samples (and optionally their ground truth, one per sample) as canonical CSV.
///
/// Gyro columns are written when any sample has `GYRO_VALID`, the temperature column when any
/// has `TEMP_VALID`; `flags` and `lost_before` always. Floats are written in Rust's shortest
/// round-trip form and times as exact decimal seconds, so [`read_raw`] gives back identical
/// samples when their `seq` numbers run 0, 1, 2, ..., their counts are the values at +-2 g and
/// +-250 deg/s, and their stamps other than `sample_ns` are 0 (see the module documentation).
///
/// Errors (before anything is written) if the truth does not match the samples one to one in
/// time, if times do not strictly increase or step further than
/// [`ipc_types::limits::MAX_STEP_S`], or if a value is not finite or beyond the sensor's range
/// ([`ipc_types::limits::check_raw`]).
pub fn write_raw(
    path: impl AsRef<Path>,
    samples: &[RawImuSample],
    truth: Option<&[Truth]>,
) -> Result<()> {
    let path = path.as_ref();
    validate_for_writing(path, samples, truth, true)?;
    write_rows(path, samples, truth)
}

/// [`write_raw`] for a logger's CSV: times need only not decrease (a logger that repeats
/// rows or stamps with a coarse host clock), which the strict reader refuses and
/// [`crate::LogPolicy::Repair`] reads.
pub fn write_log(
    path: impl AsRef<Path>,
    samples: &[RawImuSample],
    truth: Option<&[Truth]>,
) -> Result<()> {
    let path = path.as_ref();
    validate_for_writing(path, samples, truth, false)?;
    write_rows(path, samples, truth)
}

/// Writes validated samples and truth: a private file (0600) that replaces any file at `path`
/// once complete (`mems_files::Output`; a symbolic link there is replaced, not followed).
fn write_rows(path: &Path, samples: &[RawImuSample], truth: Option<&[Truth]>) -> Result<()> {
    let gyro = samples.iter().any(|s| s.flags & raw_flags::GYRO_VALID != 0);
    let temp = samples.iter().any(|s| s.flags & raw_flags::TEMP_VALID != 0);

    let mut output = mems_files::Output::create(path, None, mems_files::Existing::Replace)
        .map_err(|e| Error::io(path, e.io))?;
    let file = output.file().try_clone().map_err(|e| Error::io(path, e))?;
    let mut out = ::csv::WriterBuilder::new().from_writer(BufWriter::new(file));
    let mut header: Vec<&str> = vec![TIME];
    header.extend(ACCEL);
    if gyro {
        header.extend(GYRO);
    }
    if temp {
        header.push(TEMP);
    }
    header.extend([FLAGS, LOST]);
    if truth.is_some() {
        header.extend(TRUTH_COLUMNS);
    }
    let csv_error = |e: ::csv::Error| Error::file(path, ErrorKind::Io(e.into()));
    out.write_record(&header).map_err(csv_error)?;
    let mut record: Vec<String> = Vec::with_capacity(header.len());
    for (i, sample) in samples.iter().enumerate() {
        record.clear();
        record.push(crate::error::seconds(sample.stamps.sample_ns));
        record.extend(sample.accel_g.iter().map(f64::to_string));
        if gyro {
            record.extend(sample.gyro_dps.iter().map(f64::to_string));
        }
        if temp {
            record.push(sample.temp_c.to_string());
        }
        record.push(sample.flags.to_string());
        record.push(sample.lost_before.to_string());
        if let Some(truth) = truth {
            let t = &truth[i];
            record.extend(
                t.position_m
                    .iter()
                    .chain(&t.velocity_mps)
                    .chain(&t.attitude_wxyz)
                    .chain(&t.specific_force_mps2)
                    .chain(&t.angular_rate_rps)
                    .map(f64::to_string),
            );
            record.push(u8::from(t.at_rest).to_string());
        }
        out.write_record(&record).map_err(csv_error)?;
    }
    let mut writer = out
        .into_inner()
        .map_err(|e| Error::io(path, e.into_error()))?;
    writer.flush().map_err(|e| Error::io(path, e))?;
    output.commit().map_err(|e| Error::io(path, e.io))
}

/// Checks what [`write_raw`] would otherwise write into a file it cannot read back.
/// With `strict`, times must strictly increase; without, they must not decrease.
fn validate_for_writing(
    path: &Path,
    samples: &[RawImuSample],
    truth: Option<&[Truth]>,
    strict: bool,
) -> Result<()> {
    // Line numbers the rows would have: the header is line 1.
    let fail = |i: usize, field: &str, message: String| {
        Error::line(path, i as u64 + 2, Some(field), ErrorKind::Invalid(message))
    };
    if let Some(truth) = truth
        && truth.len() != samples.len()
    {
        let message = format!(
            "{} truth records for {} samples (the CSV holds one per sample)",
            truth.len(),
            samples.len()
        );
        return Err(Error::file(path, ErrorKind::Invalid(message)));
    }
    for (i, sample) in samples.iter().enumerate() {
        let t_ns = sample.stamps.sample_ns;
        let previous = (i > 0).then(|| samples[i - 1].stamps.sample_ns);
        if previous.is_some_and(|p| t_ns < p || (strict && t_ns == p)) {
            let rule = if strict {
                "strictly increase"
            } else {
                "not decrease"
            };
            return Err(fail(i, TIME, format!("sample {i}: times must {rule}")));
        }
        if previous.is_some_and(|p| t_ns > p.saturating_add(ipc_types::limits::MAX_STEP_NS)) {
            let message = format!(
                "sample {i}: the step from the previous sample exceeds {} s",
                ipc_types::limits::MAX_STEP_S
            );
            return Err(fail(i, TIME, message));
        }
        let gyro = sample.flags & raw_flags::GYRO_VALID != 0;
        let temp = sample.flags & raw_flags::TEMP_VALID != 0;
        if let Err(bad) = ipc_types::limits::check_raw(
            &sample.accel_g,
            gyro.then_some(&sample.gyro_dps),
            temp.then_some(sample.temp_c),
        ) {
            return Err(fail(i, bad.field, format!("sample {i}: {bad}")));
        }
        let mut values = sample
            .accel_g
            .iter()
            .chain(&sample.gyro_dps)
            .chain([&sample.temp_c]);
        if values.any(|v| !v.is_finite()) {
            return Err(fail(
                i,
                "sample",
                format!("sample {i} holds a non-finite value"),
            ));
        }
        if let Some(t) = truth.map(|truth| &truth[i]) {
            if t.t_ns != t_ns {
                let message = format!("truth {i} is at {} ns, its sample at {t_ns} ns", t.t_ns);
                return Err(fail(i, "truth", message));
            }
            let finite = t
                .position_m
                .iter()
                .chain(&t.velocity_mps)
                .chain(&t.attitude_wxyz)
                .chain(&t.specific_force_mps2)
                .chain(&t.angular_rate_rps)
                .all(|v| v.is_finite());
            if !finite {
                return Err(fail(
                    i,
                    "truth",
                    format!("truth {i} holds a non-finite value"),
                ));
            }
        }
    }
    Ok(())
}
