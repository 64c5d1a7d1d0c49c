"""Run pytest inside Blender and make Blender exit with pytest's code.

    blender -b --factory-startup --python tests/blender/run_pytest.py -- tests/blender -q

Blender ignores an exception in a --python script (exit code 0), so the code is passed to
os._exit after flushing: nothing Blender does on shutdown can turn a failure into a success.
"""

import os
import sys

args = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else ["tests/blender"]
code = 1
try:
    import pytest

    # Blender's own warnings about its internals are not ours to fail on.
    code = int(pytest.main(["-p", "no:cacheprovider", *args]))
except BaseException:  # noqa: BLE001 - any failure to run the tests is a failure
    import traceback

    traceback.print_exc()
    code = 1
finally:
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(code)
