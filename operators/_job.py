"""Base of the operators that run one engine command in the worker.

In the UI (``invoke``) the operator is modal: a window-manager timer polls the worker, progress
shows in the status bar and in the stage's panel, Esc or right-click cancels and leaves the scene
as it was. Under ``EXEC_DEFAULT`` and in background mode the same command runs synchronously.
An engine error is reported with the engine's message and the stage state becomes
"failed: <message>"; the scene is otherwise unchanged.
"""

from __future__ import annotations

from typing import Any, ClassVar

import bpy

from ..artgs_addon import preferences
from ..artgs_addon.crop_box import sync_crop
from ..artgs_addon.properties import ArtgsStageState
from ..artgs_addon.worker import Worker, WorkerResult
from ..core.model import protocol
from ..core.model.errors import ArtgsError

#: Jobs running in the UI: (worker, timer). At most one at a time; unregister cancels them.
_ACTIVE: list[tuple[Worker, Any]] = []
_TIMER_STEP = 0.1


def job_running() -> bool:
    """True while a worker job runs in the UI (operators that start jobs are then disabled)."""
    return bool(_ACTIVE)


def cancel_all() -> None:
    """Stop every running job and remove its timer (used by unregister)."""
    wm = bpy.context.window_manager
    while _ACTIVE:
        worker, timer = _ACTIVE.pop()
        worker.cancel()
        if wm is not None and timer is not None:
            wm.event_timer_remove(timer)


def engine_inputs_ready(context: bpy.types.Context) -> bool:
    """No job running, an output folder set and a capture folder with a transforms.json."""
    settings = getattr(context.scene, "artgs", None)
    if settings is None or job_running() or settings.output_path is None:
        return False
    capture = settings.capture_path
    return capture is not None and (capture / "transforms.json").is_file()


def stage_args(context: bpy.types.Context, iterations: int = 0) -> list[str]:
    """An engine stage's arguments: OUT, the capture, the preferred device and, when set, the
    iteration cap."""
    settings = context.scene.artgs
    args = [str(settings.output_path), "--capture", str(settings.capture_path),
            "--device", preferences.get(context).device]
    return args + (["--iterations", str(iterations)] if iterations else [])


def figures_text(figures: dict[str, Any], limit: int = 4) -> str:
    """Key figures as ``name value`` pairs (floats to 4 significant digits)."""
    parts = []
    for key, value in list(figures.items())[:limit]:
        if isinstance(value, float):
            value = f"{value:.4g}"
        parts.append(f"{key.replace('_', ' ')} {value}")
    return ", ".join(parts)


class WorkerOperator:
    """Mixin for ``bpy.types.Operator`` subclasses that run ``artgs <command>`` in the worker.

    Subclasses set ``stage`` (a ``Scene.artgs`` stage) and ``command``, and implement
    ``worker_args`` and ``finish`` (build the Blender side from the engine's outputs; return the
    key figures for the panel). ``prepare`` may refuse to start with a message; ``cleanup`` runs
    once the job has ended, however it ended (after ``prepare``, even when it refused).
    """

    stage: ClassVar[str]
    command: ClassVar[str]

    # -- to override -------------------------------------------------------------------------
    def prepare(self, context: bpy.types.Context) -> str | None:
        """A reason not to start (shown as the error), or None."""
        return None

    def worker_args(self, context: bpy.types.Context) -> list[str]:
        raise NotImplementedError

    def worker_env(self, context: bpy.types.Context) -> dict[str, str]:
        return {}

    def cleanup(self, context: bpy.types.Context) -> None:
        """Remove what ``prepare`` made (temporary files)."""

    def restore(self, context: bpy.types.Context) -> None:
        """Undo what the operator changed in the scene while the job ran (cancel or failure)."""

    def on_progress(self, context: bpy.types.Context, figures: dict[str, Any]) -> None:
        """Figures of a progress event while the job runs (e.g. joints to show live)."""

    def finish(self, context: bpy.types.Context, result: WorkerResult) -> str:
        raise NotImplementedError

    # -- shared ------------------------------------------------------------------------------
    def _state(self, context: bpy.types.Context) -> ArtgsStageState:
        return context.scene.artgs.stage(self.stage)

    def _start(self, context: bpy.types.Context) -> bool:
        """Start the worker; False (after reporting) if it cannot start."""
        state = self._state(context)
        self._before = state.snapshot()
        self._figures: dict[str, Any] = {}
        out = context.scene.artgs.output_path
        if out is not None:
            sync_crop(context.scene, out)       # the crop box -> OUT/crop.json: every stage reads it
        reason = self.prepare(context)
        if reason is None:
            self._worker = Worker(preferences.engine_python(context), self.command,
                                  self.worker_args(context), env=self.worker_env(context))
            try:
                self._worker.start()
            except OSError as exc:
                reason = str(exc)
        if reason is not None:
            self._fail(context, reason)
            self.cleanup(context)
            return False
        state.set("RUNNING", "starting")
        return True

    def _fail(self, context: bpy.types.Context, message: str) -> set[str]:
        self._state(context).set("FAILED", message)
        self.report({"ERROR"}, message)
        return {"CANCELLED"}

    def _on_events(self, context: bpy.types.Context, events: list[dict[str, Any]]) -> None:
        state = self._state(context)
        for event in events:
            kind = event.get(protocol.EVENT)
            if kind == protocol.PROGRESS:
                stage, message = event.get("stage", ""), event.get("message", "")
                state.progress = float(event.get("fraction", 0.0))
                state.message = f"{stage}: {message}".strip(": ")
                self.on_progress(context, event.get("figures") or {})
            elif kind == protocol.STAGE_DONE:
                self._figures.update(event.get("figures") or {})
            elif kind == protocol.LOG and event.get("level") == "warning":
                self.report({"WARNING"}, str(event.get("message", "")))

    def _complete(self, context: bpy.types.Context) -> set[str]:
        try:
            return self._conclude(context)
        finally:
            self.cleanup(context)

    def _conclude(self, context: bpy.types.Context) -> set[str]:
        result = self._worker.result
        state = self._state(context)
        if result.cancelled:
            self.restore(context)
            state.restore(self._before)
            self.report({"WARNING"}, f"{self.bl_label}: cancelled")
            return {"CANCELLED"}
        if result.error is not None:
            self.restore(context)
            return self._fail(context, result.error)
        try:
            summary = self.finish(context, result)
        except (ArtgsError, OSError, ValueError) as exc:
            return self._fail(context, str(exc))
        state.set("DONE", summary, 1.0)
        self.report({"INFO"}, f"{self.bl_label}: {summary}")
        return {"FINISHED"}

    # -- synchronous -------------------------------------------------------------------------
    def execute(self, context: bpy.types.Context) -> set[str]:
        if not self._start(context):
            return {"CANCELLED"}
        self._worker.wait(on_events=lambda events: self._on_events(context, events))
        return self._complete(context)

    # -- modal -------------------------------------------------------------------------------
    def invoke(self, context: bpy.types.Context, event: bpy.types.Event) -> set[str]:
        if bpy.app.background or context.window is None:
            return self.execute(context)
        if not self._start(context):
            return {"CANCELLED"}
        wm = context.window_manager
        self._timer = wm.event_timer_add(_TIMER_STEP, window=context.window)
        _ACTIVE.append((self._worker, self._timer))
        wm.modal_handler_add(self)
        self._show(context)
        return {"RUNNING_MODAL"}

    def modal(self, context: bpy.types.Context, event: bpy.types.Event) -> set[str]:
        if (self._worker, self._timer) not in _ACTIVE:  # cancelled by unregister
            self.cleanup(context)
            return {"CANCELLED"}
        if event.type in {"ESC", "RIGHTMOUSE"} and event.value == "PRESS":
            self._worker.cancel()
            self._worker.wait()
            self._end_modal(context)
            return self._complete(context)
        if event.type == "TIMER":  # ours or another: polling is cheap
            self._on_events(context, self._worker.poll())
            if not self._worker.running:
                self._on_events(context, self._worker.poll())
                self._end_modal(context)
                return self._complete(context)
            self._show(context)
        return {"PASS_THROUGH"}

    def _show(self, context: bpy.types.Context) -> None:
        state = self._state(context)
        context.workspace.status_text_set(
            f"ArtGS {self.bl_label}: {100 * state.progress:.0f}% {state.message}  "
            "(Esc or right-click to cancel)")
        for area in context.screen.areas:
            if area.type == "VIEW_3D":
                area.tag_redraw()

    def _end_modal(self, context: bpy.types.Context) -> None:
        if (self._worker, self._timer) in _ACTIVE:
            _ACTIVE.remove((self._worker, self._timer))
        context.window_manager.event_timer_remove(self._timer)
        context.workspace.status_text_set(None)
        for area in context.screen.areas:
            if area.type == "VIEW_3D":
                area.tag_redraw()
