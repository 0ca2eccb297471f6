//! Cloth of any outline (issue 45): a mesh of triangles and quads with a topology fixed over the
//! shot — several pieces, open borders, holes, tubes — checked once ([`Surface::new`]), and its
//! linear subdivision ([`Subdivision`]), the HR mesh's topology: every face split into four
//! (edge midpoints, and a centre for a quad), so the user's face order, winding, UVs, seams,
//! materials and groups carry over face by face.
//!
//! HR vertex numbering: the LR vertices first (same indices), then one vertex per LR edge in
//! the order edges are first met walking the faces, then one per quad in face order. LR face
//! `f` becomes HR faces `4f .. 4f + 4`.

use crate::error::{Error, Result};
use std::collections::HashMap;
use std::path::Path;

/// A checked fixed-topology mesh: `vertices` positions, faces of 3 or 4 distinct vertices,
/// every edge in one or two faces, no face twice.
#[derive(Clone, Debug, PartialEq)]
pub struct Surface {
    pub vertices: usize,
    pub faces: Vec<Vec<u32>>,
}

/// Texture coordinates and, per face, the index of each corner's coordinate (a UV seam is an
/// edge whose two faces index different coordinates).
pub type FaceUvs<'a> = (&'a [[f32; 2]], &'a [Vec<u32>]);

/// [`FaceUvs`] owned.
pub type FaceUvsBuf = (Vec<[f32; 2]>, Vec<Vec<u32>>);

/// `(min, max)` of an edge's two vertices: the key that names an edge whatever its direction.
pub fn edge_key(a: u32, b: u32) -> (u32, u32) {
    (a.min(b), a.max(b))
}

impl Surface {
    /// Check the faces of a mesh of `vertices` vertices read from `path` (named in errors, with
    /// 1-based face and vertex numbers as in the file): what cannot be subdivided or laid out
    /// as cloth is refused with what to do about it.
    pub fn new(vertices: usize, faces: Vec<Vec<u32>>, path: &Path) -> Result<Surface> {
        if faces.is_empty() {
            return Err(Error::format(path, "the mesh has no faces: export the cloth as a mesh with faces"));
        }
        let mut seen: HashMap<Vec<u32>, usize> = HashMap::new();
        let mut edge_faces: HashMap<(u32, u32), Vec<usize>> = HashMap::new();
        for (k, f) in faces.iter().enumerate() {
            if f.len() != 3 && f.len() != 4 {
                return Err(Error::format(
                    path,
                    format!(
                        "face {} has {} vertices: anisocb takes triangles and quads; triangulate \
                         the larger faces first (Blender: Triangulate modifier with \"Quad Method: \
                         Beauty\" and \"N-gon Method\" only, or Face > Triangulate Faces)",
                        k + 1,
                        f.len()
                    ),
                ));
            }
            if let Some(&v) = f.iter().find(|&&v| v as usize >= vertices) {
                return Err(Error::format(
                    path,
                    format!("face {} uses vertex {} of {vertices}", k + 1, v + 1),
                ));
            }
            for i in 0..f.len() {
                if f[i + 1..].contains(&f[i]) {
                    return Err(Error::format(
                        path,
                        format!(
                            "face {} uses vertex {} twice (a collapsed face): merge or delete it \
                             (Blender: Mesh > Clean Up > Degenerate Dissolve)",
                            k + 1,
                            f[i] + 1
                        ),
                    ));
                }
            }
            let mut sorted = f.clone();
            sorted.sort_unstable();
            if let Some(first) = seen.insert(sorted, k) {
                return Err(Error::format(
                    path,
                    format!(
                        "faces {} and {} have the same vertices (a face used twice): delete one \
                         (Blender: Mesh > Clean Up > Delete Loose / Merge by Distance)",
                        first + 1,
                        k + 1
                    ),
                ));
            }
            for i in 0..f.len() {
                edge_faces.entry(edge_key(f[i], f[(i + 1) % f.len()])).or_default().push(k);
            }
        }
        let mut bad: Vec<(&(u32, u32), &Vec<usize>)> = edge_faces.iter().filter(|e| e.1.len() > 2).collect();
        bad.sort();
        if let Some(((a, b), fs)) = bad.first() {
            let list: Vec<String> = fs.iter().map(|f| (f + 1).to_string()).collect();
            return Err(Error::format(
                path,
                format!(
                    "edge {}–{} is shared by {} faces ({}; {} such edges in all): cloth is a \
                     surface, where an edge joins at most two faces; split the mesh there \
                     (Blender: select the edges, Edge > Edge Split) or separate the pieces",
                    a + 1,
                    b + 1,
                    fs.len(),
                    list.join(", "),
                    bad.len()
                ),
            ));
        }
        Ok(Surface { vertices, faces })
    }

    /// Whether another frame's faces (`faces`, read from `path`, frame `frame` of the shot)
    /// are this surface's: a shot's topology is fixed.
    pub fn check_same(&self, vertices: usize, faces: &[Vec<u32>], frame: usize, path: &Path) -> Result<()> {
        if vertices == self.vertices && faces == self.faces.as_slice() {
            return Ok(());
        }
        let what = if vertices != self.vertices || faces.len() != self.faces.len() {
            format!(
                "{vertices} vertices and {} faces, the first frame {} and {}",
                faces.len(),
                self.vertices,
                self.faces.len()
            )
        } else {
            let k = faces.iter().zip(&self.faces).position(|(a, b)| a != b).unwrap_or(0);
            format!(
                "face {} is {:?} here, {:?} in the first frame",
                k + 1,
                one_based(&faces[k]),
                one_based(&self.faces[k])
            )
        };
        Err(Error::format(
            path,
            format!(
                "frame {frame} has another topology than the first frame ({what}): every frame of a \
                 shot must be the same mesh moved; export without modifiers that change the mesh \
                 (remesh, decimate, subdivision after the cloth), and with the same vertex order"
            ),
        ))
    }
}

fn one_based(f: &[u32]) -> Vec<u32> {
    f.iter().map(|v| v + 1).collect()
}

/// The linear subdivision of a face list (see the module docs for the numbering). It needs no
/// manifold check, so the UVs' own faces (a seam is two edges there) subdivide with it too.
#[derive(Clone, Debug, PartialEq)]
pub struct Subdivision {
    /// LR vertices (HR vertices `0..lr` are them).
    lr: usize,
    /// One HR vertex per LR edge (`lr + k`): its two ends.
    edges: Vec<(u32, u32)>,
    /// One HR vertex per quad (`lr + edges.len() + k`): its corners.
    centres: Vec<[u32; 4]>,
    /// Per quad centre, its four edges (indices into `edges`), in corner order.
    centre_edges: Vec<[u32; 4]>,
    /// The HR faces, four per LR face in its order.
    pub faces: Vec<Vec<u32>>,
}

impl Subdivision {
    /// Subdivide `faces` (3 or 4 vertices each) over `lr` vertices.
    pub fn of(lr: usize, faces: &[Vec<u32>]) -> Subdivision {
        // Edges first (numbered as first met), so the quad centres can follow them.
        let mut index: HashMap<(u32, u32), u32> = HashMap::new();
        let mut edges = Vec::new();
        for f in faces {
            for i in 0..f.len() {
                let key = edge_key(f[i], f[(i + 1) % f.len()]);
                index.entry(key).or_insert_with(|| {
                    edges.push(key);
                    (lr + edges.len() - 1) as u32
                });
            }
        }
        let mut centres = Vec::new();
        let mut centre_edges = Vec::new();
        let mut hr_faces = Vec::with_capacity(4 * faces.len());
        for f in faces {
            let n = f.len();
            // HR vertex of the midpoint of edge f[i]–f[i+1].
            let mid: Vec<u32> = (0..n).map(|i| index[&edge_key(f[i], f[(i + 1) % n])]).collect();
            if n == 3 {
                let (a, b, c) = (f[0], f[1], f[2]);
                let (ab, bc, ca) = (mid[0], mid[1], mid[2]);
                hr_faces.extend([vec![a, ab, ca], vec![ab, b, bc], vec![ca, bc, c], vec![ab, bc, ca]]);
            } else {
                let o = (lr + edges.len() + centres.len()) as u32;
                centres.push([f[0], f[1], f[2], f[3]]);
                centre_edges.push(std::array::from_fn(|i| mid[i] - lr as u32));
                let (a, b, c, d) = (f[0], f[1], f[2], f[3]);
                let (ab, bc, cd, da) = (mid[0], mid[1], mid[2], mid[3]);
                hr_faces.extend([
                    vec![a, ab, o, da],
                    vec![ab, b, bc, o],
                    vec![o, bc, c, cd],
                    vec![da, o, cd, d],
                ]);
            }
        }
        Subdivision { lr, edges, centres, centre_edges, faces: hr_faces }
    }

    /// Vertices of the subdivided mesh.
    pub fn hr_vertices(&self) -> usize {
        self.lr + self.edges.len() + self.centres.len()
    }

    /// The subdivided mesh's values of a per-vertex quantity `lr` (positions, UVs): each edge
    /// vertex the mean of its ends, each centre the mean of its quad's corners.
    pub fn apply<const N: usize>(&self, lr: &[[f32; N]]) -> Vec<[f32; N]> {
        let mut out = Vec::with_capacity(self.hr_vertices());
        out.extend_from_slice(&lr[..self.lr]);
        for &(a, b) in &self.edges {
            let (p, q) = (lr[a as usize], lr[b as usize]);
            out.push(std::array::from_fn(|k| 0.5 * (p[k] + q[k])));
        }
        for c in &self.centres {
            let p = c.map(|v| lr[v as usize]);
            out.push(std::array::from_fn(|k| 0.25 * ((p[0][k] + p[1][k]) + (p[2][k] + p[3][k]))));
        }
        out
    }

    /// The curved subdivision of `lr` (m), given each LR vertex's unit normal `normals` (0 where
    /// it has none): [`Subdivision::apply`] with each edge vertex moved off the chord onto the
    /// arc its ends' normals describe, by ((n_b − n_a)·(x_b − x_a)) / 8 along their mean (a
    /// circle through both ends with those normals, to second order in the angle), and each
    /// quad centre by half the sum of its four edges' moves (one pair of opposite edges per
    /// direction of the quad: on z = κ(u² + v²)/2 each edge is off by κh²/2 and the centre by
    /// κh², on a cylinder the two edges across its axis carry it all). The LR vertices stay (it interpolates,
    /// unlike Loop or Catmull–Clark, which pull them in): the mesh's counterpart of the grid's
    /// Catmull-Rom U, the smooth surface through the LR vertices that the nets refine.
    pub fn apply_curved(&self, lr: &[[f32; 3]], normals: &[[f32; 3]]) -> Vec<[f32; 3]> {
        let mut out = self.apply(lr);
        let moves: Vec<[f32; 3]> = self
            .edges
            .iter()
            .map(|&(a, b)| {
                let (na, nb) = (normals[a as usize], normals[b as usize]);
                let (pa, pb) = (lr[a as usize], lr[b as usize]);
                let d: f32 = (0..3).map(|k| (nb[k] - na[k]) * (pb[k] - pa[k])).sum::<f32>() / 8.0;
                let m: [f32; 3] = std::array::from_fn(|k| na[k] + nb[k]);
                let len = (m[0] * m[0] + m[1] * m[1] + m[2] * m[2]).sqrt();
                if len > 1e-6 {
                    m.map(|c| d * c / len)
                } else {
                    [0.0; 3]
                }
            })
            .collect();
        let n = self.lr;
        for (k, mv) in moves.iter().enumerate() {
            (0..3).for_each(|c| out[n + k][c] += mv[c]);
        }
        let nc = n + self.edges.len();
        for (q, e) in self.centre_edges.iter().enumerate() {
            for c in 0..3 {
                out[nc + q][c] += 0.5 * e.iter().map(|&k| moves[k as usize][c]).sum::<f32>();
            }
        }
        out
    }

    /// Per HR vertex, the LR vertices it is the mean of and their weights (the prolongation
    /// matrix's rows: a vertex 1 on itself, an edge's ½ on each end, a quad's centre ¼ on each
    /// corner).
    pub fn weights(&self) -> Vec<Vec<(u32, f32)>> {
        let mut out: Vec<Vec<(u32, f32)>> = (0..self.lr as u32).map(|v| vec![(v, 1.0)]).collect();
        out.extend(self.edges.iter().map(|&(a, b)| vec![(a, 0.5), (b, 0.5)]));
        out.extend(self.centres.iter().map(|c| c.iter().map(|&v| (v, 0.25)).collect()));
        out
    }

    /// The smooth subdivision of the LR positions `lr` on `faces` (the faces this was made
    /// from), in the same numbering as [`Subdivision::apply`]: Loop's rules on a mesh of
    /// triangles, Catmull–Clark's on a mesh of quads (both with their border rules: a border
    /// edge's vertex is its midpoint, a border vertex ¾ itself + ⅛ each border neighbour), the
    /// baseline a smooth-surface method is measured against. `None` for a mesh that mixes
    /// triangles and quads (neither scheme has this topology there).
    pub fn apply_smooth(&self, faces: &[Vec<u32>], lr: &[[f32; 3]]) -> Option<Vec<[f32; 3]>> {
        let tris = faces.iter().all(|f| f.len() == 3);
        if !tris && !faces.iter().all(|f| f.len() == 4) {
            return None;
        }
        let n = self.lr;
        let mut out = self.apply(lr);
        // Per edge: the faces on it; per vertex: its edges.
        let mut edge_faces: HashMap<(u32, u32), Vec<usize>> = HashMap::new();
        for (fi, f) in faces.iter().enumerate() {
            for i in 0..f.len() {
                edge_faces.entry(edge_key(f[i], f[(i + 1) % f.len()])).or_default().push(fi);
            }
        }
        let centroid = |f: &Vec<u32>| -> [f32; 3] {
            std::array::from_fn(|k| f.iter().map(|&v| lr[v as usize][k]).sum::<f32>() / f.len() as f32)
        };
        let mut nb: Vec<Vec<u32>> = vec![Vec::new(); n];
        let mut border_nb: Vec<Vec<u32>> = vec![Vec::new(); n];
        let mut faces_of: Vec<Vec<usize>> = vec![Vec::new(); n];
        for (fi, f) in faces.iter().enumerate() {
            for &v in f {
                faces_of[v as usize].push(fi);
            }
        }
        for (k, &(a, b)) in self.edges.iter().enumerate() {
            let fs = &edge_faces[&(a, b)];
            nb[a as usize].push(b);
            nb[b as usize].push(a);
            if fs.len() == 1 {
                border_nb[a as usize].push(b);
                border_nb[b as usize].push(a);
                continue; // the midpoint
            }
            let (pa, pb) = (lr[a as usize], lr[b as usize]);
            out[n + k] = if tris {
                // 3/8 the ends + 1/8 the two opposite vertices.
                let opp = |f: &Vec<u32>| f.iter().copied().find(|&v| v != a && v != b).unwrap_or(a);
                let (c, d) = (lr[opp(&faces[fs[0]]) as usize], lr[opp(&faces[fs[1]]) as usize]);
                std::array::from_fn(|i| 0.375 * (pa[i] + pb[i]) + 0.125 * (c[i] + d[i]))
            } else {
                let (f1, f2) = (centroid(&faces[fs[0]]), centroid(&faces[fs[1]]));
                std::array::from_fn(|i| 0.25 * (pa[i] + pb[i] + f1[i] + f2[i]))
            };
        }
        for v in 0..n {
            let p = lr[v];
            let ring = &nb[v];
            if ring.is_empty() {
                continue;
            }
            out[v] = if !border_nb[v].is_empty() {
                if border_nb[v].len() != 2 {
                    p // where two borders touch: kept
                } else {
                    let (b1, b2) = (lr[border_nb[v][0] as usize], lr[border_nb[v][1] as usize]);
                    std::array::from_fn(|i| 0.75 * p[i] + 0.125 * (b1[i] + b2[i]))
                }
            } else if tris {
                let k = ring.len() as f32;
                let beta = if ring.len() == 3 { 3.0 / 16.0 } else { 3.0 / (8.0 * k) };
                std::array::from_fn(|i| {
                    (1.0 - k * beta) * p[i] + beta * ring.iter().map(|&u| lr[u as usize][i]).sum::<f32>()
                })
            } else {
                // (Q + 2R + (n − 3)S) / n: Q the mean face point, R the mean edge midpoint.
                let k = ring.len() as f32;
                let q: [f32; 3] = std::array::from_fn(|i| {
                    faces_of[v].iter().map(|&f| centroid(&faces[f])[i]).sum::<f32>()
                        / faces_of[v].len() as f32
                });
                let r: [f32; 3] = std::array::from_fn(|i| {
                    ring.iter().map(|&u| 0.5 * (p[i] + lr[u as usize][i])).sum::<f32>() / k
                });
                std::array::from_fn(|i| (q[i] + 2.0 * r[i] + (k - 3.0) * p[i]) / k)
            };
        }
        Some(out)
    }

    /// Per HR vertex, the LR face corners it is made from: `(face, corners)` for each face that
    /// holds it — a corner `[k]`, an edge `[k, k+1]`, a centre `[0, 1, 2, 3]` — so anything known
    /// per face corner (chart coordinates) carries over to it.
    pub fn sources(&self, faces: &[Vec<u32>]) -> Vec<Vec<(u32, Vec<u8>)>> {
        let mut out: Vec<Vec<(u32, Vec<u8>)>> = vec![Vec::new(); self.hr_vertices()];
        for (fi, f) in faces.iter().enumerate() {
            let hr = &self.faces[4 * fi..4 * fi + 4];
            let n = f.len();
            for k in 0..n {
                out[f[k] as usize].push((fi as u32, vec![k as u8]));
            }
            // The edge vertices sit in the HR faces at known places (see `of`).
            let mids: Vec<u32> = if n == 3 {
                vec![hr[0][1], hr[1][2], hr[2][0]]
            } else {
                vec![hr[0][1], hr[1][2], hr[2][3], hr[3][0]]
            };
            for k in 0..n {
                out[mids[k] as usize].push((fi as u32, vec![k as u8, ((k + 1) % n) as u8]));
            }
            if n == 4 {
                out[hr[0][2] as usize].push((fi as u32, vec![0, 1, 2, 3]));
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn p() -> &'static Path {
        Path::new("m.obj")
    }

    #[test]
    fn a_mixed_mesh_subdivides_each_face_into_four_with_shared_midpoints() {
        // A quad and a triangle sharing edge 1–2.
        let faces = vec![vec![0, 1, 2, 3], vec![1, 4, 2]];
        let s = Subdivision::of(5, &faces);
        // 5 LR + 6 edges + 1 centre.
        assert_eq!(s.hr_vertices(), 12);
        assert_eq!(s.faces.len(), 8);
        let pos: Vec<[f32; 3]> = vec![[0., 0., 0.], [1., 0., 0.], [1., 1., 0.], [0., 1., 0.], [2., 0.5, 0.]];
        let hr = s.apply(&pos);
        assert_eq!(hr[..5], pos[..]);
        // The shared edge 1–2 has one midpoint, used by both faces' children.
        let m12 = hr.iter().position(|q| *q == [1.0, 0.5, 0.0]).unwrap() as u32;
        assert!(
            s.faces[..4].iter().any(|f| f.contains(&m12)) && s.faces[4..].iter().any(|f| f.contains(&m12))
        );
        assert_eq!(hr[11], [0.5, 0.5, 0.0], "the quad's centre");
        // Every HR vertex is used, and the sources say where each came from.
        let src = s.sources(&faces);
        assert!(src.iter().all(|v| !v.is_empty()));
        assert_eq!(src[m12 as usize].len(), 2);
        assert_eq!(src[11], vec![(0, vec![0, 1, 2, 3])]);
        for (v, from) in src.iter().enumerate() {
            for (f, corners) in from {
                let f = &faces[*f as usize];
                let mean: [f32; 3] = std::array::from_fn(|k| {
                    corners.iter().map(|&c| pos[f[c as usize] as usize][k]).sum::<f32>()
                        / corners.len() as f32
                });
                assert_eq!(mean, hr[v]);
            }
        }
    }

    #[test]
    fn subdivision_keeps_each_face_winding() {
        let faces = vec![vec![0, 1, 2], vec![0, 2, 3, 4]];
        let pos: Vec<[f32; 3]> = vec![[0., 0., 0.], [1., 0., 0.], [1., 1., 0.], [0., 2., 0.], [-1., 1., 0.]];
        let s = Subdivision::of(5, &faces);
        let hr = s.apply(&pos);
        let area_z = |f: &[u32]| -> f32 {
            let n = f.len();
            (0..n)
                .map(|i| {
                    let (a, b) = (hr[f[i] as usize], hr[f[(i + 1) % n] as usize]);
                    a[0] * b[1] - a[1] * b[0]
                })
                .sum()
        };
        for (k, f) in s.faces.iter().enumerate() {
            assert!(area_z(f) > 0.0, "HR face {k} {f:?} turned over");
        }
    }

    #[test]
    fn smooth_subdivision_keeps_a_plane_and_rounds_a_bent_strip() {
        // A flat 4×4 grid of quads and the same grid in triangles: every smooth vertex stays
        // on the plane, interior ones where the linear subdivision puts them (both schemes
        // reproduce linear functions on a regular grid).
        let (w, h) = (5u32, 5u32);
        let pos: Vec<[f32; 3]> =
            (0..h).flat_map(|j| (0..w).map(move |i| [i as f32, j as f32, 0.0])).collect();
        let v = |i: u32, j: u32| j * w + i;
        let quads: Vec<Vec<u32>> = (0..h - 1)
            .flat_map(|j| (0..w - 1).map(move |i| vec![v(i, j), v(i + 1, j), v(i + 1, j + 1), v(i, j + 1)]))
            .collect();
        let tris: Vec<Vec<u32>> =
            quads.iter().flat_map(|q| [vec![q[0], q[1], q[2]], vec![q[0], q[2], q[3]]]).collect();
        for faces in [&quads, &tris] {
            let s = Subdivision::of(pos.len(), faces);
            let smooth = s.apply_smooth(faces, &pos).unwrap();
            let lin = s.apply(&pos);
            assert!(smooth.iter().all(|p| p[2] == 0.0));
            // An interior vertex of the grid stays put.
            assert_eq!(smooth[v(2, 2) as usize], lin[v(2, 2) as usize]);
        }
        // A strip bent into a roof: the smooth surface is lower at the ridge than the linear one.
        let roof: Vec<[f32; 3]> = pos.iter().map(|p| [p[0], p[1], 2.0 - (p[0] - 2.0).abs()]).collect();
        let s = Subdivision::of(roof.len(), &quads);
        let smooth = s.apply_smooth(&quads, &roof).unwrap();
        assert!(smooth[v(2, 2) as usize][2] < 2.0);
        let mixed = vec![vec![0, 1, 6], vec![1, 2, 7, 6]];
        assert!(Subdivision::of(25, &mixed).apply_smooth(&mixed, &pos).is_none());
    }

    #[test]
    fn the_curved_subdivision_keeps_the_lr_vertices_and_puts_midpoints_on_the_cylinder() {
        // A tube of 12 × 3 quads on a cylinder of radius 1: its LR vertices stay, its edge
        // midpoints and quad centres come within a tenth of the chord's distance to the
        // cylinder; on a plane it is the linear subdivision.
        let (around, rows) = (12u32, 3u32);
        let pos: Vec<[f32; 3]> = (0..rows)
            .flat_map(|j| {
                (0..around).map(move |i| {
                    let t = std::f32::consts::TAU * i as f32 / around as f32;
                    [t.cos(), 0.3 * j as f32, t.sin()]
                })
            })
            .collect();
        let normals: Vec<[f32; 3]> = pos.iter().map(|p| [p[0], 0.0, p[2]]).collect();
        let v = |i: u32, j: u32| j * around + i % around;
        let quads: Vec<Vec<u32>> = (0..rows - 1)
            .flat_map(|j| (0..around).map(move |i| vec![v(i, j), v(i + 1, j), v(i + 1, j + 1), v(i, j + 1)]))
            .collect();
        let s = Subdivision::of(pos.len(), &quads);
        let (lin, curved) = (s.apply(&pos), s.apply_curved(&pos, &normals));
        assert_eq!(&curved[..pos.len()], &pos[..]);
        let off = |p: &[f32; 3]| ((p[0] * p[0] + p[2] * p[2]).sqrt() - 1.0).abs();
        let mut cut = 0;
        for (c, l) in curved.iter().zip(&lin).skip(pos.len()) {
            // Edges along the axis lie on the cylinder: their midpoints stay there.
            cut += (off(l) > 0.03) as usize;
            assert!(off(c) <= 0.1 * off(l) + 1e-6, "curved {} against linear {}", off(c), off(l));
        }
        assert_eq!(cut, 3 * 12 + 2 * 12, "edges around and quad centres cut through the cylinder");
        let flat: Vec<[f32; 3]> = pos.iter().map(|p| [p[0], p[1], 0.0]).collect();
        assert_eq!(s.apply_curved(&flat, &vec![[0.0, 0.0, 1.0]; flat.len()]), s.apply(&flat));
    }

    #[test]
    fn meshes_that_are_not_cloth_surfaces_are_refused_naming_the_faces() {
        let err = |faces: Vec<Vec<u32>>| Surface::new(6, faces, p()).unwrap_err().to_string();
        assert!(err(vec![vec![0, 1, 2], vec![0, 2, 1]]).contains("faces 1 and 2 have the same vertices"));
        let e = err(vec![vec![0, 1, 2], vec![1, 0, 3], vec![0, 1, 4]]);
        assert!(e.contains("edge 1–2 is shared by 3 faces (1, 2, 3"), "{e}");
        assert!(err(vec![vec![0, 1, 1]]).contains("face 1 uses vertex 2 twice"));
        assert!(err(vec![vec![0, 1, 2, 3, 4]]).contains("face 1 has 5 vertices"));
        assert!(err(vec![vec![0, 1, 7]]).contains("uses vertex 8 of 6"));
        assert!(err(vec![]).contains("no faces"));
        let s = Surface::new(6, vec![vec![0, 1, 2], vec![2, 1, 3]], p()).unwrap();
        assert!(s.check_same(6, &s.faces.clone(), 3, p()).is_ok());
        let e = s.check_same(6, &[vec![0, 1, 2], vec![2, 1, 4]], 3, p()).unwrap_err().to_string();
        assert!(e.contains("frame 3") && e.contains("face 2 is [3, 2, 5]"), "{e}");
        assert!(s.check_same(7, &s.faces.clone(), 1, p()).is_err());
    }
}
