//! File-system helpers: atomic writes, and the location of the shared real-data folder.

use std::ffi::OsString;
use std::fs::{self, File};
use std::io::{self, Write};
use std::path::{Path, PathBuf};

/// Writes `bytes` to `path` atomically: the bytes go to `<path>.tmp` in the same folder, are
/// flushed to disk, and the temporary file is then renamed over `path`. A reader sees either the
/// old file or the complete new one, never a partial write. On error the temporary file is
/// removed (best effort) and the error returned.
pub fn write_atomic(path: impl AsRef<Path>, bytes: impl AsRef<[u8]>) -> io::Result<()> {
    let path = path.as_ref();
    let tmp = tmp_path(path);
    let result = (|| {
        let mut file = File::create(&tmp)?;
        file.write_all(bytes.as_ref())?;
        file.sync_all()?;
        drop(file);
        fs::rename(&tmp, path)
    })();
    if result.is_err() {
        // Best effort: the original error is the one worth reporting.
        let _ = fs::remove_file(&tmp);
    }
    result
}

/// `<path>.tmp`: the file name with `.tmp` appended (so `a.txt` becomes `a.txt.tmp`).
fn tmp_path(path: &Path) -> PathBuf {
    let mut name: OsString = path.file_name().map(OsString::from).unwrap_or_default();
    name.push(".tmp");
    path.with_file_name(name)
}

/// The folder of shared real data for tests and benchmarks (see docs/methods.md §5.3): the
/// environment variable `CPOSE_DATA_DIR` if set, else `<workspace root>/../shared/data`,
/// where the workspace root is two levels above this crate's manifest. `None` when that folder does
/// not exist (a user's machine); callers then skip, saying so.
pub fn shared_data_dir() -> Option<PathBuf> {
    let dir = shared_data_candidate();
    dir.is_dir().then_some(dir)
}

/// Where [`shared_data_dir`] looks, whether or not the folder exists.
pub fn shared_data_candidate() -> PathBuf {
    match std::env::var_os("CPOSE_DATA_DIR") {
        Some(dir) if !dir.is_empty() => PathBuf::from(dir),
        _ => Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared/data"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn write_atomic_replaces_file_and_leaves_no_temporary() {
        let dir = crate::testing::TempDir::new("fs");
        let path = dir.join("out.txt");
        write_atomic(&path, b"first").unwrap();
        write_atomic(&path, "second").unwrap();
        assert_eq!(fs::read_to_string(&path).unwrap(), "second");
        assert!(!dir.join("out.txt.tmp").exists());
    }

    #[test]
    fn write_atomic_into_missing_folder_is_an_error() {
        let path = std::env::temp_dir().join("cpose-no-such-folder-4711/x.txt");
        assert!(write_atomic(&path, b"x").is_err());
    }
}
