//! OBJ sequences: frame files in natural order, each frame put in the first frame's vertex
//! order (among the grid's 8 symmetries) as it is read.

use super::mesh::{GridMesh, GridSymmetry};
use super::obj::*;
use super::surface::Surface;
use crate::error::{Error, Result};
use std::cell::RefCell;
use std::path::{Path, PathBuf};

/// Natural order of file names: digit runs compare as numbers (`frame_2` before `frame_10`).
pub fn natural_cmp(a: &str, b: &str) -> std::cmp::Ordering {
    use std::cmp::Ordering;
    let (a, b) = (a.as_bytes(), b.as_bytes());
    let (mut i, mut j) = (0, 0);
    while i < a.len() && j < b.len() {
        if a[i].is_ascii_digit() && b[j].is_ascii_digit() {
            let (si, sj) = (i, j);
            while i < a.len() && a[i].is_ascii_digit() {
                i += 1;
            }
            while j < b.len() && b[j].is_ascii_digit() {
                j += 1;
            }
            let na = std::str::from_utf8(&a[si..i]).unwrap_or("0").trim_start_matches('0');
            let nb = std::str::from_utf8(&b[sj..j]).unwrap_or("0").trim_start_matches('0');
            let o = na.len().cmp(&nb.len()).then_with(|| na.cmp(nb));
            if o != Ordering::Equal {
                return o;
            }
        } else {
            if a[i] != b[j] {
                return a[i].cmp(&b[j]);
            }
            i += 1;
            j += 1;
        }
    }
    (a.len() - i).cmp(&(b.len() - j)).then_with(|| a.cmp(b))
}

/// The `.obj` files of a directory in natural order.
pub fn list_obj_files(dir: &Path) -> Result<Vec<PathBuf>> {
    let rd = std::fs::read_dir(dir).map_err(|e| Error::io(dir, e))?;
    let mut files: Vec<PathBuf> = Vec::new();
    for e in rd {
        let p = e.map_err(|e| Error::io(dir, e))?.path();
        let obj = p.extension().is_some_and(|x| x.eq_ignore_ascii_case("obj"));
        if obj && p.is_file() {
            files.push(p);
        } else if obj && !p.exists() {
            // A link to a frame that is gone: skipping it would drop a frame from the shot.
            return Err(Error::format(
                &p,
                "a link to a file that does not exist: restore the frame, or remove the link",
            ));
        }
    }
    files.sort_by(|a, b| natural_cmp(&a.to_string_lossy(), &b.to_string_lossy()));
    if files.is_empty() {
        return Err(Error::format(dir, "no .obj files in this directory"));
    }
    Ok(files)
}

/// An OBJ sequence read one frame at a time (memory for one frame, whatever the shot's
/// length). The first file fixes the grid's orientation, size, UVs and attributes; every other
/// frame must be a grid of the same size and is returned in the first file's vertex order.
///
/// A frame may number its vertices differently (exporters renumber a grid after an edit:
/// rows reversed, transposed, with the faces renumbered to match or written from the same
/// template). The grid is known up to its 8 symmetries ([`GridSymmetry`]); the one that fits
/// is the one that keeps the cloth where the previous frame left it. A frame whose faces are
/// those of the previous frame keeps the previous frame's numbering unless another symmetry
/// fits [`CLEARLY_BETTER`] times better; a frame with other faces takes the best fit, and is
/// refused, naming it, when two symmetries fit about equally (a sheet folded exactly onto
/// itself). Where the files have one UV per vertex, the UVs decide first: a frame whose UVs sit
/// on the same vertices as the frame before's is numbered as it was, however far the cloth
/// turned (a sheet that really turns 180° between two frames stays itself), and one whose UVs
/// moved with a symmetry is renumbered by it. Frames are aligned in order from the first, so reading frame k first aligns the
/// frames before it once (a farm slice reads the shot's earlier frames): every run gives
/// frame k the same orientation.
pub struct ObjSequence {
    pub files: Vec<PathBuf>,
    /// The first file as a grid.
    pub first: ObjGrid,
    faces: Vec<Vec<u32>>,
    vertices: usize,
    align: RefCell<Alignment>,
}

/// Squared-distance ratio under which one symmetry fits clearly better than another
/// ([`ObjSequence`]): an RMS distance under about a third.
pub const CLEARLY_BETTER: f64 = 0.1;

/// What [`ObjSequence`] knows of its frames' numbering.
struct Alignment {
    /// Per frame, the symmetry that takes the frame's grid as read to the first file's order;
    /// known for frames `0..=last`.
    sym: Vec<Option<GridSymmetry>>,
    last: usize,
    /// The last aligned frame's positions and UVs (first file's order) and its faces.
    last_pos: Vec<[f32; 3]>,
    last_uv: Option<Vec<[f32; 2]>>,
    last_faces: Vec<Vec<u32>>,
    /// Frames found renumbered, for the caller to report ([`ObjSequence::take_notes`]).
    notes: Vec<String>,
}

/// A frame as read: its grid in the order the file's numbering gives, faces and attributes.
struct RawFrame {
    grid: GridMesh,
    /// One UV per grid vertex (the grid's order as read), when the file has them.
    uv: Option<Vec<[f32; 2]>>,
    faces: Vec<Vec<u32>>,
    attrs: ObjAttrs,
}

impl ObjSequence {
    /// Open a sequence (reads the first file).
    pub fn open(paths: &[PathBuf]) -> Result<ObjSequence> {
        let Some(p) = paths.first() else { return Err(Error::config("no OBJ files given")) };
        let m = parse_obj(&read_obj_text(p)?, p)?;
        let first = obj_to_grid(&m, p)?;
        let mut sym = vec![None; paths.len()];
        sym[0] = Some(GridSymmetry::IDENTITY);
        let align = RefCell::new(Alignment {
            sym,
            last: 0,
            last_pos: first.mesh.pos.clone(),
            last_uv: first.uv.clone(),
            last_faces: m.faces.clone(),
            notes: Vec::new(),
        });
        Ok(ObjSequence { files: paths.to_vec(), first, faces: m.faces, vertices: m.pos.len(), align })
    }

    pub fn len(&self) -> usize {
        self.files.len()
    }

    pub fn is_empty(&self) -> bool {
        self.files.is_empty()
    }

    /// Frame `k` as a grid in the first file's orientation.
    pub fn frame(&self, k: usize) -> Result<GridMesh> {
        Ok(self.frame_and_attrs(k)?.0)
    }

    /// Frame `k` in the first file's vertex order, and what its file carries besides geometry
    /// (exporters write per-frame `mtllib`s: Blender's `cloth0002.obj` uses `cloth0002.mtl`);
    /// faces wind as the first file's do.
    pub fn frame_and_attrs(&self, k: usize) -> Result<(GridMesh, ObjAttrs)> {
        let raw = self.raw(k)?;
        let known = self.align.borrow().sym[k];
        let s = match known {
            Some(s) => s,
            None => {
                let last = self.align.borrow().last;
                for n in last + 1..k {
                    let r = self.raw(n)?;
                    self.align_next(n, &r)?;
                }
                self.align_next(k, &raw)?
            }
        };
        let attrs = ObjAttrs { flipped: self.first.attrs.flipped, ..raw.attrs };
        Ok((s.apply(&raw.grid), attrs))
    }

    /// Notes on frames found numbered differently from the frame before them, once each.
    pub fn take_notes(&self) -> Vec<String> {
        std::mem::take(&mut self.align.borrow_mut().notes)
    }

    /// Read frame `k`: a file with the first file's faces reuses its grid order, any other is
    /// recovered as a grid of its own.
    fn raw(&self, k: usize) -> Result<RawFrame> {
        let p = &self.files[k];
        let m = parse_obj(&read_obj_text(p)?, p)?;
        let g0 = &self.first;
        if m.faces == self.faces && m.pos.len() == self.vertices {
            let grid =
                GridMesh::new(g0.mesh.w, g0.mesh.h, g0.order.iter().map(|&v| m.pos[v as usize]).collect());
            let uv = grid_uv(&m, &g0.order).0;
            return Ok(RawFrame { grid, uv, faces: m.faces, attrs: m.attrs });
        }
        let g = obj_to_grid(&m, p)?;
        let fits = |s: GridSymmetry| s.dims(g.mesh.w, g.mesh.h) == (g0.mesh.w, g0.mesh.h);
        if !GridSymmetry::all().into_iter().any(fits) {
            return Err(Error::format(
                p,
                format!(
                    "grid is {}x{}, but the first frame is {}x{}",
                    g.mesh.w, g.mesh.h, g0.mesh.w, g0.mesh.h
                ),
            ));
        }
        Ok(RawFrame { grid: g.mesh, uv: g.uv, faces: m.faces, attrs: g.attrs })
    }

    /// Find frame `n`'s symmetry (frame `n - 1` is the last aligned one) and make it the last.
    fn align_next(&self, n: usize, raw: &RawFrame) -> Result<GridSymmetry> {
        let mut al = self.align.borrow_mut();
        debug_assert_eq!(al.last + 1, n);
        let (w, h) = (self.first.mesh.w, self.first.mesh.h);
        let (gw, gh) = (raw.grid.w, raw.grid.h);
        let cost = |s: GridSymmetry| -> f64 {
            let idx = s.source_index(gw, gh);
            idx.iter().zip(&al.last_pos).map(|(&k, q)| dist2(raw.grid.pos[k], *q)).sum()
        };
        let mut fits: Vec<(f64, GridSymmetry)> = GridSymmetry::all()
            .into_iter()
            .filter(|s| s.dims(gw, gh) == (w, h))
            .map(|s| (cost(s), s))
            .collect();
        fits.sort_by(|a, b| a.0.total_cmp(&b.0));
        let prev = al.sym[n - 1].expect("aligned in order");
        let same_faces = raw.faces == al.last_faces;
        let (best_cost, best) = fits[0];
        let rms_mm = |c: f64| 1e3 * (c / (w * h) as f64).sqrt();
        // The UVs' say: the symmetries under which this frame's UVs are the last frame's.
        let uv_fits: Vec<GridSymmetry> = match (&raw.uv, &al.last_uv) {
            (Some(uv), Some(last)) => fits
                .iter()
                .map(|f| f.1)
                .filter(|s| s.source_index(gw, gh).iter().zip(last).all(|(&k, q)| uv[k] == *q))
                .collect(),
            _ => Vec::new(),
        };
        let s = if let [only] = uv_fits.as_slice() {
            *only
        } else if same_faces {
            let keep = fits.iter().find(|f| f.1 == prev).map_or(f64::INFINITY, |f| f.0);
            if best != prev && best_cost < CLEARLY_BETTER * keep {
                best
            } else {
                prev
            }
        } else {
            let second = fits.get(1).map_or(f64::INFINITY, |f| f.0);
            // (NaN-safe: a NaN cost is never clearly better.)
            let clear = best_cost < CLEARLY_BETTER * second;
            if !clear {
                return Err(Error::format(
                    &self.files[n],
                    format!(
                        "this frame numbers its vertices differently from {}, and two orientations \
                         of the grid fit the cloth about equally (RMS {:.1} mm and {:.1} mm from the \
                         frame before), so it cannot be put in the first frame's vertex order; \
                         export every frame with the same vertex order",
                        self.files[n - 1].display(),
                        rms_mm(best_cost),
                        rms_mm(second)
                    ),
                ));
            }
            best
        };
        if s != prev {
            let note = format!(
                "{}: vertices numbered differently from {} (its grid is the first frame's with {}); \
                 written in the first frame's vertex order",
                self.files[n].display(),
                self.files[n - 1].display(),
                s.describe()
            );
            al.notes.push(note);
        }
        al.sym[n] = Some(s);
        al.last = n;
        al.last_pos = s.apply(&raw.grid).pos;
        al.last_uv = raw.uv.as_ref().map(|uv| s.source_index(gw, gh).iter().map(|&k| uv[k]).collect());
        al.last_faces.clone_from(&raw.faces);
        Ok(s)
    }
}

/// Squared distance in f64.
fn dist2(a: [f32; 3], b: [f32; 3]) -> f64 {
    (0..3).map(|k| (a[k] as f64 - b[k] as f64).powi(2)).sum()
}

/// Read a whole OBJ sequence into memory (see [`ObjSequence`]) and its face style.
pub fn read_obj_sequence(paths: &[PathBuf]) -> Result<(Vec<GridMesh>, FaceStyle)> {
    let seq = ObjSequence::open(paths)?;
    let frames = (0..seq.len()).map(|k| seq.frame(k)).collect::<Result<Vec<_>>>()?;
    Ok((frames, seq.first.style))
}

/// An OBJ sequence of a mesh that is not a regular grid (issue 45), read one frame at a time:
/// the first file fixes the topology ([`Surface`]), UVs and tags; every other frame must have
/// the same faces and vertex count (its positions are taken in its own vertex order, which is
/// the first file's when the faces are equal).
pub struct MeshSequence {
    pub files: Vec<PathBuf>,
    /// The first file as parsed.
    pub first: ObjMesh,
    pub surface: Surface,
}

impl MeshSequence {
    /// The sequence `paths` whose first file parsed as `first`; its faces are checked as a
    /// cloth surface.
    pub fn open(paths: &[PathBuf], first: ObjMesh) -> Result<MeshSequence> {
        let Some(p) = paths.first() else { return Err(Error::config("no OBJ files given")) };
        let surface = Surface::new(first.pos.len(), first.faces.clone(), p)?;
        Ok(MeshSequence { files: paths.to_vec(), first, surface })
    }

    pub fn len(&self) -> usize {
        self.files.len()
    }

    pub fn is_empty(&self) -> bool {
        self.files.is_empty()
    }

    /// Frame `k`'s positions and what its file carries besides geometry.
    pub fn frame_and_attrs(&self, k: usize) -> Result<(Vec<[f32; 3]>, ObjAttrs)> {
        let p = &self.files[k];
        let m = if k == 0 { self.first.clone() } else { parse_obj(&read_obj_text(p)?, p)? };
        self.surface.check_same(m.pos.len(), &m.faces, k, p)?;
        Ok((m.pos, m.attrs))
    }
}
