"""The ArtGS engine. Never imports bpy.

Modules that the Blender process uses (capture reading, joints, PLY, parts) depend on numpy only;
torch is imported only by the stages that run in the worker process.
"""
