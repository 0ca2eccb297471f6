//! One home for test scratch folders: `TempDir::new("what")` makes a fresh, empty folder under
//! the system's temp dir, named after the test and the process (parallel tests and parallel
//! `cargo test` runs never share one), and removes it when dropped — also when the test fails,
//! so a red run leaves nothing behind either. Include with
//! `#[path = "common/tempdir.rs"] mod tempdir;`.

use std::path::{Path, PathBuf};

pub struct TempDir(PathBuf);

#[allow(dead_code)]
impl TempDir {
    /// A fresh empty folder `anisocb-<what>-<pid>`.
    pub fn new(what: &str) -> TempDir {
        let p = std::env::temp_dir().join(format!("anisocb-{what}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&p);
        std::fs::create_dir_all(&p).expect("create a temp dir");
        TempDir(p)
    }

    pub fn path(&self) -> &Path {
        &self.0
    }

    /// `path/name`.
    pub fn join(&self, name: impl AsRef<Path>) -> PathBuf {
        self.0.join(name)
    }

    /// `path/name` as a `&str`-able String, for command lines.
    pub fn arg(&self, name: &str) -> String {
        self.0.join(name).to_string_lossy().into_owned()
    }
}

impl Drop for TempDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}
