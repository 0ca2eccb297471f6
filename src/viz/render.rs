//! A small software rasterizer for grid cloth meshes: fixed camera fitted to a bounding box
//! (orthographic or perspective), z-buffer, smooth per-vertex normals, two-sided Lambert
//! shading with ambient + key light + headlight, optional per-vertex scalar colouring (heat
//! map, e.g. per-vertex error, see [`super::heat`]), supersampled edges. Deterministic,
//! single-threaded, no crates.
//!
//! World up is +y (the simulator's gravity is −y); the default view is a 3/4 view from the
//! front (+z) right and slightly above, which shows wrinkles as bands of light and shade.
//! Tiles meant to be compared (LR / bicubic / anisocb / HR) share one [`Camera`], fitted to
//! the union of their bounding boxes: see [`Camera::fit_meshes`] and [`render_row`].

use super::heat::{heat_color, ScalarColors};
use super::image::{hstack, Rgb8, BLACK, WHITE};
use crate::error::{Error, Result};
use crate::geom::mesh::vertex_normals;
use crate::geom::vec3::{cross, dot, normalize_or, sub, V3};
use crate::geom::GridMesh;

/// Where the camera looks from. Angles in degrees.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct View {
    /// Rotation about world +y of the direction towards the camera; 0 = camera on the +z side.
    pub azimuth_deg: f32,
    /// Height of the camera above the horizontal plane; 90 = looking straight down.
    pub elevation_deg: f32,
    /// Vertical field of view; 0 = orthographic (sizes comparable across depth).
    pub fov_deg: f32,
    /// Fraction of the picture left empty on each side (0..0.45).
    pub margin: f32,
}

impl Default for View {
    /// 3/4 view: 35° to the right, 20° above, orthographic, 6% margin.
    fn default() -> Self {
        View { azimuth_deg: 35.0, elevation_deg: 20.0, fov_deg: 0.0, margin: 0.06 }
    }
}

impl View {
    /// Unit vector from the target towards the camera.
    pub fn toward_camera(&self) -> V3 {
        let (az, el) = (self.azimuth_deg.to_radians(), self.elevation_deg.to_radians());
        normalize([el.cos() * az.sin(), el.sin(), el.cos() * az.cos()])
    }
}

/// Unit vector along `a`; +z for a zero vector.
#[inline]
fn normalize(a: V3) -> V3 {
    normalize_or(a, [0.0, 0.0, 1.0])
}

/// A camera fitted to a box: orthonormal basis (right, up, back = towards the camera), the
/// box centre, and the screen mapping `screen = offset + scale · (x, −y)` for a `w × h` picture.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Camera {
    pub right: V3,
    pub up: V3,
    /// Unit vector from the target towards the camera.
    pub back: V3,
    pub center: V3,
    /// Camera distance from `center` (metres) for perspective; `None` = orthographic.
    pub dist: Option<f32>,
    /// Pixels per projected unit.
    pub scale: f32,
    pub offset: [f32; 2],
    pub w: usize,
    pub h: usize,
}

impl Camera {
    /// Fits `view` to the box `lo..hi` (metres) so that the whole box shows in a `w × h` picture.
    pub fn fit(view: &View, lo: V3, hi: V3, w: usize, h: usize) -> Result<Camera> {
        if w == 0 || h == 0 {
            return Err(Error::config(format!("render size must be positive, got {w}x{h}")));
        }
        if !(0.0..0.45).contains(&view.margin) || !(0.0..170.0).contains(&view.fov_deg) {
            return Err(Error::config(format!("bad view {view:?}: margin in [0, 0.45), fov in [0, 170)")));
        }
        if (0..3).any(|k| !(lo[k].is_finite() && hi[k].is_finite() && hi[k] >= lo[k])) {
            return Err(Error::config(format!("render: empty or non-finite box {lo:?}..{hi:?}")));
        }
        let back = view.toward_camera();
        // Looking straight down/up: pick a world "up" that is not parallel to the view.
        let world_up = if back[1].abs() > 0.999 { [0.0, 0.0, -back[1].signum()] } else { [0.0, 1.0, 0.0] };
        let right = normalize(cross(world_up, back));
        let up = cross(back, right);
        let center = [0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1]), 0.5 * (lo[2] + hi[2])];
        let radius = 0.5 * dot(sub(hi, lo), sub(hi, lo)).sqrt();
        let dist = if view.fov_deg > 0.0 {
            Some(radius.max(1e-6) / (0.5 * view.fov_deg.to_radians()).sin())
        } else {
            None
        };
        let mut cam = Camera { right, up, back, center, dist, scale: 1.0, offset: [0.0, 0.0], w, h };
        let (mut x0, mut x1, mut y0, mut y1) = (f32::MAX, f32::MIN, f32::MAX, f32::MIN);
        for c in 0..8 {
            let p = [
                if c & 1 == 0 { lo[0] } else { hi[0] },
                if c & 2 == 0 { lo[1] } else { hi[1] },
                if c & 4 == 0 { lo[2] } else { hi[2] },
            ];
            let (x, y, _) = cam.project_unit(p);
            x0 = x0.min(x);
            x1 = x1.max(x);
            y0 = y0.min(y);
            y1 = y1.max(y);
        }
        let usable = 1.0 - 2.0 * view.margin;
        let sx = usable * w as f32 / (x1 - x0).max(1e-9);
        let sy = usable * h as f32 / (y1 - y0).max(1e-9);
        cam.scale = sx.min(sy);
        cam.offset =
            [0.5 * w as f32 - cam.scale * 0.5 * (x0 + x1), 0.5 * h as f32 + cam.scale * 0.5 * (y0 + y1)];
        Ok(cam)
    }

    /// One camera for several meshes (the union of their bounding boxes), so tiles compare.
    pub fn fit_meshes(view: &View, meshes: &[&GridMesh], w: usize, h: usize) -> Result<Camera> {
        let mut lo = [f32::INFINITY; 3];
        let mut hi = [f32::NEG_INFINITY; 3];
        for m in meshes {
            let (a, b) = m.bounds();
            for k in 0..3 {
                lo[k] = lo[k].min(a[k]);
                hi[k] = hi[k].max(b[k]);
            }
        }
        Camera::fit(view, lo, hi, w, h)
    }

    /// The same view for a picture `factor` times larger (supersampling).
    fn scaled(&self, factor: usize) -> Camera {
        let f = factor as f32;
        Camera {
            scale: self.scale * f,
            offset: [self.offset[0] * f, self.offset[1] * f],
            w: self.w * factor,
            h: self.h * factor,
            ..*self
        }
    }

    /// Projected coordinates before the screen mapping, and "nearness" (larger = closer).
    #[inline]
    fn project_unit(&self, p: V3) -> (f32, f32, f32) {
        let d = sub(p, self.center);
        let (x, y, z) = (dot(d, self.right), dot(d, self.up), dot(d, self.back));
        match self.dist {
            None => (x, y, z),
            Some(dd) => {
                let inv = 1.0 / (dd - z).max(1e-6);
                (x * inv, y * inv, inv)
            }
        }
    }

    /// Screen position (pixels, y down) and nearness of a world point.
    #[inline]
    pub fn project(&self, p: V3) -> (f32, f32, f32) {
        let (x, y, z) = self.project_unit(p);
        (self.offset[0] + self.scale * x, self.offset[1] - self.scale * y, z)
    }

    /// Unit vector from `p` towards the camera.
    #[inline]
    fn toward_eye(&self, p: V3) -> V3 {
        match self.dist {
            None => self.back,
            Some(d) => {
                let eye = [
                    self.center[0] + d * self.back[0],
                    self.center[1] + d * self.back[1],
                    self.center[2] + d * self.back[2],
                ];
                normalize(sub(eye, p))
            }
        }
    }
}

/// Material, lights and background. Colours are sRGB in [0,1]; shading runs in linear light.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Shading {
    /// Cloth colour on the side the vertex normals point to.
    pub front: V3,
    /// Cloth colour on the other side (two-sided cloth; a slightly different tint helps read folds).
    pub back: V3,
    /// Ambient light (fraction of the base colour).
    pub ambient: f32,
    /// Key light strength and direction in camera space (x right, y up, z towards the viewer).
    pub key: f32,
    pub key_dir: V3,
    /// Headlight (light from the camera) strength.
    pub head: f32,
    /// Small Blinn–Phong highlight of the key light (cloth sheen), strength and exponent.
    pub spec: f32,
    pub shininess: f32,
    /// Background gradient, top and bottom.
    pub bg_top: V3,
    pub bg_bottom: V3,
    /// Supersampling factor per axis (1 = off, 2 = 4 samples per pixel).
    pub ssaa: usize,
    /// Lit cloth colours, or a colour from the surface normal.
    pub look: Look,
}

/// How a surface point gets its colour.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Look {
    /// The cloth (or heat, or tint) colour lit by ambient, key light, headlight and sheen.
    Lit,
    /// A normal map: the camera-space unit normal n (turned towards the camera) as sRGB
    /// `(0.5 + 0.5·g·n_x, 0.5 + 0.5·g·n_y, 0.5 + 0.5·n_z)`, clamped. A tilt of the surface
    /// changes the colour in proportion, so millimetre folds that grey Lambert shading washes
    /// out show as red/green bands; `gain` g > 1 exaggerates the tilt (close-ups). Per-vertex
    /// colours and tints are ignored.
    Normals { gain: f32 },
}

impl Shading {
    /// The default background and supersampling with [`Look::Normals`] of tilt gain `gain`.
    pub fn normals(gain: f32) -> Shading {
        Shading { look: Look::Normals { gain }, ..Shading::default() }
    }
}

impl Default for Shading {
    fn default() -> Self {
        Shading {
            front: [0.85, 0.62, 0.45],
            back: [0.62, 0.70, 0.85],
            ambient: 0.10,
            key: 0.85,
            // Raking light from the upper left: wrinkles turn into light/shade bands.
            key_dir: [-0.75, 0.45, 0.45],
            head: 0.20,
            spec: 0.08,
            shininess: 24.0,
            bg_top: [0.96, 0.96, 0.97],
            bg_bottom: [0.80, 0.82, 0.85],
            ssaa: 2,
            look: Look::Lit,
        }
    }
}

#[inline]
fn to_linear(c: f32) -> f32 {
    c.max(0.0).powf(2.2)
}
#[inline]
fn to_srgb8(c: f32) -> u8 {
    (c.clamp(0.0, 1.0).powf(1.0 / 2.2) * 255.0 + 0.5) as u8
}

/// One mesh of a picture: the cloth (optionally heat-coloured) or a prop such as a collision
/// sphere drawn in a flat `tint`.
#[derive(Clone, Copy, Debug)]
pub struct Layer<'a> {
    /// The vertices (a grid's; any other mesh as a one-row "grid" of its vertices, with `tris`).
    pub mesh: &'a GridMesh,
    /// The triangles to draw, for a mesh that is not a grid (`None`: the grid's own).
    pub tris: Option<&'a [[usize; 3]]>,
    pub colors: Option<ScalarColors<'a>>,
    /// sRGB colour for both sides instead of the cloth colours (props).
    pub tint: Option<V3>,
}

/// Renders `mesh` as seen by `cam` into a `cam.w × cam.h` picture.
pub fn render_mesh(
    mesh: &GridMesh,
    cam: &Camera,
    shade: &Shading,
    colors: Option<ScalarColors<'_>>,
) -> Result<Rgb8> {
    render_layers(&[Layer { tris: None, mesh, colors, tint: None }], cam, shade)
}

/// [`render_mesh`] without per-vertex colours, shaded with the given unit per-vertex
/// `normals` instead of the mesh's own (e.g. exaggerated ones, see [`super::closeup`]).
pub fn render_mesh_with_normals(
    mesh: &GridMesh,
    normals: &[V3],
    cam: &Camera,
    shade: &Shading,
) -> Result<Rgb8> {
    rasterize(&[Layer { tris: None, mesh, colors: None, tint: None }], &[normals], cam, shade)
}

/// Renders several meshes into one z-buffer (cloth and props), as seen by `cam`.
pub fn render_layers(layers: &[Layer<'_>], cam: &Camera, shade: &Shading) -> Result<Rgb8> {
    rasterize(layers, &[], cam, shade)
}

/// [`render_layers`] where `normals[k]`, if given, shades layer k instead of its vertex normals.
fn rasterize(layers: &[Layer<'_>], normals: &[&[V3]], cam: &Camera, shade: &Shading) -> Result<Rgb8> {
    for (k, l) in layers.iter().enumerate() {
        if normals.get(k).is_some_and(|n| n.len() != l.mesh.pos.len()) {
            return Err(Error::shape(format!(
                "render: {} normals for a mesh of {} vertices",
                normals[k].len(),
                l.mesh.pos.len()
            )));
        }
        if let Some(c) = &l.colors {
            if c.values.len() != l.mesh.pos.len() {
                return Err(Error::shape(format!(
                    "render: {} per-vertex values for a mesh of {} vertices",
                    c.values.len(),
                    l.mesh.pos.len()
                )));
            }
        }
    }
    let ss = shade.ssaa.clamp(1, 4);
    let cam_s = cam.scaled(ss);
    let (w, h) = (cam_s.w, cam_s.h);
    let mut depth = vec![f32::NEG_INFINITY; w * h];
    let mut color = vec![[0.0f32; 3]; w * h];
    for y in 0..h {
        let t = y as f32 / (h.max(2) - 1) as f32;
        let bg: V3 =
            std::array::from_fn(|k| to_linear(shade.bg_top[k] + t * (shade.bg_bottom[k] - shade.bg_top[k])));
        for x in 0..w {
            color[y * w + x] = bg;
        }
    }
    for (li, layer) in layers.iter().enumerate() {
        let (mesh, colors) = (layer.mesh, layer.colors);
        let tris = layer.tris.map_or_else(|| mesh.triangles(), <[[usize; 3]]>::to_vec);
        let normals = normals.get(li).map_or_else(
            || match layer.tris {
                Some(t) => triangle_normals(&mesh.pos, t),
                None => vertex_normals(mesh),
            },
            |n| n.to_vec(),
        );
        let scr: Vec<(f32, f32, f32)> = mesh.pos.iter().map(|&p| cam_s.project(p)).collect();
        // Vertex normals in camera space.
        let ncam: Vec<V3> =
            normals.iter().map(|&n| [dot(n, cam.right), dot(n, cam.up), dot(n, cam.back)]).collect();
        let base_lin = |side: V3, v: usize| -> V3 {
            match &colors {
                Some(c) => {
                    let span = (c.hi - c.lo).abs().max(1e-30);
                    let col = heat_color((c.values[v] - c.lo) / span);
                    col.map(to_linear)
                }
                None => side.map(to_linear),
            }
        };
        let key = normalize(shade.key_dir);
        let half = normalize([key[0], key[1], key[2] + 1.0]);
        for &[a, b, c] in &tris {
            let (p0, p1, p2) = (scr[a], scr[b], scr[c]);
            let area = (p1.0 - p0.0) * (p2.1 - p0.1) - (p2.0 - p0.0) * (p1.1 - p0.1);
            if area.abs() < 1e-12 || !area.is_finite() {
                continue;
            }
            // Which side of the cloth faces the camera.
            let (wa, wb, wc) = (mesh.pos[a], mesh.pos[b], mesh.pos[c]);
            let fnorm = cross(sub(wb, wa), sub(wc, wa));
            let centroid: V3 = std::array::from_fn(|k| (wa[k] + wb[k] + wc[k]) / 3.0);
            let front = dot(fnorm, cam.toward_eye(centroid)) >= 0.0;
            let sgn = if front { 1.0 } else { -1.0 };
            let side = layer.tint.unwrap_or(if front { shade.front } else { shade.back });
            let (c0, c1, c2) = (base_lin(side, a), base_lin(side, b), base_lin(side, c));
            let xmin = p0.0.min(p1.0).min(p2.0).floor().max(0.0) as usize;
            let ymin = p0.1.min(p1.1).min(p2.1).floor().max(0.0) as usize;
            let xmax = (p0.0.max(p1.0).max(p2.0).ceil().max(0.0) as usize).min(w);
            let ymax = (p0.1.max(p1.1).max(p2.1).ceil().max(0.0) as usize).min(h);
            let inv = 1.0 / area;
            for y in ymin..ymax {
                let py = y as f32 + 0.5;
                for x in xmin..xmax {
                    let px = x as f32 + 0.5;
                    // Barycentric weights from edge functions, normalised by the signed area.
                    let l0 = ((p1.0 - px) * (p2.1 - py) - (p2.0 - px) * (p1.1 - py)) * inv;
                    let l1 = ((p2.0 - px) * (p0.1 - py) - (p0.0 - px) * (p2.1 - py)) * inv;
                    let l2 = 1.0 - l0 - l1;
                    if l0 < 0.0 || l1 < 0.0 || l2 < 0.0 {
                        continue;
                    }
                    let z = l0 * p0.2 + l1 * p1.2 + l2 * p2.2;
                    let i = y * w + x;
                    if z <= depth[i] {
                        continue;
                    }
                    depth[i] = z;
                    let n: V3 =
                        std::array::from_fn(|k| sgn * (l0 * ncam[a][k] + l1 * ncam[b][k] + l2 * ncam[c][k]));
                    let n = normalize(n);
                    if let Look::Normals { gain } = shade.look {
                        let c = |v: f32| to_linear((0.5 + 0.5 * v).clamp(0.0, 1.0));
                        color[i] = [c(gain * n[0]), c(gain * n[1]), c(n[2])];
                        continue;
                    }
                    let diff = shade.ambient + shade.key * dot(n, key).max(0.0) + shade.head * n[2].max(0.0);
                    let spec = shade.spec * dot(n, half).max(0.0).powf(shade.shininess);
                    color[i] = std::array::from_fn(|k| (l0 * c0[k] + l1 * c1[k] + l2 * c2[k]) * diff + spec);
                }
            }
        }
    }
    // Box filter down to the output size.
    let mut out = Rgb8::new(cam.w, cam.h, BLACK);
    let norm = 1.0 / (ss * ss) as f32;
    for y in 0..cam.h {
        for x in 0..cam.w {
            let mut acc = [0.0f32; 3];
            for sy in 0..ss {
                for sx in 0..ss {
                    let c = color[(y * ss + sy) * w + x * ss + sx];
                    for k in 0..3 {
                        acc[k] += c[k];
                    }
                }
            }
            out.set(x, y, acc.map(|v| to_srgb8(v * norm)));
        }
    }
    Ok(out)
}

/// Area-weighted unit vertex normals of the triangles `tris` over `pos` ((0, 0, 1) for a vertex
/// in none).
pub fn triangle_normals(pos: &[V3], tris: &[[usize; 3]]) -> Vec<V3> {
    let mut n = vec![[0.0f32; 3]; pos.len()];
    for &[a, b, c] in tris {
        let f = cross(sub(pos[b], pos[a]), sub(pos[c], pos[a]));
        for v in [a, b, c] {
            for k in 0..3 {
                n[v][k] += f[k];
            }
        }
    }
    n.into_iter().map(|v| crate::geom::vec3::normalize_or(v, [0.0, 0.0, 1.0])).collect()
}

/// A UV sphere as a grid mesh (`2·segments + 1` columns around, `segments + 1` rows from pole
/// to pole; seam and poles duplicated), e.g. a collision sphere to draw beside the cloth.
/// `center`, `radius` in metres.
pub fn sphere_mesh(center: V3, radius: f32, segments: usize) -> GridMesh {
    let n = segments.max(3);
    let (w, h) = (2 * n + 1, n + 1);
    let mut pos = Vec::with_capacity(w * h);
    for j in 0..h {
        let th = std::f32::consts::PI * j as f32 / n as f32;
        for i in 0..w {
            let ph = std::f32::consts::PI * i as f32 / n as f32;
            pos.push([
                center[0] + radius * th.sin() * ph.cos(),
                center[1] + radius * th.cos(),
                center[2] + radius * th.sin() * ph.sin(),
            ]);
        }
    }
    GridMesh::new(w, h, pos)
}

/// Grey of props (spheres) in [`render_row_with_props`].
pub const PROP_TINT: V3 = [0.72, 0.72, 0.70];

/// One tile of a comparison row: a mesh, its label, optional per-vertex scalars.
pub struct Tile<'a> {
    pub mesh: &'a GridMesh,
    pub label: &'a str,
    pub colors: Option<ScalarColors<'a>>,
}

/// Renders the tiles side by side with ONE camera fitted to all of them (so LR, bicubic,
/// anisocb and HR are comparable), each `tile_w × tile_h` px, labelled, `gap` px apart.
pub fn render_row(
    tiles: &[Tile<'_>],
    view: &View,
    shade: &Shading,
    tile_w: usize,
    tile_h: usize,
    gap: usize,
) -> Result<Rgb8> {
    render_row_with_props(tiles, &[], view, shade, (tile_w, tile_h), gap)
}

/// [`render_row`] with props (e.g. [`sphere_mesh`] of the scene's colliders) drawn in grey in
/// every tile. The camera is fitted to the cloth tiles only; props may run off the picture.
pub fn render_row_with_props(
    tiles: &[Tile<'_>],
    props: &[GridMesh],
    view: &View,
    shade: &Shading,
    (tile_w, tile_h): (usize, usize),
    gap: usize,
) -> Result<Rgb8> {
    let meshes: Vec<&GridMesh> = tiles.iter().map(|t| t.mesh).collect();
    let cam = Camera::fit_meshes(view, &meshes, tile_w, tile_h)?;
    let scale = if tile_h >= 256 { 2 } else { 1 };
    let mut pics = Vec::with_capacity(tiles.len());
    for t in tiles {
        let mut layers = vec![Layer { tris: None, mesh: t.mesh, colors: t.colors, tint: None }];
        layers.extend(props.iter().map(|m| Layer {
            tris: None,
            mesh: m,
            colors: None,
            tint: Some(PROP_TINT),
        }));
        let mut p = render_layers(&layers, &cam, shade)?;
        if !t.label.is_empty() {
            p.label(t.label, scale);
        }
        pics.push(p);
    }
    Ok(hstack(&pics, gap, WHITE))
}
