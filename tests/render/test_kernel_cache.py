"""numba's on-disk cache of the rasterizer kernels follows the image-model constants, and kernels
loaded from it compute what the freshly compiled ones did.

numba freezes a kernel's globals into the compiled code but checks only the kernel's own file when
loading its cache; core/render/cpu/jit.py keys the cache on the constants as well, and leaves
fused multiply-adds out of the fast-math flags (the JIT and the cached object code fused them
differently).
"""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap

import pytest

from artgs.core.render import constants
from artgs.core.render.cpu import blend_kernels, project_kernels
from artgs.core.render.cpu.jit import cache_key

# a module whose kernels read a model constant, one through core.render.cpu.jit.kernel and one
# through plain njit(cache=True); run in fresh processes sharing its on-disk cache
_MODULE = """
from numba import njit
from artgs.core.render import constants
from artgs.core.render.cpu.jit import kernel

LIMIT = constants.ALPHA_MAX


@kernel
def keyed(x):
    return min(x, LIMIT)


@njit(cache=True)
def plain(x):
    return min(x, LIMIT)
"""

_RUN = """
import sys
from artgs.core.render import constants
if len(sys.argv) > 1:
    constants.ALPHA_MAX = float(sys.argv[1])
import kernels
print(kernels.keyed(5.0), kernels.plain(5.0))
"""


def _run(folder, *args: str) -> tuple[float, float]:
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"}  # cache in the folder
    env["PYTHONPATH"] = os.pathsep.join([str(folder), env.get("PYTHONPATH", "")])
    res = subprocess.run([sys.executable, "-c", _RUN, *args], capture_output=True, text=True,
                         env=env, cwd=folder, timeout=300)
    assert res.returncode == 0, res.stderr
    keyed, plain = res.stdout.split()
    return float(keyed), float(plain)


def test_changed_constant_compiles_afresh(tmp_path):
    (tmp_path / "kernels.py").write_text(textwrap.dedent(_MODULE))
    assert _run(tmp_path) == pytest.approx((0.99, 0.99))
    assert list((tmp_path / "__pycache__").glob("*.nbi"))       # both were cached on disk
    keyed, plain = _run(tmp_path, "0.5")
    assert keyed == pytest.approx(0.5)     # compiled with the new value
    assert plain == pytest.approx(0.99)    # plain njit(cache=True): the stale kernel (the bug)
    assert _run(tmp_path)[0] == pytest.approx(0.99)   # back: the first files are found again
    assert len(list((tmp_path / "__pycache__").glob("kernels.keyed-*.nbi"))) == 2


def test_cache_files_of_the_kernels_carry_the_key(monkeypatch):
    key = cache_key()
    for dispatcher in (blend_kernels.blend_forward, blend_kernels.blend_backward,
                       project_kernels.project_forward, project_kernels.project_backward):
        assert key in dispatcher._cache._cache_file._index_name
    monkeypatch.setattr(constants, "T_MIN", constants.T_MIN * 2)
    assert cache_key() != key


# a small random splat rendered and differentiated: sums of the outputs and gradients, exactly
_RENDER = """
import numpy as np, torch
from artgs.core.render.rasterize import rasterize
r = np.random.default_rng(0); n = 3000
t = lambda a: torch.tensor(a, dtype=torch.float32, requires_grad=True)
P = [t(r.uniform(-0.5, 0.5, (n, 3))), t(r.standard_normal((n, 4))), t(r.uniform(-4.5, -3, (n, 3))),
     t(r.uniform(-1, 3, n)), t(r.uniform(-0.5, 0.5, (n, 1, 3)))]
K = torch.tensor([[40.0, 0, 24], [0, 40.0, 18], [0, 0, 1]])
w2c = torch.eye(4); w2c[2, 3] = 2.0
out = rasterize(*P, K, w2c, 48, 36, backend="cpu")
(out.rgb.square().sum() + out.depth.sum()).backward()
print(*(float(np.abs(v.detach().numpy()).astype(np.float64).sum()).hex()
        for v in [out.rgb, out.depth, *[p.grad for p in P]]))
"""


def test_kernels_loaded_from_the_cache_compute_what_compiled_ones_did(tmp_path):
    """The same render and gradients, to the bit, in a process that compiles the kernels (empty
    cache) and in one that loads them (with LLVM's ``contract`` flag the two differed: depth
    4e-5 and gradients 2e-3 apart on a PartNet capture's render)."""
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "cache"))
    runs = [subprocess.run([sys.executable, "-c", _RENDER], capture_output=True, text=True,
                           env=env, timeout=600) for _ in range(2)]
    assert all(r.returncode == 0 for r in runs), runs[0].stderr + runs[1].stderr
    assert list((tmp_path / "cache").rglob("*.nbi"))          # the second run loaded them
    assert runs[0].stdout == runs[1].stdout
