"""What the Blender scripts here share: a fresh scene, selection and transforms, colliders,
the cloth modifier's settings, and silencing Blender's C-level output. Imported by
make_scenes.py, make_garments.py and roundtrip.py (run from any folder: each puts this one on
sys.path)."""

import os
import sys

import bpy


def reset(fps=24):
    """An empty scene at `fps` frames per second, gravity -z."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    scene.render.fps = fps
    scene.gravity = (0.0, 0.0, -9.81)
    scene.use_gravity = True
    return scene


def deselect_all():
    for o in bpy.context.view_layer.objects:
        o.select_set(False)


def apply_transform(obj):
    deselect_all()
    obj.select_set(True)
    bpy.context.view_layer.objects.active = obj
    bpy.ops.object.transform_apply(location=True, rotation=True, scale=True)


def add_collider(obj, thickness=0.01, friction=5.0):
    obj.modifiers.new("Collision", "COLLISION")
    c = obj.collision
    c.thickness_outer = thickness
    c.cloth_friction = friction
    c.damping = 0.5
    return obj


def cloth_modifier(obj, p, quality, mass, m_scale, k_scale, frames, pinned):
    """The Cloth modifier on `obj` with fabric `p` (see make_scenes.fabric): `mass` per vertex
    (kg), air damping scaled by `m_scale`, stretch/shear stiffness by `k_scale` (resolution
    consistency: make_scenes.py's docstring), pinned to the vertex group "pin" if `pinned`."""
    mod = obj.modifiers.new("Cloth", "CLOTH")
    s = mod.settings
    s.quality = quality
    s.mass = mass
    s.air_damping = p["air"] * m_scale
    s.bending_model = "ANGULAR"
    for attr in ("tension", "compression", "shear"):
        setattr(s, f"{attr}_stiffness", p[attr] * k_scale)
        setattr(s, f"{attr}_stiffness_max", p[attr] * k_scale)
        setattr(s, f"{attr}_damping", p["damp"])
    s.bending_stiffness = p["bend"]
    s.bending_stiffness_max = p["bend"]
    s.bending_damping = p["bend_damp"]
    if pinned:
        s.vertex_group_mass = "pin"
        s.pin_stiffness = 1.0
    cs = mod.collision_settings
    cs.use_collision = True
    cs.use_self_collision = False
    cs.distance_min = 0.01
    cs.collision_quality = 3
    mod.point_cache.frame_start = 1
    mod.point_cache.frame_end = frames
    return mod


class quiet:
    """Send C-level output on file descriptor `fd` (1 stdout, 2 stderr) to /dev/null."""

    def __init__(self, fd=1):
        self.fd = fd

    def __enter__(self):
        sys.stdout.flush()
        sys.stderr.flush()
        self.saved = os.dup(self.fd)
        self.null = os.open(os.devnull, os.O_WRONLY)
        os.dup2(self.null, self.fd)

    def __exit__(self, *exc):
        sys.stdout.flush()
        sys.stderr.flush()
        os.dup2(self.saved, self.fd)
        os.close(self.saved)
        os.close(self.null)
