//! Layers and the shared trunk of all three networks.
//!
//! ```text
//! x (N,3,H,W) ─ conv_in ─► a ─┬─ blocks.k: conv1 ─ relu ─ conv2 ─(+a if residual)─► a   (k = 0..B)
//!                              └─ upscale (C→r²C) ─ pixel shuffle ─► (N,C,rH,rW)
//!               ─ tail.0 ─ relu ─ tail.1 ─ relu ─ tail.2 ─ relu ─ tail.3 ─► y (N,out,rH,rW)
//! ```
//! GeometryNet uses the residual form (`a ← a + conv2(relu(conv1(a)))`), BoundaryNet and
//! EnhanceNet the plain one (`a ← conv2(relu(conv1(a)))`), as in the paper. Every conv is 3×3,
//! stride 1, "same" size, with bias. Every op goes through `&dyn Ops`.

use super::config::{NetConfig, NetKind, IN_CHANNELS, KERNEL, TAIL_CONVS};
use crate::ops::conv2d::amx::{conv_act, conv_to_act, Act, ActEpilogue};
use crate::ops::conv2d::chain::{conv_f32_act, conv_f32_act_relu_small_out, conv_to_f32_act};
use crate::ops::conv2d::{conv_act_relu_small_out, Epilogue, PackedConv};
use crate::ops::Precision;
use crate::ops::{Ops, Padding};
use crate::rng::{mix_seed, Rng};
use crate::tensor::Tensor;

/// One convolution of a trunk. [`layout`] lists them in the canonical order (the order of
/// [`Trunk::convs`], [`Trunk::pack`], the weights file and the random initialisation).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Layer {
    ConvIn,
    /// `blocks.k.conv1` and `blocks.k.conv2`.
    Conv1(usize),
    Conv2(usize),
    /// The C → r²C conv before the pixel shuffle.
    Upscale,
    /// `tail.i`, i < [`TAIL_CONVS`].
    Tail(usize),
}

impl Layer {
    /// Position in the canonical order of a trunk with `blocks` residual blocks.
    pub fn index(self, blocks: usize) -> usize {
        match self {
            Layer::ConvIn => 0,
            Layer::Conv1(k) => 1 + 2 * k,
            Layer::Conv2(k) => 2 + 2 * k,
            Layer::Upscale => 1 + 2 * blocks,
            Layer::Tail(i) => 2 + 2 * blocks + i,
        }
    }

    /// The PyTorch-style name (`conv_in`, `blocks.3.conv1`, `upscale`, `tail.0`).
    pub fn name(self) -> String {
        match self {
            Layer::ConvIn => "conv_in".into(),
            Layer::Conv1(k) => format!("blocks.{k}.conv1"),
            Layer::Conv2(k) => format!("blocks.{k}.conv2"),
            Layer::Upscale => "upscale".into(),
            Layer::Tail(i) => format!("tail.{i}"),
        }
    }
}

/// The trunk of a `kind` net with `config`: every conv in canonical order with its (output,
/// input) channels. The one description of the layout: construction, initialisation, names,
/// packing, the forward's indices and the weights file's shapes all read it.
pub fn layout(kind: NetKind, config: NetConfig) -> Vec<(Layer, usize, usize)> {
    let c = config.channels;
    let mut v = vec![(Layer::ConvIn, c, IN_CHANNELS)];
    for k in 0..config.blocks {
        v.extend([(Layer::Conv1(k), c, c), (Layer::Conv2(k), c, c)]);
    }
    v.push((Layer::Upscale, c * config.scale * config.scale, c));
    for i in 0..TAIL_CONVS {
        v.push((Layer::Tail(i), if i + 1 == TAIL_CONVS { kind.out_channels() } else { c }, c));
    }
    v
}

/// A 3×3 convolution: weight (O, I, 3, 3) OIHW, bias (O).
#[derive(Clone, Debug, PartialEq)]
pub struct Conv {
    pub weight: Tensor,
    pub bias: Tensor,
}

impl Conv {
    pub fn zeros(out_c: usize, in_c: usize) -> Conv {
        Conv { weight: Tensor::zeros(&[out_c, in_c, KERNEL, KERNEL]), bias: Tensor::zeros(&[out_c]) }
    }

    /// Kaiming-uniform weights, `U(−b, b)` with `b = gain·√(3 / fan_in)`, `fan_in = I·3·3`
    /// (PyTorch's `kaiming_uniform_` with that gain); zero bias.
    pub fn kaiming(out_c: usize, in_c: usize, gain: f32, rng: &mut Rng) -> Conv {
        let mut c = Conv::zeros(out_c, in_c);
        let bound = gain * (3.0 / (in_c * KERNEL * KERNEL) as f32).sqrt();
        for w in &mut c.weight.data {
            *w = rng.uniform_in(-bound, bound);
        }
        c
    }

    /// x: (N, I, H, W) → (N, O, H, W).
    pub fn forward(&self, ops: &dyn Ops, x: &Tensor, pad: Padding) -> Tensor {
        ops.conv2d(x, &self.weight, Some(&self.bias), pad)
    }

    /// [`Conv::forward`] with this conv's weights packed ([`PackedConv::new`]), then `epi`.
    pub fn forward_packed(
        &self,
        ops: &dyn Ops,
        x: &Tensor,
        pad: Padding,
        packed: &PackedConv,
        epi: Epilogue,
    ) -> Tensor {
        ops.conv2d_packed(x, &self.weight, packed, Some(&self.bias), pad, epi)
    }

    /// Adds into `grad` (dW, db) and into `dx` if given. x: the forward input, dy like the output.
    pub fn backward(
        &self,
        ops: &dyn Ops,
        x: &Tensor,
        dy: &Tensor,
        pad: Padding,
        dx: Option<&mut Tensor>,
        grad: &mut Conv,
    ) {
        ops.conv2d_backward(x, &self.weight, dy, pad, dx, &mut grad.weight, Some(&mut grad.bias));
    }
}

/// `conv1 → relu → conv2`, with or without the skip.
#[derive(Clone, Debug, PartialEq)]
pub struct Block {
    pub conv1: Conv,
    pub conv2: Conv,
}

/// Parameters of one network (also used, zero-filled, as its gradient and Adam moments).
#[derive(Clone, Debug, PartialEq)]
pub struct Trunk {
    pub kind: NetKind,
    pub config: NetConfig,
    pub conv_in: Conv,
    pub blocks: Vec<Block>,
    pub upscale: Conv,
    pub tail: Vec<Conv>,
}

/// Activations kept by a training forward pass for its backward.
#[derive(Clone, Debug)]
pub struct Tape {
    input: Tensor,
    /// Per block: its input `a`, conv1's output (pre-ReLU), the ReLU's output.
    blocks: Vec<[Tensor; 3]>,
    upscale_in: Tensor,
    /// Input of each tail conv; pre-ReLU outputs of the first three.
    tail_in: Vec<Tensor>,
    tail_pre: Vec<Tensor>,
}

impl Default for Tape {
    fn default() -> Self {
        let e = Tensor::zeros(&[0]);
        Tape {
            input: e.clone(),
            blocks: Vec::new(),
            upscale_in: e,
            tail_in: Vec::new(),
            tail_pre: Vec::new(),
        }
    }
}

impl Trunk {
    /// All parameters zero (the shape of a gradient buffer).
    pub fn zeros(kind: NetKind, config: NetConfig) -> Trunk {
        Trunk::from_convs(kind, config, layout(kind, config).into_iter().map(|(_, o, i)| Conv::zeros(o, i)))
    }

    /// A trunk from its convs in [`layout`] order.
    fn from_convs(kind: NetKind, config: NetConfig, convs: impl IntoIterator<Item = Conv>) -> Trunk {
        let mut it = convs.into_iter();
        let mut next = || it.next().expect("one conv per layout entry");
        let conv_in = next();
        let blocks = (0..config.blocks).map(|_| Block { conv1: next(), conv2: next() }).collect();
        let upscale = next();
        let tail = (0..TAIL_CONVS).map(|_| next()).collect();
        Trunk { kind, config, conv_in, blocks, upscale, tail }
    }

    /// Deterministic initialisation from `seed` (same seed, same bits).
    ///
    /// Kaiming-uniform ([`Conv::kaiming`]) with gain √2 for convs followed by a ReLU (conv1,
    /// tail.0–2) and gain 1 for the others, so the plain trunk keeps its activation scale;
    /// in the residual trunk conv2 gets gain 1/√B so the sum of B branches stays O(1), and the
    /// last conv of GeometryNet gets gain 0.1 so training starts near `R = 0`, i.e. from the
    /// bicubic baseline. Biases start at 0.
    pub fn init(kind: NetKind, config: NetConfig, seed: u64) -> Trunk {
        let mut rng = Rng::new(mix_seed(&[seed, kind as u64]));
        let relu_gain = std::f32::consts::SQRT_2;
        let conv2_gain = if kind.residual() { 1.0 / (config.blocks.max(1) as f32).sqrt() } else { 1.0 };
        let last_gain = if kind == NetKind::Geometry { 0.1 } else { 1.0 };
        let gain = |l: Layer| match l {
            Layer::Conv1(_) => relu_gain,
            Layer::Conv2(_) => conv2_gain,
            Layer::Tail(i) if i + 1 == TAIL_CONVS => last_gain,
            Layer::Tail(_) => relu_gain,
            Layer::ConvIn | Layer::Upscale => 1.0,
        };
        let convs: Vec<Conv> = layout(kind, config)
            .into_iter()
            .map(|(l, o, i)| Conv::kaiming(o, i, gain(l), &mut rng))
            .collect();
        Trunk::from_convs(kind, config, convs)
    }

    pub fn zeros_like(&self) -> Trunk {
        Trunk::zeros(self.kind, self.config)
    }

    /// The convolutions with their PyTorch-style names (`conv_in`, `blocks.3.conv1`, `upscale`,
    /// `tail.0` …), in the canonical order.
    pub fn convs(&self) -> Vec<(String, &Conv)> {
        layout(self.kind, self.config).into_iter().map(|(l, ..)| (l.name(), self.conv(l))).collect()
    }

    /// The conv at `l`.
    pub fn conv(&self, l: Layer) -> &Conv {
        match l {
            Layer::ConvIn => &self.conv_in,
            Layer::Conv1(k) => &self.blocks[k].conv1,
            Layer::Conv2(k) => &self.blocks[k].conv2,
            Layer::Upscale => &self.upscale,
            Layer::Tail(i) => &self.tail[i],
        }
    }

    fn convs_mut(&mut self) -> Vec<&mut Conv> {
        let mut v = vec![&mut self.conv_in];
        for b in &mut self.blocks {
            v.push(&mut b.conv1);
            v.push(&mut b.conv2);
        }
        v.push(&mut self.upscale);
        v.extend(self.tail.iter_mut());
        v
    }

    /// Every parameter tensor with its name (`conv_in.weight`, `conv_in.bias`, …), canonical order.
    pub fn params(&self) -> Vec<(String, &Tensor)> {
        self.convs()
            .into_iter()
            .flat_map(|(n, c)| [(format!("{n}.weight"), &c.weight), (format!("{n}.bias"), &c.bias)])
            .collect()
    }

    /// Every parameter tensor, mutable, in the order of [`Trunk::params`].
    pub fn params_mut(&mut self) -> Vec<&mut Tensor> {
        self.convs_mut().into_iter().flat_map(|c| [&mut c.weight, &mut c.bias]).collect()
    }

    pub fn num_params(&self) -> usize {
        self.params().iter().map(|(_, t)| t.len()).sum()
    }

    pub fn fill_zero(&mut self) {
        for t in self.params_mut() {
            t.data.fill(0.0);
        }
    }

    /// Every conv's weights packed for [`Trunk::forward_packed`] in `precision`
    /// ([`PackedConv::with_precision`]), in [`Trunk::convs`] order.
    ///
    /// On the bf16 tiles ([`Trunk::forward_packed`]'s chain of [`Act`]s) the upscale conv is
    /// packed for the pixel shuffle its store fuses, and the LR part (the blocks and the
    /// upscale conv) takes its inputs as hi + lo pairs of bf16 ([`PackedConv::for_chain`]):
    /// rounding them to one bf16 moved held-out output vertices by up to 0.36 mm and raised
    /// flicker (STED) by up to 6.5 %; pairs there keep every held-out figure within 0.7 % of
    /// fp32 (docs/performance.md). The HR tail, whose rounding measured no difference, reads
    /// single bf16, and so do all of BoundaryNet and EnhanceNet: their outputs gate
    /// GeometryNet's residual R, so an error δ in them moves a vertex by δ·|R| (η·δ·|R|), not by
    /// δ; on the validation runs their single rounding moved no output vertex more than 5 %
    /// further from fp32's and no figure by more than 0.01 %, for 11 % less tile work a frame
    /// (17 % at η > 0).
    pub fn pack(&self, precision: Precision) -> Vec<PackedConv> {
        let lr_pairs = self.kind == NetKind::Geometry;
        layout(self.kind, self.config)
            .into_iter()
            .map(|(l, ..)| {
                let (shuffle, split) = match l {
                    Layer::Upscale => (self.config.scale, lr_pairs),
                    Layer::Conv1(_) | Layer::Conv2(_) => (1, lr_pairs),
                    Layer::ConvIn | Layer::Tail(_) => (1, false),
                };
                PackedConv::for_chain(&self.conv(l).weight, precision, shuffle, split)
            })
            .collect()
    }

    /// Inference forward: x (N, 3, H, W) → (N, out, rH, rW). Keeps no activations beyond the
    /// current layer; `observe(layer_name, activation)` sees every layer's output (audit).
    pub fn forward_observed(
        &self,
        ops: &dyn Ops,
        x: &Tensor,
        observe: &mut dyn FnMut(&str, &Tensor),
    ) -> Tensor {
        self.run(ops, x, None, observe)
    }

    pub fn forward(&self, ops: &dyn Ops, x: &Tensor) -> Tensor {
        self.run(ops, x, None, &mut |_, _| {})
    }

    /// [`Trunk::forward`] with the weights packed in advance (`packed` = [`Trunk::pack`]) and
    /// the ReLUs and residual skips fused into the convs' stores ([`Epilogue`]): the same bits,
    /// without packing the weights on every call or a pass of their own for the ReLUs and adds.
    pub fn forward_packed(&self, ops: &dyn Ops, x: &Tensor, packed: &[PackedConv]) -> Tensor {
        let (nb, last) = (self.blocks.len(), self.tail.len() - 1);
        let at = |l: Layer| &packed[l.index(nb)];
        assert_eq!(packed.len(), Layer::Tail(last).index(nb) + 1, "packed weights of another net");
        let pad = self.config.padding;
        let (_, c, _, _) = x.dims4();
        assert_eq!(c, IN_CHANNELS, "trunk input must have {IN_CHANNELS} channels");
        if ops.runs_chains() && self.fits_f32_chain(packed) {
            return self.forward_f32_chain(x, packed);
        }
        if at(Layer::Upscale).is_bf16() {
            let split = at(Layer::Conv1(0)).is_split();
            let a = conv_to_act(x, at(Layer::ConvIn), Some(&self.conv_in.bias), pad, split);
            return self.forward_bf16(a, packed);
        }
        let mut a = self.conv_in.forward_packed(ops, x, pad, at(Layer::ConvIn), Epilogue::NONE);
        for (k, b) in self.blocks.iter().enumerate() {
            let r1 = b.conv1.forward_packed(ops, &a, pad, at(Layer::Conv1(k)), Epilogue::RELU);
            let skip = self.kind.residual().then_some(&a);
            a = b.conv2.forward_packed(ops, &r1, pad, at(Layer::Conv2(k)), Epilogue { skip, relu: false });
        }
        let u = self.upscale.forward_packed(ops, &a, pad, at(Layer::Upscale), Epilogue::NONE);
        let mut z = ops.pixel_shuffle(&u, self.config.scale);
        drop(u);
        for (i, conv) in self.tail.iter().enumerate() {
            z = conv.forward_packed(
                ops,
                &z,
                pad,
                at(Layer::Tail(i)),
                Epilogue { skip: None, relu: i < last },
            );
        }
        z
    }

    /// Whether `packed` (fp32) takes the fp32 chain: every conv after the first on the Winograd
    /// kernel but the last, which is a small-output one.
    fn fits_f32_chain(&self, packed: &[PackedConv]) -> bool {
        let (first, rest) = packed.split_first().expect("a trunk has convs");
        let (last, inner) = rest.split_last().expect("a trunk has convs");
        !first.is_bf16()
            && !first.is_small_out()
            && inner.iter().all(|p| p.is_winograd())
            && last.is_small_out()
    }

    /// [`Trunk::forward_packed`] on the fp32 chain ([`conv_f32_act`]): conv_in stores straight
    /// into the padded channels-last layout the Winograd kernel reads, every conv after it reads
    /// and writes that layout, the residual adds, ReLUs and the pixel shuffle fused into the
    /// stores, and the tail's last Winograd conv stores into the padded planar input of the last
    /// conv. The same bits as the convs one by one on NCHW tensors, without the transposes
    /// between them. CPU only ([`Ops::runs_chains`]).
    fn forward_f32_chain(&self, x: &Tensor, packed: &[PackedConv]) -> Tensor {
        let (nb, last) = (self.blocks.len(), self.tail.len() - 1);
        let at = |l: Layer| &packed[l.index(nb)];
        let relu = ActEpilogue { skip: None, relu: true };
        let mut a = conv_to_f32_act(x, at(Layer::ConvIn), Some(&self.conv_in.bias), self.config.padding);
        for (k, b) in self.blocks.iter().enumerate() {
            let r1 = conv_f32_act(&a, at(Layer::Conv1(k)), Some(&b.conv1.bias), relu, 1);
            let skip = self.kind.residual().then_some(&a);
            let epi = ActEpilogue { skip, relu: false };
            a = conv_f32_act(&r1, at(Layer::Conv2(k)), Some(&b.conv2.bias), epi, 1);
        }
        let up = at(Layer::Upscale);
        let mut z = conv_f32_act(&a, up, Some(&self.upscale.bias), ActEpilogue::default(), self.config.scale);
        drop(a);
        for (i, conv) in self.tail[..last - 1].iter().enumerate() {
            z = conv_f32_act(&z, at(Layer::Tail(i)), Some(&conv.bias), relu, 1);
        }
        let (t, tl) = (Layer::Tail(last - 1), Layer::Tail(last));
        conv_f32_act_relu_small_out(&z, at(t), Some(&self.conv(t).bias), at(tl), Some(&self.conv(tl).bias))
    }

    /// [`Trunk::forward_packed`] from conv_in's output `a` on (stored by the fp32 conv straight
    /// into the tiles' layout, [`conv_to_act`]), with the weights packed for the
    /// bf16 tiles ([`Precision::Bf16`]): every conv but the first and the last (the ones with
    /// 32·k input channels: all of them when any is) reads and writes bf16 activations in the
    /// tiles' padded channels-last layout ([`Act`]), the residual adds, ReLUs and the pixel
    /// shuffle fused into the stores; the tail's last tile conv stores f32 straight into the
    /// padded input of the last conv ([`conv_act_relu_small_out`]). CPU only: the pipelines
    /// pack for the tiles only for the CPU table ([`Precision::for_ops`]).
    fn forward_bf16(&self, mut a: Act, packed: &[PackedConv]) -> Tensor {
        let (nb, last) = (self.blocks.len(), self.tail.len() - 1);
        let at = |l: Layer| &packed[l.index(nb)];
        for (k, b) in self.blocks.iter().enumerate() {
            let r1 = conv_act(
                &a,
                at(Layer::Conv1(k)),
                Some(&b.conv1.bias),
                ActEpilogue { skip: None, relu: true },
                at(Layer::Conv2(k)).is_split(),
            );
            let skip = self.kind.residual().then_some(&a);
            let next = if k + 1 < nb { Layer::Conv1(k + 1) } else { Layer::Upscale };
            a = conv_act(
                &r1,
                at(Layer::Conv2(k)),
                Some(&b.conv2.bias),
                ActEpilogue { skip, relu: false },
                at(next).is_split(),
            );
        }
        let mut z = conv_act(
            &a,
            at(Layer::Upscale),
            Some(&self.upscale.bias),
            ActEpilogue::default(),
            at(Layer::Tail(0)).is_split(),
        );
        drop(a);
        for (i, conv) in self.tail[..last - 1].iter().enumerate() {
            z = conv_act(
                &z,
                at(Layer::Tail(i)),
                Some(&conv.bias),
                ActEpilogue { skip: None, relu: true },
                at(Layer::Tail(i + 1)).is_split(),
            );
        }
        conv_act_relu_small_out(
            &z,
            at(Layer::Tail(last - 1)),
            Some(&self.tail[last - 1].bias),
            at(Layer::Tail(last)),
            Some(&self.tail[last].bias),
            self.config.padding,
        )
    }

    /// Training forward: the output and the activations [`Trunk::backward`] needs.
    pub fn forward_train(&self, ops: &dyn Ops, x: &Tensor) -> (Tensor, Tape) {
        let mut tape = Tape::default();
        let y = self.run(ops, x, Some(&mut tape), &mut |_, _| {});
        (y, tape)
    }

    fn run(
        &self,
        ops: &dyn Ops,
        x: &Tensor,
        mut tape: Option<&mut Tape>,
        observe: &mut dyn FnMut(&str, &Tensor),
    ) -> Tensor {
        let pad = self.config.padding;
        let (_, c, _, _) = x.dims4();
        assert_eq!(c, IN_CHANNELS, "trunk input must have {IN_CHANNELS} channels");
        if let Some(t) = tape.as_deref_mut() {
            t.input = x.clone();
        }
        let mut a = self.conv_in.forward(ops, x, pad);
        observe("conv_in", &a);
        for (k, b) in self.blocks.iter().enumerate() {
            let t1 = b.conv1.forward(ops, &a, pad);
            observe(&format!("blocks.{k}.conv1"), &t1);
            let r1 = ops.relu(&t1);
            observe(&format!("blocks.{k}.relu"), &r1);
            let mut out = b.conv2.forward(ops, &r1, pad);
            observe(&format!("blocks.{k}.conv2"), &out);
            if self.kind.residual() {
                ops.add_assign(&mut out, &a);
                observe(&format!("blocks.{k}"), &out);
            }
            if let Some(t) = tape.as_deref_mut() {
                t.blocks.push([a, t1, r1]);
            }
            a = out;
        }
        let u = self.upscale.forward(ops, &a, pad);
        observe("upscale", &u);
        if let Some(t) = tape.as_deref_mut() {
            t.upscale_in = a;
        }
        let mut z = ops.pixel_shuffle(&u, self.config.scale);
        drop(u);
        observe("pixel_shuffle", &z);
        for (i, conv) in self.tail.iter().enumerate() {
            let y = conv.forward(ops, &z, pad);
            observe(&format!("tail.{i}"), &y);
            if i + 1 == self.tail.len() {
                if let Some(t) = tape.as_deref_mut() {
                    t.tail_in.push(z);
                }
                return y;
            }
            let r = ops.relu(&y);
            observe(&format!("tail.{i}.relu"), &r);
            let zin = std::mem::replace(&mut z, r);
            if let Some(t) = tape.as_deref_mut() {
                t.tail_in.push(zin);
                t.tail_pre.push(y);
            }
        }
        unreachable!("the tail has {TAIL_CONVS} convs")
    }

    /// Backward of [`Trunk::forward_train`]: `dy` is the gradient w.r.t. its output; adds the
    /// parameter gradients into `grads` (a trunk of the same config). The input gets no gradient.
    pub fn backward(&self, ops: &dyn Ops, tape: &Tape, dy: &Tensor, grads: &mut Trunk) {
        assert_eq!((grads.kind, grads.config), (self.kind, self.config), "gradient buffer of another net");
        let pad = self.config.padding;
        let last = self.tail.len() - 1;
        let mut dz = Tensor::zeros(&tape.tail_in[last].shape);
        self.tail[last].backward(ops, &tape.tail_in[last], dy, pad, Some(&mut dz), &mut grads.tail[last]);
        for i in (0..last).rev() {
            let mut dpre = Tensor::zeros(&dz.shape);
            ops.relu_backward(&tape.tail_pre[i], &dz, &mut dpre);
            let mut dzin = Tensor::zeros(&tape.tail_in[i].shape);
            self.tail[i].backward(ops, &tape.tail_in[i], &dpre, pad, Some(&mut dzin), &mut grads.tail[i]);
            dz = dzin;
        }
        let du = ops.pixel_unshuffle(&dz, self.config.scale);
        drop(dz);
        let mut da = Tensor::zeros(&tape.upscale_in.shape);
        self.upscale.backward(ops, &tape.upscale_in, &du, pad, Some(&mut da), &mut grads.upscale);
        drop(du);
        for (k, b) in self.blocks.iter().enumerate().rev() {
            let [a_in, t1, r1] = &tape.blocks[k];
            let g = &mut grads.blocks[k];
            let mut dr1 = Tensor::zeros(&r1.shape);
            b.conv2.backward(ops, r1, &da, pad, Some(&mut dr1), &mut g.conv2);
            let mut dt1 = Tensor::zeros(&t1.shape);
            ops.relu_backward(t1, &dr1, &mut dt1);
            drop(dr1);
            let mut da_in = Tensor::zeros(&a_in.shape);
            b.conv1.backward(ops, a_in, &dt1, pad, Some(&mut da_in), &mut g.conv1);
            if self.kind.residual() {
                ops.add_assign(&mut da_in, &da);
            }
            da = da_in;
        }
        self.conv_in.backward(ops, &tape.input, &da, pad, None, &mut grads.conv_in);
    }
}

/// Names and shapes of every parameter of a net, in canonical order (what a weights file holds).
pub fn param_shapes(kind: NetKind, config: NetConfig) -> Vec<(String, Vec<usize>)> {
    layout(kind, config)
        .into_iter()
        .flat_map(|(l, o, i)| {
            let n = l.name();
            [(format!("{n}.weight"), vec![o, i, KERNEL, KERNEL]), (format!("{n}.bias"), vec![o])]
        })
        .collect()
}
