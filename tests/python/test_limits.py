"""The add-on's copy of the native module's accepted input range (core/native.py LIMITS, with
which options and meshes are refused by name before any call) is the module's own."""
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "addon"))

from canopy_ao import core  # noqa: E402
from canopy_ao.core import native  # noqa: E402

assert core.core_status()[0], core.core_status()[1]  # an unbuilt module fails, not skips


def test_the_limits_are_the_native_modules():
    assert native.LIMITS == dict(native.require().LIMITS)
