//! `mems-stack`'s command line, and what is checked of it before anything starts.

use std::path::PathBuf;

use acquire::acquisition::SourceSpec;
use anyhow::{Context, Result, bail};
use calibrate::zero_state::DetectorKind;
use clap::Parser;
use odometry::profile::Profile;

#[derive(Parser)]
#[command(version, about, args_override_self = true)]
pub struct Cli {
    /// Read settings from this TOML file first (every flag is a key, its long name: see
    /// `packaging/mems-stack.toml`); flags given here override it.
    #[arg(long, value_name = "FILE")]
    pub config: Option<PathBuf>,
    /// `sim` (the simulated MPU-9250 on simulated I2C), `sim-spi` (the same on simulated SPI),
    /// `i2c:/dev/i2c-N[@0x68]` or `spi:/dev/spidevB.C`.
    #[arg(long, default_value = "sim")]
    pub source: String,
    /// Output rate of the sensor, Hz (1000/n with gyro; 4000 is accelerometer-only and needs
    /// SPI: the odometry then estimates no position and the status line says so).
    #[arg(long, default_value_t = 1000)]
    pub rate: u32,
    /// Record every topic to this MCAP file, checked before anything starts (its directory
    /// must exist and be writable; an existing recording is refused unless `--force`). A
    /// recorder that dies is restarted and continues the run in the file's next segment
    /// (`run.1.mcap`, ...), which the readers and `mems-replay` read with it as one run.
    #[arg(long)]
    pub record: Option<PathBuf>,
    /// Overwrite the recording at `--record` (its successor segments too), once the stack
    /// starts its stages.
    #[arg(long, requires = "record")]
    pub force: bool,
    /// Stop after this many seconds (default: until Ctrl-C).
    #[arg(long)]
    pub duration: Option<f64>,
    /// Calibration file. Required for a real sensor; for `sim` the stack calibrates the
    /// simulated part from simulated six-position and orientation sessions when it is not given.
    #[arg(long)]
    pub calib: Option<PathBuf>,
    /// Zero-state detector of the calibration stage (default: `glrt`, which needs the
    /// gyroscope; above 1000 Hz, where the sensor runs accelerometer-only, `glrt-accel` over a
    /// 0.5 s window). `yu` is the thesis's detector.
    #[arg(long, value_enum)]
    pub detector: Option<DetectorKind>,
    /// Seed of the simulated sensor and its drive.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Namespace prefix for service names (default: $MEMS_NAMESPACE).
    #[arg(long)]
    pub namespace: Option<String>,
    /// Run the acquisition loop under SCHED_FIFO at this priority (1-99), as `mems-acquire
    /// --sched-fifo`. Needs CAP_SYS_NICE or an RLIMIT_RTPRIO of at least PRIO: where it is
    /// refused, acquire fails at start-up and the stack stops with its error.
    #[arg(long, value_name = "PRIO", value_parser = clap::value_parser!(u8).range(1..=99))]
    pub sched_fifo: Option<u8>,
    /// Pin the acquisition process to this CPU core, as `mems-acquire --cpu`.
    #[arg(long, value_name = "N")]
    pub cpu: Option<usize>,
    /// Lock the acquisition process's memory (mlockall), as `mems-acquire --mlock`.
    #[arg(long)]
    pub mlock: bool,
    /// Serve the live topics to the Foxglove app over its WebSocket protocol at HOST:PORT
    /// (`mems-foxglove`; off by default). Use a loopback address unless the network is trusted:
    /// anyone who can connect sees the robot's odometry.
    #[arg(long, value_name = "HOST:PORT")]
    pub foxglove: Option<String>,
    /// Motion profile, passed to `mems-odometry serve --profile` (the names of `mems-odometry
    /// offline --profile`): `auto` (the platform recognized from the first 10 s of motion; the
    /// calibration stage's detector is then the GLRT), `vehicle`, `other`, or `pedestrian` for
    /// a foot-mounted sensor, whose default detector is then SHOE.
    #[arg(long, value_enum, default_value_t)]
    pub profile: Profile,
    /// Every setting in effect, `NAME=VALUE` (`config::settings`), for the live view.
    #[arg(skip)]
    pub settings: Vec<String>,
}

impl Cli {
    /// Refuses, before anything starts (before calibrating: a stack that cannot record must not
    /// start, nor touch a recording), what cannot run: the source and rate ([`check_source`]),
    /// a recording target that exists (unless `--force`) or cannot be written, and a
    /// `--foxglove` address that is not HOST:PORT. Returns the files of an old recording to
    /// remove once the stack starts its stages.
    pub fn check(&self) -> Result<Vec<PathBuf>> {
        check_source(self)?;
        let overwrite = match &self.record {
            Some(out) => recording::segment::check_target(out, self.force)?,
            None => Vec::new(),
        };
        if let Some(addr) = &self.foxglove {
            std::net::ToSocketAddrs::to_socket_addrs(addr.as_str())
                .with_context(|| format!("--foxglove {addr:?}: expected HOST:PORT"))?;
        }
        Ok(overwrite)
    }

    /// `mems-stack ARGS` parsed (the tests' command lines).
    #[cfg(test)]
    pub fn parse_args(args: &[&str]) -> Self {
        Self::try_parse_from(std::iter::once("mems-stack").chain(args.iter().copied())).unwrap()
    }
}

/// The detector of the calibration stage: the one asked for, else the profile's (SHOE for a
/// pedestrian; otherwise, `auto` included, the GLRT, on the accelerometer alone above 1000 Hz,
/// where the sensor samples no gyroscope).
pub fn detector(cli: &Cli) -> DetectorKind {
    match (cli.detector, cli.profile) {
        (Some(d), _) => d,
        (None, Profile::Pedestrian) => DetectorKind::Shoe,
        (None, _) if cli.rate > 1000 => DetectorKind::GlrtAccel,
        (None, Profile::Auto | Profile::Vehicle | Profile::Other | Profile::Walking) => {
            DetectorKind::Glrt
        }
    }
}

/// Refuses, before anything starts, a source that cannot be parsed, a rate its bus cannot
/// carry (acquire's own check, with its arithmetic: 4 kHz needs SPI), and a detector that needs
/// the gyroscope above 1000 Hz, where the sensor runs accelerometer-only.
fn check_source(cli: &Cli) -> Result<()> {
    let source: SourceSpec = cli.source.parse().map_err(anyhow::Error::msg)?;
    source
        .check_rate(cli.rate)
        .map_err(|e| anyhow::anyhow!("--source {} --rate {}: {e}", cli.source, cli.rate))?;
    let d = detector(cli);
    if d.needs_gyro() && cli.rate > 1000 {
        bail!(
            "--detector {} needs the gyroscope, which the sensor does not sample above 1000 Hz \
             (--rate {}): use glrt-accel or yu",
            d.name(),
            cli.rate
        );
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rates_the_bus_cannot_carry_are_refused_before_start() {
        let check = |args: &[&str]| check_source(&Cli::parse_args(args)).map_err(|e| e.to_string());
        let err = check(&["--rate", "4000"]).unwrap_err();
        for needle in [
            "--source sim --rate 4000",
            "400 kHz I2C",
            "108 %",
            "sim-spi",
        ] {
            assert!(err.contains(needle), "{needle:?} missing from: {err}");
        }
        assert!(check(&["--rate", "4000", "--source", "i2c:/dev/i2c-1"]).is_err());
        check(&["--rate", "4000", "--source", "sim-spi"]).unwrap();
        check(&["--rate", "4000", "--source", "spi:/dev/spidev0.0"]).unwrap();
        check(&["--rate", "1000"]).unwrap();
        assert!(check(&["--rate", "3000", "--source", "sim-spi"]).is_err());
        assert!(check(&["--source", "usb"]).is_err());
        let err = check(&[
            "--rate",
            "4000",
            "--source",
            "sim-spi",
            "--detector",
            "glrt",
        ])
        .unwrap_err();
        assert!(err.contains("--detector glrt needs the gyroscope"), "{err}");
        check(&["--rate", "4000", "--source", "sim-spi", "--detector", "yu"]).unwrap();
    }

    #[test]
    fn an_unknown_detector_is_refused_by_the_parser() {
        let err = Cli::try_parse_from(["mems-stack", "--detector", "foo"])
            .err()
            .expect("--detector foo parses");
        assert!(err.to_string().contains("glrt-accel"), "{err}");
    }

    #[test]
    fn a_priority_outside_1_to_99_is_refused_by_the_stack_itself() {
        for bad in ["0", "100"] {
            let err = Cli::try_parse_from(["mems-stack", "--sched-fifo", bad])
                .err()
                .unwrap_or_else(|| panic!("--sched-fifo {bad} accepted"));
            assert!(err.to_string().contains("--sched-fifo"), "{err}");
        }
    }
}
