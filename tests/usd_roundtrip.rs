//! USD in and out (`--features usd`, `make usd-test`): an animated disk of triangles and quads
//! under an Xform, as .usda and as .usdc, upscaled; the output read back with openusd gives the
//! prim path, transform, time codes, subdivided topology and the same vertices as the same
//! frames upscaled as an OBJ sequence.
#![cfg(feature = "usd")]

use openusd::sdf::{self, Value};
use openusd::usd::Stage;
use std::fmt::Write as _;
use std::path::Path;

#[path = "common/tempdir.rs"]
mod tempdir;
use tempdir::TempDir;

fn anisocb(args: &[&str]) -> std::process::Output {
    std::process::Command::new(env!("CARGO_BIN_EXE_anisocb")).args(args).output().unwrap()
}

/// A scratch folder removed when the test ends (pass or fail).
fn tmp(name: &str) -> TempDir {
    TempDir::new(&format!("usd-{name}"))
}

const TIMES: [f64; 4] = [1.0, 2.0, 3.0, 4.0];

/// Faces, positions per frame, a UV per vertex.
type Disk = (Vec<Vec<u32>>, Vec<Vec<[f32; 3]>>, Vec<[f32; 2]>);

/// A disk: a centre, two rings of 8; triangles inside, quads outside (not a grid).
fn disk() -> Disk {
    let mut faces = Vec::new();
    for i in 0..8u32 {
        let j = (i + 1) % 8;
        faces.push(vec![0, 1 + i, 1 + j]);
        faces.push(vec![1 + i, 9 + i, 9 + j, 1 + j]);
    }
    let mut frames = Vec::new();
    for (k, _) in TIMES.iter().enumerate() {
        let mut p = vec![[0.0f32, 0.0, 0.02 * k as f32]];
        for r in [0.15f32, 0.3] {
            for i in 0..8 {
                let a = i as f32 * std::f32::consts::TAU / 8.0;
                let z = 0.02 * k as f32 - r * r * (1.0 + 0.3 * (a * 2.0 + k as f32).sin());
                p.push([r * a.cos(), r * a.sin(), z]);
            }
        }
        frames.push(p);
    }
    let uv = frames[0].iter().map(|p| [p[0] / 0.6 + 0.5, p[1] / 0.6 + 0.5]).collect();
    (faces, frames, uv)
}

fn list<T>(v: &[T], f: impl Fn(&T) -> String) -> String {
    v.iter().map(f).collect::<Vec<_>>().join(", ")
}

fn usda_text() -> String {
    let (faces, frames, uv) = disk();
    let mut s = String::from(
        "#usda 1.0\n(\n    defaultPrim = \"World\"\n    upAxis = \"Z\"\n    metersPerUnit = 1\n",
    );
    s += "    startTimeCode = 1\n    endTimeCode = 4\n    timeCodesPerSecond = 24\n)\n\n";
    s += "def Xform \"World\"\n{\n    double3 xformOp:translate = (0, 0, 1)\n";
    s += "    uniform token[] xformOpOrder = [\"xformOp:translate\"]\n\n    def Mesh \"Cloth\"\n    {\n";
    let _ = writeln!(s, "        int[] faceVertexCounts = [{}]", list(&faces, |f| f.len().to_string()));
    let _ =
        writeln!(s, "        int[] faceVertexIndices = [{}]", list(&faces, |f| list(f, |v| v.to_string())));
    s += "        point3f[] points.timeSamples = {\n";
    for (t, p) in TIMES.iter().zip(&frames) {
        let _ = writeln!(s, "            {t}: [{}],", list(p, |p| format!("({}, {}, {})", p[0], p[1], p[2])));
    }
    s += "        }\n";
    let _ = writeln!(
        s,
        "        texCoord2f[] primvars:st = [{}] (\n            interpolation = \"faceVarying\"\n        )",
        list(&uv, |t| format!("({}, {})", t[0], t[1]))
    );
    let _ =
        writeln!(s, "        int[] primvars:st:indices = [{}]", list(&faces, |f| list(f, |v| v.to_string())));
    s += "    }\n}\n";
    s
}

/// The same frames as an OBJ sequence.
fn write_objs(dir: &Path) {
    let (faces, frames, uv) = disk();
    for (k, p) in frames.iter().enumerate() {
        let mut s = String::new();
        for p in p {
            let _ = writeln!(s, "v {} {} {}", p[0], p[1], p[2]);
        }
        for t in &uv {
            let _ = writeln!(s, "vt {} {}", t[0], t[1]);
        }
        for f in &faces {
            let c: Vec<String> = f.iter().map(|v| format!("{}/{}", v + 1, v + 1)).collect();
            let _ = writeln!(s, "f {}", c.join(" "));
        }
        std::fs::write(dir.join(format!("frame_{k:04}.obj")), s).unwrap();
    }
}

fn obj_positions(p: &Path) -> Vec<[f32; 3]> {
    std::fs::read_to_string(p)
        .unwrap()
        .lines()
        .filter_map(|l| l.strip_prefix("v "))
        .map(|l| {
            let v: Vec<f32> = l.split_whitespace().map(|x| x.parse().unwrap()).collect();
            [v[0], v[1], v[2]]
        })
        .collect()
}

fn check_output(usd_in: &Path, root: &Path) {
    let out = root.join("hr_usd");
    let o = anisocb(&["upscale", usd_in.to_str().unwrap(), "--out", out.to_str().unwrap()]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "upscale failed: {err}");
    assert!(err.contains("up axis Z"), "{err}");
    let stem = usd_in.file_stem().unwrap().to_str().unwrap();
    let dst = out.join(format!("{stem}.usda"));
    assert!(!out.join(".anisocb-usd").exists());
    // The completion marker beside the .usda: the run's summary, naming it.
    let summary = std::fs::read_to_string(out.join("upscale.json")).expect("upscale.json beside the .usda");
    assert!(
        summary.contains("\"complete\": true") && summary.contains(&format!("\"{stem}.usda\"")),
        "{summary}"
    );
    assert!(summary.contains("/World/Cloth"), "{summary}");

    // The same frames as OBJ.
    let (objs, hr_obj) = (root.join("objs"), root.join("hr_obj"));
    if !hr_obj.join("frame_0003.obj").exists() {
        std::fs::create_dir_all(&objs).unwrap();
        write_objs(&objs);
        let o = anisocb(&["upscale", objs.to_str().unwrap(), "--out", hr_obj.to_str().unwrap()]);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    }

    let stage = Stage::open(dst.to_str().unwrap()).unwrap();
    assert_eq!(stage.stage_metadata("upAxis").unwrap(), Some(Value::Token("Z".into())));
    assert_eq!(stage.time_codes_per_second(), 24.0);
    assert_eq!((stage.start_time_code(), stage.end_time_code()), (1.0, 4.0));
    let world = stage.prim(sdf::path("/World").unwrap());
    assert_eq!(world.type_name().unwrap().unwrap().as_str(), "Xform");
    let tr = world.attribute("xformOp:translate").get::<Value>().unwrap().unwrap();
    assert_eq!(format!("{tr:?}"), format!("{:?}", Value::Vec3d([0.0, 0.0, 1.0].into())));
    let mesh = stage.prim(sdf::path("/World/Cloth").unwrap());
    assert_eq!(mesh.type_name().unwrap().unwrap().as_str(), "Mesh");
    let Some(Value::IntVec(counts)) = mesh.attribute("faceVertexCounts").get::<Value>().unwrap() else {
        panic!()
    };
    // 8 triangles + 8 quads, each split in four quads.
    assert_eq!(counts.len(), 4 * 16);
    // Vertices: 17 + 32 edge midpoints (8 spokes, 8 + 8 ring edges, 8 outer spokes) + 8 quad centres.
    let samples = mesh.attribute("points").time_samples().unwrap().unwrap();
    let times: Vec<f64> = samples.iter().map(|s| s.0).collect();
    assert_eq!(times, TIMES);
    let Some(Value::Vec2fVec(st)) = mesh.attribute("primvars:st").get::<Value>().unwrap() else { panic!() };
    assert!(!st.is_empty());
    let interp = mesh.attribute("primvars:st").get_metadata::<Value>("interpolation").unwrap();
    assert_eq!(interp, Some(Value::Token("faceVarying".into())));
    let Some(Value::IntVec(ind)) = mesh.attribute("primvars:st:indices").get::<Value>().unwrap() else {
        panic!()
    };
    assert_eq!(ind.len(), counts.iter().sum::<i32>() as usize);
    assert_eq!(counts.iter().filter(|&&c| c == 3).count(), 4 * 8, "a triangle splits into four");
    for (k, (_, v)) in samples.iter().enumerate() {
        let Value::Vec3fVec(p) = v else { panic!("{v:?}") };
        let want = obj_positions(&hr_obj.join(format!("frame_{k:04}.obj")));
        assert_eq!(p.len(), 17 + 32 + 8, "the subdivision's vertex count");
        assert_eq!(p.len(), want.len());
        for (a, b) in p.iter().zip(&want) {
            assert_eq!([a.x, a.y, a.z], *b, "frame {k}");
        }
    }
}

#[test]
fn usda_in_usda_out_matches_the_obj_sequence() {
    let root = tmp("usda");
    let f = root.join("shot.usda");
    std::fs::write(&f, usda_text()).unwrap();
    check_output(&f, &root);
}

#[test]
fn usdc_in_usda_out_matches_the_obj_sequence() {
    let root = tmp("usdc");
    let data = openusd::usda::parse(&usda_text()).unwrap();
    let f = root.join("shot.usdc");
    openusd::usdc::CrateWriter::write_to_file(&data, &f).unwrap();
    check_output(&f, &root);
}

#[test]
fn no_mesh_and_static_mesh_are_refused_naming_the_file() {
    let root = tmp("bad");
    let f = root.join("empty.usda");
    std::fs::write(&f, "#usda 1.0\n\ndef Xform \"World\"\n{\n}\n").unwrap();
    let o = anisocb(&["upscale", f.to_str().unwrap(), "--out", root.join("o").to_str().unwrap()]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success());
    assert!(err.contains("empty.usda") && err.contains("no Mesh prim"), "{err}");

    let g = root.join("still.usda");
    let text = usda_text();
    let at = text.find("point3f[] points.timeSamples").unwrap();
    let end = text[at..].find("        }\n").unwrap() + at + 10;
    let still = format!("{}point3f[] points = [(0, 0, 0)]\n{}", &text[..at], &text[end..]);
    std::fs::write(&g, still).unwrap();
    let o = anisocb(&["upscale", g.to_str().unwrap(), "--out", root.join("o").to_str().unwrap()]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success());
    assert!(
        err.contains("still.usda") && err.contains("/World/Cloth") && err.contains("time-sampled"),
        "{err}"
    );
}

/// A cloth whose parent moves (an animated `xformOp:translate`, as a character's root carries a
/// garment): the points are upscaled as authored, and the output carries the transform's time
/// samples unchanged, so it plays where the input plays.
#[test]
fn an_animated_transform_is_carried_to_the_output() {
    let root = tmp("animated-xform");
    let f = root.join("moving.usda");
    let moving = "    double3 xformOp:translate.timeSamples = {\n        1: (0, 0, 1),\n        2: (0.1, 0, 1),\n        \
                  3: (0.2, 0, 1.05),\n        4: (0.3, 0, 1.1),\n    }\n";
    let text = usda_text().replace("    double3 xformOp:translate = (0, 0, 1)\n", moving);
    assert!(text.contains("translate.timeSamples"));
    std::fs::write(&f, text).unwrap();
    let out = root.join("hr");
    let o = anisocb(&["upscale", f.to_str().unwrap(), "--out", out.to_str().unwrap()]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "upscale failed: {err}");
    assert!(err.contains("animated transforms") && err.contains("xformOp:translate"), "{err}");
    let stage = Stage::open(out.join("moving.usda").to_str().unwrap()).unwrap();
    let world = stage.prim(sdf::path("/World").unwrap());
    let samples = world.attribute("xformOp:translate").time_samples().unwrap().unwrap();
    let got: Vec<(f64, String)> = samples.iter().map(|(t, v)| (*t, format!("{v:?}"))).collect();
    let want: Vec<(f64, String)> = [[0.0, 0.0, 1.0], [0.1, 0.0, 1.0], [0.2, 0.0, 1.05], [0.3, 0.0, 1.1]]
        .iter()
        .zip(TIMES)
        .map(|(v, t)| (t, format!("{:?}", Value::Vec3d((*v).into()))))
        .collect();
    assert_eq!(got, want);
    // The points are those of the same shot without the motion (the static file's output).
    let still = root.join("still.usda");
    std::fs::write(&still, usda_text()).unwrap();
    let out2 = root.join("hr-still");
    assert!(anisocb(&["upscale", still.to_str().unwrap(), "--out", out2.to_str().unwrap()]).status.success());
    let pts = |p: &Path| {
        let s = Stage::open(p.to_str().unwrap()).unwrap();
        let m = s.prim(sdf::path("/World/Cloth").unwrap());
        format!("{:?}", m.attribute("points").time_samples().unwrap().unwrap())
    };
    assert!(pts(&out.join("moving.usda")) == pts(&out2.join("still.usda")), "the points changed");
}

/// A farm's --frames slices of one USD shot into one folder: each slice its own `.usda` and
/// summary, together the whole shot's points (the slices give the whole shot's bytes).
#[test]
fn frame_slices_write_their_own_usda_beside_each_other() {
    let root = tmp("slices");
    let f = root.join("shot.usda");
    std::fs::write(&f, usda_text()).unwrap();
    let (out, whole) = (root.join("hr"), root.join("whole"));
    for range in ["0:2", "2:4"] {
        let o = anisocb(&["upscale", f.to_str().unwrap(), "--out", out.to_str().unwrap(), "--frames", range]);
        assert!(o.status.success(), "{range}: {}", String::from_utf8_lossy(&o.stderr));
    }
    assert!(anisocb(&["upscale", f.to_str().unwrap(), "--out", whole.to_str().unwrap()]).status.success());
    let samples = |p: &Path| {
        let s = Stage::open(p.to_str().unwrap()).unwrap();
        s.prim(sdf::path("/World/Cloth").unwrap()).attribute("points").time_samples().unwrap().unwrap()
    };
    let mut joined = samples(&out.join("shot.0-2.usda"));
    joined.extend(samples(&out.join("shot.2-4.usda")));
    assert_eq!(format!("{joined:?}"), format!("{:?}", samples(&whole.join("shot.usda"))));
    for tag in ["0-2", "2-4"] {
        let s = std::fs::read_to_string(out.join(format!("upscale.{tag}.json"))).unwrap();
        assert!(s.contains(&format!("\"shot.{tag}.usda\"")), "{s}");
    }
    assert!(!out.join("shot.usda").exists());
}
