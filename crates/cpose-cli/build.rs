//! Records the git commit the CLI is built from, for `provenance.json` and `cpose --version`.
//!
//! Exports `CPOSE_GIT_COMMIT` (40 hex digits, or empty when unknown) and `CPOSE_GIT_DIRTY`
//! (`true`, `false`, or empty when unknown), and `CPOSE_LONG_VERSION` for `cpose --version`
//! (`0.1.0 (<commit>[, dirty])`). Outside a git checkout of this workspace (a
//! crates.io tarball, no `git` installed) the commit comes from `.cargo_vcs_info.json` when
//! `cargo package` wrote one, else it is unknown; the build never fails because of git.

use std::path::{Path, PathBuf};
use std::process::Command;

fn main() {
    let manifest_dir = PathBuf::from(std::env::var_os("CARGO_MANIFEST_DIR").unwrap_or_default());
    let (commit, dirty) = from_git(&manifest_dir)
        .or_else(|| from_vcs_info(&manifest_dir))
        .unwrap_or_default();
    println!("cargo:rustc-env=CPOSE_GIT_COMMIT={commit}");
    println!("cargo:rustc-env=CPOSE_GIT_DIRTY={dirty}");
    let version = std::env::var("CARGO_PKG_VERSION").unwrap_or_default();
    let long_version = match (commit.as_str(), dirty.as_str()) {
        ("", _) => format!("{version} (unknown commit)"),
        (c, "true") => format!("{version} ({c}, dirty)"),
        (c, _) => format!("{version} ({c})"),
    };
    println!("cargo:rustc-env=CPOSE_LONG_VERSION={long_version}");
    println!("cargo:rerun-if-changed=build.rs");
}

/// `git` output of `args` run in `dir`, trimmed; `None` if git is missing or fails.
fn git(dir: &Path, args: &[&str]) -> Option<String> {
    let out = Command::new("git")
        // Never take the index lock: a build must not disturb a git command running beside it.
        .arg("--no-optional-locks")
        .args(args)
        .current_dir(dir)
        .output()
        .ok()?;
    out.status
        .success()
        .then(|| String::from_utf8_lossy(&out.stdout).trim().to_owned())
}

/// Commit and dirty flag from the git checkout holding this crate at `crates/cpose-cli`, with
/// `rerun-if-changed` lines for the files a commit, checkout or edit changes.
fn from_git(manifest_dir: &Path) -> Option<(String, String)> {
    // A vendored or packaged copy inside someone else's repository is not our checkout.
    if git(manifest_dir, &["rev-parse", "--show-prefix"])? != "crates/cpose-cli/" {
        return None;
    }
    let commit = git(manifest_dir, &["rev-parse", "HEAD"])?;
    let status = git(
        manifest_dir,
        &["status", "--porcelain", "--untracked-files=no"],
    )?;
    let abs = |p: String| manifest_dir.join(p);
    let git_dir = abs(git(manifest_dir, &["rev-parse", "--git-dir"])?);
    let common_dir = git(manifest_dir, &["rev-parse", "--git-common-dir"]).map(abs);
    let mut watched = vec![git_dir.join("HEAD"), git_dir.join("index")];
    if let Some(common) = &common_dir {
        watched.push(common.join("packed-refs"));
        if let Some(branch) = git(manifest_dir, &["symbolic-ref", "-q", "HEAD"]) {
            // A branch whose ref is only packed gets its loose file on the next commit, in the
            // folder watched instead (not always: other branches' commits touch it too).
            let loose = common.join(&branch);
            match loose.parent() {
                Some(folder) if !loose.exists() => watched.push(folder.to_path_buf()),
                _ => watched.push(loose),
            }
        }
    }
    // The sources: an edit there reruns this script, so the dirty flag follows the code (edits
    // elsewhere, such as the README, are seen at the next rebuild).
    let workspace = manifest_dir.join("../..");
    watched.extend(["crates", "Cargo.toml", "Cargo.lock"].map(|p| workspace.join(p)));
    // Cargo reruns on every build for a missing path, so only existing ones are named.
    for path in watched.iter().filter(|p| p.exists()) {
        println!("cargo:rerun-if-changed={}", path.display());
    }
    let dirty = if status.is_empty() { "false" } else { "true" };
    is_hex_commit(&commit).then(|| (commit, dirty.to_owned()))
}

/// Commit and dirty flag that `cargo package` stored in `.cargo_vcs_info.json`.
fn from_vcs_info(manifest_dir: &Path) -> Option<(String, String)> {
    let path = manifest_dir.join(".cargo_vcs_info.json");
    let text = std::fs::read_to_string(&path).ok()?;
    println!("cargo:rerun-if-changed={}", path.display());
    // `"sha1": "<hex>"`, and `"dirty": true` only when the tree was dirty.
    let after = &text[text.find("\"sha1\"")? + 6..];
    let commit: String = after
        .trim_start_matches([' ', ':', '"'])
        .chars()
        .take_while(char::is_ascii_hexdigit)
        .collect();
    let dirty = text.contains("\"dirty\": true") || text.contains("\"dirty\":true");
    is_hex_commit(&commit).then(|| (commit, dirty.to_string()))
}

fn is_hex_commit(s: &str) -> bool {
    s.len() == 40 && s.bytes().all(|b| b.is_ascii_hexdigit())
}
