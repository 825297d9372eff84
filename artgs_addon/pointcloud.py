"""Coloured point-cloud preview objects, built with ``foreach_set`` (no per-point Python loops).

A preview is a mesh of loose vertices with a ``Col`` colour attribute (linear RGBA) and a
``radius`` attribute, displayed (and rendered) as points by a geometry-nodes modifier
("Mesh to Points" with the radius attribute, then a material reading ``Col``).
"""

from __future__ import annotations

import bpy
import numpy as np

COLOR_ATTRIBUTE = "Col"
RADIUS_ATTRIBUTE = "radius"
_NODE_GROUP = "ArtGS Point Preview"
_MATERIAL = "ArtGS Point Colour"
_MODIFIER = "ArtGS Points"


def srgb_to_linear(c: np.ndarray) -> np.ndarray:
    """sRGB-encoded colours in 0..1 -> scene-linear (Blender colour attributes are linear)."""
    c = np.clip(c, 0.0, 1.0)
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def point_cloud_object(name: str, points: np.ndarray, colors: np.ndarray, radius: np.ndarray,
                       collection: bpy.types.Collection,
                       extra: dict[str, np.ndarray] | None = None) -> bpy.types.Object:
    """A new object ``name`` in ``collection``: points (N,3) metres, sRGB colours (N,3) in 0..1,
    per-point radius (N,) metres, and optional extra float point attributes."""
    n = len(points)
    mesh = bpy.data.meshes.new(name)
    mesh.vertices.add(n)
    mesh.vertices.foreach_set("co", np.ascontiguousarray(points, np.float32).ravel())
    rgba = np.ones((n, 4), np.float32)
    rgba[:, :3] = srgb_to_linear(np.asarray(colors, np.float32))
    col = mesh.color_attributes.new(COLOR_ATTRIBUTE, "FLOAT_COLOR", "POINT")
    col.data.foreach_set("color", rgba.ravel())
    mesh.color_attributes.active_color = col
    attrs = {RADIUS_ATTRIBUTE: radius, **(extra or {})}
    for key, values in attrs.items():
        attr = mesh.attributes.new(key, "FLOAT", "POINT")
        attr.data.foreach_set("value", np.ascontiguousarray(values, np.float32).ravel())
    mesh.update()
    obj = bpy.data.objects.new(name, mesh)
    collection.objects.link(obj)
    modifier = obj.modifiers.new(_MODIFIER, "NODES")
    modifier.node_group = _point_node_group()
    obj.data.materials.append(_point_material())
    return obj


def points_modifier_last(obj: bpy.types.Object) -> None:
    """Move the points modifier to the end of the stack (deforming modifiers, such as an
    Armature modifier added later, must act on the mesh before it becomes points)."""
    index = obj.modifiers.find(_MODIFIER)
    if index >= 0:
        obj.modifiers.move(index, len(obj.modifiers) - 1)


def _point_node_group() -> bpy.types.NodeTree:
    """Mesh vertices -> points with the ``radius`` attribute, coloured by the point material."""
    group = bpy.data.node_groups.get(_NODE_GROUP)
    if group is not None:
        return group
    group = bpy.data.node_groups.new(_NODE_GROUP, "GeometryNodeTree")
    group.interface.new_socket("Geometry", in_out="INPUT", socket_type="NodeSocketGeometry")
    group.interface.new_socket("Geometry", in_out="OUTPUT", socket_type="NodeSocketGeometry")
    nodes, links = group.nodes, group.links
    gin = nodes.new("NodeGroupInput")
    gout = nodes.new("NodeGroupOutput")
    radius = nodes.new("GeometryNodeInputNamedAttribute")
    radius.data_type = "FLOAT"
    radius.inputs["Name"].default_value = RADIUS_ATTRIBUTE
    to_points = nodes.new("GeometryNodeMeshToPoints")
    set_mat = nodes.new("GeometryNodeSetMaterial")
    set_mat.inputs["Material"].default_value = _point_material()
    links.new(gin.outputs[0], to_points.inputs["Mesh"])
    links.new(radius.outputs["Attribute"], to_points.inputs["Radius"])
    links.new(to_points.outputs["Points"], set_mat.inputs["Geometry"])
    links.new(set_mat.outputs["Geometry"], gout.inputs[0])
    for i, node in enumerate((gin, radius, to_points, set_mat, gout)):
        node.location = (200 * i, 0)
    return group


def _point_material() -> bpy.types.Material:
    """Emission-like material showing the ``Col`` attribute (the capture's colours, unlit)."""
    mat = bpy.data.materials.get(_MATERIAL)
    if mat is not None:
        return mat
    mat = bpy.data.materials.new(_MATERIAL)
    if mat.node_tree is None:  # Blender 4.x; 5.x materials always have nodes (use_nodes goes in 6.0)
        mat.use_nodes = True
    nodes, links = mat.node_tree.nodes, mat.node_tree.links
    nodes.clear()
    attr = nodes.new("ShaderNodeAttribute")
    attr.attribute_name = COLOR_ATTRIBUTE
    emit = nodes.new("ShaderNodeEmission")
    out = nodes.new("ShaderNodeOutputMaterial")
    links.new(attr.outputs["Color"], emit.inputs["Color"])
    links.new(emit.outputs["Emission"], out.inputs["Surface"])
    attr.location, emit.location, out.location = (-400, 0), (-150, 0), (100, 0)
    mat.diffuse_color = (0.8, 0.8, 0.8, 1.0)
    return mat
