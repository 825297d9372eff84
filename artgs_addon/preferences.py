"""Add-on preferences: the engine interpreter (and setting one up), the VLM endpoint (key kept out
of .blend files), the compute device and the preview point cap.

The engine interpreter is also kept in ``engine.json`` in the extension's user folder
(engine_setup.py), so it survives disabling the add-on and restarts: the preference, when set,
wins; else the stored engine; else ``default_engine()``.
"""

import sys
from pathlib import Path
from types import SimpleNamespace

import bpy
from bpy.props import EnumProperty, IntProperty, StringProperty

from . import engine_setup

#: The root package: ``artgs`` as a Python module, ``bl_ext.<repo>.artgs`` inside Blender.
ADDON_ID = __package__.rpartition(".")[0]
#: The package folder (the extension folder; a source checkout's root).
ROOT = Path(__file__).resolve().parent.parent

DEVICES = (("auto", "Auto", "CUDA when available, else CPU"),
           ("cpu", "CPU", "Always run on the CPU"),
           ("cuda", "CUDA", "Run on the GPU (needs a CUDA build of torch)"))


def default_engine() -> str:
    """``.venv/bin/python`` beside the package root if there is one, else Blender's Python."""
    for candidate in (ROOT / ".venv" / "bin" / "python", ROOT / ".venv" / "Scripts" / "python.exe"):
        if candidate.is_file():
            return str(candidate)
    return sys.executable


TORCH_BUILDS = (("cpu", "CPU", "The CPU build of torch (works everywhere)"),
                ("cuda", "CUDA", "A CUDA build of torch (NVIDIA GPU with a recent driver)"))


def user_folder() -> Path:
    """The extension's user folder (kept across updates and restarts); for the package
    registered as a plain add-on (bpy as a module), Blender's config folder ``artgs``."""
    if ADDON_ID.startswith("bl_ext."):
        return Path(bpy.utils.extension_path_user(ADDON_ID, create=True))
    return Path(bpy.utils.user_resource("CONFIG", path="artgs", create=True))


def get(context: bpy.types.Context | None = None):
    """The add-on's preferences; their defaults when the package was registered without
    ``addon_utils`` (e.g. ``import artgs; artgs.register()`` with bpy as a module)."""
    addon = (context or bpy.context).preferences.addons.get(ADDON_ID)
    return addon.preferences if addon is not None else _defaults()


def engine_python(context: bpy.types.Context | None = None) -> str:
    """The interpreter that runs the engine: the preference, else the stored engine, else the
    default."""
    chosen = bpy.path.abspath(get(context).engine_python)
    return chosen or engine_setup.load_state(user_folder()).python or default_engine()


def _engine_chosen(self, context: bpy.types.Context) -> None:
    """The preference is stored too (it survives disable/enable and restarts); clearing it
    goes back to the default engine."""
    chosen = bpy.path.abspath(self.engine_python)
    folder = user_folder()
    if engine_setup.load_state(folder).python != chosen:
        engine_setup.save_state(folder, engine_setup.EngineState(
            python=chosen, message="chosen in the preferences" if chosen else ""))


def preview_cap(context: bpy.types.Context) -> int:
    """Points allowed in a preview: the preference's cap times the scene's density."""
    return max(1, int(get(context).preview_cap * context.scene.artgs.preview_density))


#: Outcome of the last "Check Engine" (kept in memory only, shown in the preferences).
last_check: list[str] = []


class ArtgsPreferences(bpy.types.AddonPreferences):
    bl_idname = ADDON_ID

    engine_python: StringProperty(
        name="Engine Python", subtype="FILE_PATH", update=_engine_chosen,
        description="Python interpreter of the environment where the ArtGS engine (torch, numba, "
                    "...) is installed; empty: the one Set Up Engine made, else the .venv beside "
                    "the add-on, else Blender's own")
    setup_python: StringProperty(
        name="Python for Set Up", subtype="FILE_PATH",
        description="Python (a version the engine supports) to make the engine's environment "
                    "with; empty: found on this computer (PATH, pyenv, py launcher, uv)")
    setup_torch: EnumProperty(name="Torch", items=TORCH_BUILDS, default="cpu",
                              description="Which torch build Set Up Engine installs")
    setup_wheels: StringProperty(
        name="Wheel Folder", subtype="DIR_PATH",
        description="Install everything from the wheels in this folder only (offline); empty: "
                    "from the package indexes (needs Allow Online Access)")
    vlm_endpoint: StringProperty(
        name="VLM Endpoint", default="",
        description="OpenAI-compatible base URL of the vision-language model, "
                    "e.g. http://127.0.0.1:8000/v1")
    vlm_model: StringProperty(name="VLM Model", default="", description="Model name at the endpoint")
    vlm_api_key: StringProperty(
        name="VLM API Key", subtype="PASSWORD", default="",
        description="Kept in the preferences only (never in .blend files); passed to the engine "
                    "in the environment variable ARTGS_VLM_API_KEY")
    device: EnumProperty(name="Device", items=DEVICES, default="auto",
                         description="Where the engine runs torch work")
    preview_cap: IntProperty(
        name="Preview Point Cap", default=200_000, min=1_000, max=20_000_000,
        description="Most points in a capture or splat preview (a deterministic random subset)")

    def draw(self, context: bpy.types.Context) -> None:
        layout = self.layout
        col = layout.column()
        row = col.row(align=True)
        row.prop(self, "engine_python")
        row.operator("artgs.check_engine", icon="CHECKMARK")
        if not self.engine_python:
            col.label(text=f"Using: {engine_python(context)}", icon="INFO")
        for line in last_check:
            col.label(text=line)
        self._draw_setup(layout.box())
        col.separator()
        col.prop(self, "device")
        col.prop(self, "preview_cap")
        box = layout.box()
        box.label(text="Vision-language model (proposal method 'VLM')")
        box.prop(self, "vlm_endpoint")
        box.prop(self, "vlm_model")
        box.prop(self, "vlm_api_key")
        if not bpy.app.online_access:
            box.label(text="Online access is off: enable Preferences > System > Network > "
                           "Allow Online Access to use the VLM", icon="ERROR")


    def _draw_setup(self, box: bpy.types.UILayout) -> None:
        state = engine_setup.load_state(user_folder())
        row = box.row()
        row.label(text="Set up the engine in the add-on's own folder")
        row.operator("artgs.setup_engine", icon="CONSOLE")
        box.prop(self, "setup_torch", expand=True)
        box.prop(self, "setup_python")
        box.prop(self, "setup_wheels")
        if state.status != "NONE":
            icon = {"READY": "CHECKMARK", "FAILED": "ERROR"}.get(state.status, "INFO")
            box.label(text=f"Last set-up: {state.status.lower()}: {state.message}", icon=icon)
        note = state.version_note()
        if note:
            box.label(text=note, icon="ERROR")
        if not bpy.app.online_access and not self.setup_wheels:
            box.label(text="Online access is off: Set Up Engine needs Preferences > System > "
                           "Network > Allow Online Access, or a wheel folder", icon="ERROR")


def _defaults() -> SimpleNamespace:
    return SimpleNamespace(**{name: prop.keywords.get("default", "")
                              for name, prop in ArtgsPreferences.__annotations__.items()})


CLASSES = (ArtgsPreferences,)
