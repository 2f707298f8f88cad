#!/usr/bin/env python3
"""surfalize's per-line roughness of a grid: the reference `surfscan analyze` is timed against.

For every line (row) of the grid: a surfalize `Profile` at the x pitch, its Gaussian high-pass
at the cutoff (surfalize's ISO 16610-21 kernel, ends reflected), and on the roughness profile
the five parameters Ra, Rq, Rz (five sections), Rsk and Rku. Each line's profile is a new object,
so no cached value is reused between lines.

Usage: lines_surfalize.py GRID.csv PITCH_X_MM CUTOFF_MM [--repeat N]

Prints one JSON object: `lines_s` and `lines_cpu_s` (median wall and CPU seconds over N repeats,
default 5, of all lines' filter and parameters, after one warm-up pass over the first line; CSV
reading and imports excluded), `lines`, and `ra_um` (each line's Ra, so a caller can check that
the work was done on the grid it meant).
"""
import json
import sys
import time

try:
    import numpy as np
    from surfalize import Profile
except ImportError as exc:  # fail loudly: the Rust side reports this text
    sys.stderr.write("numpy/surfalize are not installed ({}); run: bash .ci/run\n".format(exc))
    sys.exit(3)


def per_line(z, step_um, cutoff_um):
    """Each line's (Ra, Rq, Rz, Rsk, Rku) of its roughness profile, µm (Rsk, Rku unitless)."""
    out = []
    for row in z:
        r = Profile(row, step_um).filter("highpass", cutoff_um)
        out.append((r.Ra(), r.Rq(), r.Rz(), r.Rsk(), r.Rku()))
    return out


def main():
    args, repeat = list(sys.argv[1:]), 5
    if "--repeat" in args:
        k = args.index("--repeat")
        repeat = int(args[k + 1])
        del args[k : k + 2]
    if len(args) != 3:
        sys.stderr.write(__doc__)
        sys.exit(2)
    path, pitch_x_mm, cutoff_mm = args[0], float(args[1]), float(args[2])
    z = np.loadtxt(path, delimiter=",", ndmin=2)
    step_um, cutoff_um = pitch_x_mm * 1000.0, cutoff_mm * 1000.0
    per_line(z[:1], step_um, cutoff_um)
    walls, cpus, values = [], [], None
    for _ in range(repeat):
        t0, c0 = time.perf_counter(), time.process_time()
        values = per_line(z, step_um, cutoff_um)
        walls.append(time.perf_counter() - t0)
        cpus.append(time.process_time() - c0)
    json.dump(
        {
            "lines_s": float(np.median(walls)),
            "lines_cpu_s": float(np.median(cpus)),
            "lines": len(values),
            "ra_um": [float(v[0]) for v in values],
        },
        sys.stdout,
    )
    sys.stdout.write("\n")


if __name__ == "__main__":
    main()
