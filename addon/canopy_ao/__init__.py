bl_info = {"name": "Canopy AO", "blender": (3, 4, 0), "category": "Render", "version": (0, 1, 0)}
