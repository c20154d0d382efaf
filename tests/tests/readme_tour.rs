//! The README's tour, run as written: its `sh` block, read from README.md at test time, in a
//! fresh directory laid out like the workspace's (`tools` and `../shared` reachable as the
//! tour expects), with the workspace's binaries first on PATH (the block's first line, which
//! builds them, is replaced by that), a namespace of its own, and the real-data corpus dir
//! empty (the benchmark then lists what is not converted). `bash -e`: every command must
//! succeed; background jobs are killed at the end whatever happens.

use std::path::Path;
use std::process::Command;
use std::time::Duration;

use integration_tests::{Proc, bin, unique_namespace, workspace_root};

/// The tour's first line, which builds the binaries and puts them on PATH.
const BUILD_LINE: &str = "cargo build --release --workspace; export PATH=$PWD/target/release:$PATH";

/// The commands of the README's tour.
fn tour(readme: &str) -> String {
    let section = &readme[readme.find("\n## Tour\n").expect("a Tour section")..];
    let start = section.find("```sh\n").expect("an sh block") + "```sh\n".len();
    let end = start + section[start..].find("\n```").expect("the block's end");
    let block = &section[start..end];
    let (first, rest) = block.split_once('\n').expect("more than one line");
    assert_eq!(first, BUILD_LINE, "the tour's first line changed");
    rest.to_string()
}

#[test]
fn the_readme_tour_runs_as_written() {
    let root = workspace_root();
    let readme = std::fs::read_to_string(root.join("README.md")).unwrap();
    let commands = tour(&readme);
    let ns = unique_namespace("tour");
    let dir = std::env::temp_dir().join(&ns);
    let work = dir.join("work");
    std::fs::create_dir_all(&work).unwrap();
    std::fs::create_dir_all(dir.join("empty-corpus")).unwrap();
    std::os::unix::fs::symlink(root.join("tools"), work.join("tools")).unwrap();
    std::os::unix::fs::symlink(root.join("../shared"), dir.join("shared")).unwrap();

    let bins = bin("mems-stack").parent().unwrap().to_path_buf();
    let script =
        format!("set -euo pipefail\ntrap 'kill $(jobs -p) 2>/dev/null || true' EXIT\n{commands}\n");
    let mut command = Command::new("bash");
    command
        .args(["-c", &script])
        .current_dir(&work)
        .env(
            "PATH",
            format!("{}:{}", bins.display(), std::env::var("PATH").unwrap()),
        )
        .env("MEMS_NAMESPACE", &ns)
        .env("MEMS_REAL_DATA", dir.join("empty-corpus"));
    let (status, stdout) = Proc::start("the README tour", command).wait(Duration::from_secs(1800));
    assert!(status.success(), "the tour failed: {status}\n{stdout}");
    for made in [
        "six.csv",
        "calib.toml",
        "drive.mcap",
        "run.mcap",
        "walk.csv",
        "plots",
    ] {
        assert!(
            Path::new(&work.join(made)).exists(),
            "the tour made no {made}"
        );
    }
    assert!(
        stdout.contains("mems/odometry/state"),
        "mems-info and the Python reader list the recorded odometry:\n{stdout}"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}
