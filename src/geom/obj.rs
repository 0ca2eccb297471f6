//! Wavefront OBJ for grid meshes: write a [`GridMesh`] as quads or triangles, and read a
//! regular grid exported by any tool (any vertex order, quads or triangulated quads),
//! recovering its `W × H` structure from connectivity alone.
//!
//! Orientation of a recovered grid is deterministic and follows the file's vertex numbering:
//! vertex (0, 0) is the grid corner with the smallest index, and the row runs from it toward
//! its lower-numbered neighbour. A file written by [`write_obj_grid`] therefore reads back as
//! exactly the same grid, and every frame of a sequence with the same faces gets the same
//! orientation.
//!
//! Triangulated input: each triangle's quad diagonal is taken to be the edge opposite its
//! largest angle (≈ 90° in a grid cell, so this holds for any mildly sheared cloth); both
//! triangles of a cell must agree, otherwise the file is rejected with a message that asks
//! for quads.

use super::mesh::{vertex_normals, GridMesh};
pub use super::obj_sequence::{list_obj_files, natural_cmp, read_obj_sequence, ObjSequence, CLEARLY_BETTER};
use super::vec3::{cross, dot, norm};
use crate::error::{Error, Result};
use std::collections::HashMap;
use std::path::Path;

/// Whether a mesh file had quads or triangles (an upscaled result is written the same way).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FaceStyle {
    Quads,
    Triangles,
}

/// Vertices and faces of an OBJ file (0-based indices); faces have 3 or 4 vertices.
#[derive(Clone, Debug, PartialEq, Default)]
pub struct ObjMesh {
    pub pos: Vec<[f32; 3]>,
    pub faces: Vec<Vec<u32>>,
    /// Texture coordinates (`vt u v`), and per face the `vt` index of each corner (an empty
    /// list for a face written without them).
    pub uv: Vec<[f32; 2]>,
    pub face_uv: Vec<Vec<u32>>,
    /// Everything else an upscaled copy should keep.
    pub attrs: ObjAttrs,
    /// The `g`, `usemtl` and `s` lines (and `o` lines after the first face) as written, each
    /// with the number of faces before it: a mesh of several materials, groups or objects
    /// keeps them face by face when it is written subdivided ([`mesh_obj_text`]).
    pub tags: Vec<(usize, String)>,
}

/// What an OBJ carries besides geometry, kept so that an upscaled frame is written the way it
/// came in: a textured cloth comes back textured, and diffs against the input stay small.
#[derive(Clone, Debug, PartialEq, Default)]
pub struct ObjAttrs {
    /// Arguments of the `mtllib` lines, in order (the `.mtl` files themselves are untouched).
    pub mtllib: Vec<String>,
    /// `o NAME` (the object's name in Blender, Maya, …).
    pub object: Option<String>,
    /// The first `g NAME` before the faces.
    pub group: Option<String>,
    /// The first `usemtl NAME` (one material per cloth: a grid is one piece of fabric).
    pub material: Option<String>,
    /// The smoothing-group line's argument (`s 1`, `s off`).
    pub smooth: Option<String>,
    /// The file had `vn` normals: the output gets normals too (recomputed on the HR grid).
    pub normals: bool,
    /// Set when the file is read as a grid ([`obj_to_grid`]): its faces wind opposite to
    /// [`GridMesh::quads`], so faces are written reversed and normals point the file's way.
    pub flipped: bool,
}

/// The text of an OBJ file; a byte that is not UTF-8 (a Latin-1 name) is refused with its line
/// number.
pub fn read_obj_text(path: &Path) -> Result<String> {
    obj_text_from_bytes(&crate::io::read_bytes(path)?, path)
}

/// [`read_obj_text`] on bytes already read (`path` names the file in errors).
pub fn obj_text_from_bytes(bytes: &[u8], path: &Path) -> Result<String> {
    let text = std::str::from_utf8(bytes).map_err(|e| {
        let at = e.valid_up_to();
        let line = 1 + bytes[..at].iter().filter(|&&b| b == b'\n').count();
        Error::format(
            path,
            format!(
                "line {line}: byte 0x{:02X} is not UTF-8 (a name or comment in Latin-1?); save the \
                 file as UTF-8",
                bytes[at]
            ),
        )
    })?;
    Ok(text.to_string())
}

/// Parse OBJ text (`path` only names the file in errors), as exporters write it: a byte-order
/// mark is skipped, and CR alone (old Mac) ends a line as LF and CR LF do.
pub fn parse_obj(text: &str, path: &Path) -> Result<ObjMesh> {
    let text = text.strip_prefix('\u{FEFF}').unwrap_or(text);
    let lf;
    let text = if text.contains('\r') {
        lf = text.replace("\r\n", "\n").replace('\r', "\n");
        lf.as_str()
    } else {
        text
    };
    let mut pos = Vec::new();
    let mut uv: Vec<[f32; 2]> = Vec::new();
    let mut attrs = ObjAttrs::default();
    // (line, corner vt indices, vt read before the face).
    let mut raw_face_uv: Vec<(usize, Vec<i64>, i64)> = Vec::new();
    let rest = |line: &str, key: &str| line[key.len()..].trim().to_string();
    // (line, vertex indices, vertices read before the face: what a negative index counts
    // back from).
    let mut raw_faces: Vec<(usize, Vec<i64>, i64)> = Vec::new();
    let mut tags = Vec::new();
    for (ln, line) in text.lines().enumerate() {
        let ln = ln + 1;
        let line = line.split('#').next().unwrap_or("").trim();
        let mut it = line.split_whitespace();
        let key = it.clone().next();
        if matches!(key, Some("g" | "usemtl" | "s")) || (key == Some("o") && !raw_faces.is_empty()) {
            tags.push((raw_faces.len(), line.to_string()));
        }
        match it.next() {
            Some("v") => {
                let c: Vec<&str> = it.collect();
                if c.len() < 3 {
                    return Err(Error::format(path, format!("line {ln}: vertex needs 3 coordinates")));
                }
                let mut p = [0.0f32; 3];
                for k in 0..3 {
                    p[k] = c[k]
                        .parse::<f32>()
                        .map_err(|_| Error::format(path, format!("line {ln}: bad coordinate '{}'", c[k])))?;
                    if !p[k].is_finite() {
                        return Err(Error::format(
                            path,
                            format!("line {ln}: non-finite coordinate '{}'", c[k]),
                        ));
                    }
                }
                pos.push(p);
            }
            Some("vt") => {
                let c: Vec<&str> = it.collect();
                if c.len() < 2 {
                    return Err(Error::format(path, format!("line {ln}: texture coordinate needs u and v")));
                }
                let mut t = [0.0f32; 2];
                for k in 0..2 {
                    t[k] = c[k].parse::<f32>().ok().filter(|v| v.is_finite()).ok_or_else(|| {
                        Error::format(path, format!("line {ln}: bad texture coordinate '{}'", c[k]))
                    })?;
                }
                uv.push(t);
            }
            Some("vn") => attrs.normals = true,
            Some("mtllib") => attrs.mtllib.push(rest(line, "mtllib")),
            Some("o") => attrs.object = attrs.object.take().or(Some(rest(line, "o"))),
            Some("g") if raw_faces.is_empty() => attrs.group = attrs.group.take().or(Some(rest(line, "g"))),
            Some("usemtl") => attrs.material = attrs.material.take().or(Some(rest(line, "usemtl"))),
            Some("s") => attrs.smooth = attrs.smooth.take().or(Some(rest(line, "s"))),
            Some("f") => {
                let mut f = Vec::new();
                let mut t = Vec::new();
                for tok in it {
                    let mut parts = tok.split('/');
                    let bad = || Error::format(path, format!("line {ln}: bad face index '{tok}'"));
                    let i: i64 = parts.next().unwrap_or("").parse().map_err(|_| bad())?;
                    f.push(i);
                    match parts.next() {
                        Some(vt) if !vt.is_empty() => t.push(vt.parse::<i64>().map_err(|_| bad())?),
                        _ => {}
                    }
                }
                raw_faces.push((ln, f, pos.len() as i64));
                raw_face_uv.push((ln, t, uv.len() as i64));
            }
            _ => {}
        }
    }
    let faces = resolve_indices(raw_faces, pos.len() as i64, ("vertex", "vertices"), path)?;
    let mut face_uv =
        resolve_indices(raw_face_uv, uv.len() as i64, ("texture coordinate", "texture coordinates"), path)?;
    // Corner UVs count only when every corner of the face has one.
    for (t, f) in face_uv.iter_mut().zip(&faces) {
        if t.len() != f.len() {
            t.clear();
        }
    }
    Ok(ObjMesh { pos, faces, uv, face_uv, attrs, tags })
}

/// 1-based (or negative, relative) OBJ indices → 0-based, checked against `n` entries.
fn resolve_indices(
    raw: Vec<(usize, Vec<i64>, i64)>,
    n: i64,
    (what, plural): (&str, &str),
    path: &Path,
) -> Result<Vec<Vec<u32>>> {
    raw.into_iter()
        .map(|(ln, f, seen)| {
            f.into_iter()
                .map(|i| {
                    // OBJ indices are 1-based; negative (relative) ones count back from the
                    // last entry read before this face line (-1 = the one just above it).
                    let k = if i > 0 { i - 1 } else { seen + i };
                    if i == 0 || k < 0 || k >= n {
                        return Err(Error::format(
                            path,
                            format!("line {ln}: face references {what} {i}, but the file has {n} {plural}"),
                        ));
                    }
                    Ok(k as u32)
                })
                .collect()
        })
        .collect()
}

fn not_grid(path: &Path, why: impl std::fmt::Display) -> Error {
    Error::format(path, format!("not a regular grid mesh: {why}"))
}

fn ekey(a: u32, b: u32) -> (u32, u32) {
    (a.min(b), a.max(b))
}

/// Pair triangles into quads (vertex cycles), the diagonal of each cell being the edge
/// opposite the larger angle of both its triangles.
fn pair_triangles(m: &ObjMesh, path: &Path) -> Result<Vec<[u32; 4]>> {
    let mut edge_tris: HashMap<(u32, u32), Vec<usize>> = HashMap::new();
    for (t, f) in m.faces.iter().enumerate() {
        for k in 0..3 {
            edge_tris.entry(ekey(f[k], f[(k + 1) % 3])).or_default().push(t);
        }
    }
    let angle = |a: u32, b: u32, c: u32| -> f64 {
        // Angle at a between b and c.
        let (pa, pb, pc) = (m.pos[a as usize], m.pos[b as usize], m.pos[c as usize]);
        let u: [f64; 3] = std::array::from_fn(|k| (pb[k] - pa[k]) as f64);
        let v: [f64; 3] = std::array::from_fn(|k| (pc[k] - pa[k]) as f64);
        norm(cross(u, v)).atan2(dot(u, v))
    };
    // For each triangle, the edge (as index k: edge f[k]–f[k+1]) it proposes as the diagonal.
    let mut choice = Vec::with_capacity(m.faces.len());
    for (t, f) in m.faces.iter().enumerate() {
        let mut best: Option<(f64, usize)> = None;
        for k in 0..3 {
            let (a, b, c) = (f[k], f[(k + 1) % 3], f[(k + 2) % 3]);
            let shared = edge_tris[&ekey(a, b)].len();
            if shared > 2 {
                return Err(not_grid(path, format!("edge {}–{} is shared by {shared} faces", a + 1, b + 1)));
            }
            if shared < 2 {
                continue; // a border edge is never a cell diagonal
            }
            let ang = angle(c, a, b);
            if best.is_none_or(|(bang, _)| ang > bang) {
                best = Some((ang, k));
            }
        }
        let Some((_, k)) = best else {
            return Err(not_grid(path, format!("triangle {} has no interior edge", t + 1)));
        };
        choice.push(k);
    }
    let mut quads = Vec::with_capacity(m.faces.len() / 2);
    for (t, f) in m.faces.iter().enumerate() {
        let k = choice[t];
        let (a, b, c) = (f[k], f[(k + 1) % 3], f[(k + 2) % 3]);
        let other = edge_tris[&ekey(a, b)].iter().copied().find(|&o| o != t).unwrap_or(t);
        let g = &m.faces[other];
        let ok = ekey(g[choice[other]], g[(choice[other] + 1) % 3]) == ekey(a, b);
        if !ok {
            return Err(not_grid(
                path,
                "could not pair the triangles into grid cells (diagonals are ambiguous); export quads instead",
            ));
        }
        if t < other {
            let d = g.iter().copied().find(|&v| v != a && v != b).unwrap_or(a);
            quads.push([a, d, b, c]);
        }
    }
    Ok(quads)
}

/// Recover the grid of a quad mesh: `grid[j*w + i]` = file vertex at (i, j), and whether the
/// file's faces wind opposite to [`GridMesh::quads`].
fn recover_grid(nv: usize, quads: &[[u32; 4]], path: &Path) -> Result<(usize, usize, Vec<u32>, bool)> {
    let mut edge_faces: HashMap<(u32, u32), Vec<usize>> = HashMap::new();
    let mut faces_of = vec![0u32; nv];
    for (q, f) in quads.iter().enumerate() {
        for k in 0..4 {
            if f[k] == f[(k + 1) % 4] || f[k] == f[(k + 2) % 4] {
                return Err(not_grid(path, format!("face {} repeats a vertex", q + 1)));
            }
            edge_faces.entry(ekey(f[k], f[(k + 1) % 4])).or_default().push(q);
            faces_of[f[k] as usize] += 1;
        }
    }
    if let Some(v) = faces_of.iter().position(|&c| c == 0) {
        return Err(not_grid(path, format!("vertex {} is not used by any face", v + 1)));
    }
    if let Some((e, fs)) = edge_faces.iter().find(|(_, fs)| fs.len() > 2) {
        return Err(not_grid(path, format!("edge {}–{} is shared by {} faces", e.0 + 1, e.1 + 1, fs.len())));
    }
    let corners: Vec<u32> = (0..nv as u32).filter(|&v| faces_of[v as usize] == 1).collect();
    if corners.len() != 4 {
        return Err(not_grid(
            path,
            format!("found {} corner vertices (in exactly one face), expected 4", corners.len()),
        ));
    }
    let c0 = corners[0];
    let q0 = quads.iter().find(|f| f.contains(&c0)).expect("corner has a face");
    let p = q0.iter().position(|&v| v == c0).unwrap_or(0);
    let (na, nb) = (q0[(p + 1) % 4], q0[(p + 3) % 4]);
    let (right, down) = if na < nb { (na, nb) } else { (nb, na) };
    let is_border = |a: u32, b: u32| edge_faces.get(&ekey(a, b)).is_some_and(|f| f.len() == 1);
    // Border neighbours of each vertex.
    let mut border_nb: Vec<Vec<u32>> = vec![Vec::new(); nv];
    for (&(a, b), fs) in &edge_faces {
        if fs.len() == 1 {
            border_nb[a as usize].push(b);
            border_nb[b as usize].push(a);
        }
    }
    let walk = |first: u32| -> Result<Vec<u32>> {
        let mut line = vec![c0, first];
        if !is_border(c0, first) {
            return Err(not_grid(path, "the border around a corner is not made of single-face edges"));
        }
        while faces_of[*line.last().unwrap() as usize] != 1 {
            let cur = *line.last().unwrap();
            let prev = line[line.len() - 2];
            let nexts: Vec<u32> = border_nb[cur as usize].iter().copied().filter(|&v| v != prev).collect();
            if nexts.len() != 1 || line.len() > nv {
                return Err(not_grid(path, format!("the border is not a simple loop at vertex {}", cur + 1)));
            }
            line.push(nexts[0]);
        }
        Ok(line)
    };
    let row0 = walk(right)?;
    let col0 = walk(down)?;
    let (w, h) = (row0.len(), col0.len());
    if w * h != nv || (w - 1) * (h - 1) != quads.len() {
        return Err(not_grid(
            path,
            format!(
                "the border says {w}x{h} vertices, but the mesh has {nv} vertices and {} cells",
                quads.len()
            ),
        ));
    }
    const NONE: u32 = u32::MAX;
    let mut g = vec![NONE; nv];
    g[..w].copy_from_slice(&row0);
    for j in 0..h {
        g[j * w] = col0[j];
    }
    let mut used_face = vec![false; quads.len()];
    let mut flipped = false;
    for j in 0..h - 1 {
        for i in 0..w - 1 {
            let (a, b, d) = (g[j * w + i], g[j * w + i + 1], g[(j + 1) * w + i]);
            let fs = edge_faces.get(&ekey(a, b)).map(|v| v.as_slice()).unwrap_or(&[]);
            let found = fs.iter().copied().find(|&q| !used_face[q] && quads[q].contains(&d));
            let Some(q) = found else {
                return Err(not_grid(
                    path,
                    format!("no cell at ({i}, {j}) next to vertices {} and {}", a + 1, b + 1),
                ));
            };
            used_face[q] = true;
            let f = quads[q];
            let c = f.iter().copied().find(|&v| v != a && v != b && v != d).unwrap_or(NONE);
            // The cell's cycle must be a–b–c–d (either direction).
            let pa = f.iter().position(|&v| v == a).unwrap_or(0);
            let cyc_ok = (f[(pa + 1) % 4] == b && f[(pa + 2) % 4] == c && f[(pa + 3) % 4] == d)
                || (f[(pa + 3) % 4] == b && f[(pa + 2) % 4] == c && f[(pa + 1) % 4] == d);
            if i == 0 && j == 0 {
                // GridMesh::quads winds (0,0) → (0,1) → (1,1) → (1,0).
                flipped = f[(pa + 1) % 4] == b;
            }
            let slot = &mut g[(j + 1) * w + i + 1];
            if !cyc_ok || (*slot != NONE && *slot != c) {
                return Err(not_grid(path, format!("cell at ({i}, {j}) does not fit a grid")));
            }
            *slot = c;
        }
    }
    let mut seen = vec![false; nv];
    for &v in &g {
        if v == NONE || std::mem::replace(&mut seen[v as usize], true) {
            return Err(not_grid(path, "a vertex appears twice in the recovered grid"));
        }
    }
    Ok((w, h, g, flipped))
}

/// A parsed OBJ turned into a grid: the mesh, the face style, and the file index of each grid
/// vertex (`order[j*w + i]`), so other frames with the same faces can reuse it.
#[derive(Clone, Debug)]
pub struct ObjGrid {
    pub mesh: GridMesh,
    pub style: FaceStyle,
    pub order: Vec<u32>,
    /// Texture coordinates per grid vertex (`uv[j*w + i]`), when the file has them for every
    /// face and each vertex has one (no UV seam inside the cloth).
    pub uv: Option<Vec<[f32; 2]>>,
    /// Why the file's UVs could not be kept, if it had some.
    pub uv_note: Option<String>,
    pub attrs: ObjAttrs,
}

/// The file's UVs per grid vertex, or why there are none (see [`ObjGrid::uv`]).
pub(crate) fn grid_uv(m: &ObjMesh, order: &[u32]) -> (Option<Vec<[f32; 2]>>, Option<String>) {
    if m.uv.is_empty() {
        return (None, None);
    }
    if let Some(f) = m.face_uv.iter().position(Vec::is_empty) {
        return (None, Some(format!("face {} has no texture coordinates; the output has no UVs", f + 1)));
    }
    let mut per_vertex: Vec<Option<[f32; 2]>> = vec![None; m.pos.len()];
    for (f, t) in m.faces.iter().zip(&m.face_uv) {
        for (&v, &t) in f.iter().zip(t) {
            let uv = m.uv[t as usize];
            match per_vertex[v as usize] {
                Some(old) if old != uv => {
                    return (
                        None,
                        Some(format!(
                            "vertex {} has two texture coordinates (a UV seam inside the cloth); the output has no UVs",
                            v + 1
                        )),
                    )
                }
                _ => per_vertex[v as usize] = Some(uv),
            }
        }
    }
    // Every grid vertex is in a face (checked by the grid recovery), so each has a UV.
    (Some(order.iter().map(|&v| per_vertex[v as usize].unwrap_or([0.0; 2])).collect()), None)
}

/// Turn parsed OBJ data into a grid (see the module docs).
pub fn obj_to_grid(m: &ObjMesh, path: &Path) -> Result<ObjGrid> {
    if m.faces.is_empty() {
        return Err(not_grid(path, "the file has no faces"));
    }
    let n3 = m.faces.iter().filter(|f| f.len() == 3).count();
    let n4 = m.faces.iter().filter(|f| f.len() == 4).count();
    if n3 + n4 != m.faces.len() {
        let bad = m.faces.iter().position(|f| f.len() != 3 && f.len() != 4).unwrap_or(0);
        return Err(not_grid(
            path,
            format!("face {} has {} vertices (need 3 or 4)", bad + 1, m.faces[bad].len()),
        ));
    }
    if n3 > 0 && n4 > 0 {
        return Err(not_grid(path, format!("it mixes {n4} quads and {n3} triangles")));
    }
    let (quads, style) = if n4 > 0 {
        (m.faces.iter().map(|f| [f[0], f[1], f[2], f[3]]).collect(), FaceStyle::Quads)
    } else {
        if n3 % 2 != 0 {
            return Err(not_grid(path, format!("{n3} triangles cannot pair into grid cells")));
        }
        (pair_triangles(m, path)?, FaceStyle::Triangles)
    };
    let (w, h, order, flipped) = recover_grid(m.pos.len(), &quads, path)?;
    let pos = order.iter().map(|&v| m.pos[v as usize]).collect();
    let (uv, uv_note) = grid_uv(m, &order);
    let attrs = ObjAttrs { flipped, ..m.attrs.clone() };
    Ok(ObjGrid { mesh: GridMesh::new(w, h, pos), style, order, uv, uv_note, attrs })
}

/// Read an OBJ grid and its face style.
pub fn read_obj_grid_styled(path: &Path) -> Result<ObjGrid> {
    obj_to_grid(&parse_obj(&read_obj_text(path)?, path)?, path)
}

/// Read an OBJ grid (any vertex order, quads or triangulated quads).
pub fn read_obj_grid(path: &Path) -> Result<GridMesh> {
    Ok(read_obj_grid_styled(path)?.mesh)
}

/// OBJ text of a grid, quads or (with `quads = false`) the triangles of [`GridMesh::triangles`].
pub fn obj_text(mesh: &GridMesh, quads: bool) -> String {
    obj_text_with(mesh, quads, None, &ObjAttrs::default())
}

/// OBJ text of a grid with texture coordinates per grid vertex (`uv`, `w·h` of them) and what
/// `attrs` says the input had: `mtllib`, `o`, normals (computed from `mesh`, one per vertex),
/// `g`, `usemtl`, `s`, in the order Blender writes them. Positions and UVs print as the
/// shortest decimal that reads back to the same f32, normals with 4 decimals (Blender's own
/// precision), so two runs write identical files.
pub fn obj_text_with(mesh: &GridMesh, quads: bool, uv: Option<&[[f32; 2]]>, attrs: &ObjAttrs) -> String {
    use std::fmt::Write;
    let mut s = String::with_capacity(mesh.pos.len() * if uv.is_some() { 90 } else { 40 });
    let _ = writeln!(s, "# anisocb grid {} x {} vertices (columns x rows), metres", mesh.w, mesh.h);
    for m in &attrs.mtllib {
        let _ = writeln!(s, "mtllib {m}");
    }
    if let Some(o) = &attrs.object {
        let _ = writeln!(s, "o {o}");
    }
    for p in &mesh.pos {
        let _ = writeln!(s, "v {} {} {}", p[0], p[1], p[2]);
    }
    if let Some(uv) = uv {
        for t in uv {
            let _ = writeln!(s, "vt {} {}", t[0], t[1]);
        }
    }
    if attrs.normals {
        let sign = if attrs.flipped { -1.0 } else { 1.0 };
        for n in vertex_normals(mesh) {
            // `+ 0.0` turns -0.0 into 0.0 so a flat cloth prints `0.0000`, as Blender does.
            let _ =
                writeln!(s, "vn {:.4} {:.4} {:.4}", sign * n[0] + 0.0, sign * n[1] + 0.0, sign * n[2] + 0.0);
        }
    }
    if let Some(g) = &attrs.group {
        let _ = writeln!(s, "g {g}");
    }
    if let Some(m) = &attrs.material {
        let _ = writeln!(s, "usemtl {m}");
    }
    if let Some(sm) = &attrs.smooth {
        let _ = writeln!(s, "s {sm}");
    }
    // One index per vertex for v, vt and vn alike: `i`, `i/i`, `i//i` or `i/i/i`.
    let corner = |s: &mut String, v: usize| {
        let i = v + 1;
        let _ = match (uv.is_some(), attrs.normals) {
            (false, false) => write!(s, " {i}"),
            (true, false) => write!(s, " {i}/{i}"),
            (false, true) => write!(s, " {i}//{i}"),
            (true, true) => write!(s, " {i}/{i}/{i}"),
        };
    };
    let faces: Vec<Vec<usize>> = if quads {
        mesh.quads().iter().map(|q| q.to_vec()).collect()
    } else {
        mesh.triangles().iter().map(|t| t.to_vec()).collect()
    };
    for mut f in faces {
        if attrs.flipped {
            f.reverse();
        }
        s.push('f');
        for v in f {
            corner(&mut s, v);
        }
        s.push('\n');
    }
    s
}

/// OBJ text of any mesh (the subdivided mesh of an any-cloth upscale): positions `pos`,
/// `faces` (as in the file: written in their order and winding), texture coordinates `uv`
/// with their per-face indices, and what the input had: `mtllib`, the object name, normals
/// (area-weighted per vertex, when the input had `vn`), and its `tags` — each `(k, line)`
/// written before face `k · per_face` (an LR face's tags before its four HR faces). Numbers
/// print as in [`obj_text_with`].
pub fn mesh_obj_text(
    pos: &[[f32; 3]],
    faces: &[Vec<u32>],
    uv: Option<super::surface::FaceUvs>,
    attrs: &ObjAttrs,
    tags: &[(usize, String)],
    per_face: usize,
) -> String {
    use std::fmt::Write;
    let mut s = String::with_capacity(pos.len() * if uv.is_some() { 90 } else { 40 } + faces.len() * 24);
    let _ = writeln!(s, "# anisocb mesh {} vertices, {} faces, metres", pos.len(), faces.len());
    for m in &attrs.mtllib {
        let _ = writeln!(s, "mtllib {m}");
    }
    if let Some(o) = &attrs.object {
        let _ = writeln!(s, "o {o}");
    }
    for p in pos {
        let _ = writeln!(s, "v {} {} {}", p[0], p[1], p[2]);
    }
    if let Some((t, _)) = uv {
        for t in t {
            let _ = writeln!(s, "vt {} {}", t[0], t[1]);
        }
    }
    if attrs.normals {
        for n in mesh_normals(pos, faces) {
            let _ = writeln!(s, "vn {:.4} {:.4} {:.4}", n[0] + 0.0, n[1] + 0.0, n[2] + 0.0);
        }
    }
    let mut tag = tags.iter().peekable();
    for (k, f) in faces.iter().enumerate() {
        while let Some((_, line)) = tag.next_if(|t| t.0 * per_face <= k) {
            let _ = writeln!(s, "{line}");
        }
        s.push('f');
        let fuv = uv.map(|(_, fu)| &fu[k]).filter(|fu| fu.len() == f.len());
        for (c, &v) in f.iter().enumerate() {
            let i = v + 1;
            let _ = match (fuv.map(|fu| fu[c] + 1), attrs.normals) {
                (None, false) => write!(s, " {i}"),
                (Some(t), false) => write!(s, " {i}/{t}"),
                (None, true) => write!(s, " {i}//{i}"),
                (Some(t), true) => write!(s, " {i}/{t}/{i}"),
            };
        }
        s.push('\n');
    }
    for (_, line) in tag {
        let _ = writeln!(s, "{line}");
    }
    s
}

/// Area-weighted vertex normals of a mesh of triangles and quads (a quad by its two
/// triangles 0-1-2, 0-2-3), unit length; (0, 0, 1) for a vertex in no face or no area.
pub fn mesh_normals(pos: &[[f32; 3]], faces: &[Vec<u32>]) -> Vec<[f32; 3]> {
    let mut n = vec![[0.0f32; 3]; pos.len()];
    for f in faces {
        for t in 1..f.len() - 1 {
            let (a, b, c) = (pos[f[0] as usize], pos[f[t] as usize], pos[f[t + 1] as usize]);
            let c = cross(super::vec3::sub(b, a), super::vec3::sub(c, a));
            for &v in f {
                for k in 0..3 {
                    n[v as usize][k] += c[k];
                }
            }
        }
    }
    n.into_iter().map(|v| super::vec3::normalize_or(v, [0.0, 0.0, 1.0])).collect()
}

/// Write a grid as OBJ (atomically).
pub fn write_obj_grid(path: &Path, mesh: &GridMesh, quads: bool) -> Result<()> {
    crate::io::write_atomic_bytes(path, obj_text(mesh, quads).as_bytes())
}

/// A text file of vertex numbers (from 1; spaces, commas or new lines; `#` comments) as 0-based
/// indices, each once, in the file's order.
pub fn read_vertex_list(path: &Path) -> Result<Vec<u32>> {
    let text = read_obj_text(path)?;
    let (mut out, mut seen) = (Vec::new(), std::collections::HashSet::new());
    for (ln, line) in text.lines().enumerate() {
        let line = line.split('#').next().unwrap_or("");
        for tok in line.split(|c: char| c.is_whitespace() || c == ',').filter(|t| !t.is_empty()) {
            match tok.parse::<u32>() {
                Ok(v) if v >= 1 => {
                    if seen.insert(v) {
                        out.push(v - 1);
                    }
                }
                _ => {
                    return Err(Error::format(
                        path,
                        format!(
                            "line {}: {tok:?} is not a vertex number (they start at 1, as in the OBJ file)",
                            ln + 1
                        ),
                    ))
                }
            }
        }
    }
    if out.is_empty() {
        return Err(Error::format(path, "holds no vertex numbers: list the held vertices, numbered from 1"));
    }
    Ok(out)
}
/// The vertices (0-based, ascending) of the faces of `m` (read from `path`) in the OBJ group
/// `name`: the faces after a `g` line naming it (among its names), up to the next `g` line —
/// how Blender, Maya and Houdini export a vertex or face group to OBJ. An error names the
/// groups the file has when none is called `name`.
pub fn group_vertices(m: &ObjMesh, name: &str, path: &Path) -> Result<Vec<u32>> {
    let mut groups: Vec<&str> = Vec::new();
    let mut in_group = vec![false; m.faces.len()];
    let mut tags = m.tags.iter().peekable();
    let mut current = false;
    for (k, inside) in in_group.iter_mut().enumerate() {
        while let Some((_, line)) = tags.next_if(|t| t.0 <= k) {
            let mut words = line.split_whitespace();
            if words.next() == Some("g") {
                let names: Vec<&str> = words.collect();
                for n in &names {
                    if !groups.contains(n) {
                        groups.push(n);
                    }
                }
                current = names.contains(&name);
            }
        }
        *inside = current;
    }
    let mut held = vec![false; m.pos.len()];
    for (f, _) in m.faces.iter().zip(&in_group).filter(|(_, g)| **g) {
        f.iter().for_each(|&v| held[v as usize] = true);
    }
    let out: Vec<u32> = (0..m.pos.len() as u32).filter(|&v| held[v as usize]).collect();
    if out.is_empty() {
        let have = if groups.is_empty() { "none".to_string() } else { groups.join(", ") };
        return Err(Error::format(
            path,
            format!("has no faces in a group called {name:?} (its groups: {have}); export the pin group as an OBJ group, or list the vertices in a file"),
        ));
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn group_vertices_are_those_of_the_faces_after_the_groups_g_line() {
        // A strip of three quads: the first in `waist hem`, the second in `body`, the third
        // back in `waist`.
        let text = "v 0 0 0\nv 1 0 0\nv 2 0 0\nv 3 0 0\nv 0 1 0\nv 1 1 0\nv 2 1 0\nv 3 1 0\n\
                    g waist hem\nf 1 2 6 5\ng body\nusemtl cloth\nf 2 3 7 6\ng waist\nf 3 4 8 7\n";
        let p = Path::new("strip.obj");
        let m = parse_obj(text, p).unwrap();
        assert_eq!(group_vertices(&m, "waist", p).unwrap(), vec![0, 1, 2, 3, 4, 5, 6, 7]);
        assert_eq!(group_vertices(&m, "hem", p).unwrap(), vec![0, 1, 4, 5]);
        assert_eq!(group_vertices(&m, "body", p).unwrap(), vec![1, 2, 5, 6]);
        let e = group_vertices(&m, "collar", p).unwrap_err().to_string();
        assert!(e.contains("strip.obj") && e.contains("\"collar\"") && e.contains("waist, hem, body"), "{e}");
    }
}
