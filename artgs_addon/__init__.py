"""Blender glue: preferences, properties, building and reading Blender objects, the worker client.

Registration lives in the package root (``artgs/__init__.py``); nothing here imports the
operators or panels.
"""
