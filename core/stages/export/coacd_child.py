"""Run as a script: ``python coacd_child.py IN.npz OUT.npz`` decomposes the mesh in IN.npz
(``vertices``, ``faces``, ``settings`` as JSON) with CoACD and writes its pieces to OUT.npz
(``v0``, ``f0``, ``v1``, …). Imports nothing of this package, so it runs the same under any
package name and from a daemonic batch worker (see ``collision.isolated_coacd``)."""

import json
import sys

import numpy as np


def main(src: str, dst: str) -> None:
    import coacd

    data = np.load(src)
    settings = json.loads(str(data["settings"]))
    coacd.set_log_level("error")
    pieces = coacd.run_coacd(coacd.Mesh(data["vertices"], data["faces"]), **settings)
    arrays = {}
    for k, (v, f) in enumerate(pieces):
        arrays[f"v{k}"], arrays[f"f{k}"] = np.asarray(v, float), np.asarray(f, np.int64)
    np.savez(dst, **arrays)


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2])
