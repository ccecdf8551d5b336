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

/// The one file `<stem>_<condition>_<method>.<ext>` of a study's run folder.
pub fn unit_file(dir: &Path, stem: &str, method: &str, ext: &str) -> PathBuf {
    let (prefix, suffix) = (format!("{stem}_"), format!("_{method}.{ext}"));
    let found: Vec<PathBuf> = std::fs::read_dir(dir)
        .map(|entries| {
            entries
                .filter_map(Result::ok)
                .map(|e| e.path())
                .filter(|p| {
                    p.file_name()
                        .and_then(|n| n.to_str())
                        .is_some_and(|n| n.starts_with(&prefix) && n.ends_with(&suffix))
                })
                .collect()
        })
        .unwrap_or_default();
    match found.as_slice() {
        [one] => one.clone(),
        _ => dir.join(format!("{stem}_?_{method}.{ext} (found {found:?})")),
    }
}

/// The metrics of `method` under the only condition of a study's `metrics.json`.
pub fn method_metrics<'a>(metrics: &'a serde_json::Value, method: &str) -> &'a serde_json::Value {
    let conditions = metrics.as_object().expect("metrics.json is an object");
    assert_eq!(conditions.len(), 1, "one condition: {metrics}");
    let (_, methods) = conditions.iter().next().expect("one condition");
    &methods[method]
}
