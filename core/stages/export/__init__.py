"""``artgs export``: part meshes, collision pieces and the URDF from the splat."""
