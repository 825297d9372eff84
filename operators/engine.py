"""Preferences buttons: set up the engine in the add-on's user folder, check the engine."""

from __future__ import annotations

import sys
from pathlib import Path

import bpy
from bpy.props import BoolProperty

from ..artgs_addon import engine_setup, preferences
from ..artgs_addon.worker import Worker
from ..core.model import interpreters
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
                     f"the add-on is {package_version()}: press Set Up Engine to install the "
                     "matching engine")
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


def base_python(prefs) -> interpreters.Interpreter:
    """The Python to make the engine's environment with: the preference, else one found here
    that the engine supports (pyproject's requires-python), else Blender's own Python if it is
    one; OSError naming what is needed."""
    requires, _, _ = engine_setup.engine_requirements(preferences.ROOT)
    low, high = interpreters.parse_requires(requires)
    if prefs.setup_python:
        path = bpy.path.abspath(prefs.setup_python)
        chosen = interpreters.probe(path)
        if chosen is None or not interpreters.matches(chosen.version, low, high):
            raise OSError(f"'Python for Set Up' {path} is not a Python the engine supports "
                          f"({requires}); pick another, or leave it empty to search this computer")
        return chosen
    found = interpreters.find(low, high)
    own = interpreters.probe(sys.executable)  # Blender's bundled Python (3.11 in Blender 4.x)
    if not found and own is not None and interpreters.matches(own.version, low, high):
        return own
    if not found:
        raise OSError(f"no Python {requires} found (looked at {interpreters.WHERE}); install "
                      "one (python.org) or set 'Python for Set Up'")
    return found[0]


class ARTGS_OT_setup_engine(bpy.types.Operator):
    """Make a virtual environment with the engine (torch, numba, ...) in the add-on's user
    folder, then check it; Esc cancels"""

    bl_idname = "artgs.setup_engine"
    bl_label = "Set Up Engine"
    bl_options = {"REGISTER"}

    no_deps: BoolProperty(name="Engine Only", default=False, options={"SKIP_SAVE"},
                          description="Install the engine without torch and the other "
                                      "dependencies (they are there already)")

    def execute(self, context: bpy.types.Context) -> set[str]:
        if not self._start(context):
            return {"CANCELLED"}
        self._job.wait()
        return self._conclude(context)

    def invoke(self, context: bpy.types.Context, event: bpy.types.Event) -> set[str]:
        if bpy.app.background or context.window is None:
            return self.execute(context)
        if not self._start(context):
            return {"CANCELLED"}
        wm = context.window_manager
        self._timer = wm.event_timer_add(0.2, window=context.window)
        wm.modal_handler_add(self)
        return {"RUNNING_MODAL"}

    def modal(self, context: bpy.types.Context, event: bpy.types.Event) -> set[str]:
        if event.type == "ESC" and event.value == "PRESS":
            self._job.cancel()
        if event.type != "TIMER" or self._job.running:
            if event.type == "TIMER":
                context.workspace.status_text_set(
                    f"ArtGS Set Up Engine: {100 * self._job.fraction:.0f}% {self._job.message}  "
                    "(Esc to cancel)")
            return {"PASS_THROUGH"}
        context.window_manager.event_timer_remove(self._timer)
        context.workspace.status_text_set(None)
        return self._conclude(context)

    def _start(self, context: bpy.types.Context) -> bool:
        prefs = preferences.get(context)
        wheels = Path(bpy.path.abspath(prefs.setup_wheels)) if prefs.setup_wheels else None
        try:
            base = base_python(prefs)
            self._plan = engine_setup.plan(preferences.user_folder(), base.path, preferences.ROOT,
                                           torch=prefs.setup_torch, find_links=wheels,
                                           no_deps=self.no_deps)
        except (OSError, ValueError) as exc:
            self.report({"ERROR"}, f"Set Up Engine: {exc}")
            return False
        if wheels is None and not bpy.app.online_access:
            command = self._plan.command_line(preferences.ROOT)
            print(f"ArtGS Set Up Engine, to run by hand:\n{command}")
            self.report({"ERROR"}, "Set Up Engine downloads packages, which Blender's 'Allow "
                                   "Online Access' (Preferences > System > Network) forbids: "
                                   "enable it, or run by hand (printed to the console): "
                                   f"{command}")
            return False
        self._job = engine_setup.SetupJob(self._plan, preferences.ROOT).start()
        return True

    def _conclude(self, context: bpy.types.Context) -> set[str]:
        job, plan = self._job, self._plan
        state = engine_setup.EngineState(python=str(plan.python), addon_version=package_version(),
                                         torch="" if self.no_deps else plan.torch)
        if job.cancelled:
            state.status, state.message = "CANCELLED", "cancelled; Set Up Engine again to finish"
        elif job.error is not None:
            state.status, state.message = "FAILED", job.error
        else:
            state.status, state.message = "READY", f"{plan.python} (Python from {plan.base_python})"
        if state.status != "READY":
            state.python = engine_setup.load_state(plan.folder).python  # the engine stays as it was
        else:
            preferences.get(context).engine_python = ""  # the stored engine is used
        engine_setup.save_state(plan.folder, state)
        if state.status != "READY":
            self.report({"WARNING" if job.cancelled else "ERROR"},
                        f"Set Up Engine: {state.message}")
            return {"CANCELLED"}
        self.report({"INFO"}, f"Engine set up: {plan.python}")
        try:
            bpy.ops.artgs.check_engine()
        except RuntimeError:
            pass  # what the check found is in the preferences (last_check)
        return {"FINISHED"}


CLASSES = (ARTGS_OT_check_engine, ARTGS_OT_setup_engine)
