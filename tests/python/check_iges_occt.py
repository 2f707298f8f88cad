#!/usr/bin/env python3
"""Independent CAD check of an IGES file with OpenCascade (OCP, from cadquery-ocp-novtk).

Usage: check_iges_occt.py FILE.igs EXPECT.json

EXPECT.json: {"faces": N, "patches": [{"degree_u", "degree_v", "poles_u", "poles_v",
"knots_u", "knots_v" (optional, full clamped vectors, compared exactly),
"points": [[u, v, x, y, z], ...]}, ...], "tolerance_mm": 1e-10}

Reads the file with IGESControl_Reader, transfers all roots, requires exactly N faces, each a
Geom_BSplineSurface with the expected degrees and pole counts, and evaluates each at the given
(u, v) parameters, comparing with the given points (mm). Exits 0 only if everything matches;
prints one line per check. Fails (exit 2) if OCP is not installed.
"""
import json
import sys

try:
    from OCP.IGESControl import IGESControl_Reader
    from OCP.IFSelect import IFSelect_RetDone
    from OCP.TopExp import TopExp_Explorer
    from OCP.TopAbs import TopAbs_FACE
    from OCP.TopoDS import TopoDS
    from OCP.BRep import BRep_Tool
    from OCP.Geom import Geom_BSplineSurface
except ImportError as e:  # fail loudly: the check is required
    print(f"FAIL: OCP (pip install cadquery-ocp-novtk) is not importable: {e}")
    sys.exit(2)


def main():
    path, expect_path = sys.argv[1], sys.argv[2]
    with open(expect_path) as f:
        expect = json.load(f)
    tol = expect.get("tolerance_mm", 1e-10)
    reader = IGESControl_Reader()
    status = reader.ReadFile(path)
    if status != IFSelect_RetDone:
        print(f"FAIL: ReadFile returned {status}")
        return 1
    reader.TransferRoots()
    shape = reader.OneShape()
    faces = []
    exp = TopExp_Explorer(shape, TopAbs_FACE)
    while exp.More():
        faces.append(TopoDS.Face(exp.Current()))
        exp.Next()
    patches = expect["patches"]
    if len(faces) != expect["faces"] or len(faces) != len(patches):
        print(f"FAIL: {len(faces)} faces, expected {expect['faces']}")
        return 1
    worst = 0.0
    for k, (face, want) in enumerate(zip(faces, patches)):
        surf = BRep_Tool.Surface_s(face)
        bs = Geom_BSplineSurface.DownCast(surf) if hasattr(Geom_BSplineSurface, "DownCast") else surf
        if bs is None or not isinstance(bs, Geom_BSplineSurface):
            print(f"FAIL: face {k} is {type(surf).__name__}, not a Geom_BSplineSurface")
            return 1
        got = (bs.UDegree(), bs.VDegree(), bs.NbUPoles(), bs.NbVPoles())
        exp_t = (want["degree_u"], want["degree_v"], want["poles_u"], want["poles_v"])
        if got != exp_t:
            print(f"FAIL: face {k}: degrees/poles {got}, expected {exp_t}")
            return 1
        for name, seq_fn in (("knots_u", bs.UKnotSequence), ("knots_v", bs.VKnotSequence)):
            if name in want:
                arr = seq_fn()
                got_k = [arr.Value(i) for i in range(arr.Lower(), arr.Upper() + 1)]
                if got_k != want[name]:
                    print(f"FAIL: face {k}: {name} {got_k} differ from the written {want[name]}")
                    return 1
        for u, v, x, y, z in want["points"]:
            p = bs.Value(u, v)
            d = max(abs(p.X() - x), abs(p.Y() - y), abs(p.Z() - z))
            worst = max(worst, d)
            if not d <= tol:
                print(f"FAIL: face {k}: S({u}, {v}) = ({p.X()}, {p.Y()}, {p.Z()}), expected ({x}, {y}, {z}), |d| = {d:.3e} mm > {tol}")
                return 1
    npts = sum(len(p["points"]) for p in patches)
    print(f"OK: {len(faces)} face(s), {npts} points, max deviation {worst:.3e} mm <= {tol} mm")
    return 0


if __name__ == "__main__":
    sys.exit(main())
