//! Pinned and kinematically driven vertices. A pin holds its vertex at
//! `Kinematics::position(anchor, side, t)`; pinned vertices have infinite mass.

/// One pinned vertex: `anchor` is its rest position (m), `side` tells driven groups apart
/// (−1 left end / +1 right end for a twist; unused otherwise).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Pin {
    pub vertex: usize,
    pub anchor: [f32; 3],
    pub side: f32,
}

/// How pinned vertices move over time `t` (s).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Kinematics {
    /// Pins stay at their anchors.
    Static,
    /// The flag's edge: pins translate by `amplitude · sin(2π · freq · t) · dir` (m, Hz, unit
    /// vector), eased in over the first period.
    Flap { amplitude: f32, freq: f32, dir: [f32; 3] },
    /// Twisting ends: pins rotate about the x axis through (`center_y`, `center_z`) (m) by
    /// `side · omega · t` (rad/s; the two ends turn in opposite directions) and move toward
    /// the middle by `min(inward_speed · t, max_inward)` (m/s, m).
    Twist { center_y: f32, center_z: f32, omega: f32, inward_speed: f32, max_inward: f32 },
    /// Corners of a draped sheet: x scaled toward 0 by `squeeze` (fraction) and lowered by
    /// `drop` (m), eased in with a smoothstep over `ramp` seconds.
    Drape { squeeze: f32, drop: f32, ramp: f32 },
}

fn smoothstep(x: f32) -> f32 {
    let x = x.clamp(0.0, 1.0);
    x * x * (3.0 - 2.0 * x)
}

impl Kinematics {
    pub fn position(&self, anchor: [f32; 3], side: f32, t: f32) -> [f32; 3] {
        match *self {
            Kinematics::Static => anchor,
            Kinematics::Flap { amplitude, freq, dir } => {
                let ease = smoothstep(t * freq);
                let s = amplitude * ease * (std::f32::consts::TAU * freq * t).sin();
                [anchor[0] + s * dir[0], anchor[1] + s * dir[1], anchor[2] + s * dir[2]]
            }
            Kinematics::Twist { center_y, center_z, omega, inward_speed, max_inward } => {
                // Ease the angular velocity in over 0.5 s so the strip is not jerked.
                let ramp = 0.5;
                let angle = if t < ramp { omega * t * t / (2.0 * ramp) } else { omega * (t - 0.5 * ramp) };
                let a = side * angle;
                let (s, c) = a.sin_cos();
                let (y, z) = (anchor[1] - center_y, anchor[2] - center_z);
                let inward = (inward_speed * t).min(max_inward);
                [anchor[0] - side * inward, center_y + c * y - s * z, center_z + s * y + c * z]
            }
            Kinematics::Drape { squeeze, drop, ramp } => {
                let e = smoothstep(t / ramp.max(1e-6));
                [anchor[0] * (1.0 - squeeze * e), anchor[1] - drop * e, anchor[2]]
            }
        }
    }
}
