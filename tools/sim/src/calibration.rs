//! How the simulated part is calibrated the way a user calibrates a real one (README's tour):
//! the command lines, as data, for the programs that run them: `mems-stack` for a simulated
//! source without `--calib`, and the integration tests for their calibrated parts.
//!
//! A `mems-sim` six-position session of the datasheet-level MPU-9250 at 200 Hz, fitted with
//! model 3 by `mems-calibrate fit`; then the gyro's scale and misalignment from a session of 16
//! orientations of the same power-on by `mems-odometry gyrocal --into` (the six positions are
//! too few poses for it).

use std::ffi::OsString;
use std::path::{Path, PathBuf};

/// One command: a workspace binary and its arguments.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Step {
    /// The binary's name (`mems-sim`, `mems-calibrate`, `mems-odometry`).
    pub program: &'static str,
    /// Its arguments.
    pub args: Vec<OsString>,
}

/// The commands that calibrate the simulated part, and the files they write.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Recipe {
    /// The commands, to run in order; each must succeed.
    pub steps: Vec<Step>,
    /// The six-position session's recording (CSV).
    pub six_position: PathBuf,
    /// The orientation session's recording (CSV).
    pub orientations: PathBuf,
    /// The calibration file the steps leave.
    pub calib: PathBuf,
}

/// The recipe for the simulated datasheet-level part of power-on `seed` (`mems-sim --seed`),
/// writing its recordings and calibration file into `dir`.
pub fn recipe(dir: &Path, seed: u64) -> Recipe {
    let six_position = dir.join("six-position.csv");
    let orientations = dir.join("orientations.csv");
    let calib = dir.join("calib.toml");
    let seed = seed.to_string();
    let os = |p: &Path| p.as_os_str().to_owned();
    // Both sessions of the same simulated power-on, at 200 Hz.
    let session = |kind: &[&str], out: &Path| Step {
        program: "mems-sim",
        args: kind
            .iter()
            .chain(&["--preset", "datasheet", "--seed", &seed, "--rate", "200"])
            .map(OsString::from)
            .chain(["--out".into(), os(out)])
            .collect(),
    };
    let step = |program, args: &[&dyn AsRef<std::ffi::OsStr>]| Step {
        program,
        args: args.iter().map(|a| a.as_ref().to_owned()).collect(),
    };
    let steps = vec![
        session(&["six-position"], &six_position),
        step(
            "mems-calibrate",
            &[
                &"fit",
                &"--input",
                &six_position,
                &"--model",
                &"full",
                &"--out",
                &calib,
            ],
        ),
        session(&["orientations", "--n", "16"], &orientations),
        step(
            "mems-odometry",
            &[
                &"gyrocal",
                &"--input",
                &orientations,
                &"--calib",
                &calib,
                &"--into",
                &calib,
            ],
        ),
    ];
    Recipe {
        steps,
        six_position,
        orientations,
        calib,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_steps_write_and_read_the_recipes_files() {
        let r = recipe(Path::new("/tmp/x"), 7);
        let line = |s: &Step| {
            let args: Vec<_> = s.args.iter().map(|a| a.to_string_lossy()).collect();
            format!("{} {}", s.program, args.join(" "))
        };
        let lines: Vec<String> = r.steps.iter().map(line).collect();
        assert_eq!(
            lines,
            [
                "mems-sim six-position --preset datasheet --seed 7 --rate 200 --out \
                 /tmp/x/six-position.csv",
                "mems-calibrate fit --input /tmp/x/six-position.csv --model full --out \
                 /tmp/x/calib.toml",
                "mems-sim orientations --n 16 --preset datasheet --seed 7 --rate 200 --out \
                 /tmp/x/orientations.csv",
                "mems-odometry gyrocal --input /tmp/x/orientations.csv --calib /tmp/x/calib.toml \
                 --into /tmp/x/calib.toml",
            ]
        );
        assert_eq!(r.calib, Path::new("/tmp/x/calib.toml"));
    }
}
