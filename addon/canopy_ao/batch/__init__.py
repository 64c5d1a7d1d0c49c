"""Batch bakes of many .blend files (``python3 -m canopy_ao.batch``), locally or on Slurm.

    plan      what to bake, where results go, resume, task command lines, summary (pure Python)
    runner    one task: a Blender process over a group of files, one retry per failed file
    worker    the Blender side of a task (runs inside blender -b)
    __main__  the command line and the local and Slurm back ends

Importing this package imports neither bpy nor the native core.
"""
