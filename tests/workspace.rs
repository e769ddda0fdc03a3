//! The workspace's rules that no lint can check (docs/architecture.md, "Rules, and what enforces
//! them"): each crate's error enum, README and lints, the top prelude, and the built-in scenes
//! the docs list.

use std::path::{Path, PathBuf};

use rgbd_dataset::scenes::SceneKind;

/// Crates without a prelude, and why: conv-kernels' kernels are plain functions in modules, for
/// patch-gan (the top crate does not re-export it).
const NO_PRELUDE: [&str; 1] = ["conv-kernels"];

fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

fn read(path: &Path) -> String {
    std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// Every library crate's directory, by name.
fn crates() -> Vec<(String, PathBuf)> {
    let mut crates: Vec<(String, PathBuf)> = std::fs::read_dir(root().join("crates"))
        .unwrap()
        .map(|entry| entry.unwrap().path())
        .filter(|dir| dir.join("Cargo.toml").is_file())
        .map(|dir| (dir.file_name().unwrap().to_string_lossy().into_owned(), dir))
        .collect();
    crates.sort();
    assert!(crates.len() >= 11, "{crates:?}");
    crates
}

#[test]
fn every_crates_errors_are_non_exhaustive() {
    for (name, dir) in crates() {
        let error = dir.join("src/error.rs");
        if !error.is_file() {
            continue;
        }
        let text = read(&error);
        let at = text
            .find("pub enum Error")
            .unwrap_or_else(|| panic!("{name}: no `pub enum Error` in src/error.rs"));
        let attributes = text[..at].rsplit("///").next().unwrap_or_default();
        assert!(
            attributes.contains("#[non_exhaustive]"),
            "{name}'s Error is not #[non_exhaustive]"
        );
    }
}

#[test]
fn every_crate_has_its_readme_and_takes_the_workspaces_lints() {
    let lints = "[lints]\nworkspace = true";
    for (name, dir) in crates() {
        let manifest = read(&dir.join("Cargo.toml"));
        assert!(manifest.contains(lints), "{name} does not take the lints");
        assert!(
            manifest.contains("readme = \"README.md\"") && dir.join("README.md").is_file(),
            "{name} has no README named in its Cargo.toml"
        );
    }
    for manifest in ["Cargo.toml", "research/Cargo.toml"] {
        assert!(read(&root().join(manifest)).contains(lints), "{manifest}");
    }
}

#[test]
fn the_top_prelude_takes_every_crates_prelude() {
    let top = read(&root().join("src/lib.rs"));
    for (name, dir) in crates() {
        if read(&dir.join("src/lib.rs")).contains("pub mod prelude") {
            let line = format!("pub use {}::prelude::*;", name.replace('-', "_"));
            assert!(top.contains(&line), "src/lib.rs lacks `{line}`");
        } else {
            assert!(NO_PRELUDE.contains(&name.as_str()), "{name} has no prelude");
        }
    }
}

#[test]
fn the_docs_list_the_built_in_scenes_there_are() {
    let names: Vec<&str> = SceneKind::ALL.iter().map(|kind| kind.name()).collect();
    let listed = names.join(", ");
    for (file, marker) in [
        ("README.md", "| `volgen scene` |"),
        ("docs/cli.md", "built-in scenes:"),
        ("docs/architecture.md", "built-in procedural scenes"),
    ] {
        let text = read(&root().join(file));
        let line = text
            .lines()
            .find(|line| line.contains(marker))
            .unwrap_or_else(|| panic!("{file}: no line with {marker:?}"));
        assert!(
            line.contains(&listed),
            "{file} lists other scenes than {listed}: {line}"
        );
    }
}
