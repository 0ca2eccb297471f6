#!/usr/bin/env python3
"""The anisocb add-on (blender/anisocb_addon) in real Blender, headless.

Runs in Blender's `bpy` module from PyPI (pinned in tests/blender/requirements.txt; Python
3.11). It builds a scene the way an artist would:

  Sheet   a 12 x 12-vertex, 0.8 m quad grid at z = 1.2 m, its y = -0.4 m edge in the vertex
          group "pin" (the cloth's pin group), UVs and a material "Sheet Red"
  Skirt   an open tube of quads (16 around x 6 rings), waist r 0.12 m pinned ("pin"), hem
          r 0.25 m, UVs and a material "Skirt Blue"; the skirt object slides 0.25 m along x
          (keyframes), dragging its pinned waist
  Sphere  r 0.15 m with a Collision modifier, inside the skirt, keyed along the same path
          (an animated collider)

bakes the two cloths over 20 frames at 24 fps, enables the add-on from this repository's
blender/ folder, sets its binary in the add-on preferences, and runs the operator
synchronously (`bpy.ops.anisocb.upscale()` = execute: the script mode) on each cloth. Checks:

  1. the export: rest.obj, cloth.pc2 (20 samples), the sphere as 20 OBJ frames that move,
     the command line (physics, fps 24, gravity 0,-9.81,0, material, pins, --collider);
  2. the new object `<cloth>_anisocb`: Mesh Cache modifier, materials and UV map kept; its
     evaluated world-space vertices, frame by frame, equal `anisocb upscale` run by hand on
     the same exported files (the HR PC2 turned back to Blender's Z up) within 1e-4 m; and it
     plays in place over the LR cloth (HR bounding box within 3 cm of the LR one);
  0. with --zip: the add-on zip installs as an extension (Install from Disk) and registers;
  3. errors: a wrong binary path, and an option the binary refuses (a wrapper adding
     `--margin 5`), are reported by the operator with the binary's own message.

Prints PASS/FAIL per check and a summary; exit status 1 if any failed. `make blender-test`.

Usage:
    python3 -m pip install -r tests/blender/requirements.txt   # Python 3.11
    python3 tests/blender/test_addon.py --anisocb target/release/anisocb [--zip target/anisocb_addon.zip] [--keep DIR]
"""

import argparse
import math
import os
import shlex
import stat
import struct
import subprocess
import sys
import tempfile
import time

import numpy as np

# Blender's user folders (preferences, extensions) in a temporary folder: the test installs and
# enables add-ons, and leaves the user's own Blender configuration alone.
USER_RESOURCES = tempfile.TemporaryDirectory(prefix="anisocb-blender-user-")
os.environ["BLENDER_USER_RESOURCES"] = USER_RESOURCES.name

try:
    import bpy
    import addon_utils  # after bpy: the PyPI module provides it once bpy is loaded
except ImportError:
    sys.exit("test_addon.py needs Blender's bpy module: python3 -m pip install -r tests/blender/requirements.txt")

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
FRAMES = 20
FPS = 24
FAILED = []
RESULTS = []


def check(name, ok, numbers):
    print(f"[{'PASS' if ok else 'FAIL'}] {name}: {numbers}", flush=True)
    RESULTS.append((name, ok))
    if not ok:
        FAILED.append(name)


class quiet:
    """Send C-level output on file descriptor 1 to /dev/null (Blender's chatter)."""

    def __enter__(self):
        sys.stdout.flush()
        self.saved = os.dup(1)
        self.null = os.open(os.devnull, os.O_WRONLY)
        os.dup2(self.null, 1)

    def __exit__(self, *exc):
        sys.stdout.flush()
        os.dup2(self.saved, 1)
        os.close(self.saved)
        os.close(self.null)


# --------------------------------------------------------------------------- the scene


def material(name, rgb):
    m = bpy.data.materials.new(name)
    m.diffuse_color = (*rgb, 1.0)
    m.use_nodes = True
    m.node_tree.nodes["Principled BSDF"].inputs["Base Color"].default_value = (*rgb, 1.0)
    return m


def cloth(obj, pins, mass=0.3, bending=0.5):
    vg = obj.vertex_groups.new(name="pin")
    vg.add(pins, 1.0, "REPLACE")
    mod = obj.modifiers.new("Cloth", "CLOTH")
    s = mod.settings
    s.quality = 6
    s.mass = mass
    s.bending_stiffness = bending
    s.vertex_group_mass = "pin"
    mod.collision_settings.use_collision = True
    mod.collision_settings.distance_min = 0.01
    mod.point_cache.frame_start = 1
    mod.point_cache.frame_end = FRAMES
    return mod


def build_sheet():
    n, size = 12, 0.8
    bpy.ops.mesh.primitive_grid_add(x_subdivisions=n - 1, y_subdivisions=n - 1, size=size, calc_uvs=True,
                                    location=(-0.9, 0.0, 1.2))
    obj = bpy.context.object
    obj.name = obj.data.name = "Sheet"
    assert len(obj.data.vertices) == n * n
    obj.data.materials.append(material("Sheet Red", (0.7, 0.1, 0.1)))
    pins = [v.index for v in obj.data.vertices if v.co.y < -size / 2 + 1e-6]
    cloth(obj, pins)
    return obj, len(pins)


def build_skirt():
    around, rings = 16, 6
    waist, hem, length = 0.12, 0.25, 0.4
    verts, faces = [], []
    for j in range(rings):
        t = j / (rings - 1)
        r, z = waist + (hem - waist) * t, -length * t
        for i in range(around):
            a = 2 * math.pi * i / around
            verts.append((r * math.cos(a), r * math.sin(a), z))
    for j in range(rings - 1):
        for i in range(around):
            a, b = j * around + i, j * around + (i + 1) % around
            faces.append((a, a + around, b + around, b))  # outward normals
    me = bpy.data.meshes.new("Skirt")
    me.from_pydata(verts, [], faces)
    uv = me.uv_layers.new(name="UVMap")
    for p in me.polygons:
        for li in p.loop_indices:
            vi = me.loops[li].vertex_index
            i, j = vi % around, vi // around
            # u wraps: the last column's right edge gets u = 1 (a UV seam down the skirt)
            if i == 0 and any(me.loops[k].vertex_index % around == around - 1 for k in p.loop_indices):
                i = around
            uv.data[li].uv = (i / around, 1 - j / (rings - 1))
    me.materials.append(material("Skirt Blue", (0.1, 0.2, 0.7)))
    for p in me.polygons:
        p.use_smooth = True
    obj = bpy.data.objects.new("Skirt", me)
    bpy.context.scene.collection.objects.link(obj)
    obj.location = (0.4, 0.0, 1.0)
    cloth(obj, list(range(around)), mass=0.15, bending=0.05)
    return obj, around


def build_sphere():
    bpy.ops.mesh.primitive_uv_sphere_add(radius=0.15, segments=24, ring_count=12, location=(0.4, 0.0, 0.9))
    s = bpy.context.object
    s.name = "Sphere"
    s.modifiers.new("Collision", "COLLISION")
    s.collision.thickness_outer = 0.01
    s.collision.cloth_friction = 5.0
    return s


def key_path(objs, frames):
    """Both objects still for 4 frames, then 0.25 m along x by the last frame (eased)."""
    for o in objs:
        x0 = o.location.x
        for fr, dx in ((1, 0.0), (5, 0.0), (frames, 0.25)):
            o.location.x = x0 + dx
            o.keyframe_insert("location", index=0, frame=fr)


def build_scene(fresh=True):
    """fresh: start from Blender's factory settings (else: clear the objects of the open file,
    as screenshot_panel.py does in a Blender window)."""
    if fresh:
        with quiet():
            bpy.ops.wm.read_factory_settings(use_empty=True)
    else:
        for o in list(bpy.data.objects):
            bpy.data.objects.remove(o)
    scene = bpy.context.scene
    scene.render.fps = FPS
    scene.render.fps_base = 1.0
    scene.frame_start, scene.frame_end = 1, FRAMES
    scene.gravity = (0.0, 0.0, -9.81)
    sheet, sheet_pins = build_sheet()
    skirt, skirt_pins = build_skirt()
    sphere = build_sphere()
    key_path([skirt, sphere], FRAMES)
    t0 = time.time()
    with quiet(), bpy.context.temp_override(scene=scene):
        bpy.ops.ptcache.bake_all(bake=True)  # Physics > Cloth > Cache > Bake All Dynamics
    assert all(o.modifiers["Cloth"].point_cache.is_baked for o in (sheet, skirt))
    scene.frame_set(1)
    print(f"scene: Sheet {len(sheet.data.vertices)} vertices ({sheet_pins} pinned), Skirt "
          f"{len(skirt.data.vertices)} vertices ({skirt_pins} pinned), Sphere collider keyed; "
          f"{FRAMES} frames at {FPS} fps baked in {time.time() - t0:.1f} s", flush=True)
    return sheet, skirt, sphere


# --------------------------------------------------------------------------- helpers


def world_verts(obj):
    dg = bpy.context.evaluated_depsgraph_get()
    ev = obj.evaluated_get(dg)
    me = ev.to_mesh()
    co = np.empty(len(me.vertices) * 3, dtype=np.float32)
    me.vertices.foreach_get("co", co)
    mw = np.array(ev.matrix_world)
    ev.to_mesh_clear()
    return co.reshape(-1, 3).astype(np.float64) @ mw[:3, :3].T + mw[:3, 3]


def read_pc2(path):
    with open(path, "rb") as fh:
        data = fh.read()
    assert data[:12] == b"POINTCACHE2\0", path
    _, npts, start, rate, ns = struct.unpack("<iiffi", data[12:32])
    arr = np.frombuffer(data, dtype="<f4", offset=32, count=npts * ns * 3).reshape(ns, npts, 3)
    return dict(points=npts, start=start, rate=rate, samples=ns), arr


def yup_to_blender(co):
    return np.stack([co[..., 0], -co[..., 2], co[..., 1]], axis=-1)


def run_operator(**kw):
    """bpy.ops.anisocb.upscale(**kw): (ok, the error message or '')."""
    try:
        with quiet():
            r = bpy.ops.anisocb.upscale(**kw)
        return "FINISHED" in r, ""
    except RuntimeError as e:
        return False, str(e)


# --------------------------------------------------------------------------- checks


def check_cloth(obj, out, exe, expect_pin):
    name = obj.name
    s = obj.anisocb
    s.output_dir = out
    s.physics = True
    s.material = "AUTO"
    s.eta = 0.0
    t0 = time.time()
    ok, err = run_operator(object_name=name)
    secs = time.time() - t0
    check(f"{name}: operator finishes", ok, f"{secs:.1f} s" + (f"; error: {err}" if err else ""))
    if not ok:
        return
    d = os.path.join(out, name)
    with open(os.path.join(d, "command.txt")) as fh:
        cmd = shlex.split(fh.read())
    head, lr = read_pc2(os.path.join(d, "cloth.pc2"))
    args = cmd[1:]  # upscale ...
    opt = lambda k: args[args.index(k) + 1] if k in args else None  # noqa: E731
    colliders = [args[i + 1] for i, a in enumerate(args) if a == "--collider"]
    check(f"{name}: export and command line",
          head["samples"] == FRAMES and head["points"] == len(obj.data.vertices) and head["start"] == 1
          and os.path.isfile(os.path.join(d, "rest.obj")) and "--physics" in args and opt("--fps") == str(FPS)
          and opt("--gravity") == "0,-9.81,0" and expect_pin(args) and len(colliders) == 1
          and opt("--collider-thickness") == "0.01",
          f"PC2 {head['samples']} samples x {head['points']} points from frame {head['start']:g}; "
          f"--fps {opt('--fps')} --gravity {opt('--gravity')} --material {opt('--material')} "
          f"--physics-pin {opt('--physics-pin')} --physics-pin-vertices "
          f"{os.path.basename(opt('--physics-pin-vertices') or '-')} --collider "
          f"{[os.path.relpath(c, d) for c in colliders]} --collider-thickness {opt('--collider-thickness')}")
    if colliders:
        col = colliders[0]
        files = sorted(os.listdir(col)) if os.path.isdir(col) else []
        moved = 0.0
        if len(files) == FRAMES:
            v = [np.array([[float(x) for x in l.split()[1:4]] for l in open(os.path.join(col, f))
                           if l.startswith("v ")]) for f in (files[0], files[-1])]
            moved = float(np.abs(v[1] - v[0]).max())
        check(f"{name}: animated collider exported as OBJ frames", len(files) == FRAMES and moved > 0.2,
              f"{os.path.relpath(col, d)}/: {len(files)} files ({files[0] if files else '-'} .. "
              f"{files[-1] if files else '-'}), moves {moved:.3f} m along x between the first and last")

    # The same files through the binary by hand.
    hand = os.path.join(d, "hand")
    hand_cmd = [exe] + [hand if a == os.path.join(d, "hr") else a for a in args]
    hand_cmd = [a for a in hand_cmd if a != "--overwrite"]
    r = subprocess.run(hand_cmd, capture_output=True, text=True)
    check(f"{name}: anisocb upscale by hand on the exported files", r.returncode == 0,
          f"exit {r.returncode}" + (f": {r.stderr.strip()[-300:]}" if r.returncode else ""))
    if r.returncode:
        return
    hhead, hand_frames = read_pc2(os.path.join(hand, "cloth.pc2"))

    new = bpy.data.objects.get(f"{name}_anisocb")
    mc = [m for m in new.modifiers if m.type == "MESH_CACHE"] if new else []
    lr_mats = [m.material for m in obj.material_slots]
    hr_mats = [m.material for m in new.material_slots] if new else []
    check(f"{name}: new object {name}_anisocb with a Mesh Cache, materials and UVs kept",
          new is not None and len(mc) == 1 and mc[0].cache_format == "PC2" and hr_mats == lr_mats
          and len(new.data.uv_layers) == 1 and len(new.data.vertices) == hhead["points"],
          (f"{len(new.data.vertices)} vertices (LR {len(obj.data.vertices)}), Mesh Cache "
           f"{os.path.relpath(mc[0].filepath, d)} frame start {mc[0].frame_start:g}, materials "
           f"{[m.name for m in hr_mats]} (the LR object's own: {hr_mats == lr_mats}), UV maps "
           f"{[u.name for u in new.data.uv_layers]}") if new and mc else "missing")
    if new is None:
        return
    scene = bpy.context.scene
    worst, worst_box = 0.0, 0.0
    for fr in range(1, FRAMES + 1):
        scene.frame_set(fr)
        hw = world_verts(new)
        want = yup_to_blender(hand_frames[fr - 1].astype(np.float64))
        worst = max(worst, float(np.abs(hw - want).max()))
        lw = yup_to_blender(lr[fr - 1].astype(np.float64))  # the LR shot as exported
        worst_box = max(worst_box, float(np.abs(hw.min(0) - lw.min(0)).max()),
                        float(np.abs(hw.max(0) - lw.max(0)).max()))
    scene.frame_set(1)
    check(f"{name}: plays the by-hand upscale frame by frame", worst < 1e-4,
          f"max |evaluated world vertex - by-hand HR PC2 (Z up)| over {FRAMES} frames {worst:.2e} m (limit 1e-4)")
    check(f"{name}: in place over the LR cloth", worst_box < 0.03,
          f"largest HR/LR bounding-box bound difference over the frames {1000 * worst_box:.1f} mm (limit 30)")

    # Again, with the LR cloth now hidden (a hidden object is not evaluated: the add-on shows it
    # while exporting): the same LR export, the HR object replaced.
    hidden = obj.hide_get()
    with open(os.path.join(d, "cloth.pc2"), "rb") as fh:
        first = fh.read()
    ok, err = run_operator(object_name=name)
    with open(os.path.join(d, "cloth.pc2"), "rb") as fh:
        again = fh.read()
    n_new = sum(1 for o in bpy.data.objects if o.name.startswith(f"{name}_anisocb"))
    check(f"{name}: Upscale again with the LR cloth hidden", ok and again == first and n_new == 1
          and obj.hide_get() == hidden,
          f"LR hidden {hidden}; cloth.pc2 {'identical' if again == first else 'DIFFERS'}, "
          f"{n_new} {name}_anisocb object(s)" + (f"; error: {err}" if err else ""))


def check_errors(obj, out, exe):
    obj.anisocb.output_dir = out
    ok, err = run_operator(object_name=obj.name, binary=os.path.join(out, "no-such-dir", "anisocb"))
    check("error: a wrong binary path is reported", not ok and "not an executable" in err,
          f"operator reported: {err.strip()}")
    wrapper = os.path.join(out, "anisocb-bad-margin")
    with open(wrapper, "w") as fh:
        fh.write(f'#!/bin/sh\nexec {shlex.quote(exe)} "$@" --margin 5\n')
    os.chmod(wrapper, os.stat(wrapper).st_mode | stat.S_IXUSR)
    ok, err = run_operator(object_name=obj.name, binary=wrapper)
    check("error: the binary's own message for an invalid option is reported",
          not ok and "exit status 1" in err and "--margin" in err, f"operator reported: {err.strip()}")
    from anisocb_addon import STATE
    check("error: kept for the panel", "--margin" in STATE["error"], f"panel shows: {STATE['error'][:160]}")


def check_progress_and_cancel(obj, out, exe):
    """What the modal run does each timer tick, without a window: Job.steps() for the progress
    bar, and Cancel's kill on a binary that would run for a minute."""
    from anisocb_addon import core

    obj.anisocb.output_dir = os.path.join(out, "steps")
    job = core.Job(bpy.context, obj, obj.anisocb, exe)
    fracs = []
    for f, _ in job.steps():
        fracs.append(f)
        time.sleep(0.01)
    check("progress: Job.steps() rises to 1", fracs[-1] == 1.0 and all(b >= a for a, b in zip(fracs, fracs[1:]))
          and job.result is not None, f"{len(fracs)} steps, first {fracs[0]:.3f}, last {fracs[-1]:.3f}, "
          f"{sum(1 for f in fracs if 0.3 <= f < 0.95)} while the binary ran")
    sleeper = os.path.join(out, "anisocb-slow")
    with open(sleeper, "w") as fh:
        fh.write("#!/bin/sh\nexec sleep 60\n")
    os.chmod(sleeper, os.stat(sleeper).st_mode | stat.S_IXUSR)
    frame = bpy.context.scene.frame_current
    job = core.Job(bpy.context, obj, obj.anisocb, sleeper)
    steps = job.steps()
    while job.proc is None:
        next(steps)
    t0 = time.time()
    job.kill()  # what Esc and the panel's Cancel do
    steps.close()
    secs = time.time() - t0
    check("cancel: the running binary is stopped", job.proc.poll() is not None and secs < 5
          and bpy.context.scene.frame_current == frame,
          f"process ended with {job.proc.returncode} after {secs:.2f} s; scene frame {bpy.context.scene.frame_current}")


def check_zip(path):
    """Install from Disk: the zip installs as an extension, registers its operator and panel."""
    with quiet():
        r = bpy.ops.extensions.package_install_files(filepath=path, repo="user_default", enable_on_install=True)
    name = "bl_ext.user_default.anisocb"
    ok = "FINISHED" in r and name in bpy.context.preferences.addons and hasattr(bpy.types, "ANISOCB_PT_panel")
    with quiet():
        addon_utils.disable(name, default_set=True)
        repos = bpy.context.preferences.extensions.repos
        index = next(i for i, r in enumerate(repos) if r.module == "user_default")
        bpy.ops.extensions.package_uninstall(repo_index=index, pkg_id="anisocb")
    check("the zip installs as an extension (Install from Disk)", ok and not hasattr(bpy.types, "ANISOCB_PT_panel"),
          f"{os.path.basename(path)} -> add-on {name!r} registered, then disabled and removed")


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--anisocb", required=True, help="path to the anisocb binary")
    ap.add_argument("--keep", help="write everything into this folder and keep it")
    ap.add_argument("--zip", help="also install this add-on zip (make blender-addon) as an extension, "
                    "as Install from Disk does, check it registers, and remove it")
    a = ap.parse_args()
    exe = os.path.abspath(a.anisocb)
    if not os.access(exe, os.X_OK):
        sys.exit(f"{a.anisocb}: not an executable: build it with `cargo build --release`")
    work = None
    if a.keep:
        out = os.path.abspath(a.keep)
        os.makedirs(out, exist_ok=True)
    else:
        work = tempfile.TemporaryDirectory(prefix="anisocb-addon-")
        out = work.name
    print(f"Blender {bpy.app.version_string}; add-on from {os.path.join(REPO, 'blender', 'anisocb_addon')}")

    sheet, skirt, _ = build_scene()
    if a.zip:
        check_zip(os.path.abspath(a.zip))
    sys.path.insert(0, os.path.join(REPO, "blender"))
    with quiet():
        mod = addon_utils.enable("anisocb_addon", default_set=True, handle_error=None)
    check("add-on enables", mod is not None and hasattr(bpy.ops.anisocb, "upscale")
          and "anisocb_addon" in bpy.context.preferences.addons, f"module {getattr(mod, '__name__', None)}")
    bpy.context.preferences.addons["anisocb_addon"].preferences.binary = exe

    check_cloth(sheet, out, exe, lambda args: "--physics-pin" in args and args[args.index("--physics-pin") + 1] == "top"
                or "--physics-pin" in args)
    check_cloth(skirt, out, exe, lambda args: "--physics-pin-vertices" in args)
    check_progress_and_cancel(skirt, out, exe)
    check_errors(sheet, out, exe)

    if work is not None:
        work.cleanup()
    else:
        print(f"files kept in {out}")
    print(f"summary: {len(RESULTS) - len(FAILED)}/{len(RESULTS)} checks passed"
          + (f"; FAILED: {'; '.join(FAILED)}" if FAILED else ""))
    sys.exit(1 if FAILED else 0)


if __name__ == "__main__":
    main()
