"""Reads or writes a profile X3P (FeatureType PRF) with x3pio, a reader and writer independent of
surfscan's (surfalize and SurfaceTopography read surfaces only).

Usage:
  python3 x3p_profile.py read FILE.x3p
      prints as JSON what x3pio finds: the file's kind (Profile, Surface), its points, the x
      of the first point and the x increment in µm (the axis offset placing the points), and
      the heights in µm.
  python3 x3p_profile.py write PROFILE.csv OUT.x3p
      writes the profile CSV (header, then x_mm,z_um rows at a constant pitch) as a PRF file
      with x3pio's own writer (float64 heights in metres, x increment from the first two rows).
"""

import json
import sys

import numpy as np
import x3pio


def read(path):
    f = x3pio.read(path)
    layer = f.layers[0]
    z = np.asarray(layer.z, dtype=float).ravel()
    points = layer.points().reshape(-1, 3)
    json.dump(
        {
            "kind": type(f).__name__,
            "points": int(z.size),
            "first_x_um": float(points[0, 0] * 1e6),
            "step_x_um": float((points[1, 0] - points[0, 0]) * 1e6),
            "heights_um": [float(v) * 1e6 for v in z],
        },
        sys.stdout,
    )


def write(csv, out):
    data = np.loadtxt(csv, delimiter=",", skiprows=1)
    pitch_m = round((data[1, 0] - data[0, 0]) * 1e9) / 1e12
    metadata = x3pio.Metadata(
        probing_system=x3pio.ProbingSystem(x3pio.ProbingType.CONTACTING, "stylus"),
    )
    x3pio.write(out, data[:, 1] * 1e-6, x_scale=pitch_m, metadata=metadata)


if __name__ == "__main__":
    if sys.argv[1] == "read":
        read(sys.argv[2])
    else:
        write(sys.argv[2], sys.argv[3])
