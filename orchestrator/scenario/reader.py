"""The scenario file's reader: typed TOML tables whose errors are :class:`ScenarioError`.

Every error names the file, the dotted field and what is expected; the generic parts are
``plant.common.toml_reader``'s, shared with the airframe files.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from itertools import pairwise

from plant.common.toml_reader import FieldError, TomlTable


class ScenarioError(FieldError):
    """A scenario file (or a setting given on top of it) is missing, unreadable or invalid."""


def is_number(value: object) -> bool:
    """Whether value is an int or float (not a bool)."""
    return isinstance(value, (int, float)) and not isinstance(value, bool)


class FieldReader(TomlTable):
    """Typed access to one TOML table; every error names the file and the dotted field."""

    error = ScenarioError

    def table(self, key: str) -> FieldReader | None:
        """A sub-table, or None when absent."""
        self.used.add(key)
        if key not in self.data:
            return None
        value = self.data[key]
        if not isinstance(value, dict):
            raise self.fail(key, f"expected a table, got {value!r}")
        return FieldReader(self.source, value, f"{self.field(key)}.")

    def integer(self, key: str) -> int:
        """The integer at key; an error naming the field when missing or not an integer."""
        self.used.add(key)
        value = self.data.get(key)
        if key not in self.data:
            raise self.fail(key, "missing (expected an integer)")
        if not isinstance(value, int) or isinstance(value, bool):
            raise self.fail(key, f"expected an integer, got {value!r}")
        return value

    def numbers(self, key: str, *, increasing: bool = False) -> tuple[float, ...]:
        """The non-empty array of numbers at key (strictly increasing with increasing)."""
        self.used.add(key)
        if key not in self.data:
            raise self.fail(key, "missing (expected an array of numbers)")
        value = self.data[key]
        if not isinstance(value, list) or not value or not all(is_number(v) for v in value):
            raise self.fail(key, f"expected a non-empty array of numbers, got {value!r}")
        out = tuple(float(v) for v in value)
        if not all(math.isfinite(v) for v in out):
            raise self.fail(key, "expected finite numbers")
        if increasing and any(b <= a for a, b in pairwise(out)):
            raise self.fail(key, f"expected strictly increasing times, got {list(out)}")
        return out

    def reject_unknown(self, hint: Callable[[str], str] | None = None) -> None:
        """An error for the first key the reader was never asked for."""
        for key in self.data:
            if key not in self.used:
                extra = hint(key) if hint is not None else ""
                raise self.fail(key, f"unknown field{extra}")
