//! A crate's module trees, read from its roots by following `mod` declarations.

use std::path::{Path, PathBuf};

use syn::{Attribute, Item};

/// One module: its path, the file it is in and its own items (an inline child module is a
/// module of its own, not part of its parent's items).
pub struct Module {
    /// `["crate", "a", "b"]` for `crate::a::b`.
    pub path: Vec<String>,
    /// The file holding it.
    pub file: PathBuf,
    /// Whether it is the whole of `file` (not an inline `mod name { ... }`).
    pub whole_file: bool,
    /// Whether it is test code: `#[cfg(test)]`, or inside such a module.
    pub test: bool,
    /// Its items.
    pub items: Vec<Item>,
}

impl Module {
    /// `crate::a::b`.
    pub fn name(&self) -> String {
        self.path.join("::")
    }
}

/// One compilation target of a crate (library, binary, example, build script), its modules
/// in declaration order, the root first.
pub struct Target {
    /// Its root file.
    pub root: PathBuf,
    /// Whether it is an example.
    pub example: bool,
    /// Its modules.
    pub modules: Vec<Module>,
}

/// A crate's targets (integration tests excluded: they are test code).
pub struct Crate {
    /// The crate's directory.
    pub dir: PathBuf,
    /// Its targets.
    pub targets: Vec<Target>,
}

/// Reads the crate in `dir`. Errors name the file that cannot be read or parsed, or the
/// module declaration whose file is missing.
pub fn load_crate(dir: &Path) -> Result<Crate, String> {
    let mut roots: Vec<(PathBuf, bool)> = Vec::new();
    for name in ["src/lib.rs", "src/main.rs", "build.rs"] {
        roots.push((dir.join(name), false));
    }
    for (sub, example) in [("src/bin", false), ("examples", true)] {
        let Ok(entries) = std::fs::read_dir(dir.join(sub)) else {
            continue;
        };
        let mut found: Vec<PathBuf> = entries.filter_map(|e| e.ok().map(|e| e.path())).collect();
        found.sort();
        for path in found {
            if path.is_dir() {
                roots.push((path.join("main.rs"), example));
            } else if path.extension().is_some_and(|e| e == "rs") {
                roots.push((path, example));
            }
        }
    }
    let mut targets = Vec::new();
    for (root, example) in roots.into_iter().filter(|(r, _)| r.is_file()) {
        let mut modules = Vec::new();
        let dir = root.parent().expect("a file has a directory").to_path_buf();
        let items = parse(&root)?;
        walk(
            vec!["crate".into()],
            &root,
            true,
            dir,
            false,
            items,
            &mut modules,
        )?;
        targets.push(Target {
            root,
            example,
            modules,
        });
    }
    Ok(Crate {
        dir: dir.to_path_buf(),
        targets,
    })
}

/// Reads and parses a file.
fn parse(file: &Path) -> Result<Vec<Item>, String> {
    let text = std::fs::read_to_string(file).map_err(|e| format!("{}: {e}", file.display()))?;
    let parsed = syn::parse_file(&text).map_err(|e| {
        let at = e.span().start();
        format!("{}:{}: {e}", file.display(), at.line)
    })?;
    Ok(parsed.items)
}

/// Whether the attributes hold `#[cfg(test)]` (or a `cfg` naming `test`).
pub(crate) fn is_cfg_test(attrs: &[Attribute]) -> bool {
    attrs.iter().any(|a| {
        a.path().is_ident("cfg")
            && a.meta.require_list().is_ok_and(|l| {
                l.tokens
                    .clone()
                    .into_iter()
                    .any(|t| t.to_string() == "test")
            })
    })
}

/// The value of a `#[path = "..."]` attribute.
fn path_attr(attrs: &[Attribute]) -> Option<String> {
    attrs.iter().find_map(|a| match &a.meta {
        syn::Meta::NameValue(nv) if nv.path.is_ident("path") => match &nv.value {
            syn::Expr::Lit(syn::ExprLit {
                lit: syn::Lit::Str(s),
                ..
            }) => Some(s.value()),
            _ => None,
        },
        _ => None,
    })
}

/// Adds the module `path` (in `file`, its children's files under `child_dir`) and its
/// descendants to `out`.
fn walk(
    path: Vec<String>,
    file: &Path,
    whole_file: bool,
    child_dir: PathBuf,
    test: bool,
    items: Vec<Item>,
    out: &mut Vec<Module>,
) -> Result<(), String> {
    let mut children = Vec::new();
    let mut own = Vec::new();
    for item in items {
        match item {
            Item::Mod(m) => children.push(m),
            other => own.push(other),
        }
    }
    out.push(Module {
        path: path.clone(),
        file: file.to_path_buf(),
        whole_file,
        test,
        items: own,
    });
    for m in children {
        let name = m.ident.to_string();
        let mut child_path = path.clone();
        child_path.push(name.clone());
        let child_test = test || is_cfg_test(&m.attrs);
        match m.content {
            Some((_, items)) => walk(
                child_path,
                file,
                false,
                child_dir.join(&name),
                child_test,
                items,
                out,
            )?,
            None => {
                let child_file = match path_attr(&m.attrs) {
                    Some(p) => file.parent().expect("file in a directory").join(p),
                    None => {
                        let flat = child_dir.join(format!("{name}.rs"));
                        if flat.is_file() {
                            flat
                        } else {
                            child_dir.join(&name).join("mod.rs")
                        }
                    }
                };
                if !child_file.is_file() {
                    return Err(format!(
                        "{}: `mod {name};` has no file {}",
                        file.display(),
                        child_file.display()
                    ));
                }
                let grand_dir = if child_file.file_name().is_some_and(|n| n == "mod.rs") {
                    child_file
                        .parent()
                        .expect("file in a directory")
                        .to_path_buf()
                } else {
                    child_dir.join(&name)
                };
                let items = parse(&child_file)?;
                walk(
                    child_path,
                    &child_file,
                    true,
                    grand_dir,
                    child_test,
                    items,
                    out,
                )?;
            }
        }
    }
    Ok(())
}
