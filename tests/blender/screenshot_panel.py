"""Take the README's screenshot of the add-on's panel in a real Blender window.

Run by Blender itself (not the bpy module, which draws no UI), under a virtual X display
(`xvfb-run`; `xwd` from x11-apps takes the picture): `make blender-screenshot BLENDER=...`,
which starts Blender on an empty .blend with the splash screen off.

It builds test_addon.py's scene (a pinned sheet and a skirt on a keyed sphere, baked with
Blender's cloth), enables the add-on from this repository, selects the skirt and presses
*Upscale* as the button does (the modal operator, which test_addon.py cannot run without a
window: it fails here if the run does not end, ends with an error, or brings no HR object back).
Once `Skirt_anisocb` is in the scene it saves the whole window, the Properties editor on the
Physics tab, where the panel is.
Blender 4.2 or newer (the add-on's minimum).
"""

import argparse
import os
import struct
import subprocess
import sys

import numpy as np

import bpy
import addon_utils
from mathutils import Euler, Vector

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(os.path.dirname(HERE))
sys.path.insert(0, HERE)
import test_addon as scene_of_the_test  # noqa: E402  (the scene only; its checks do not run)


def args():
    argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else []
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--anisocb", required=True, help="path to the anisocb binary")
    ap.add_argument("--out", required=True, help="the PNG to write")
    ap.add_argument("--frame", type=int, default=14, help="the frame shown")
    return ap.parse_args(argv)


A = args()
STEP = {"n": 0}


def areas(kind):
    return [(w, a) for w in bpy.context.window_manager.windows for a in w.screen.areas if a.type == kind]


def press_upscale():
    """Build the scene, enable the add-on and press *Upscale* on the skirt as the button does
    (the modal operator: the binary runs while the window keeps drawing)."""
    win, view = areas("VIEW_3D")[0]
    region = next(r for r in view.regions if r.type == "WINDOW")
    with bpy.context.temp_override(window=win, area=view, region=region):
        sheet, skirt, sphere = scene_of_the_test.build_scene(fresh=False)
    sys.path.insert(0, os.path.join(REPO, "blender"))
    addon_utils.enable("anisocb_addon", default_set=True, handle_error=None)
    bpy.context.preferences.addons["anisocb_addon"].preferences.binary = os.path.abspath(A.anisocb)
    for o in bpy.context.view_layer.objects:
        o.select_set(o is skirt)
    bpy.context.view_layer.objects.active = skirt
    for w, a in areas("PROPERTIES"):
        a.spaces.active.context = "PHYSICS"
    with bpy.context.temp_override(window=win, area=view, region=region):
        r = bpy.ops.anisocb.upscale("INVOKE_DEFAULT")
    assert "RUNNING_MODAL" in r, f"Upscale did not start: {r}"


def frame_the_result():
    """Show frame --frame, looking at the HR skirt on the ball from the front, a little above."""
    skirt, hr = bpy.data.objects["Skirt"], bpy.data.objects.get("Skirt_anisocb")
    assert hr is not None, f"the add-on did not bring the HR skirt back: {addon().STATE}"
    bpy.context.scene.frame_set(A.frame)
    dg = bpy.context.evaluated_depsgraph_get()
    ev = hr.evaluated_get(dg)
    pts = [ev.matrix_world @ v.co for v in ev.data.vertices]
    lo = [min(p[k] for p in pts) for k in range(3)]
    hi = [max(p[k] for p in pts) for k in range(3)]
    centre = Vector([(a + b) / 2 for a, b in zip(lo, hi)])
    size = max(b - a for a, b in zip(lo, hi))
    for w, a in areas("VIEW_3D"):
        sp = a.spaces.active
        sp.shading.type = "SOLID"
        sp.shading.color_type = "MATERIAL"
        sp.overlay.show_wireframes = True
        r3d = sp.region_3d
        r3d.view_perspective = "PERSP"
        r3d.view_location = centre
        r3d.view_rotation = Euler((1.15, 0.0, 0.5)).to_quaternion()
        r3d.view_distance = 2.2 * size
    bpy.context.view_layer.objects.active = skirt
    print(f"upscaled {skirt.name} → {hr.name} ({len(hr.data.vertices)} vertices)", flush=True)


def addon():
    import anisocb_addon

    return anisocb_addon


def save_x_screen(path):
    """The X server's picture of the screen (`xwd -root`) as a PNG. Blender's own
    `screen.screenshot` reads its GL front buffer, which is black under Xvfb."""
    raw = subprocess.run(["xwd", "-root", "-silent"], capture_output=True, check=True).stdout
    h = struct.unpack(">25I", raw[:100])
    header, w, hh, byte_order, bpp, bpl, ncolors = h[0], h[4], h[5], h[7], h[11], h[12], h[19]
    assert bpp == 32, f"xwd: {bpp} bits a pixel, expected a 24-bit screen (xvfb-run -s '-screen 0 WxHx24')"
    px = np.frombuffer(raw, np.uint8, count=bpl * hh, offset=header + 12 * ncolors)
    px = px.reshape(hh, bpl)[:, : 4 * w].reshape(hh, w, 4)
    rgb = px[..., [2, 1, 0]] if byte_order == 0 else px[..., [1, 2, 3]]  # LSBFirst: B G R x
    rgba = np.concatenate([rgb, np.full((hh, w, 1), 255, np.uint8)], axis=-1)[::-1]  # Blender: bottom row first
    img = bpy.data.images.new("anisocb-screenshot", w, hh, alpha=False)
    img.pixels.foreach_set((rgba.astype(np.float32) / 255.0).ravel())
    img.filepath_raw = path
    img.file_format = "PNG"
    img.save()


def tick():
    STEP["n"] += 1
    if STEP["n"] == 1:
        press_upscale()
        return 0.2
    state = addon().STATE
    if "done_at" not in STEP:
        # The modal run: its progress moves, then the job ends (an error would show in the panel).
        STEP["progress"] = max(STEP.get("progress", 0.0), state["progress"])
        if state["job"] is not None:
            assert STEP["n"] < 600, "Upscale still running after 2 minutes"
            return 0.2
        assert not state["error"], f"Upscale failed: {state['error']}"
        print(f"the modal run ended: progress reached {STEP['progress']:.2f}; {state['status']}", flush=True)
        frame_the_result()
        STEP["done_at"] = STEP["n"]
    if STEP["n"] == STEP["done_at"] + 2:
        # The panel comes after Blender's own cloth panels: scroll the Physics tab to its end
        # (once the window has drawn the finished panel).
        for w, a in areas("PROPERTIES"):
            region = next(r for r in a.regions if r.type == "WINDOW")
            with bpy.context.temp_override(window=w, area=a, region=region):
                for _ in range(40):
                    bpy.ops.view2d.scroll_down(deltay=200)
    if STEP["n"] < STEP["done_at"] + 5:  # let the window redraw with the new scene, tab and scroll
        return 0.5
    save_x_screen(os.path.abspath(A.out))
    print(f"wrote {A.out}", flush=True)
    bpy.ops.wm.quit_blender()
    return None


def guarded_tick():
    """A failure in a timer would only print and leave Blender open: exit with status 1."""
    try:
        return tick()
    except Exception:
        import traceback

        traceback.print_exc()
        sys.stdout.flush()
        os._exit(1)


bpy.app.timers.register(guarded_tick, first_interval=1.0)
