//! One home for test scratch folders: `TempDir::new("what")` makes a fresh, empty folder under
//! cargo's `target/tmp` (never the system's /tmp), named after the test and the process
//! (parallel tests and parallel `cargo test` runs never share one), and removes it when
//! dropped — also when the test fails, so a red run leaves nothing behind either. It derefs to
//! its `Path`. Include with
//! `#[path = "common/tempdir.rs"] mod tempdir;`.

use std::path::{Path, PathBuf};

pub struct TempDir(PathBuf);

#[allow(dead_code)]
impl TempDir {
    /// A fresh empty folder `anisocb-<what>-<pid>`.
    pub fn new(what: &str) -> TempDir {
        let p = Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("anisocb-{what}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&p);
        std::fs::create_dir_all(&p).expect("create a temp dir");
        TempDir(p)
    }

    pub fn path(&self) -> &Path {
        &self.0
    }

    /// `path/name` as a `&str`-able String, for command lines.
    pub fn arg(&self, name: &str) -> String {
        self.0.join(name).to_string_lossy().into_owned()
    }
}

impl std::ops::Deref for TempDir {
    type Target = Path;
    fn deref(&self) -> &Path {
        &self.0
    }
}

impl AsRef<Path> for TempDir {
    fn as_ref(&self) -> &Path {
        &self.0
    }
}

impl Drop for TempDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}
