"""Deterministic zip archives: the entry writer of the SSP export and of the ScenarioSignals
FMU with its table (the same inputs give the same bytes)."""

from __future__ import annotations

import zipfile

ZIP_DATE = (1980, 1, 1, 0, 0, 0)
"""The timestamp of every entry written here."""


def add_entry(zf: zipfile.ZipFile, name: str, data: bytes, compress: int) -> None:
    """Add ``data`` as ``name`` with fixed metadata (1980-01-01, unix, 0644)."""
    info = zipfile.ZipInfo(name, date_time=ZIP_DATE)
    info.compress_type = compress
    info.create_system = 3  # unix, whatever the host
    info.external_attr = 0o644 << 16
    zf.writestr(info, data)
