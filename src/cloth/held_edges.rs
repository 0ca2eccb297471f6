//! The edges of a grid an artist names as held (`upscale --physics-pin`): the physics pass
//! ([`super::follow`]) pins those HR vertices to the shot, and each scenario says which of its
//! own it holds ([`super::Scenario::held_edges`]).

use crate::error::{Error, Result};

/// Which vertices of the HR grid the physics pass pins to the shot (`--physics-pin`): whole
/// edges of the grid as the input lists it (row 0 is `top`, column 0 is `left`) or its four
/// corners. Pinned vertices take the nets' positions at every substep (blended linearly over
/// the frame), so a held edge pulls the cloth as the shot's hand or hook did; the coarse
/// constraints still hold the rest.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct PinnedEdges {
    pub top: bool,
    pub bottom: bool,
    pub left: bool,
    pub right: bool,
    pub corners: bool,
}

impl PinnedEdges {
    const NAMES: [&'static str; 5] = ["top", "bottom", "left", "right", "corners"];

    /// `top,left,...` (any of top, bottom, left, right, corners; `none` or empty = nothing).
    pub fn parse(s: &str) -> Result<PinnedEdges> {
        let mut e = PinnedEdges::default();
        for w in s.split(',').map(str::trim).filter(|w| !w.is_empty() && *w != "none") {
            *match w {
                "top" => &mut e.top,
                "bottom" => &mut e.bottom,
                "left" => &mut e.left,
                "right" => &mut e.right,
                "corners" => &mut e.corners,
                _ => {
                    return Err(Error::invalid(
                        "pins",
                        format!(
                            "the held edges are a comma-separated list of {} (or none), got {w:?}",
                            Self::NAMES.join(", ")
                        ),
                    ))
                }
            } = true;
        }
        Ok(e)
    }

    fn flags(&self) -> [bool; 5] {
        [self.top, self.bottom, self.left, self.right, self.corners]
    }

    pub fn is_empty(&self) -> bool {
        !self.flags().iter().any(|&f| f)
    }

    /// The names set, comma-separated (`none` when empty), as `parse` reads them.
    pub fn names(&self) -> String {
        let n: Vec<&str> =
            Self::NAMES.iter().zip(self.flags()).filter(|(_, f)| *f).map(|(n, _)| *n).collect();
        if n.is_empty() {
            "none".into()
        } else {
            n.join(",")
        }
    }

    /// The pinned vertices of a `w × h` grid, in index order.
    pub fn vertices(&self, w: usize, h: usize) -> Vec<usize> {
        (0..w * h)
            .filter(|&v| {
                let (i, j) = (v % w, v / w);
                let (l, r, t, b) = (i == 0, i + 1 == w, j == 0, j + 1 == h);
                (self.top && t)
                    || (self.bottom && b)
                    || (self.left && l)
                    || (self.right && r)
                    || (self.corners && (l || r) && (t || b))
            })
            .collect()
    }
}
