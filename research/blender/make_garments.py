#!/usr/bin/env python3
"""Make LR/HR cloth animations of garment-like meshes that are not grids, with Blender's cloth.

Companion of make_scenes.py (square sheets) for anisocb's any-mesh path: each scene's cloth is
a mesh that is not a rectangular vertex grid (a tube, a triangulated disk, a sheet with a hole,
a T outline). Each is simulated twice with Blender's cloth modifier (the `bpy` module from
PyPI, pinned in research/blender/requirements.txt): once as built (LR) and once after one
level of *simple* subdivision applied before the simulation (HR: every edge split at its
midpoint, every quad into 4 quads, every triangle into 4 triangles; same outline, 4x the
faces). The subdivision appends the new vertices, so HR vertices 0..N_LR-1 are the LR
vertices at the same rest positions (checked). Every frame 1..N is exported with Blender's
OBJ exporter the way make_scenes.py does it (wm.obj_export: Y up, forward -Z, world space,
modifiers applied, UVs and normals on, polygons kept, materials off), plus the colliders:

    OUT/<scene>/lr/cloth_0001.obj ... cloth_NNNN.obj
    OUT/<scene>/hr/cloth_0001.obj ... cloth_NNNN.obj
    OUT/<scene>/collider/collider_0001.obj ...      (every collider object, world space)
    OUT/<scene>/scene.json                           (frames, fps, counts, collider, timing)

Scenes (metres; Blender is Z up, the OBJ files Y up):
  skirt-turn          a flared skirt, a tube of quads (24 around x 8 rows of faces, 216
                      vertices; waist r 0.16 m, hem r 0.30 m with 6 gentle flutes of +-3 cm,
                      0.55 m long), its waist ring pinned (vertex group "pin"). The skirt
                      object is parented to an invisible body (a 24-sided lathed collider:
                      waist r 0.145, hips r 0.165) that stands still for the first sixth of
                      the shot, turns 0 -> 90 deg about the vertical while moving 0.2 m
                      sideways (eased) until two thirds of it, then stands still. Blender's
                      cloth works in world space, so the pinned waist follows the body (to
                      ~2 mm at the fastest, checked on every frame) and the skirt swings after.
  round-tablecloth    a disk of triangles (r 0.6 m: a centre fan and 6 rings of 8k vertices,
                      169 vertices) dropped from 0.1 m above a round table (r 0.4 m cylinder).
  holed-sheet-sphere  a 0.8 m square sheet of quads (16 x 16 vertices, 15 x 15 cells) with a
                      centred square hole (5 x 5 cells deleted, 240 vertices left) dropped on a
                      sphere (r 0.25 m, friction 20) resting on a floor; the sphere's top goes
                      through the hole.
  tshirt-drop         a flat T-shirt outline of quads (body 0.5 x 0.7 m, sleeves 0.2 m, a
                      neck notch; 202 vertices) dropped over a box (0.3 x 0.4 m, 0.5 m high)
                      on a floor; it slides slowly towards one sleeve, whose cuff reaches the
                      floor.

Resolution consistency follows make_scenes.py: mass per vertex = areal density * area /
vertex count; stretch/shear stiffness times the spring-length ratio (HR 0.5) so that
k = stiffness / length is the same; air damping scaled with the vertex mass; the same
quality (substeps) for both.

Repeatability: skirt-turn, round-tablecloth and tshirt-drop came out bit-identical on a rerun;
holed-sheet-sphere drifted by up to 3 mm (Blender's threaded collision handling).

After writing, the script reads its OBJ files back and checks them: the same vertex count
and the same face list in every frame (a warning otherwise), vt/vn present; and prints per
scene the LR/HR counts, the cloth's bounding box at the first and last frame, the largest
per-frame vertex displacement, how far the HR run is from the LR run at the LR vertices, the
share of cloth vertices inside the collider (primitive shapes, approximate; last frame and
worst frame) and the seconds spent.

This is NOT part of `make test`: it needs bpy (a large download); all four scenes take about
half a minute of CPU.

Usage:
    python3 -m pip install -r research/blender/requirements.txt   # Python 3.11
    python3 research/blender/make_garments.py --out DIR [--frames N] [--scenes a,b] [--quality Q]
"""

import argparse
import glob
import json
import math
import os
import sys
import time

import numpy as np

try:
    import bpy
    import bmesh  # after bpy: the PyPI module provides it once bpy is loaded
except ImportError:
    sys.exit("make_garments.py needs Blender's bpy module: pip install -r research/blender/requirements.txt")

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from blender_common import add_collider, apply_transform, cloth_modifier, deselect_all, quiet, reset  # noqa: E402

QUALITY = None  # --quality: overrides every scene's cloth quality (substeps per frame)
FPS = 24


# --------------------------------------------------------------------------- scene building


def floor(z, size=6.0):
    bpy.ops.mesh.primitive_plane_add(size=size, location=(0, 0, z))
    obj = bpy.context.object
    obj.name = "floor"
    return add_collider(obj)


def planar_uv(extent):
    """UVs from the rest x, y (the mesh's own coordinates, before placing it)."""
    def uv(face, uv_layer):
        for loop in face.loops:
            x, y = loop.vert.co.x, loop.vert.co.y
            loop[uv_layer].uv = (0.5 + x / extent, 0.5 + y / extent)
    return uv


def cloth_object(name, verts, faces, subdivide, uv_fn, location=(0, 0, 0), rotation=(0, 0, 0)):
    """A mesh object from vertex positions and faces (index tuples); with `subdivide`, one
    level of simple subdivision first (midpoints; quads -> 4 quads, triangles -> 4 triangles;
    new vertices appended after the originals). Smooth shaded, one UV map, transforms applied."""
    bm = bmesh.new()
    bv = [bm.verts.new(co) for co in verts]
    for f in faces:
        bm.faces.new([bv[i] for i in f])
    n_faces = len(bm.faces)
    if subdivide:
        bmesh.ops.subdivide_edges(bm, edges=bm.edges[:], cuts=1, use_grid_fill=True)
        assert len(bm.faces) == 4 * n_faces, f"subdivision made {len(bm.faces)} faces from {n_faces}"
    bm.verts.index_update()
    uv_layer = bm.loops.layers.uv.new("UVMap")
    for f in bm.faces:
        uv_fn(f, uv_layer)
    me = bpy.data.meshes.new(name)
    bm.to_mesh(me)
    bm.free()
    co = np.array([v.co[:] for v in me.vertices])
    assert np.allclose(co[: len(verts)], np.array(verts), atol=1e-6), "subdivision reordered the vertices"
    me.shade_smooth()
    obj = bpy.data.objects.new(name, me)
    bpy.context.collection.objects.link(obj)
    obj.location = location
    obj.rotation_euler = rotation
    apply_transform(obj)
    return obj


def fabric(density, bend, air=1.0, bend_damp=0.5, quality=12):
    """make_scenes.py's fabric: areal density (kg/m²), angular bending stiffness, air damping;
    stretch, shear and their damping the same in every scene."""
    return dict(density=density, quality=quality, air=air, tension=15.0, compression=15.0, shear=5.0,
                damp=5.0, bend=bend, bend_damp=bend_damp)


def mesh_area(obj):
    return sum(p.area for p in obj.data.polygons)


def add_cloth(obj, hr, n_lr, frames, p, pin_fn=None):
    """Cloth modifier with resolution-consistent settings (module docstring). `pin_fn(co)`
    says which rest vertices (object coordinates) go into the pin group."""
    n = len(obj.data.vertices)
    k_scale = 0.5 if hr else 1.0  # simple subdivision halves every spring
    mass = p["density"] * mesh_area(obj) / n
    m_scale = n_lr / n

    pins = []
    if pin_fn is not None:
        pins = [v.index for v in obj.data.vertices if pin_fn(v.co)]
        assert pins, "no pinned vertices"
        vg = obj.vertex_groups.new(name="pin")
        vg.add(pins, 1.0, "REPLACE")

    mod = cloth_modifier(obj, p, QUALITY or p["quality"], mass, m_scale, k_scale, frames, bool(pins))
    s = mod.settings
    return dict(pinned=len(pins), mass_per_vertex=mass, quality=s.quality,
                stretch_stiffness=p["tension"] * k_scale, shear_stiffness=p["shear"] * k_scale,
                bending_stiffness=p["bend"], air_damping=s.air_damping)


# --- skirt-turn

SKIRT = dict(around=24, rows=8, waist_r=0.16, hem_r=0.30, length=0.55, waist_z=1.0, folds=6, fold_amp=0.03)
# The body: a lathe of (radius, z) through waist and hips, capped, 24 sides.
# It stands still for the first sixth of the shot (the skirt settles), turns and shifts (eased)
# until two thirds of the shot, then stands still again (the skirt swings on and settles).
BODY = dict(profile=[(0.15, 0.30), (0.165, 0.80), (0.145, 1.0), (0.14, 1.20)], sides=24,
            turn_deg=90.0, shift_x=0.2)


def body_keys(frames):
    return 1 + frames // 6, 1 + (2 * frames) // 3


def lathe(name, profile, sides):
    """A closed surface of revolution about the z axis from (radius, z) pairs, capped."""
    verts, faces = [], []
    for r, z in profile:
        for i in range(sides):
            a = 2 * math.pi * i / sides
            verts.append((r * math.cos(a), r * math.sin(a), z))
    for j in range(len(profile) - 1):
        for i in range(sides):
            a, b = j * sides + i, j * sides + (i + 1) % sides
            faces.append((a, b, b + sides, a + sides))
    faces.append(tuple(reversed(range(sides))))
    top = (len(profile) - 1) * sides
    faces.append(tuple(range(top, top + sides)))
    me = bpy.data.meshes.new(name)
    me.from_pydata(verts, [], faces)
    me.update()
    obj = bpy.data.objects.new(name, me)
    bpy.context.collection.objects.link(obj)
    return obj


def skirt_mesh():
    s = SKIRT
    n = s["around"]
    verts = []
    for j in range(s["rows"] + 1):  # ring 0 = waist
        t = j / s["rows"]
        r0 = s["waist_r"] + (s["hem_r"] - s["waist_r"]) * t
        z = s["waist_z"] - s["length"] * t
        for i in range(n):
            a = 2 * math.pi * i / n
            # gentle flutes growing towards the hem: the rest shape of a cone is a stable
            # equilibrium for Blender's cloth (its bending keeps the rest angles), so a plain
            # cone just turns rigidly with the body; flutes give it folds to swing.
            r = r0 + s["fold_amp"] * t * math.sin(s["folds"] * a)
            verts.append((r * math.cos(a), r * math.sin(a), z))
    faces = []
    for j in range(s["rows"]):
        for i in range(n):
            a, b = j * n + i, j * n + (i + 1) % n
            faces.append((a, a + n, b + n, b))  # normals point outwards
    return verts, faces


def skirt_uv(face, uv_layer):
    """u = angle / 2pi, unwrapped across the seam per face; v = height from the hem / length."""
    s = SKIRT
    ang = [math.atan2(l.vert.co.y, l.vert.co.x) % (2 * math.pi) for l in face.loops]
    if max(ang) - min(ang) > math.pi:  # the face straddles the seam at angle 0
        ang = [a + 2 * math.pi if a < math.pi else a for a in ang]
    for loop, a in zip(face.loops, ang):
        v = (loop.vert.co.z - (s["waist_z"] - s["length"])) / s["length"]
        loop[uv_layer].uv = (a / (2 * math.pi), v)


def scene_skirt_turn(hr, frames):
    body = lathe("body", BODY["profile"], BODY["sides"])
    add_collider(body, thickness=0.01, friction=5.0)
    body.hide_render = True  # invisible: only a collider and the skirt's parent
    verts, faces = skirt_mesh()
    cloth = cloth_object("skirt", verts, faces, hr, skirt_uv)
    cloth.parent = body  # body is at the identity on frame 1: no parent inverse needed
    # Eased turn and sideways shift (Bezier keys, auto-clamped handles), held before and after.
    t0, t1 = body_keys(frames)
    body.location = (0, 0, 0)
    body.rotation_euler = (0, 0, 0)
    body.keyframe_insert(data_path="location", frame=t0)
    body.keyframe_insert(data_path="rotation_euler", frame=t0)
    body.location = (BODY["shift_x"], 0, 0)
    body.rotation_euler = (0, 0, math.radians(BODY["turn_deg"]))
    body.keyframe_insert(data_path="location", frame=t1)
    body.keyframe_insert(data_path="rotation_euler", frame=t1)
    waist_z = SKIRT["waist_z"]
    info = add_cloth(cloth, hr, len(verts), frames, fabric(30.0, 0.2),
                     pin_fn=lambda co: co.z > waist_z - 1e-5)
    shape = dict(kind="lathe (body, turning and shifting)", object="body", profile=BODY["profile"],
                 sides=BODY["sides"])
    return cloth, [body], shape, info


# --- round-tablecloth

DISK = dict(radius=0.6, rings=6, per_ring=8)
TABLE = dict(radius=0.4, height=0.75, sides=64)


def disk_mesh():
    """A centre vertex and rings k = 1..R of per_ring * k vertices, zipped into triangles."""
    R, m = DISK["rings"], DISK["per_ring"]
    verts = [(0.0, 0.0, 0.0)]
    starts = []
    for k in range(1, R + 1):
        starts.append(len(verts))
        r = DISK["radius"] * k / R
        for i in range(m * k):
            a = 2 * math.pi * i / (m * k)
            verts.append((r * math.cos(a), r * math.sin(a), 0.0))
    faces = [(0, starts[0] + i, starts[0] + (i + 1) % m) for i in range(m)]
    for k in range(2, R + 1):
        ni, no = m * (k - 1), m * k
        si, so = starts[k - 2], starts[k - 1]
        i = o = 0
        while i < ni or o < no:
            # advance along the ring whose next vertex comes first in angle
            if o < no and (i >= ni or (o + 1) / no <= (i + 1) / ni):
                faces.append((si + i % ni, so + o % no, so + (o + 1) % no))
                o += 1
            else:
                faces.append((si + i % ni, so + o % no, si + (i + 1) % ni))
                i += 1
    assert len(faces) == m * R * R
    return verts, faces


def scene_round_tablecloth(hr, frames):
    t = TABLE
    bpy.ops.mesh.primitive_cylinder_add(radius=t["radius"], depth=t["height"], vertices=t["sides"],
                                        location=(0, 0, t["height"] / 2))
    table = bpy.context.object
    table.name = "table"
    apply_transform(table)
    add_collider(table, thickness=0.01, friction=5.0)
    verts, faces = disk_mesh()
    cloth = cloth_object("tablecloth", verts, faces, hr, planar_uv(2 * DISK["radius"]),
                         location=(0.04, -0.03, t["height"] + 0.1), rotation=(0, 0, math.radians(10)))
    info = add_cloth(cloth, hr, len(verts), frames, fabric(40.0, 0.5))
    shape = dict(kind="cylinder (table)", object="table", radius=t["radius"], z0=0.0, z1=t["height"],
                 sides=t["sides"])
    return cloth, [table], shape, info


# --- holed-sheet-sphere


def cell_sheet(nx, ny, cell, keep):
    """Quads of a grid of nx x ny cells of side `cell`, only the cells (i, j) with keep(i, j);
    only the vertices those cells use, in row order; centred on the origin."""
    used = {}
    cells = [(i, j) for j in range(ny) for i in range(nx) if keep(i, j)]
    for i, j in cells:
        for c in ((i, j), (i + 1, j), (i + 1, j + 1), (i, j + 1)):
            used[c] = True
    order = sorted(used, key=lambda c: (c[1], c[0]))
    index = {c: k for k, c in enumerate(order)}
    verts = [((i - nx / 2) * cell, (j - ny / 2) * cell, 0.0) for i, j in order]
    faces = [tuple(index[c] for c in ((i, j), (i + 1, j), (i + 1, j + 1), (i, j + 1))) for i, j in cells]
    return verts, faces


HOLED = dict(cells=15, size=0.8, hole=(5, 10))  # 16 x 16 vertices; cells 5..9 both ways deleted
SPHERE = dict(radius=0.25, segments=48, rings=24)


def scene_holed_sheet_sphere(hr, frames):
    r = SPHERE["radius"]
    bpy.ops.mesh.primitive_uv_sphere_add(radius=r, segments=SPHERE["segments"], ring_count=SPHERE["rings"],
                                         location=(0, 0, r))
    sphere = bpy.context.object
    sphere.name = "sphere"
    apply_transform(sphere)
    sphere.data.shade_smooth()
    # A grippy ball: with make_scenes.py's friction 5 the sheet slid off the top in one run
    # and not in the other (HR vs LR 0.15 m apart by frame 48); with 20 both stay put.
    add_collider(sphere, thickness=0.01, friction=20.0)
    floor(0.0)
    n, (h0, h1) = HOLED["cells"], HOLED["hole"]
    cell = HOLED["size"] / n
    verts, faces = cell_sheet(n, n, cell, lambda i, j: not (h0 <= i < h1 and h0 <= j < h1))
    cloth = cloth_object("holed_sheet", verts, faces, hr, planar_uv(HOLED["size"]),
                         location=(0.01, -0.008, 2 * r + 0.1), rotation=(0, 0, math.radians(15)))
    info = add_cloth(cloth, hr, len(verts), frames, fabric(35.0, 0.5))
    shape = dict(kind="sphere on a floor", object="sphere", radius=r, segments=SPHERE["segments"], floor_z=0.0)
    return cloth, [sphere, bpy.data.objects["floor"]], shape, info


# --- tshirt-drop

TSHIRT = dict(cell=0.05, nx=18, ny=14, body=(4, 14), sleeve_rows=4, neck=(7, 11))
BOX = dict(size=(0.3, 0.4, 0.5), turn_deg=20.0)


def tshirt_keep(i, j):
    t = TSHIRT
    in_body = t["body"][0] <= i < t["body"][1]
    in_sleeves = j >= t["ny"] - t["sleeve_rows"]
    in_neck = t["neck"][0] <= i < t["neck"][1] and j == t["ny"] - 1
    return (in_body or in_sleeves) and not in_neck


def scene_tshirt_drop(hr, frames):
    sx, sy, sz = BOX["size"]
    bpy.ops.mesh.primitive_cube_add(size=1.0, location=(0, 0, sz / 2), rotation=(0, 0, math.radians(BOX["turn_deg"])))
    box = bpy.context.object
    box.name = "box"
    box.scale = (sx, sy, sz)
    apply_transform(box)
    add_collider(box, thickness=0.01, friction=5.0)
    floor(0.0)
    t = TSHIRT
    verts, faces = cell_sheet(t["nx"], t["ny"], t["cell"], tshirt_keep)
    cx, cy = np.array(verts)[:, :2].mean(0)  # centre the shirt's mass (sleeves and all) over the box
    verts = [(x - cx, y - cy, z) for x, y, z in verts]
    cloth = cloth_object("tshirt", verts, faces, hr, planar_uv(t["nx"] * t["cell"]),
                         location=(0.02, 0.03, sz + 0.15), rotation=(0, 0, math.radians(-5)))
    info = add_cloth(cloth, hr, len(verts), frames, fabric(30.0, 0.4))
    shape = dict(kind="box on a floor", object="box", size=BOX["size"], turn_deg=BOX["turn_deg"], floor_z=0.0)
    return cloth, [box, bpy.data.objects["floor"]], shape, info


SCENES = {
    "skirt-turn": scene_skirt_turn,
    "round-tablecloth": scene_round_tablecloth,
    "holed-sheet-sphere": scene_holed_sheet_sphere,
    "tshirt-drop": scene_tshirt_drop,
}


def export(objs, path, uv):
    deselect_all()
    for o in objs:
        o.select_set(True)
    bpy.context.view_layer.objects.active = objs[0]
    with quiet(1):  # "Writing to ..." / "File exported successfully" per frame
        bpy.ops.wm.obj_export(
            filepath=path,
            export_animation=False,
            export_selected_objects=True,
            apply_modifiers=True,
            export_eval_mode="DAG_EVAL_VIEWPORT",
            forward_axis="NEGATIVE_Z",
            up_axis="Y",
            global_scale=1.0,
            export_uv=uv,
            export_normals=True,
            export_materials=False,
            export_triangulated_mesh=False,
            export_object_groups=False,
            export_vertex_groups=False,
        )


def clear(folder, prefix):
    os.makedirs(folder, exist_ok=True)
    for old in glob.glob(os.path.join(folder, f"{prefix}_*.obj")) + glob.glob(os.path.join(folder, f"{prefix}_*.mtl")):
        os.remove(old)


def simulate_and_export(build, hr, frames, scene_dir):
    """Build the scene, step it frame by frame, export the cloth (and, for LR, the colliders)."""
    out_dir = os.path.join(scene_dir, "hr" if hr else "lr")
    col_dir = None if hr else os.path.join(scene_dir, "collider")
    clear(out_dir, "cloth")
    if col_dir:
        clear(col_dir, "collider")
    scene = reset(FPS)
    scene.frame_start = 1
    scene.frame_end = frames
    scene.frame_set(1)
    with quiet(2):  # harmless dependency-graph warnings (see make_scenes.py)
        cloth, colliders, shape, info = build(hr, frames)
        bpy.context.view_layer.update()
    for fr in range(1, frames + 1):
        scene.frame_set(fr)  # steps the cloth cache frame by frame
        export([cloth], os.path.join(out_dir, f"cloth_{fr:04d}.obj"), uv=True)
        if col_dir:
            export(colliders, os.path.join(col_dir, f"collider_{fr:04d}.obj"), uv=False)
    info.update(vertices=len(cloth.data.vertices), faces=len(cloth.data.polygons))
    return shape, info


# --------------------------------------------------------------------------- checking


def read_obj(path):
    """Vertices (k, 3) in Blender's Z-up coordinates, vertices per object name, counts of vt/vn,
    and the faces as tuples of 0-based vertex indices."""
    v, objects, nvt, nvn, faces = [], {}, 0, 0, []
    name = None
    with open(path) as fh:
        for line in fh:
            if line.startswith("v "):
                x, y, z = (float(c) for c in line.split()[1:4])
                v.append([x, -z, y])  # OBJ Y up, forward -Z -> Blender Z up
                objects.setdefault(name, []).append(len(v) - 1)
            elif line.startswith("o "):
                name = line.split(None, 1)[1].strip()
            elif line.startswith("vt "):
                nvt += 1
            elif line.startswith("vn "):
                nvn += 1
            elif line.startswith("f "):
                faces.append(tuple(int(c.split("/")[0]) - 1 for c in line.split()[1:]))
    return np.array(v), objects, nvt, nvn, faces


def read_run(out_dir, frames, warnings):
    seq, faces0 = [], None
    for fr in range(1, frames + 1):
        path = os.path.join(out_dir, f"cloth_{fr:04d}.obj")
        v, _, nvt, nvn, faces = read_obj(path)
        if nvt == 0 or nvn == 0:
            warnings.append(f"{path}: vt {nvt}, vn {nvn}")
        if faces0 is None:
            faces0 = faces
        elif faces != faces0 or (seq and v.shape != seq[0].shape):
            warnings.append(f"{path}: {v.shape[0]} vertices / {len(faces)} faces differ from frame 1")
        seq.append(v)
    if any(s.shape != seq[0].shape for s in seq):
        return None, faces0
    return np.stack(seq), faces0


def collider_at(scene_dir, frame, name):
    v, objects, *_ = read_obj(os.path.join(scene_dir, "collider", f"collider_{frame:04d}.obj"))
    key = next(k for k in objects if k and k.split(".")[0].startswith(name))
    return v[objects[key]]


def inside_share(scene_dir, frame, shape, pts, tol=0.002):
    """Share of cloth points inside the collider (deeper than `tol`), using the primitive shape
    and the collider's exported vertices for its placement on that frame."""
    cv = collider_at(scene_dir, frame, shape["object"])
    inside = np.zeros(len(pts), bool)
    if shape["object"] == "body":
        c = cv[:, :2].mean(0)  # the lathe is symmetric: its vertex mean is on its axis
        prof = np.array(shape["profile"])
        d = np.linalg.norm(pts[:, :2] - c, axis=1)
        z = pts[:, 2]
        r = np.interp(z, prof[:, 1], prof[:, 0]) * math.cos(math.pi / shape["sides"])
        inside = (z > prof[0, 1]) & (z < prof[-1, 1]) & (d < r - tol)
    elif shape["object"] == "table":
        c = cv[:, :2].mean(0)
        d = np.linalg.norm(pts[:, :2] - c, axis=1)
        r = shape["radius"] * math.cos(math.pi / shape["sides"])
        inside = (pts[:, 2] < shape["z1"] - tol) & (pts[:, 2] > shape["z0"]) & (d < r - tol)
    elif shape["object"] == "sphere":
        c = cv.mean(0)
        inside = np.linalg.norm(pts - c, axis=1) < shape["radius"] * math.cos(math.pi / shape["segments"]) - tol
    elif shape["object"] == "box":
        c = cv.mean(0)
        a = math.radians(shape["turn_deg"])
        rel = pts - c
        local = np.stack([rel[:, 0] * math.cos(a) + rel[:, 1] * math.sin(a),
                          -rel[:, 0] * math.sin(a) + rel[:, 1] * math.cos(a), rel[:, 2]], 1)
        inside = np.all(np.abs(local) < np.array(shape["size"]) / 2 - tol, axis=1)
    if "floor_z" in shape:
        inside |= pts[:, 2] < shape["floor_z"] - tol
    return inside.mean()


def bbox(v):
    lo, hi = v.min(0), v.max(0)
    return "[" + ", ".join(f"{a:+.3f}..{b:+.3f}" for a, b in zip(lo, hi)) + "]"


def check_scene(name, scene_dir, frames, meta):
    warnings = []
    runs = {}
    for res in ("lr", "hr"):
        runs[res], faces = read_run(os.path.join(scene_dir, res), frames, warnings)
        meta[res]["obj_faces"] = len(faces)
        meta[res]["face_sizes"] = sorted({len(f) for f in faces})
    lr, hr = runs["lr"], runs["hr"]
    if lr is None or hr is None:
        warnings.append("vertex count changes between frames: no further checks")
        return warnings
    n_lr = lr.shape[1]
    rest_err = np.abs(hr[0, :n_lr] - lr[0]).max()
    if rest_err > 1e-5:
        warnings.append(f"HR vertices 0..{n_lr - 1} are not the LR vertices at rest (max {rest_err:.2e} m)")
    print(f"== {name}: {frames} frames; LR {lr.shape[1]} vertices / {meta['lr']['obj_faces']} faces "
          f"(sizes {meta['lr']['face_sizes']}), HR {hr.shape[1]} / {meta['hr']['obj_faces']} "
          f"(sizes {meta['hr']['face_sizes']}); HR[:N_LR] = LR at rest to {rest_err:.1e} m; "
          f"{meta['seconds_total']:.1f} s")
    gap = np.linalg.norm(hr[:, :n_lr] - lr, axis=2)  # same rest vertex, LR run vs HR run
    picks = sorted({2, frames // 4, frames // 2, frames})
    meta["hr_vs_lr_gap"] = {f"frame {f}": [float(gap[f - 1].mean()), float(gap[f - 1].max())] for f in picks}
    print("   HR-vs-LR gap at the LR vertices (m), mean / max:  " + "  ".join(
        f"f{f}: {gap[f - 1].mean():.3f}/{gap[f - 1].max():.3f}" for f in picks))
    checks = {}
    for res, seq in (("lr", lr), ("hr", hr)):
        step = np.linalg.norm(np.diff(seq, axis=0), axis=2).max(1)  # per frame, largest vertex move
        disp = np.linalg.norm(seq[-1] - seq[0], axis=1)
        share = inside_share(scene_dir, frames, meta["collider"], seq[-1])
        share_all = max(inside_share(scene_dir, f, meta["collider"], seq[f - 1]) for f in range(1, frames + 1))
        checks[res] = dict(bbox_first=[seq[0].min(0).tolist(), seq[0].max(0).tolist()],
                           bbox_last=[seq[-1].min(0).tolist(), seq[-1].max(0).tolist()],
                           max_step=float(step.max()), max_step_frame=int(step.argmax()) + 2,
                           max_displacement_last=float(disp.max()), inside_last=float(share),
                           inside_max_any_frame=float(share_all))
        print(f"   {res.upper()} frame 1 bbox {bbox(seq[0])}   frame {frames} bbox {bbox(seq[-1])}  (Blender Z up)")
        print(f"   {res.upper()} largest per-frame move {step.max():.4f} m (frame {step.argmax() + 2}); "
              f"largest move frame 1 -> {frames} {disp.max():.3f} m; inside collider: last frame "
              f"{100 * share:.1f} %, worst frame {100 * share_all:.1f} %")
        if share > 0.01:
            warnings.append(f"{res}: {100 * share:.1f} % of the cloth inside the collider on the last frame")
        if step.max() > 0.25:
            warnings.append(f"{res}: a vertex moved {step.max():.2f} m in one frame (explosion?)")
    if name == "skirt-turn":
        # The pinned waist must follow the body: its rest positions moved rigidly as the body
        # (the turn and shift read from the exported body: its axis and its vertex 0) on every
        # frame. Also how far the rest of the skirt is from that rigid motion (it swings).
        body0 = collider_at(scene_dir, 1, "body")
        a0 = math.atan2(*(body0[0, :2] - body0[:, :2].mean(0))[::-1])
        for res, seq in (("lr", lr), ("hr", hr)):
            waist = np.abs(seq[0, :, 2] - SKIRT["waist_z"]) < 1e-4
            err, swing = 0.0, 0.0
            for f in range(1, frames + 1):
                b = collider_at(scene_dir, f, "body")
                c = b[:, :2].mean(0)
                a = math.atan2(*(b[0, :2] - c)[::-1]) - a0
                rot = np.array([[math.cos(a), -math.sin(a), 0], [math.sin(a), math.cos(a), 0], [0, 0, 1]])
                rigid = seq[0] @ rot.T + np.array([c[0], c[1], 0.0])
                err = max(err, np.linalg.norm(seq[f - 1, waist] - rigid[waist], axis=1).max())
                swing = max(swing, np.linalg.norm(seq[f - 1] - rigid, axis=1).max())
            checks[res]["waist_follow_err"] = float(err)
            checks[res]["max_off_rigid"] = float(swing)
            print(f"   {res.upper()} waist ({waist.sum()} pinned vertices) vs the body's motion, all frames: "
                  f"max {err:.1e} m; skirt off the body's rigid motion: max {swing:.3f} m")
            if err > 5e-3:
                warnings.append(f"{res}: the pinned waist is {err:.3f} m off the body's motion")
    meta["checks"] = checks
    for w in warnings:
        print(f"   WARNING: {w}")
    return warnings


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", required=True, help="output folder (keep it outside the repo)")
    ap.add_argument("--frames", type=int, default=48)
    ap.add_argument("--scenes", default=",".join(SCENES), help="comma-separated scenes (default: all: "
                    + ",".join(SCENES) + ")")
    ap.add_argument("--quality", type=int, default=None, help="override the scenes' cloth quality (steps/frame)")
    args = ap.parse_args()
    global QUALITY
    QUALITY = args.quality
    names = [s for s in args.scenes.split(",") if s]
    for s in names:
        if s not in SCENES:
            sys.exit(f"unknown scene {s!r}; known: {', '.join(SCENES)}")
    if args.frames < 2:
        sys.exit("--frames must be at least 2")
    print(f"Blender {bpy.app.version_string}, {args.frames} frames, scenes {', '.join(names)} -> {args.out}")
    t_all = time.time()
    n_warn = 0
    for name in names:
        t0 = time.time()
        scene_dir = os.path.join(args.out, name)
        meta = dict(scene=name, frames=args.frames, fps=FPS, blender=bpy.app.version_string,
                    up_axis="Y (OBJ); Blender Z up", units="m",
                    hr_mesh="LR after one level of simple subdivision (midpoints), applied before simulating; "
                            "HR vertices 0..N_LR-1 are the LR vertices",
                    files=dict(lr="lr/cloth_NNNN.obj", hr="hr/cloth_NNNN.obj", collider="collider/collider_NNNN.obj",
                               obj="Y up, forward -Z, world space, v/vt/vn, polygons as simulated, no materials"))
        if name == "skirt-turn":
            meta["body_motion"] = dict(keys=body_keys(args.frames), turn_deg=BODY["turn_deg"], shift_x=BODY["shift_x"],
                                       interpolation="Bezier, auto-clamped (eased), held outside the keys")
        for res, hr in (("lr", False), ("hr", True)):
            t1 = time.time()
            shape, info = simulate_and_export(SCENES[name], hr, args.frames, scene_dir)
            info["seconds"] = round(time.time() - t1, 2)
            meta[res] = info
            meta["collider"] = shape
            print(f"   {name}/{res}: {info['vertices']} vertices, {info['faces']} faces, "
                  f"simulated and exported in {info['seconds']:.1f} s", flush=True)
        meta["seconds_total"] = round(time.time() - t0, 2)
        meta["warnings"] = check_scene(name, scene_dir, args.frames, meta)
        n_warn += len(meta["warnings"])
        with open(os.path.join(scene_dir, "scene.json"), "w") as fh:
            json.dump(meta, fh, indent=1)
    print(f"all done in {time.time() - t_all:.1f} s, {n_warn} warning(s)")


if __name__ == "__main__":
    main()
