//! `mems-calibrate fit` as a process on a six-position means file with an absurd entry: a
//! non-zero exit naming the file, the line and the column.

use std::process::Command;

#[test]
fn an_absurd_mean_stops_the_fit_naming_file_line_and_column() {
    let dir = std::env::temp_dir().join(format!("bad-means-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let fit = |spoil: bool| {
        let means = dir.join(if spoil { "means.csv" } else { "clean.csv" });
        let mut text = String::from(
            "x_true (g),x_mean (g),x_std,y_true (g),y_mean (g),y_std,z_true (g),z_mean (g),z_std\n",
        );
        for (axis, sign) in [
            (0, 1.0),
            (0, -1.0),
            (1, 1.0),
            (1, -1.0),
            (2, 1.0),
            (2, -1.0),
        ] {
            let cells: Vec<String> = (0..3)
                .map(|k| {
                    let t: f64 = if k == axis { sign } else { 0.0 };
                    let mean = if spoil && axis == 1 && sign < 0.0 && k == 2 {
                        "1e300".to_owned()
                    } else {
                        format!("{}", t * 1.01 + 0.01 * k as f64)
                    };
                    format!("{t},{mean},0.002")
                })
                .collect();
            text.push_str(&cells.join(","));
            text.push('\n');
        }
        std::fs::write(&means, text).unwrap();
        Command::new(env!("CARGO_BIN_EXE_mems-calibrate-offline"))
            .args(["fit", "--input"])
            .arg(&means)
            .args(["--model", "full", "--force", "--out"])
            .arg(dir.join("fit.toml"))
            .output()
            .unwrap()
    };
    let clean = fit(false);
    assert!(
        clean.status.success(),
        "{}",
        String::from_utf8_lossy(&clean.stderr)
    );
    let out = fit(true);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "exit 0 with {err}");
    for w in ["means.csv:5", "field \"z_mean (g)\"", "1e300"] {
        assert!(err.contains(w), "{w:?} not in: {err}");
    }
    std::fs::remove_dir_all(&dir).unwrap();
}
