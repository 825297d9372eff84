"""Blender panels of the add-on (imported only by register())."""
