//! `.npz` = a zip of `.npy` files (what `numpy.savez` writes). We write stored (uncompressed)
//! zips and read stored ones; entries that are not `.npy` (e.g. `config.json`) are kept as raw
//! bytes, which `numpy.load` also returns as bytes. Hand-written (~150 lines) so the core does
//! not pull a zip crate with C compression libraries; `np.savez_compressed` files get a clear
//! error asking for `np.savez`.

use super::npy::{npy_bytes, tensor_from_npy_bytes_str};
use crate::error::{Error, Result};
use crate::tensor::Tensor;
use std::path::Path;

#[derive(Default, Debug, Clone)]
pub struct NpzEntries {
    /// Arrays in file order, named without the `.npy` suffix.
    pub arrays: Vec<(String, Tensor)>,
    /// Non-array entries (metadata such as `config.json`), with their full names.
    pub files: Vec<(String, Vec<u8>)>,
}

impl NpzEntries {
    pub fn array(&self, name: &str) -> Option<&Tensor> {
        self.arrays.iter().find(|(n, _)| n == name).map(|(_, t)| t)
    }
    pub fn file(&self, name: &str) -> Option<&[u8]> {
        self.files.iter().find(|(n, _)| n == name).map(|(_, b)| b.as_slice())
    }
    pub fn push_array(&mut self, name: impl Into<String>, t: Tensor) {
        self.arrays.push((name.into(), t));
    }
    pub fn push_file(&mut self, name: impl Into<String>, bytes: Vec<u8>) {
        self.files.push((name.into(), bytes));
    }
    /// The array `name`, or an error naming `path` and what is missing.
    pub fn require(&self, path: &Path, name: &str) -> Result<&Tensor> {
        self.array(name).ok_or_else(|| Error::format(path, format!("missing array '{name}'")))
    }
}

/// zlib's CRC-32 (reflected, polynomial 0xEDB88320), slicing by 8: eight bytes a step through
/// eight tables, T₀ the byte-wise one and Tₖ[i] = T₀[Tₖ₋₁[i] & 0xFF] ^ (Tₖ₋₁[i] >> 8), the
/// rest byte by byte. About 5× the byte-wise loop ([`crc32_bytewise`], its twin); the weights
/// bundle is checked on every start.
fn crc32(data: &[u8]) -> u32 {
    static TABLES: std::sync::OnceLock<[[u32; 256]; 8]> = std::sync::OnceLock::new();
    let t = TABLES.get_or_init(|| {
        let mut t = [[0u32; 256]; 8];
        t[0] = crc32_table();
        for k in 1..8 {
            for i in 0..256 {
                let prev = t[k - 1][i];
                t[k][i] = t[0][(prev & 0xFF) as usize] ^ (prev >> 8);
            }
        }
        t
    });
    let mut chunks = data.chunks_exact(8);
    let mut c = !0u32;
    for ch in &mut chunks {
        let one = u32::from_le_bytes([ch[0], ch[1], ch[2], ch[3]]) ^ c;
        let two = u32::from_le_bytes([ch[4], ch[5], ch[6], ch[7]]);
        let b = |v: u32, s: u32| ((v >> s) & 0xFF) as usize;
        c = t[7][b(one, 0)]
            ^ t[6][b(one, 8)]
            ^ t[5][b(one, 16)]
            ^ t[4][b(one, 24)]
            ^ t[3][b(two, 0)]
            ^ t[2][b(two, 8)]
            ^ t[1][b(two, 16)]
            ^ t[0][b(two, 24)];
    }
    !chunks.remainder().iter().fold(c, |c, &b| t[0][((c ^ b as u32) & 0xFF) as usize] ^ (c >> 8))
}

/// The byte-wise table of zlib's CRC-32: the remainder of each byte.
fn crc32_table() -> [u32; 256] {
    let mut t = [0u32; 256];
    for (i, e) in t.iter_mut().enumerate() {
        let mut c = i as u32;
        for _ in 0..8 {
            c = if c & 1 != 0 { 0xEDB8_8320 ^ (c >> 1) } else { c >> 1 };
        }
        *e = c;
    }
    t
}

/// [`crc32`]'s scalar twin: one byte a step.
#[cfg(test)]
fn crc32_bytewise(data: &[u8]) -> u32 {
    let table = crc32_table();
    !data.iter().fold(!0u32, |c, &b| table[((c ^ b as u32) & 0xFF) as usize] ^ (c >> 8))
}

/// Serialize entries as a stored zip.
pub fn npz_bytes(entries: &NpzEntries) -> Result<Vec<u8>> {
    let mut out = Vec::new();
    let mut central = Vec::new();
    let mut count = 0u16;
    let all = entries
        .arrays
        .iter()
        .map(|(n, t)| (format!("{n}.npy"), npy_bytes(t)))
        .chain(entries.files.iter().cloned());
    for (name, data) in all {
        if data.len() > u32::MAX as usize || out.len() > u32::MAX as usize {
            return Err(Error::shape(format!("npz entry {name} exceeds 4 GiB (no zip64)")));
        }
        let crc = crc32(&data);
        let offset = out.len() as u32;
        let common = |v: &mut Vec<u8>| {
            v.extend_from_slice(&20u16.to_le_bytes()); // version needed
            v.extend_from_slice(&0u16.to_le_bytes()); // flags
            v.extend_from_slice(&0u16.to_le_bytes()); // method: stored
            v.extend_from_slice(&0u16.to_le_bytes()); // time
            v.extend_from_slice(&0x21u16.to_le_bytes()); // date 1980-01-01
            v.extend_from_slice(&crc.to_le_bytes());
            v.extend_from_slice(&(data.len() as u32).to_le_bytes());
            v.extend_from_slice(&(data.len() as u32).to_le_bytes());
            v.extend_from_slice(&(name.len() as u16).to_le_bytes());
            v.extend_from_slice(&0u16.to_le_bytes()); // extra
        };
        out.extend_from_slice(&0x0403_4b50u32.to_le_bytes());
        common(&mut out);
        out.extend_from_slice(name.as_bytes());
        out.extend_from_slice(&data);
        central.extend_from_slice(&0x0201_4b50u32.to_le_bytes());
        central.extend_from_slice(&20u16.to_le_bytes()); // version made by
        common(&mut central);
        central.extend_from_slice(&[0u8; 8]); // comment len, disk, int attr, ext attr (lo)
        central.extend_from_slice(&[0u8; 2]); // ext attr (hi)
        central.extend_from_slice(&offset.to_le_bytes());
        central.extend_from_slice(name.as_bytes());
        count += 1;
    }
    let cd_offset = out.len() as u32;
    out.extend_from_slice(&central);
    out.extend_from_slice(&0x0605_4b50u32.to_le_bytes());
    out.extend_from_slice(&[0u8; 4]);
    out.extend_from_slice(&count.to_le_bytes());
    out.extend_from_slice(&count.to_le_bytes());
    out.extend_from_slice(&(central.len() as u32).to_le_bytes());
    out.extend_from_slice(&cd_offset.to_le_bytes());
    out.extend_from_slice(&0u16.to_le_bytes());
    Ok(out)
}

pub fn write_npz(path: &Path, entries: &NpzEntries) -> Result<()> {
    super::write_atomic_bytes(path, &npz_bytes(entries)?)
}

pub fn read_npz(path: &Path) -> Result<NpzEntries> {
    let bytes = super::read_bytes(path)?;
    npz_from_bytes(&bytes).map_err(|e| e.in_file(path))
}

fn u16_at(b: &[u8], i: usize) -> std::result::Result<u16, String> {
    b.get(i..i + 2).map(|s| u16::from_le_bytes([s[0], s[1]])).ok_or_else(|| "truncated zip".into())
}
fn u32_at(b: &[u8], i: usize) -> std::result::Result<u32, String> {
    b.get(i..i + 4)
        .map(|s| u32::from_le_bytes([s[0], s[1], s[2], s[3]]))
        .ok_or_else(|| "truncated zip".into())
}

pub fn npz_from_bytes(b: &[u8]) -> Result<NpzEntries> {
    npz_from_bytes_str(b).map_err(Error::Malformed)
}

fn npz_from_bytes_str(b: &[u8]) -> std::result::Result<NpzEntries, String> {
    if b.is_empty() {
        return Err("empty file (0 bytes); expected an .npz archive".into());
    }
    if b.len() < 22 || &b[..2] != b"PK" {
        return Err("not an .npz (zip) file".into());
    }
    let lo = b.len().saturating_sub(22 + 65535);
    let eocd = (lo..=b.len() - 22)
        .rev()
        .find(|&i| b[i..i + 4] == 0x0605_4b50u32.to_le_bytes())
        .ok_or("no zip end-of-directory record (truncated file?)")?;
    let count = u16_at(b, eocd + 10)? as usize;
    let mut p = u32_at(b, eocd + 16)? as usize;
    let mut entries = NpzEntries::default();
    // Entries must not overlap: the sum of their sizes is bounded by the file's size, so a
    // directory that points many entries at one big array cannot multiply the memory used.
    let mut total = 0usize;
    for _ in 0..count {
        if u32_at(b, p)? != 0x0201_4b50 {
            return Err("corrupt zip central directory".into());
        }
        let method = u16_at(b, p + 10)?;
        let crc = u32_at(b, p + 16)?;
        let csize = u32_at(b, p + 20)? as usize;
        let name_len = u16_at(b, p + 28)? as usize;
        let extra_len = u16_at(b, p + 30)? as usize;
        let comment_len = u16_at(b, p + 32)? as usize;
        let local = u32_at(b, p + 42)? as usize;
        let name = b.get(p + 46..p + 46 + name_len).ok_or("truncated zip")?;
        let name = String::from_utf8_lossy(name).into_owned();
        p += 46 + name_len + extra_len + comment_len;
        if method != 0 {
            return Err(format!(
                "entry '{name}' is compressed (method {method}); only stored .npz is supported — save with numpy.savez, not savez_compressed"
            ));
        }
        if csize == u32::MAX as usize || local == u32::MAX as usize {
            return Err(format!("entry '{name}' needs zip64 (over 4 GiB), which is not supported"));
        }
        if u32_at(b, local)? != 0x0403_4b50 {
            return Err(format!("entry '{name}': corrupt local header"));
        }
        let start = local + 30 + u16_at(b, local + 26)? as usize + u16_at(b, local + 28)? as usize;
        let data = b
            .get(start..start.saturating_add(csize))
            .ok_or_else(|| format!("entry '{name}' is truncated"))?;
        total = total.saturating_add(30 + name_len + csize);
        if total > b.len() {
            return Err(format!(
                "entry '{name}': entries overlap or exceed the file (corrupt zip directory)"
            ));
        }
        if entries.arrays.iter().any(|(n, _)| name.strip_suffix(".npy") == Some(n.as_str()))
            || entries.files.iter().any(|(n, _)| *n == name)
        {
            return Err(format!("duplicate entry '{name}'"));
        }
        if crc32(data) != crc {
            return Err(format!("entry '{name}': CRC mismatch (corrupted file)"));
        }
        match name.strip_suffix(".npy") {
            Some(stem) => {
                let t = tensor_from_npy_bytes_str(data).map_err(|m| format!("array '{stem}': {m}"))?;
                entries.arrays.push((stem.to_string(), t));
            }
            None => entries.files.push((name, data.to_vec())),
        }
    }
    Ok(entries)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn npz_round_trip_keeps_arrays_and_files() {
        let mut e = NpzEntries::default();
        e.push_array("a.weight", Tensor::from_vec(&[2, 3], (0..6).map(|v| v as f32).collect()).unwrap());
        e.push_file("config.json", b"{\"c\":1}".to_vec());
        let back = npz_from_bytes(&npz_bytes(&e).unwrap()).unwrap();
        assert_eq!(back.array("a.weight"), e.array("a.weight"));
        assert_eq!(back.file("config.json"), Some(&b"{\"c\":1}"[..]));
    }

    #[test]
    fn crc32_matches_known_value() {
        assert_eq!(crc32(b"123456789"), 0xCBF4_3926);
        assert_eq!(crc32_bytewise(b"123456789"), 0xCBF4_3926);
        assert_eq!(crc32(b""), 0);
    }

    #[test]
    fn crc32_sliced_by_8_is_its_bytewise_twin_on_every_length_and_offset() {
        let mut rng = crate::rng::Rng::new(11);
        let data: Vec<u8> = (0..5000).map(|_| (rng.uniform() * 256.0) as u8).collect();
        for len in (0..40).chain([63, 64, 65, 1000, 4093]) {
            for off in 0..9 {
                let d = &data[off..off + len];
                assert_eq!(crc32(d), crc32_bytewise(d), "length {len} offset {off}");
            }
        }
    }
}
