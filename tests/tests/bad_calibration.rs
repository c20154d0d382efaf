//! Calibration files that cannot be right stop every process that would run with them, at
//! start: `mems-calibrate serve`, `mems-odometry serve` and `mems-stack` exit with status 1 and
//! one line naming the file and the key, before any sample flows (the files are the refused
//! corpus of the calibration-file fuzzer, `tools/parser-fuzz/corpus/calib-refused/`, each with
//! what its refusal names on its first line).

use std::time::Duration;

use integration_tests::{Proc, path_arg, unique_namespace, workspace_root};

#[test]
fn every_process_refuses_an_implausible_calibration_at_start() {
    let dir = workspace_root().join("tools/parser-fuzz/corpus/calib-refused");
    let mut files: Vec<_> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    files.sort();
    assert!(files.len() >= 9, "{files:?}");
    for file in &files {
        let text = std::fs::read_to_string(file).unwrap();
        let named = text
            .lines()
            .next()
            .unwrap()
            .strip_prefix("# refused: ")
            .unwrap();
        let ns = unique_namespace("bad-calib");
        let calib = path_arg(file);
        let commands: [(&str, Vec<&str>); 3] = [
            (
                "mems-calibrate",
                vec!["serve", "--calib", calib, "--namespace", &ns],
            ),
            (
                "mems-odometry",
                vec!["serve", "--calib", calib, "--namespace", &ns],
            ),
            (
                "mems-stack",
                vec!["--calib", calib, "--duration", "5", "--namespace", &ns],
            ),
        ];
        for (program, args) in commands {
            let log = std::env::temp_dir().join(format!("{ns}-{program}.log"));
            let (status, _) =
                Proc::spawn_logged(program, &args, &log).wait(Duration::from_secs(60));
            let stderr = std::fs::read_to_string(&log).unwrap();
            std::fs::remove_file(&log).unwrap();
            let last = stderr.lines().last().unwrap_or_default();
            assert_eq!(status.code(), Some(1), "{program} {calib}: {stderr}");
            assert!(
                last.starts_with(&format!("{program}: error: "))
                    && last.contains(calib)
                    && last.contains(named),
                "{program} {calib}: {stderr}"
            );
        }
    }
}
