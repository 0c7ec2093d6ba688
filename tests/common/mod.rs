//! Helpers shared by the integration tests.
#![allow(dead_code)] // each test binary uses its own subset

use std::path::{Path, PathBuf};

pub fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// Every `.dpp` file under `pipelines/` that holds a pipeline (the prelude holds only fns).
pub fn pipeline_files() -> Vec<PathBuf> {
    fn walk(dir: &Path, out: &mut Vec<PathBuf>) {
        for entry in std::fs::read_dir(dir).unwrap() {
            let path = entry.unwrap().path();
            if path.is_dir() {
                walk(&path, out);
            } else if path.extension().is_some_and(|e| e == "dpp")
                && std::fs::read_to_string(&path)
                    .unwrap()
                    .contains("pipeline ")
            {
                out.push(path);
            }
        }
    }
    let mut files = Vec::new();
    walk(&repo().join("pipelines"), &mut files);
    files.sort();
    files
}

/// `workload1`, `examples.histogram`: the path under `pipelines/` without extension.
pub fn pipeline_name(path: &Path) -> String {
    path.strip_prefix(repo().join("pipelines"))
        .unwrap()
        .with_extension("")
        .to_string_lossy()
        .replace('/', ".")
}
