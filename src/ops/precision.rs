//! [`Precision`]: the arithmetic the nets run in at inference. Training, `audit` and every
//! reference run in fp32.

use crate::error::{Error, Result};
use crate::ops::conv2d::amx;
use crate::ops::Ops;

#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Precision {
    /// f32 throughout: the audited path.
    #[default]
    Fp32,
    /// bf16 operands with f32 sums on the CPU's AMX tiles, or its AVX512_BF16 dot products
    /// where it has no tiles ([`amx`]): the convs with 32·k
    /// input channels; the first conv (3 channels) and the last (≤ 4 outputs) stay fp32, so
    /// the geometry enters and leaves each net in f32, and the trunk's LR part takes its
    /// activations as hi + lo pairs of bf16 ([`crate::nn::layers::Trunk::pack`]). Only where
    /// [`amx::available`].
    Bf16,
    /// fp16 operands with f32 accumulation: the CUDA tensor-core path (`cuda::nets_views`).
    Fp16,
    /// f32 throughout, the trunks' 3×3 convs by Winograd F(4×4, 3×3) instead of F(2×2, 3×3):
    /// 1.8× fewer multiply-adds in their products, sums rounded differently from [`Fp32`]'s
    /// (differences from the exact sums 5–9× F(2×2)'s: about 2·10⁻⁵ of a 64-channel conv's
    /// typical output; docs/performance.md). CPU only; training and `audit` stay [`Fp32`].
    ///
    /// [`Fp32`]: Precision::Fp32
    Fp32Fast,
}

impl Precision {
    /// Its name on the command line and in reports.
    pub fn name(self) -> &'static str {
        match self {
            Precision::Fp32 => "fp32",
            Precision::Bf16 => "bf16",
            Precision::Fp16 => "fp16",
            Precision::Fp32Fast => "fp32-fast",
        }
    }

    /// The fastest the CPU has: bf16 where it has AMX tiles, else fp32-fast (Winograd
    /// F(4×4, 3×3): `upscale` in about 0.7× fp32's time, output vertices within 0.0002 mm of
    /// fp32's on the held-out runs, docs/performance.md). The dot-product kernel of a CPU with
    /// AVX512_BF16 and no tiles is not chosen: it measured 1.9× slower than fp32 on `upscale`,
    /// since the hi + lo pairs double its work and one `vdpbf16ps` does as many multiply-adds
    /// as one fp32 FMA there.
    pub fn fastest_cpu() -> Precision {
        if amx::tiles() {
            Precision::Bf16
        } else {
            Precision::Fp32Fast
        }
    }

    /// The precision the nets are packed in for `ops`: bf16 only on a table that runs the
    /// CPU kernels' chains, the tiles' among them ([`Ops::runs_chains`]), fp32 elsewhere.
    pub fn for_ops(self, ops: &dyn Ops) -> Precision {
        match self {
            Precision::Bf16 | Precision::Fp32Fast if !ops.runs_chains() => Precision::Fp32,
            p => p,
        }
    }

    /// Whether it runs on the CPU here (bf16 needs [`amx::available`]; fp16 is a GPU's).
    pub fn runs_on_cpu(self) -> bool {
        match self {
            Precision::Fp32 | Precision::Fp32Fast => true,
            Precision::Bf16 => amx::available(),
            Precision::Fp16 => false,
        }
    }

    /// The precision `request` (`auto`, `fp32`, `fp32-fast`, `bf16` or `fp16`) resolved for
    /// `ops`: `auto` is fp16 where `ops` is a GPU with tensor cores, fp32 on a GPU without,
    /// and on the CPU [`Precision::fastest_cpu`] (bf16 with AMX tiles, else fp32-fast). `fp32` on such a GPU turns its tensor-core path off (the op-by-op fp32 kernels
    /// run). Errors: a precision that cannot run here, saying which can.
    pub fn resolve(request: &str, ops: &dyn Ops) -> Result<Precision> {
        let tc = ops.as_cuda().map(|c| c.tensor_cores());
        match (request, tc) {
            ("fp32", Some(_)) => {
                ops.as_cuda().expect("a CUDA table").use_tensor_cores(false);
                Ok(Precision::Fp32)
            }
            ("fp32", None) => Ok(Precision::Fp32),
            ("fp32-fast", None) => Ok(Precision::Fp32Fast),
            ("fp32-fast", Some(_)) => Err(Error::invalid(
                "precision",
                "fp32-fast runs on the CPU; on --device cuda use fp16, fp32 or auto",
            )),
            ("auto", None) => Ok(Precision::fastest_cpu()),
            ("auto", Some(Err(_))) => Ok(Precision::Fp32),
            ("auto", Some(Ok(()))) | ("fp16", Some(Ok(()))) => Ok(Precision::Fp16),
            ("fp16", Some(Err(why))) => {
                Err(Error::invalid("precision", format!("fp16 cannot run here: {why}")))
            }
            ("fp16", None) => Err(Error::invalid(
                "precision",
                "fp16 runs on --device cuda (a GPU with tensor cores); on the CPU use bf16 (with AVX512_BF16), fp32 or auto",
            )),
            ("bf16", None) if amx::available() => Ok(Precision::Bf16),
            ("bf16", None) => Err(Error::invalid("precision", BF16_NEEDS_AVX512)),
            ("bf16", Some(_)) => Err(Error::invalid(
                "precision",
                "bf16 runs on the CPU (AMX tiles or AVX512_BF16); on --device cuda use fp16, fp32 or auto",
            )),
            (other, _) => Err(Error::invalid(
                "precision",
                format!("unknown precision `{other}`: expected auto, fp32, fp32-fast, bf16 or fp16"),
            )),
        }
    }
}

/// Why bf16 is refused on a CPU without AVX512_BF16.
pub(crate) const BF16_NEEDS_AVX512: &str = "bf16 needs a CPU with AVX512_BF16 (Intel Cooper Lake or \
     Sapphire Rapids and later, whose AMX tiles make it fast; AMD Zen 4 and later); this one has none: \
     use fp32 or auto";
