"""Independent check of a STEP solid written by surfscan (tests/it/step_occt.rs).

  check_step_occt.py SOLID.step GRID.csv PITCH_X_MM Y_MM_JSON BOTTOM_MM MESH

OpenCascade (cadquery-ocp) reads the file with STEPControl_Reader and must find exactly one
solid of six faces that BRepCheck_Analyzer finds valid. Its volume (BRepGProp) is compared
with the block's volume computed here from the measured grid alone: the integral of
(height - BOTTOM_MM) over the grid's rectangle by the trapezoidal rule, BOTTOM_MM being the
z of the flat bottom as the writer reports it (OpenCascade's bounding box is wider by the
vertices' tolerance, 1e-7 mm, which over the block's area is more than the surface's whole
roughness volume for a small window). With MESH = 1, gmsh imports the
same file, meshes it into tetrahedra, and the sum of the tetrahedra's volumes is reported.

Prints one JSON object: solids, faces, shells, valid, volume_mm3, expected_mm3, bottom_mm,
top_mm, tetrahedra, mesh_volume_mm3.
"""

import json
import sys

import numpy as np


def occ(path):
    from OCP.BRepCheck import BRepCheck_Analyzer
    from OCP.BRepGProp import BRepGProp
    from OCP.Bnd import Bnd_Box
    from OCP.BRepBndLib import BRepBndLib
    from OCP.GProp import GProp_GProps
    from OCP.IFSelect import IFSelect_RetDone
    from OCP.STEPControl import STEPControl_Reader
    from OCP.TopAbs import TopAbs_FACE, TopAbs_SHELL, TopAbs_SOLID
    from OCP.TopExp import TopExp_Explorer

    reader = STEPControl_Reader()
    status = reader.ReadFile(path)
    if status != IFSelect_RetDone:
        raise SystemExit(f"OpenCascade could not read {path}: status {status}")
    reader.TransferRoots()
    shape = reader.OneShape()

    def count(kind):
        e = TopExp_Explorer(shape, kind)
        n = 0
        while e.More():
            n += 1
            e.Next()
        return n

    props = GProp_GProps()
    BRepGProp.VolumeProperties_s(shape, props, 1e-9)
    box = Bnd_Box()
    BRepBndLib.AddOptimal_s(shape, box, False, False)
    # The box includes the vertices' tolerance (the file's 1e-7 mm uncertainty).
    lo, hi = box.CornerMin(), box.CornerMax()
    xmin, ymin, zmin, xmax, ymax, zmax = lo.X(), lo.Y(), lo.Z(), hi.X(), hi.Y(), hi.Z()
    return dict(
        solids=count(TopAbs_SOLID),
        shells=count(TopAbs_SHELL),
        faces=count(TopAbs_FACE),
        valid=bool(BRepCheck_Analyzer(shape).IsValid()),
        volume_mm3=props.Mass(),
        bottom_mm=zmin,
        top_mm=zmax,
        box=[xmin, ymin, xmax, ymax],
    )


def mesh(path):
    import gmsh

    gmsh.initialize(["-noenv"])
    try:
        gmsh.option.setNumber("General.Terminal", 0)
        gmsh.model.occ.importShapes(path)
        gmsh.model.occ.synchronize()
        xmin, ymin, zmin, xmax, ymax, zmax = gmsh.model.getBoundingBox(-1, -1)
        size = min(xmax - xmin, ymax - ymin, zmax - zmin) / 4
        gmsh.option.setNumber("Mesh.MeshSizeMax", size)
        gmsh.model.mesh.generate(3)
        types, tags, nodes = gmsh.model.mesh.getElements(3)
        tets = 0
        volume = 0.0
        node_tags, coords, _ = gmsh.model.mesh.getNodes()
        index = {t: i for i, t in enumerate(node_tags)}
        xyz = coords.reshape(-1, 3)
        for t, n in zip(types, nodes):
            if t != 4:  # 4-node tetrahedra
                continue
            n = np.array([index[k] for k in n]).reshape(-1, 4)
            tets += len(n)
            a, b, c, d = (xyz[n[:, k]] for k in range(4))
            volume += np.abs(np.einsum("ij,ij->i", b - a, np.cross(c - a, d - a))).sum() / 6
        return tets, volume
    finally:
        gmsh.finalize()


def main():
    path, grid, pitch_x, y_json, bottom, want_mesh = sys.argv[1:7]
    z_mm = np.loadtxt(grid, delimiter=",", ndmin=2) / 1000.0
    y = np.array(json.loads(y_json))
    x = np.arange(z_mm.shape[1]) * float(pitch_x)
    out = occ(path)
    inner = np.trapezoid(z_mm - float(bottom), x, axis=1)
    out["expected_mm3"] = float(abs(np.trapezoid(inner, y)))
    out["tetrahedra"], out["mesh_volume_mm3"] = mesh(path) if want_mesh == "1" else (0, 0.0)
    json.dump(out, sys.stdout)


if __name__ == "__main__":
    main()
