"""A universal ("fat") Mach-O file from thin 64-bit slices, as Apple's ``lipo -create`` makes
it (Zig compiles one architecture at a time and has no ``lipo``).

The layout (``<mach-o/fat.h>``): a big-endian header ``FAT_MAGIC, nfat_arch``, then per slice
``cputype, cpusubtype, offset, size, align`` (uint32 each, ``align`` a power of two), then the
slices, each starting at a multiple of ``2**align``.  The bytes depend only on the slices.
"""

from __future__ import annotations

import struct
from collections.abc import Sequence

FAT_MAGIC = 0xCAFEBABE
MH_MAGIC_64 = 0xFEEDFACF  # a thin 64-bit Mach-O, read little-endian (x86_64 and arm64)
SLICE_ALIGN = 14  # 16 KiB: the page size of arm64 macOS, a multiple of x86_64's 4 KiB


def thin_cpu(data: bytes) -> tuple[int, int]:
    """(cputype, cpusubtype) of a thin little-endian 64-bit Mach-O, or ValueError."""
    if len(data) < 32 or struct.unpack_from("<I", data, 0)[0] != MH_MAGIC_64:
        raise ValueError("not a thin 64-bit little-endian Mach-O file")
    cputype, cpusubtype = struct.unpack_from("<iI", data, 4)
    return int(cputype), int(cpusubtype)


def universal_binary(slices: Sequence[bytes]) -> bytes:
    """The universal file holding ``slices`` (thin Mach-O files of distinct CPU types)."""
    if not slices:
        raise ValueError("a universal binary needs at least one slice")
    cpus = [thin_cpu(s) for s in slices]
    if len({c for c, _ in cpus}) != len(cpus):
        raise ValueError("two slices of the same CPU type")
    align = 1 << SLICE_ALIGN
    header = struct.pack(">II", FAT_MAGIC, len(slices))
    offset = align
    arches = b""
    body = b""
    for i, (data, (cputype, cpusubtype)) in enumerate(zip(slices, cpus, strict=True)):
        arches += struct.pack(">iIIII", cputype, cpusubtype, offset, len(data), SLICE_ALIGN)
        pad = (-len(data)) % align if i + 1 < len(slices) else 0  # the next slice's start
        body += data + b"\0" * pad
        offset += len(data) + pad
    head = header + arches
    return head + b"\0" * (align - len(head)) + body
