//! Cloth meshes that are not a regular grid, as OBJ text, for the any-mesh tests (issue 45):
//! a flared skirt (a tube of quads), a round tablecloth (triangles), a T-shaped sheet, a sheet
//! with a hole, an unwelded sheet (every quad its own four vertices) and a mixed mesh of quads
//! and triangles with UVs, two materials, groups and normals. Each is a [`Mesh`]; frames of a
//! shot are the same mesh moved ([`Mesh::moved`]). Include with
//! `#[path = "common/meshes.rs"] mod meshes;`.

#![allow(dead_code)]

use std::fmt::Write;

#[derive(Clone, Debug)]
pub struct Mesh {
    pub pos: Vec<[f32; 3]>,
    /// 0-based faces of 3 or 4 vertices.
    pub faces: Vec<Vec<u32>>,
    /// Optional UVs: coordinates and per-face indices.
    pub uv: Option<anisocb::geom::surface::FaceUvsBuf>,
    /// Lines written before face k: (k, line).
    pub tags: Vec<(usize, String)>,
    pub normals: bool,
}

impl Mesh {
    fn plain(pos: Vec<[f32; 3]>, faces: Vec<Vec<u32>>) -> Mesh {
        Mesh { pos, faces, uv: None, tags: Vec::new(), normals: false }
    }

    /// OBJ text.
    pub fn obj(&self) -> String {
        let mut s = String::new();
        for p in &self.pos {
            let _ = writeln!(s, "v {} {} {}", p[0], p[1], p[2]);
        }
        if let Some((uv, _)) = &self.uv {
            for t in uv {
                let _ = writeln!(s, "vt {} {}", t[0], t[1]);
            }
        }
        if self.normals {
            for _ in &self.pos {
                let _ = writeln!(s, "vn 0 0 1");
            }
        }
        for (k, f) in self.faces.iter().enumerate() {
            for (_, line) in self.tags.iter().filter(|t| t.0 == k) {
                let _ = writeln!(s, "{line}");
            }
            s.push('f');
            for (c, v) in f.iter().enumerate() {
                let t = self.uv.as_ref().map(|(_, fu)| fu[k][c] + 1);
                let _ = match (t, self.normals) {
                    (None, false) => write!(s, " {}", v + 1),
                    (Some(t), false) => write!(s, " {}/{t}", v + 1),
                    (None, true) => write!(s, " {}//{}", v + 1, v + 1),
                    (Some(t), true) => write!(s, " {}/{t}/{}", v + 1, v + 1),
                };
            }
            s.push('\n');
        }
        s
    }

    /// The mesh turned by `angle` radians about the y axis, then moved by `t` (metres).
    pub fn moved(&self, angle: f32, t: [f32; 3]) -> Mesh {
        let (c, s) = (angle.cos(), angle.sin());
        let pos = self
            .pos
            .iter()
            .map(|p| [c * p[0] + s * p[2] + t[0], p[1] + t[1], -s * p[0] + c * p[2] + t[2]])
            .collect();
        Mesh { pos, ..self.clone() }
    }

    /// The mesh with a soft ripple of `amp` metres along its local normal-ish z (a frame that
    /// is not only moved).
    pub fn rippled(&self, amp: f32, phase: f32) -> Mesh {
        let pos = self
            .pos
            .iter()
            .map(|p| [p[0], p[1], p[2] + amp * (7.0 * p[0] + phase).sin() * (5.0 * p[1]).cos()])
            .collect();
        Mesh { pos, ..self.clone() }
    }
}

/// A grid of `w` × `h` vertices over `size` metres in the xy plane, with a gentle drape in z,
/// keeping the cells `keep(i, j)` (cell (i, j) spans vertices i..i+1, j..j+1); vertices of no
/// kept cell are dropped.
fn sheet_cells(w: usize, h: usize, size: f32, keep: impl Fn(usize, usize) -> bool) -> Mesh {
    let mut index = vec![u32::MAX; w * h];
    let mut pos = Vec::new();
    let mut faces = Vec::new();
    let mut id = |i: usize, j: usize, pos: &mut Vec<[f32; 3]>| {
        let k = j * w + i;
        if index[k] == u32::MAX {
            index[k] = pos.len() as u32;
            let (x, y) = (size * i as f32 / (w - 1) as f32, size * j as f32 / (w - 1) as f32);
            pos.push([x, -y, 0.08 * (3.0 * x).sin() * (2.0 * y).cos()]);
        }
        index[k]
    };
    for j in 0..h - 1 {
        for i in 0..w - 1 {
            if keep(i, j) {
                let f = vec![
                    id(i, j, &mut pos),
                    id(i, j + 1, &mut pos),
                    id(i + 1, j + 1, &mut pos),
                    id(i + 1, j, &mut pos),
                ];
                faces.push(f);
            }
        }
    }
    Mesh::plain(pos, faces)
}

/// A flared skirt: `around` × `rings` quads, a tube open at the waist and the hem.
pub fn skirt(around: usize, rings: usize) -> Mesh {
    let mut pos = Vec::new();
    for j in 0..=rings {
        let t = j as f32 / rings as f32;
        let r = 0.16 + 0.14 * t;
        for i in 0..around {
            let a = std::f32::consts::TAU * i as f32 / around as f32;
            // A few soft folds towards the hem.
            let rr = r * (1.0 + 0.06 * t * (6.0 * a).sin());
            pos.push([rr * a.cos(), -0.55 * t, rr * a.sin()]);
        }
    }
    let mut faces = Vec::new();
    for j in 0..rings {
        for i in 0..around {
            let n = (i + 1) % around;
            let v = |i: usize, j: usize| (j * around + i) as u32;
            faces.push(vec![v(i, j), v(n, j), v(n, j + 1), v(i, j + 1)]);
        }
    }
    Mesh::plain(pos, faces)
}

/// A round tablecloth of triangles: a centre, `rings` rings of `around` vertices, draped over
/// the table's edge at `table` of the radius.
pub fn tablecloth(around: usize, rings: usize, radius: f32) -> Mesh {
    let mut pos = vec![[0.0, 0.0, 0.0]];
    for k in 1..=rings {
        let r = radius * k as f32 / rings as f32;
        for i in 0..around {
            let a = std::f32::consts::TAU * (i as f32 + 0.5 * (k % 2) as f32) / around as f32;
            let over = (r - 0.6 * radius).max(0.0);
            pos.push([
                (r - 0.5 * over) * a.cos(),
                -over * (1.0 + 0.2 * (5.0 * a).sin()),
                (r - 0.5 * over) * a.sin(),
            ]);
        }
    }
    let v = |k: usize, i: usize| if k == 0 { 0 } else { (1 + (k - 1) * around + i % around) as u32 };
    let mut faces = Vec::new();
    for i in 0..around {
        faces.push(vec![0, v(1, i + 1), v(1, i)]);
    }
    for k in 1..rings {
        for i in 0..around {
            let (a, b, c, d) = (v(k, i), v(k, i + 1), v(k + 1, i + 1), v(k + 1, i));
            // Diagonals that alternate with the rings' stagger.
            if k % 2 == 1 {
                faces.push(vec![a, b, c]);
                faces.push(vec![a, c, d]);
            } else {
                faces.push(vec![a, b, d]);
                faces.push(vec![b, c, d]);
            }
        }
    }
    Mesh::plain(pos, faces)
}

/// A T-shaped sheet (a flat T-shirt's outline): the top `arm` rows full width, below them only
/// the middle third.
pub fn t_shape(w: usize, h: usize, arm: usize) -> Mesh {
    sheet_cells(w, h, 0.8, |i, j| j < arm || (i >= (w - 1) / 3 && i < 2 * (w - 1) / 3))
}

/// A sheet with a square hole in the middle.
pub fn holed_sheet(w: usize) -> Mesh {
    let (a, b) = (w / 3, w - 1 - w / 3);
    sheet_cells(w, w, 0.8, |i, j| !(i >= a && i < b && j >= a && j < b))
}

/// A sheet exported unwelded: every quad with its own four vertices (coincident with its
/// neighbours').
pub fn unwelded_sheet(w: usize) -> Mesh {
    let m = sheet_cells(w, w, 0.8, |_, _| true);
    let mut pos = Vec::new();
    let mut faces = Vec::new();
    for f in &m.faces {
        let base = pos.len() as u32;
        for &v in f {
            pos.push(m.pos[v as usize]);
        }
        faces.push((0..4).map(|k| base + k).collect());
    }
    Mesh::plain(pos, faces)
}

/// A sheet of quads whose last column of cells is split into triangles, with UVs, two
/// materials, two groups and normals.
pub fn mixed_textured(w: usize) -> Mesh {
    let g = sheet_cells(w, w, 0.6, |_, _| true);
    let mut faces = Vec::new();
    for (k, f) in g.faces.iter().enumerate() {
        if k % (w - 1) == w - 2 {
            faces.push(vec![f[0], f[1], f[2]]);
            faces.push(vec![f[0], f[2], f[3]]);
        } else {
            faces.push(f.clone());
        }
    }
    // UVs from the rest position (one per vertex), with the same indices as the vertices.
    let uv: Vec<[f32; 2]> = g.pos.iter().map(|p| [p[0] / 0.6, 1.0 + p[1] / 0.6]).collect();
    let fuv = faces.clone();
    let half = faces.len() / 2;
    let tags = vec![
        (0, "g front".to_string()),
        (0, "usemtl silk".to_string()),
        (0, "s 1".to_string()),
        (half, "g back".to_string()),
        (half, "usemtl lining".to_string()),
    ];
    Mesh { pos: g.pos, faces, uv: Some((uv, fuv)), tags, normals: true }
}
