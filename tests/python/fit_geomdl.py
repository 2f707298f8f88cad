#!/usr/bin/env python3
"""Independent reference for the surface fit: geomdl.fitting.interpolate_surface (P&T A9.4).

Usage: fit_geomdl.py GRID.csv PITCH_X_MM DEGREE_U DEGREE_V

GRID.csv: one line per traced line (row, v direction): y_mm followed by the heights in um.
Point Q(k, l) = (k * pitch_x_mm, y_l, h_kl / 1000), all in mm.
Prints JSON: knots_u, knots_v, size_u, size_v and ctrlpts in geomdl's u-major order
(ctrlpts[i_u * size_v + j_v] = [x, y, z]).
"""
import csv
import json
import sys

try:
    from geomdl import fitting
except ImportError as exc:  # fail loudly: the Rust test reports this text
    sys.stderr.write("geomdl is not installed ({}); run: pip install geomdl\n".format(exc))
    sys.exit(3)


def main():
    if len(sys.argv) != 5:
        sys.stderr.write(__doc__)
        sys.exit(2)
    path, pitch, deg_u, deg_v = sys.argv[1], float(sys.argv[2]), int(sys.argv[3]), int(sys.argv[4])
    with open(path, newline="") as f:
        rows = [[float(c) for c in r] for r in csv.reader(f) if r]
    ys = [r[0] for r in rows]
    heights = [r[1:] for r in rows]
    size_v = len(rows)
    size_u = len(heights[0])
    # geomdl point order is u-major: points[v + size_v * u].
    points = []
    for k in range(size_u):
        for l in range(size_v):
            points.append([k * pitch, ys[l], heights[l][k] / 1000.0])
    surf = fitting.interpolate_surface(points, size_u, size_v, deg_u, deg_v)
    json.dump(
        {
            "size_u": size_u,
            "size_v": size_v,
            "knots_u": list(surf.knotvector_u),
            "knots_v": list(surf.knotvector_v),
            "ctrlpts": [list(p) for p in surf.ctrlpts],
        },
        sys.stdout,
    )


if __name__ == "__main__":
    main()
