"""Export URDF and Check Manipulation (engine ``artgs export`` / ``artgs check``), Import URDF
(any URDF as meshes on a joint armature) and Write Edited URDF (its joints as edited)."""

from __future__ import annotations

from pathlib import Path

import bpy
from bpy.props import EnumProperty, IntProperty, StringProperty
from bpy_extras.io_utils import ExportHelper, ImportHelper

from ..artgs_addon.armature import find_armature
from ..artgs_addon.crop_box import add_crop_box
from ..artgs_addon.urdf_import import URDF_KEY, import_urdf, write_edited_urdf
from ..artgs_addon.worker import WorkerResult
from ..core.model import layout
from ..core.model.errors import ArtgsError
from ..core.model.registry import ROBOTS
from ._job import WorkerOperator, job_running

STRIP_IMAGE = "ArtGS Check Frames"


def _output_ready(context: bpy.types.Context) -> bool:
    settings = getattr(context.scene, "artgs", None)
    return (settings is not None and not job_running() and settings.output_path is not None
            and (settings.output_path / layout.SPLAT).is_file()
            and layout.joints_file(settings.output_path).is_file())


class ARTGS_OT_export_urdf(WorkerOperator, bpy.types.Operator):
    """Write part meshes, collision pieces and model.urdf from the splat and the joints, and
    validate them (yourdfpy FK, PyBullet sweep, MuJoCo); runs in the engine"""

    bl_idname = "artgs.export_urdf"
    bl_label = "Export URDF"
    bl_options = {"REGISTER"}
    stage = "export"
    command = "export"

    face_budget: IntProperty(name="Face Budget", default=5000, min=100,
                             description="Most faces of a link's visual mesh")

    @classmethod
    def poll(cls, context: bpy.types.Context) -> bool:
        return _output_ready(context)

    def worker_args(self, context: bpy.types.Context) -> list[str]:
        settings = context.scene.artgs
        args = [str(settings.output_path), "--face-budget", str(self.face_budget)]
        if settings.capture_path is not None and (settings.capture_path / "transforms.json").is_file():
            args += ["--capture", str(settings.capture_path)]
        return args

    def finish(self, context: bpy.types.Context, result: WorkerResult) -> str:
        report = layout.read_report(context.scene.artgs.output_path)
        entry = report.get("stages", {}).get("export", {})
        links = entry.get("links", {})
        valid = "valid" if entry.get("valid") else "VALIDATION FAILED (see report.json)"
        return f"{len(links)} links, {valid}: {context.scene.artgs.output_path / layout.URDF}"


class ARTGS_OT_check_manipulation(WorkerOperator, bpy.types.Operator):
    """A robot opens every part of model.urdf in PyBullet along the estimated joints (engine);
    the frames are shown in the Export panel"""

    bl_idname = "artgs.check_manipulation"
    bl_label = "Check Manipulation"
    bl_options = {"REGISTER"}
    stage = "check"
    command = "check"

    robot: EnumProperty(name="Robot", items=[(r, r, f"{r} from pybullet_data") for r in ROBOTS])

    @classmethod
    def poll(cls, context: bpy.types.Context) -> bool:
        return _output_ready(context) and (context.scene.artgs.output_path / layout.URDF).is_file()

    def worker_args(self, context: bpy.types.Context) -> list[str]:
        return [str(context.scene.artgs.output_path), "--robot", self.robot]

    def finish(self, context: bpy.types.Context, result: WorkerResult) -> str:
        out = context.scene.artgs.output_path
        load_strip(out / layout.CHECK_STRIP)
        entry = layout.read_report(out).get("stages", {}).get("check", {})
        joints = entry.get("joints", {})
        wins = [n for n, r in joints.items() if r.get("success")]
        return f"opened {len(wins)}/{len(joints)} parts ({entry.get('robot', self.robot)})"


def load_strip(path: Path) -> bpy.types.Image | None:
    """The check's PNG strip as the image ``STRIP_IMAGE`` (reloaded), or None if absent."""
    if not path.is_file():
        return None
    image = bpy.data.images.get(STRIP_IMAGE)
    if image is None or Path(bpy.path.abspath(image.filepath)) != path:
        if image is not None:
            bpy.data.images.remove(image)
        image = bpy.data.images.load(str(path))
        image.name = STRIP_IMAGE
    else:
        image.reload()
    return image


class ARTGS_OT_show_check_frames(bpy.types.Operator):
    """Open the manipulation check's frames in an Image Editor window"""

    bl_idname = "artgs.show_check_frames"
    bl_label = "Show Check Frames"

    @classmethod
    def poll(cls, context: bpy.types.Context) -> bool:
        out = getattr(context.scene, "artgs", None) and context.scene.artgs.output_path
        return bool(out) and (out / layout.CHECK_STRIP).is_file()

    def execute(self, context: bpy.types.Context) -> set[str]:
        image = load_strip(context.scene.artgs.output_path / layout.CHECK_STRIP)
        if bpy.app.background or context.window is None:
            return {"FINISHED"}
        bpy.ops.wm.window_new()
        area = bpy.context.window_manager.windows[-1].screen.areas[0]
        area.type = "IMAGE_EDITOR"
        area.spaces.active.image = image
        return {"FINISHED"}


class ARTGS_OT_add_crop_box(bpy.types.Operator):
    """Add (or select) the crop box: an Empty shown as a cube; place and scale it around the
    object (closed). Every stage keeps only what lies inside (written to OUT/crop.json when a
    stage runs); starts from OUT's crop.json when there is one (the separation's)"""

    bl_idname = "artgs.add_crop_box"
    bl_label = "Add Crop Box"
    bl_options = {"REGISTER", "UNDO"}

    @classmethod
    def poll(cls, context: bpy.types.Context) -> bool:
        return getattr(context.scene, "artgs", None) is not None

    def execute(self, context: bpy.types.Context) -> set[str]:
        obj = add_crop_box(context)
        self.report({"INFO"}, f"'{obj.name}': place and scale it around the object")
        return {"FINISHED"}


class ARTGS_OT_import_urdf(bpy.types.Operator, ImportHelper):
    """Import a URDF (ours, PyBullet's examples, PartNet-Mobility's mobility.urdf) as part meshes
    parented to an editable joint armature"""

    bl_idname = "artgs.import_urdf"
    bl_label = "Import URDF"
    bl_options = {"REGISTER", "UNDO"}
    filename_ext = ".urdf"
    filter_glob: StringProperty(default="*.urdf", options={"HIDDEN"})

    def execute(self, context: bpy.types.Context) -> set[str]:
        try:
            arm, made, skipped = import_urdf(context, self.filepath)
        except (ArtgsError, OSError, ValueError) as exc:
            self.report({"ERROR"}, str(exc))
            return {"CANCELLED"}
        extra = f", {skipped} visuals skipped (format not importable)" if skipped else ""
        self.report({"INFO"}, f"'{arm.name}': {len(arm.data.bones)} joints, {made} meshes{extra}")
        return {"FINISHED"}


class ARTGS_OT_write_edited_urdf(bpy.types.Operator, ExportHelper):
    """Write a copy of the imported URDF with the joints as edited on its armature (meshes stay
    where they are; a moved joint origin moves its link frame, not the geometry)"""

    bl_idname = "artgs.write_edited_urdf"
    bl_label = "Write Edited URDF"
    filename_ext = ".urdf"
    filter_glob: StringProperty(default="*.urdf", options={"HIDDEN"})

    @classmethod
    def poll(cls, context: bpy.types.Context) -> bool:
        arm = find_armature(context)
        return arm is not None and URDF_KEY in arm

    def execute(self, context: bpy.types.Context) -> set[str]:
        try:
            path = write_edited_urdf(find_armature(context), self.filepath)
        except (ArtgsError, OSError, ValueError) as exc:
            self.report({"ERROR"}, str(exc))
            return {"CANCELLED"}
        self.report({"INFO"}, f"wrote {path}")
        return {"FINISHED"}


CLASSES = (ARTGS_OT_export_urdf, ARTGS_OT_check_manipulation, ARTGS_OT_show_check_frames,
           ARTGS_OT_add_crop_box, ARTGS_OT_import_urdf, ARTGS_OT_write_edited_urdf)
