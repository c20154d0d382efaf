//! Outputs on real files: an existing path or a planted symbolic link is refused without
//! --force and replaced (never followed) with it; files are 0600, directories 0700; an output
//! never committed leaves nothing.

use std::io::Write;
use std::os::unix::fs::{PermissionsExt, symlink};
use std::path::{Path, PathBuf};

use mems_files::{Existing, Output, create_dir, create_new, private_dir, write};

fn mode(path: &Path) -> u32 {
    path.symlink_metadata().unwrap().permissions().mode() & 0o777
}

/// A fresh private directory for one test.
fn dir(tag: &str) -> (tempfile::TempDir, PathBuf) {
    let dir = private_dir(&format!("mems-files-{tag}-")).unwrap();
    let path = dir.path().to_path_buf();
    (dir, path)
}

#[test]
fn a_new_output_is_private_and_appears_only_when_committed() {
    let (_keep, d) = dir("new");
    let path = d.join("out.csv");
    let mut out = Output::create(&path, Some("--out"), Existing::Refuse).unwrap();
    out.file().write_all(b"a,b\n").unwrap();
    assert!(!path.exists(), "nothing at the path before the commit");
    out.commit().unwrap();
    assert_eq!(std::fs::read(&path).unwrap(), b"a,b\n");
    assert_eq!(mode(&path), 0o600);
    assert_eq!(
        std::fs::read_dir(&d).unwrap().count(),
        1,
        "no temporary file left"
    );

    let failed = Output::create(d.join("failed.csv"), Some("--out"), Existing::Refuse).unwrap();
    drop(failed);
    assert_eq!(
        std::fs::read_dir(&d).unwrap().count(),
        1,
        "a dropped output leaves nothing"
    );
}

#[test]
fn an_existing_path_is_refused_without_force_and_replaced_with_it() {
    let (_keep, d) = dir("exists");
    let path = d.join("calib.toml");
    std::fs::write(&path, "old").unwrap();
    let err = write(&path, Some("--out"), Existing::Refuse, b"new").unwrap_err();
    let text = err.to_string();
    assert!(
        text.contains("--out") && text.contains(&*path.to_string_lossy()),
        "{text}"
    );
    assert!(text.contains("--force"), "{text}");
    assert_eq!(std::fs::read_to_string(&path).unwrap(), "old");
    write(&path, Some("--out"), Existing::Replace, b"new").unwrap();
    assert_eq!(std::fs::read_to_string(&path).unwrap(), "new");
    assert_eq!(mode(&path), 0o600);
}

#[test]
fn a_planted_symlink_is_refused_or_replaced_never_followed() {
    let (_keep, d) = dir("symlink");
    let victim = d.join("victim");
    std::fs::write(&victim, "precious").unwrap();
    let path = d.join("out.mcap");
    symlink(&victim, &path).unwrap();
    let dangling = d.join("dangling.mcap");
    symlink(d.join("nowhere"), &dangling).unwrap();

    for link in [&path, &dangling] {
        let err = write(link, Some("--out"), Existing::Refuse, b"x").unwrap_err();
        assert!(err.to_string().contains("--force"), "{err}");
        let err = create_new(link, Some("--out")).unwrap_err();
        assert!(err.to_string().contains("--force"), "{err}");
    }
    assert!(
        !d.join("nowhere").exists(),
        "the dangling link's target was not created"
    );
    write(&path, Some("--out"), Existing::Replace, b"x").unwrap();
    assert_eq!(std::fs::read_to_string(&victim).unwrap(), "precious");
    assert!(!path.symlink_metadata().unwrap().file_type().is_symlink());
    assert_eq!(std::fs::read_to_string(&path).unwrap(), "x");
}

#[test]
fn files_written_in_place_and_directories_are_private() {
    let (keep, d) = dir("modes");
    assert_eq!(mode(keep.path()), 0o700);
    let file = d.join("run.mcap");
    create_new(&file, None).unwrap();
    assert_eq!(mode(&file), 0o600);
    let plots = d.join("plots/deep");
    create_dir(&plots, Some("--out")).unwrap();
    assert_eq!(mode(&plots), 0o700);
    assert_eq!(mode(&d.join("plots")), 0o700);
    create_dir(&plots, Some("--out")).unwrap();
    let link = d.join("link");
    symlink(&plots, &link).unwrap();
    let err = create_dir(&link, Some("--out")).unwrap_err();
    assert!(err.to_string().contains("symbolic link"), "{err}");
}
