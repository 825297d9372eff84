"""The import rules of the package, checked by an AST walk over every module's imports.

Every ``import`` / ``from ... import`` of every module of the package (the repo root without
tests/, scripts/ and hidden folders), at module level or lazily inside a function, is resolved to
a module name and checked against these rules (README, "Repository layout"):

1. Layers inside ``core/``: a part imports only the parts listed for it in :data:`MAY_IMPORT`:
   model <- geometry <- render <- train <- stages <- pipeline <- batch <- cli; ``sim`` beside
   render (model and geometry only); ``synth`` may import stages and what they may; ``bench``
   also synth (it generates its sets), pipeline and batch (it times them); only ``cli`` imports
   ``cli``, ``bench``, ``synth`` (and ``artgs.__main__`` imports cli). The ``artgs.core`` package
   itself imports nothing. Every module of core/ belongs to one of these parts (a top-level
   module of core/ is the part of its name, or the one :data:`MODULE_PARTS` gives it).
2. ``core.model`` is numpy-only: at module level it imports only the standard library, numpy and
   model modules; inside functions only the few imports listed in :data:`MODEL_LAZY` (cv2 where
   the capture reader decodes images, model/frame_files.py; torch in the environment probe), so
   importing any model module in Blender loads neither torch nor cv2. The geometry modules in :data:`BLENDER_GEOMETRY` follow the same rule
   (no lazy exceptions). ``core.geometry`` imports only numpy and scipy from outside.
3. The Blender side (``artgs/__init__.py``, ``artgs_addon``, ``operators``, ``panels``) imports,
   at any level, only the standard library, Blender's modules, numpy, ``core.model``, the
   geometry modules in :data:`BLENDER_GEOMETRY` and itself; everything else it reaches through
   the engine process. ``core`` never imports Blender's modules nor the Blender side.
4. No import cycles among the package's modules, counting module-level imports (not those inside
   functions or under ``if TYPE_CHECKING``); importing ``a.b`` is an edge to ``a.b``, not to the
   package ``a`` that Python runs first.
5. Imports of the package are relative (no ``import artgs...`` inside it).
6. Only ``core.cli`` imports argparse: stages and tools take options dataclasses.
"""

from __future__ import annotations

import ast
import shutil
import sys
import textwrap
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = "artgs"
SKIP_DIRS = {"tests", "scripts", "build", "dist", "out", "__pycache__"}

CORE_PARTS = ("model", "geometry", "render", "sim", "train", "stages", "pipeline", "batch",
              "synth", "bench", "cli")
_BELOW_STAGES = {"model", "geometry", "render", "sim", "train"}
MAY_IMPORT: dict[str, set[str]] = {
    "model": set(),
    "geometry": {"model"},
    "render": {"model", "geometry"},
    "sim": {"model", "geometry"},
    "train": {"model", "geometry", "render"},
    "stages": _BELOW_STAGES,
    "pipeline": _BELOW_STAGES | {"stages"},
    "batch": _BELOW_STAGES | {"stages", "pipeline"},
    "synth": _BELOW_STAGES | {"stages"},
    "bench": _BELOW_STAGES | {"stages", "pipeline", "batch", "synth"},
    "cli": set(CORE_PARTS) - {"cli"},
}
#: top-level modules of core/ that belong to a part of another name
MODULE_PARTS = {"artgs.core.resume": "pipeline"}   # what of a run is done: the runner's helper
BLENDER_SIDE = ("artgs_addon", "operators", "panels")
BLENDER_APIS = {"bpy", "bpy_extras", "mathutils", "gpu", "gpu_extras", "bmesh", "addon_utils",
                "_bpy"}
#: numpy-only geometry modules the Blender side may import
BLENDER_GEOMETRY = {"artgs.core.geometry.parts", "artgs.core.geometry.lift",
                    "artgs.core.geometry.metrics"}
#: the only lazy (inside a function) outside imports of core.model, per module
MODEL_LAZY = {"artgs.core.model.frame_files": {"cv2"}, "artgs.core.model.envcheck": {"torch"}}
GEOMETRY_THIRD_PARTY = {"numpy", "scipy"}
STDLIB = set(sys.stdlib_module_names)


@dataclass(frozen=True)
class Import:
    src: str        # importing module
    dst: str        # imported module (dotted; outside the package: as written)
    lazy: bool      # inside a function (or under TYPE_CHECKING): not run at import time
    line: int
    relative: bool

    def __str__(self) -> str:
        return f"{self.src}:{self.line} imports {self.dst}{' (lazily)' if self.lazy else ''}"


def module_name(root: Path, path: Path) -> str:
    parts = list(path.relative_to(root).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join([PACKAGE, *parts])


def package_files(root: Path) -> dict[str, Path]:
    """Module name -> file of every module of the package under ``root``."""
    files = {}
    for path in sorted(root.rglob("*.py")):
        rel = path.relative_to(root).parts
        if any(p in SKIP_DIRS or p.startswith(".") for p in rel[:-1]):
            continue
        files[module_name(root, path)] = path
    return files


def _is_type_checking(node: ast.If) -> bool:
    t = node.test
    return (isinstance(t, ast.Name) and t.id == "TYPE_CHECKING") or \
        (isinstance(t, ast.Attribute) and t.attr == "TYPE_CHECKING")


def imports_of(name: str, path: Path, modules: set[str]) -> list[Import]:
    """Every import statement of module ``name`` (file ``path``), resolved."""
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    found: list[Import] = []

    def visit(node: ast.AST, lazy: bool) -> None:
        for child in ast.iter_child_nodes(node):
            inner = lazy or isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda))
            if isinstance(child, ast.If) and _is_type_checking(child):
                for stmt in child.body:
                    visit_stmt(stmt, True)
                for stmt in child.orelse:
                    visit_stmt(stmt, lazy)
                continue
            visit_stmt(child, inner)

    def visit_stmt(node: ast.AST, lazy: bool) -> None:
        if isinstance(node, ast.Import):
            for a in node.names:
                found.append(Import(name, a.name, lazy, node.lineno, False))
        elif isinstance(node, ast.ImportFrom) and node.module != "__future__":
            if node.level:
                base = package.split(".")
                base = base[:len(base) - (node.level - 1)]
                mod = ".".join(base + ([node.module] if node.module else []))
            else:
                mod = node.module or ""
            for a in node.names:
                sub = f"{mod}.{a.name}"
                found.append(Import(name, sub if sub in modules else mod, lazy, node.lineno,
                                    bool(node.level)))
        visit(node, lazy)

    visit(ast.parse(path.read_text(encoding="utf-8"), str(path)), False)
    return found


def core_part(module: str) -> str | None:
    """``model``, ``geometry``, ... for a module of core/ (``pipeline`` for core/pipeline.py);
    ``""`` for the ``artgs.core`` package itself; None outside core."""
    parts = module.split(".")
    if parts[:2] != [PACKAGE, "core"]:
        return None
    if len(parts) == 3 and module in MODULE_PARTS:
        return MODULE_PARTS[module]
    return parts[2] if len(parts) > 2 else ""


def is_blender_side(module: str) -> bool:
    parts = module.split(".")
    return module == PACKAGE or (len(parts) > 1 and parts[0] == PACKAGE
                                 and parts[1] in BLENDER_SIDE)


def _top(module: str) -> str:
    return module.split(".")[0]


def _blender_importable(module: str) -> bool:
    return (core_part(module) == "model" or module in BLENDER_GEOMETRY
            or module in ("artgs.core", "artgs.core.geometry"))


def rule_violations(imp: Import) -> list[str]:
    """The rules (module docstring) that one import breaks."""
    out = []
    src, dst = imp.src, imp.dst
    inside = _top(dst) == PACKAGE
    if inside and not imp.relative:
        out.append(f"{imp}: imports of the package must be relative")
    src_part, dst_part = core_part(src), core_part(dst) if inside else None
    # 1. layers
    if src_part is not None and dst_part is not None and src_part != dst_part:
        if src_part == "" or dst_part not in MAY_IMPORT.get(src_part, set()):
            out.append(f"{imp}: core.{src_part or '(package)'} may not import core.{dst_part}")
    if src_part is not None and inside and dst_part is None:
        out.append(f"{imp}: core imports outside core")
    if dst_part in ("cli", "bench", "synth") and src_part not in ("cli", dst_part) \
            and not (dst_part == "cli" and src == f"{PACKAGE}.__main__") \
            and not (dst_part == "synth" and src_part == "bench"):
        out.append(f"{imp}: only core.cli imports core.{dst_part}")
    # 2. numpy-only model (and the Blender-importable geometry modules)
    if not inside and _top(dst) not in STDLIB:
        if (src_part == "model" or src in BLENDER_GEOMETRY) and _top(dst) != "numpy":
            if not (imp.lazy and _top(dst) in MODEL_LAZY.get(src, set())):
                out.append(f"{imp}: core.model and Blender-importable geometry are numpy-only")
        if src_part == "geometry" and _top(dst) not in GEOMETRY_THIRD_PARTY:
            out.append(f"{imp}: core.geometry imports only numpy and scipy")
    # 3. the Blender side
    if is_blender_side(src):
        if inside and not (is_blender_side(dst) or _blender_importable(dst)):
            out.append(f"{imp}: the Blender side reaches {dst} only through the engine process")
        if not inside and _top(dst) not in STDLIB | BLENDER_APIS | {"numpy"}:
            out.append(f"{imp}: the Blender side may not import {_top(dst)}")
    if _top(dst) == "argparse" and src_part != "cli":
        out.append(f"{imp}: only core.cli parses command lines")
    if src_part is not None and ((not inside and _top(dst) in BLENDER_APIS)
                                 or (inside and is_blender_side(dst))):
        out.append(f"{imp}: core never imports Blender or the add-on")
    if src_part is not None and src in BLENDER_GEOMETRY | {"artgs.core", "artgs.core.geometry"} \
            and inside and not _blender_importable(dst):
        out.append(f"{imp}: a Blender-importable module imports beyond model")
    return out


def cycles(modules: set[str], imports: list[Import]) -> list[list[str]]:
    """Strongly connected components (size > 1, or a module importing itself) of the
    module-level import graph (Tarjan)."""
    graph: dict[str, set[str]] = {m: set() for m in modules}
    for imp in imports:
        if not imp.lazy and imp.dst in modules:
            graph[imp.src].add(imp.dst)
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []
    sys.setrecursionlimit(max(sys.getrecursionlimit(), 10 * len(graph) + 100))

    def strong(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph[v]):
            if w not in index:
                strong(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1 or v in graph[v]:
                found.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            strong(v)
    return found


def violations(root: Path) -> list[str]:
    """Every broken rule in the package under ``root``, one line each."""
    files = package_files(root)
    modules = set(files)
    imports = [imp for name, path in files.items() for imp in imports_of(name, path, modules)]
    out = [v for imp in imports for v in rule_violations(imp)]
    out += [f"import cycle: {' -> '.join(c)}" for c in cycles(modules, imports)]
    return out


# --- tests ---------------------------------------------------------------------------------------

def test_the_package_follows_the_import_rules():
    assert package_files(ROOT)["artgs.core.model.capture"].is_file()
    assert violations(ROOT) == []


def test_every_core_module_is_in_a_layer():
    parts = {core_part(m) for m in package_files(ROOT)} - {None, ""}
    assert parts <= set(CORE_PARTS), parts - set(CORE_PARTS)


def _copy_package(dst: Path) -> Path:
    """The package's modules copied to ``dst`` (no tests, caches or data)."""
    for name, path in package_files(ROOT).items():
        target = dst / path.relative_to(ROOT)
        target.parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(path, target)
    return dst


def _inject(root: Path, rel: str, source: str) -> None:
    path = root / rel
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(textwrap.dedent(source), encoding="utf-8")


def test_the_checker_reports_broken_rules(tmp_path):
    root = _copy_package(tmp_path / "artgs")
    assert violations(root) == []
    _inject(root, "operators/injected.py", """
        import numpy as np


        def execute():
            import torch                      # lazily, still in Blender's process
            from ..core.stages import reconstruct
            return torch, reconstruct
        """)
    _inject(root, "artgs_addon/injected.py", "import scipy.spatial\n")
    _inject(root, "core/stages/injected.py", "from ..cli import app\n")
    _inject(root, "core/model/injected.py", """
        import torch
        from ..render import sh


        def read():
            import cv2                        # lazily, but not in the capture reader
            return cv2
        """)
    _inject(root, "core/geometry/cycle_a.py", "from . import cycle_b\n")
    _inject(root, "core/geometry/cycle_b.py", "from .cycle_a import x\n")
    _inject(root, "core/render/absolute.py", "from artgs.core.model import layout\n")
    _inject(root, "core/stages/parsing.py", "def run(args):\n    import argparse\n")
    found = violations(root)
    expected = {
        "artgs.operators.injected:6 imports torch (lazily)": "Blender side may not import torch",
        "artgs.operators.injected:7 imports artgs.core.stages.reconstruct (lazily)":
            "only through the engine process",
        "artgs.artgs_addon.injected:1 imports scipy.spatial": "Blender side may not import scipy",
        "artgs.core.stages.injected:1 imports artgs.core.cli.app":
            "core.stages may not import core.cli",
        "artgs.core.model.injected:2 imports torch": "numpy-only",
        "artgs.core.model.injected:3 imports artgs.core.render.sh":
            "core.model may not import core.render",
        "artgs.core.model.injected:7 imports cv2 (lazily)": "numpy-only",
        "import cycle": "artgs.core.geometry.cycle_a -> artgs.core.geometry.cycle_b",
        "artgs.core.render.absolute:1 imports artgs.core.model.layout": "must be relative",
        "artgs.core.stages.parsing:2 imports argparse (lazily)": "only core.cli parses",
    }
    for where, what in expected.items():
        assert any(line.startswith(where) and what in line for line in found), (where, found)
    assert "only core.cli imports core.cli" in "\n".join(found)
    assert len(found) == len(expected) + 1, found
