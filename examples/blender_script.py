"""The entry every headless Blender script in this repository shares.

`blender -b --python script.py -- args` exits 0 even when the script raised, so a pipeline
could not tell a failure from a success. `run(main, name)` hands `main` the arguments after
`--`, prints a failure as `name: error: message` on stderr (with the traceback), and then ends
Blender with a non-zero exit code; on success Blender quits as usual.
"""
import os
import sys
import traceback


def script_args():
    """The command-line arguments after `--` (Blender's own come before it)."""
    return sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else []


def run(main, name):
    try:
        rc = main(script_args())
    except SystemExit as e:  # argparse errors and explicit exits keep their code
        rc = e.code if isinstance(e.code, int) else 1
    except Exception as e:
        traceback.print_exc()
        print(f"{name}: error: {e}", file=sys.stderr)
        rc = 1
    sys.stdout.flush()
    sys.stderr.flush()
    if rc:
        os._exit(rc)
