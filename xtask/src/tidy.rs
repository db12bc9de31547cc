//! `cargo xtask tidy`: checks on the source tree that rustc and clippy do not make.

use anyhow::{Context, Result, bail};
use std::path::{Path, PathBuf};

/// Stage crates: each may depend on `rangeimage` and on math or utility crates, never on another stage or on I/O.
const STAGES: &[&str] = &["features", "regiongrow", "vcanny", "relax", "finalseg", "eval", "scenegen"];
/// Shared crates every stage may depend on; they obey the stages' rule themselves.
const SHARED: &[&str] = &["rangeimage", "planefit"];
/// Crates a stage must not depend on (dev-dependencies included).
const FORBIDDEN_FOR_STAGES: &[&str] = &[
    "features",
    "regiongrow",
    "vcanny",
    "relax",
    "finalseg",
    "eval",
    "scenegen",
    "rangeio",
    "rangeseg",
    "image",
];

/// Stages whose output later stages' tests and benches take as input: a stage may list them in
/// `[dev-dependencies]` (to test on the real computation rather than a test-only copy of it), never in
/// `[dependencies]`.
const DEV_INPUTS_FOR_STAGES: &[&str] = &["features"];

/// Runs every check and returns the problems found, one line each.
pub fn problems(root: &Path) -> Result<Vec<String>> {
    let mut problems = Vec::new();
    for file in rust_files(root)? {
        let text =
            std::fs::read_to_string(&file).with_context(|| format!("{}: cannot read", file.display()))?;
        // A crate root may instead take its docs from a file (`#![doc = include_str!(..)]`).
        if !text.starts_with("//!") && !text.starts_with("#![doc = include_str!(") {
            problems.push(format!("{}: does not start with a `//!` doc line", rel(root, &file)));
        }
    }
    let mut manifests = vec![root.join("xtask/Cargo.toml"), root.join("Cargo.toml")];
    for entry in std::fs::read_dir(root.join("crates")).context("crates/: cannot list")? {
        manifests.push(entry?.path().join("Cargo.toml"));
    }
    manifests.sort();
    for manifest in &manifests {
        let text = std::fs::read_to_string(manifest)
            .with_context(|| format!("{}: cannot read", manifest.display()))?;
        let doc: toml::Table =
            toml::from_str(&text).with_context(|| format!("{}: invalid TOML", manifest.display()))?;
        let lints_ok =
            doc.get("lints").and_then(|l| l.get("workspace")).and_then(|w| w.as_bool()).unwrap_or(false);
        if !lints_ok {
            problems.push(format!("{}: missing `[lints] workspace = true`", rel(root, manifest)));
        }
        for p in layering_problems(&doc) {
            problems.push(format!("{}: {p}", rel(root, manifest)));
        }
    }
    Ok(problems)
}

/// The dependencies a stage or shared crate's manifest may not have (see [`FORBIDDEN_FOR_STAGES`]).
fn layering_problems(doc: &toml::Table) -> Vec<String> {
    let mut problems = Vec::new();
    let name = doc.get("package").and_then(|p| p.get("name")).and_then(|n| n.as_str()).unwrap_or("");
    if !(STAGES.contains(&name) || SHARED.contains(&name)) {
        return problems;
    }
    for table in ["dependencies", "dev-dependencies", "build-dependencies"] {
        let Some(deps) = doc.get(table).and_then(|d| d.as_table()) else { continue };
        for dep in deps.keys().map(String::as_str) {
            let dev_input =
                table == "dev-dependencies" && STAGES.contains(&name) && DEV_INPUTS_FOR_STAGES.contains(&dep);
            if FORBIDDEN_FOR_STAGES.contains(&dep) && dep != name && !dev_input {
                problems.push(format!(
                    "stage crate {name} depends on {dep} in [{table}]; stages depend only on the shared crates (rangeimage, planefit, isa) and math or utility crates"
                ));
            }
        }
    }
    problems
}

/// Runs `cargo xtask tidy`: prints the problems and fails if there are any.
pub fn run(root: &Path) -> Result<()> {
    let problems = problems(root)?;
    if problems.is_empty() {
        eprintln!("tidy: ok");
        return Ok(());
    }
    for p in &problems {
        eprintln!("{p}");
    }
    bail!("tidy: {} problem(s)", problems.len())
}

fn rel(root: &Path, p: &Path) -> String {
    p.strip_prefix(root).unwrap_or(p).display().to_string()
}

/// Every tracked-looking `.rs` file under the project's source folders.
fn rust_files(root: &Path) -> Result<Vec<PathBuf>> {
    let mut out = Vec::new();
    let mut stack: Vec<PathBuf> =
        ["src", "crates", "xtask", "tests", "examples", "benches"].iter().map(|d| root.join(d)).collect();
    while let Some(dir) = stack.pop() {
        let Ok(entries) = std::fs::read_dir(&dir) else { continue };
        for entry in entries {
            let path = entry?.path();
            if path.is_dir() {
                if path.file_name().is_some_and(|n| n != "target") {
                    stack.push(path);
                }
            } else if path.extension().is_some_and(|e| e == "rs") {
                out.push(path);
            }
        }
    }
    out.sort();
    Ok(out)
}

#[cfg(test)]
mod tests {
    fn layering(manifest: &str) -> Vec<String> {
        super::layering_problems(&toml::from_str(manifest).unwrap())
    }

    #[test]
    fn stages_may_test_on_features_but_not_depend_on_it() {
        let dev = "[package]\nname = \"regiongrow\"\n[dev-dependencies]\nfeatures = \"1\"\n";
        assert_eq!(layering(dev), Vec::<String>::new());
        let normal = "[package]\nname = \"regiongrow\"\n[dependencies]\nfeatures = \"1\"\n";
        assert_eq!(layering(normal).len(), 1, "{:?}", layering(normal));
        let other = "[package]\nname = \"relax\"\n[dev-dependencies]\nregiongrow = \"1\"\n";
        assert_eq!(layering(other).len(), 1);
        let shared = "[package]\nname = \"rangeimage\"\n[dev-dependencies]\nfeatures = \"1\"\n";
        assert_eq!(layering(shared).len(), 1);
    }

    #[test]
    fn tree_is_tidy() {
        let problems = super::problems(&crate::project_root()).unwrap();
        assert!(problems.is_empty(), "tidy problems:\n{}", problems.join("\n"));
    }
}
