//! The house rules over the workspace's Rust sources, checked by its tests
//! (`cargo test --release -p house-rules`):
//! - no non-test file over [`MAX_FILE_LINES`] lines (test files: under a crate's `tests/`, or
//!   a module declared `#[cfg(test)] mod name;`);
//! - no function over [`MAX_FN_LINES`] lines (from `fn` to its closing brace) outside examples
//!   and tests (`#[test]` functions, `#[cfg(test)]` modules);
//! - no import circle between the modules of a crate: module `a` depends on module `b` when a
//!   path in `a` (a `use` line or a path in the code, starting with `crate::`, `super::`,
//!   `self::` or a child module's name) names `b` or an item `b` defines, followed through one
//!   module's re-exports (`pub use b::Item` in `m` makes `m::Item` name `b`). A module and its
//!   own ancestors are not a circle (a parent declares and re-exports its children; a child
//!   uses what its parent holds), so dependencies between a module and its ancestor are left
//!   out of the graph.
//!
//! Each crate's modules are found from its roots (`src/lib.rs`, `src/main.rs`, `src/bin/*`,
//! `examples/*`, `build.rs`) by following `mod` declarations, so files outside a crate's
//! module tree are not read.

mod modules;
mod rules;

pub use modules::{Crate, Module, load_crate};
pub use rules::{Finding, check_crate, check_workspace};

/// Longest non-test file, lines.
pub const MAX_FILE_LINES: usize = 1000;
/// Longest function outside examples and tests, lines.
pub const MAX_FN_LINES: usize = 100;
