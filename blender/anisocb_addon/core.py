"""What the add-on does, without its UI: export the cloth's shot, build the `anisocb upscale`
command, run it, and bring the HR result back.

Axes. Blender is Z up; the files written here are Y up with forward -Z, as Blender's OBJ
exporter writes them by default: a world point (X, Y, Z) is written (X, Z, -Y). Gravity is
turned the same way. The HR object gets the inverse turn (+90 deg about X) as its transform,
so its mesh and the Mesh Cache modifier hold the file's coordinates unchanged.
"""

import math
import os
import re
import shutil
import struct
import subprocess
import threading
from collections import deque

import bpy
import numpy as np

# Blender's own cloth presets (scripts/presets/cloth/*.py): mass per vertex (kg), bending.
BLENDER_PRESETS = {
    "Silk": (0.15, 0.05),
    "Cotton": (0.3, 0.5),
    "Denim": (1.0, 10.0),
    "Leather": (0.4, 150.0),
    "Rubber": (3.0, 25.0),
}
# Blender preset -> anisocb material. Blender's cotton-like cloth (bending 0.5) folds finer
# than anisocb's cotton: `--preset blender` (silk) was chosen on such scenes (docs/results.md).
TO_ANISOCB = {"Silk": "silk", "Cotton": "silk", "Denim": "denim", "Leather": "denim", "Rubber": "rubber"}
MATERIALS = ("silk", "cotton", "denim", "rubber")
PIN_WEIGHT = 0.5  # a vertex of the pin group with at least this weight is held

PC2_HEADER = struct.Struct("<12siiffi")


class AddonError(Exception):
    """A problem the user can fix; the message says how."""


# --------------------------------------------------------------------------- small helpers


def to_yup(co):
    """Blender world (Z up) -> file axes (Y up, forward -Z): (x, y, z) -> (x, z, -y)."""
    co = np.asarray(co, dtype=np.float64)
    return np.stack([co[..., 0], co[..., 2], -co[..., 1]], axis=-1)


def from_yup(co):
    co = np.asarray(co, dtype=np.float64)
    return np.stack([co[..., 0], -co[..., 2], co[..., 1]], axis=-1)


def fmt(x):
    return "%.9g" % x


def safe_name(name):
    """A name usable as a file name and an OBJ `usemtl` word."""
    s = re.sub(r"[^A-Za-z0-9_.-]+", "_", name).strip("._")
    return s or "unnamed"


def fps_of(scene):
    return scene.render.fps / scene.render.fps_base


def gravity_of(scene, cloth_settings):
    """The gravity the cloth feels (m/s^2), in the files' Y-up axes."""
    if not scene.use_gravity:
        return (0.0, 0.0, 0.0)
    g = np.array(scene.gravity, dtype=np.float64) * cloth_settings.effector_weights.gravity
    return tuple(float("%.6g" % v) + 0.0 for v in to_yup(g))  # scene.gravity is float32


def nearest_material(settings):
    """(anisocb material, nearest Blender preset) for the cloth's mass and bending."""
    m = max(settings.mass, 1e-6)
    b = max(settings.bending_stiffness, 1e-6)
    best = min(BLENDER_PRESETS, key=lambda k: math.log(m / BLENDER_PRESETS[k][0]) ** 2
               + math.log(b / BLENDER_PRESETS[k][1]) ** 2)
    return TO_ANISOCB[best], best


def cloth_modifier(obj):
    if obj is None or obj.type != "MESH":
        return None
    for m in obj.modifiers:
        if m.type == "CLOTH":
            return m
    return None


def find_binary(pref_path):
    """The anisocb binary: the preference's path, else `anisocb` on PATH."""
    if pref_path:
        p = bpy.path.abspath(pref_path)
        if os.path.isfile(p) and os.access(p, os.X_OK):
            return p
        raise AddonError(f"anisocb binary {p!r} is not an executable file: set its path in Edit > "
                         "Preferences > Add-ons > anisocb (build it with `cargo build --release`: "
                         "target/release/anisocb)")
    p = shutil.which("anisocb")
    if p:
        return p
    raise AddonError("anisocb binary not found: set its path in Edit > Preferences > Add-ons > "
                     "anisocb, or put anisocb on PATH")


# --------------------------------------------------------------------------- mesh reading


def evaluated_world(obj, depsgraph, topology=False):
    """World-space vertices (Z up, float64, n x 3) of the evaluated object, and with
    `topology` its faces, UVs, material indices and smooth flags."""
    ev = obj.evaluated_get(depsgraph)
    me = ev.to_mesh()
    try:
        n = len(me.vertices)
        co = np.empty(n * 3, dtype=np.float32)
        me.vertices.foreach_get("co", co)
        mw = np.array(ev.matrix_world, dtype=np.float64)
        co = co.reshape(-1, 3).astype(np.float64) @ mw[:3, :3].T + mw[:3, 3]
        if not topology:
            return co, None
        np_ = len(me.polygons)
        loop_start = np.empty(np_, dtype=np.int64)
        loop_total = np.empty(np_, dtype=np.int64)
        me.polygons.foreach_get("loop_start", loop_start)
        me.polygons.foreach_get("loop_total", loop_total)
        loop_vert = np.empty(len(me.loops), dtype=np.int64)
        me.loops.foreach_get("vertex_index", loop_vert)
        mat = np.empty(np_, dtype=np.int64)
        me.polygons.foreach_get("material_index", mat)
        smooth = np.empty(np_, dtype=bool)
        me.polygons.foreach_get("use_smooth", smooth)
        uv, uv_name = None, None
        layer = me.uv_layers.active
        if layer is not None and len(me.loops):
            uv = np.empty(len(me.loops) * 2, dtype=np.float32)
            layer.data.foreach_get("uv", uv)
            uv = uv.reshape(-1, 2)
            uv_name = layer.name
        tris = np.empty(len(me.loop_triangles) * 3, dtype=np.int64)
        me.loop_triangles.foreach_get("vertices", tris)
        topo = dict(loop_start=loop_start, loop_total=loop_total, loop_vert=loop_vert, mat=mat,
                    smooth=smooth, uv=uv, uv_name=uv_name, tris=tris.reshape(-1, 3))
        return co, topo
    finally:
        ev.to_mesh_clear()


def faces_of(topo):
    return [topo["loop_vert"][s:s + t].tolist() for s, t in zip(topo["loop_start"], topo["loop_total"])]


def hr_point_count(nv, faces, grid):
    """Vertices of the HR mesh anisocb writes: 2W x 2H for a grid, else the subdivision."""
    if grid is not None:
        return 4 * grid["w"] * grid["h"]
    edges = set()
    for f in faces:
        for k in range(len(f)):
            a, b = f[k], f[(k + 1) % len(f)]
            edges.add((a, b) if a < b else (b, a))
    return nv + len(edges) + sum(1 for f in faces if len(f) == 4)


def recover_grid(nv, faces):
    """The grid anisocb sees in a quad mesh, as its OBJ reader recovers it (src/geom/obj.rs
    `recover_grid`): its four edges as vertex lists named top/bottom/left/right (row 0 = top,
    column 0 = left), or None for a mesh that is not a quad grid."""
    if not faces or any(len(f) != 4 for f in faces):
        return None
    count = [0] * nv
    edge_faces = {}
    for q, f in enumerate(faces):
        for k in range(4):
            a, b = f[k], f[(k + 1) % 4]
            edge_faces.setdefault((min(a, b), max(a, b)), []).append(q)
            count[f[k]] += 1
    if 0 in count or any(len(v) > 2 for v in edge_faces.values()):
        return None
    corners = [v for v in range(nv) if count[v] == 1]
    if len(corners) != 4:
        return None
    border_nb = [[] for _ in range(nv)]
    for (a, b), fs in edge_faces.items():
        if len(fs) == 1:
            border_nb[a].append(b)
            border_nb[b].append(a)

    def walk(start, first):
        line = [start, first]
        while count[line[-1]] != 1:
            nxt = [v for v in border_nb[line[-1]] if v != line[-2]]
            if len(nxt) != 1 or len(line) > nv:
                return None
            line.append(nxt[0])
        return line

    c0 = corners[0]
    q0 = next(f for f in faces if c0 in f)
    p = q0.index(c0)
    na, nb = q0[(p + 1) % 4], q0[(p + 3) % 4]
    right, down = min(na, nb), max(na, nb)
    if right not in border_nb[c0] or down not in border_nb[c0]:
        return None
    top, left = walk(c0, right), walk(c0, down)
    if top is None or left is None:
        return None
    w, h = len(top), len(left)
    if w * h != nv or (w - 1) * (h - 1) != len(faces):
        return None
    bottom = walk(left[-1], next(v for v in border_nb[left[-1]] if v != left[-2]))
    rightcol = walk(top[-1], next(v for v in border_nb[top[-1]] if v != top[-2]))
    if bottom is None or rightcol is None:
        return None
    return dict(w=w, h=h, top=top, left=left, bottom=bottom, right=rightcol)


def pinned_vertices(obj, settings, nv):
    """0-based vertices of the cloth's pin group (weight >= PIN_WEIGHT), or [] if none."""
    name = settings.vertex_group_mass
    if not name:
        return []
    vg = obj.vertex_groups.get(name)
    if vg is None:
        return []
    if len(obj.data.vertices) != nv:
        raise AddonError(f"{obj.name}: the pin group {name!r} is on {len(obj.data.vertices)} vertices but "
                         f"the evaluated cloth has {nv}: apply the modifiers that change the vertex count")
    gi = vg.index
    out = []
    for v in obj.data.vertices:
        for g in v.groups:
            if g.group == gi and g.weight >= PIN_WEIGHT:
                out.append(v.index)
    return out


def grid_pin_edges(grid, pins):
    """The held grid edges for `--physics-pin` that the pinned vertices make (and a note when
    they are not exactly whole edges)."""
    p = set(pins)
    sides = [s for s in ("top", "bottom", "left", "right") if set(grid[s]) <= p]
    covered = set().union(*(grid[s] for s in sides)) if sides else set()
    corners = {grid["top"][0], grid["top"][-1], grid["bottom"][0], grid["bottom"][-1]}
    if not sides and corners <= p:
        return "corners", (None if p == corners else "the grid is held by its corners only")
    if not sides:
        return None, ("the pin group is not a whole edge of the grid, and a grid is held by whole "
                      "edges (top, bottom, left, right, corners): the physics pass holds nothing")
    note = None if covered == p else f"the grid is held by its whole edges {','.join(sides)}"
    return ",".join(sides), note


# --------------------------------------------------------------------------- file writers


def write_obj(path, co_yup, faces, uv=None, loop_start=None, mat=None, mat_names=None,
              smooth=None, mtllib=None, name=None):
    """An OBJ file: `v` per vertex in order, `vt` per distinct UV, faces with usemtl/s."""
    out = []
    if mtllib:
        out.append(f"mtllib {mtllib}")
    if name:
        out.append(f"o {name}")
    co32 = np.asarray(co_yup, dtype=np.float32)
    out.extend("v %s %s %s" % (fmt(x), fmt(y), fmt(z)) for x, y, z in co32.tolist())
    vt_of_loop = None
    if uv is not None:
        # 6 decimals, as Blender's OBJ exporter: a vertex whose faces give it UVs that differ in the
        # last bits keeps one UV (anisocb drops the UVs of a grid with a seam inside)
        uv6 = np.round(np.asarray(uv, dtype=np.float64), 6).astype(np.float32)
        uniq, vt_of_loop = np.unique(uv6, axis=0, return_inverse=True)
        vt_of_loop = np.asarray(vt_of_loop).reshape(-1)
        out.extend("vt %s %s" % (fmt(u), fmt(v)) for u, v in uniq.tolist())
    cur_mat, cur_s = None, None
    for k, f in enumerate(faces):
        if mat is not None and mat_names:
            m = mat_names[min(int(mat[k]), len(mat_names) - 1)]
            if m != cur_mat:
                out.append(f"usemtl {m}")
                cur_mat = m
        if smooth is not None:
            s = "1" if smooth[k] else "off"
            if s != cur_s:
                out.append(f"s {s}")
                cur_s = s
        if vt_of_loop is not None:
            s0 = int(loop_start[k])
            out.append("f " + " ".join(f"{v + 1}/{vt_of_loop[s0 + i] + 1}" for i, v in enumerate(f)))
        else:
            out.append("f " + " ".join(str(v + 1) for v in f))
    with open(path, "w") as fh:
        fh.write("\n".join(out) + "\n")


def write_mtl(path, materials):
    """A plain .mtl: one `newmtl` per material with its viewport colour (the add-on keeps the
    Blender materials themselves; this is for other tools reading the files)."""
    lines = []
    for word, m in materials:
        c = tuple(m.diffuse_color)[:3] if m is not None else (0.8, 0.8, 0.8)
        lines += [f"newmtl {word}", "Kd %.4f %.4f %.4f" % c, ""]
    with open(path, "w") as fh:
        fh.write("\n".join(lines))


class PC2Writer:
    """PC2 point cache, written a sample at a time: b'POINTCACHE2\\0', int32 version 1, int32
    points, float32 start frame, float32 sample rate, int32 samples, then float32 xyz."""

    def __init__(self, path, points, start, samples):
        self.fh = open(path, "wb")
        self.points = points
        self.fh.write(PC2_HEADER.pack(b"POINTCACHE2\0", 1, points, float(start), 1.0, samples))

    def add(self, co_yup):
        arr = np.ascontiguousarray(co_yup, dtype="<f4")
        assert arr.shape == (self.points, 3)
        self.fh.write(arr.tobytes())

    def close(self):
        self.fh.close()


def read_pc2(path):
    with open(path, "rb") as fh:
        data = fh.read()
    if data[:12] != b"POINTCACHE2\0":
        raise AddonError(f"{path}: not a PC2 file")
    _, _, npts, start, rate, ns = PC2_HEADER.unpack(data[:32])
    arr = np.frombuffer(data, dtype="<f4", offset=32, count=npts * ns * 3).reshape(ns, npts, 3)
    return dict(points=npts, start=start, rate=rate, samples=ns), arr


def read_obj(path):
    """The parts of an OBJ file the add-on needs back: vertices, UVs, faces with their UV
    indices, material words and smooth flags per face."""
    v, vt, faces, fuv, fmat, fsmooth = [], [], [], [], [], []
    mat, smooth = None, False
    with open(path) as fh:
        for line in fh:
            if line.startswith("v "):
                v.append([float(x) for x in line.split()[1:4]])
            elif line.startswith("vt "):
                vt.append([float(x) for x in line.split()[1:3]])
            elif line.startswith("f "):
                idx, tex = [], []
                for c in line.split()[1:]:
                    parts = c.split("/")
                    idx.append(int(parts[0]) - 1)
                    tex.append(int(parts[1]) - 1 if len(parts) > 1 and parts[1] else -1)
                faces.append(idx)
                fuv.append(tex)
                fmat.append(mat)
                fsmooth.append(smooth)
            elif line.startswith("usemtl "):
                mat = line[7:].strip()
            elif line.startswith("s "):
                smooth = line[2:].strip() not in ("off", "0")
    return dict(v=np.array(v, dtype=np.float64).reshape(-1, 3), vt=vt, faces=faces, fuv=fuv,
                fmat=fmat, fsmooth=fsmooth)


# --------------------------------------------------------------------------- the job


class Job:
    """One Upscale of one cloth object: `steps()` yields (fraction done, status) while it
    exports, runs the binary and imports; `result` is the new object at the end."""

    def __init__(self, context, obj, opts, binary):
        self.scene = context.scene
        self.view_layer = context.view_layer
        self.obj = obj
        self.opts = opts
        self.binary = binary
        self.proc = None
        self.stderr = deque(maxlen=400)
        self.stdout = deque(maxlen=400)
        self.notes = []
        self.result = None
        self.command = None
        out = bpy.path.abspath(opts.output_dir) if opts.output_dir else ""
        if not out or (opts.output_dir.startswith("//") and not bpy.data.filepath):
            raise AddonError("no output folder: save the .blend file first (the default is //anisocb/ "
                             "beside it) or set an absolute Output folder in the anisocb panel")
        self.dir = os.path.join(os.path.abspath(out), safe_name(obj.name))
        self.hr_dir = os.path.join(self.dir, "hr")

    # ---- export

    def colliders(self, cloth_mod):
        cs = cloth_mod.collision_settings
        if not cs.use_collision:
            return []
        pool = cs.collection.all_objects if cs.collection else self.scene.objects
        out = []
        for o in pool:
            if o is self.obj or o.type != "MESH":
                continue
            if any(m.type == "COLLISION" for m in o.modifiers) and o.visible_get(view_layer=self.view_layer):
                out.append(o)
        return sorted(out, key=lambda o: o.name)

    def export_steps(self):
        scene, obj = self.scene, self.obj
        mod = cloth_modifier(obj)
        if mod is None:
            raise AddonError(f"{obj.name} has no Cloth modifier: select the cloth object")
        f0, f1 = scene.frame_start, scene.frame_end
        frames = list(range(f0, f1 + 1))
        if len(frames) < 2:
            raise AddonError(f"the scene's frame range {f0}..{f1} has fewer than 2 frames: set Start and End")
        os.makedirs(self.dir, exist_ok=True)
        col_root = os.path.join(self.dir, "colliders")
        if os.path.isdir(col_root):  # the add-on's own folder: last run's frames go
            shutil.rmtree(col_root)
        colliders = self.colliders(mod)
        self.saved_frame = scene.frame_current
        settings = mod.settings
        # A hidden object is not evaluated (its mesh would stay at one frame): shown while
        # exporting, as it was after.
        # Touched only when hidden: any change resets a cache that is not baked.
        hidden = (obj.hide_get(view_layer=self.view_layer), obj.hide_viewport)
        if hidden[1]:
            obj.hide_viewport = False
        if hidden[0]:
            obj.hide_set(False, view_layer=self.view_layer)
        if not mod.point_cache.is_baked:
            self.notes.append(f"{obj.name}'s cloth is not baked: bake it (Physics > Cloth > Cache > Bake) "
                              "so that the export is the animation you saw, not a new simulation")
        try:
            yield from self.export_frames(scene, obj, mod, settings, frames, colliders, col_root)
        finally:
            if hidden[0]:
                obj.hide_set(True, view_layer=self.view_layer)
            if hidden[1]:
                obj.hide_viewport = True
            scene.frame_set(self.saved_frame)

    def export_frames(self, scene, obj, mod, settings, frames, colliders, col_root):
        f0 = frames[0]
        scene.frame_set(f0)
        dg = bpy.context.evaluated_depsgraph_get()
        co, topo = evaluated_world(obj, dg, topology=True)
        nv = len(co)
        faces = faces_of(topo)
        bad = next((k for k, f in enumerate(faces) if len(f) > 4), None)
        if bad is not None:
            raise AddonError(f"{obj.name}: face {bad + 1} has {len(faces[bad])} vertices; anisocb reads "
                             "triangles and quads: triangulate the n-gons (Face > Triangulate Faces)")
        if not faces:
            raise AddonError(f"{obj.name} has no faces")
        self.grid = recover_grid(nv, faces)
        self.hr_points = hr_point_count(nv, faces, self.grid)
        self.frames = frames

        # rest.obj (+ rest.mtl): frame Start, UVs, materials, smooth flags.
        slots = [s.material for s in obj.material_slots]
        mat_words, self.mat_of_word = [], {}
        for k, m in enumerate(slots):
            word = safe_name(m.name) if m is not None else f"slot{k + 1}"
            while word in self.mat_of_word:
                word += "_"
            mat_words.append(word)
            self.mat_of_word[word] = m
        self.uv_name = topo["uv_name"]
        self.smooth_all = bool(topo["smooth"].all())
        rest = os.path.join(self.dir, "rest.obj")
        if mat_words:
            write_mtl(os.path.join(self.dir, "rest.mtl"), list(zip(mat_words, slots)))
        write_obj(rest, to_yup(co), faces, uv=topo["uv"], loop_start=topo["loop_start"], mat=topo["mat"],
                  mat_names=mat_words or None, smooth=topo["smooth"],
                  mtllib="rest.mtl" if mat_words else None, name=safe_name(obj.name))

        # Pins, fps, gravity, material.
        o = self.opts
        args = ["upscale", os.path.join(self.dir, "cloth.pc2"), "--rest", rest, "--out", self.hr_dir,
                "--overwrite", "--eta", fmt(o.eta)]
        if o.physics:
            if o.material == "AUTO":
                material, preset = nearest_material(settings)
                self.notes.append(f"material {material} (nearest Blender preset: {preset})")
            else:
                material = o.material.lower()
            g = gravity_of(scene, settings)
            args += ["--physics", "--fps", fmt(fps_of(scene)), "--gravity", ",".join(fmt(x) for x in g),
                     "--preset", "blender", "--material", material]
            pins = pinned_vertices(obj, settings, nv)
            if pins and self.grid is not None:
                edges, note = grid_pin_edges(self.grid, pins)
                if note:
                    self.notes.append(note)
                if edges:
                    args += ["--physics-pin", edges]
            elif pins:
                pin_file = os.path.join(self.dir, "pins.txt")
                with open(pin_file, "w") as fh:
                    fh.write(f"# {obj.name}: vertex group {settings.vertex_group_mass!r}, weight >= {PIN_WEIGHT}, "
                             "numbered from 1\n" + "\n".join(str(v + 1) for v in pins) + "\n")
                args += ["--physics-pin-vertices", pin_file]
        self.collider_dirs = {}

        # Frame by frame: the cloth's PC2 and each collider's OBJ frames.
        pc2 = PC2Writer(os.path.join(self.dir, "cloth.pc2"), nv, f0, len(frames))
        col_frames = {c.name: [] for c in colliders}
        col_faces = {}
        try:
            for i, fr in enumerate(frames):
                scene.frame_set(fr)
                dg = bpy.context.evaluated_depsgraph_get()
                co, _ = evaluated_world(obj, dg)
                if len(co) != nv:
                    raise AddonError(f"{obj.name} has {len(co)} vertices at frame {fr} and {nv} at frame {f0}: "
                                     "the cloth must keep its vertices over the shot")
                pc2.add(to_yup(co))
                for c in colliders:
                    cco, ctopo = evaluated_world(c, dg, topology=c.name not in col_faces)
                    if ctopo is not None:
                        col_faces[c.name] = ctopo["tris"].tolist()
                        if not col_faces[c.name]:
                            raise AddonError(f"collider {c.name} has no faces: give it a mesh or remove its "
                                             "Collision modifier")
                    col_frames[c.name].append(to_yup(cco).astype(np.float32))
                yield (i + 1) / len(frames), f"exporting frame {fr} ({i + 1}/{len(frames)})"
        finally:
            pc2.close()

        for c in colliders:
            seq = col_frames[c.name]
            word = safe_name(c.name)
            if all(np.array_equal(s, seq[0]) for s in seq[1:]):
                path = os.path.join(col_root, f"{word}.obj")
                os.makedirs(col_root, exist_ok=True)
                write_obj(path, seq[0], col_faces[c.name], name=word)
            else:
                path = os.path.join(col_root, word)
                os.makedirs(path)
                for i, (fr, s) in enumerate(zip(frames, seq)):
                    write_obj(os.path.join(path, f"{word}_{fr:04d}.obj"), s, col_faces[c.name], name=word)
            self.collider_dirs[c.name] = path
            if o.physics:
                args += ["--collider", path]
        if colliders and o.physics:
            # The gap Blender keeps around its colliders (Collision > Thickness Outer), for the
            # physics pass; anisocb takes one gap for all colliders (the largest) up to 10 cm.
            thick = max(c.collision.thickness_outer for c in colliders)
            if thick > 0.1:
                self.notes.append(f"collider Thickness Outer {thick:g} capped to anisocb's largest, 0.1")
                thick = 0.1
            args += ["--collider-thickness", f"{thick:.6g}"]
        if colliders and not o.physics:
            self.notes.append(f"{len(colliders)} collider(s) exported, used only with Physics on")
        self.args = args
        self.command = [self.binary] + args
        with open(os.path.join(self.dir, "command.txt"), "w") as fh:
            fh.write(" ".join(shell_quote(a) for a in self.command) + "\n")

    # ---- run

    def start(self):
        def pump(stream, sink):
            for line in stream:
                sink.append(line.rstrip("\n"))
            stream.close()

        try:
            self.proc = subprocess.Popen(self.command, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                         text=True, errors="replace")
        except OSError as e:
            raise AddonError(f"could not start {self.binary}: {e}: check the binary's path in Edit > "
                             "Preferences > Add-ons > anisocb")
        self.threads = [threading.Thread(target=pump, args=(self.proc.stderr, self.stderr), daemon=True),
                        threading.Thread(target=pump, args=(self.proc.stdout, self.stdout), daemon=True)]
        for t in self.threads:
            t.start()

    def written_fraction(self):
        """How much of the HR cache is on disk (the binary writes it to a temporary file
        beside hr/cloth.pc2 chunk by chunk, then renames it)."""
        total = self.hr_points * len(self.frames) * 12
        best = getattr(self, "written", 0)  # never back: the file goes when it is renamed
        try:
            for n in os.listdir(self.hr_dir):
                if n.startswith(".cloth.pc2.tmp."):
                    best = max(best, os.path.getsize(os.path.join(self.hr_dir, n)) - 32)
        except OSError:
            pass
        self.written = best
        return min(1.0, max(0.0, best / total)) if total else 0.0

    def kill(self):
        if self.proc is not None and self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(timeout=5)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()

    def error_text(self, lines=6):
        tail = [l for l in self.stderr if l.strip()][-lines:]
        return " | ".join(tail) if tail else "(no message on stderr)"

    # ---- the whole job

    def steps(self):
        """Yields (fraction 0..1, status). Export 0-0.3, the binary 0.3-0.95, import the rest."""
        for f, s in self.export_steps():
            yield 0.3 * f, s
        self.start()
        while self.proc.poll() is None:
            yield 0.3 + 0.65 * self.written_fraction(), "anisocb upscale running"
        for t in self.threads:
            t.join(timeout=5)
        if self.proc.returncode != 0:
            raise AddonError(f"anisocb upscale failed (exit status {self.proc.returncode}): {self.error_text()}")
        yield 0.95, "importing the HR result"
        self.result = self.import_result()
        yield 1.0, "done"

    # ---- import

    def import_result(self):
        rest = os.path.join(self.hr_dir, "rest.obj")
        cache = os.path.join(self.hr_dir, "cloth.pc2")
        if not (os.path.isfile(rest) and os.path.isfile(cache)):
            raise AddonError(f"anisocb exited 0 but {rest} or {cache} is missing: {self.error_text()}")
        o = read_obj(rest)
        head, _ = read_pc2(cache)
        if head["points"] != len(o["v"]):
            raise AddonError(f"{cache} has {head['points']} points but {rest} {len(o['v'])} vertices")
        name = f"{self.obj.name}_anisocb"
        old = bpy.data.objects.get(name)
        if old is not None and old.get("anisocb_source") == self.obj.name:
            old_mesh = old.data
            bpy.data.objects.remove(old)
            if old_mesh.users == 0:
                bpy.data.meshes.remove(old_mesh)
        me = bpy.data.meshes.new(name)
        me.from_pydata(o["v"].tolist(), [], o["faces"])
        if o["vt"] and all(min(t) >= 0 for t in o["fuv"]):
            layer = me.uv_layers.new(name=self.uv_name or "UVMap")
            vt = np.array(o["vt"], dtype=np.float32)
            flat = np.array([t for f in o["fuv"] for t in f], dtype=np.int64)
            layer.data.foreach_set("uv", vt[flat].reshape(-1))
        words = []
        for w in o["fmat"]:
            if w is not None and w not in words:
                words.append(w)
        slot_words = [w for w in self.mat_of_word] or words
        for w in slot_words:
            me.materials.append(self.mat_of_word.get(w))
        index = {w: k for k, w in enumerate(slot_words)}
        me.polygons.foreach_set("material_index", [index.get(w, 0) for w in o["fmat"]])
        me.polygons.foreach_set("use_smooth", o["fsmooth"])
        me.update()
        new = bpy.data.objects.new(name, me)
        for coll in self.obj.users_collection:
            coll.objects.link(new)
        if not new.users_collection:
            self.scene.collection.objects.link(new)
        new.rotation_euler = (math.pi / 2, 0.0, 0.0)  # the files' Y up -> Blender's Z up
        new["anisocb_source"] = self.obj.name
        new["anisocb_command"] = " ".join(shell_quote(a) for a in self.command)
        mc = new.modifiers.new("anisocb HR cache", "MESH_CACHE")
        mc.cache_format = "PC2"
        mc.filepath = cache
        mc.forward_axis, mc.up_axis = "POS_Y", "POS_Z"  # cache floats straight into the mesh
        mc.deform_mode = "OVERWRITE"
        mc.play_mode = "SCENE"
        mc.time_mode = "FRAME"
        mc.frame_scale = 1.0
        mc.frame_start = self.scene.frame_start  # the modifier ignores the file's start frame
        if self.opts.hide_lr:
            if not self.obj.hide_get(view_layer=self.view_layer):
                self.obj.hide_set(True, view_layer=self.view_layer)
            if not self.obj.hide_render:
                self.obj.hide_render = True
        return new


def shell_quote(s):
    return s if re.fullmatch(r"[A-Za-z0-9_./,:=+-]+", s) else "'" + s.replace("'", "'\\''") + "'"
