//! Weights in `.npz` (a stored zip of `.npy`, what `numpy.savez` writes), PyTorch-style:
//! `conv_in.weight` (C, 3, 3, 3), `conv_in.bias` (C), `blocks.K.conv1.weight`, …,
//! `upscale.weight` (r²C, C, 3, 3), `tail.0.weight` … `tail.3.weight` (out, C, 3, 3), all OIHW,
//! plus a `config.json` entry (`{"kind": "geometry", "channels": 64, "blocks": 10, "scale": 2,
//! "padding": "zero", …}`). A bundle holds the three nets with prefixes `geometry.`,
//! `boundary.`, `enhance.` on every name, `geometry.config.json` included.
//! See `weights/README.md` for a PyTorch module that loads the same file.

use super::bundle::AnisoCb;
use super::config::{NetConfig, NetKind};
use super::layers::{param_shapes, Trunk};
use crate::error::{Error, Result};
use crate::io::npz::npz_from_bytes;
use crate::io::{read_npz, write_npz, NpzEntries};
use std::path::Path;

/// The shipped ×2 model (see weights/README.md), embedded so the binary needs no files.
pub static EMBEDDED_WEIGHTS: &[u8] = include_bytes!("../../weights/anisocb-x2.npz");

/// Decode [`EMBEDDED_WEIGHTS`].
pub fn embedded_model() -> Result<AnisoCb> {
    let what = Path::new("<embedded weights/anisocb-x2.npz>");
    let e = npz_from_bytes(EMBEDDED_WEIGHTS).map_err(|e| e.in_file(what))?;
    bundle_from_npz(&e, what)
}

/// Add `trunk`'s arrays and config to `entries`, every name prefixed by `prefix`.
pub fn push_trunk(entries: &mut NpzEntries, trunk: &Trunk, prefix: &str) {
    for (name, t) in trunk.params() {
        entries.push_array(format!("{prefix}{name}"), t.clone());
    }
    entries.push_file(format!("{prefix}config.json"), trunk.config.to_json(trunk.kind).into_bytes());
}

fn listed(v: &[String]) -> String {
    const MAX: usize = 8;
    let mut s = v.iter().take(MAX).cloned().collect::<Vec<_>>().join(", ");
    if v.len() > MAX {
        s.push_str(&format!(" … and {} more", v.len() - MAX));
    }
    s
}

/// Read the net stored under `prefix` from `entries` (read from `path`, for messages). With
/// `expect`, the stored kind and config must equal it. Names and shapes must match the config
/// exactly; every difference is listed in the error.
pub fn trunk_from_npz(
    entries: &NpzEntries,
    prefix: &str,
    path: &Path,
    expect: Option<(NetKind, NetConfig)>,
) -> Result<Trunk> {
    let cfg_name = format!("{prefix}config.json");
    let cfg_bytes = entries.file(&cfg_name).ok_or_else(|| {
        // A single net (`train`'s output) where a bundle's net was looked for.
        let single = (!prefix.is_empty())
            .then(|| entries.file("config.json"))
            .flatten()
            .and_then(|b| NetConfig::from_json(&String::from_utf8_lossy(b)).ok());
        let why = match single {
            Some((kind, _)) => format!(
                "this file is a single {} net (as `anisocb train` writes), not a bundle of the \
                 three nets that upscaling needs: combine nets with `anisocb bundle --geometry G \
                 --boundary B --enhance E --out W.npz`, or give a bundle such as \
                 weights/anisocb-x2.npz",
                kind.name()
            ),
            None => format!(
                "no '{cfg_name}' entry: not an anisocb weights file (see weights/README.md for the layout)"
            ),
        };
        Error::format(path, why)
    })?;
    let (kind, config) = NetConfig::from_json_str(&String::from_utf8_lossy(cfg_bytes))
        .map_err(|m| Error::format(path, format!("{cfg_name}: {}", m.trim_start_matches("config.json: "))))?;
    if let Some((ekind, ecfg)) = expect {
        let mut diffs = Vec::new();
        if ekind != kind {
            diffs.push(format!("kind: {} vs {}", kind.name(), ekind.name()));
        }
        diffs.extend(config.diff(&ecfg));
        if !diffs.is_empty() {
            return Err(Error::format(
                path,
                format!(
                    "{prefix}weights do not match the expected net (file vs expected): {}",
                    diffs.join("; ")
                ),
            ));
        }
    }
    let want = param_shapes(kind, config);
    let mut missing = Vec::new();
    let mut wrong = Vec::new();
    // Check every array before allocating the trunk: a tiny file whose config.json claims a
    // huge net must not allocate that net (sizes are then bounded by the arrays present).
    for (name, shape) in want.iter() {
        match entries.array(&format!("{prefix}{name}")) {
            None => missing.push(format!("{prefix}{name}")),
            Some(t) if &t.shape != shape => {
                wrong.push(format!("{prefix}{name} is {:?}, expected {:?}", t.shape, shape))
            }
            Some(t) => {
                if let Some((i, v)) = t.first_non_finite() {
                    return Err(Error::format(
                        path,
                        format!("{prefix}{name}: non-finite value {v} at index {i}"),
                    ));
                }
            }
        }
    }
    let unexpected: Vec<String> = entries
        .arrays
        .iter()
        .filter_map(|(n, _)| n.strip_prefix(prefix).map(|rest| (n, rest)))
        .filter(|(_, rest)| !want.iter().any(|(w, _)| w == rest))
        // In a bundle, another net's names also start with the empty prefix; skip them.
        .filter(|(_, rest)| {
            !prefix.is_empty() || !NetKind::ALL.iter().any(|k| rest.starts_with(&format!("{}.", k.name())))
        })
        .map(|(n, _)| n.clone())
        .collect();
    if !(missing.is_empty() && wrong.is_empty() && unexpected.is_empty()) {
        let mut parts = Vec::new();
        if !missing.is_empty() {
            parts.push(format!("missing {}: {}", missing.len(), listed(&missing)));
        }
        if !wrong.is_empty() {
            parts.push(format!("wrong shape {}: {}", wrong.len(), listed(&wrong)));
        }
        if !unexpected.is_empty() {
            parts.push(format!("unexpected {}: {}", unexpected.len(), listed(&unexpected)));
        }
        return Err(Error::format(
            path,
            format!(
                "weights do not match their config ({} net, {}): {}",
                kind.name(),
                config,
                parts.join("; ")
            ),
        ));
    }
    let mut trunk = Trunk::zeros(kind, config);
    for ((name, _), dst) in want.iter().zip(trunk.params_mut()) {
        if let Some(t) = entries.array(&format!("{prefix}{name}")) {
            dst.data.copy_from_slice(&t.data);
        }
    }
    Ok(trunk)
}

/// Write one net (names without prefix), atomically.
pub fn save_net(path: &Path, trunk: &Trunk) -> Result<()> {
    let mut e = NpzEntries::default();
    push_trunk(&mut e, trunk, "");
    write_npz(path, &e)
}

/// Read one net; with `expect`, refuse any other kind or config.
pub fn load_net(path: &Path, expect: Option<(NetKind, NetConfig)>) -> Result<Trunk> {
    trunk_from_npz(&read_npz(path)?, "", path, expect)
}

/// A weights file holds either one net or a bundle of three.
#[derive(Clone, Debug)]
pub enum Weights {
    Net(Box<Trunk>),
    Bundle(Box<AnisoCb>),
}

/// Read a weights file of either layout.
pub fn load_any(path: &Path) -> Result<Weights> {
    let e = read_npz(path)?;
    if e.file("geometry.config.json").is_some() {
        Ok(Weights::Bundle(Box::new(bundle_from_npz(&e, path)?)))
    } else {
        Ok(Weights::Net(Box::new(trunk_from_npz(&e, "", path, None)?)))
    }
}

pub fn bundle_to_npz(b: &AnisoCb) -> NpzEntries {
    let mut e = NpzEntries::default();
    for (name, t) in b.named_trunks() {
        push_trunk(&mut e, t, &format!("{name}."));
    }
    e
}

pub fn bundle_from_npz(e: &NpzEntries, path: &Path) -> Result<AnisoCb> {
    let mut t = NetKind::ALL.iter().map(|k| trunk_from_npz(e, &format!("{}.", k.name()), path, None));
    let (g, b, n) = (t.next().unwrap()?, t.next().unwrap()?, t.next().unwrap()?);
    // An ensemble's further GeometryNets: `geometry1.`, `geometry2.`, … while they last.
    let mut more = Vec::new();
    while e.file(&format!("geometry{}.config.json", more.len() + 1)).is_some() {
        let prefix = format!("geometry{}.", more.len() + 1);
        more.push(trunk_from_npz(e, &prefix, path, Some((NetKind::Geometry, g.config)))?);
    }
    let mut prefixes: Vec<String> = NetKind::ALL.iter().map(|k| format!("{}.", k.name())).collect();
    prefixes.extend((1..=more.len()).map(|k| format!("geometry{k}.")));
    let other: Vec<String> = e
        .arrays
        .iter()
        .map(|(n, _)| n.clone())
        .filter(|n| !prefixes.iter().any(|p| n.starts_with(p.as_str())))
        .collect();
    if !other.is_empty() {
        return Err(Error::format(path, format!("bundle has arrays outside its nets: {}", listed(&other))));
    }
    AnisoCb::from_trunks(g, b, n).and_then(|m| m.with_more_geometry(more)).map_err(|e| e.in_file(path))
}

impl AnisoCb {
    /// Write the bundle (`geometry.*`, `geometry1.*` … for an ensemble, `boundary.*`,
    /// `enhance.*`), atomically.
    pub fn save(&self, path: &Path) -> Result<()> {
        write_npz(path, &bundle_to_npz(self))
    }

    /// Read a bundle written by [`AnisoCb::save`] (or by the PyTorch module in weights/README.md).
    pub fn load(path: &Path) -> Result<AnisoCb> {
        bundle_from_npz(&read_npz(path)?, path)
    }
}
