"""Everything or nothing: a bake's writes go through a Transaction, which records how to undo
each one; a failure part-way undoes them all, in reverse (docs/DESIGN.md, 'Data flow')."""

import sys
import traceback

from . import ownership


class Transaction:
    def __init__(self):
        self._undo = []

    def add(self, undo):
        """Record undo() for a write just made (or about to be)."""
        self._undo.append(undo)

    def attribute(self, obj, name, last=False):
        """Record obj's attribute ``name`` (or its absence) and its mesh's ownership records,
        before a write replaces them. last: nothing that can fail follows this write, and a
        FLOAT_COLOR POINT attribute is overwritten in place (whole, or not at all), so its old
        values are never needed again: they are not copied (16 bytes a vertex)."""
        mesh = obj.data
        marks = [(key, mesh.get(key))
                 for key in (ownership.OWNED_PROP, ownership.LEGACY_OWNED_PROP)]
        attr = mesh.attributes.get(name)
        old = None
        in_place = (last and attr is not None and attr.data_type == 'FLOAT_COLOR'
                    and attr.domain == 'POINT')
        if in_place:
            old = "in place"
        elif attr is not None and attr.data_type in ownership.LAYOUT:
            old = (attr.data_type, attr.domain, ownership.LAYOUT[attr.data_type][0],
                   ownership.read_attribute(attr))

        def undo():
            cur = mesh.attributes.get(name)
            if old is None:
                if cur is not None:
                    mesh.attributes.remove(cur)
            elif old == "in place":
                pass  # its values were not overwritten: the write failed before it wrote
            else:
                kind, domain, key, buf = old
                if cur is None or cur.data_type != kind or cur.domain != domain:
                    if cur is not None:
                        mesh.attributes.remove(cur)
                    cur = mesh.attributes.new(name, kind, domain)
                cur.data.foreach_set(key, buf)
            for key, raw in marks:
                if raw is None:
                    mesh.pop(key, None)
                else:
                    mesh[key] = raw
            mesh.update_tag()
        self.add(undo)

    def rollback(self):
        """Undo every recorded write, newest first; an undo that fails is printed and the
        others still run."""
        for undo in reversed(self._undo):
            try:
                undo()
            except Exception:  # noqa: BLE001 - the rest must still be undone
                print("Canopy AO: could not undo a write:", file=sys.stderr)
                traceback.print_exc()
        self._undo.clear()

    def done(self):
        """The writes stand: drop their undos (and the old file bytes they hold)."""
        self._undo.clear()
