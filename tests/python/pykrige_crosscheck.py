#!/usr/bin/env python3
"""Ordinary kriging with PyKrige for tests/it/fm.rs.

Usage: pykrige_crosscheck.py IN.json OUT.json. IN holds the data (x, y, z), the
prediction points (xp, yp) and the variogram (model "spherical" or "exponential",
psill, range, nugget), given explicitly so that PyKrige does not refit it. OUT gets the
predictions z and the kriging variances ss. Exit status 3 when PyKrige is missing.
"""
import json
import sys

try:
    import numpy as np
    from pykrige.ok import OrdinaryKriging
except ImportError:
    sys.exit(3)


def main():
    with open(sys.argv[1]) as f:
        p = json.load(f)
    ok = OrdinaryKriging(
        np.array(p["x"], dtype=float),
        np.array(p["y"], dtype=float),
        np.array(p["z"], dtype=float),
        variogram_model=p["model"],
        variogram_parameters={"psill": p["psill"], "range": p["range"], "nugget": p["nugget"]},
        exact_values=True,
    )
    z, ss = ok.execute("points", np.array(p["xp"], dtype=float), np.array(p["yp"], dtype=float))
    with open(sys.argv[2], "w") as f:
        json.dump({"z": np.asarray(z).tolist(), "ss": np.asarray(ss).tolist()}, f)


if __name__ == "__main__":
    main()
