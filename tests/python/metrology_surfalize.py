"""Independent reference values for the metrology checks, from surfalize and scipy.

Usage: python3 metrology_surfalize.py DATA_DIR
Prints one JSON object on stdout. Exits non-zero (ImportError) when surfalize, numpy or scipy is
missing, so the calling test fails instead of skipping.

What is computed (the conventions are surfalize's own, stated beside each value):
* mitutoyo: the Mitutoyo SurfTest R profile as exported (no filter).
  - Rdc(10 %, 25 %) and Rmr(c) at 10 % and 15 % of Rt below the highest point: surfalize's
    material ratio curve is the point quantiles, ours the piecewise-linear bearing length.
  - Rp/Rv/Rz with n_sections=4 and Rt: surfalize takes the ordinates as given for these.
  - Ra/Rq/Rsk/Rku: surfalize subtracts the profile mean and evaluates over the whole length.
  - Rk/Rpk/Rvk/Mr1/Mr2: surfalize least-squares fits the 40 % window (our secant differs).
  - Rdq: surfalize uses the forward difference (our 7-point differs).
* gaussian_<name>: the ISO 16610-21 mean line from scipy.ndimage.gaussian_filter1d with
  sigma = lambda_c * sqrt(ln2 / 2) / pi and truncation at +-lambda_c (the same kernel, normalised
  the same way); ends differ (scipy pads, we use the moment criterion), so only the interior
  one lambda_c away from either end is reported: Ra, Rq, max, min of R there.
* areal_sur2: the 31-profile sur-2 grid levelled by surfalize's least-squares plane; Sa..Sku,
  Sdq (forward differences per direction) and Sdr (ISO 25178-2:2021 D.3, two triangulations
  averaged) are the same discretisations as ours.
"""

import json
import math
import sys
import warnings
from pathlib import Path

import numpy as np
from scipy.ndimage import gaussian_filter1d
from surfalize import Profile, Surface


def load(path):
    data = np.loadtxt(path, delimiter=",", skiprows=1)
    return data[:, 0], data[:, 1]


def main():
    root = Path(sys.argv[1])
    out = {}

    x, z = load(root / "mitutoyo_surftest_R.x_mm_z_um.csv")
    step_um = (x[1] - x[0]) * 1000.0
    p = Profile(z, step_um)
    out["mitutoyo"] = {
        "Rp": float(p.Rp(n_sections=4)),
        "Rv": float(p.Rv(n_sections=4)),
        "Rz": float(p.Rz(n_sections=4)),
        "Rt": float(p.Rt()),
        "Ra_ln_mean_removed": float(p.Ra()),
        "Rq_ln_mean_removed": float(p.Rq()),
        "Rsk_ln_mean_removed": float(p.Rsk()),
        "Rku_ln_mean_removed": float(p.Rku()),
        "Rdq_forward_difference": float(p.Rdq()),
        "Rk_least_squares": float(p.Rk()),
        "Rpk_least_squares": float(p.Rpk()),
        "Rvk_least_squares": float(p.Rvk()),
        "Mr1_least_squares": float(p.Rmr1()),
        "Mr2_least_squares": float(p.Rmr2()),
        # The material ratio curve as point quantiles (np.quantile), ours is the
        # piecewise-linear bearing length: they differ by about one point's share.
        "Rdc_10_25_quantiles": float(p.Rdc(10.0, 25.0)),
    }
    # Rmr(c) with the SJ series' peak reference: depth below the highest point in % of Rt.
    # surfalize's material ratio curve is built from the heights as given (no mean removal).
    rt = float(z.max() - z.min())
    for depth in (10.0, 15.0):
        out["mitutoyo"][f"Rmr_c_peak_{depth:g}pct_quantiles"] = float(
            p.Rmr(float(z.max()) - rt * depth / 100.0)
        )

    for name, lc in (("hfm-1", 0.8), ("dektak-1", 0.25)):
        x, z = load(root / f"{name}.x_mm_z_um.csv")
        pitch = 1500.0 / 9600.0 / 1000.0 if name == "dektak-1" else x[1] - x[0]
        sigma_pts = lc * math.sqrt(math.log(2.0) / 2.0) / math.pi / pitch
        half = math.floor(lc / pitch + 1e-9)
        w = gaussian_filter1d(z, sigma_pts, mode="reflect", truncate=half / sigma_pts)
        r = (z - w)[half:-half]
        out["gaussian_" + name] = {
            "lambda_c_mm": lc,
            "pitch_mm": pitch,
            "skip_points": half,
            "Ra": float(np.mean(np.abs(r))),
            "Rq": float(np.sqrt(np.mean(r * r))),
            "max": float(r.max()),
            "min": float(r.min()),
        }

    # Areal: the 31 profiles of sur-2 as a grid, least-squares plane levelled by surfalize.
    data = np.loadtxt(root / "sur-2.31profiles.y_mm_x_mm_z_um.csv", delimiter=",", skiprows=1)
    rows = int(data[:, 0].max()) - int(data[:, 0].min()) + 1
    grid = data[:, 3].reshape(rows, -1)
    xs = data[: grid.shape[1], 2]
    ys = data[:: grid.shape[1], 1]
    step_x = (xs[-1] - xs[0]) / (len(xs) - 1) * 1000.0
    step_y = (ys[-1] - ys[0]) / (len(ys) - 1) * 1000.0
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # unequal pitches are expected here
        surf = Surface(grid, step_x, step_y).level()
        out["areal_sur2"] = {
            "rows": int(grid.shape[0]),
            "cols": int(grid.shape[1]),
            "pitch_x_mm": step_x / 1000.0,
            "pitch_y_mm": step_y / 1000.0,
            **{k: float(getattr(surf, k)()) for k in ("Sa", "Sq", "Sp", "Sv", "Sz", "Ssk", "Sku", "Sdq", "Sdr")},
        }

    json.dump(out, sys.stdout, indent=1)


if __name__ == "__main__":
    main()
