//! The house's structure, checked from the source text (issue 29): no import cycles between the
//! files of protocol, runtime, ffi and trainer; the trainer's and the runtime's modules import only
//! from their own layer or below, as docs/DESIGN.md §1 states the layers (no import points
//! upward, in the trainer or the runtime); every "DESIGN §N" citation names a section that
//! exists, and every path DESIGN cites from the repository's root exists.
//!
//! An import is a path that starts with `crate::`, `super::` or `self::` in product code (a
//! module's `#[cfg(test)]` items and `tests.rs` files are left out: tests may reach anywhere). It
//! points at the deepest file the path names; a module's own `mod.rs` re-exporting its children
//! is its face, not an import, so arrows from a module file down into its own folder are not
//! counted.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// A source file's module path: `src/a/b.rs` → [a, b]; `src/a/mod.rs` → [a]; `src/lib.rs` → [].
fn module_path(src: &Path, file: &Path) -> Vec<String> {
    let rel = file.strip_prefix(src).unwrap();
    let mut parts: Vec<String> = rel.iter().map(|p| p.to_string_lossy().into_owned()).collect();
    let last = parts.pop().unwrap();
    let stem = last.trim_end_matches(".rs");
    if stem != "mod" && stem != "lib" && stem != "main" {
        parts.push(stem.to_string());
    }
    parts
}

fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    let mut entries: Vec<_> = std::fs::read_dir(dir).unwrap().map(|e| e.unwrap().path()).collect();
    entries.sort();
    for path in entries {
        if path.is_dir() {
            if path.file_name().unwrap() != "tests" {
                rust_files(&path, out);
            }
        } else if path.extension().is_some_and(|e| e == "rs") && path.file_name().unwrap() != "tests.rs" {
            out.push(path);
        }
    }
}

/// The text without comments and without `#[cfg(test)]` items (brace-matched).
fn product_code(text: &str) -> String {
    let mut code = String::new();
    let mut chars = text.chars().peekable();
    let mut in_string = false;
    while let Some(c) = chars.next() {
        if in_string {
            code.push(c);
            if c == '\\' {
                if let Some(n) = chars.next() {
                    code.push(n);
                }
            } else if c == '"' {
                in_string = false;
            }
            continue;
        }
        match (c, chars.peek()) {
            ('/', Some('/')) => {
                for n in chars.by_ref() {
                    if n == '\n' {
                        code.push('\n');
                        break;
                    }
                }
            }
            ('/', Some('*')) => {
                chars.next();
                let mut prev = ' ';
                for n in chars.by_ref() {
                    if prev == '*' && n == '/' {
                        break;
                    }
                    prev = n;
                }
            }
            ('"', _) => {
                in_string = true;
                code.push(c);
            }
            _ => code.push(c),
        }
    }
    // Drop each `#[cfg(test)]` item: up to its first `;` at depth 0 or its matching `}`.
    let mut out = String::new();
    let mut rest = code.as_str();
    while let Some(at) = rest.find("#[cfg(test)]") {
        out.push_str(&rest[..at]);
        let item = &rest[at + "#[cfg(test)]".len()..];
        let mut depth = 0usize;
        let mut end = item.len();
        for (i, ch) in item.char_indices() {
            match ch {
                '{' => depth += 1,
                '}' => {
                    depth -= 1;
                    if depth == 0 {
                        end = i + 1;
                        break;
                    }
                }
                ';' if depth == 0 => {
                    end = i + 1;
                    break;
                }
                _ => {}
            }
        }
        rest = &item[end..];
    }
    out.push_str(rest);
    out
}

fn is_ident(c: char) -> bool {
    c.is_ascii_alphanumeric() || c == '_'
}

/// Every path the use tree or inline path at the start of `text` spells (`text` begins just after
/// the first `::`), each appended to `prefix`.
fn expand_paths(prefix: Vec<String>, text: &str, out: &mut Vec<Vec<String>>) {
    let text = text.trim_start();
    if let Some(group) = text.strip_prefix('{') {
        let mut depth = 0usize;
        let mut item_start = 0;
        for (i, ch) in group.char_indices() {
            match ch {
                '{' => depth += 1,
                '}' if depth == 0 => {
                    expand_paths(prefix.clone(), &group[item_start..i], out);
                    return;
                }
                '}' => depth -= 1,
                ',' if depth == 0 => {
                    expand_paths(prefix.clone(), &group[item_start..i], out);
                    item_start = i + 1;
                }
                _ => {}
            }
        }
        return;
    }
    let ident: String = text.chars().take_while(|&c| is_ident(c)).collect();
    if ident.is_empty() || ident == "self" {
        if !prefix.is_empty() {
            out.push(prefix);
        }
        return;
    }
    let mut path = prefix;
    path.push(ident.clone());
    let after = &text[ident.len()..];
    match after.strip_prefix("::") {
        Some(more) => expand_paths(path, more, out),
        None => out.push(path),
    }
}

/// The absolute module paths a file's product code names.
fn imports(module: &[String], code: &str) -> Vec<Vec<String>> {
    let mut found = Vec::new();
    for (i, _) in code.match_indices("::") {
        // The path's first segment ends here: read it backwards.
        let head: String = code[..i].chars().rev().take_while(|&c| is_ident(c)).collect::<String>().chars().rev().collect();
        let before = code[..i - head.len()].chars().next_back();
        if before.is_some_and(|c| is_ident(c) || c == ':') {
            continue; // not the first segment of a path
        }
        let base: Vec<String> = match head.as_str() {
            "crate" => Vec::new(),
            "self" => module.to_vec(),
            "super" => {
                let mut base = module.to_vec();
                base.pop();
                base
            }
            _ => continue,
        };
        let mut paths = Vec::new();
        expand_paths(Vec::new(), &code[i + 2..], &mut paths);
        for p in paths {
            let mut full = base.clone();
            let mut segments = p.into_iter().peekable();
            while segments.peek().is_some_and(|s| s == "super") {
                segments.next();
                full.pop();
            }
            full.extend(segments);
            found.push(full);
        }
    }
    found
}

struct Crate {
    /// module path → file (relative to the repository).
    files: BTreeMap<Vec<String>, String>,
    /// file → the files it imports.
    arrows: BTreeMap<String, BTreeSet<String>>,
}

fn read_crate(dir: &str) -> Crate {
    let src = repo().join(dir).join("src");
    let mut paths = Vec::new();
    rust_files(&src, &mut paths);
    let name = |p: &Path| p.strip_prefix(repo()).unwrap().to_string_lossy().into_owned();
    let mut files = BTreeMap::new();
    for p in &paths {
        if p.file_name().unwrap() != "main.rs" {
            files.insert(module_path(&src, p), name(p));
        }
    }
    let mut arrows = BTreeMap::new();
    for p in &paths {
        if p.file_name().unwrap() == "main.rs" {
            continue; // a binary: it imports the library by name, not through `crate::`
        }
        let module = module_path(&src, p);
        let is_module_file = matches!(p.file_name().unwrap().to_str(), Some("mod.rs" | "lib.rs"));
        let code = product_code(&std::fs::read_to_string(p).unwrap());
        let mut to = BTreeSet::new();
        for path in imports(&module, &code) {
            // The deepest file the path names.
            let target = (0..=path.len()).rev().find_map(|k| files.get(&path[..k]).map(|f| (k, f)));
            let Some((k, target)) = target else { continue };
            let target_module = &path[..k];
            let own = target == &name(p);
            let into_own_folder = is_module_file && target_module.starts_with(&module) && target_module.len() > module.len();
            if !own && !into_own_folder {
                to.insert(target.clone());
            }
        }
        arrows.insert(name(p), to);
    }
    Crate { files, arrows }
}

/// The strongly connected components with more than one file (Tarjan).
fn cycles(arrows: &BTreeMap<String, BTreeSet<String>>) -> Vec<Vec<String>> {
    struct State<'a> {
        arrows: &'a BTreeMap<String, BTreeSet<String>>,
        index: BTreeMap<&'a str, usize>,
        low: BTreeMap<&'a str, usize>,
        stack: Vec<&'a str>,
        on_stack: BTreeSet<&'a str>,
        out: Vec<Vec<String>>,
    }
    fn visit<'a>(s: &mut State<'a>, v: &'a str) {
        let i = s.index.len();
        s.index.insert(v, i);
        s.low.insert(v, i);
        s.stack.push(v);
        s.on_stack.insert(v);
        for w in s.arrows.get(v).into_iter().flatten() {
            let w = w.as_str();
            if !s.index.contains_key(w) {
                visit(s, w);
                let low = s.low[v].min(s.low[w]);
                s.low.insert(v, low);
            } else if s.on_stack.contains(w) {
                let low = s.low[v].min(s.index[w]);
                s.low.insert(v, low);
            }
        }
        if s.low[v] == s.index[v] {
            let mut component = Vec::new();
            while let Some(w) = s.stack.pop() {
                s.on_stack.remove(w);
                component.push(w.to_string());
                if w == v {
                    break;
                }
            }
            if component.len() > 1 {
                component.sort();
                s.out.push(component);
            }
        }
    }
    let mut s =
        State { arrows, index: BTreeMap::new(), low: BTreeMap::new(), stack: Vec::new(), on_stack: BTreeSet::new(), out: Vec::new() };
    for v in arrows.keys() {
        if !s.index.contains_key(v.as_str()) {
            visit(&mut s, v);
        }
    }
    s.out
}

#[test]
fn no_crate_has_an_import_cycle() {
    let mut found = Vec::new();
    for dir in ["protocol", "runtime", "ffi", "trainer"] {
        for component in cycles(&read_crate(dir).arrows) {
            found.push(component.join(" → "));
        }
    }
    assert!(found.is_empty(), "import cycles between files:\n{}", found.join("\n"));
}

/// A crate's layers as docs/DESIGN.md §1 states them under `heading`: rows `| N | `module`, `module` |`
/// up to the next heading.
fn design_layers(heading: &str) -> BTreeMap<String, usize> {
    let design = std::fs::read_to_string(repo().join("docs/DESIGN.md")).unwrap();
    let section = &design[design.find("## 1.").unwrap()..design.find("## 2.").unwrap()];
    let Some(at) = section.find(heading) else { return BTreeMap::new() };
    let mut layers = BTreeMap::new();
    for line in section[at + heading.len()..].lines().skip(1).take_while(|l| !l.starts_with('#')) {
        let cells: Vec<&str> = line.split('|').map(str::trim).collect();
        if cells.len() < 4 || !cells[0].is_empty() {
            continue;
        }
        let Ok(layer) = cells[1].parse::<usize>() else { continue };
        for module in cells[2].split(',') {
            layers.insert(module.trim().trim_matches('`').to_string(), layer);
        }
    }
    layers
}

/// The imports of `dir`'s modules that point up a layer of the table under `heading` (which must
/// place every module, and name no other). With
/// `face_on_top` the crate's root (lib.rs: its face, which re-exports) stands above every layer, so
/// a module that names a path through it (`crate::Error`) imports upward; without, such paths are
/// not counted.
fn upward_imports(dir: &str, heading: &str, face_on_top: bool) -> Vec<String> {
    let layers = design_layers(heading);
    assert!(!layers.is_empty(), "docs/DESIGN.md §1 has no table under {heading:?}");
    let krate = read_crate(dir);
    let root = format!("{dir}/src/lib.rs");
    let top = |file: &str| -> Option<String> {
        let (path, _) = krate.files.iter().find(|(_, f)| f.as_str() == file)?;
        path.first().cloned()
    };
    let modules: BTreeSet<String> = krate.files.keys().filter_map(|p| p.first().cloned()).collect();
    let unplaced: Vec<&String> = modules.iter().filter(|m| !layers.contains_key(*m)).collect();
    assert!(unplaced.is_empty(), "{dir} modules missing from the layer table {heading:?} in docs/DESIGN.md §1: {unplaced:?}");
    // And no row for a module that is gone (a merged file's row stood on after it, unchecked).
    let stale: Vec<&String> = layers.keys().filter(|m| !modules.contains(*m)).collect();
    assert!(stale.is_empty(), "the layer table {heading:?} in docs/DESIGN.md §1 names modules {dir} no longer has: {stale:?}");
    let mut upward = Vec::new();
    for (from, targets) in &krate.arrows {
        let Some(from_module) = top(from) else { continue };
        for to in targets {
            if *to == root && face_on_top {
                upward.push(format!("{from} → {to} (layer {} → the crate's face)", layers[&from_module]));
                continue;
            }
            let Some(to_module) = top(to) else { continue };
            if layers[&to_module] > layers[&from_module] {
                upward.push(format!("{from} → {to} (layer {} → {})", layers[&from_module], layers[&to_module]));
            }
        }
    }
    println!("{dir}: imports pointing up a layer ({}):\n{}", upward.len(), upward.join("\n"));
    upward
}

#[test]
fn trainer_modules_import_downward_as_design_states() {
    let upward = upward_imports("trainer", "### The trainer's layers", false);
    assert!(upward.is_empty(), "{} imports point from a lower layer to a higher one (none allowed):\n{}", upward.len(), upward.join("\n"));
}

#[test]
fn runtime_modules_import_downward_as_design_states() {
    let upward = upward_imports("runtime", "### The runtime's layers", true);
    assert!(upward.is_empty(), "{} imports point from a lower layer to a higher one (none allowed):\n{}", upward.len(), upward.join("\n"));
}

#[test]
fn paths_design_cites_exist() {
    let design = std::fs::read_to_string(repo().join("docs/DESIGN.md")).unwrap();
    let folders = ["protocol/", "runtime/", "ffi/", "trainer/", "tests/", "examples/", "docs/", "python/", "fuzz/", ".ci/"];
    let mut missing = Vec::new();
    let mut checked = 0;
    // Code spans: the odd pieces between backticks (a span may wrap a line).
    let mut line = 1;
    for (k, span) in design.split('`').enumerate() {
        let at = line;
        line += span.matches('\n').count();
        // A path from the repository's root, one file or folder (no globs, braces or spaces).
        let looks_like_path =
            k % 2 == 1 && folders.iter().any(|f| span.starts_with(f)) && !span.contains(|c: char| c.is_whitespace() || "{}*<>".contains(c));
        if !looks_like_path {
            continue;
        }
        checked += 1;
        let path = span.split(':').next().unwrap();
        if !repo().join(path).exists() {
            missing.push(format!("docs/DESIGN.md:{at}: {span}"));
        }
    }
    println!("paths cited in docs/DESIGN.md: {checked}");
    assert!(checked > 0, "no paths found in docs/DESIGN.md");
    assert!(missing.is_empty(), "paths docs/DESIGN.md cites that do not exist:\n{}", missing.join("\n"));
}

#[test]
fn design_citations_name_sections_that_exist() {
    let design = std::fs::read_to_string(repo().join("docs/DESIGN.md")).unwrap();
    let sections: BTreeSet<u32> = design.lines().filter_map(|l| l.strip_prefix("## ")?.split('.').next()?.parse().ok()).collect();
    let mut files = Vec::new();
    for dir in ["protocol/src", "runtime/src", "ffi/src", "trainer/src", "trainer/tests", "tests/tests", "examples", "docs"] {
        collect_text(&repo().join(dir), &mut files);
    }
    for name in ["README.md", "BENCHMARKS.md"] {
        files.push(repo().join(name));
    }
    let mut wrong = Vec::new();
    for file in files {
        let Ok(text) = std::fs::read_to_string(&file) else { continue };
        let in_design = file.ends_with("docs/DESIGN.md");
        for (n, line) in text.lines().enumerate() {
            for (at, _) in line.match_indices('§') {
                // A citation of DESIGN: on a line that names DESIGN before it, or inside DESIGN.
                if !in_design && !line[..at].contains("DESIGN") {
                    continue;
                }
                let number: String = line[at + '§'.len_utf8()..].trim_start().chars().take_while(char::is_ascii_digit).collect();
                if let Ok(k) = number.parse::<u32>() {
                    if !sections.contains(&k) {
                        wrong.push(format!("{}:{}: §{k}", file.strip_prefix(repo()).unwrap().display(), n + 1));
                    }
                }
            }
        }
    }
    assert!(wrong.is_empty(), "citations of docs/DESIGN.md sections that do not exist:\n{}", wrong.join("\n"));
}

fn collect_text(dir: &Path, out: &mut Vec<PathBuf>) {
    let Ok(entries) = std::fs::read_dir(dir) else { return };
    for entry in entries {
        let path = entry.unwrap().path();
        if path.is_dir() {
            if path.file_name().unwrap() != "target" {
                collect_text(&path, out);
            }
        } else if path.extension().is_some_and(|e| e == "rs" || e == "md" || e == "toml" || e == "h" || e == "c") {
            out.push(path);
        }
    }
}
