"""Brings a carried library's C++ runtime needs down to the portable zip's baseline
(docs/PORTABILITY.md, 'C++ runtime'). Called by scripts/build_portable.sh.
    python3 scripts/portable_cxx.py LIB COMPAT_LIB BASELINE...   (e.g. GLIBCXX_3.4.28 CXXABI_1.3.12)

Every symbol LIB imports from libstdc++ under a version newer than the baseline of its family
must be defined by COMPAT_LIB (native/portable/cxx_compat.cpp); its version requirement is
dropped (.gnu.version entry 1: bound by name, to the first definition in scope, the system's
libstdc++ or COMPAT_LIB), and each such version LIB no longer uses is marked weak in
.gnu.version_r (VER_FLG_WEAK: the dynamic linker does not refuse a libstdc++ without it). LIB
is rewritten in place; prints one line per symbol let go, and exits 1 naming any symbol newer
than the baseline that COMPAT_LIB does not define (nothing is written then).
ELF64 little-endian only (x86-64)."""
import struct
import sys

SHT_DYNSYM, SHT_VERNEED, SHT_VERSYM = 11, 0x6FFFFFFE, 0x6FFFFFFF
VER_NDX_GLOBAL, VER_FLG_WEAK = 1, 0x2


class Elf:
    def __init__(self, path):
        self.path = path
        self.data = bytearray(open(path, "rb").read())
        d = self.data
        if d[:4] != b"\x7fELF" or d[4] != 2 or d[5] != 1:
            sys.exit(f"portable_cxx.py: {path} is not a little-endian ELF64 file")
        shoff, = struct.unpack_from("<Q", d, 0x28)
        shentsize, shnum = struct.unpack_from("<HH", d, 0x3A)
        self.sections = []
        for i in range(shnum):
            name, typ, _flags, _addr, off, size, link, _info, _align, entsize = \
                struct.unpack_from("<IIQQQQIIQQ", d, shoff + i * shentsize)
            self.sections.append((typ, off, size, link, entsize))

    def section(self, typ):
        found = [s for s in self.sections if s[0] == typ]
        return found[0] if found else None

    def string(self, strtab, offset):
        start = self.sections[strtab][1] + offset
        return self.data[start:self.data.index(b"\0", start)].decode()

    def symbols(self):
        """(index, name, defined) of every .dynsym entry."""
        typ, off, size, link, entsize = self.section(SHT_DYNSYM)
        for i in range(size // entsize):
            st_name, _info, _other, shndx = struct.unpack_from("<IBBH", self.data, off + i * entsize)
            yield i, self.string(link, st_name), shndx != 0

    def needed_versions(self):
        """{version index: (file, version name, offset of the Vernaux entry)}"""
        sec = self.section(SHT_VERNEED)
        if sec is None:
            return {}
        _typ, off, _size, link, _entsize = sec
        out, vn = {}, off
        while True:
            _ver, cnt, file, aux, nxt = struct.unpack_from("<HHIII", self.data, vn)
            a = vn + aux
            for _ in range(cnt):
                _hash, _flags, other, name, anext = struct.unpack_from("<IHHII", self.data, a)
                out[other] = (self.string(link, file), self.string(link, name), a)
                a += anext
            if not nxt:
                return out
            vn += nxt


def newer(version, baseline):
    family, _, number = version.partition("_")
    if family not in baseline:
        return False
    as_tuple = lambda v: tuple(int(x) for x in v.split("."))  # noqa: E731
    return as_tuple(number) > as_tuple(baseline[family])


def main(lib_path, compat_path, *baselines):
    baseline = dict(b.partition("_")[::2] for b in baselines)
    lib, compat = Elf(lib_path), Elf(compat_path)
    provided = {name for _, name, defined in compat.symbols() if defined}
    versions = lib.needed_versions()
    too_new = {ndx for ndx, (file, name, _) in versions.items()
               if file.startswith("libstdc++.so") and newer(name, baseline)}
    if not too_new:
        return 0
    _typ, versym, _size, _link, _entsize = lib.section(SHT_VERSYM)
    let_go, missing = [], []
    for i, name, defined in lib.symbols():
        ndx, = struct.unpack_from("<H", lib.data, versym + 2 * i)
        if ndx & 0x7FFF not in too_new:
            continue
        if defined or name not in provided:
            missing.append(f"{name}@{versions[ndx & 0x7FFF][1]}")
            continue
        struct.pack_into("<H", lib.data, versym + 2 * i, VER_NDX_GLOBAL)
        let_go.append(f"{name} ({versions[ndx & 0x7FFF][1]}): version dropped (binds to the"
                      f" system's libstdc++ or {compat_path.rsplit('/', 1)[-1]})")
    if missing:
        sys.exit(f"portable_cxx.py: {lib_path} needs {', '.join(missing)}, newer than the baseline"
                 f" ({' '.join(baselines)}) and not defined in native/portable/cxx_compat.cpp")
    for ndx in too_new:
        flags_at = versions[ndx][2] + 4
        flags, = struct.unpack_from("<H", lib.data, flags_at)
        struct.pack_into("<H", lib.data, flags_at, flags | VER_FLG_WEAK)
    open(lib_path, "wb").write(lib.data)
    for line in let_go:
        print(line)
    return 0


if __name__ == "__main__":
    if len(sys.argv) < 4:
        sys.exit(__doc__)
    sys.exit(main(*sys.argv[1:]))
