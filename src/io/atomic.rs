//! Atomic file writes: write to `.NAME.tmp.<pid>.<n>` in the same directory, fsync, rename over
//! `NAME`, fsync the directory. A crash leaves either the old file or the new one, never half
//! of one. An error or a panic inside the writer removes the temporary file; an interrupt
//! (SIGINT, SIGTERM) removes every open one through [`remove_live_temps_and_exit`], which the
//! binary calls from its signal handler; only a kill (SIGKILL, power loss) can leave one
//! behind, and [`remove_stale_temps`] clears those (not another live process's).

use crate::error::{Error, Result};
use std::fs::{self, File};
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Mutex;

/// Distinguishes concurrent writes of the same path from one process.
static COUNTER: AtomicU64 = AtomicU64::new(0);

/// The temporary files this process has open (created, not yet renamed or removed).
static LIVE: Mutex<Vec<PathBuf>> = Mutex::new(Vec::new());

fn live() -> std::sync::MutexGuard<'static, Vec<PathBuf>> {
    LIVE.lock().unwrap_or_else(|e| e.into_inner())
}

/// Remove every temporary file this process has open, hold off new ones, and exit with
/// `code`: for a signal handler (`anisocb` on SIGINT / SIGTERM).
pub fn remove_live_temps_and_exit(code: i32) -> ! {
    let mut l = live();
    for p in l.drain(..) {
        let _ = fs::remove_file(p);
    }
    // The lock stays held: a writer about to create a temp file waits for the exit.
    std::process::exit(code)
}

/// Removes the temporary file unless disarmed (after a successful rename), also on panic.
struct TempGuard(Option<PathBuf>);

impl TempGuard {
    /// Disarm: the file was renamed into place.
    fn disarm(&mut self) {
        if let Some(p) = self.0.take() {
            live().retain(|q| *q != p);
        }
    }
}

impl Drop for TempGuard {
    fn drop(&mut self) {
        if let Some(p) = self.0.take() {
            let mut l = live();
            let _ = fs::remove_file(&p);
            l.retain(|q| *q != p);
        }
    }
}

fn temp_prefix(name: &std::ffi::OsStr) -> String {
    format!(".{}.tmp.", name.to_string_lossy())
}

/// Most names [`create_temp`] tries before it gives up.
const TEMP_TRIES: u64 = 1000;

/// A new temporary file `.NAME.tmp.<pid>.<n>` in `dir`, created exclusively (`O_CREAT |
/// O_EXCL`): never an existing file, and never through a symbolic link planted at that name
/// (its target would be overwritten); a name that exists is skipped for the next `n`.
fn create_temp(dir: &Path, name: &std::ffi::OsStr) -> std::io::Result<(PathBuf, File)> {
    for _ in 0..TEMP_TRIES {
        let n = COUNTER.fetch_add(1, Ordering::Relaxed);
        let tmp = dir.join(format!("{}{}.{n}", temp_prefix(name), std::process::id()));
        match fs::OpenOptions::new().write(true).create_new(true).open(&tmp) {
            Ok(f) => return Ok((tmp, f)),
            Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => continue,
            Err(e) => return Err(e),
        }
    }
    Err(std::io::Error::new(
        std::io::ErrorKind::AlreadyExists,
        format!("{TEMP_TRIES} temporary names beside it are all taken; remove the .*.tmp.* files there"),
    ))
}

/// A file written in pieces that appears at `path` only when [`AtomicFile::commit`] succeeds
/// (temp + fsync + rename, as [`write_atomic`]); dropped uncommitted — an error, a panic — it
/// leaves nothing. For outputs too large to build in memory (streamed point caches, `.npy`).
pub struct AtomicFile {
    path: PathBuf,
    tmp: PathBuf,
    w: Option<BufWriter<File>>,
    guard: TempGuard,
}

impl AtomicFile {
    pub fn create(path: &Path) -> Result<AtomicFile> {
        let dir = path.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new("."));
        let name =
            path.file_name().ok_or_else(|| Error::config(format!("{}: not a file name", path.display())))?;
        let (tmp, file) = {
            let mut l = live();
            let (tmp, file) = create_temp(dir, name).map_err(|e| Error::io(path, e))?;
            l.push(tmp.clone());
            (tmp, file)
        };
        Ok(AtomicFile {
            path: path.to_path_buf(),
            tmp: tmp.clone(),
            w: Some(BufWriter::new(file)),
            guard: TempGuard(Some(tmp)),
        })
    }

    /// The writer for the file's bytes (errors from it belong to [`AtomicFile::path`]).
    pub fn writer(&mut self) -> &mut BufWriter<File> {
        self.w.as_mut().expect("an AtomicFile is only written before commit")
    }

    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Flush, fsync, rename over the final path, fsync the directory.
    pub fn commit(mut self) -> Result<()> {
        let w = self.w.take().expect("commit runs once");
        let result = (|| {
            let file = w.into_inner().map_err(|e| e.into_error())?;
            file.sync_all()?;
            fs::rename(&self.tmp, &self.path)?;
            self.guard.disarm();
            // Make the rename itself durable; not every filesystem allows syncing a directory.
            let dir = self.path.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new("."));
            if let Ok(d) = File::open(dir) {
                let _ = d.sync_all();
            }
            Ok(())
        })();
        result.map_err(|e| Error::io(&self.path, e))
    }
}

pub fn write_atomic(path: &Path, f: impl FnOnce(&mut dyn Write) -> std::io::Result<()>) -> Result<()> {
    let mut file = AtomicFile::create(path)?;
    f(file.writer()).map_err(|e| Error::io(path, e))?;
    file.commit()
}

pub fn write_atomic_bytes(path: &Path, bytes: &[u8]) -> Result<()> {
    write_atomic(path, |w| w.write_all(bytes))
}

/// Remove temporary files that a killed writer of `path` left behind (`.NAME.tmp.<pid>.*`
/// beside it), where a run restarts (e.g. `--resume`, an upscale rerun). A temp file of a
/// process that is still running (another run writing the same folder) is left alone (on
/// Linux, where `/proc` tells). Returns how many were removed.
pub fn remove_stale_temps(path: &Path) -> Result<usize> {
    let dir = path.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new("."));
    let Some(name) = path.file_name() else { return Ok(0) };
    let prefix = temp_prefix(name);
    let Ok(list) = fs::read_dir(dir) else { return Ok(0) };
    let mut removed = 0;
    for e in list.flatten() {
        let file = e.file_name().to_string_lossy().into_owned();
        let Some(rest) = file.strip_prefix(&prefix) else { continue };
        if rest.split('.').next().and_then(|p| p.parse::<u32>().ok()).is_some_and(process_alive) {
            continue;
        }
        fs::remove_file(e.path()).map_err(|err| Error::io(e.path(), err))?;
        removed += 1;
    }
    Ok(removed)
}

/// Whether process `pid` is running (this one included); without `/proc`, every other process
/// is taken to be gone.
fn process_alive(pid: u32) -> bool {
    pid == std::process::id() || Path::new("/proc").join(pid.to_string()).exists()
}

/// Create `dir` (and parents), with an error that names it and says what to do.
pub fn ensure_dir(dir: &Path) -> Result<()> {
    if dir.exists() && !dir.is_dir() {
        return Err(Error::format(
            dir,
            "output path exists and is not a directory; choose a writable output folder",
        ));
    }
    fs::create_dir_all(dir).map_err(|e| {
        Error::format(dir, format!("cannot create output directory ({e}); choose a writable output folder"))
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scratch(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("anisocb-atomic-{name}-{}", std::process::id()));
        let _ = fs::remove_dir_all(&d);
        fs::create_dir_all(&d).unwrap();
        d
    }

    fn entries(d: &Path) -> Vec<String> {
        let mut v: Vec<String> =
            fs::read_dir(d).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into()).collect();
        v.sort();
        v
    }

    #[test]
    fn failed_write_keeps_old_file_and_leaves_no_temp() {
        let d = scratch("fail");
        let p = d.join("a.bin");
        write_atomic_bytes(&p, b"old").unwrap();
        let e = write_atomic(&p, |w| {
            w.write_all(b"half")?;
            Err(std::io::Error::other("disk full"))
        })
        .unwrap_err();
        assert!(e.to_string().contains("a.bin") && e.to_string().contains("disk full"), "{e}");
        assert_eq!(fs::read(&p).unwrap(), b"old");
        assert_eq!(entries(&d), ["a.bin"]);
        let _ = fs::remove_dir_all(&d);
    }

    #[test]
    fn panicking_writer_leaves_no_temp() {
        let d = scratch("panic");
        let p = d.join("b.bin");
        let r = std::panic::catch_unwind(|| {
            let _ = write_atomic(&p, |_| panic!("writer bug"));
        });
        assert!(r.is_err());
        assert!(entries(&d).is_empty(), "{:?}", entries(&d));
        let _ = fs::remove_dir_all(&d);
    }

    #[test]
    fn stale_temps_of_a_killed_writer_are_removed() {
        let d = scratch("stale");
        let p = d.join("ckpt.npz");
        // A pid above Linux's largest possible (2^22): that process is gone.
        fs::write(d.join(".ckpt.npz.tmp.4194305.0"), b"partial").unwrap();
        fs::write(d.join("other.npz"), b"x").unwrap();
        assert_eq!(remove_stale_temps(&p).unwrap(), 1);
        assert_eq!(entries(&d), ["other.npz"]);
        let _ = fs::remove_dir_all(&d);
    }

    #[test]
    fn temps_of_a_running_process_are_not_stale() {
        let d = scratch("live");
        let p = d.join("frame.obj");
        // Another run writing the same folder right now (this process stands in for it).
        let mut f = AtomicFile::create(&p).unwrap();
        f.writer().write_all(b"v 0 0 0").unwrap();
        assert_eq!(remove_stale_temps(&p).unwrap(), 0);
        f.commit().unwrap();
        assert_eq!(entries(&d), ["frame.obj"]);
        let _ = fs::remove_dir_all(&d);
    }
}
