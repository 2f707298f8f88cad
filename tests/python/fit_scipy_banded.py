#!/usr/bin/env python3
"""Independent, paper-exact reference of the surface fit with banded solves (numpy + scipy).

The algorithm of the paper (P&T A9.3/A9.4, as geomdl.fitting.interpolate_surface does it, which
is too slow beyond a few hundred points per line):

* Q(k, l) = (k * pitch_x, l * pitch_y, h_lk / 1000) in mm, k = column (u), l = row (v);
* parameters along u: per row the cumulative 3-D chord lengths normalised to [0, 1], averaged
  over the rows; along v likewise per column, averaged over the columns;
* knots by averaging (P&T eq. 9.8), clamped;
* collocation matrices from scipy's B-spline basis (BSpline.design_matrix), stored in LAPACK
  band form and solved with scipy.linalg.solve_banded (LAPACK gbsv), first along u for all rows
  at once, then along v for all columns at once.

Nothing here comes from the Rust code: the basis is scipy's, the solver LAPACK's.

Usage: fit_scipy_banded.py GRID.csv PITCH_X_MM PITCH_Y_MM DEGREE_U DEGREE_V [--json] [--repeat N]

GRID.csv: the grid `surfscan fit` reads (heights in um, one row per traced line, ',' separated,
no header). Prints one JSON object: `fit_s` and `fit_cpu_s` (median wall and CPU seconds of the
fit alone over N repeats after a warm-up fit of a small corner of the grid, CSV reading
and imports excluded), and with --json also knots_u, knots_v, x
(pole x per column), y (pole y per row) and z (pole z, row-major: z[j][i] is pole (i, j)).
"""
import json
import sys
import time

try:
    import numpy as np
    from scipy.interpolate import BSpline
    from scipy.linalg import solve_banded
except ImportError as exc:  # fail loudly: the Rust side reports this text
    sys.stderr.write("numpy/scipy are not installed ({}); run: bash .ci/run\n".format(exc))
    sys.exit(3)


def params(z, step, axis):
    """Chord-length parameters along `axis` of the height grid z (mm), averaged over the other
    axis: neighbours along `axis` are `step` mm apart laterally, so a chord is
    sqrt(step^2 + dz^2)."""
    d = np.sqrt(step * step + np.diff(z, axis=axis) ** 2)
    cum = np.cumsum(d, axis=axis)
    total = np.take(cum, [-1], axis=axis)
    t = np.concatenate([[0.0], (cum / total).mean(axis=1 - axis)])
    t[-1] = 1.0
    return t


def knots(t, p):
    inner = np.convolve(t[1:-1], np.full(p, 1.0 / p), mode="valid")
    return np.concatenate([np.zeros(p + 1), inner, np.ones(p + 1)])


def banded(t, kv, p):
    """The collocation matrix N_i(t_k) in LAPACK band form, with its half-bandwidths."""
    m = BSpline.design_matrix(t, kv, p).tocoo()
    rows, cols, vals = m.row, m.col, m.data
    lower = int(max(0, (rows - cols).max()))
    upper = int(max(0, (cols - rows).max()))
    ab = np.zeros((lower + upper + 1, len(t)))
    ab[upper + rows - cols, cols] = vals
    return (lower, upper), ab


def fit(z, pitch_x, pitch_y, p, q):
    rows, cols = z.shape
    x = np.arange(cols) * pitch_x
    y = np.arange(rows) * pitch_y
    tu = params(z, pitch_x, 1)
    tv = params(z, pitch_y, 0)
    ku, kv = knots(tu, p), knots(tv, q)
    lu, abu = banded(tu, ku, p)
    lv, abv = banded(tv, kv, q)
    zu = solve_banded(lu, abu, z.T, check_finite=False)  # (cols, rows)
    pz = solve_banded(lv, abv, zu.T, check_finite=False)  # (rows, cols)
    px = solve_banded(lu, abu, x, check_finite=False)
    py = solve_banded(lv, abv, y, check_finite=False)
    return ku, kv, px, py, pz


def poles_json(result):
    """The knots and poles of `fit`'s result as the members of the JSON printed."""
    ku, kv, px, py, pz = result
    return dict(
        knots_u=ku.tolist(), knots_v=kv.tolist(), x=px.tolist(), y=py.tolist(), z=pz.tolist()
    )


def main(fit, doc, poles_json):
    """Reads the arguments (`doc` says them), times `fit` and prints the JSON, with
    --json `poles_json` of its result."""
    args = [a for a in sys.argv[1:] if not a.startswith("--")]
    want_json = "--json" in sys.argv
    repeat = 1
    if "--repeat" in sys.argv:
        repeat = int(sys.argv[sys.argv.index("--repeat") + 1])
        args.remove(str(repeat))
    if len(args) != 5:
        sys.stderr.write(doc)
        sys.exit(2)
    path = args[0]
    pitch_x, pitch_y = float(args[1]), float(args[2])
    p, q = int(args[3]), int(args[4])
    z = np.loadtxt(path, delimiter=",", ndmin=2) / 1000.0
    # Warm-up on a small corner of the grid, so that scipy's lazily imported modules are not
    # counted as fit time.
    fit(z[: q + 3, : p + 3].copy(), pitch_x, pitch_y, p, q)
    walls, cpus = [], []
    for _ in range(repeat):
        t0, c0 = time.perf_counter(), time.process_time()
        result = fit(z, pitch_x, pitch_y, p, q)
        walls.append(time.perf_counter() - t0)
        cpus.append(time.process_time() - c0)
    out = {
        "fit_s": sorted(walls)[len(walls) // 2],
        "fit_cpu_s": sorted(cpus)[len(cpus) // 2],
    }
    if want_json:
        out.update(poles_json(result))
    json.dump(out, sys.stdout)


if __name__ == "__main__":
    main(fit, __doc__, poles_json)
