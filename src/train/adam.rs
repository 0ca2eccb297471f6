//! Adam over a list of flat parameter buffers, with its state (m, v, step) saved into and
//! restored from a checkpoint's [`NpzEntries`], so a resumed run continues bit for bit.
//!
//! Checkpoint entries, for a prefix such as `"adam."`:
//! `{prefix}m.{i}`, `{prefix}v.{i}` (flat f32 arrays, one per parameter buffer, in the order
//! the buffers are passed to [`Adam::step`]), `{prefix}hparams` ([lr, β1, β2, ε]) and
//! `{prefix}step` (a raw entry holding the step count as decimal text, exact beyond 2²⁴).

use crate::error::{Error, Result};
use crate::io::NpzEntries;
use crate::ops::{AdamParams, Ops};
use crate::tensor::Tensor;
use std::path::Path;

#[derive(Clone, Debug, PartialEq)]
pub struct Adam {
    pub params: AdamParams,
    /// First moments, one flat buffer per parameter buffer.
    pub m: Vec<Vec<f32>>,
    /// Second moments, one flat buffer per parameter buffer.
    pub v: Vec<Vec<f32>>,
    /// Steps taken so far (the next step uses step + 1 in the bias correction).
    pub step: u64,
}

impl Adam {
    /// Fresh state for parameter buffers of the given lengths (elements).
    pub fn new(params: AdamParams, sizes: &[usize]) -> Self {
        Adam {
            params,
            m: sizes.iter().map(|&n| vec![0.0; n]).collect(),
            v: sizes.iter().map(|&n| vec![0.0; n]).collect(),
            step: 0,
        }
    }

    /// One optimizer step: every `params[i]` moves along `grads[i]`. The buffers must be the
    /// ones (count, lengths, order) this optimizer was built for.
    pub fn step(&mut self, ops: &dyn Ops, params: &mut [&mut [f32]], grads: &[&[f32]]) {
        assert_eq!(
            params.len(),
            self.m.len(),
            "Adam::step: {} buffers, optimizer has {}",
            params.len(),
            self.m.len()
        );
        assert_eq!(
            grads.len(),
            params.len(),
            "Adam::step: {} grads for {} buffers",
            grads.len(),
            params.len()
        );
        self.step += 1;
        for (i, (p, g)) in params.iter_mut().zip(grads).enumerate() {
            assert_eq!(
                p.len(),
                self.m[i].len(),
                "Adam::step: buffer {i} has {} values, state {}",
                p.len(),
                self.m[i].len()
            );
            ops.adam_update(p, g, &mut self.m[i], &mut self.v[i], self.step, &self.params);
        }
    }

    /// Append this optimizer's state to a checkpoint under `prefix`.
    pub fn save(&self, prefix: &str, out: &mut NpzEntries) {
        for (i, (m, v)) in self.m.iter().zip(&self.v).enumerate() {
            out.push_array(format!("{prefix}m.{i}"), Tensor { shape: [m.len()].into(), data: m.clone() });
            out.push_array(format!("{prefix}v.{i}"), Tensor { shape: [v.len()].into(), data: v.clone() });
        }
        let h = &self.params;
        out.push_array(
            format!("{prefix}hparams"),
            Tensor { shape: [4].into(), data: vec![h.lr, h.beta1, h.beta2, h.eps] },
        );
        out.push_file(format!("{prefix}step"), format!("{}\n", self.step).into_bytes());
    }

    /// Restore m, v, step and the hyper-parameters saved by [`Adam::save`] under `prefix`.
    /// `self` must have been built for the same buffers; `path` names the checkpoint in errors.
    /// (To change the learning rate on resume, set `params.lr` after loading.)
    pub fn load(&mut self, entries: &NpzEntries, prefix: &str, path: &Path) -> Result<()> {
        let mut m = Vec::with_capacity(self.m.len());
        let mut v = Vec::with_capacity(self.v.len());
        for (i, want) in self.m.iter().map(Vec::len).enumerate() {
            for (name, dst) in [("m", &mut m), ("v", &mut v)] {
                let t = entries.require(path, &format!("{prefix}{name}.{i}"))?;
                if t.len() != want {
                    return Err(Error::format(
                        path,
                        format!("{prefix}{name}.{i} has {} values, parameter buffer {i} has {want}", t.len()),
                    ));
                }
                dst.push(t.data.clone());
            }
        }
        let extra = format!("{prefix}m.{}", self.m.len());
        if entries.array(&extra).is_some() {
            return Err(Error::format(
                path,
                format!("optimizer state has more buffers than the model ({extra})"),
            ));
        }
        let h = entries.require(path, &format!("{prefix}hparams"))?;
        if h.len() != 4 {
            return Err(Error::format(path, format!("{prefix}hparams: expected 4 values, got {}", h.len())));
        }
        let step_name = format!("{prefix}step");
        let step = entries
            .file(&step_name)
            .and_then(|b| std::str::from_utf8(b).ok())
            .and_then(|s| s.trim().parse::<u64>().ok())
            .ok_or_else(|| Error::format(path, format!("missing or unreadable '{step_name}'")))?;
        self.params = AdamParams { lr: h.data[0], beta1: h.data[1], beta2: h.data[2], eps: h.data[3] };
        self.m = m;
        self.v = v;
        self.step = step;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::npz::{npz_bytes, npz_from_bytes};
    use crate::ops::Cpu;

    fn grads(step: usize, sizes: &[usize]) -> Vec<Vec<f32>> {
        sizes
            .iter()
            .map(|&n| (0..n).map(|k| ((k * 7 + step * 13) % 11) as f32 / 5.0 - 1.0).collect())
            .collect()
    }

    fn run(adam: &mut Adam, p: &mut [Vec<f32>], steps: std::ops::Range<usize>) {
        let sizes: Vec<usize> = p.iter().map(Vec::len).collect();
        for s in steps {
            let g = grads(s, &sizes);
            let mut pr: Vec<&mut [f32]> = p.iter_mut().map(|v| v.as_mut_slice()).collect();
            let gr: Vec<&[f32]> = g.iter().map(|v| v.as_slice()).collect();
            adam.step(&Cpu, &mut pr, &gr);
        }
    }

    #[test]
    fn resume_from_saved_state_matches_uninterrupted_run_bitwise() {
        let sizes = [5, 40_000, 3];
        let hp = AdamParams { lr: 1e-3, ..Default::default() };
        let init: Vec<Vec<f32>> =
            sizes.iter().map(|&n| (0..n).map(|k| (k % 17) as f32 * 0.1).collect()).collect();

        let mut a = Adam::new(hp, &sizes);
        let mut pa = init.clone();
        run(&mut a, &mut pa, 0..10);

        let mut b = Adam::new(hp, &sizes);
        let mut pb = init;
        run(&mut b, &mut pb, 0..4);
        let mut e = NpzEntries::default();
        b.save("adam.", &mut e);
        let e = npz_from_bytes(&npz_bytes(&e).unwrap()).unwrap();
        let mut c = Adam::new(AdamParams::default(), &sizes);
        c.load(&e, "adam.", Path::new("ckpt.npz")).unwrap();
        assert_eq!(c, b);
        run(&mut c, &mut pb, 4..10);
        assert_eq!(pa, pb);
        assert_eq!(a, c);
    }

    #[test]
    fn load_rejects_state_for_other_buffers() {
        let mut e = NpzEntries::default();
        Adam::new(AdamParams::default(), &[4, 6]).save("opt.", &mut e);
        let p = Path::new("ckpt.npz");
        let err = Adam::new(AdamParams::default(), &[4, 7]).load(&e, "opt.", p).unwrap_err().to_string();
        assert!(err.contains("ckpt.npz") && err.contains("opt.m.1"), "{err}");
        assert!(Adam::new(AdamParams::default(), &[4]).load(&e, "opt.", p).is_err());
        assert!(Adam::new(AdamParams::default(), &[4, 6, 1]).load(&e, "opt.", p).is_err());
        assert!(Adam::new(AdamParams::default(), &[4, 6]).load(&e, "other.", p).is_err());
    }
}
