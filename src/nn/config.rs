//! Which network, and its shape: [`NetKind`] and [`NetConfig`] with named presets.
//!
//! | preset  | channels C | blocks | scale | conv layers | parameters (GeometryNet) | use |
//! |---------|-----------:|-------:|------:|------------:|-------------------------:|-----|
//! | `paper` | 64         | 10     | ×2    | 26          | ≈ 1.0 M                 | the paper's model |
//! | `small` | 32         | 4      | ×2    | 14          | ≈ 0.14 M                 | CPU training (≈ 6× cheaper per pixel than `paper`; ~10 min on 2 cores gives a useful model) |
//! | `tiny`  | 4          | 2      | ×2    | 10          | ≈ 1.9 k                  | tests and reference fixtures |
//!
//! All presets use zero padding (the paper's "padding 1"); replicate padding is a per-config
//! option (`with_padding`).

use crate::error::{Error, Result};
use crate::geom::cloth_frame::InputFrame;
use crate::io::json::Object;
use crate::ops::{Interp, Padding};

/// The three networks. GeometryNet predicts the 3-channel residual `R`; BoundaryNet and
/// EnhanceNet predict one channel of logits.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum NetKind {
    Geometry,
    Boundary,
    Enhance,
}

impl NetKind {
    pub const ALL: [NetKind; 3] = [NetKind::Geometry, NetKind::Boundary, NetKind::Enhance];

    pub fn name(self) -> &'static str {
        match self {
            NetKind::Geometry => "geometry",
            NetKind::Boundary => "boundary",
            NetKind::Enhance => "enhance",
        }
    }

    pub fn parse(s: &str) -> Result<NetKind> {
        match s {
            "geometry" => Ok(NetKind::Geometry),
            "boundary" => Ok(NetKind::Boundary),
            "enhance" => Ok(NetKind::Enhance),
            _ => Err(Error::config(format!("unknown net '{s}' (expected geometry, boundary or enhance)"))),
        }
    }

    /// Output channels: 3 (residual xyz) for GeometryNet, 1 (logits) for the map nets.
    pub fn out_channels(self) -> usize {
        match self {
            NetKind::Geometry => 3,
            _ => 1,
        }
    }

    /// Residual skips inside the blocks: only GeometryNet has them (paper).
    pub fn residual(self) -> bool {
        self == NetKind::Geometry
    }
}

/// Shape of one network. Input is always a 3-channel geometry image.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct NetConfig {
    /// Feature width C of every hidden conv.
    pub channels: usize,
    /// Number of blocks `conv → relu → conv` (with a skip in GeometryNet).
    pub blocks: usize,
    /// Upscale factor r of the sub-pixel layer (output is r·H × r·W).
    pub scale: usize,
    /// How every 3×3 conv reads outside the image.
    pub padding: Padding,
    /// The coordinates the net's input (and GeometryNet's residual) are in: the paper's
    /// sequence box, or the per-frame cloth frame (`geom::cloth_frame`). `config.json` key
    /// `input`; a file without it is a `domain` net (every model before the cloth frame).
    pub input_frame: InputFrame,
    /// The interpolation `U` that GeometryNet's residual refines (and the composition falls
    /// back to): `bicubic` (Keys a = −0.75, the paper's and PyTorch's) or `catmull-rom`
    /// (a = −0.5, keeps evenly spaced vertices evenly spaced). `config.json` key `upsample`;
    /// a file without it is a `bicubic` net (every model before the key).
    pub upsample: Interp,
}

/// Input channels of every net (x, y, z of the geometry image).
pub const IN_CHANNELS: usize = 3;
/// Number of convolutions after the pixel shuffle (C→C ×3 with ReLU, then C→out).
pub const TAIL_CONVS: usize = 4;
/// Kernel size of every conv.
pub const KERNEL: usize = 3;

impl NetConfig {
    /// The paper's model: C = 64, 10 blocks, ×2.
    pub fn paper() -> Self {
        NetConfig {
            channels: 64,
            blocks: 10,
            scale: 2,
            padding: Padding::Zero,
            input_frame: InputFrame::Domain,
            upsample: Interp::Bicubic,
        }
    }
    /// The CPU preset: C = 32, 4 blocks, ×2.
    pub fn small() -> Self {
        NetConfig {
            channels: 32,
            blocks: 4,
            scale: 2,
            padding: Padding::Zero,
            input_frame: InputFrame::Domain,
            upsample: Interp::Bicubic,
        }
    }
    /// For tests and fixtures: C = 4, 2 blocks, ×2.
    pub fn tiny() -> Self {
        NetConfig {
            channels: 4,
            blocks: 2,
            scale: 2,
            padding: Padding::Zero,
            input_frame: InputFrame::Domain,
            upsample: Interp::Bicubic,
        }
    }

    pub fn preset(name: &str) -> Result<Self> {
        match name {
            "paper" => Ok(Self::paper()),
            "small" => Ok(Self::small()),
            "tiny" => Ok(Self::tiny()),
            _ => Err(Error::config(format!("unknown config '{name}' (expected paper, small or tiny)"))),
        }
    }

    pub fn with_padding(mut self, padding: Padding) -> Self {
        self.padding = padding;
        self
    }

    pub fn with_input_frame(mut self, input_frame: InputFrame) -> Self {
        self.input_frame = input_frame;
        self
    }

    pub fn with_upsample(mut self, upsample: Interp) -> Self {
        self.upsample = upsample;
        self
    }

    pub fn validate(&self) -> Result<()> {
        if self.channels == 0
            || self.scale == 0
            || self.channels > 4096
            || self.blocks > 1000
            || self.scale > 16
        {
            return Err(Error::config(format!("unreasonable net config {self:?}")));
        }
        Ok(())
    }

    /// Multiply-adds per LR pixel of one forward pass (for benchmarks): 2·that = FLOP.
    pub fn macs_per_lr_pixel(&self, kind: NetKind) -> usize {
        let (c, k2, r2) = (self.channels, KERNEL * KERNEL, self.scale * self.scale);
        let lr = IN_CHANNELS * c * k2 + 2 * self.blocks * c * c * k2 + c * c * r2 * k2;
        let hr = (TAIL_CONVS - 1) * c * c * k2 + c * kind.out_channels() * k2;
        lr + r2 * hr
    }

    pub fn to_json(&self, kind: NetKind) -> String {
        Object::default()
            .str("format", "anisocb-net")
            .num("version", 1)
            .str("kind", kind.name())
            .num("channels", self.channels)
            .num("blocks", self.blocks)
            .num("scale", self.scale)
            .str("padding", padding_name(self.padding))
            .num("in_channels", IN_CHANNELS)
            .num("out_channels", kind.out_channels())
            .num("tail_convs", TAIL_CONVS)
            .num("kernel", KERNEL)
            .str("input", self.input_frame.name())
            .str("upsample", self.upsample.name())
            .to_json()
    }

    /// Parse a `config.json` entry; the message says which field is missing or wrong.
    pub fn from_json(text: &str) -> crate::Result<(NetKind, NetConfig)> {
        Self::from_json_str(text).map_err(crate::Error::Malformed)
    }

    pub(crate) fn from_json_str(text: &str) -> std::result::Result<(NetKind, NetConfig), String> {
        let o = Object::parse_str(text)?;
        let s =
            |k: &str| o.get(k).and_then(|v| v.as_str()).ok_or(format!("config.json: missing string '{k}'"));
        // A count: absent, or present as anything but a non-negative integer, say which.
        let count = |k: &str| -> std::result::Result<Option<usize>, String> {
            match o.get(k) {
                None => Ok(None),
                Some(v) => v.as_u64().and_then(|v| usize::try_from(v).ok()).map(Some).ok_or(format!(
                    "config.json: '{k}' is {v}; it must be a non-negative integer (a count, as \
                     `anisocb train` writes it)"
                )),
            }
        };
        let n = |k: &str| count(k)?.ok_or(format!("config.json: missing integer '{k}'"));
        let kind = NetKind::parse(s("kind")?).map_err(|e| format!("config.json: {e}"))?;
        let padding = match s("padding")? {
            "zero" => Padding::Zero,
            "replicate" => Padding::Replicate,
            p => return Err(format!("config.json: unknown padding '{p}'")),
        };
        for (k, want) in [("in_channels", IN_CHANNELS), ("tail_convs", TAIL_CONVS), ("kernel", KERNEL)] {
            if let Some(v) = count(k)? {
                if v != want {
                    return Err(format!("config.json: {k} = {v}, this build supports only {want}"));
                }
            }
        }
        let input_frame = match o.get("input") {
            None => InputFrame::Domain,
            Some(v) => InputFrame::parse(v.as_str().ok_or("config.json: 'input' must be a string")?)
                .map_err(|e| format!("config.json: {e}"))?,
        };
        let upsample = match o.get("upsample") {
            None => Interp::Bicubic,
            Some(v) => v
                .as_str()
                .and_then(parse_upsample_name)
                .ok_or("config.json: 'upsample' must be \"bicubic\" or \"catmull-rom\"")?,
        };
        let cfg = NetConfig {
            channels: n("channels")?,
            blocks: n("blocks")?,
            scale: n("scale")?,
            padding,
            input_frame,
            upsample,
        };
        cfg.validate().map_err(|e| e.to_string())?;
        Ok((kind, cfg))
    }

    /// Human-readable list of the fields that differ (`"channels: 32 vs 64"`).
    pub fn diff(&self, other: &NetConfig) -> Vec<String> {
        let mut d = Vec::new();
        let mut f = |name: &str, a: String, b: String| {
            if a != b {
                d.push(format!("{name}: {a} vs {b}"));
            }
        };
        f("channels", self.channels.to_string(), other.channels.to_string());
        f("blocks", self.blocks.to_string(), other.blocks.to_string());
        f("scale", self.scale.to_string(), other.scale.to_string());
        f("padding", padding_name(self.padding).into(), padding_name(other.padding).into());
        f("input", self.input_frame.name().into(), other.input_frame.name().into());
        f("upsample", self.upsample.name().into(), other.upsample.name().into());
        d
    }
}

impl std::fmt::Display for NetConfig {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "C={}, {} blocks, x{}, {} padding, {} input, {} U",
            self.channels,
            self.blocks,
            self.scale,
            padding_name(self.padding),
            self.input_frame.name(),
            self.upsample.name()
        )
    }
}

pub fn padding_name(p: Padding) -> &'static str {
    match p {
        Padding::Zero => "zero",
        Padding::Replicate => "replicate",
    }
}

/// The cubic kernels `U` may use (bilinear is not one: it would put a kink at every LR vertex).
fn parse_upsample_name(s: &str) -> Option<Interp> {
    Interp::parse(s).filter(|m| *m != Interp::Bilinear)
}

pub fn parse_upsample(s: &str) -> Result<Interp> {
    parse_upsample_name(s)
        .ok_or_else(|| Error::config(format!("unknown upsample '{s}' (expected catmull-rom or bicubic)")))
}

pub fn parse_padding(s: &str) -> Result<Padding> {
    match s {
        "zero" => Ok(Padding::Zero),
        "replicate" => Ok(Padding::Replicate),
        _ => Err(Error::config(format!("unknown padding '{s}' (expected zero or replicate)"))),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn config_json_round_trips_and_diff_names_fields() {
        for kind in NetKind::ALL {
            let c = NetConfig::small().with_padding(Padding::Replicate);
            assert_eq!(NetConfig::from_json(&c.to_json(kind)).unwrap(), (kind, c));
            let c = c.with_input_frame(InputFrame::Cloth);
            assert_eq!(NetConfig::from_json(&c.to_json(kind)).unwrap(), (kind, c));
            let c = c.with_upsample(Interp::CatmullRom);
            assert_eq!(NetConfig::from_json(&c.to_json(kind)).unwrap(), (kind, c));
        }
        // Files written before the key: Keys bicubic. A bilinear U is refused.
        let old = NetConfig::small().to_json(NetKind::Geometry).replace(", \"upsample\": \"bicubic\"", "");
        assert!(!old.contains("upsample"), "{old}");
        assert_eq!(NetConfig::from_json(&old).unwrap().1.upsample, Interp::Bicubic);
        let bl = NetConfig::small().to_json(NetKind::Geometry).replace("\"bicubic\"", "\"bilinear\"");
        assert!(NetConfig::from_json(&bl).unwrap_err().to_string().contains("upsample"));
        let d = NetConfig::small().diff(&NetConfig::paper());
        assert_eq!(d, vec!["channels: 32 vs 64".to_string(), "blocks: 4 vs 10".to_string()]);
    }
}
