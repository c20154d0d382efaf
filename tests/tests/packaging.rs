//! `packaging/mems-stack.service`, the robot's systemd unit: it runs the installed
//! `mems-stack` as a dedicated user, restarts it on failure, and its default flags, with the
//! robot's configuration file `packaging/mems-stack.toml` where it is installed, are ones
//! `mems-stack` accepts.

use integration_tests::{run_ok, workspace_root};

/// The value of `key=` in `unit` (the first such line).
fn value<'a>(unit: &'a str, key: &str) -> &'a str {
    unit.lines()
        .find_map(|l| l.strip_prefix(key)?.strip_prefix('='))
        .unwrap_or_else(|| panic!("no {key}= in the unit"))
}

#[test]
fn the_unit_runs_the_stack_as_its_own_user_with_flags_it_accepts() {
    let unit = std::fs::read_to_string(workspace_root().join("packaging/mems-stack.service"))
        .expect("packaging/mems-stack.service");
    assert_eq!(value(&unit, "ExecStart"), "mems-stack $MEMS_STACK_ARGS");
    assert_eq!(value(&unit, "Restart"), "on-failure");
    assert_eq!(value(&unit, "User"), "mems");
    assert_eq!(value(&unit, "WantedBy"), "multi-user.target");
    let default = value(&unit, "Environment")
        .strip_prefix("\"MEMS_STACK_ARGS=")
        .and_then(|v| v.strip_suffix('"'))
        .expect("Environment=\"MEMS_STACK_ARGS=...\"");
    // The configuration file where the package installs it is the repository's; clap refuses
    // an unknown flag (and the stack an unknown key) before it reaches --help.
    let config = workspace_root().join("packaging/mems-stack.toml");
    let default = default.replace("/etc/mems-stack/mems-stack.toml", config.to_str().unwrap());
    assert!(default.contains("--config"), "{default}");
    let mut args: Vec<&str> = default.split_whitespace().collect();
    args.push("--help");
    assert!(run_ok("mems-stack", &args).contains("Usage: mems-stack"));
}
