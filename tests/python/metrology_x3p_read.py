"""Reads an X3P file with surfalize (an independent reader) and prints its grid as JSON.

Usage: python3 metrology_x3p_read.py FILE.x3p
Fails (ImportError / reader error, non-zero exit) when surfalize is missing or rejects the file.
"""

import json
import sys

from surfalize import Surface


def main():
    surface = Surface.load(sys.argv[1])
    data = surface.data
    json.dump(
        {
            "rows": int(data.shape[0]),
            "cols": int(data.shape[1]),
            "step_x_um": float(surface.step_x),
            "step_y_um": float(surface.step_y),
            "heights_um": [float(v) for v in data.ravel()],
        },
        sys.stdout,
    )


if __name__ == "__main__":
    main()
