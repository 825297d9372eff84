"""Add-on preferences: the engine interpreter, the VLM endpoint (key kept out of .blend files),
the compute device and the preview point cap."""

import sys
from pathlib import Path
from types import SimpleNamespace

import bpy
from bpy.props import EnumProperty, IntProperty, StringProperty

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


def get(context: bpy.types.Context | None = None):
    """The add-on's preferences; their defaults when the package was registered without
    ``addon_utils`` (e.g. ``import artgs; artgs.register()`` with bpy as a module)."""
    addon = (context or bpy.context).preferences.addons.get(ADDON_ID)
    return addon.preferences if addon is not None else _defaults()


def engine_python(context: bpy.types.Context | None = None) -> str:
    """The interpreter that runs the engine (the preference, or the default when empty)."""
    return bpy.path.abspath(get(context).engine_python) or default_engine()


def preview_cap(context: bpy.types.Context) -> int:
    """Points allowed in a preview: the preference's cap times the scene's density."""
    return max(1, int(get(context).preview_cap * context.scene.artgs.preview_density))


#: Outcome of the last "Check Engine" (kept in memory only, shown in the preferences).
last_check: list[str] = []


class ArtgsPreferences(bpy.types.AddonPreferences):
    bl_idname = ADDON_ID

    engine_python: StringProperty(
        name="Engine Python", subtype="FILE_PATH",
        description="Python interpreter of the environment where the ArtGS engine (torch, numba, "
                    "...) is installed; empty: " + "the .venv beside the add-on, else Blender's own")
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
            col.label(text=f"Using: {default_engine()}", icon="INFO")
        for line in last_check:
            col.label(text=line)
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


def _defaults() -> SimpleNamespace:
    return SimpleNamespace(**{name: prop.keywords.get("default", "")
                              for name, prop in ArtgsPreferences.__annotations__.items()})


CLASSES = (ArtgsPreferences,)
