//! What an upscale runs with: [`UpscaleParams`] with each default and the measurement that
//! chose it.

use crate::error::{Error, Result};
use crate::ops::Precision;

/// Default [`UpscaleParams::strain_iters`]: off. Measured on validation runs (seed 6), 10
/// iterations lower vertex RMSE by 6 % on a drape and a flag and put their temporal
/// edge-length error well below bicubic's, but on a strongly twisted strip with a rubber band
/// (LR edges strained up to 35 %) they cost 26 % — the LR frame's edge lengths are then not
/// the HR cloth's. Opt in with `upscale --strain-iters 10` for cloth that does not stretch much.
pub const DEFAULT_STRAIN_ITERS: usize = 0;
/// The strain-limit iterations `eval` reports as its own row.
pub const EVAL_STRAIN_ITERS: usize = 10;

/// Default temporal smoothing radius (frames), [`UpscaleParams::temporal`]: off. With one pass
/// of the nets, radius 2 was chosen on the validation runs (seed 6 = `--vary 6`: neither
/// training nor held out; STED temporal 1.044 → 1.019 % on the drape, 2.192 → 2.125 % on the
/// flag with radius 1, a little more with 2). With mirror averaging ([`DEFAULT_MIRRORS`]) the
/// residual no longer carries the frame-to-frame noise the window removed, and on the same
/// runs radius 0 against 2 was better or equal on every run and metric: STED temporal −0.0 to
/// −14 % (twist-6 0.918 → 0.791× bicubic: averaging the detail of a strip that keeps turning
/// moves it off its place), the flicker metric −0.3 to −0.8 %, vertex RMSE −0.1 to −0.4 %,
/// normal angle equal or lower. Radius 1 and 3 sat between.
pub const DEFAULT_TEMPORAL: usize = 0;

/// Largest temporal smoothing radius (frames) [`UpscaleParams::validate`] accepts: a window of
/// 129 frames (±2 s at 30 fps) is already far wider than any detail worth keeping, and the
/// cost grows with the radius.
pub const MAX_TEMPORAL: usize = 64;

/// Largest enhancement factor η [`UpscaleParams::validate`] accepts: η multiplies the detail
/// on wrinkle edges by up to 1 + η (Eq 12); at 10 the folds are already 11× deeper than the
/// nets predict, and larger values only blow the mesh up.
pub const MAX_ETA: f32 = 10.0;

/// Smallest η [`UpscaleParams::validate`] accepts: −1 removes the detail where EnhanceNet is
/// sure of a wrinkle (gain 1 + ηΓe = 0); below it the gain would turn the folds inside out.
pub const MIN_ETA: f32 = -1.0;

/// Largest strain-limit iteration count [`UpscaleParams::validate`] accepts: the default 10
/// already removes the swimming; each iteration is a pass over every edge of every frame, so
/// a count in the millions would run for days.
pub const MAX_STRAIN_ITERS: usize = 1000;

/// Largest network batch [`UpscaleParams::validate`] accepts (frames per pass): beyond a few
/// dozen frames a pass is no faster, only larger in memory.
pub const MAX_BATCH: usize = 1024;

/// Default [`UpscaleParams::mirrors`]: on. Measured on the validation runs (seed 6: neither
/// training nor held out) with the shipped model, against one pass: the smooth flag's
/// normal-angle error 1.06 → 0.98× bicubic's and its STED temporal 1.015 → 0.981× (the only
/// per-run targets the single pass missed there), its mean-curvature error 0.347 → 0.271 1/m,
/// STED temporal lower on all five runs (−0.6 to −4.2 %); vertex RMSE −0.9 % (flag), −3.2 %
/// (smooth flag), but +0.9 % (drape), +4.0 % (twist) and +2.8 % (twist-materials), whose
/// training clips twist one way, so a mirrored view is less familiar to the nets. Training
/// with mirrored samples (`train --mirror-augment`) raised GeometryNet's validation loss by
/// 59 % and did not beat this (docs/research/model-history.md).
pub const DEFAULT_MIRRORS: bool = true;

/// Default [`UpscaleParams::pin_border`]: off. Measured on the validation runs (seed 6) with
/// the shipped model (trained on whole frames, BoundaryNet's target judging the border like
/// any pixel): pinning the outermost ring to U costs 0–6 % vertex RMSE (twists 5–6 %) and
/// 0–35 % border-band RMSE (drape 11 %, twists 30–35 %), and raises the normal-angle error on
/// the drape and twists. The border length stays within 0.5 % of the truth's unpinned.
pub const DEFAULT_PIN_BORDER: bool = false;

/// Default [`UpscaleParams::keep_outline`]: on (since 2026-11-24; off before). The nets were
/// trained on our simulator's cloth, whose hems rarely fold; on draped sheets from Blender
/// they flatten the hanging hem's folds and the outline comes out shorter than the LR frame's
/// own. Chosen by a rule written down before the three draped Blender validation scenes
/// stool-drape, oval-table and bench-drape were simulated (docs/research/model-history.md): over the five
/// Blender validation scenes the border's distance from the truth's length falls from 0.27 %
/// to 0.11 % on average (stool-drape 0.9951 → 0.9984 of the truth's, oval-table 0.9957 →
/// 0.9992), vertex RMSE +0.00 to +0.05 %. The cost is on our simulator's twisted strips, whose
/// true outline is itself shorter than the LR polyline: on the seed-6 validation runs vertex
/// RMSE +0.6 % (drape), +1.0 % (twist), +0.9 % (twist-materials), the flags unchanged, and
/// border-band RMSE +4 to +6 % on those three; every run stays below bicubic's error, normal
/// angle and flicker. Scaling the whole correction toward U instead of its normal part (tried
/// first) cost up to 2.8 % vertex RMSE, 17 % border-band RMSE and +6.8 % STED temporal.
pub const DEFAULT_KEEP_OUTLINE: bool = true;

/// Options of the pipeline.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct UpscaleParams {
    /// Enhancement factor η of Eq 12 (dimensionless, ≥ 0); see [`super::compose::DEFAULT_ETA`].
    /// At η = 0 EnhanceNet is not run (Γe = 0) unless `enhance_map`.
    pub eta: f32,
    /// Run EnhanceNet even at η = 0: for its map Γe, or to compose other η later
    /// ([`super::upscale::Upscaled::with_eta`]).
    pub enhance_map: bool,
    /// Frames handed to the nets at a time (memory ≈ batch · 2·C·r²·H·W floats at the widest
    /// layer): one batch on a GPU; on the CPU, passes of [`crate::nn::bundle::CPU_PASS_BYTES`]
    /// ([`crate::nn::AnisoCb::frames_per_pass`]).
    pub batch: usize,
    /// Set Γb = 1 on the grid's border pixels, so the border keeps the interpolated input
    /// whatever BoundaryNet says there (the outline is U's by construction). Off by default
    /// ([`DEFAULT_PIN_BORDER`]): the nets are trained on whole frames, so they see real borders
    /// and correct U's one-sided extrapolation there.
    pub pin_border: bool,
    /// Temporal smoothing radius (frames) of the residual and of the maps Γb, Γe that gate it,
    /// in the cloth frame: binomial weights over frames t − k … t + k (k = 1: ¼ ½ ¼),
    /// renormalised at the ends of the sequence; 0 = off, and off for models in the paper's
    /// domain frame (their residuals are not comparable across frames). Detail that stays on
    /// the cloth is kept; detail that flips from frame to frame (what shows as shading flicker
    /// and swimming edges) is averaged out. With one pass of the nets, smoothing Γb as well as
    /// R lowered STED temporal on every seed-6 validation run (twist-materials 2.35 → 2.31 %);
    /// with mirror averaging it is off by default ([`DEFAULT_TEMPORAL`]).
    pub temporal: usize,
    /// Strain limit: Jacobi iterations pulling the HR grid's edge lengths toward those implied
    /// by the LR frame's own edges ([`super::strain::hr_edge_targets`], [`super::strain::limit_strain`]), in the cloth frame;
    /// 0 = off ([`DEFAULT_STRAIN_ITERS`]). Border vertices stay put.
    pub strain_iters: usize,
    /// Average the nets' outputs over the grid's four mirror images (the LR grid as given,
    /// flipped along its rows, its columns, both): each mirror is upscaled in its own cloth
    /// frame, its R, Γb and Γe mapped back onto the original grid and frame, and the four
    /// averaged before Eq 12 ([`DEFAULT_MIRRORS`]). Every mirror is the same surface, so the
    /// result keeps the invariances; detail the nets agree on stays, and what one
    /// parametrisation of the grid invents and the others do not is averaged down. 4× the
    /// network time.
    pub mirrors: bool,
    /// Outline floor: each frame's HR border loop is never shorter than the LR frame's own
    /// border polyline (a curve through the LR border vertices is not shorter than the
    /// polyline through them). Where the composed result's would be, the part of its
    /// correction Γfinal − U along U's surface normal ([`super::outline::outline_base`]: what flattens a
    /// hem's folds) is scaled down near the border, by α on the border ring and (1 + α)/2 on
    /// the ring inside it, α ∈ [0, 1] the largest that keeps the length ([`super::outline::outline_weight`];
    /// α = 0 if even that is not enough). Measured in each frame's cloth frame, so the
    /// invariances hold; off for models in the paper's domain frame and with `pin_border`
    /// ([`DEFAULT_KEEP_OUTLINE`]).
    pub keep_outline: bool,
    /// BoundaryNet gates only the coarse part of the residual, S(R) (R through the LR grid
    /// and back, Catmull-Rom), and leaves its fine part R − S(R) — folds finer than the LR
    /// grid — as the net predicts it: `(1 − Γb)` then cannot flatten wrinkles where the
    /// BoundaryNet says "interpolate", only their coarse shift; η's gain `1 + ηΓe` applies to
    /// the fine part: Γ = U + (1 − Γb)·S(R) + (1 + ηΓe)·(R − S(R)). Off by default.
    pub gate_coarse_only: bool,
    /// The nets' arithmetic ([`Precision`]): by default the fastest the CPU has
    /// ([`Precision::fastest_cpu`]: bf16 on AMX tiles, within 0.7 % of fp32 on every held-out
    /// figure, else fp32-fast, within 0.0002 mm of fp32's vertices), as `upscale --precision
    /// auto`; [`Precision::Fp32`] for the audited path and the same bits on every machine.
    pub precision: Precision,
}

impl UpscaleParams {
    /// Refuse values that make no sense or could not finish: η not in [[`MIN_ETA`], [`MAX_ETA`]],
    /// `temporal` above [`MAX_TEMPORAL`], `batch` not in 1..=[`MAX_BATCH`], `strain_iters`
    /// above [`MAX_STRAIN_ITERS`]. Checked before any network runs.
    pub fn validate(&self) -> Result<()> {
        if !(self.eta.is_finite() && (MIN_ETA..=MAX_ETA).contains(&self.eta)) {
            return Err(Error::invalid(
                "eta",
                format!(
                    "the enhancement factor η must be a number from {MIN_ETA} to {MAX_ETA}, got {}; \
                 0 = the nets' detail as predicted, 1 = up to twice as deep on wrinkle edges, \
                 -0.5 = half as deep",
                    self.eta
                ),
            ));
        }
        if self.precision == Precision::Bf16 && !self.precision.runs_on_cpu() {
            return Err(Error::invalid("precision", crate::ops::precision::BF16_NEEDS_AVX512));
        }
        if self.temporal > MAX_TEMPORAL {
            return Err(Error::invalid(
                "temporal",
                format!(
                    "the temporal smoothing radius must be at most {MAX_TEMPORAL} frames, got {}; \
                 1 or 2 calm flicker, 0 = off",
                    self.temporal
                ),
            ));
        }
        if self.batch == 0 || self.batch > MAX_BATCH {
            return Err(Error::invalid(
                "batch",
                format!("must be 1 to {MAX_BATCH} frames per network pass, got {}", self.batch),
            ));
        }
        if self.strain_iters > MAX_STRAIN_ITERS {
            return Err(Error::invalid(
                "strain_iters",
                format!(
                    "the strain-limit iterations must be at most {MAX_STRAIN_ITERS}, got {}; \
                 about 10 removes swimming, 0 = off",
                    self.strain_iters
                ),
            ));
        }
        Ok(())
    }
}

impl Default for UpscaleParams {
    fn default() -> Self {
        UpscaleParams {
            eta: super::compose::DEFAULT_ETA,
            enhance_map: false,
            batch: 8,
            pin_border: DEFAULT_PIN_BORDER,
            temporal: DEFAULT_TEMPORAL,
            strain_iters: DEFAULT_STRAIN_ITERS,
            mirrors: DEFAULT_MIRRORS,
            keep_outline: DEFAULT_KEEP_OUTLINE,
            gate_coarse_only: false,
            precision: Precision::fastest_cpu(),
        }
    }
}
