//! `mems-stack --config FILE`: the stack's settings in a TOML file (`packaging/mems-stack.toml`
//! is an example). Every flag has a key, its long name without `--` (`sched-fifo = 80`,
//! `record = "run.mcap"`); a switch is `true` or `false`. The file's settings come first and
//! the command line's flags override them (a switch set `true` in the file stays on). A key
//! that is no flag, a value of the wrong kind and a file that is not TOML are refused, naming
//! the file and the key.

use std::ffi::OsString;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use clap::{ArgAction, ArgMatches, CommandFactory};
use toml::Value;

use crate::cli::Cli;

/// The flag naming the file.
pub const FLAG: &str = "config";

/// The command line `args` (program name first) with the settings of its `--config FILE`, if
/// any, as flags before its own.
pub fn expand(args: Vec<OsString>) -> Result<Vec<OsString>> {
    let Some(path) = config_path(&args) else {
        return Ok(args);
    };
    let text = std::fs::read_to_string(&path)
        .with_context(|| format!("--config {}: cannot read", path.display()))?;
    let flags = flags_of(&path, &text)?;
    let mut out = Vec::with_capacity(args.len() + flags.len());
    out.extend(args.first().cloned());
    out.extend(flags.into_iter().map(OsString::from));
    out.extend(args.into_iter().skip(1));
    Ok(out)
}

/// The path given with `--config PATH` or `--config=PATH` (the last one).
fn config_path(args: &[OsString]) -> Option<PathBuf> {
    let long = format!("--{FLAG}");
    let mut found = None;
    let mut iter = args.iter().skip(1);
    while let Some(arg) = iter.next() {
        let arg = arg.to_string_lossy();
        if arg == long {
            found = iter.next().map(PathBuf::from);
        } else if let Some(path) = arg.strip_prefix(&format!("{long}=")) {
            found = Some(PathBuf::from(path));
        }
    }
    found
}

/// The flags `text` (the file at `path`) sets, in the file's order.
fn flags_of(path: &Path, text: &str) -> Result<Vec<String>> {
    let table: toml::Table =
        toml::from_str(text).with_context(|| format!("{}: not a TOML table", path.display()))?;
    let command = Cli::command();
    let mut flags = Vec::new();
    for (key, value) in &table {
        let at = || format!("{}:{}", path.display(), line_of(text, key));
        let Some(arg) = command
            .get_arguments()
            .find(|a| a.get_long() == Some(key.as_str()) && key != FLAG)
        else {
            bail!(
                "{}: unknown key `{key}` (keys are the flags' long names, as in `mems-stack --help`)",
                at()
            );
        };
        let switch = matches!(arg.get_action(), ArgAction::SetTrue);
        match (value, switch) {
            (Value::Boolean(on), true) => {
                if *on {
                    flags.push(format!("--{key}"));
                }
            }
            (Value::String(s), false) => flags.extend([format!("--{key}"), s.clone()]),
            (Value::Integer(i), false) => flags.extend([format!("--{key}"), i.to_string()]),
            (Value::Float(x), false) => flags.extend([format!("--{key}"), x.to_string()]),
            (_, true) => bail!("{}: `{key}` is a switch: true or false, not {value}", at()),
            (_, false) => bail!("{}: `{key}` takes a string or a number, not {value}", at()),
        }
    }
    Ok(flags)
}

/// The 1-based line where `key` is set in `text` (1 if it cannot be found).
fn line_of(text: &str, key: &str) -> usize {
    text.lines()
        .position(|l| {
            l.trim_start()
                .strip_prefix(key)
                .is_some_and(|rest| rest.trim_start().starts_with('='))
        })
        .map_or(1, |i| i + 1)
}

/// Every setting in effect, `NAME=VALUE` (flags given, from the file, or defaults; `--config`
/// itself left out): what `mems-foxglove` shows as parameters.
pub fn settings(matches: &ArgMatches) -> Vec<String> {
    let command = Cli::command();
    let mut out = Vec::new();
    for arg in command.get_arguments() {
        let (Some(long), id) = (arg.get_long(), arg.get_id().as_str()) else {
            continue;
        };
        if long == FLAG {
            continue;
        }
        if matches!(arg.get_action(), ArgAction::SetTrue) {
            out.push(format!("{long}={}", matches.get_flag(id)));
        } else if let Ok(Some(mut values)) = matches.try_get_raw(id) {
            let values: Vec<String> = values
                .by_ref()
                .map(|v| v.to_string_lossy().into())
                .collect();
            out.push(format!("{long}={}", values.join(",")));
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::{FromArgMatches, Parser};

    fn write(name: &str, text: &str) -> (tempfile::TempDir, PathBuf) {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join(name);
        std::fs::write(&path, text).unwrap();
        (dir, path)
    }

    fn parse(args: Vec<OsString>) -> (Cli, ArgMatches) {
        let matches = Cli::command().try_get_matches_from(args).unwrap();
        (Cli::from_arg_matches(&matches).unwrap(), matches)
    }

    #[test]
    fn the_file_sets_every_kind_of_flag_and_flags_override_it() {
        let (_dir, path) = write(
            "stack.toml",
            "rate = 500\nsource = \"sim-spi\"\nduration = 12.5\nmlock = true\nsched-fifo = 80\n",
        );
        let args = |extra: &[&str]| {
            let mut a: Vec<OsString> =
                vec!["mems-stack".into(), "--config".into(), path.clone().into()];
            a.extend(extra.iter().map(OsString::from));
            expand(a).unwrap()
        };
        let (cli, matches) = parse(args(&[]));
        assert_eq!((cli.rate, cli.source.as_str()), (500, "sim-spi"));
        assert_eq!(
            (cli.duration, cli.mlock, cli.sched_fifo),
            (Some(12.5), true, Some(80))
        );
        let settings = settings(&matches);
        for s in [
            "rate=500",
            "source=sim-spi",
            "mlock=true",
            "seed=1",
            "force=false",
        ] {
            assert!(settings.contains(&s.to_string()), "{s} in {settings:?}");
        }
        let (cli, _) = parse(args(&["--rate", "250", "--source", "sim"]));
        assert_eq!((cli.rate, cli.source.as_str()), (250, "sim"));
        assert_eq!(Cli::parse_from(args(&["--rate=100"])).rate, 100);
    }

    #[test]
    fn unknown_keys_and_wrong_kinds_are_refused_naming_file_and_key() {
        let refused = |text: &str| {
            let (_dir, path) = write("bad.toml", text);
            let args = vec![
                "mems-stack".into(),
                format!("--config={}", path.display()).into(),
            ];
            expand(args).unwrap_err().to_string()
        };
        let err = refused("rate = 1000\n\nsorce = \"sim\"\n");
        assert!(err.contains("bad.toml:3: unknown key `sorce`"), "{err}");
        let err = refused("config = \"other.toml\"\n");
        assert!(err.contains("unknown key `config`"), "{err}");
        let err = refused("mlock = 1\n");
        assert!(err.contains("bad.toml:1: `mlock` is a switch"), "{err}");
        let err = refused("rate = [1]\n");
        assert!(err.contains("`rate` takes a string or a number"), "{err}");
        let err = refused("rate = \n");
        assert!(err.contains("bad.toml: not a TOML table"), "{err}");
    }

    #[test]
    fn the_committed_example_parses() {
        let example = concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../../packaging/mems-stack.toml"
        );
        let args = vec!["mems-stack".into(), "--config".into(), example.into()];
        parse(expand(args).unwrap());
    }
}
