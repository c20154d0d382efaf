//! Writes the short-pose sessions of docs/diagnosis.md: for each case of
//! `tests/sim_sessions` (clean, temperature bias, scale nonlinearity, a bias drift through both
//! files of one power-on, a periodic bias no candidate describes), a calibration file (the six
//! positions twice, held 2 s each, from power-on) and a test file (the six positions held 4 s,
//! 10 s later, its stamps on the same clock), as canonical CSV at 200 Hz. Prints one
//! tab-separated line per case: name, what the part has, whether the files share a power-on
//! for the diagnosis (`--same-power-on`), the effect it should select, whether it should
//! report unexplained structure, and the held-out rms a fit with the true model achieves on
//! the test file (m/s^2).
//!
//! ```text
//! cargo run --release -p calibrate-science --example short_pose_sessions -- DIR
//! ```

#[path = "../tests/sim_sessions/mod.rs"]
mod sim_sessions;

use std::path::PathBuf;

use anyhow::{Context, Result};

fn main() -> Result<()> {
    let dir = PathBuf::from(
        std::env::args()
            .nth(1)
            .context("usage: short_pose_sessions DIR (the folder the CSV files go to)")?,
    );
    std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
    for case in sim_sessions::short_cases() {
        let s = sim_sessions::short_pose_sessions(&case);
        for (part, samples) in [("calib", &s.calib), ("test", &s.test)] {
            let path = dir.join(format!("{}-{part}.csv", case.name));
            recording::csv::write_raw(&path, samples, None)?;
        }
        println!(
            "{}\t{}\t{}\t{}\t{}\t{:.5}",
            case.name,
            case.what,
            case.same_power_on,
            case.effect.map_or("none", |e| e.name()),
            case.unexplained,
            s.true_rms_mps2
        );
    }
    Ok(())
}
