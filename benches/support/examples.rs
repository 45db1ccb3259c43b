//! What the benchmarks that walk the examples share (included with `#[path]`: each
//! benchmark is its own crate).

use std::path::{Path, PathBuf};

/// The motion files in `data/motions/` whose path contains `filter`, sorted.
pub fn example_motions(filter: &str) -> Vec<PathBuf> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("data/motions");
    let mut files: Vec<PathBuf> = std::fs::read_dir(&dir)
        .expect("data/motions exists")
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|x| x == "toml"))
        .filter(|p| p.to_string_lossy().contains(filter))
        .collect();
    files.sort();
    files
}
