//! 3-vectors as plain arrays `[T; 3]`, `T` = f32 (positions in metres, directions, colours)
//! or f64 (the Laplacian and metrics): the few operations the simulator, the geometry, the
//! metrics and the renderer share. Each is written once, component by component in index
//! order, so a caller gets the bits it would get from the same expression written inline.

use std::ops::{Add, Div, Mul, Sub};

/// A 3-vector of f32 (metres for positions, unit for directions, sRGB in [0,1] for colours).
pub type V3 = [f32; 3];

/// f32 or f64.
pub trait Real:
    Copy + PartialOrd + Add<Output = Self> + Sub<Output = Self> + Mul<Output = Self> + Div<Output = Self>
{
    const ZERO: Self;
    fn sqrt(self) -> Self;
}

impl Real for f32 {
    const ZERO: f32 = 0.0;
    #[inline]
    fn sqrt(self) -> f32 {
        f32::sqrt(self)
    }
}

impl Real for f64 {
    const ZERO: f64 = 0.0;
    #[inline]
    fn sqrt(self) -> f64 {
        f64::sqrt(self)
    }
}

/// `a − b`
#[inline]
pub fn sub<T: Real>(a: [T; 3], b: [T; 3]) -> [T; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

/// `a + b`
#[inline]
pub fn add<T: Real>(a: [T; 3], b: [T; 3]) -> [T; 3] {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}

/// `s·a`
#[inline]
pub fn scale<T: Real>(a: [T; 3], s: T) -> [T; 3] {
    [a[0] * s, a[1] * s, a[2] * s]
}

/// `a · b`
#[inline]
pub fn dot<T: Real>(a: [T; 3], b: [T; 3]) -> T {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// `a × b`
#[inline]
pub fn cross<T: Real>(a: [T; 3], b: [T; 3]) -> [T; 3] {
    [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]
}

/// `|a|`
#[inline]
pub fn norm<T: Real>(a: [T; 3]) -> T {
    dot(a, a).sqrt()
}

/// `a / |a|`, or `fallback` when `|a|` is not positive (zero, or NaN).
#[inline]
pub fn normalize_or<T: Real>(a: [T; 3], fallback: [T; 3]) -> [T; 3] {
    let n = norm(a);
    if n > T::ZERO {
        [a[0] / n, a[1] / n, a[2] / n]
    } else {
        fallback
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn products_of_the_axes() {
        let (x, y, z) = ([1.0f32, 0.0, 0.0], [0.0f32, 1.0, 0.0], [0.0f32, 0.0, 1.0]);
        assert_eq!(cross(x, y), z);
        assert_eq!(cross(y, x), [0.0, 0.0, -1.0]);
        assert_eq!(dot([1.0f64, 2.0, 3.0], [4.0, 5.0, 6.0]), 32.0);
        assert_eq!(norm(sub([4.0f64, 6.0, 3.0], [1.0, 2.0, 3.0])), 5.0);
        assert_eq!(normalize_or([0.0f32, 3.0, 4.0], z), [0.0, 0.6, 0.8]);
        assert_eq!(normalize_or([0.0f32; 3], z), z);
    }
}
