"""Preferences button: check that the engine interpreter has every dependency."""

from __future__ import annotations

import bpy

from ..artgs_addon import preferences
from ..artgs_addon.worker import Worker
from ..core.model.envcheck import missing_message, package_version

#: The check imports torch and friends: generous, but a hung interpreter must not hang Blender.
CHECK_TIMEOUT = 180.0


def check_lines(outputs: dict) -> list[str]:
    """What ``artgs check-env`` found, as lines for the preferences."""
    versions = outputs.get("versions", {})
    found = ", ".join(f"{k} {v}" for k, v in versions.items() if v is not None)
    lines = [f"Python {outputs.get('python_version', '?')}: {outputs.get('python', '?')}",
             f"Found: {found or 'nothing'}",
             f"Device: {outputs.get('cuda_note', '?')}; gsplat: "
             f"{'yes' if outputs.get('gsplat') else 'no'}"]
    if outputs.get("missing"):
        lines.append(missing_message(outputs))
    if outputs.get("artgs") not in (None, package_version()):
        lines.append(f"Engine code is version {outputs.get('artgs')} ({outputs.get('root')}); "
                     f"the add-on is {package_version()}: install the same version in both")
    return lines


class ARTGS_OT_check_engine(bpy.types.Operator):
    """Run the engine's environment check with the interpreter set in the preferences"""

    bl_idname = "artgs.check_engine"
    bl_label = "Check Engine"
    bl_options = {"REGISTER"}

    def execute(self, context: bpy.types.Context) -> set[str]:
        engine = preferences.engine_python(context)
        worker = Worker(engine, "check-env")
        try:
            worker.start()
        except OSError as exc:
            preferences.last_check[:] = [str(exc)]
            self.report({"ERROR"}, str(exc))
            return {"CANCELLED"}
        result = worker.wait(timeout=CHECK_TIMEOUT)
        lines = check_lines(result.outputs) if result.outputs else []
        if result.error is not None and not result.outputs:
            lines.append(result.error)
        preferences.last_check[:] = lines
        if result.error is not None:
            self.report({"ERROR"}, result.error)
            return {"CANCELLED"}
        self.report({"INFO"}, f"Engine OK: {engine}")
        return {"FINISHED"}


CLASSES = (ARTGS_OT_check_engine,)
