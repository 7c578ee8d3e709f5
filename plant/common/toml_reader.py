"""A validating TOML reader: typed access to tables whose errors name file and field.

The base of the airframe files' reader (``plant.airframe``) and the scenario files'
(``orchestrator.scenario.reader``).

Every error names the file, the dotted field and what is expected.
"""

from __future__ import annotations

import math
import sys
from collections.abc import Sequence
from importlib import resources
from pathlib import Path
from typing import Any, ClassVar

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib


class FieldError(ValueError):
    """A file's field is missing or invalid: ``source: field 'a.b': reason``."""

    def __init__(self, source: str, field: str, reason: str) -> None:
        self.source = source
        self.field = field
        self.reason = reason
        where = f"field '{field}': " if field else ""
        super().__init__(f"{source}: {where}{reason}")


class TomlTable:
    """Typed access to one TOML table; subclasses choose the error type and add readers."""

    error: ClassVar[type[FieldError]] = FieldError

    def __init__(self, source: str, data: dict[str, Any], prefix: str = "") -> None:
        self.source = source
        self.data = data
        self.prefix = prefix
        self.used: set[str] = set()

    def field(self, key: str) -> str:
        """The field's full name in messages (with its table prefix)."""
        return f"{self.prefix}{key}"

    def fail(self, key: str, reason: str) -> FieldError:
        """The error for key: the file, the field and reason."""
        return self.error(self.source, self.field(key), reason)

    def has(self, key: str) -> bool:
        """Whether the table has key."""
        return key in self.data

    def raw(self, key: str) -> Any:
        """The value at key as it is (None when missing)."""
        self.used.add(key)
        return self.data.get(key)

    def number(self, key: str, default: float | None = None, *, positive: bool = False,
               nonnegative: bool = False) -> float:
        """The number at key (default when missing), checked positive or non-negative on request."""
        self.used.add(key)
        if key not in self.data:
            if default is None:
                raise self.fail(key, "missing (expected a number)")
            return default
        value = self.data[key]
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise self.fail(key, f"expected a number, got {value!r}")
        x = float(value)
        if not math.isfinite(x):
            raise self.fail(key, f"expected a finite number, got {value!r}")
        if positive and not x > 0:
            raise self.fail(key, f"expected a positive number, got {value!r}")
        if nonnegative and x < 0:
            raise self.fail(key, f"expected a number >= 0, got {value!r}")
        return x

    def string(self, key: str, default: str | None = None,
               choices: Sequence[str] | None = None) -> str:
        """The string at key (default when missing)."""
        self.used.add(key)
        if key not in self.data:
            if default is None:
                raise self.fail(key, "missing (expected a string)")
            return default
        value = self.data[key]
        if not isinstance(value, str):
            raise self.fail(key, f"expected a string, got {value!r}")
        if choices is not None and value not in choices:
            raise self.fail(key, f"expected one of {', '.join(repr(c) for c in choices)}, "
                            f"got {value!r}")
        return value


def shipped_names(package: str, folder: str) -> list[str]:
    """Names (without ``.toml``) of the files shipped in a package's data folder."""
    root = resources.files(package) / folder
    return sorted(p.name[:-5] for p in root.iterdir() if p.name.endswith(".toml"))


def resolve_file(name_or_path: str | Path, package: str, folder: str, what: str,
                 error: type[FieldError] = FieldError) -> Path:
    """A TOML file given as a path, or by the name of a shipped one; ``error`` when neither."""
    path = Path(name_or_path)
    if path.suffix == ".toml" or path.exists():
        return path
    shipped = resources.files(package) / folder / f"{name_or_path}.toml"
    if shipped.is_file():
        return Path(str(shipped))
    raise error(str(name_or_path), "", f"no such file or shipped {what} (shipped: "
                f"{', '.join(shipped_names(package, folder))})")


MAX_DEPTH = 32
"""Tables and arrays nest at most this deep in a file (the deepest shipped field, a sum of
signals' values, is 6 levels down)."""


class Overflowed(float):
    """A TOML float beyond a double's range (``1e400``): infinite, but shown in messages
    as the file spells it, not as ``inf``."""

    text: str

    def __new__(cls, text: str) -> Overflowed:
        """The float of ``text`` (infinite), keeping ``text``."""
        obj = super().__new__(cls, float(text))
        obj.text = text
        return obj

    def __repr__(self) -> str:
        """The number as the file spells it."""
        return self.text

    __str__ = __repr__


def _parse_float(text: str) -> float:
    x = float(text)
    if math.isinf(x) and "inf" not in text:
        return Overflowed(text)
    return x


class NestingError(ValueError):
    """A TOML document nested deeper than :data:`MAX_DEPTH`; ``field`` is the dotted path
    where it does ("" when the parser itself could not follow)."""

    def __init__(self, field: str) -> None:
        self.field = field
        super().__init__(f"nested deeper than {MAX_DEPTH} levels of tables and arrays")


def _too_deep(doc: dict[str, Any]) -> str | None:
    """The dotted path (keys only) of the first value nested deeper than MAX_DEPTH."""
    stack: list[tuple[Any, int, tuple[str, ...]]] = [(doc, 0, ())]
    while stack:
        value, depth, path = stack.pop()
        if depth > MAX_DEPTH:
            shown = list(path[:4]) + (["..."] if len(path) > 4 else [])
            return ".".join(shown)
        if isinstance(value, dict):
            stack.extend((v, depth + 1, (*path, str(k))) for k, v in value.items())
        elif isinstance(value, list):
            stack.extend((v, depth + 1, path) for v in value)
    return None


def loads(text: str) -> dict[str, Any]:
    """A TOML document from text: ``tomllib.TOMLDecodeError`` when it is not TOML,
    :class:`NestingError` when it nests deeper than :data:`MAX_DEPTH`; a number beyond a
    double's range reads as :class:`Overflowed`."""
    try:
        doc = tomllib.loads(text, parse_float=_parse_float)
    except RecursionError:  # (tomllib recurses into nested values: some hundred levels)
        raise NestingError("") from None
    where = _too_deep(doc)
    if where is not None:
        raise NestingError(where)
    return doc


def read_toml(path: Path, error: type[FieldError] = FieldError) -> dict[str, Any]:
    """The TOML document of the file at path; ``error`` naming the file when it is missing,
    unreadable, not UTF-8 text, not TOML or nested deeper than :data:`MAX_DEPTH`."""
    source = str(path)
    try:
        data = path.read_bytes()
    except FileNotFoundError:
        raise error(source, "", "file not found") from None
    except OSError as e:
        raise error(source, "", f"cannot read the file: {e}") from None
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as e:
        line = data.count(b"\n", 0, e.start) + 1
        raise error(source, "", f"not UTF-8 text (byte 0x{data[e.start]:02x} at offset "
                    f"{e.start}, line {line}): TOML files are UTF-8; save it as UTF-8"
                    ) from None
    try:
        return loads(text.replace("\r\n", "\n").replace("\r", "\n"))  # (as read_text)
    except tomllib.TOMLDecodeError as e:
        raise error(source, "", f"not valid TOML: {e}") from None
    except NestingError as e:
        raise error(source, e.field, str(e)) from None
