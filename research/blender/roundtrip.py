#!/usr/bin/env python3
"""Check anisocb's round trip through Blender: export from Blender, upscale, import back.

In Blender (the `bpy` module from PyPI, pinned in research/blender/requirements.txt; factory
settings, no UI) this builds a cloth the way an artist would: a 16x16-vertex, 1 m grid named
`Cloth` with its UV map and a texture-free Principled material `Fabric`, pinned along one
edge and falling under gravity (cloth modifier, 12 frames). It then exports

    DIR/lr/cloth0001.obj ... cloth0012.obj   Blender's OBJ exporter, Animation on, Y up
                                             (+ cloth0001.mtl ...: the exporter's materials)
    DIR/rest.obj (+ rest.mtl)                frame 1 alone, same exporter settings
    DIR/cloth.pc2                            the same 12 frames as a PC2 point cache

(Blender 4.5 ships no PC2 exporter, so the PC2 is written here with `struct` from the evaluated
mesh, in the OBJ files' Y-up coordinates, i.e. the rest OBJ's space, vertex order checked
against the OBJ frames), runs

    anisocb upscale DIR/lr --out DIR/hr
    anisocb upscale DIR/cloth.pc2 --rest DIR/rest.obj --out DIR/hr_pc2

copies the LR .mtl files beside the HR frames (anisocb keeps `mtllib`/`usemtl`; the .mtl files
are the user's), imports the results with Blender's OBJ importer and checks:

  a. every HR frame: 2W x 2H vertices, one UV map spanning the LR UV range, the UV corners on
     the same corners of the cloth as in LR, material slot `Fabric` with its .mtl present,
     object name `Cloth`, normals facing the LR mesh's way (winding kept);
  b. no shrinkage: HR bounding box within 1 % (of the LR box diagonal) of the LR box;
  c. the HR PC2 plays on the HR rest mesh through a Mesh Cache modifier: the evaluated
     vertices equal the positions stored in the cache, frame by frame.

Each check prints its numbers and PASS/FAIL; the exit status is 1 if any check failed.
Not part of `make test` (needs bpy, a large download).

Usage:
    python3 -m pip install -r research/blender/requirements.txt   # Python 3.11
    python3 research/blender/roundtrip.py --anisocb target/release/anisocb [--keep DIR]
"""

import argparse
import glob
import math
import os
import re
import shutil
import struct
import subprocess
import sys
import tempfile

import numpy as np

try:
    import bpy
    import mathutils
except ImportError:
    sys.exit("roundtrip.py needs Blender's bpy module: pip install -r research/blender/requirements.txt")

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from blender_common import quiet  # noqa: E402

N = 16  # LR grid: N x N vertices
SIZE = 1.0  # metres
FRAMES = 12
OBJ_NAME = "Cloth"
MAT_NAME = "Fabric"

FAILED = []


def check(name, ok, numbers):
    print(f"[{'PASS' if ok else 'FAIL'}] {name}: {numbers}", flush=True)
    if not ok:
        FAILED.append(name)


# --------------------------------------------------------------------------- the LR shot


def reset():
    with quiet(1):
        bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    scene.render.fps = 24
    scene.frame_start = 1
    scene.frame_end = FRAMES
    return scene


def build_cloth():
    """A horizontal 1 m grid at z = 1 m, pinned along its y = -0.5 edge, with UVs and `Fabric`."""
    # Blender >= 3.0: subdivisions count faces per side, so N vertices need N - 1.
    bpy.ops.mesh.primitive_grid_add(x_subdivisions=N - 1, y_subdivisions=N - 1, size=SIZE,
                                    calc_uvs=True, location=(0, 0, 1.0))
    obj = bpy.context.object
    me = obj.data
    assert len(me.vertices) == N * N, f"grid has {len(me.vertices)} vertices, wanted {N * N}"
    assert len(me.polygons) == (N - 1) ** 2 and all(len(p.vertices) == 4 for p in me.polygons)
    assert len(me.uv_layers) == 1, f"grid has {len(me.uv_layers)} UV maps, wanted 1"
    obj.name = OBJ_NAME
    me.name = OBJ_NAME
    bpy.ops.object.transform_apply(location=True, rotation=True, scale=True)

    mat = bpy.data.materials.new(MAT_NAME)
    mat.use_nodes = True  # a Principled BSDF, no image textures
    bsdf = mat.node_tree.nodes["Principled BSDF"]
    bsdf.inputs["Base Color"].default_value = (0.6, 0.15, 0.1, 1.0)
    bsdf.inputs["Roughness"].default_value = 0.8
    me.materials.append(mat)

    pins = [v.index for v in me.vertices if v.co.y < -SIZE / 2 + 1e-6]
    assert len(pins) == N, f"{len(pins)} pinned vertices, wanted {N}"
    vg = obj.vertex_groups.new(name="pin")
    vg.add(pins, 1.0, "REPLACE")

    mod = obj.modifiers.new("Cloth", "CLOTH")
    s = mod.settings
    s.quality = 5
    s.mass = 0.3
    s.vertex_group_mass = "pin"
    s.pin_stiffness = 1.0
    mod.collision_settings.use_collision = False
    mod.point_cache.frame_start = 1
    mod.point_cache.frame_end = FRAMES
    return obj


def obj_export(path, animation, frame=None):
    kw = dict(export_animation=True, start_frame=1, end_frame=FRAMES) if animation else {}
    with quiet(1):
        bpy.ops.wm.obj_export(
            filepath=path,
            export_selected_objects=True,
            apply_modifiers=True,
            export_eval_mode="DAG_EVAL_VIEWPORT",
            forward_axis="NEGATIVE_Z",  # the defaults: Y up
            up_axis="Y",
            export_uv=True,
            export_normals=True,
            export_materials=True,
            export_triangulated_mesh=False,
            **kw,
        )


def blender_to_obj_axes(co):
    """Blender world (Z up) -> the OBJ files' coordinates with forward -Z, up Y: (x, z, -y)."""
    co = np.asarray(co)
    return np.stack([co[:, 0], co[:, 2], -co[:, 1]], axis=1)


def evaluated_world_co(obj):
    dg = bpy.context.evaluated_depsgraph_get()
    ev = obj.evaluated_get(dg)
    me = ev.to_mesh()
    co = np.empty(len(me.vertices) * 3, dtype=np.float32)
    me.vertices.foreach_get("co", co)
    co = co.reshape(-1, 3).astype(np.float64)
    mw = np.array(ev.matrix_world)
    ev.to_mesh_clear()
    return co @ mw[:3, :3].T + mw[:3, 3]


def write_pc2(path, frames_xyz, start_frame):
    """PC2: b'POINTCACHE2\\0', int32 version 1, int32 points, float32 start, float32 sample
    rate, int32 samples, then float32 xyz per point per sample (little-endian)."""
    arr = np.asarray(frames_xyz, dtype="<f4")
    with open(path, "wb") as fh:
        fh.write(b"POINTCACHE2\0")
        fh.write(struct.pack("<iiffi", 1, arr.shape[1], float(start_frame), 1.0, arr.shape[0]))
        fh.write(arr.tobytes())


def read_pc2(path):
    with open(path, "rb") as fh:
        data = fh.read()
    assert data[:12] == b"POINTCACHE2\0", f"{path}: not a PC2 file"
    version, npts, start, rate, nsamp = struct.unpack("<iiffi", data[12:32])
    arr = np.frombuffer(data, dtype="<f4", offset=32, count=npts * nsamp * 3).reshape(nsamp, npts, 3)
    return dict(version=version, points=npts, start=start, rate=rate, samples=nsamp), arr


def read_obj_text(path):
    """Vertices, vt count, the mtllib / usemtl / o lines and face sizes of an OBJ file."""
    v, vt, mtllib, usemtl, o, fs = [], 0, [], [], [], set()
    with open(path) as fh:
        for line in fh:
            if line.startswith("v "):
                v.append([float(x) for x in line.split()[1:4]])
            elif line.startswith("vt "):
                vt += 1
            elif line.startswith("mtllib "):
                mtllib.append(line[7:].strip())
            elif line.startswith("usemtl "):
                usemtl.append(line[7:].strip())
            elif line.startswith("o "):
                o.append(line[2:].strip())
            elif line.startswith("f "):
                fs.add(len(line.split()) - 1)
    return dict(v=np.array(v), vt=vt, mtllib=mtllib, usemtl=usemtl, o=o, face_sizes=fs)


def make_shot(d):
    scene = reset()
    cloth = build_cloth()
    for o in bpy.context.view_layer.objects:
        o.select_set(o is cloth)
    bpy.context.view_layer.objects.active = cloth
    for fr in range(1, FRAMES + 1):  # bake: the cloth cache fills frame by frame
        scene.frame_set(fr)

    lr = os.path.join(d, "lr")
    os.makedirs(lr)
    obj_export(os.path.join(lr, "cloth.obj"), animation=True)
    scene.frame_set(1)
    obj_export(os.path.join(d, "rest.obj"), animation=False)

    world = []
    for fr in range(1, FRAMES + 1):
        scene.frame_set(fr)
        world.append(blender_to_obj_axes(evaluated_world_co(cloth)))
    world = np.stack(world)
    write_pc2(os.path.join(d, "cloth.pc2"), world, start_frame=1)

    files = sorted(glob.glob(os.path.join(lr, "*.obj")))
    print(f"LR shot: {len(files)} OBJ frames in lr/ ({os.path.basename(files[0])} .. "
          f"{os.path.basename(files[-1])}), {len(glob.glob(os.path.join(lr, '*.mtl')))} .mtl, "
          f"rest.obj, cloth.pc2 ({FRAMES} samples x {world.shape[1]} points)")
    # The PC2 and the OBJ frames must list the same vertices in the same order.
    diffs = []
    for fr, f in enumerate(files):
        diffs.append(np.abs(read_obj_text(f)["v"] - world[fr]).max())
    rest_diff = np.abs(read_obj_text(os.path.join(d, "rest.obj"))["v"] - world[0]).max()
    moved = np.linalg.norm(world[-1] - world[0], axis=1).max()
    check("LR export: PC2 vertex order = OBJ vertex order",
          len(files) == FRAMES and max(diffs) < 1e-5 and rest_diff < 1e-5,
          f"max |PC2 - OBJ frame| {max(diffs):.2e} m over {len(files)} frames, "
          f"|PC2[0] - rest.obj| {rest_diff:.2e} m (OBJ prints 6 decimals)")
    check("LR shot: the cloth moves", moved > 0.05, f"max displacement frame 1 -> {FRAMES}: {moved:.3f} m")
    return files


def run_anisocb(exe, args):
    cmd = [exe, "upscale", *args]
    print("$ anisocb upscale " + " ".join(args), flush=True)
    r = subprocess.run(cmd, capture_output=True, text=True)
    out = (r.stdout + r.stderr).strip()
    if out:
        print("  " + out.replace("\n", "\n  "))
    check(f"anisocb upscale {os.path.basename(args[0].rstrip(os.sep))} exits 0", r.returncode == 0,
          f"exit status {r.returncode}")
    return r.returncode == 0


# --------------------------------------------------------------------------- checks in Blender


def import_obj(path):
    """Blender's OBJ importer; returns the new object. Like the exporter's defaults it reads
    Y up: it keeps the file's coordinates in the mesh and puts the Y-up -> Z-up turn (90 deg
    about X) in the object's transform."""
    before = set(bpy.data.objects)
    with quiet(1):
        bpy.ops.wm.obj_import(filepath=path, forward_axis="NEGATIVE_Z", up_axis="Y")
    new = [o for o in bpy.data.objects if o not in before]
    assert len(new) == 1, f"{path}: the importer made {len(new)} objects"
    return new[0]


def mesh_arrays(obj):
    me = obj.data
    co = np.empty(len(me.vertices) * 3)
    me.vertices.foreach_get("co", co)
    co = co.reshape(-1, 3)
    vn = np.empty(len(me.vertices) * 3)
    me.vertex_normals.foreach_get("vector", vn)
    vn = vn.reshape(-1, 3)
    uv = None
    if me.uv_layers:
        uv = np.empty(len(me.loops) * 2)
        me.uv_layers[0].data.foreach_get("uv", uv)
        uv = uv.reshape(-1, 2)
    lv = np.empty(len(me.loops), dtype=np.int64)
    me.loops.foreach_get("vertex_index", lv)
    # area-weighted mean face normal
    fa = np.empty(len(me.polygons))
    me.polygons.foreach_get("area", fa)
    fnrm = np.empty(len(me.polygons) * 3)
    me.polygons.foreach_get("normal", fnrm)
    mean_n = (fnrm.reshape(-1, 3) * fa[:, None]).sum(0)
    return dict(co=co, vn=vn, uv=uv, loop_vert=lv, mean_n=mean_n / np.linalg.norm(mean_n))


def uv_corner_positions(m):
    """Position of the vertex at each UV-square corner (min/max u, min/max v)."""
    uv, co = m["uv"], m["co"]
    lo, hi = uv.min(0), uv.max(0)
    out = []
    for cu in (lo[0], hi[0]):
        for cv in (lo[1], hi[1]):
            k = np.argmin(np.abs(uv[:, 0] - cu) + np.abs(uv[:, 1] - cv))
            out.append(co[m["loop_vert"][k]])
    return np.array(out)


def check_obj_frames(d, lr_files):
    hr_dir = os.path.join(d, "hr")
    hr_files = [os.path.join(hr_dir, os.path.basename(f)) for f in lr_files]
    missing = [f for f in hr_files if not os.path.exists(f)]
    check("hr/: one HR OBJ per LR frame, same names", not missing,
          f"{len(hr_files) - len(missing)}/{len(hr_files)} present" + (f", missing {missing[:3]}" if missing else ""))
    if missing:
        return
    mtl_in_hr = sorted(glob.glob(os.path.join(hr_dir, "*.mtl")))
    print(f"  anisocb wrote {len(mtl_in_hr)} .mtl files into hr/ (expected 0: the .mtl files are the "
          f"user's); copying the LR .mtl files beside the HR frames, as the README says")
    for m in glob.glob(os.path.join(d, "lr", "*.mtl")):
        shutil.copy(m, hr_dir)

    want = 4 * N * N
    worst = dict(count=[], uv=0.0, corner=0.0, ndot=1.0, mean_ndot=1.0, bbox=0.0)
    text_problems = []
    bl_problems = []
    for fr, (lf, hf) in enumerate(zip(lr_files, hr_files), start=1):
        reset()
        lt, ht = read_obj_text(lf), read_obj_text(hf)
        for key in ("mtllib", "usemtl", "o"):
            if lt[key] != ht[key]:
                text_problems.append(f"frame {fr}: {key} {ht[key]} (LR {lt[key]})")
        for m in ht["mtllib"]:
            if not os.path.exists(os.path.join(hr_dir, m)):
                text_problems.append(f"frame {fr}: mtllib {m} not found beside the HR OBJ")
        if ht["face_sizes"] != lt["face_sizes"]:
            text_problems.append(f"frame {fr}: face sizes {ht['face_sizes']} (LR {lt['face_sizes']})")

        hi_obj = import_obj(hf)  # first, into an empty scene: names must come back unchanged
        lo_obj = import_obj(lf)
        lm, hm = mesh_arrays(lo_obj), mesh_arrays(hi_obj)
        worst["count"].append(len(hm["co"]))
        if hi_obj.name != OBJ_NAME:
            bl_problems.append(f"frame {fr}: object name {hi_obj.name!r}")
        slots = [s.material.name if s.material else None for s in hi_obj.material_slots]
        if slots != [MAT_NAME]:
            bl_problems.append(f"frame {fr}: material slots {slots}")
        if len(hi_obj.data.uv_layers) != 1 or hm["uv"] is None:
            bl_problems.append(f"frame {fr}: {len(hi_obj.data.uv_layers)} UV maps")
        else:
            span = max(np.abs(hm["uv"].min(0) - lm["uv"].min(0)).max(),
                       np.abs(hm["uv"].max(0) - lm["uv"].max(0)).max())
            worst["uv"] = max(worst["uv"], span)
            # The texture's corners sit on the same corners of the cloth (UVs not flipped).
            worst["corner"] = max(worst["corner"],
                                  np.linalg.norm(uv_corner_positions(hm) - uv_corner_positions(lm), axis=1).max())
        # Normals: each HR vertex against the nearest LR vertex (both meshes in the same space).
        kd = mathutils.kdtree.KDTree(len(lm["co"]))
        for i, c in enumerate(lm["co"]):
            kd.insert(c, i)
        kd.balance()
        near = np.array([kd.find(c)[1] for c in hm["co"]])
        dots = (hm["vn"] * lm["vn"][near]).sum(1)
        worst["ndot"] = min(worst["ndot"], dots.mean())
        worst["mean_ndot"] = min(worst["mean_ndot"], float(hm["mean_n"] @ lm["mean_n"]))
        # Bounding boxes, in Blender's world space (after the importer's Y-up -> Z-up turn).
        mw = np.array(hi_obj.matrix_world)
        hw = hm["co"] @ mw[:3, :3].T + mw[:3, 3]
        lw = lm["co"] @ mw[:3, :3].T + mw[:3, 3]
        diag = np.linalg.norm(lw.max(0) - lw.min(0))
        if fr == 1:
            print(f"  info: frame 1 is the flat rest sheet: height spread LR {np.ptp(lw[:, 2]) * 1e3:.2f} mm, "
                  f"HR {np.ptp(hw[:, 2]) * 1e3:.2f} mm (detail the nets add to a flat cloth)")
        dev = max(np.abs(hw.min(0) - lw.min(0)).max(), np.abs(hw.max(0) - lw.max(0)).max()) / diag
        if dev > worst["bbox"]:
            worst["bbox"], worst["bbox_frame"] = dev, fr
            worst["bbox_lr"], worst["bbox_hr"] = (lw.min(0), lw.max(0)), (hw.min(0), hw.max(0))

    n_frames = len(hr_files)
    counts = sorted(set(worst["count"]))
    check("a. HR vertex count = 2W x 2H", counts == [want],
          f"{counts} vertices per frame over {n_frames} frames, want {want} (LR {N}x{N})")
    check("a. OBJ text: mtllib/usemtl/o/face sizes kept, .mtl present", not text_problems,
          "; ".join(text_problems[:4]) if text_problems
          else f"mtllib {ht['mtllib']}, usemtl {ht['usemtl']}, o {ht['o']}, faces {sorted(ht['face_sizes'])}-gons")
    check("a. Blender import: object name, one UV map, material slot", not bl_problems,
          "; ".join(bl_problems[:4]) if bl_problems
          else f"object {OBJ_NAME!r}, UV maps 1, material slots [{MAT_NAME!r}] in all {n_frames} frames")
    check("a. UV range HR = LR", worst["uv"] <= 1e-5, f"max |min/max difference| {worst['uv']:.2e} (limit 1e-5)")
    check("a. UV corners on the same cloth corners", worst["corner"] < 1e-3,
          f"max distance between the HR and LR vertices at the 4 UV corners {worst['corner']:.2e} m")
    check("a. normals face the LR way (winding kept)", worst["ndot"] > 0.9 and worst["mean_ndot"] > 0.9,
          f"worst frame: mean dot(HR vertex normal, nearest LR vertex normal) {worst['ndot']:.4f}, "
          f"dot of the area-weighted mean normals {worst['mean_ndot']:.4f} (limit 0.9)")
    f = worst.get("bbox_frame", 1)
    lr_b = worst.get("bbox_lr", (np.zeros(3), np.zeros(3)))
    hr_b = worst.get("bbox_hr", (np.zeros(3), np.zeros(3)))
    fmt = lambda b: "[" + ", ".join(f"{a:+.4f}..{c:+.4f}" for a, c in zip(*b)) + "]"
    check("b. no shrinkage: HR bbox within 1 % of LR bbox", worst["bbox"] < 0.01,
          f"worst frame {f}: largest bound difference {100 * worst['bbox']:.3f} % of the LR diagonal; "
          f"LR {fmt(lr_b)} HR {fmt(hr_b)} m")


def check_pc2(d):
    hp = os.path.join(d, "hr_pc2")
    cache, rest = os.path.join(hp, "cloth.pc2"), os.path.join(hp, "rest.obj")
    ok = os.path.exists(cache) and os.path.exists(rest)
    check("hr_pc2/: cloth.pc2 and rest.obj written", ok, f"{sorted(os.listdir(hp)) if os.path.isdir(hp) else 'no dir'}")
    if not ok:
        return
    head, frames = read_pc2(cache)
    lr_head, _ = read_pc2(os.path.join(d, "cloth.pc2"))
    check("c. HR PC2 header", head["points"] == 4 * N * N and head["samples"] == lr_head["samples"]
          and head["start"] == lr_head["start"] and head["rate"] == lr_head["rate"] and head["version"] == 1,
          f"{head} (LR {lr_head})")

    for m in glob.glob(os.path.join(d, "*.mtl")):  # rest.mtl, copied by the user as for hr/
        shutil.copy(m, hp)
    reset()
    scene = bpy.context.scene
    obj = import_obj(rest)
    slots = [s.material.name if s.material else None for s in obj.material_slots]
    check("c. HR rest.obj imports: point count, name, UV map, material",
          len(obj.data.vertices) == head["points"] and obj.name == OBJ_NAME and slots == [MAT_NAME]
          and len(obj.data.uv_layers) == 1,
          f"{len(obj.data.vertices)} vertices (cache {head['points']} points), object {obj.name!r}, "
          f"{len(obj.data.uv_layers)} UV map(s), material slots {slots}")
    # Coordinates: the cache was written in the OBJ files' Y-up space (the rest OBJ's space).
    # Blender's OBJ importer keeps the file coordinates in the mesh (local space) and puts the
    # Y-up -> Z-up conversion in the object's rotation (90 deg about X), and the Mesh Cache
    # modifier writes cache positions straight into local space when its axes are the
    # identity (forward +Y, up +Z, no flip: the defaults). So the evaluated local vertex
    # positions must equal the cache's floats, and the object's rotation stands the cloth up
    # in the viewport exactly as the imported OBJ frames.
    mod = obj.modifiers.new("MeshCache", "MESH_CACHE")
    mod.cache_format = "PC2"
    mod.filepath = cache
    mod.forward_axis, mod.up_axis, mod.flip_axis = "POS_Y", "POS_Z", (False, False, False)
    mod.deform_mode = "OVERWRITE"
    mod.interpolation = "NONE"
    mod.play_mode = "SCENE"
    # In Frame mode the modifier reads sample (scene frame * frame_scale - frame_start) and
    # ignores the start frame stored in the PC2 header, so a cache starting at frame 1 needs
    # Frame Start = 1 for scene frame 1 to show sample 0 (checked below frame by frame).
    mod.time_mode = "FRAME"
    mod.frame_scale = 1.0
    mod.frame_start = head["start"]
    rot = tuple(round(math.degrees(a), 3) for a in obj.rotation_euler)
    picks = sorted({1, 2, FRAMES // 2, FRAMES})
    errs = []
    for fr in picks:
        scene.frame_set(fr)
        dg = bpy.context.evaluated_depsgraph_get()
        ev = obj.evaluated_get(dg)
        me = ev.to_mesh()
        co = np.empty(len(me.vertices) * 3, dtype=np.float32)
        me.vertices.foreach_get("co", co)
        ev.to_mesh_clear()
        sample = int(round((fr - head["start"]) * head["rate"]))
        errs.append((fr, sample, float(np.abs(co.reshape(-1, 3) - frames[sample]).max())))
    worst = max(e for _, _, e in errs)
    check("c. Mesh Cache modifier plays the HR PC2 as written", worst < 1e-5,
          ", ".join(f"frame {fr} = sample {s}: max |eval - cache| {e:.1e} m" for fr, s, e in errs)
          + f" (object rotation {rot} deg, frame_start {mod.frame_start})")

    # Informative: the PC2 path and the OBJ path give (almost) the same HR animation.
    hr_objs = sorted(glob.glob(os.path.join(d, "hr", "*.obj")))
    if len(hr_objs) == head["samples"]:
        diff = max(np.abs(read_obj_text(f)["v"] - frames[k]).max() for k, f in enumerate(hr_objs))
        print(f"  info: max |HR PC2 sample - HR OBJ frame| over {len(hr_objs)} frames: {diff:.2e} m "
              f"(inputs differ by the OBJ exporter's 6-decimal rounding)")


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--anisocb", required=True, help="path to the anisocb binary")
    ap.add_argument("--keep", help="write everything into this (new or empty) folder and keep it")
    args = ap.parse_args()
    exe = os.path.abspath(args.anisocb)
    if not os.access(exe, os.X_OK):
        sys.exit(f"{args.anisocb}: not an executable")
    if args.keep:
        d = os.path.abspath(args.keep)
        os.makedirs(d, exist_ok=True)
        if os.listdir(d):
            sys.exit(f"{d}: not empty")
        work = None
    else:
        work = tempfile.TemporaryDirectory(prefix="anisocb-roundtrip-")
        d = work.name
    print(f"Blender {bpy.app.version_string}; LR {N}x{N} vertices, {FRAMES} frames")

    lr_files = make_shot(d)
    if run_anisocb(exe, [os.path.join(d, "lr"), "--out", os.path.join(d, "hr")]):
        check_obj_frames(d, lr_files)
    if run_anisocb(exe, [os.path.join(d, "cloth.pc2"), "--rest", os.path.join(d, "rest.obj"),
                         "--out", os.path.join(d, "hr_pc2")]):
        check_pc2(d)

    if work is not None:
        work.cleanup()
    else:
        print(f"files kept in {d}")
    if FAILED:
        print(f"{len(FAILED)} check(s) FAILED: " + "; ".join(FAILED))
        sys.exit(1)
    print("all checks passed")


if __name__ == "__main__":
    main()
