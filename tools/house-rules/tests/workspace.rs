//! The workspace keeps the house rules, and the checks find what breaks them.

use std::path::Path;

use house_rules::{Finding, check_crate, check_workspace, load_crate};

/// Every member crate of this workspace: no non-test file over 1,000 lines, no function over
/// 100 lines outside examples and tests, no import circle.
#[test]
fn the_workspace_keeps_the_house_rules() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../..")
        .canonicalize()
        .unwrap();
    let findings = check_workspace(&root).unwrap();
    let list: Vec<String> = findings.iter().map(ToString::to_string).collect();
    assert!(
        findings.is_empty(),
        "{} breaches of the house rules:\n{}",
        findings.len(),
        list.join("\n")
    );
}

fn write(dir: &Path, path: &str, text: &str) {
    let path = dir.join(path);
    std::fs::create_dir_all(path.parent().unwrap()).unwrap();
    std::fs::write(path, text).unwrap();
}

/// A function of `lines` lines (from `fn` to its closing brace).
fn function(name: &str, lines: usize) -> String {
    let body: String = (0..lines - 2)
        .map(|k| format!("    let _x{k} = {k};\n"))
        .collect();
    format!("pub fn {name}() {{\n{body}}}\n")
}

/// A crate that breaks each rule once, beside code each rule leaves alone.
#[test]
fn the_checks_name_each_breach() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    write(
        d,
        "src/lib.rs",
        "mod a;\nmod b;\nmod c;\nmod d;\npub mod outer;\npub use d::Thing;\n#[cfg(test)]\nmod tests;\n",
    );
    // a and b import each other: a circle.
    write(d, "src/a.rs", "use crate::b::B;\npub struct A;\n");
    write(d, "src/b.rs", "pub struct B(pub super::a::A);\n");
    // c imports d's item through the root's re-export, and d names c in its code: a circle.
    write(d, "src/c.rs", "use super::Thing;\npub struct C;\n");
    write(
        d,
        "src/d.rs",
        &format!("pub struct Thing;\n{}", function("fine", 100)),
    );
    let d_extra = "pub fn uses_c() -> crate::c::C { crate::c::C }\n";
    let d_text = std::fs::read_to_string(d.join("src/d.rs")).unwrap() + d_extra;
    write(d, "src/d.rs", &d_text);
    // A parent and its child naming each other is no circle.
    write(
        d,
        "src/outer/mod.rs",
        "mod inner;\npub use inner::Inner;\npub struct Outer;\n",
    );
    write(
        d,
        "src/outer/inner.rs",
        "pub struct Inner(pub super::Outer);\n",
    );
    // Test code may be long.
    let long_test: String = (0..1200).map(|_| "// a test line\n").collect();
    write(
        d,
        "src/tests.rs",
        &(function("long_test_helper", 150) + &long_test),
    );
    // A long file, and a long function in a binary.
    let long_file: String = (0..1001).map(|_| "// a line\n").collect();
    write(
        d,
        "src/main.rs",
        &(long_file + &function("long", 101) + "fn main() {}\n"),
    );
    // Examples may hold long functions (but not long files).
    write(
        d,
        "examples/demo.rs",
        &(function("long_example", 150) + "fn main() {}\n"),
    );
    let findings = check_crate(&load_crate(d).unwrap());
    let text: Vec<String> = findings.iter().map(ToString::to_string).collect();
    let text = text.join("\n");
    assert_eq!(findings.len(), 4, "{text}");
    assert!(
        findings.contains(&Finding::LongFile {
            file: d.join("src/main.rs"),
            lines: 1001 + 101 + 1
        }),
        "{text}"
    );
    assert!(
        findings.iter().any(|f| matches!(f, Finding::LongFunction { name, lines: 101, line: 1002, .. } if name == "long")),
        "{text}"
    );
    assert!(text.contains("crate::a -> crate::b"), "{text}");
    assert!(text.contains("crate::b -> crate::a"), "{text}");
    assert!(text.contains("crate::c -> crate::d"), "{text}");
    assert!(text.contains("crate::d -> crate::c"), "{text}");
    assert!(!text.contains("outer"), "{text}");
    assert!(!text.contains("tests.rs"), "{text}");
    assert!(!text.contains("long_example"), "{text}");
}
