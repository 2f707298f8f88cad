"""Independent reference values for the areal functional and spatial parameters (ISO 25178-2).

Usage: python3 areal_reference.py GRID_CSV PITCH_X_MM PITCH_Y_MM
Prints one JSON object on stdout. Exits non-zero (ImportError) when numpy, scipy, surfalize or
SurfaceTopography is missing, so the calling test fails instead of skipping.

Every reference works on the same heights: the grid (one row per line, y increasing with the
row) levelled here by its least-squares plane with numpy. Three independent sources:

* numpy_ours: our conventions re-implemented from their definitions in numpy, not from our code:
  the Sk family on the linear-quantile material ratio curve with the least-gradient 40 % secant
  (0.1 % steps, first if tied) and trapezoid areas; the volumes as exact integrals of that
  curve; the unbiased linear ACF from scipy.signal.fftconvolve divided by the overlap counts.
* surfalize (0.19.2, its own conventions): Sk family with a least-squares line inside the 40 %
  window on a 10000-class curve; Vmp/Vmc/Vvc/Vvv on that curve (nearest class); the unbiased
  linear ACF; Sal/Str from the edge of the thresholded ACF region with cubic interpolation
  along rays; Std from the angular amplitude spectrum in 0.5 deg bins. surfalize's map has
  row 0 at the top with y pointing up, so it gets the rows reversed (the first line at the
  bottom), which puts its angles in our frame.
* SurfaceTopography (1.27.1): the 1D PSD along x of every line (Hann window, no resampling,
  all wavevectors) averaged over the lines, and along y from the transposed grid; the
  height-difference ACF along x, turned into the height-height ACF with numpy.
"""

import json
import sys
import warnings

import numpy as np
from scipy.signal import fftconvolve
from surfalize import Surface
from SurfaceTopography import Topography


def levelled(z):
    rows, cols = z.shape
    yy, xx = np.mgrid[0:rows, 0:cols]
    a = np.column_stack([np.ones(z.size), xx.ravel(), yy.ravel()])
    coef, *_ = np.linalg.lstsq(a, z.ravel(), rcond=None)
    return z - (a @ coef).reshape(z.shape)


def rmc(s, mr):
    """Linear quantile of ordinates sorted highest first at material ratio mr (%)."""
    p = np.clip(mr / 100.0, 0.0, 1.0) * (len(s) - 1)
    i = np.minimum(np.floor(p).astype(int), len(s) - 1)
    j = np.minimum(i + 1, len(s) - 1)
    return s[i] + (p - i) * (s[j] - s[i])


def mr_at(s, c):
    """Inverse of rmc: the material ratio (%) at level c."""
    asc = s[::-1]
    n = len(s)
    if c >= s[0]:
        return 0.0
    if c <= s[-1]:
        return 100.0
    # position of c in the descending sequence, linear between ordinates
    k = n - np.searchsorted(asc, c, side="left")  # number of ordinates >= c
    hi, lo = s[k - 1], s[k]
    t = (hi - c) / (hi - lo) if hi > lo else 0.0
    return ((k - 1) + t) / (n - 1) * 100.0


def sk_family(z):
    s = np.sort(z.ravel())[::-1]
    mrs = np.arange(1001) * 0.1
    h = rmc(s, mrs)
    drops = h[:601] - h[400:]
    best = 0
    for a in range(1, 601):
        if drops[a] < drops[best] - 1e-12 * abs(drops[best]):
            best = a
    slope = -drops[best] / 40.0
    c = h[best] - slope * mrs[best]
    d = h[best] + slope * (100.0 - mrs[best])
    mr1, mr2 = mr_at(s, c), mr_at(s, d)
    x1 = np.linspace(0.0, mr1, 2001)
    a1 = np.trapezoid(np.maximum(rmc(s, x1) - c, 0.0), x1)
    x2 = np.linspace(mr2, 100.0, 2001)
    a2 = np.trapezoid(np.maximum(d - rmc(s, x2), 0.0), x2)
    return {
        "Sk": c - d,
        "Spk": 2 * a1 / mr1 if mr1 > 0 else 0.0,
        "Svk": 2 * a2 / (100 - mr2) if mr2 < 100 else 0.0,
        "Smr1": mr1,
        "Smr2": mr2,
    }


def volumes(z, p=10.0, q=80.0):
    s = np.sort(z.ravel())[::-1]
    nodes = np.linspace(0.0, 100.0, len(s))

    def integral(a, b):
        inside = (nodes > a) & (nodes < b)
        x = np.concatenate([[a], nodes[inside], [b]])
        return np.trapezoid(rmc(s, x), x)

    vm = lambda m: (integral(0.0, m) - m * rmc(s, m)) / 100.0
    vv = lambda m: ((100.0 - m) * rmc(s, m) - integral(m, 100.0)) / 100.0
    return {
        "Vmp": vm(p),
        "Vmc": vm(q) - vm(p),
        "Vvc": vv(p) - vv(q),
        "Vvv": vv(q),
    }


def acf_unbiased(z):
    rows, cols = z.shape
    raw = fftconvolve(z, z[::-1, ::-1], mode="full")
    ly = np.abs(np.arange(-(rows - 1), rows))
    lx = np.abs(np.arange(-(cols - 1), cols))
    acf = raw / np.outer(rows - ly, cols - lx)
    return acf / acf[rows - 1, cols - 1]


def sample_lags(acf, rows, cols):
    """A few lags (ky, kx) of the ACF for the comparison."""
    out = []
    for ky in sorted({0, 1, 2, rows // 3, -(rows // 2), rows - 1}):
        for kx in sorted({0, 1, 3, 17, cols // 5, -(cols // 3), cols - 1}):
            if abs(ky) < rows and abs(kx) < cols:
                out.append([ky, kx, float(acf[ky + rows - 1, kx + cols - 1])])
    return out


def main():
    path, px_mm, py_mm = sys.argv[1], float(sys.argv[2]), float(sys.argv[3])
    z = levelled(np.loadtxt(path, delimiter=","))
    rows, cols = z.shape
    dx, dy = px_mm * 1000.0, py_mm * 1000.0
    out = {"rows": rows, "cols": cols}

    ours = sk_family(z)
    ours.update(volumes(z))
    acf = acf_unbiased(z)
    out["numpy_ours"] = ours
    out["numpy_acf_lags"] = sample_lags(acf, rows, cols)

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        surf = Surface(z[::-1, :].copy(), dx, dy)
        sal = float(surf.Sal())
        strr = float(surf.Str())
        surfalize_acf = surf.get_autocorrelation_function().data
        out["surfalize"] = {
            "Sk": float(surf.Sk()),
            "Spk": float(surf.Spk()),
            "Svk": float(surf.Svk()),
            "Smr1": float(surf.Smr1()),
            "Smr2": float(surf.Smr2()),
            "Vmp": float(surf.Vmp()),
            "Vmc": float(surf.Vmc()),
            "Vvc": float(surf.Vvc()),
            "Vvv": float(surf.Vvv()),
            "Sal": None if np.isnan(sal) else sal,
            "Str": None if np.isnan(strr) else strr,
            "Std": float(surf.Std()),
        }
    # surfalize's ACF of the row-reversed grid, back in our row order, normalised.
    sa = surfalize_acf[::-1, :]
    sa = sa / sa[rows - 1, cols - 1]
    out["surfalize_acf_lags"] = sample_lags(sa, rows, cols)

    # SurfaceTopography: heights indexed [x, y].
    topo_x = Topography(z.T.copy(), (cols * dx, rows * dy), periodic=False)
    q, c = topo_x.power_spectrum_from_profile(reliable=False, resampling_method=None)
    out["st_psd_x"] = {"q": [float(v) for v in q], "C": [float(v) for v in c]}
    topo_y = Topography(z.copy(), (rows * dy, cols * dx), periodic=False)
    q, c = topo_y.power_spectrum_from_profile(reliable=False, resampling_method=None)
    out["st_psd_y"] = {"q": [float(v) for v in q], "C": [float(v) for v in c]}
    r, a = topo_x.autocorrelation_from_profile(reliable=False, resampling_method=None)
    # A(r_k) = <(h_i^2 + h_{i+k}^2)/2>_k - <h_i h_{i+k}>_k over the lines: the first term from
    # the heights directly, the height-height ACF is what remains.
    zsq = z**2
    a0 = np.array(
        [((zsq[:, : cols - k] + zsq[:, k:]) / 2).mean() for k in range(cols)]
    )
    hh = a0 - np.asarray(a)
    out["st_acf_x"] = [float(v) for v in hh / hh[0]]
    json.dump(out, sys.stdout)


if __name__ == "__main__":
    main()
