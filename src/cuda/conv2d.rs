//! `kernels/conv2d.cu` on device buffers: implicit-GEMM forward, split-K weight gradient with
//! an ordered reduction, input gradient (for zero padding the forward kernel on the output
//! gradient with the weights transposed and flipped; for replicate padding a full correlation
//! on the padded grid, then a fold onto the input), bias gradient. GEMMs of at most 32 rows
//! (output channels; input channels for the input gradient) run the kernels' 32-row tiles.
//! The stores can fuse what follows a conv in a trunk (the ReLU, the residual skip; the ReLU's
//! backward into the input gradient), with the element-wise kernels' bits.

use cudarc::driver::{LaunchConfig, PushKernelArg};

use super::device::{dims4, grid1, i32_of, Cuda, DResult, DevBuf, THREADS};
use crate::ops::Padding;

/// Output tile edge of the implicit-GEMM conv kernels, and their reduction slice.
const TILE: usize = 64;
const BK: usize = 16;
/// Blocks the weight-gradient kernel aims for (split over the pixel reduction).
const WGRAD_TARGET_BLOCKS: usize = 1024;

/// The tile height for a GEMM of `rows` rows: (index into the kernel pairs, rows per tile).
fn tile_rows(rows: usize) -> (usize, usize) {
    if rows <= TILE / 2 {
        (1, TILE / 2)
    } else {
        (0, TILE)
    }
}

/// What the forward's store does besides the bias (`EPI_*` in `kernels/conv2d.cu`).
#[derive(Clone, Copy)]
pub enum Epilogue<'a> {
    None,
    /// y = relu(conv): the ReLU after conv1 of a block and after each tail conv but the last.
    Relu,
    /// y = conv + skip (same shape as y): the residual add of a GeometryNet block, or U + R.
    Add(&'a DevBuf),
}

const EPI_NONE: i32 = 0;
const EPI_RELU: i32 = 1;
const EPI_ADD: i32 = 2;
const EPI_MASK: i32 = 3;

fn pad_mode(pad: Padding) -> i32 {
    match pad {
        Padding::Zero => 0,
        Padding::Replicate => 1,
    }
}

impl Cuda {
    /// y = conv2d(x, w, b); x (N, C, H, W), w (O, C, KH, KW), b (O) → (N, O, H, W).
    pub fn conv2d_dev(&self, x: &DevBuf, w: &DevBuf, b: Option<&DevBuf>, pad: Padding) -> DResult<DevBuf> {
        self.conv2d_epi_dev(x, w, b, pad, Epilogue::None)
    }

    /// [`Cuda::conv2d_dev`] with `epi` applied in the store.
    pub fn conv2d_epi_dev(
        &self,
        x: &DevBuf,
        w: &DevBuf,
        b: Option<&DevBuf>,
        pad: Padding,
        epi: Epilogue,
    ) -> DResult<DevBuf> {
        let [n, c, h, wd] = dims4(&x.shape, "conv2d x");
        let [o, c2, kh, kw] = dims4(&w.shape, "conv2d w");
        assert_eq!(c, c2, "conv2d: x has {c} channels, weight expects {c2}");
        assert!(kh % 2 == 1 && kw % 2 == 1, "conv2d: odd kernels only, got {kh}x{kw}");
        if let Some(b) = b {
            assert_eq!(b.len(), o, "conv2d: bias has {} values for {o} output channels", b.len());
        }
        let mut y = self.zeros(&[n, o, h, wd])?;
        let p = n * h * wd;
        if y.is_empty() {
            return Ok(y);
        }
        let _ = i32_of(n * c.max(o) * h * wd, "conv2d tensor size");
        let dummy;
        let bias = match b {
            Some(b) => &b.buf,
            None => {
                dummy = self.stream.alloc_zeros::<f32>(1)?;
                &dummy
            }
        };
        let (ni, ci, hi, wi, oi, khi, kwi) =
            (n as i32, c as i32, h as i32, wd as i32, o as i32, kh as i32, kw as i32);
        let (pm, hb, dgrad) = (pad_mode(pad), b.is_some() as i32, 0i32);
        let (aux, epi) = match epi {
            Epilogue::None => (&x.buf, EPI_NONE),
            Epilogue::Relu => (&x.buf, EPI_RELU),
            Epilogue::Add(skip) => {
                assert_eq!(skip.shape, y.shape, "conv2d: the skip's shape is not the output's");
                (&skip.buf, EPI_ADD)
            }
        };
        let (kt, bm) = tile_rows(o);
        let cfg = LaunchConfig {
            grid_dim: (p.div_ceil(TILE) as u32, o.div_ceil(bm) as u32, 1),
            block_dim: (THREADS, 1, 1),
            shared_mem_bytes: 0,
        };
        let mut l = self.stream.launch_builder(&self.k.conv2d_fwd[kt]);
        l.arg(&x.buf).arg(&w.buf).arg(bias).arg(&mut y.buf);
        l.arg(&ni).arg(&ci).arg(&hi).arg(&wi).arg(&oi).arg(&khi).arg(&kwi).arg(&pm).arg(&hb).arg(&dgrad);
        l.arg(aux).arg(&epi);
        // SAFETY: argument list matches conv2d_fwd; buffers hold the sizes the shapes imply
        // (aux is read only by EPI_ADD, where it has y's shape).
        unsafe { l.launch(cfg) }?;
        self.mark(|| format!("conv fwd {c}->{o} {h}x{wd}"));
        Ok(y)
    }

    /// Adds the conv2d gradients into `dx` (if given), `dw`, `db` (if given). With `mask`
    /// (x's shape: the ReLU output that x is), dx gets the input gradient where mask > 0 and
    /// nothing elsewhere: the ReLU's backward fused (`relu_backward_dev`'s bits into a zeroed dx).
    #[allow(clippy::too_many_arguments)]
    pub fn conv2d_backward_dev(
        &self,
        x: &DevBuf,
        w: &DevBuf,
        dy: &DevBuf,
        pad: Padding,
        dx: Option<&mut DevBuf>,
        mask: Option<&DevBuf>,
        dw: &mut DevBuf,
        db: Option<&mut DevBuf>,
    ) -> DResult<()> {
        let [n, c, h, wd] = dims4(&x.shape, "conv2d_backward x");
        let [o, c2, kh, kw] = dims4(&w.shape, "conv2d_backward w");
        assert_eq!(c, c2, "conv2d_backward: x has {c} channels, weight expects {c2}");
        assert!(kh % 2 == 1 && kw % 2 == 1, "conv2d_backward: odd kernels only, got {kh}x{kw}");
        assert_eq!(dy.shape, [n, o, h, wd], "conv2d_backward: dy shape");
        assert_eq!(dw.shape, w.shape, "conv2d_backward: dw shape");
        if let Some(dx) = dx.as_deref() {
            assert_eq!(dx.shape, x.shape, "conv2d_backward: dx shape");
        }
        if let Some(db) = db.as_deref() {
            assert_eq!(db.len(), o, "conv2d_backward: db has {} values for {o} channels", db.len());
        }
        if let Some(m) = mask {
            assert_eq!(m.shape, x.shape, "conv2d_backward: the ReLU mask's shape is not x's");
        }
        let (mask_buf, masked) = match mask {
            Some(m) => (&m.buf, 1i32),
            None => (&dy.buf, 0i32),
        };
        if dy.is_empty() {
            return Ok(()); // every gradient gets += 0
        }
        let (hp, wp) = (h + kh - 1, wd + kw - 1);
        let _ = i32_of(n * c.max(o) * hp * wp, "conv2d tensor size");
        let (ni, ci, hi, wi, oi, khi, kwi) =
            (n as i32, c as i32, h as i32, wd as i32, o as i32, kh as i32, kw as i32);
        let pm = pad_mode(pad);
        let p = n * h * wd;
        let kk = c * kh * kw;

        // Weight gradient: split-K partials, then an ordered sum into dw.
        if kk > 0 {
            let tiles = kk.div_ceil(TILE) * o.div_ceil(TILE);
            let want_z = WGRAD_TARGET_BLOCKS.div_ceil(tiles).max(1);
            let chunk = p.div_ceil(want_z).next_multiple_of(BK).max(16 * BK);
            let z = p.div_ceil(chunk);
            let mut part = self.stream.alloc_zeros::<f32>(z * o * kk)?;
            let (chunk_i, z_i, len) = (chunk as i32, z as i32, (o * kk) as i64);
            let (kt, bm) = tile_rows(o);
            let cfg = LaunchConfig {
                grid_dim: (kk.div_ceil(TILE) as u32, o.div_ceil(bm) as u32, z as u32),
                block_dim: (THREADS, 1, 1),
                shared_mem_bytes: 0,
            };
            let mut l = self.stream.launch_builder(&self.k.conv2d_wgrad[kt]);
            l.arg(&x.buf).arg(&dy.buf).arg(&mut part);
            l.arg(&ni).arg(&ci).arg(&hi).arg(&wi).arg(&oi).arg(&khi).arg(&kwi).arg(&pm).arg(&chunk_i);
            // SAFETY: matches conv2d_wgrad; part holds z·O·C·KH·KW values.
            unsafe { l.launch(cfg) }?;
            self.mark(|| format!("conv wgrad {c}->{o} {h}x{wd} (z {z})"));
            let mut l = self.stream.launch_builder(&self.k.conv2d_wgrad_reduce);
            l.arg(&part).arg(&mut dw.buf).arg(&z_i).arg(&len);
            // SAFETY: matches conv2d_wgrad_reduce; dw holds O·C·KH·KW values.
            unsafe { l.launch(grid1(o * kk)) }?;
            self.mark(|| format!("conv wgrad reduce {c}->{o}"));
        }

        // Input gradient. Zero padding: dx += the forward kernel on dy with the weights
        // transposed and flipped (its `dgrad` mode). Replicate padding: full correlation onto
        // the padded grid, then fold onto dx.
        let (kt, bm) = tile_rows(c);
        match dx {
            Some(dx) if c > 0 && pad == Padding::Zero => {
                let (no_bias, no, dgrad) = (0i32, 0i32, 1i32);
                let cfg = LaunchConfig {
                    grid_dim: (p.div_ceil(TILE) as u32, c.div_ceil(bm) as u32, 1),
                    block_dim: (THREADS, 1, 1),
                    shared_mem_bytes: 0,
                };
                let epi = if masked == 1 { EPI_MASK } else { EPI_NONE };
                let mut l = self.stream.launch_builder(&self.k.conv2d_fwd[kt]);
                l.arg(&dy.buf).arg(&w.buf).arg(&dy.buf).arg(&mut dx.buf);
                l.arg(&ni).arg(&oi).arg(&hi).arg(&wi).arg(&ci).arg(&khi).arg(&kwi).arg(&no).arg(&no_bias);
                l.arg(&dgrad).arg(mask_buf).arg(&epi);
                // SAFETY: matches conv2d_fwd in its dgrad mode (x = dy with O channels, the
                // weight read as (C, O, KH, KW) transposed, y = dx with C channels; the bias
                // argument is not read, the mask only with EPI_MASK, where it has dx's shape).
                unsafe { l.launch(cfg) }?;
                self.mark(|| format!("conv dgrad {c}->{o} {h}x{wd}"));
            }
            Some(dx) if c > 0 => {
                let q = n * hp * wp;
                let mut dxp = self.stream.alloc_zeros::<f32>(n * c * hp * wp)?;
                let cfg = LaunchConfig {
                    grid_dim: (q.div_ceil(TILE) as u32, c.div_ceil(bm) as u32, 1),
                    block_dim: (THREADS, 1, 1),
                    shared_mem_bytes: 0,
                };
                let mut l = self.stream.launch_builder(&self.k.conv2d_dgrad_padded[kt]);
                l.arg(&w.buf).arg(&dy.buf).arg(&mut dxp);
                l.arg(&ni).arg(&ci).arg(&hi).arg(&wi).arg(&oi).arg(&khi).arg(&kwi);
                // SAFETY: matches conv2d_dgrad_padded; dxp holds N·C·Hp·Wp values.
                unsafe { l.launch(cfg) }?;
                self.mark(|| format!("conv dgrad {c}->{o} {h}x{wd}"));
                let nc = (n * c) as i32;
                let mut l = self.stream.launch_builder(&self.k.conv2d_dgrad_fold);
                l.arg(&dxp).arg(&mut dx.buf).arg(&nc).arg(&hi).arg(&wi).arg(&khi).arg(&kwi).arg(&pm);
                l.arg(mask_buf).arg(&masked);
                // SAFETY: matches conv2d_dgrad_fold; dx (and the mask, read only if masked)
                // hold N·C·H·W values.
                unsafe { l.launch(grid1(n * c * h * wd)) }?;
                self.mark(|| format!("conv dgrad fold {c} {h}x{wd}"));
            }
            _ => {}
        }

        if let Some(db) = db {
            let hw = (h * wd) as i32;
            let cfg =
                LaunchConfig { grid_dim: (o as u32, 1, 1), block_dim: (THREADS, 1, 1), shared_mem_bytes: 0 };
            let mut l = self.stream.launch_builder(&self.k.conv2d_bias_grad);
            l.arg(&dy.buf).arg(&mut db.buf).arg(&ni).arg(&oi).arg(&hw);
            // SAFETY: matches conv2d_bias_grad (256 threads, one block per output channel).
            unsafe { l.launch(cfg) }?;
            self.mark(|| format!("conv bias grad {o} {h}x{wd}"));
        }
        Ok(())
    }
}
