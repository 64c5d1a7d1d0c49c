"""The bake's math and data, in numpy and the native core; imports no bpy."""
