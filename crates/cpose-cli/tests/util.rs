use std::path::{Path, PathBuf};

pub use cpose_core::testing::TempDir;

/// A fresh, empty folder under the system temp dir, removed when the test ends.
pub fn temp_dir(name: &str) -> TempDir {
    TempDir::new(&format!("cli-{name}"))
}

/// Writes `text` to `dir/name` and returns the path.
pub fn write(dir: &Path, name: &str, text: &str) -> PathBuf {
    let path = dir.join(name);
    std::fs::write(&path, text).expect("temp dir is writable");
    path
}
