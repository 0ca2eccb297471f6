//! The rule for output folders, one for every command that writes a folder (`upscale`,
//! `simulate`, `train`, `eval`, `demo`): a run writes into a new or empty folder, or into one
//! that earlier runs of the same job own, and holds a lock on its part of it for its whole life.
//! Commands that write one file (`bundle`, `dataset`) take [`claim_file`].
//!
//! A job is known by its inputs; its runs' summaries (`upscale.json`, `upscale.A-B.json` for a
//! slice, `train.json`, `simulate.json`, …) name the inputs, the settings that decide the
//! output's bytes and every file the run writes (paths inside the folder, `/`-separated: a
//! run may write subfolders). [`claim`] reads the folder before anything is written:
//! - a file that no summary of this job lists is foreign (another shot's frames, someone's
//!   notes): refused, naming it, unless the caller overwrites;
//! - files that this run's own earlier summary lists and this run will not write (the input
//!   shrank, `--maps` dropped) are stale and removed;
//! - another slice's files made with other settings would leave a folder of two settings:
//!   refused unless the caller overwrites, which removes them and their summary.
//!
//! Names starting with `.` (temporary files, locks, a desktop's own files) are not looked at;
//! a subfolder is looked into where the job writes into it, and is otherwise foreign itself.

use crate::error::{Error, Result};
use crate::io::atomic::{ensure_dir, remove_stale_temps};
use crate::io::json::{read_json, write_json, Layout, Object, Value};
use std::collections::{HashMap, HashSet};
use std::fs::{self, File, TryLockError};
use std::io::{Read, Seek, Write};
use std::path::{Path, PathBuf};

/// Who a run is and what it leaves in its folder, as its summary records it.
pub struct Ownership {
    /// The summaries' name stem (`upscale`): `upscale*.json` are this kind of job's summaries.
    pub job: &'static str,
    /// What the inputs are, in messages: `shot` (upscale), `data set` (train), `scene`
    /// (simulate, demo), `set of runs` (eval).
    pub noun: &'static str,
    /// The job's identity: its inputs, canonical paths.
    pub inputs: Vec<String>,
    /// Everything that decides the output's bytes: runs with the same settings write the same
    /// bytes for the same frame.
    pub settings: Value,
    /// This run's summary file name (`upscale.json`, `upscale.0-100.json`).
    pub summary: String,
    /// The files this run writes besides its summary, as paths inside the folder
    /// (`frame_0000.obj`, `lr/geometry.npy`).
    pub files: Vec<String>,
}

impl Ownership {
    /// `o` (a summary) with the run's identity: its inputs, its settings and the files it
    /// writes, so the summary lists exactly what the run leaves in the folder.
    pub fn record(&self, o: Object) -> Object {
        let strings =
            |v: &[String]| Value::from(v.iter().map(|s| Value::from(s.as_str())).collect::<Vec<_>>());
        o.val("inputs", strings(&self.inputs))
            .val("settings", self.settings.clone())
            .val("files", strings(&self.files))
    }

    /// Write the run's summary `dir/SUMMARY`: `body` with `complete` and the run's identity
    /// ([`Ownership::record`]). A run writes it `complete: false` right after [`claim`] (so a
    /// killed run's files are still its job's) and `complete: true` when it is done.
    pub fn write_summary(&self, dir: &Path, body: Object, complete: bool) -> Result<()> {
        let mut o = Object::new().val("complete", Value::Bool(complete));
        o.0.extend(body.0);
        write_json(&dir.join(&self.summary), &self.record(o).into(), Layout::Indented)
    }
}

/// A folder a run may write: the lock on its summary, held until dropped.
pub struct Claim {
    lock: File,
    /// Stale files removed, by name.
    pub removed: Vec<String>,
}

impl Drop for Claim {
    /// The lock file is left empty (its holder gone) and then released: two finished runs leave
    /// the same bytes in the folder. A killed run's holder line stays until the next run.
    fn drop(&mut self) {
        let _ = self.lock.set_len(0);
    }
}

/// What an earlier summary in the folder says.
struct Earlier {
    name: String,
    same_job: bool,
    same_settings: bool,
    files: Vec<String>,
}

/// Claim `dir` for the run `own` (see the module docs). `overwrite`: foreign files the run
/// writes are replaced and other settings' files removed instead of refused.
pub fn claim(dir: &Path, own: &Ownership, overwrite: bool) -> Result<Claim> {
    ensure_dir(dir)?;
    let lock_path = dir.join(format!(".{}.lock", own.summary));
    let created = !lock_path.exists();
    let lock = lock(&lock_path, dir, &own.summary)?;
    match check(dir, own, overwrite) {
        Ok(removed) => {
            // Temporaries of atomic writes that a killed run of this folder left behind (the
            // summary's too); under the lock no other run is writing them.
            for f in std::iter::once(&own.summary).chain(&own.files) {
                remove_stale_temps(&dir.join(f))?;
            }
            Ok(Claim { lock, removed })
        }
        Err(e) => {
            // A refused run leaves the folder as it found it.
            if created {
                let _ = fs::remove_file(&lock_path);
            }
            Err(e)
        }
    }
}

/// Claim the one file `path` a run writes whole (`bundle`, `dataset`): refused while another
/// run writes it (a lock, `.NAME.lock` beside it), and where it exists but is not what this
/// command writes (`ours` says whether it is; `what` names that kind in the message), unless
/// `overwrite`. The caller refuses a path that is one of its inputs.
pub fn claim_file(
    path: &Path,
    what: &str,
    ours: impl FnOnce(&Path) -> bool,
    overwrite: bool,
) -> Result<Claim> {
    let name = path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
    if name.is_empty() || path.is_dir() {
        return Err(Error::format(path, "is a folder, not a file name: give the file to write"));
    }
    let dir = path.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new("."));
    ensure_dir(dir)?;
    let lock_path = dir.join(format!(".{name}.lock"));
    let created = !lock_path.exists();
    let lock = lock(&lock_path, dir, &name)?;
    let exists = fs::symlink_metadata(path).is_ok();
    if exists && !overwrite && !ours(path) {
        if created {
            let _ = fs::remove_file(&lock_path);
        }
        return Err(Error::invalid(
            "out",
            format!(
                "{} exists and is not {what}: writing it would replace someone's file; choose \
                 another file, or overwrite to replace it",
                path.display()
            ),
        ));
    }
    Ok(Claim { lock, removed: Vec::new() })
}

/// [`claim`]'s reading of the folder, under the lock: the stale files it removed.
fn check(dir: &Path, own: &Ownership, overwrite: bool) -> Result<Vec<String>> {
    let mut earlier = Vec::new();
    for e in fs::read_dir(dir).map_err(|e| Error::io(dir, e))? {
        let e = e.map_err(|e| Error::io(dir, e))?;
        let name = e.file_name().to_string_lossy().into_owned();
        let file = e.file_type().is_ok_and(|t| t.is_file());
        if file && name.starts_with(own.job) && name.ends_with(".json") {
            earlier.push(read_earlier(&dir.join(&name), name, own));
        }
    }
    // The subfolders this job writes into (its own, and its earlier runs'): looked into.
    let mut subfolders = HashSet::new();
    let ours = earlier.iter().filter(|s| s.same_job).flat_map(|s| &s.files);
    for f in own.files.iter().chain(ours) {
        let mut p = f.as_str();
        while let Some((d, _)) = p.rsplit_once('/') {
            subfolders.insert(d.to_string());
            p = d;
        }
    }
    let summaries: HashSet<&str> = earlier.iter().map(|s| s.name.as_str()).collect();
    let mut others = Vec::new();
    list(dir, "", &subfolders, &mut others)?;
    others.retain(|n| !summaries.contains(n.as_str()));
    let writes: HashSet<&str> = own.files.iter().map(String::as_str).collect();
    // Every file a summary of this job lists, and which summaries list it.
    let mut listed: HashMap<&str, Vec<&str>> = HashMap::new();
    for s in earlier.iter().filter(|s| s.same_job) {
        for f in &s.files {
            listed.entry(f).or_default().push(&s.name);
        }
    }
    // What the run removes, once nothing refuses it: a refused run leaves the folder as it was.
    let mut stale: Vec<&str> = Vec::new();
    // Another run's summary (another job, or one this version cannot read): its folder.
    if let Some(s) = earlier.iter().find(|s| !s.same_job) {
        if !overwrite {
            return Err(foreign(dir, &s.name, &format!("the summary of another {}'s run", own.noun), own));
        }
    }
    for s in earlier.iter().filter(|s| s.same_job && !s.same_settings && s.name != own.summary) {
        if !overwrite {
            return Err(Error::invalid(
                "out",
                format!(
                    "{} holds {} (another slice of this {}, made with other settings): the folder \
                     would mix two settings; run that slice again with these settings, choose \
                     another folder, or overwrite to remove it",
                    dir.display(),
                    s.name,
                    own.noun
                ),
            ));
        }
        stale.extend(
            s.files.iter().filter(|f| !writes.contains(f.as_str())).chain([&s.name]).map(String::as_str),
        );
    }
    for name in &others {
        match listed.get(name.as_str()) {
            // This run's own earlier output that it will not write again: stale.
            Some(by) if by.iter().all(|s| *s == own.summary) && !writes.contains(name.as_str()) => {
                stale.push(name)
            }
            Some(_) => {}
            None if overwrite => {}
            None => {
                let what = format!("a file no {} of these inputs wrote", own.job);
                return Err(foreign(dir, name, &what, own));
            }
        }
    }
    let mut removed = Vec::new();
    for f in stale {
        remove(dir, f, &mut removed)?;
    }
    Ok(removed)
}

/// Every entry of `root/rel` (paths inside `root`), looking into the subfolders the job writes
/// into; another folder (a link to one included) is one entry, `NAME/`. Names starting with
/// `.` are left out.
fn list(root: &Path, rel: &str, subfolders: &HashSet<String>, out: &mut Vec<String>) -> Result<()> {
    let here = if rel.is_empty() { root.to_path_buf() } else { root.join(rel) };
    for e in fs::read_dir(&here).map_err(|e| Error::io(&here, e))? {
        let e = e.map_err(|e| Error::io(&here, e))?;
        let name = e.file_name().to_string_lossy().into_owned();
        if name.starts_with('.') {
            continue;
        }
        let path = if rel.is_empty() { name } else { format!("{rel}/{name}") };
        // `file_type` does not follow a link: a link to a folder is never walked.
        let folder = e.file_type().is_ok_and(|t| t.is_dir());
        if folder && subfolders.contains(&path) {
            list(root, &path, subfolders, out)?;
        } else if folder {
            out.push(format!("{path}/"));
        } else {
            out.push(path);
        }
    }
    Ok(())
}

/// The error for a file of `dir` that is not this job's.
fn foreign(dir: &Path, name: &str, what: &str, own: &Ownership) -> Error {
    Error::invalid(
        "out",
        format!(
            "{} holds {name} ({what}): a run writes into a new or empty folder, or one that \
             earlier runs of the same {} own; choose another folder, or overwrite to write \
             into this one anyway",
            dir.display(),
            own.noun
        ),
    )
}

fn remove(dir: &Path, name: &str, removed: &mut Vec<String>) -> Result<()> {
    let p = dir.join(name);
    match fs::remove_file(&p) {
        Ok(()) => removed.push(name.to_string()),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
        Err(e) => return Err(Error::io(p, e)),
    }
    Ok(())
}

/// Read the summary `path` (named `name`) against `own`; one that cannot be read is another
/// job's.
fn read_earlier(path: &Path, name: String, own: &Ownership) -> Earlier {
    let v = read_json(path).ok();
    let strings = |key: &str| -> Option<Vec<String>> {
        let a = v.as_ref()?.get(key)?.as_array()?;
        a.iter().map(|s| s.as_str().map(str::to_string)).collect()
    };
    let same_job = strings("inputs").is_some_and(|i| i == own.inputs);
    let same_settings =
        v.as_ref().and_then(|v| v.get("settings")).is_some_and(|s| s.to_json() == own.settings.to_json());
    Earlier { name, same_job, same_settings, files: strings("files").unwrap_or_default() }
}

/// Lock `path` (`dir/.SUMMARY.lock`) for this process (released by the OS when it ends, a kill
/// included); refused, naming the holder, while another run holds it.
fn lock(path: &Path, dir: &Path, summary: &str) -> Result<File> {
    // Never through a link planted at the lock's name (its target would be truncated).
    if fs::symlink_metadata(path).is_ok_and(|m| !m.is_file()) {
        return Err(Error::format(path, "not a regular file: remove it (anisocb keeps its lock here)"));
    }
    let mut file = fs::OpenOptions::new()
        .read(true)
        .write(true)
        .create(true)
        .truncate(false)
        .open(path)
        .map_err(|e| Error::io(path, e))?;
    match file.try_lock() {
        Ok(()) => {}
        Err(TryLockError::WouldBlock) => {
            let mut holder = String::new();
            let _ = file.read_to_string(&mut holder);
            return Err(Error::invalid(
                "out",
                format!(
                    "{} is being written by another run ({}) of the same output ({summary}); \
                     wait for it to finish, or choose another folder",
                    dir.display(),
                    holder.trim()
                ),
            ));
        }
        Err(TryLockError::Error(e)) => return Err(Error::io(path, e)),
    }
    let host = fs::read_to_string("/proc/sys/kernel/hostname").unwrap_or_default();
    let me = format!("process {} on {}", std::process::id(), host.trim());
    let written = file.set_len(0).and_then(|()| file.rewind()).and_then(|()| file.write_all(me.as_bytes()));
    written.map_err(|e| Error::io(path, e))?;
    Ok(file)
}

/// Canonical paths of `paths` (as given where they cannot be resolved), for
/// [`Ownership::inputs`].
pub fn canonical(paths: &[PathBuf]) -> Vec<String> {
    paths
        .iter()
        .map(|p| p.canonicalize().unwrap_or_else(|_| p.clone()).to_string_lossy().into_owned())
        .collect()
}
