"""What the foliage tests share (test_mesh_parts, test_card_proxies, test_scattered_cards): a
bake through the CLI's entry, its JSON report, and an object's baked AO per vertex."""

import json

import bpy
import numpy as np
import pytest


def cli_bake(tmp_path, capsys, *args):
    """canopy_ao.cli.main(--overwrite --report ... *args), which must exit 0: its report."""
    from canopy_ao import cli
    report = tmp_path / "r.json"
    with pytest.raises(SystemExit) as exc:
        cli.main(["--overwrite", "--report", str(report), *args])
    assert exc.value.code == 0, capsys.readouterr().err
    return json.loads(report.read_text())


def baked_ao(name):
    """float32 (V,): the AO attribute's first channel on object ``name``'s vertices."""
    a = bpy.data.objects[name].data.attributes[bpy.context.scene.canopy_ao.attribute]
    v = np.empty(len(a.data) * 4, np.float32)
    a.data.foreach_get("color", v)
    return v[0::4]
