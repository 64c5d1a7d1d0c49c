"""Blender glue: everything that touches bpy."""
