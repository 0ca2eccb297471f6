//! What an output folder may hold and how it is written: temporary files are created
//! exclusively, never through a link planted in the folder.

#[path = "common/tempdir.rs"]
mod tempdir;
use anisocb::io::atomic::write_atomic_bytes;
use tempdir::TempDir;

#[test]
fn a_symlink_planted_at_a_temp_name_is_never_followed() {
    let d = TempDir::new("temp-symlink");
    let victim = d.join("victim.txt");
    std::fs::write(&victim, b"someone else's file").unwrap();
    // Every temp name this process can take first (`.NAME.tmp.<pid>.<n>`), a link to the victim.
    for n in 0..64 {
        let link = d.join(format!(".out.json.tmp.{}.{n}", std::process::id()));
        std::os::unix::fs::symlink(&victim, link).unwrap();
    }
    write_atomic_bytes(&d.join("out.json"), b"{}").unwrap();
    assert_eq!(std::fs::read(d.join("out.json")).unwrap(), b"{}");
    assert_eq!(std::fs::read(&victim).unwrap(), b"someone else's file", "the link was followed");
}
