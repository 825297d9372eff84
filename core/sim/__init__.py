"""Simulation: URDF writing (``urdf``) and the PyBullet scene client (``client``); may import model and
geometry, never stages."""
