//! File-system helpers shared by every crate: atomic writes and the shared data folder.

use std::io::Write as _;
use std::path::{Path, PathBuf};

/// Writes `bytes` to `path` atomically: first to `<name>.tmp` in the same folder (flushed to
/// disk), then renamed over `path`, so readers never see a half-written file. The folder must
/// exist. On error the temporary file is removed (best effort).
pub fn write_atomic(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    let mut tmp_name = path
        .file_name()
        .ok_or_else(|| {
            std::io::Error::new(std::io::ErrorKind::InvalidInput, "path has no file name")
        })?
        .to_os_string();
    tmp_name.push(".tmp");
    let tmp = path.with_file_name(tmp_name);
    let result = (|| {
        let mut file = std::fs::File::create(&tmp)?;
        file.write_all(bytes)?;
        file.sync_all()?;
        std::fs::rename(&tmp, path)
    })();
    if result.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    result
}

/// The folder with the real datasets: `$CPOSE_DATA_DIR` if set, else `../shared/data` next to
/// the workspace; `None` if that folder does not exist (tests then skip with one line).
pub fn shared_data_dir() -> Option<PathBuf> {
    let dir = match std::env::var_os("CPOSE_DATA_DIR") {
        Some(dir) => PathBuf::from(dir),
        // crates/cpose-core → workspace root → its sibling `shared/data`.
        None => Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared/data"),
    };
    dir.is_dir().then_some(dir)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn write_atomic_replaces_and_leaves_no_temporary() {
        let dir = std::env::temp_dir().join(format!("cpose-fs-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("a.json");
        write_atomic(&path, b"one").unwrap();
        write_atomic(&path, b"two").unwrap();
        assert_eq!(std::fs::read(&path).unwrap(), b"two");
        assert!(!dir.join("a.json.tmp").exists());
        assert!(write_atomic(&dir.join("missing/x"), b"x").is_err());
        assert!(!dir.join("missing").exists());
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
