"""anisocb for Blender: upscale the selected cloth's animation with the anisocb binary.

Physics Properties of a mesh with a Cloth modifier > anisocb panel > Upscale: the add-on
exports the cloth's shot over the scene's frame range (rest.obj + cloth.pc2, the colliders as
OBJ frames, fps, gravity, pins and material), runs `anisocb upscale` with a progress bar
(Esc or Cancel stops it) and brings the HR result back as `<cloth>_anisocb`, a mesh with a Mesh
Cache modifier playing the HR cache in place. Scripts: `bpy.ops.anisocb.upscale()` (execute)
runs synchronously. Documentation: docs/blender.md in the anisocb repository.
"""

bl_info = {
    "name": "anisocb",
    "author": "anisocb authors",
    "version": (0, 1, 0),
    "blender": (4, 2, 0),
    "location": "Properties > Physics > anisocb",
    "description": "Upscale a cloth animation with the anisocb binary (twice the vertices per side, wrinkles)",
    "category": "Physics",
}

import time

import bpy
from bpy.props import BoolProperty, EnumProperty, FloatProperty, PointerProperty, StringProperty

from . import core

ADDON_ID = __package__


class AnisocbPreferences(bpy.types.AddonPreferences):
    bl_idname = ADDON_ID

    binary: StringProperty(
        name="anisocb binary",
        description="Path to the anisocb executable (empty: `anisocb` on PATH)",
        subtype="FILE_PATH",
        default="",
    )

    def draw(self, context):
        self.layout.prop(self, "binary")


def preferences(context):
    addon = context.preferences.addons.get(ADDON_ID)
    return addon.preferences if addon is not None else None


class AnisocbSettings(bpy.types.PropertyGroup):
    eta: FloatProperty(name="η (wrinkles)", description="--eta: wrinkle enhancement, 0 = the nets' detail, "
                       "larger = deeper wrinkles where EnhanceNet sees edges, below 0 = softer",
                       default=0.0, min=-1.0, max=10.0)
    physics: BoolProperty(name="Physics pass", description="--physics: an HR cloth simulated alongside the "
                          "shot with the scene's fps, gravity, pins, material and colliders", default=True)
    material: EnumProperty(
        name="Material",
        description="--material of the physics pass",
        items=[("AUTO", "From cloth settings", "The anisocb material nearest the cloth's mass and bending"),
               ("SILK", "Silk", ""), ("COTTON", "Cotton", ""), ("DENIM", "Denim", ""), ("RUBBER", "Rubber", "")],
        default="AUTO",
    )
    output_dir: StringProperty(name="Output folder", description="Where the export and the HR result go "
                               "(a folder per cloth object inside it)", subtype="DIR_PATH", default="//anisocb/")
    hide_lr: BoolProperty(name="Hide LR cloth", description="Hide the LR cloth in the viewport and in renders "
                          "once the HR object is made", default=True)


# The job in flight (one at a time) and what the panel shows.
STATE = {"job": None, "cancel": False, "progress": 0.0, "status": "", "error": ""}


def message(e):
    if isinstance(e, core.AddonError):
        return str(e)
    return f"the add-on failed ({type(e).__name__}: {e}); please report it with the files in the output folder"


def redraw(context):
    wm = context.window_manager if context else bpy.context.window_manager
    for win in wm.windows:
        for area in win.screen.areas:
            if area.type in ("PROPERTIES", "VIEW_3D"):
                area.tag_redraw()


class ANISOCB_OT_upscale(bpy.types.Operator):
    """Export the cloth's shot, run anisocb upscale on it and import the HR result"""

    bl_idname = "anisocb.upscale"
    bl_label = "Upscale"
    bl_options = {"REGISTER"}

    synchronous: BoolProperty(name="Synchronous", description="Run to the end before returning (scripts, "
                              "tests); the invoked button runs in the background with a progress bar",
                              default=False, options={"SKIP_SAVE"})
    binary: StringProperty(name="Binary", description="anisocb executable for this call (overrides the "
                           "add-on preferences)", default="", options={"SKIP_SAVE"})
    object_name: StringProperty(name="Object", description="The cloth object (default: the active object)",
                                default="", options={"SKIP_SAVE"})

    @classmethod
    def poll(cls, context):
        return STATE["job"] is None

    def make_job(self, context):
        obj = bpy.data.objects.get(self.object_name) if self.object_name else context.object
        if obj is None or core.cloth_modifier(obj) is None:
            raise core.AddonError("select a mesh object with a Cloth modifier")
        prefs = preferences(context)
        binary = core.find_binary(self.binary or (prefs.binary if prefs else ""))
        return core.Job(context, obj, obj.anisocb, binary)

    def fail(self, msg):
        STATE["error"] = msg
        STATE["status"] = "failed"
        self.report({"ERROR"}, msg)
        return {"CANCELLED"}

    def finish(self, context):
        job = STATE["job"]
        STATE["job"] = None
        STATE["progress"] = 1.0
        STATE["status"] = f"{job.result.name}: {job.hr_points} vertices, {len(job.frames)} frames"
        for line in job.stderr:  # the binary's notes (how it laid the mesh out, UVs dropped, ...)
            if line.startswith(("note:", "warning:")):
                self.report({"INFO"}, f"anisocb: {line}")
        for n in job.notes:
            self.report({"WARNING"} if "holds nothing" in n else {"INFO"}, n)
        self.report({"INFO"}, f"anisocb: made {job.result.name} ({job.hr_points} vertices) from {job.dir}")
        return {"FINISHED"}

    def execute(self, context):
        """Synchronous: export, run and import before returning."""
        STATE.update(cancel=False, progress=0.0, status="starting", error="")
        try:
            job = self.make_job(context)
            STATE["job"] = job
            for frac, status in job.steps():
                STATE["progress"], STATE["status"] = frac, status
                if job.proc is not None and job.proc.poll() is None:
                    time.sleep(0.05)
        except Exception as e:  # noqa: BLE001 -- AddonError, or a bug: either way the panel must free up
            if STATE["job"] is not None:
                STATE["job"].kill()
            STATE["job"] = None
            return self.fail(message(e))
        return self.finish(context)

    def invoke(self, context, event):
        if self.synchronous:
            return self.execute(context)
        STATE.update(cancel=False, progress=0.0, status="starting", error="")
        try:
            job = self.make_job(context)
        except core.AddonError as e:
            return self.fail(str(e))
        STATE["job"] = job
        self.steps = job.steps()
        wm = context.window_manager
        self.timer = wm.event_timer_add(0.1, window=context.window)
        wm.modal_handler_add(self)
        wm.progress_begin(0, 100)
        return {"RUNNING_MODAL"}

    def end_modal(self, context):
        wm = context.window_manager
        wm.event_timer_remove(self.timer)
        wm.progress_end()
        context.workspace.status_text_set(None)
        redraw(context)

    def modal(self, context, event):
        job = STATE["job"]
        if event.type == "ESC" or STATE["cancel"]:
            job.kill()
            self.steps.close()  # the export's finally: frame and visibility back
            STATE.update(job=None, status="cancelled", progress=0.0)
            self.end_modal(context)
            self.report({"WARNING"}, "anisocb: cancelled")
            return {"CANCELLED"}
        if event.type != "TIMER":
            return {"PASS_THROUGH"}
        t0 = time.monotonic()
        try:
            while time.monotonic() - t0 < 0.05:  # a few export frames per tick, UI stays live
                frac, status = next(self.steps)
                STATE["progress"], STATE["status"] = frac, status
                if job.proc is not None:
                    break
        except StopIteration:
            self.end_modal(context)
            return self.finish(context)
        except Exception as e:  # noqa: BLE001
            job.kill()
            STATE["job"] = None
            self.end_modal(context)
            return self.fail(message(e))
        context.window_manager.progress_update(int(100 * STATE["progress"]))
        context.workspace.status_text_set(f"anisocb: {STATE['status']} ({100 * STATE['progress']:.0f} %) — Esc cancels")
        redraw(context)
        return {"RUNNING_MODAL"}


class ANISOCB_OT_cancel(bpy.types.Operator):
    """Stop the running anisocb upscale (kills the process)"""

    bl_idname = "anisocb.cancel"
    bl_label = "Cancel"

    @classmethod
    def poll(cls, context):
        return STATE["job"] is not None

    def execute(self, context):
        STATE["cancel"] = True
        return {"FINISHED"}


class ANISOCB_PT_panel(bpy.types.Panel):
    bl_label = "anisocb"
    bl_space_type = "PROPERTIES"
    bl_region_type = "WINDOW"
    bl_context = "physics"

    @classmethod
    def poll(cls, context):
        return core.cloth_modifier(context.object) is not None

    def draw(self, context):
        layout = self.layout
        obj = context.object
        s = obj.anisocb
        layout.use_property_split = True
        layout.prop(s, "eta")
        layout.prop(s, "physics")
        col = layout.column()
        col.enabled = s.physics
        col.prop(s, "material")
        if s.material == "AUTO":
            mat, preset = core.nearest_material(core.cloth_modifier(obj).settings)
            col.label(text=f"→ {mat} (nearest Blender preset: {preset})")
        layout.prop(s, "output_dir")
        layout.prop(s, "hide_lr")
        job = STATE["job"]
        if job is None:
            layout.operator(ANISOCB_OT_upscale.bl_idname, icon="MOD_CLOTH")
        else:
            row = layout.row()
            row.progress(factor=STATE["progress"], type="BAR", text=STATE["status"])
            row.operator(ANISOCB_OT_cancel.bl_idname, text="", icon="CANCEL")
        if STATE["error"]:
            box = layout.box()
            box.alert = True
            for part in STATE["error"].split(" | "):
                box.label(text=part[:200], icon="ERROR")
        elif STATE["status"] and job is None:
            layout.label(text=STATE["status"], icon="INFO")
        prefs = preferences(context)
        if prefs is not None and not prefs.binary:
            layout.label(text="Binary: anisocb on PATH (set it in the add-on's preferences)")


CLASSES = (AnisocbPreferences, AnisocbSettings, ANISOCB_OT_upscale, ANISOCB_OT_cancel, ANISOCB_PT_panel)


def register():
    for c in CLASSES:
        bpy.utils.register_class(c)
    bpy.types.Object.anisocb = PointerProperty(type=AnisocbSettings)


def unregister():
    job = STATE["job"]
    if job is not None:
        job.kill()
        STATE["job"] = None
    del bpy.types.Object.anisocb
    for c in reversed(CLASSES):
        bpy.utils.unregister_class(c)
