"""The co-simulation step kernel (temporary shim until the library split lands)."""

from __future__ import annotations

import ctypes


def cosim() -> ctypes.CDLL:
    from plant._native import core

    return core()
