#!/usr/bin/env python3
"""Pixar's own reader on anisocb's USD output (usd-core from PyPI, pinned in
tests/blender/requirements-usd.txt): `python3 check_usd_pxr.py HR.usda LR.usd[c]`.

Opens both with `pxr.Usd`, finds the animated Mesh prim in each, and checks that the HR one has
the same prim path, the same time codes, up axis and metres per unit, four faces per LR face,
a point array per time code of one length, and, when the LR mesh has `primvars:st`, the HR one
faceVarying over every face corner.
Prints one line per check; exit status 1 if any failed."""

import sys

from pxr import Usd, UsdGeom


def animated_mesh(stage):
    for prim in stage.Traverse():
        if prim.IsA(UsdGeom.Mesh) and UsdGeom.Mesh(prim).GetPointsAttr().GetNumTimeSamples() > 1:
            return UsdGeom.Mesh(prim)
    return None


def main(hr_path, lr_path):
    ok = True

    def check(name, cond, detail=""):
        nonlocal ok
        ok &= bool(cond)
        print(f"[{'PASS' if cond else 'FAIL'}] pxr: {name}" + (f": {detail}" if detail else ""))

    hr_stage, lr_stage = Usd.Stage.Open(hr_path), Usd.Stage.Open(lr_path)
    check("opens the HR file", hr_stage is not None, hr_path)
    hr, lr = animated_mesh(hr_stage), animated_mesh(lr_stage)
    check("finds the animated mesh", hr is not None and lr is not None)
    if hr is None or lr is None:
        return ok
    check("same prim path", hr.GetPath() == lr.GetPath(), str(hr.GetPath()))
    times = hr.GetPointsAttr().GetTimeSamples()
    check("same time codes", list(times) == list(lr.GetPointsAttr().GetTimeSamples()), f"{len(times)} samples")
    check("same up axis", UsdGeom.GetStageUpAxis(hr_stage) == UsdGeom.GetStageUpAxis(lr_stage))
    check("same metres per unit", UsdGeom.GetStageMetersPerUnit(hr_stage) == UsdGeom.GetStageMetersPerUnit(lr_stage))
    counts = list(hr.GetFaceVertexCountsAttr().Get())
    lr_faces = len(lr.GetFaceVertexCountsAttr().Get())
    check("four faces per LR face", len(counts) == 4 * lr_faces, f"{len(counts)} faces, LR {lr_faces}")
    n = {len(hr.GetPointsAttr().Get(t)) for t in times}
    check("one point count over the shot", len(n) == 1, str(sorted(n)))
    lr_st = UsdGeom.PrimvarsAPI(lr).GetPrimvar("st")
    if lr_st and lr_st.HasValue():
        st = UsdGeom.PrimvarsAPI(hr).GetPrimvar("st")
        corners = sum(counts)
        flat = st.ComputeFlattened() if st else None
        check(
            "st faceVarying on every corner",
            bool(st) and st.GetInterpolation() == "faceVarying" and flat is not None and len(flat) == corners,
            f"{len(flat) if flat is not None else 0} values for {corners} corners",
        )
    else:
        print("note: pxr: the LR mesh has no st, so the HR has none to check")
    return ok


if __name__ == "__main__":
    sys.exit(0 if main(sys.argv[1], sys.argv[2]) else 1)
