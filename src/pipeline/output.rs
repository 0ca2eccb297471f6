//! Where an upscale's HR frames go: OBJ files named like the input's, a point cache, and
//! `.npy` geometry images and maps ([`Outputs`], an [`HrSink`]), each file written atomically;
//! and the checks that keep a run from overwriting its input or writing a file twice.

use super::input::{folder_of, same_file, FrameAttrs, LrFrames, MeshOut};
use super::physics::MeshPhysicsPass;
use crate::error::{Error, Result};
use crate::geom::geometry_image::image_to_mesh;
use crate::geom::layout::MeshLayout;
use crate::geom::{Domain, GridMesh};
use crate::io::atomic::{write_atomic_bytes, AtomicFile};
use crate::io::npy::NpyWriter;
use crate::io::point_cache::{write_frame, CacheFormat};
use crate::pipeline::stream::HrSink;
use crate::sr::upscale::Upscaled;
use std::cell::RefCell;
use std::ops::Range;
use std::path::{Path, PathBuf};
use std::rc::Rc;

/// How an HR image becomes the HR frame's vertices.
#[derive(Clone, Default)]
pub enum Decode {
    /// The grid is the image (Eq 2).
    #[default]
    Grid,
    /// A mesh that is not a grid: its subdivision of the LR frame (waiting in the
    /// [`LrFrames`]) plus the nets' detail at each vertex's chart position; then, with
    /// `--physics`, through the pass's cloth, in shot order.
    Mesh(Rc<MeshLayout>, LrFrames, Option<Rc<RefCell<MeshPhysicsPass>>>),
}

impl Decode {
    /// The HR vertices of entries `keep` of `up`, shot frames `first ..`, in order.
    pub fn frames(
        &self,
        first: usize,
        up: &Upscaled,
        keep: Range<usize>,
        domain: &Domain,
    ) -> Result<Vec<Vec<[f32; 3]>>> {
        match self {
            Decode::Grid => Ok(keep.map(|f| image_to_mesh(&up.hr, f, domain).pos).collect()),
            Decode::Mesh(layout, lr, physics) => {
                let base = up.interpolated();
                keep.enumerate()
                    .map(|(k, f)| {
                        let pos = lr.borrow_mut().remove(&(first + k)).ok_or_else(|| {
                            Error::shape(format!("frame {}: its LR positions were not kept", first + k))
                        })?;
                        let hr = layout.hr_frame(&up.hr, &base, f, domain, &pos, up.keeps_outline());
                        match physics {
                            Some(p) => p.borrow_mut().apply(hr, first + k),
                            None => Ok(hr),
                        }
                    })
                    .collect()
            }
        }
    }
}
/// OBJ frames written one file per frame, the way the input was: each with its own input
/// frame's attributes (from `attrs`; the first frame's for non-OBJ input).
pub struct ObjSink {
    pub dir: PathBuf,
    pub domain: Domain,
    pub mesh: MeshOut,
    pub attrs: FrameAttrs,
    pub decode: Decode,
}

impl HrSink for ObjSink {
    fn write(&mut self, first: usize, up: &Upscaled, keep: Range<usize>) -> Result<()> {
        let (_, _, hh, hw) = up.hr.dims4();
        for (k, pos) in self.decode.frames(first, up, keep, &self.domain)?.into_iter().enumerate() {
            let attrs =
                self.attrs.borrow_mut().remove(&(first + k)).unwrap_or_else(|| self.mesh.attrs.clone());
            let text = match self.decode {
                Decode::Grid => self.mesh.obj_text(&GridMesh::new(hw, hh, pos), &attrs),
                Decode::Mesh(..) => self.mesh.mesh_text(&pos, &attrs),
            };
            write_atomic_bytes(&self.dir.join(&self.mesh.names[first + k]), text.as_bytes())?;
        }
        Ok(())
    }
}

/// An HR point cache, frames appended in order, appearing when complete.
pub struct CacheSink {
    pub file: AtomicFile,
    pub format: CacheFormat,
    pub domain: Domain,
    pub frames: usize,
    pub written: usize,
    pub decode: Decode,
}

impl HrSink for CacheSink {
    fn write(&mut self, first: usize, up: &Upscaled, keep: Range<usize>) -> Result<()> {
        for pos in self.decode.frames(first, up, keep, &self.domain)? {
            let path = self.file.path().to_path_buf();
            write_frame(self.file.writer(), self.format, &pos).map_err(|e| Error::io(path, e))?;
            self.written += 1;
        }
        Ok(())
    }
}

impl CacheSink {
    pub fn finish(self) -> Result<()> {
        if self.written != self.frames {
            return Err(Error::shape(format!(
                "{}: {} of {} frames written",
                self.file.path().display(),
                self.written,
                self.frames
            )));
        }
        self.file.commit()
    }
}

/// Everything `upscale` writes: OBJ frames or geometry.npy, and the maps; the `.npy` files
/// are appended chunk by chunk, each appearing when complete ([`Outputs::finish`]).
pub struct Outputs {
    pub obj: Option<ObjSink>,
    pub cache: Option<CacheSink>,
    pub geometry: Option<NpyWriter>,
    pub maps: Option<(NpyWriter, NpyWriter)>,
}

impl HrSink for Outputs {
    fn write(&mut self, first: usize, up: &Upscaled, keep: Range<usize>) -> Result<()> {
        let (a, n) = (keep.start, keep.len());
        if let Some(o) = &mut self.obj {
            o.write(first, up, keep.clone())?;
        }
        if let Some(c) = &mut self.cache {
            c.write(first, up, keep.clone())?;
        }
        if let Some(g) = &mut self.geometry {
            g.append(&up.hr.slice_batch(a, n))?;
        }
        if let Some((b, e)) = &mut self.maps {
            b.append(&up.boundary().slice_batch(a, n))?;
            e.append(&up.enhance().slice_batch(a, n))?;
        }
        Ok(())
    }
}

impl Outputs {
    pub fn finish(self) -> Result<()> {
        if let Some(c) = self.cache {
            c.finish()?;
        }
        if let Some(g) = self.geometry {
            g.finish()?;
        }
        if let Some((b, e)) = self.maps {
            b.finish()?;
            e.finish()?;
        }
        Ok(())
    }
}

/// Refuse two outputs of one run with the same path (a point cache's rest mesh named like an
/// output frame, …): the later would silently replace the earlier.
pub fn refuse_duplicate_outputs(outputs: &[PathBuf]) -> Result<()> {
    let mut seen = std::collections::HashSet::new();
    match outputs.iter().find(|p| !seen.insert(*p)) {
        Some(p) => Err(Error::config(format!(
            "{} would be written twice by this run (an input's name clashes with an output's); \
             rename the input",
            p.display()
        ))),
        None => Ok(()),
    }
}

/// Refuse, before anything is written, an `--out` that would overwrite the input: the folder
/// of an input file, however it is spelled (`..`, a link to it, or the folder a linked input
/// file really lives in: the HR files would replace the LR ones, and the same command run
/// again would upscale its own output), or a folder where an output file already is one of
/// the input files under another name (a hard link).
pub fn refuse_out_over_input(out: &Path, inputs: &[PathBuf], outputs: &[PathBuf]) -> Result<()> {
    // A folder that does not exist yet holds no input.
    let Ok(out_c) = out.canonicalize() else { return Ok(()) };
    for f in inputs {
        let real_folder = f.canonicalize().ok().and_then(|c| c.parent().map(Path::to_path_buf));
        if [folder_of(f).canonicalize().ok(), real_folder].iter().flatten().any(|d| *d == out_c) {
            return Err(Error::invalid(
                "out",
                format!(
                    "{} is the folder of the input {}: the HR files would replace the input's; \
                 give a new folder for the output (the input is left as it is)",
                    out.display(),
                    f.display()
                ),
            ));
        }
        if let Some(o) = outputs.iter().find(|o| same_file(o, f)) {
            return Err(Error::invalid(
                "out",
                format!(
                    "{}: {} is the input {} under another name (a link), and would be \
                 overwritten; give a new folder for the output",
                    out.display(),
                    o.display(),
                    f.display()
                ),
            ));
        }
    }
    Ok(())
}
