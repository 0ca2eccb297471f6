//! USD in and out for `anisocb upscale` (feature `usd`, through the `openusd` crate): the
//! animated `Mesh` prim of a `.usda`/`.usdc`/`.usd` file read as LR frames, and the HR result
//! written back as `.usda` with the same prim path, static transforms, UVs and time codes.
//!
//! The upscale itself is the any-mesh OBJ path: [`UsdShot::write_obj_frames`] writes the LR
//! frames as OBJ (positions printed so that they read back as the same `f32`s), the pipeline
//! upscales them, and [`UsdShot::write_hr`] turns the HR OBJ frames into the USD output.

use crate::error::{Error, Result};
use crate::geom::obj::{parse_obj, read_obj_text};
use openusd::sdf::{self, ChildrenKey, FieldKey, SpecType, Specifier, Value};
use openusd::usd::{Prim, Stage};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// Whether `p` names a USD file (`.usd`, `.usda`, `.usdc`).
pub fn is_usd(p: &Path) -> bool {
    p.extension().and_then(|e| e.to_str()).is_some_and(|e| {
        let e = e.to_ascii_lowercase();
        e == "usd" || e == "usda" || e == "usdc"
    })
}

/// A prim on the way to the mesh (or the mesh itself) and its transform ops.
pub struct XformPrim {
    pub name: String,
    pub type_name: String,
    /// `xformOpOrder`, if authored.
    pub order: Option<Value>,
    /// Each op attribute: (name, type name, value); an animated op's value is its
    /// `Value::TimeSamples`, written back as they were read.
    pub ops: Vec<(String, String, Value)>,
}

/// The animated mesh of a USD file.
pub struct UsdShot {
    pub file: PathBuf,
    /// The mesh prim's path, e.g. `/World/Cloth`.
    pub prim: String,
    /// The prims from the root down to the mesh, the mesh last.
    pub chain: Vec<XformPrim>,
    pub faces: Vec<Vec<u32>>,
    pub uv: Vec<[f32; 2]>,
    pub face_uv: Vec<Vec<u32>>,
    pub times: Vec<f64>,
    /// Points as authored, one list per time code.
    pub frames: Vec<Vec<[f32; 3]>>,
    pub up_axis: String,
    pub meters_per_unit: f64,
    pub start: Option<f64>,
    pub end: Option<f64>,
    pub tcps: Option<f64>,
    /// Notes for the user (up axis, units).
    pub notes: Vec<String>,
}

fn bad_out(dst: &Path, e: impl std::fmt::Display) -> Error {
    Error::format(dst, format!("cannot build the USD output: {e}"))
}

fn err(file: &Path, e: impl std::fmt::Display) -> Error {
    Error::format(file, e.to_string())
}

fn ints(v: Option<Value>) -> Option<Vec<i32>> {
    match v? {
        Value::IntVec(v) => Some(v),
        _ => None,
    }
}

fn points(v: &Value) -> Option<Vec<[f32; 3]>> {
    match v {
        Value::Vec3fVec(v) => Some(v.iter().map(|p| [p.x, p.y, p.z]).collect()),
        Value::Vec3dVec(v) => Some(v.iter().map(|p| [p.x as f32, p.y as f32, p.z as f32]).collect()),
        _ => None,
    }
}

fn token(v: Option<Value>) -> Option<String> {
    match v? {
        Value::Token(t) => Some(t.as_str().to_string()),
        Value::String(s) => Some(s),
        _ => None,
    }
}

/// Every prim under `root`, depth first.
fn walk(root: Prim, file: &Path, out: &mut Vec<Prim>) -> Result<()> {
    for c in root.children().map_err(|e| err(file, e))? {
        out.push(c.clone());
        walk(c, file, out)?;
    }
    Ok(())
}

/// The transform ops of `prim`: each static op's value, or an animated op's time samples.
fn xform_of(stage: &Stage, path: &sdf::Path, file: &Path) -> Result<XformPrim> {
    let prim = stage.prim(path.clone());
    let name = path.name().unwrap_or_default().to_string();
    let type_name =
        prim.type_name().map_err(|e| err(file, e))?.map(|t| t.as_str().to_string()).unwrap_or_default();
    let order_attr = prim.attribute("xformOpOrder");
    let order = order_attr.get::<Value>().map_err(|e| err(file, e))?;
    let mut ops = Vec::new();
    if let Some(Value::TokenVec(names)) = &order {
        for n in names {
            let n = n.as_str();
            if n.starts_with('!') {
                continue; // !resetXformStack! and inverted ops name no new attribute
            }
            let a = prim.attribute(n);
            let ty =
                a.type_name().map_err(|e| err(file, e))?.map(|t| t.as_str().to_string()).unwrap_or_default();
            let samples = a.time_samples().map_err(|e| err(file, e))?.filter(|s| !s.is_empty());
            if let Some(s) = samples {
                ops.push((n.to_string(), ty, Value::TimeSamples(s)));
            } else if let Some(v) = a.get::<Value>().map_err(|e| err(file, e))? {
                ops.push((n.to_string(), ty, v));
            }
        }
    }
    Ok(XformPrim { name, type_name, order, ops })
}

impl XformPrim {
    /// The names of the ops that are animated (time samples).
    pub fn animated(&self) -> Vec<&str> {
        self.ops
            .iter()
            .filter(|(_, _, v)| matches!(v, Value::TimeSamples(_)))
            .map(|(n, _, _)| n.as_str())
            .collect()
    }
}

impl UsdShot {
    /// Reads the animated mesh of `file`: the single `Mesh` prim with time-sampled `points`
    /// (the first such in depth-first order when there are several).
    pub fn read(file: &Path) -> Result<UsdShot> {
        if !file.is_file() {
            return Err(Error::format(file, "no such USD file"));
        }
        let s = file.to_str().ok_or_else(|| Error::format(file, "the USD path is not UTF-8"))?;
        let stage = Stage::open(s).map_err(|e| Error::format(file, format!("cannot read USD: {e:#}")))?;
        let mut prims = Vec::new();
        walk(stage.prim(sdf::Path::abs_root()), file, &mut prims)?;
        let mut meshes = Vec::new();
        for p in prims {
            if p.type_name().map_err(|e| err(file, e))?.is_some_and(|t| t.as_str() == "Mesh") {
                let n = p.attribute("points").num_time_samples().map_err(|e| err(file, e))?;
                meshes.push((p, n));
            }
        }
        let Some((mesh, _)) = meshes.iter().find(|m| m.1 > 0) else {
            let list: Vec<String> = meshes.iter().map(|m| m.0.path().to_string()).collect();
            return Err(Error::format(
                file,
                if list.is_empty() {
                    "no Mesh prim in this USD file: anisocb upscales an animated mesh (points with time samples)"
                        .to_string()
                } else {
                    format!(
                        "no Mesh prim here has time-sampled points (found {}, all static): export the cloth \
                         animated (Blender: File > Export > USD with Animation on)",
                        list.join(", ")
                    )
                },
            ));
        };
        let mut notes = Vec::new();
        if meshes.len() > 1 {
            let list: Vec<String> =
                meshes.iter().map(|m| format!("{} ({} samples)", m.0.path(), m.1)).collect();
            notes.push(format!("several meshes ({}); upscaling {}", list.join(", "), mesh.path()));
        }
        let path = mesh.path().clone();
        let get = |name: &str| mesh.attribute(name).get::<Value>().map_err(|e| err(file, e));
        let counts = ints(get("faceVertexCounts")?)
            .ok_or_else(|| Error::format(file, format!("{path} has no faceVertexCounts (int[])")))?;
        let idx = ints(get("faceVertexIndices")?)
            .ok_or_else(|| Error::format(file, format!("{path} has no faceVertexIndices (int[])")))?;
        let samples = mesh.attribute("points").time_samples().map_err(|e| err(file, e))?.unwrap_or_default();
        let mut times = Vec::new();
        let mut frames = Vec::new();
        for (t, v) in &samples {
            let p = points(v).ok_or_else(|| {
                Error::format(file, format!("{path}.points at time {t} is not a point3f[] array"))
            })?;
            times.push(*t);
            frames.push(p);
        }
        let n = frames[0].len();
        if let Some((t, f)) = times.iter().zip(&frames).find(|(_, f)| f.len() != n) {
            return Err(Error::format(
                file,
                format!("{path}.points has {} points at time {t} but {n} at time {}", f.len(), times[0]),
            ));
        }
        let mut faces = Vec::with_capacity(counts.len());
        let mut at = 0usize;
        for &c in &counts {
            let c = c.max(0) as usize;
            let f = idx.get(at..at + c).ok_or_else(|| {
                Error::format(
                    file,
                    format!("{path}: faceVertexIndices is shorter than faceVertexCounts says"),
                )
            })?;
            if let Some(&v) = f.iter().find(|&&v| v < 0 || v as usize >= n) {
                return Err(Error::format(file, format!("{path}: vertex index {v} out of 0..{n}")));
            }
            faces.push(f.iter().map(|&v| v as u32).collect::<Vec<u32>>());
            at += c;
        }
        // UVs: primvars:st (or st), faceVarying or vertex, indexed or not.
        let (mut uv, mut face_uv) = (Vec::new(), Vec::new());
        for name in ["primvars:st", "primvars:UVMap", "primvars:uv"] {
            let a = mesh.attribute(name);
            let Some(Value::Vec2fVec(vals)) = a.get::<Value>().map_err(|e| err(file, e))? else { continue };
            let interp = token(a.get_metadata::<Value>("interpolation").map_err(|e| err(file, e))?)
                .unwrap_or_else(|| "vertex".into());
            let ind = ints(get(&format!("{name}:indices"))?);
            let lookup = |i: usize| -> Option<u32> {
                let j = match &ind {
                    Some(ind) => *ind.get(i)? as usize,
                    None => i,
                };
                (j < vals.len()).then_some(j as u32)
            };
            let mut fu = Vec::with_capacity(faces.len());
            let mut corner = 0usize;
            let mut ok = true;
            for f in &faces {
                let mut c = Vec::with_capacity(f.len());
                for &v in f {
                    let i = match interp.as_str() {
                        "faceVarying" => corner,
                        "vertex" | "varying" => v as usize,
                        _ => usize::MAX,
                    };
                    corner += 1;
                    match lookup(i) {
                        Some(j) => c.push(j),
                        None => ok = false,
                    }
                }
                fu.push(c);
            }
            if ok {
                uv = vals.iter().map(|t| [t.x, t.y]).collect();
                face_uv = fu;
            } else {
                notes.push(format!("{path}.{name} ({interp}) does not fit the mesh; UVs left out"));
            }
            break;
        }
        let up_axis =
            token(stage.stage_metadata("upAxis").map_err(|e| err(file, e))?).unwrap_or_else(|| "Y".into());
        let meters_per_unit = match stage.stage_metadata("metersPerUnit").map_err(|e| err(file, e))? {
            Some(Value::Double(m)) => m,
            Some(Value::Float(m)) => m as f64,
            _ => {
                notes.push("metersPerUnit not authored: USD's fallback 0.01 (centimetres) assumed".into());
                0.01
            }
        };
        let grav = match up_axis.as_str() {
            "Z" => "0,0,-9.81",
            _ => "0,-9.81,0",
        };
        notes.push(format!(
            "{}: mesh {path}, {} time codes, up axis {up_axis} (for --physics: --gravity {grav}), \
             {meters_per_unit} metres per unit",
            file.display(),
            times.len()
        ));
        let meta = |k: FieldKey| -> Result<Option<f64>> {
            Ok(match stage.stage_metadata(k.as_str()).map_err(|e| err(file, e))? {
                Some(Value::Double(d)) => Some(d),
                Some(Value::Float(d)) => Some(d as f64),
                Some(Value::Int(d)) => Some(d as f64),
                _ => None,
            })
        };
        let (start, end, tcps) = (
            meta(FieldKey::StartTimeCode)?,
            meta(FieldKey::EndTimeCode)?,
            meta(FieldKey::TimeCodesPerSecond)?,
        );
        let mut chain = Vec::new();
        let mut p = path.clone();
        while p != sdf::Path::abs_root() {
            chain.push(xform_of(&stage, &p, file)?);
            p = p.parent().unwrap_or_else(sdf::Path::abs_root);
        }
        chain.reverse();
        let animated: Vec<String> = chain
            .iter()
            .flat_map(|x| x.animated().into_iter().map(move |n| format!("{}.{n}", x.name)))
            .collect();
        if !animated.is_empty() {
            notes.push(format!(
                "animated transforms ({}) are written to the output as they are: the points are \
                 upscaled in the mesh's own space, where that motion is not (the physics pass, if \
                 on, does not see it either; bake it into the points for that)",
                animated.join(", ")
            ));
        }
        Ok(UsdShot {
            file: file.to_path_buf(),
            prim: path.to_string(),
            chain,
            faces,
            uv,
            face_uv,
            times,
            frames,
            up_axis,
            meters_per_unit,
            start,
            end,
            tcps,
            notes,
        })
    }

    /// The OBJ file name of frame `k`.
    pub fn frame_name(k: usize) -> String {
        format!("frame_{k:04}.obj")
    }

    /// Writes each frame as `dir/frame_NNNN.obj` (positions in metres, UVs, faces).
    pub fn write_obj_frames(&self, dir: &Path) -> Result<()> {
        let scale = self.meters_per_unit as f32;
        for (k, pos) in self.frames.iter().enumerate() {
            let mut s = String::with_capacity(pos.len() * 40 + self.faces.len() * 24);
            for p in pos {
                let p = if scale == 1.0 { *p } else { [p[0] * scale, p[1] * scale, p[2] * scale] };
                let _ = writeln!(s, "v {} {} {}", p[0], p[1], p[2]);
            }
            for t in &self.uv {
                let _ = writeln!(s, "vt {} {}", t[0], t[1]);
            }
            for (i, f) in self.faces.iter().enumerate() {
                s.push('f');
                for (c, &v) in f.iter().enumerate() {
                    match self.face_uv.get(i) {
                        Some(fu) => {
                            let _ = write!(s, " {}/{}", v + 1, fu[c] + 1);
                        }
                        None => {
                            let _ = write!(s, " {}", v + 1);
                        }
                    }
                }
                s.push('\n');
            }
            crate::io::atomic::write_atomic_bytes(&dir.join(Self::frame_name(k)), s.as_bytes())?;
        }
        Ok(())
    }

    /// Writes the HR frames found in `hr` (OBJ, as [`write_obj_frames`](Self::write_obj_frames)
    /// named them) as the `.usda` file `dst`, atomically.
    pub fn write_hr(&self, hr: &Path, dst: &Path) -> Result<()> {
        let mut samples = Vec::new();
        let mut topo = None;
        let inv = 1.0 / self.meters_per_unit as f32;
        for (k, &t) in self.times.iter().enumerate() {
            let f = hr.join(Self::frame_name(k));
            if !f.exists() {
                continue; // outside a --frames slice
            }
            let m = parse_obj(&read_obj_text(&f)?, &f)?;
            let pts: Vec<openusd::gf::Vec3f> = m
                .pos
                .iter()
                .map(|p| if inv == 1.0 { *p } else { [p[0] * inv, p[1] * inv, p[2] * inv] }.into())
                .collect();
            samples.push((t, Value::Vec3fVec(pts)));
            if topo.is_none() {
                topo = Some(m);
            }
        }
        let m = topo.ok_or_else(|| Error::format(hr, "no HR frame was written"))?;
        let mut data = sdf::Data::new();
        let root = data.create_spec(sdf::Path::abs_root(), SpecType::PseudoRoot);
        root.add(ChildrenKey::PrimChildren, Value::TokenVec(vec![self.chain[0].name.as_str().into()]));
        root.add(FieldKey::DefaultPrim, Value::Token(self.chain[0].name.as_str().into()));
        root.add("upAxis", Value::Token(self.up_axis.as_str().into()));
        root.add("metersPerUnit", Value::Double(self.meters_per_unit));
        if let Some(s) = self.start {
            root.add(FieldKey::StartTimeCode, Value::Double(s));
        }
        if let Some(e) = self.end {
            root.add(FieldKey::EndTimeCode, Value::Double(e));
        }
        if let Some(r) = self.tcps {
            root.add(FieldKey::TimeCodesPerSecond, Value::Double(r));
        }
        root.add(
            FieldKey::Documentation,
            Value::String(format!("anisocb upscale of {}", self.file.display())),
        );
        let mut text_path = String::new();
        for (i, x) in self.chain.iter().enumerate() {
            text_path = format!("{text_path}/{}", x.name);
            let path = sdf::path(&text_path).map_err(|e| bad_out(dst, e))?;
            let last = i + 1 == self.chain.len();
            let mut props: Vec<String> = Vec::new();
            let mut attr =
                |data: &mut sdf::Data, name: &str, ty: &str, uniform: bool, field: FieldKey, v: Value| {
                    let p = path.append_property(name).map_err(|e| bad_out(dst, e))?;
                    let s = data.create_spec(p, SpecType::Attribute);
                    s.add(FieldKey::TypeName, Value::Token(ty.into()));
                    if uniform {
                        s.add(FieldKey::Variability, Value::Variability(sdf::Variability::Uniform));
                    }
                    s.add(field, v);
                    props.push(name.to_string());
                    Ok::<_, Error>(())
                };
            if let Some(order) = &x.order {
                attr(&mut data, "xformOpOrder", "token[]", true, FieldKey::Default, order.clone())?;
            }
            for (n, ty, v) in &x.ops {
                let field = if matches!(v, Value::TimeSamples(_)) {
                    FieldKey::TimeSamples
                } else {
                    FieldKey::Default
                };
                attr(&mut data, n, ty, false, field, v.clone())?;
            }
            if last {
                let counts = m.faces.iter().map(|f| f.len() as i32).collect();
                let idx = m.faces.iter().flatten().map(|&v| v as i32).collect();
                attr(
                    &mut data,
                    "faceVertexCounts",
                    "int[]",
                    false,
                    FieldKey::Default,
                    Value::IntVec(counts),
                )?;
                attr(&mut data, "faceVertexIndices", "int[]", false, FieldKey::Default, Value::IntVec(idx))?;
                attr(
                    &mut data,
                    "points",
                    "point3f[]",
                    false,
                    FieldKey::TimeSamples,
                    Value::TimeSamples(samples.clone()),
                )?;
                if !m.uv.is_empty() && m.face_uv.iter().all(|f| !f.is_empty()) {
                    let st = m.uv.iter().map(|t| openusd::gf::Vec2f { x: t[0], y: t[1] }).collect();
                    let ind = m.face_uv.iter().flatten().map(|&v| v as i32).collect();
                    attr(
                        &mut data,
                        "primvars:st",
                        "texCoord2f[]",
                        false,
                        FieldKey::Default,
                        Value::Vec2fVec(st),
                    )?;
                    attr(
                        &mut data,
                        "primvars:st:indices",
                        "int[]",
                        false,
                        FieldKey::Default,
                        Value::IntVec(ind),
                    )?;
                    let p = path.append_property("primvars:st").map_err(|e| bad_out(dst, e))?;
                    if let Some(s) = data.spec_mut(&p) {
                        s.add("interpolation", Value::Token("faceVarying".into()));
                    }
                }
                attr(
                    &mut data,
                    "subdivisionScheme",
                    "token",
                    true,
                    FieldKey::Default,
                    Value::Token("none".into()),
                )?;
            }
            let s = data.create_spec(path.clone(), SpecType::Prim);
            s.add(FieldKey::Specifier, Value::Specifier(Specifier::Def));
            if !x.type_name.is_empty() {
                s.add(FieldKey::TypeName, Value::Token(x.type_name.as_str().into()));
            }
            if !last {
                s.add(
                    ChildrenKey::PrimChildren,
                    Value::TokenVec(vec![self.chain[i + 1].name.as_str().into()]),
                );
            }
            if !props.is_empty() {
                s.add(
                    ChildrenKey::PropertyChildren,
                    Value::TokenVec(props.iter().map(|p| p.as_str().into()).collect()),
                );
            }
        }
        let text = openusd::usda::TextWriter::write_to_string(&data).map_err(|e| bad_out(dst, e))?;
        crate::io::atomic::write_atomic_bytes(dst, text.as_bytes())
    }
}
