//! The layers of docs/ARCHITECTURE.md hold in the code: no module of `src/` names a module of its own
//! layer or of a higher one through a `crate::` path. The layer table of ARCHITECTURE.md is the one
//! list; this test reads it, so the document and the check cannot disagree.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// Module -> layer, from the rows `| n | `a`, `b` | ... |` of the table under `## Layers`.
fn layer_table(doc: &str) -> BTreeMap<String, usize> {
    let section = doc.split("\n## Layers").nth(1).expect("docs/ARCHITECTURE.md has a `## Layers` section");
    let section = section.split("\n## ").next().unwrap_or(section);
    let mut layers = BTreeMap::new();
    for row in section.lines().filter(|l| l.starts_with('|')) {
        let cells: Vec<&str> = row.split('|').map(str::trim).collect();
        let Ok(layer) = cells[1].parse::<usize>() else { continue };
        for m in cells[2].split(',').map(|m| m.trim().trim_matches('`')) {
            assert!(layers.insert(m.to_string(), layer).is_none(), "{m} is placed twice in the layer table");
        }
    }
    layers
}

/// `src` with comments, string literals and char literals blanked (newlines kept, so line numbers hold).
fn code_only(src: &str) -> String {
    let b = src.as_bytes();
    let mut out = Vec::with_capacity(b.len());
    let blank = |out: &mut Vec<u8>, s: &[u8]| out.extend(s.iter().map(|&c| if c == b'\n' { b'\n' } else { b' ' }));
    let mut i = 0;
    while i < b.len() {
        let rest = &b[i..];
        let end = if rest.starts_with(b"//") {
            rest.iter().position(|&c| c == b'\n').unwrap_or(rest.len())
        } else if rest.starts_with(b"/*") {
            // Block comments nest in Rust.
            let (mut depth, mut k) = (0usize, 0);
            while k < rest.len() {
                if rest[k..].starts_with(b"/*") {
                    depth += 1;
                    k += 2;
                } else if rest[k..].starts_with(b"*/") {
                    depth -= 1;
                    k += 2;
                    if depth == 0 {
                        break;
                    }
                } else {
                    k += 1;
                }
            }
            k
        } else if rest[0] == b'r' && (rest.starts_with(b"r\"") || rest.starts_with(b"r#")) && !ident_before(b, i) {
            // A raw string r#"..."#: it ends at a quote followed by as many hashes.
            let hashes = rest[1..].iter().take_while(|&&c| c == b'#').count();
            if rest.get(1 + hashes) != Some(&b'"') {
                out.push(rest[0]);
                i += 1;
                continue;
            }
            let close: Vec<u8> = std::iter::once(b'"').chain(std::iter::repeat_n(b'#', hashes)).collect();
            let body = 2 + hashes;
            body + rest[body..].windows(close.len()).position(|w| w == close).expect("closed raw string") + close.len()
        } else if rest[0] == b'"' {
            let mut k = 1;
            while rest[k] != b'"' {
                k += if rest[k] == b'\\' { 2 } else { 1 };
            }
            k + 1
        } else if rest[0] == b'\'' && rest.get(1) == Some(&b'\\') {
            1 + rest[1..].iter().skip(1).position(|&c| c == b'\'').expect("closed char literal") + 2
        } else if rest[0] == b'\'' && rest.len() > 2 && rest[2] == b'\'' {
            3
        } else {
            out.push(rest[0]);
            i += 1;
            continue;
        };
        blank(&mut out, &rest[..end]);
        i += end;
    }
    String::from_utf8(out).expect("blanking keeps UTF-8 (multi-byte characters sit only in comments and strings)")
}

fn is_ident(c: u8) -> bool {
    c.is_ascii_alphanumeric() || c == b'_'
}

fn ident_before(b: &[u8], i: usize) -> bool {
    i > 0 && is_ident(b[i - 1])
}

/// The first path segment after each `crate::` in `code`, with its line: `crate::fit::x` gives `fit`,
/// `crate::{fit::x, ndf}` gives `fit` and `ndf`.
fn crate_paths(code: &str) -> Vec<(usize, String)> {
    let b = code.as_bytes();
    let mut found = Vec::new();
    let mut from = 0;
    while let Some(k) = code[from..].find("crate::") {
        let at = from + k;
        from = at + "crate::".len();
        if ident_before(b, at) {
            continue; // `ndfit_crate::`, not the crate root.
        }
        let line = code[..at].matches('\n').count() + 1;
        let heads: Vec<String> = if b.get(from) == Some(&b'{') {
            // The names at the top level of a `{...}` group, nested groups skipped.
            let (mut depth, mut k, mut heads, mut item_start) = (0, from, Vec::new(), true);
            loop {
                match b[k] {
                    b'{' => depth += 1,
                    b'}' => {
                        depth -= 1;
                        if depth == 0 {
                            break;
                        }
                    }
                    b',' if depth == 1 => item_start = true,
                    c if item_start && depth == 1 && is_ident(c) => {
                        let n = b[k..].iter().take_while(|&&c| is_ident(c)).count();
                        heads.push(code[k..k + n].to_string());
                        item_start = false;
                        k += n;
                        continue;
                    }
                    _ => {}
                }
                k += 1;
            }
            heads
        } else {
            let n = b[from..].iter().take_while(|&&c| is_ident(c)).count();
            vec![code[from..from + n].to_string()]
        };
        found.extend(heads.into_iter().filter(|h| !h.is_empty() && h != "self").map(|h| (line, h)));
    }
    found
}

/// The names the crate root re-exports (`pub use pipeline::{Options, ...};` in src/lib.rs), with the
/// module each comes from: `crate::Options` is a path into `pipeline`.
fn root_reexports(lib: &str) -> BTreeMap<String, String> {
    let code = code_only(lib);
    let mut names = BTreeMap::new();
    for stmt in code.split(';').map(str::trim).filter_map(|s| s.strip_prefix("pub use ")) {
        let Some((module, rest)) = stmt.split_once("::") else { continue };
        let group = rest.trim().trim_start_matches('{').trim_end_matches('}');
        for name in group.split(',').map(|n| n.trim().rsplit("::").next().unwrap_or("").trim()) {
            names.insert(name.to_string(), module.trim().to_string());
        }
    }
    names
}

fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    for e in std::fs::read_dir(dir).expect("readable source folder") {
        let p = e.expect("folder entry").path();
        if p.is_dir() {
            rust_files(&p, out);
        } else if p.extension().is_some_and(|x| x == "rs") {
            out.push(p);
        }
    }
}

/// The top module `path` (under `src/`) belongs to: `src/ndf/grid.rs` and `src/preprocess.rs` give
/// `ndf` and `preprocess`; `lib.rs` and `main.rs` give `None` (the roots).
fn top_module(src: &Path, path: &Path) -> Option<String> {
    let rel = path.strip_prefix(src).expect("under src");
    let first = rel.components().next()?.as_os_str().to_str()?;
    match first {
        "lib.rs" | "main.rs" => None,
        f => Some(f.trim_end_matches(".rs").to_string()),
    }
}

/// Every `crate::` path of the library's code (comments and strings aside) against the layer table.
/// The binary (`src/main.rs`, `src/cli/`) is the top layer and its `crate::` is the binary's own root,
/// so its files are placed but not read.
#[test]
fn no_module_imports_from_its_own_layer_or_above() {
    let root = repo();
    let doc = std::fs::read_to_string(root.join("docs/ARCHITECTURE.md")).expect("docs/ARCHITECTURE.md");
    let layers = layer_table(&doc);
    assert!(layers.len() >= 10, "the layer table of docs/ARCHITECTURE.md was not read: {layers:?}");
    let src = root.join("src");
    let reexports = root_reexports(&std::fs::read_to_string(src.join("lib.rs")).expect("src/lib.rs"));
    let mut files = Vec::new();
    rust_files(&src, &mut files);
    files.sort();

    let mut wrong = Vec::new();
    for path in &files {
        let Some(module) = top_module(&src, path) else { continue };
        let Some(&own) = layers.get(&module) else {
            wrong.push(format!("{}: module `{module}` has no row in the layer table of docs/ARCHITECTURE.md", path.display()));
            continue;
        };
        if module == "cli" {
            continue;
        }
        let code = code_only(&std::fs::read_to_string(path).expect("source file"));
        for (line, head) in crate_paths(&code) {
            let target = reexports.get(&head).cloned().unwrap_or(head);
            if target == module {
                continue;
            }
            match layers.get(&target) {
                Some(&l) if l < own => {}
                Some(&l) => wrong.push(format!(
                    "{}:{line}: `{module}` (layer {own}) uses `crate::{target}` (layer {l}); only layers below {own} may be used",
                    path.display()
                )),
                None => wrong.push(format!(
                    "{}:{line}: `crate::{target}` is neither a module of the layer table nor a root re-export",
                    path.display()
                )),
            }
        }
    }
    assert!(wrong.is_empty(), "{} layer violations:\n{}", wrong.len(), wrong.join("\n"));
}

/// Every module the table places exists (a renamed module must be renamed in the table too).
#[test]
fn every_module_of_the_layer_table_exists() {
    let root = repo();
    let layers = layer_table(&std::fs::read_to_string(root.join("docs/ARCHITECTURE.md")).expect("ARCHITECTURE.md"));
    for m in layers.keys() {
        let (dir, file) = (root.join("src").join(m), root.join("src").join(format!("{m}.rs")));
        assert!(dir.is_dir() || file.is_file(), "the layer table places `{m}`, which is not a module of src/");
    }
}

/// The reader of the check itself: comments, strings and char literals are not code; `{...}` groups
/// give every top-level name; identifiers ending in `crate` are not the root.
#[test]
fn the_layer_check_reads_paths_as_the_compiler_does() {
    let code = code_only(
        "use crate::{fit::x, ndf::{a, b}, scan};\n// crate::bench\n/* crate::batch /* nested */ crate::cli */\n\
         let s = \"crate::io\"; let r = r#\"crate::synth\"#; let c = '\"'; let d = '\\'';\n\
         let q = crate::pipeline::run(); my_crate::x; fn f<'a>(x: &'a str) {}\n",
    );
    let heads: Vec<(usize, String)> = crate_paths(&code);
    let want = [(1, "fit"), (1, "ndf"), (1, "scan"), (5, "pipeline")];
    assert_eq!(heads, want.map(|(l, h)| (l, h.to_string())).to_vec(), "in {code}");
    let names = root_reexports("pub use error::{Error, ErrorKind, Result};\npub use models::ModelChoice;\n// pub use x::Y;\n");
    assert_eq!(names.get("ErrorKind").map(String::as_str), Some("error"));
    assert_eq!(names.get("ModelChoice").map(String::as_str), Some("models"));
    assert_eq!(names.len(), 4);
}

/// The public namespaces below the crate root, from the first column of the table under
/// `## The public API` (`export::rgl`, `batch::runner`, ...).
fn public_namespaces(doc: &str) -> Vec<String> {
    let section = doc.split("\n## The public API").nth(1).expect("docs/ARCHITECTURE.md has a `## The public API` section");
    let section = section.split("\n## ").next().unwrap_or(section);
    let mut names = Vec::new();
    for row in section.lines().filter(|l| l.starts_with("| `")) {
        let first = row.split('|').nth(1).unwrap_or("");
        names.extend(first.split(',').map(|n| n.trim().trim_matches('`').to_string()).filter(|n| n.contains("::")));
    }
    names
}

/// The module path of a file under `src/` (`src/export/rgl/mod.rs` gives `export::rgl`, `src/fit/tail.rs`
/// gives `fit::tail`, `src/lib.rs` the empty root).
fn module_path(src: &Path, path: &Path) -> String {
    let rel = path.strip_prefix(src).expect("under src").with_extension("");
    let mut parts: Vec<String> = rel.components().map(|c| c.as_os_str().to_string_lossy().into_owned()).collect();
    if parts.last().is_some_and(|l| l == "mod" || l == "lib") {
        parts.pop();
    }
    parts.join("::")
}

/// The boundary: below the crate root only the namespaces of ARCHITECTURE.md's table are `pub mod`;
/// every other file is a private module whose public items reach users through its module's re-exports.
#[test]
fn only_the_listed_namespaces_are_public() {
    let root = repo();
    let doc = std::fs::read_to_string(root.join("docs/ARCHITECTURE.md")).expect("docs/ARCHITECTURE.md");
    let allowed = public_namespaces(&doc);
    assert!(allowed.len() >= 10, "the public API table of docs/ARCHITECTURE.md was not read: {allowed:?}");
    let src = root.join("src");
    let mut files = Vec::new();
    rust_files(&src, &mut files);
    files.sort();
    let (mut public, mut wrong) = (Vec::new(), Vec::new());
    for path in &files {
        let parent = module_path(&src, path);
        if parent.is_empty() || parent == "main" || parent.starts_with("cli") {
            continue; // the crate root's modules are the layers; the binary's modules are not the library's API
        }
        let code = code_only(&std::fs::read_to_string(path).expect("source file"));
        for (k, line) in code.lines().enumerate() {
            let Some(name) = line.trim().strip_prefix("pub mod ") else { continue };
            let name = name.trim_end_matches(|c: char| c == ';' || c == '{' || c.is_whitespace());
            let full = format!("{parent}::{name}");
            if allowed.contains(&full) {
                public.push(full);
            } else {
                wrong.push(format!(
                    "{}:{}: `pub mod {name}` ({full}) is not a public namespace of docs/ARCHITECTURE.md",
                    path.display(),
                    k + 1
                ));
            }
        }
    }
    assert!(wrong.is_empty(), "{}", wrong.join("\n"));
    for a in &allowed {
        assert!(public.contains(a), "docs/ARCHITECTURE.md lists `{a}` as a public namespace, but it is not a `pub mod`");
    }
}
