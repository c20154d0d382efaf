//! The rules: long files, long functions, import circles.

use std::collections::{BTreeMap, BTreeSet, HashMap};
use std::fmt;
use std::path::{Path, PathBuf};

use syn::visit::Visit;
use syn::{ImplItem, Item, TraitItem, UseTree};

use crate::modules::{Crate, Module, Target, is_cfg_test, load_crate};
use crate::{MAX_FILE_LINES, MAX_FN_LINES};

/// A breach of the house rules.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Finding {
    /// A non-test file over [`MAX_FILE_LINES`] lines.
    LongFile {
        /// The file.
        file: PathBuf,
        /// Its lines.
        lines: usize,
    },
    /// A function over [`MAX_FN_LINES`] lines outside examples and tests.
    LongFunction {
        /// The file.
        file: PathBuf,
        /// Line of its `fn`.
        line: usize,
        /// Its name (`Type::name` for a method).
        name: String,
        /// Its lines.
        lines: usize,
    },
    /// Modules of one crate that import one another in a circle.
    ImportCircle {
        /// The target's root file.
        root: PathBuf,
        /// Each step of the circle: module, the module it imports, and where (file, line).
        steps: Vec<(String, String, PathBuf, usize)>,
    },
}

impl fmt::Display for Finding {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::LongFile { file, lines } => write!(
                f,
                "{}: {lines} lines, more than {MAX_FILE_LINES} (split it by concern)",
                file.display()
            ),
            Self::LongFunction {
                file,
                line,
                name,
                lines,
            } => write!(
                f,
                "{}:{line}: fn {name} is {lines} lines, more than {MAX_FN_LINES} (split it \
                 into steps)",
                file.display()
            ),
            Self::ImportCircle { root, steps } => {
                write!(f, "import circle in the crate of {}:", root.display())?;
                for (from, to, file, line) in steps {
                    write!(f, "\n    {from} -> {to} ({}:{line})", file.display())?;
                }
                Ok(())
            }
        }
    }
}

/// Checks every member crate of the workspace at `root` (its `Cargo.toml`'s
/// `workspace.members`); findings sorted by file.
pub fn check_workspace(root: &Path) -> Result<Vec<Finding>, String> {
    let manifest = root.join("Cargo.toml");
    let text =
        std::fs::read_to_string(&manifest).map_err(|e| format!("{}: {e}", manifest.display()))?;
    let value: toml::Table =
        toml::from_str(&text).map_err(|e| format!("{}: {e}", manifest.display()))?;
    let members = value
        .get("workspace")
        .and_then(|w| w.get("members"))
        .and_then(|m| m.as_array())
        .ok_or_else(|| format!("{}: no workspace.members", manifest.display()))?;
    let mut findings = Vec::new();
    for member in members {
        let member = member
            .as_str()
            .ok_or_else(|| format!("{}: a member is not a string", manifest.display()))?;
        findings.extend(check_crate(&load_crate(&root.join(member))?));
    }
    findings.sort_by(|a, b| format!("{a}").cmp(&format!("{b}")));
    findings.dedup();
    Ok(findings)
}

/// Checks one crate.
pub fn check_crate(krate: &Crate) -> Vec<Finding> {
    let mut findings = Vec::new();
    let mut files: BTreeSet<&Path> = BTreeSet::new();
    for target in &krate.targets {
        for module in target.modules.iter().filter(|m| !m.test) {
            if module.whole_file && files.insert(&module.file) {
                let lines = std::fs::read_to_string(&module.file).map_or(0, |t| t.lines().count());
                if lines > MAX_FILE_LINES {
                    findings.push(Finding::LongFile {
                        file: module.file.clone(),
                        lines,
                    });
                }
            }
            if !target.example {
                long_functions(module, &mut findings);
            }
        }
        findings.extend(circles(target));
    }
    findings
}

/// The lines from `fn` to the closing brace.
fn span_lines(sig: &syn::Signature, block: &syn::Block) -> (usize, usize) {
    let start = sig.fn_token.span.start().line;
    let end = block.brace_token.span.close().end().line;
    (start, end + 1 - start)
}

/// Whether a function is a test (`#[test]` or `#[cfg(test)]`).
fn is_test_fn(attrs: &[syn::Attribute]) -> bool {
    is_cfg_test(attrs) || attrs.iter().any(|a| a.path().is_ident("test"))
}

/// The module's functions over [`MAX_FN_LINES`] lines.
fn long_functions(module: &Module, out: &mut Vec<Finding>) {
    let mut check = |name: String, sig: &syn::Signature, block: &syn::Block| {
        let (line, lines) = span_lines(sig, block);
        if lines > MAX_FN_LINES {
            out.push(Finding::LongFunction {
                file: module.file.clone(),
                line,
                name,
                lines,
            });
        }
    };
    for item in &module.items {
        match item {
            Item::Fn(f) if !is_test_fn(&f.attrs) => {
                check(f.sig.ident.to_string(), &f.sig, &f.block)
            }
            Item::Impl(i) if !is_cfg_test(&i.attrs) => {
                let ty = type_name(&i.self_ty);
                for item in &i.items {
                    if let ImplItem::Fn(f) = item
                        && !is_test_fn(&f.attrs)
                    {
                        check(format!("{ty}::{}", f.sig.ident), &f.sig, &f.block);
                    }
                }
            }
            Item::Trait(t) if !is_cfg_test(&t.attrs) => {
                for item in &t.items {
                    if let TraitItem::Fn(f) = item
                        && let Some(block) = &f.default
                    {
                        check(format!("{}::{}", t.ident, f.sig.ident), &f.sig, block);
                    }
                }
            }
            _ => {}
        }
    }
}

/// The last segment of a type's path (`Writer` for `Writer<'a>`), or `_`.
fn type_name(ty: &syn::Type) -> String {
    match ty {
        syn::Type::Path(p) => p
            .path
            .segments
            .last()
            .map_or_else(|| "_".into(), |s| s.ident.to_string()),
        _ => "_".into(),
    }
}

/// A path named in a module: its segments and the line it is on.
struct Named {
    segments: Vec<String>,
    line: usize,
    /// For a `use` leaf: the name it brings in (`None` for a glob).
    binds: Option<String>,
}

/// Collects the paths a module's items name.
#[derive(Default)]
struct Paths {
    uses: Vec<Named>,
    code: Vec<Named>,
}

impl Paths {
    fn use_tree(&mut self, prefix: &mut Vec<String>, tree: &UseTree) {
        match tree {
            UseTree::Path(p) => {
                prefix.push(p.ident.to_string());
                self.use_tree(prefix, &p.tree);
                prefix.pop();
            }
            UseTree::Name(n) => self.use_leaf(prefix, &n.ident, &n.ident),
            UseTree::Rename(r) => self.use_leaf(prefix, &r.ident, &r.rename),
            UseTree::Glob(g) => self.uses.push(Named {
                segments: prefix.clone(),
                line: g.star_token.spans[0].start().line,
                binds: None,
            }),
            UseTree::Group(g) => {
                for tree in &g.items {
                    self.use_tree(prefix, tree);
                }
            }
        }
    }

    fn use_leaf(&mut self, prefix: &[String], ident: &syn::Ident, binds: &syn::Ident) {
        let mut segments = prefix.to_vec();
        if ident != "self" {
            segments.push(ident.to_string());
        }
        let binds = if binds == "self" {
            prefix.last().cloned()
        } else {
            Some(binds.to_string())
        };
        self.uses.push(Named {
            segments,
            line: ident.span().start().line,
            binds,
        });
    }
}

impl<'ast> Visit<'ast> for Paths {
    fn visit_item_use(&mut self, u: &'ast syn::ItemUse) {
        self.use_tree(&mut Vec::new(), &u.tree);
    }

    fn visit_path(&mut self, p: &'ast syn::Path) {
        if p.segments.len() > 1 {
            self.code.push(Named {
                segments: p.segments.iter().map(|s| s.ident.to_string()).collect(),
                line: p.segments[0].ident.span().start().line,
                binds: None,
            });
        }
        syn::visit::visit_path(self, p);
    }

    fn visit_item_fn(&mut self, f: &'ast syn::ItemFn) {
        if !is_test_fn(&f.attrs) {
            syn::visit::visit_item_fn(self, f);
        }
    }

    fn visit_impl_item_fn(&mut self, f: &'ast syn::ImplItemFn) {
        if !is_test_fn(&f.attrs) {
            syn::visit::visit_impl_item_fn(self, f);
        }
    }
}

/// The dependencies between modules: from, to, and the file and line of the first path.
type Edges = BTreeMap<Vec<String>, BTreeMap<Vec<String>, (PathBuf, usize)>>;

/// A target's module graph: modules by path, and for each the paths it names.
struct Graph<'a> {
    modules: BTreeMap<Vec<String>, &'a Module>,
    paths: HashMap<Vec<String>, Paths>,
}

impl<'a> Graph<'a> {
    fn new(target: &'a Target) -> Self {
        let mut modules = BTreeMap::new();
        let mut paths = HashMap::new();
        for m in target.modules.iter().filter(|m| !m.test) {
            let mut p = Paths::default();
            for item in &m.items {
                p.visit_item(item);
            }
            modules.insert(m.path.clone(), m);
            paths.insert(m.path.clone(), p);
        }
        Self { modules, paths }
    }

    /// Where a path named in module `at` starts: the module its first segments name, and
    /// the rest; `None` for a path outside the crate.
    fn base(&self, at: &[String], segments: &[String]) -> Option<(Vec<String>, usize)> {
        let mut base = at.to_vec();
        let mut k = 0;
        match segments.first().map(String::as_str) {
            Some("crate") => return Some((vec!["crate".into()], 1)),
            Some("self") => k = 1,
            Some("super") => {
                while segments.get(k).is_some_and(|s| s == "super") {
                    base.pop()?;
                    k += 1;
                }
            }
            Some(first) => {
                let mut child = at.to_vec();
                child.push(first.to_string());
                if !self.modules.contains_key(&child) {
                    return None;
                }
            }
            None => return None,
        }
        Some((base, k))
    }

    /// The module a path named in module `at` leads to, following re-exports `depth` deep.
    fn resolve(&self, at: &[String], segments: &[String], depth: usize) -> Option<Vec<String>> {
        let (mut module, k) = self.base(at, segments)?;
        for segment in &segments[k..] {
            let mut child = module.clone();
            child.push(segment.clone());
            if self.modules.contains_key(&child) {
                module = child;
                continue;
            }
            if depth > 0
                && let Some(target) = self.reexport(&module, segment, depth - 1)
            {
                return Some(target);
            }
            break;
        }
        Some(module)
    }

    /// The module whose item `name` module `at` brings in with a `use`.
    fn reexport(&self, at: &[String], name: &str, depth: usize) -> Option<Vec<String>> {
        let named = self.paths.get(at)?;
        named
            .uses
            .iter()
            .find(|u| u.binds.as_deref() == Some(name))
            .and_then(|u| self.resolve(at, &u.segments, depth))
    }

    /// The dependencies between modules that are not one another's ancestors, each with the
    /// file and line of its first path.
    fn edges(&self) -> Edges {
        let mut edges: BTreeMap<_, BTreeMap<_, _>> = BTreeMap::new();
        for (at, named) in &self.paths {
            let file = &self.modules[at].file;
            for n in named.uses.iter().chain(&named.code) {
                let Some(to) = self.resolve(at, &n.segments, 4) else {
                    continue;
                };
                if to.starts_with(at) || at.starts_with(&to) {
                    continue;
                }
                edges
                    .entry(at.clone())
                    .or_default()
                    .entry(to)
                    .or_insert((file.clone(), n.line));
            }
        }
        edges
    }
}

/// The import circles of a target: one circle per strongly connected set of modules.
fn circles(target: &Target) -> Vec<Finding> {
    let graph = Graph::new(target);
    let edges = graph.edges();
    let mut findings = Vec::new();
    let mut reported: BTreeSet<Vec<String>> = BTreeSet::new();
    for start in edges.keys() {
        if reported.contains(start) {
            continue;
        }
        let Some(cycle) = shortest_cycle(&edges, start) else {
            continue;
        };
        reported.extend(cycle.iter().cloned());
        let steps = cycle
            .iter()
            .zip(cycle.iter().cycle().skip(1))
            .map(|(from, to)| {
                let (file, line) = edges[from][to].clone();
                (from.join("::"), to.join("::"), file, line)
            })
            .collect();
        findings.push(Finding::ImportCircle {
            root: target.root.clone(),
            steps,
        });
    }
    findings
}

/// The shortest circle through `start` (breadth-first), its modules in order.
fn shortest_cycle(edges: &Edges, start: &Vec<String>) -> Option<Vec<Vec<String>>> {
    let mut previous: BTreeMap<&Vec<String>, &Vec<String>> = BTreeMap::new();
    let mut queue = std::collections::VecDeque::from([start]);
    while let Some(at) = queue.pop_front() {
        for next in edges.get(at).into_iter().flat_map(|e| e.keys()) {
            if next == start {
                let mut cycle = vec![at.clone()];
                let mut k = at;
                while k != start {
                    k = previous[k];
                    cycle.push(k.clone());
                }
                cycle.reverse();
                return Some(cycle);
            }
            if !previous.contains_key(next) {
                previous.insert(next, at);
                queue.push_back(next);
            }
        }
    }
    None
}
