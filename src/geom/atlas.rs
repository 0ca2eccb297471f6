//! Geometry images of any mesh (issue 45, deliverable 2): each piece of the cloth is flattened
//! to the plane — the file's own UVs where they are a usable layout, else ARAP (Liu et al.
//! 2008) — scaled so one pixel is one LR edge, packed into one image with gaps, and resampled:
//! a pixel inside a chart takes the barycentric blend of its triangle's vertices, a pixel
//! outside is extrapolated from the chart so the convolutions see the cloth continued, not a
//! cliff. The image is a fixed linear function of the frame's vertices, built once per shot.
//!
//! Pixel coordinates: `[x, y]` = (column, row) of the LR image, pixel (row r, col c) centred at
//! `[c, r]` — the convention of the align-corners resampling the nets use.
//!
//! Pieces are the edge-connected parts of the mesh (two parts touching at one vertex are two
//! pieces). [`super::charts`] finds them and the UV islands and judges the UVs (a UV island is
//! used through the linear map that best matches its lengths to the rest mesh, so a layout
//! squeezed into the unit square still has one texel per LR edge); [`super::arap`] flattens a
//! piece without usable UVs. Charts are turned so a face wound as
//! [`super::mesh::GridMesh::quads`] winds the way a grid's face does in its image; the same
//! mesh gives the same layout, bit for bit (no hash order anywhere).

use super::arap;
use super::charts::{self, area3, bary, bbox, corners, orient2, orient2_of, p3, turn, Chart};
use super::layout::MAX_LR_VERTICES;
use super::vec3::{norm, sub};
use crate::error::{Error, Result};

/// Empty pixels between two charts' boxes: room for the extrapolated rings of both, so a 3×3
/// convolution near one chart's border sees that chart continued, not its neighbour.
pub const GAP: usize = 6;

/// Empty pixels between the charts and the image border.
pub const MARGIN: usize = 3;

/// Sign of [`orient2`] of a face wound as a [`super::mesh::GridMesh`] quad, in (column, row)
/// pixel axes: the grid's quad (i,j), (i,j+1), (i+1,j+1), (i+1,j) at pixels (c, r) = (i, j).
const GRID_WINDING: f64 = -1.0;

/// A pixel centre this far outside a triangle (in barycentric units) still counts as inside, so
/// a centre on a shared edge or on the chart's border is covered despite rounding; the
/// triangle it is deepest in wins.
const BARY_EPS: f64 = 1e-4;

/// Slack (pixels) when a chart's extent is rounded to whole pixels: an 11-pixel-wide chart that
/// came out 11.0000001 wide keeps 12 columns, not 13.
const SNAP: f64 = 1e-3;

/// Rings of extrapolated pixels that continue the chart's slope; beyond them each ring repeats
/// the mean of the ring inside. A curved cloth continued linearly leaves its bounding box after
/// a few texels, and the receptive field of the nets' first layers is this wide.
const LINEAR_RINGS: u32 = 8;

/// A piece whose rest area is under this many square texels is collapsed (all its vertices on
/// a point or a line): it has no layout.
const DEGENERATE_PIECE: f64 = 1e-6;

/// A fixed-topology mesh to lay out.
pub struct AtlasInput<'a> {
    /// Faces of 3 or 4 vertex indices into `rest`, manifold (an edge in at most two faces, no
    /// repeated vertex in a face, no face twice): checked by the caller.
    pub faces: &'a [Vec<u32>],
    /// The positions the layout is made from (the first frame, or a point cache's rest mesh),
    /// metres.
    pub rest: &'a [[f32; 3]],
    /// The file's UVs, if it has them: coordinates and, per face (parallel to `faces`), the
    /// coordinate index of each corner.
    #[allow(clippy::type_complexity)]
    pub uv: Option<(&'a [[f32; 2]], &'a [Vec<u32>])>,
}

/// Where the charts came from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ChartSource {
    /// The file's UV islands.
    Uv,
    /// ARAP flattening of each piece (cut to a disk where it is not one).
    Arap,
}

/// A pixel inside a chart: its row-major index, and the mesh vertices and barycentric weights
/// of the triangle its centre lies in.
#[derive(Clone, Copy, Debug)]
struct Cover {
    px: u32,
    v: [u32; 3],
    w: [f32; 3],
}

/// The layout of one topology (see the module docs).
pub struct Atlas {
    /// LR image rows and columns.
    pub h: usize,
    pub w: usize,
    /// Per face, per corner: the corner's chart position in LR pixel units (`[col, row]`).
    pub corner_px: Vec<Vec<[f32; 2]>>,
    /// Metres per pixel on the rest mesh.
    pub texel: f32,
    /// Charts in the image.
    pub charts: usize,
    pub source: ChartSource,
    /// Pixels inside a chart, row-major.
    cover: Vec<Cover>,
    /// The other pixels, in the order they are filled; `fill_start[i]..fill_start[i + 1]`
    /// index `fill_src`/`fill_coef`: pixel `fill_px[i]` = Σ coef · pixel src.
    fill_px: Vec<u32>,
    fill_start: Vec<u32>,
    fill_src: Vec<u32>,
    fill_coef: Vec<f32>,
    /// Per face, its chart.
    face_chart: Vec<u32>,
    /// Why the file's UVs were not used, when it had some.
    uv_note: Option<String>,
    /// Vertices of the rest mesh (a frame has as many).
    vertices: usize,
}

impl Atlas {
    /// Lay out `input`.
    pub fn build(input: &AtlasInput) -> Result<Atlas> {
        validate(input)?;
        let texel = mean_edge(input)?;
        let uv = input.uv.map(|uv| charts::uv_charts(input.faces, input.rest, uv, texel, GRID_WINDING));
        let (source, mut charts, uv_note) = match uv {
            Some(Ok(c)) => (ChartSource::Uv, c, None),
            Some(Err(why)) => (ChartSource::Arap, arap_charts(input, texel)?, Some(why)),
            None => (ChartSource::Arap, arap_charts(input, texel)?, None),
        };
        let (h, w) = pack(&mut charts)?;
        let mut corner_px: Vec<Vec<[f32; 2]>> = input.faces.iter().map(|f| vec![[0.0; 2]; f.len()]).collect();
        let mut face_chart = vec![0u32; input.faces.len()];
        for (ci, c) in charts.iter().enumerate() {
            for (tri, o) in c.tris.iter().zip(&c.origin) {
                face_chart[o.face as usize] = ci as u32;
                for k in 0..3 {
                    let p = c.pos[tri[k] as usize];
                    corner_px[o.face as usize][o.corner[k] as usize] = [p[0] as f32, p[1] as f32];
                }
            }
        }
        let cover = rasterize(&charts, h, w);
        let mut covered = vec![false; h * w];
        cover.iter().for_each(|c| covered[c.px as usize] = true);
        let (fill_px, fill_start, fill_src, fill_coef) = extrapolation(h, w, &covered);
        Ok(Atlas {
            h,
            w,
            corner_px,
            texel: texel as f32,
            charts: charts.len(),
            source,
            cover,
            fill_px,
            fill_start,
            fill_src,
            fill_coef,
            face_chart,
            uv_note,
            vertices: input.rest.len(),
        })
    }

    /// The (3, h, w) geometry image (planar x, y, z) of `pos` (a frame of the same topology as
    /// the rest mesh) into `out` (3·h·w floats).
    ///
    /// # Panics
    /// If `pos` has fewer vertices than the rest mesh or `out` fewer than 3·h·w floats.
    pub fn image_into(&self, pos: &[[f32; 3]], out: &mut [f32]) {
        let hw = self.h * self.w;
        assert!(pos.len() >= self.vertices, "atlas: a frame of {} vertices for {}", pos.len(), self.vertices);
        assert!(out.len() >= 3 * hw, "atlas: an image of {} floats for 3×{}×{}", out.len(), self.h, self.w);
        for (ch, plane) in out.chunks_exact_mut(hw).take(3).enumerate() {
            for c in &self.cover {
                let v = c.v.map(|v| pos[v as usize][ch]);
                plane[c.px as usize] = c.w[0] * v[0] + c.w[1] * v[1] + c.w[2] * v[2];
            }
            for (i, &px) in self.fill_px.iter().enumerate() {
                let (a, b) = (self.fill_start[i] as usize, self.fill_start[i + 1] as usize);
                let mut acc = 0.0f32;
                for (&s, &k) in self.fill_src[a..b].iter().zip(&self.fill_coef[a..b]) {
                    acc += k * plane[s as usize];
                }
                plane[px as usize] = acc;
            }
        }
    }

    /// The image of another mesh laid out in this atlas's charts: `faces` (of `rest`'s
    /// vertices) with corner positions `corner_px` (LR pixels of this atlas, per face, per
    /// corner), mapped by `to_px` into an `h` × `w` image, rasterised and filled as this atlas
    /// is. A window of this atlas (a training tile: `faces` = its own, `to_px` a shift), or the
    /// HR subdivision's faces at the charts' places on the HR grid (see
    /// [`super::layout::MeshLayout::training_windows`]). Corners that share a mesh vertex and a
    /// position are one chart vertex; the faces are triangulated as the atlas's are.
    pub fn resampled(
        &self,
        faces: &[Vec<u32>],
        rest: &[[f32; 3]],
        corner_px: &[Vec<[f32; 2]>],
        to_px: impl Fn([f32; 2]) -> [f64; 2],
        (h, w): (usize, usize),
    ) -> Atlas {
        let key = |f: usize, k: usize| (faces[f][k], corner_px[f][k].map(f32::to_bits));
        let mut c = charts::triangulate(faces, rest, key);
        for (tri, o) in c.tris.iter().zip(&c.origin) {
            for k in 0..3 {
                c.pos[tri[k] as usize] = to_px(corner_px[o.face as usize][o.corner[k] as usize]);
            }
        }
        let cover = rasterize(std::slice::from_ref(&c), h, w);
        let mut covered = vec![false; h * w];
        cover.iter().for_each(|c| covered[c.px as usize] = true);
        let (fill_px, fill_start, fill_src, fill_coef) = extrapolation(h, w, &covered);
        Atlas {
            h,
            w,
            corner_px: corner_px
                .iter()
                .map(|f| f.iter().map(|&p| to_px(p).map(|x| x as f32)).collect())
                .collect(),
            texel: self.texel,
            charts: self.charts,
            source: self.source,
            cover,
            fill_px,
            fill_start,
            fill_src,
            fill_coef,
            // `faces` are this atlas's faces or their subdivision (four per face, in order).
            face_chart: (0..faces.len())
                .map(|f| self.face_chart[f * self.face_chart.len() / faces.len()])
                .collect(),
            uv_note: None,
            vertices: rest.len(),
        }
    }

    /// Per pixel (row-major, h·w), whether it lies inside a chart.
    pub fn mask(&self) -> Vec<bool> {
        let mut m = vec![false; self.h * self.w];
        self.cover.iter().for_each(|c| m[c.px as usize] = true);
        m
    }

    /// Per face, the index of the chart it lies in (`0..charts`).
    pub fn face_chart(&self) -> &[u32] {
        &self.face_chart
    }

    /// Why the file's UVs were not used (`source` is ARAP though the file has UVs), or `None`.
    pub fn uv_note(&self) -> Option<&str> {
        self.uv_note.as_deref()
    }
}

/// Refuses what would make the layout index out of bounds or compute with NaN.
fn validate(input: &AtlasInput) -> Result<()> {
    if input.faces.is_empty() {
        return Err(Error::shape("any-mesh layout: the mesh has no faces"));
    }
    for (f, face) in input.faces.iter().enumerate() {
        if !(3..=4).contains(&face.len()) {
            return Err(Error::shape(format!(
                "any-mesh layout: face {} has {} vertices; only triangles and quads are laid out",
                f + 1,
                face.len()
            )));
        }
        for (k, &v) in face.iter().enumerate() {
            let p = input.rest.get(v as usize).ok_or_else(|| {
                Error::shape(format!(
                    "any-mesh layout: face {} names vertex {}, but the mesh has {}",
                    f + 1,
                    v + 1,
                    input.rest.len()
                ))
            })?;
            if face[..k].contains(&v) {
                return Err(Error::shape(format!(
                    "any-mesh layout: face {} names vertex {} twice",
                    f + 1,
                    v + 1
                )));
            }
            if !p.iter().all(|x| x.is_finite()) {
                return Err(Error::shape(format!("any-mesh layout: vertex {} is not finite: {p:?}", v + 1)));
            }
        }
    }
    Ok(())
}

/// The texel: mean length (m) of the mesh's edges (each once; a quad's diagonal is no edge).
fn mean_edge(input: &AtlasInput) -> Result<f64> {
    let mut e: Vec<(u32, u32)> = Vec::new();
    for face in input.faces {
        for k in 0..face.len() {
            let (a, b) = (face[k], face[(k + 1) % face.len()]);
            e.push((a.min(b), a.max(b)));
        }
    }
    e.sort_unstable();
    e.dedup();
    let sum: f64 = e.iter().map(|&(a, b)| norm(sub(p3(input.rest, a), p3(input.rest, b)))).sum();
    let texel = sum / e.len() as f64;
    if !(texel > 0.0 && texel.is_finite()) {
        return Err(Error::shape(format!(
            "any-mesh layout: the mesh's edges have mean length {texel} m: all its vertices coincide"
        )));
    }
    Ok(texel)
}

/// One ARAP chart per piece of the mesh, in LR pixels.
fn arap_charts(input: &AtlasInput, texel: f64) -> Result<Vec<Chart>> {
    let (faces, rest) = (input.faces, input.rest);
    let pieces = charts::pieces(faces, rest, |f, k| faces[f][k])?;
    let mut out = Vec::with_capacity(pieces.len());
    for (i, c) in pieces.into_iter().enumerate() {
        let name = format!("piece {} (the part with face {})", i + 1, c.origin[0].face + 1);
        let area: f64 = c
            .tris
            .iter()
            .map(|t| t.map(|v| p3(rest, c.vert[v as usize])))
            .map(|p| area3(p[0], p[1], p[2]))
            .sum();
        if area.is_nan() || area <= DEGENERATE_PIECE * texel * texel {
            return Err(Error::shape(format!(
                "any-mesh layout: {name} has an area of {area:e} m² (its vertices lie on a point or a line): remove it"
            )));
        }
        let mut c = arap::flatten(c, rest, GRID_WINDING, &name)?;
        c.pos.iter_mut().for_each(|p| *p = [p[0] / texel, p[1] / texel]);
        out.push(c);
    }
    Ok(out)
}

/// The rotation `(cos, sin)` (applied as in [`turn`]) that gives `pts` their smallest bounding
/// box: the smallest box has a side along an edge of the convex hull.
fn box_rotation(pts: &[[f64; 2]]) -> [f64; 2] {
    let mut s: Vec<[f64; 2]> = pts.to_vec();
    s.sort_by(|a, b| a[0].total_cmp(&b[0]).then(a[1].total_cmp(&b[1])));
    s.dedup();
    // Andrew's monotone chain: lower hull, then upper.
    let mut hull: Vec<[f64; 2]> = Vec::new();
    for pass in 0..2 {
        let start = hull.len();
        let it: Box<dyn Iterator<Item = &[f64; 2]>> =
            if pass == 0 { Box::new(s.iter()) } else { Box::new(s.iter().rev()) };
        for &p in it {
            while hull.len() >= start + 2 && orient2(hull[hull.len() - 2], hull[hull.len() - 1], p) <= 0.0 {
                hull.pop();
            }
            hull.push(p);
        }
        hull.pop();
    }
    let mut best = ([1.0, 0.0], f64::INFINITY);
    for i in 0..hull.len() {
        let (a, b) = (hull[i], hull[(i + 1) % hull.len()]);
        let d = [b[0] - a[0], b[1] - a[1]];
        let l = (d[0] * d[0] + d[1] * d[1]).sqrt();
        if l.is_nan() || l <= 0.0 {
            continue;
        }
        let r = [d[0] / l, -d[1] / l];
        let bb = bbox(&hull.iter().map(|&p| turn(r, p)).collect::<Vec<_>>());
        let area = (bb[1][0] - bb[0][0]) * (bb[1][1] - bb[0][1]);
        if area < best.1 {
            best = (r, area);
        }
    }
    best.0
}

/// Turns each chart to its smallest box (long side along the rows), shelves the boxes tallest
/// first into a roughly square image with [`GAP`] between them and [`MARGIN`] round them, and
/// moves the charts there (whole-pixel offsets). Returns (h, w).
fn pack(charts: &mut [Chart]) -> Result<(usize, usize)> {
    let mut ext = Vec::with_capacity(charts.len());
    for c in charts.iter_mut() {
        let mut r = box_rotation(&c.pos);
        let b = bbox(&c.pos.iter().map(|&p| turn(r, p)).collect::<Vec<_>>());
        if b[1][0] - b[0][0] < b[1][1] - b[0][1] {
            r = turn([0.0, -1.0], r); // a quarter turn more: the long side along the rows
        }
        c.pos.iter_mut().for_each(|p| *p = turn(r, *p));
        let b = bbox(&c.pos);
        c.pos.iter_mut().for_each(|p| *p = [p[0] - b[0][0], p[1] - b[0][1]]);
        ext.push([b[1][0] - b[0][0], b[1][1] - b[0][1]]);
    }
    let (gap, margin) = (GAP as f64, MARGIN as f64);
    let area: f64 = ext.iter().map(|e| (e[0] + gap) * (e[1] + gap)).sum();
    let shelf_w = ext.iter().map(|e| e[0]).fold(area.sqrt(), f64::max);
    let mut order: Vec<usize> = (0..charts.len()).collect();
    order.sort_by(|&a, &b| ext[b][1].total_cmp(&ext[a][1]).then(a.cmp(&b)));
    let (mut x, mut y, mut shelf_h) = (margin, margin, 0.0f64);
    let (mut w, mut h) = (0.0f64, 0.0f64);
    for &i in &order {
        if x > margin && x + ext[i][0] > margin + shelf_w {
            (x, y, shelf_h) = (margin, (y + shelf_h + gap - SNAP).ceil(), 0.0);
        }
        charts[i].pos.iter_mut().for_each(|p| *p = [p[0] + x, p[1] + y]);
        w = w.max((x + ext[i][0] + SNAP).floor() + 1.0 + margin);
        h = h.max((y + ext[i][1] + SNAP).floor() + 1.0 + margin);
        shelf_h = shelf_h.max(ext[i][1]);
        x = (x + ext[i][0] + gap - SNAP).ceil();
    }
    if w.is_nan() || h.is_nan() || w * h > MAX_LR_VERTICES as f64 {
        return Err(Error::shape(format!(
            "any-mesh layout: the charts need a {h}×{w} image, more than the {MAX_LR_VERTICES} pixels an LR \
             frame may have: upscale the cloth in pieces"
        )));
    }
    Ok((h as usize, w as usize))
}

/// The pixels whose centres lie in a chart triangle (the triangle a centre is deepest in wins,
/// the first on a tie), row-major. A chart too small to hold a pixel centre gets the pixel
/// nearest its largest triangle's centroid, so every chart shows in the image.
fn rasterize(charts: &[Chart], h: usize, w: usize) -> Vec<Cover> {
    let mut depth = vec![f64::NEG_INFINITY; h * w];
    let mut who = vec![(u32::MAX, 0u32); h * w];
    for (ci, c) in charts.iter().enumerate() {
        let mut hit = false;
        for t in 0..c.tris.len() {
            let q = corners(c, t);
            let b = bbox(&q);
            let (c0, c1) =
                ((b[0][0] - SNAP).ceil().max(0.0) as usize, ((b[1][0] + SNAP).floor() as usize).min(w - 1));
            let (r0, r1) =
                ((b[0][1] - SNAP).ceil().max(0.0) as usize, ((b[1][1] + SNAP).floor() as usize).min(h - 1));
            for r in r0..=r1 {
                for col in c0..=c1 {
                    let Some(wt) = bary([col as f64, r as f64], q) else { continue };
                    let d = wt[0].min(wt[1]).min(wt[2]);
                    if d >= -BARY_EPS && d > depth[r * w + col] {
                        hit = true;
                        depth[r * w + col] = d;
                        who[r * w + col] = (ci as u32, t as u32);
                    }
                }
            }
        }
        if !hit {
            let t = (0..c.tris.len()).fold(0, |b, t| {
                if orient2_of(&corners(c, t)).abs() > orient2_of(&corners(c, b)).abs() {
                    t
                } else {
                    b
                }
            });
            let q = corners(c, t);
            let m = [0, 1].map(|k| (q[0][k] + q[1][k] + q[2][k]) / 3.0);
            let px = (m[1].round().clamp(0.0, (h - 1) as f64) as usize) * w
                + m[0].round().clamp(0.0, (w - 1) as f64) as usize;
            if who[px].0 == u32::MAX {
                who[px] = (ci as u32, t as u32);
            }
        }
    }
    let mut out = Vec::new();
    for (px, &(ci, t)) in who.iter().enumerate() {
        if ci == u32::MAX {
            continue;
        }
        let c = &charts[ci as usize];
        let p = [(px % w) as f64, (px / w) as f64];
        let wt = bary(p, corners(c, t as usize)).unwrap_or([1.0 / 3.0; 3]);
        let v = c.tris[t as usize].map(|v| c.vert[v as usize]);
        out.push(Cover { px: px as u32, v, w: wt.map(|x| x as f32) });
    }
    out
}

/// The fill of the pixels outside the charts, ring by ring (chessboard distance from the covered
/// pixels): a pixel p at distance d is the mean, over its 8 neighbours n at distance d − 1, of
/// the line from p through n continued — 2·v[n] − v[n + (n − p)] where that pixel is covered or
/// nearer than d − 1, else v[n]. A plane is continued exactly. After [`LINEAR_RINGS`] rings every
/// term is v[n]. Returns (pixels, their op starts (+1 at the end), sources, coefficients).
fn extrapolation(h: usize, w: usize, covered: &[bool]) -> (Vec<u32>, Vec<u32>, Vec<u32>, Vec<f32>) {
    const NEIGHBOURS: [(isize, isize); 8] =
        [(-1, -1), (-1, 0), (-1, 1), (0, -1), (0, 1), (1, -1), (1, 0), (1, 1)];
    let at = |r: usize, c: usize, dr: isize, dc: isize, k: isize| {
        let (rr, cc) = (r as isize + k * dr, c as isize + k * dc);
        (rr >= 0 && cc >= 0 && (rr as usize) < h && (cc as usize) < w).then(|| rr as usize * w + cc as usize)
    };
    let mut dist = vec![u32::MAX; h * w];
    let mut queue: std::collections::VecDeque<usize> = (0..h * w).filter(|&p| covered[p]).collect();
    queue.iter().for_each(|&p| dist[p] = 0);
    while let Some(p) = queue.pop_front() {
        for &(dr, dc) in &NEIGHBOURS {
            if let Some(n) = at(p / w, p % w, dr, dc, 1) {
                if dist[n] == u32::MAX {
                    dist[n] = dist[p] + 1;
                    queue.push_back(n);
                }
            }
        }
    }
    let mut order: Vec<usize> = (0..h * w).filter(|&p| dist[p] != 0 && dist[p] != u32::MAX).collect();
    order.sort_by_key(|&p| (dist[p], p));
    let (mut px, mut start, mut src, mut coef) = (Vec::new(), vec![0u32], Vec::new(), Vec::new());
    for p in order {
        let (r, c, d) = (p / w, p % w, dist[p]);
        let first = src.len();
        let mut terms = 0usize;
        for &(dr, dc) in &NEIGHBOURS {
            let Some(n) = at(r, c, dr, dc, 1).filter(|&n| dist[n] == d - 1) else { continue };
            terms += 1;
            let far = at(r, c, dr, dc, 2).filter(|&m| dist[m] == 0 || dist[m] < d - 1);
            match far {
                Some(m) if d <= LINEAR_RINGS => {
                    src.extend([n as u32, m as u32]);
                    coef.extend([2.0f32, -1.0]);
                }
                _ => {
                    src.push(n as u32);
                    coef.push(1.0);
                }
            }
        }
        coef[first..].iter_mut().for_each(|k| *k /= terms as f32);
        px.push(p as u32);
        start.push(src.len() as u32);
    }
    (px, start, src, coef)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geom::vec3::{cross, dot};

    /// Faces and rest positions (m).
    type Mesh = (Vec<Vec<u32>>, Vec<[f32; 3]>);

    /// A `nx × ny` sheet of quads wound as a grid's, vertex (i, j) at `at(i, j)`.
    fn sheet(nx: usize, ny: usize, at: impl Fn(usize, usize) -> [f32; 3]) -> Mesh {
        let id = |i: usize, j: usize| (j * nx + i) as u32;
        let rest = (0..ny).flat_map(|j| (0..nx).map(move |i| (i, j))).map(|(i, j)| at(i, j)).collect();
        let mut faces = Vec::new();
        for j in 0..ny - 1 {
            for i in 0..nx - 1 {
                faces.push(vec![id(i, j), id(i, j + 1), id(i + 1, j + 1), id(i + 1, j)]);
            }
        }
        (faces, rest)
    }

    /// The 12 × 9 sheet, 2 cm spacing, in a tilted plane, with the plane's origin and unit normal.
    fn tilted_sheet() -> (Mesh, [f64; 3], [f64; 3]) {
        let (o, e1, e2) = ([0.1f64, -0.2, 0.3], [0.6f64, 0.0, 0.8], [0.0f64, 1.0, 0.0]);
        let (faces, rest) = sheet(12, 9, |i, j| {
            let (a, b) = (0.02 * i as f64, 0.02 * j as f64);
            [0, 1, 2].map(|k| (o[k] + a * e1[k] + b * e2[k]) as f32)
        });
        ((faces, rest), o, cross(e1, e2))
    }

    fn build(faces: &[Vec<u32>], rest: &[[f32; 3]]) -> Atlas {
        Atlas::build(&AtlasInput { faces, rest, uv: None }).unwrap()
    }

    fn image(a: &Atlas, rest: &[[f32; 3]]) -> Vec<f32> {
        let mut out = vec![f32::NAN; 3 * a.h * a.w];
        a.image_into(rest, &mut out);
        out
    }

    /// Image pixels per mesh vertex in a face (printed: the image's cost against the grid's 1).
    fn pixels_per_vertex(what: &str, a: &Atlas, faces: &[Vec<u32>]) -> f64 {
        let mut used: Vec<u32> = faces.iter().flatten().copied().collect();
        used.sort_unstable();
        used.dedup();
        let r = (a.h * a.w) as f64 / used.len() as f64;
        eprintln!(
            "{what}: {}×{} image, {} vertices, {r:.2} pixels per vertex, {:?}",
            a.h,
            a.w,
            used.len(),
            a.source
        );
        r
    }

    /// Largest relative error of the faces' edge lengths in the image (× texel) against 3D.
    fn edge_error(a: &Atlas, faces: &[Vec<u32>], rest: &[[f32; 3]]) -> f64 {
        let mut worst = 0.0f64;
        for (f, face) in faces.iter().enumerate() {
            for k in 0..face.len() {
                let k1 = (k + 1) % face.len();
                let l3 = norm(sub(p3(rest, face[k]), p3(rest, face[k1])));
                let (p, q) = (a.corner_px[f][k], a.corner_px[f][k1]);
                let l2 = ((p[0] - q[0]) as f64).hypot((p[1] - q[1]) as f64) * a.texel as f64;
                worst = worst.max((l2 - l3).abs() / l3);
            }
        }
        worst
    }

    /// The faces' triangles (both diagonals of a quad) in pixels, with their mesh vertices.
    fn face_tris(a: &Atlas, faces: &[Vec<u32>]) -> Vec<(usize, [[f64; 2]; 3], [u32; 3])> {
        let mut out = Vec::new();
        for (f, face) in faces.iter().enumerate() {
            let ks: &[[usize; 3]] =
                if face.len() == 3 { &[[0, 1, 2]] } else { &[[0, 1, 2], [0, 2, 3], [0, 1, 3], [1, 2, 3]] };
            for k in ks {
                let q = k.map(|k| a.corner_px[f][k].map(|x| x as f64));
                out.push((f, q, k.map(|k| face[k])));
            }
        }
        out
    }

    /// The plane sheet's image: every pixel on the plane; a covered pixel the blend of a face's
    /// corners around it (within `tol` metres).
    fn check_planar(a: &Atlas, faces: &[Vec<u32>], rest: &[[f32; 3]], o: [f64; 3], n: [f64; 3], tol: f64) {
        let img = image(a, rest);
        let hw = a.h * a.w;
        let mask = a.mask();
        let tris = face_tris(a, faces);
        for px in 0..hw {
            let v = [img[px] as f64, img[hw + px] as f64, img[2 * hw + px] as f64];
            let off = dot(sub(v, o), n);
            assert!(off.abs() < 1e-4, "pixel {px} is {off} m off the plane");
            if !mask[px] {
                continue;
            }
            let p = [(px % a.w) as f64, (px / a.w) as f64];
            let (_, q, vs) = tris
                .iter()
                .find(|(_, q, _)| bary(p, *q).is_some_and(|w| w.iter().all(|&x| x > -1e-3)))
                .unwrap_or_else(|| panic!("covered pixel {px} is in no face"));
            let wt = bary(p, *q).unwrap();
            let want: [f64; 3] =
                std::array::from_fn(|k| (0..3).map(|c| wt[c] * rest[vs[c] as usize][k] as f64).sum());
            let err = norm(sub(v, want));
            assert!(err < tol, "covered pixel {px}: {v:?} vs {want:?}");
        }
    }

    #[test]
    fn flat_sheet_flattens_to_an_isometric_chart_and_a_planar_image() {
        let ((faces, rest), o, n) = tilted_sheet();
        let a = build(&faces, &rest);
        assert_eq!((a.source, a.charts), (ChartSource::Arap, 1));
        let err = edge_error(&a, &faces, &rest);
        eprintln!("12×9 sheet, ARAP: edge length error {:.2e}", err);
        assert!(err < 0.01, "edge length error {err}");
        assert!(pixels_per_vertex("12×9 sheet (ARAP)", &a, &faces) <= 2.5);
        check_planar(&a, &faces, &rest, o, n, 1e-3 * a.texel as f64);
    }

    #[test]
    fn flat_sheet_with_uvs_uses_them() {
        let ((faces, rest), o, n) = tilted_sheet();
        let uv: Vec<[f32; 2]> =
            (0..9).flat_map(|j| (0..12).map(move |i| [i as f32 / 11.0, j as f32 / 8.0])).collect();
        let a = Atlas::build(&AtlasInput { faces: &faces, rest: &rest, uv: Some((&uv, &faces)) }).unwrap();
        assert_eq!((a.source, a.charts), (ChartSource::Uv, 1));
        let err = edge_error(&a, &faces, &rest);
        assert!(err < 1e-4, "edge length error {err}");
        assert!(pixels_per_vertex("12×9 sheet (UV)", &a, &faces) <= 2.5);
        check_planar(&a, &faces, &rest, o, n, 1e-5);
        // The grid is the image: vertex (i, j) is pixel (MARGIN + j, MARGIN + i).
        let img = image(&a, &rest);
        let hw = a.h * a.w;
        for (v, p) in rest.iter().enumerate() {
            let px = (MARGIN + v / 12) * a.w + MARGIN + v % 12;
            for k in 0..3 {
                assert!((img[k * hw + px] - p[k]).abs() < 1e-6, "vertex {v}");
            }
        }
    }

    #[test]
    fn tube_is_cut_open_and_unrolled() {
        let (around, along) = (16usize, 6usize);
        let r = 0.05f64;
        let step = 2.0 * r * (std::f64::consts::PI / around as f64).sin();
        let at = |i: usize, j: usize| {
            let t = std::f64::consts::TAU * i as f64 / around as f64;
            [(r * t.cos()) as f32, (r * t.sin()) as f32, (step * j as f64) as f32]
        };
        let rest: Vec<[f32; 3]> =
            (0..along).flat_map(|j| (0..around).map(move |i| (i, j))).map(|(i, j)| at(i, j)).collect();
        let id = |i: usize, j: usize| (j * around + i % around) as u32;
        let faces: Vec<Vec<u32>> = (0..along - 1)
            .flat_map(|j| {
                (0..around).map(move |i| vec![id(i, j), id(i, j + 1), id(i + 1, j + 1), id(i + 1, j)])
            })
            .collect();
        let a = build(&faces, &rest);
        assert_eq!((a.source, a.charts), (ChartSource::Arap, 1));
        let err = edge_error(&a, &faces, &rest);
        eprintln!("tube 16×6, ARAP: edge length error {:.2e}", err);
        assert!(err < 0.03, "edge length error {err}");
        for (f, q, _) in face_tris(&a, &faces).iter().step_by(4) {
            assert!(orient2_of(q) * GRID_WINDING > 0.0, "face {f} flipped: {q:?}");
        }
        pixels_per_vertex("tube 16×6", &a, &faces);
        check_layout(&a, &faces, 1);
    }

    /// Every corner inside the image, no pixel centre inside faces of two charts, corners of
    /// different charts at least GAP − 1 pixels apart.
    fn check_layout(a: &Atlas, faces: &[Vec<u32>], charts: usize) {
        assert_eq!(a.charts, charts);
        assert_eq!(a.face_chart().iter().map(|&c| c as usize + 1).max(), Some(charts));
        for (f, cs) in a.corner_px.iter().enumerate() {
            for p in cs {
                assert!(
                    p[0] >= 0.0 && p[1] >= 0.0 && p[0] <= (a.w - 1) as f32 && p[1] <= (a.h - 1) as f32,
                    "face {f}: {p:?}"
                );
            }
        }
        let mut owner = vec![u32::MAX; a.h * a.w];
        for (f, q, _) in face_tris(a, faces) {
            let b = bbox(&q);
            for r in b[0][1].floor() as usize..=b[1][1].ceil() as usize {
                for c in b[0][0].floor() as usize..=b[1][0].ceil() as usize {
                    if bary([c as f64, r as f64], q).is_some_and(|w| w.iter().all(|&x| x > 1e-9)) {
                        let ch = a.face_chart()[f];
                        assert!(
                            owner[r * a.w + c] == u32::MAX || owner[r * a.w + c] == ch,
                            "pixel ({r}, {c}) in two charts"
                        );
                        owner[r * a.w + c] = ch;
                    }
                }
            }
        }
        for (f, cf) in a.corner_px.iter().enumerate() {
            for (g, cg) in a.corner_px.iter().enumerate().skip(f + 1) {
                if a.face_chart()[f] == a.face_chart()[g] {
                    continue;
                }
                for p in cf {
                    for q in cg {
                        let d = (p[0] - q[0]).hypot(p[1] - q[1]);
                        assert!(d >= (GAP - 1) as f32, "faces {f} and {g} are {d} pixels apart");
                    }
                }
            }
        }
    }

    /// A domed disk of triangles: a centre and `rings` rings of 12 vertices, radius 1 cm a ring.
    fn disk(rings: usize, centre: [f32; 3]) -> Mesh {
        const N: usize = 12;
        let mut rest = vec![centre];
        for k in 1..=rings {
            for i in 0..N {
                let (t, rr) =
                    (std::f32::consts::TAU * (i as f32 + 0.5 * k as f32) / N as f32, 0.01 * k as f32);
                rest.push([centre[0] + rr * t.cos(), centre[1] + rr * t.sin(), centre[2] - 2.0 * rr * rr]);
            }
        }
        let ring = |k: usize, i: usize| if k == 0 { 0 } else { (1 + (k - 1) * N + i % N) as u32 };
        let mut faces = Vec::new();
        for i in 0..N {
            faces.push(vec![0, ring(1, i), ring(1, i + 1)]);
        }
        for k in 1..rings {
            for i in 0..N {
                faces.push(vec![ring(k, i), ring(k + 1, i), ring(k + 1, i + 1)]);
                faces.push(vec![ring(k, i), ring(k + 1, i + 1), ring(k, i + 1)]);
            }
        }
        (faces, rest)
    }

    #[test]
    fn disk_hole_and_two_pieces_pack_apart() {
        let (faces, rest) = disk(4, [0.0; 3]);
        let a = build(&faces, &rest);
        pixels_per_vertex("disk of 4 rings", &a, &faces);
        check_layout(&a, &faces, 1);

        let (mut faces, rest) = sheet(10, 10, |i, j| [0.01 * i as f32, 0.01 * j as f32, 0.0]);
        faces.retain(|f| {
            let (i, j) = (f[0] % 10, f[0] / 10);
            !((4..6).contains(&i) && (4..6).contains(&j))
        });
        let a = build(&faces, &rest);
        pixels_per_vertex("10×10 sheet with a 2×2 hole", &a, &faces);
        check_layout(&a, &faces, 1);

        let (mut faces, mut rest) = sheet(6, 5, |i, j| [0.01 * i as f32, 0.01 * j as f32, 0.0]);
        let (f2, r2) = disk(3, [0.5, 0.0, 0.0]);
        let base = rest.len() as u32;
        faces.extend(f2.iter().map(|f| f.iter().map(|v| v + base).collect::<Vec<_>>()));
        rest.extend(r2);
        let a = build(&faces, &rest);
        pixels_per_vertex("6×5 sheet and a disk", &a, &faces);
        check_layout(&a, &faces, 2);
    }

    #[test]
    fn building_twice_gives_the_same_bits() {
        let ((faces, rest), ..) = tilted_sheet();
        let (a, b) = (build(&faces, &rest), build(&faces, &rest));
        let bits =
            |a: &Atlas| a.corner_px.iter().flatten().flat_map(|p| p.map(f32::to_bits)).collect::<Vec<_>>();
        assert_eq!(bits(&a), bits(&b));
        let img = |a: &Atlas| image(a, &rest).iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        assert_eq!(img(&a), img(&b));
    }

    /// Quads of a `n × m` grid of vertex ids `id(i, j)`, wound as a grid's.
    fn quads(n: usize, m: usize, id: impl Fn(usize, usize) -> u32) -> Vec<Vec<u32>> {
        (0..m)
            .flat_map(|j| (0..n).map(move |i| (i, j)))
            .map(|(i, j)| vec![id(i, j), id(i, j + 1), id(i + 1, j + 1), id(i + 1, j)])
            .collect()
    }

    #[test]
    fn closed_and_curved_pieces_flatten_and_stay_bounded() {
        // A sphere of quads (a latitude/longitude grid closed by two triangle fans): closed, no
        // boundary, strongly curved.
        let (n, m, r) = (16usize, 8usize, 0.1f32);
        let mut rest = vec![[0.0, 0.0, r], [0.0, 0.0, -r]];
        for j in 1..m {
            let th = std::f32::consts::PI * j as f32 / m as f32;
            for i in 0..n {
                let ph = std::f32::consts::TAU * i as f32 / n as f32;
                rest.push([r * th.sin() * ph.cos(), r * th.sin() * ph.sin(), r * th.cos()]);
            }
        }
        let id = |i: usize, j: usize| (2 + (j - 1) * n + i % n) as u32;
        let mut faces = quads(n, m - 2, |i, j| id(i, j + 1));
        for i in 0..n {
            faces.push(vec![0, id(i, 1), id(i + 1, 1)]);
            faces.push(vec![1, id(i + 1, m - 1), id(i, m - 1)]);
        }
        let a = build(&faces, &rest);
        pixels_per_vertex("sphere 16×8", &a, &faces);
        check_layout(&a, &faces, 1);
        // A hemisphere (one boundary loop, not developable): its image stays near the cloth.
        let half: Vec<Vec<u32>> = faces
            .iter()
            .filter(|f| f.iter().all(|&v| v == 0 || rest[v as usize][2] >= -1e-6))
            .cloned()
            .collect();
        let a = build(&half, &rest);
        pixels_per_vertex("hemisphere", &a, &half);
        check_layout(&a, &half, 1);
        let img = image(&a, &rest);
        let hw = a.h * a.w;
        for px in 0..hw {
            let v = [img[px], img[hw + px], img[2 * hw + px]];
            assert!(v.iter().all(|x| x.abs() < 3.0 * r), "pixel {px} wandered off to {v:?}");
        }
    }

    #[test]
    fn a_torus_is_refused_naming_its_handle() {
        let (n, m) = (12usize, 8usize);
        let rest: Vec<[f32; 3]> = (0..m)
            .flat_map(|j| (0..n).map(move |i| (i, j)))
            .map(|(i, j)| {
                let (u, v) = (
                    std::f32::consts::TAU * i as f32 / n as f32,
                    std::f32::consts::TAU * j as f32 / m as f32,
                );
                [(0.3 + 0.1 * v.cos()) * u.cos(), (0.3 + 0.1 * v.cos()) * u.sin(), 0.1 * v.sin()]
            })
            .collect();
        let faces = quads(n, m, |i, j| ((j % m) * n + i % n) as u32);
        let e = Atlas::build(&AtlasInput { faces: &faces, rest: &rest, uv: None })
            .err()
            .expect("a torus has no disk layout");
        assert!(e.to_string().contains("handle"), "{e}");
    }

    #[test]
    fn odd_meshes_give_charts_or_clear_errors() {
        // Two triangles sharing only a vertex (a bowtie), a mixed tri/quad strip, an isolated
        // vertex: three charts.
        let rest = vec![
            [0.0, 0.0, 0.0],
            [0.01, 0.0, 0.0],
            [0.0, 0.01, 0.0],
            [-0.01, 0.0, 0.0],
            [0.0, -0.01, 0.0],
            [1.0, 0.0, 0.0],
            [1.01, 0.0, 0.0],
            [1.01, 0.01, 0.0],
            [1.0, 0.01, 0.0],
            [1.02, 0.005, 0.0],
            [5.0, 5.0, 5.0],
        ];
        let faces = vec![vec![0, 1, 2], vec![0, 3, 4], vec![5, 6, 7, 8], vec![6, 9, 7]];
        let a = build(&faces, &rest);
        check_layout(&a, &faces, 3);
        let img = image(&a, &rest);
        assert!(img.iter().all(|x| x.is_finite()));
        // A piece collapsed to a point is named.
        let mut rest2 = rest.clone();
        (5..10).for_each(|v| rest2[v] = [1.0; 3]);
        let e = Atlas::build(&AtlasInput { faces: &faces, rest: &rest2, uv: None })
            .err()
            .expect("collapsed piece");
        assert!(e.to_string().contains("piece") && e.to_string().contains("face 3)"), "{e}");
        // A zero-area face inside a piece is laid out.
        let (mut faces3, mut rest3) = sheet(5, 5, |i, j| [0.01 * i as f32, 0.01 * j as f32, 0.0]);
        rest3[12] = rest3[13];
        faces3.push(vec![0, 1, 2]);
        faces3.remove(faces3.len() - 1);
        build(&faces3, &rest3);
        // An image larger than an LR frame may be is refused before it is allocated.
        let mut rest4: Vec<[f32; 3]> = sheet(100, 100, |i, j| [1e-4 * i as f32, 1e-4 * j as f32, 0.0]).1;
        let mut faces4 = sheet(100, 100, |_, _| [0.0; 3]).0;
        let b = rest4.len() as u32;
        rest4.extend([[10.0, 0.0, 0.0], [20.0, 0.0, 0.0], [10.0, 10.0, 0.0]]);
        faces4.push(vec![b, b + 1, b + 2]);
        let e =
            Atlas::build(&AtlasInput { faces: &faces4, rest: &rest4, uv: None }).err().expect("too large");
        assert!(e.to_string().contains("pixels an LR"), "{e}");
        // Faces that name no vertex, or 5 of them, are refused.
        assert!(Atlas::build(&AtlasInput { faces: &[vec![0, 1, 99]], rest: &rest, uv: None }).is_err());
        assert!(Atlas::build(&AtlasInput { faces: &[vec![0, 1, 2, 3, 4]], rest: &rest, uv: None }).is_err());
        assert!(Atlas::build(&AtlasInput { faces: &[], rest: &rest, uv: None }).is_err());
    }

    #[test]
    fn unusable_uvs_fall_back_to_arap_saying_why() {
        let ((faces, rest), ..) = tilted_sheet();
        let good: Vec<[f32; 2]> =
            (0..9).flat_map(|j| (0..12).map(move |i| [i as f32 / 11.0, j as f32 / 8.0])).collect();
        let try_uv = |uv: &[[f32; 2]]| {
            Atlas::build(&AtlasInput { faces: &faces, rest: &rest, uv: Some((uv, &faces)) }).unwrap()
        };
        // One vertex dragged across its neighbours: flipped triangles.
        let mut flipped = good.clone();
        flipped[5 * 12 + 5] = [7.5 / 11.0, 5.0 / 8.0];
        let a = try_uv(&flipped);
        assert_eq!(a.source, ChartSource::Arap);
        assert!(a.uv_note().is_some_and(|n| n.contains("flipped")), "{:?}", a.uv_note());
        // Stretched tenfold along one edge column.
        let stretched: Vec<[f32; 2]> =
            good.iter().map(|p| [if p[0] > 0.95 { p[0] * 10.0 } else { p[0] }, p[1]]).collect();
        let a = try_uv(&stretched);
        assert_eq!(a.source, ChartSource::Arap, "{:?}", a.uv_note());
        // Two halves whose islands overlap in UV (the right half laid over the left).
        let (nx, ny) = (12usize, 9usize);
        let mut uv = good.clone();
        let mut uvf: Vec<Vec<u32>> = faces.clone();
        for (f, face) in faces.iter().enumerate() {
            if f % (nx - 1) >= 6 {
                uvf[f] = face.iter().map(|&v| v + (nx * ny) as u32).collect();
            }
        }
        uv.extend(good.iter().map(|p| [p[0] - 5.5 / 11.0, p[1]]));
        let a = Atlas::build(&AtlasInput { faces: &faces, rest: &rest, uv: Some((&uv, &uvf)) }).unwrap();
        assert_eq!(a.source, ChartSource::Arap);
        assert!(a.uv_note().is_some_and(|n| n.contains("overlap")), "{:?}", a.uv_note());
        // The same halves side by side are two charts.
        let uv2: Vec<[f32; 2]> =
            good.iter().copied().chain(good.iter().map(|p| [p[0] + 0.5, p[1]])).collect();
        let a = Atlas::build(&AtlasInput { faces: &faces, rest: &rest, uv: Some((&uv2, &uvf)) }).unwrap();
        assert_eq!((a.source, a.charts), (ChartSource::Uv, 2), "{:?}", a.uv_note());
        check_layout(&a, &faces, 2);
    }

    /// Time and shape of a large tube (run by hand: `cargo test --lib atlas -- --ignored`).
    #[test]
    #[ignore]
    fn large_tube_timing() {
        let (around, along) = (256usize, 200usize);
        let rest: Vec<[f32; 3]> = (0..along)
            .flat_map(|j| (0..around).map(move |i| (i, j)))
            .map(|(i, j)| {
                let t = std::f32::consts::TAU * i as f32 / around as f32;
                [0.5 * t.cos(), 0.5 * t.sin() + 0.02 * (j as f32 * 0.3).sin(), 0.0123 * j as f32]
            })
            .collect();
        let faces = quads(around, along - 1, |i, j| (j * around + i % around) as u32);
        let t0 = std::time::Instant::now();
        let a = build(&faces, &rest);
        eprintln!(
            "large tube: built in {:?}, edge error {:.2e}",
            t0.elapsed(),
            edge_error(&a, &faces, &rest)
        );
        pixels_per_vertex("large tube", &a, &faces);
        let t0 = std::time::Instant::now();
        image(&a, &rest);
        eprintln!("image in {:?}", t0.elapsed());
    }
}
