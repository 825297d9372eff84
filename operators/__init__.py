"""Blender operators of the add-on (imported only by register())."""
