//! A time-varying wind field, deterministic from the seed: a mean velocity plus a few gust
//! harmonics whose phase also travels along the cloth, so it ripples rather than shakes.

use crate::geom::vec3::norm;
use crate::rng::SplitMix64;

#[derive(Clone, Debug, PartialEq)]
pub struct Wind {
    /// Mean wind velocity (m/s).
    pub mean: [f32; 3],
    /// Gust harmonics: (amplitude as a fraction of |mean|, frequency Hz, phase rad,
    /// wave number along x rad/m, direction of the gust velocity (unit)).
    pub gusts: Vec<(f32, f32, f32, f32, [f32; 3])>,
}

impl Wind {
    pub fn none() -> Wind {
        Wind { mean: [0.0; 3], gusts: Vec::new() }
    }

    /// Mean velocity `mean` (m/s) with `n` random gusts of total relative strength `gust`.
    pub fn gusty(mean: [f32; 3], gust: f32, n: usize, seed: u64) -> Wind {
        let mut rng = SplitMix64::new(seed.wrapping_mul(0xA24B_AED4_963E_E407).wrapping_add(17));
        let gusts = (0..n)
            .map(|_| {
                let amp = gust * rng.uniform_in(0.5, 1.0) / n as f32;
                let freq = rng.uniform_in(0.2, 1.5);
                let phase = rng.uniform_in(0.0, std::f32::consts::TAU);
                let kx = rng.uniform_in(-3.0, 3.0);
                let d = [rng.uniform_in(-0.5, 0.5), rng.uniform_in(-0.3, 0.3), 1.0];
                let l = norm(d);
                (amp, freq, phase, kx, [d[0] / l, d[1] / l, d[2] / l])
            })
            .collect();
        Wind { mean, gusts }
    }

    /// Wind velocity (m/s) at time `t` (s) and position `p` (m).
    pub fn velocity(&self, t: f32, p: [f32; 3]) -> [f32; 3] {
        let speed = norm(self.mean);
        let mut w = self.mean;
        for &(amp, freq, phase, kx, dir) in &self.gusts {
            let s = amp * speed * (std::f32::consts::TAU * freq * t + phase + kx * p[0]).sin();
            for k in 0..3 {
                w[k] += s * dir[k];
            }
        }
        w
    }

    pub fn is_calm(&self) -> bool {
        self.mean == [0.0; 3] && self.gusts.is_empty()
    }
}
