#!/usr/bin/env python3
"""Independent, paper-exact reference of the surface fit that interpolates all three
coordinates of every point, as the paper's P(x, y, z) does (numpy + scipy, banded solves).

Beside `fit_scipy_banded.py`, which solves for the heights only and takes the x of a pole
column and the y of a pole row from one solve each: here the points Q(k, l) = (x_k, y_l, z_lk)
are interpolated as 3-vectors, so the u-solve has three right-hand sides per row and the
v-solve three per column, and every pole has its own x, y and z. This is the reference the
`process` benchmark times `surfscan fit` against (a fit in the paper's terms); the test
`fit_scipy::matches_the_full_xyz_reference_*` checks that our poles equal these, all three
coordinates of each.

The parameters, knots and collocation matrices are those of `fit_scipy_banded.py` (scipy's
B-spline basis, LAPACK's banded solver): the same paper-exact definitions, see there.

Usage: fit_scipy_banded_xyz.py GRID.csv PITCH_X_MM PITCH_Y_MM DEGREE_U DEGREE_V [--json] [--repeat N]

Prints one JSON object: `fit_s` and `fit_cpu_s` (median wall and CPU seconds of the fit alone
over N repeats after a warm-up fit of a small corner of the grid, CSV reading and imports
excluded), and with --json also knots_u, knots_v and x, y, z (each row-major: z[j][i] is the z
of pole (i, j)).
"""
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

try:
    import numpy as np
    from scipy.linalg import solve_banded
    from fit_scipy_banded import banded, knots, main, params
except ImportError as exc:  # fail loudly: the Rust side reports this text
    sys.stderr.write("numpy/scipy are not installed ({}); run: bash .ci/run\n".format(exc))
    sys.exit(3)


def fit(z, pitch_x, pitch_y, p, q):
    """Poles (rows, cols, 3) of the interpolating surface of the points (x, y, z) in mm."""
    rows, cols = z.shape
    q_points = np.empty((rows, cols, 3))
    q_points[:, :, 0] = np.arange(cols)[None, :] * pitch_x
    q_points[:, :, 1] = np.arange(rows)[:, None] * pitch_y
    q_points[:, :, 2] = z
    tu = params(z, pitch_x, 1)
    tv = params(z, pitch_y, 0)
    ku, kv = knots(tu, p), knots(tv, q)
    lu, abu = banded(tu, ku, p)
    lv, abv = banded(tv, kv, q)
    # Along u: for each row, cols points of 3 coordinates -> (cols, rows * 3).
    rhs_u = q_points.transpose(1, 0, 2).reshape(cols, rows * 3)
    r = solve_banded(lu, abu, rhs_u, check_finite=False).reshape(cols, rows, 3)
    # Along v: for each column of R, rows points of 3 coordinates -> (rows, cols * 3).
    rhs_v = r.transpose(1, 0, 2).reshape(rows, cols * 3)
    poles = solve_banded(lv, abv, rhs_v, check_finite=False).reshape(rows, cols, 3)
    return ku, kv, poles


def poles_json(result):
    """The knots and the poles' x, y and z (each row-major) as the members of the JSON."""
    ku, kv, poles = result
    return dict(
        knots_u=ku.tolist(),
        knots_v=kv.tolist(),
        x=poles[:, :, 0].tolist(),
        y=poles[:, :, 1].tolist(),
        z=poles[:, :, 2].tolist(),
    )


if __name__ == "__main__":
    main(fit, __doc__, poles_json)
