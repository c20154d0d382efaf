//! What the workspace's tests share.
//!
//! [`shared_data`] finds the background data beside the repository (`../shared`: the thesis's
//! recordings and the real MPU-9250 logs). Outside CI a test without it skips and says so on
//! stderr; in CI (the `CI` environment variable set and not empty, as `.ci/run` and every CI
//! service set it) a missing directory fails the test, so that no thesis-data test passes
//! there without having run.

use std::path::PathBuf;

/// The repository's root (this crate is `tests/support` in it).
fn repository() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// Whether the tests run in CI: `CI` set and not empty.
pub fn in_ci() -> bool {
    std::env::var_os("CI").is_some_and(|v| !v.is_empty())
}

/// `../shared/<relative>` beside the repository when it exists. When it does not: `None`
/// with a line on stderr naming the path (the caller's test skips), or, in CI ([`in_ci`]), a
/// panic naming it.
pub fn shared_data(relative: &str) -> Option<PathBuf> {
    let path = repository().join("../shared").join(relative);
    if path.exists() {
        return Some(path);
    }
    let message = format!(
        "the background data {} is absent (../shared/{relative} beside the repository)",
        path.display()
    );
    assert!(!in_ci(), "{message}: CI is set, so tests that need it fail");
    eprintln!("SKIPPED: {message}; CI=true makes this a failure");
    None
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A path that cannot exist skips outside CI and fails in CI (each case in a child
    /// process, with `CI` set as the case needs).
    #[test]
    fn a_missing_directory_skips_outside_ci_and_fails_in_ci() {
        if let Some(ci) = std::env::var_os("TEST_SUPPORT_CASE") {
            let _ = ci;
            let _ = shared_data("no-such-directory-for-test-support");
            return;
        }
        let exe = std::env::current_exe().unwrap();
        let run = |ci: &str| {
            std::process::Command::new(&exe)
                .args([
                    "--exact",
                    "--nocapture",
                    "tests::a_missing_directory_skips_outside_ci_and_fails_in_ci",
                ])
                .env("TEST_SUPPORT_CASE", "1")
                .env("CI", ci)
                .output()
                .unwrap()
        };
        let outside = run("");
        assert!(outside.status.success());
        assert!(String::from_utf8_lossy(&outside.stderr).contains("SKIPPED"));
        let inside = run("true");
        assert!(!inside.status.success());
        let text =
            String::from_utf8_lossy(&inside.stdout) + String::from_utf8_lossy(&inside.stderr);
        assert!(text.contains("CI is set"), "{text}");
    }
}
