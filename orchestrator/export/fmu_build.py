"""``fullpose build-fmus``: the FMUs with binaries for several platforms (plant, controller and
the SSP export's ScenarioSignals), compiled by Zig
from each FMU's own ``sources/`` (so every cross build also proves the sources complete).

Each archive written holds the installed FMU's ``modelDescription.xml`` and ``sources/``
unchanged and ``binaries/<folder>/`` for every platform asked for
(``orchestrator.export.platforms``).
The archives are deterministic: entries sorted, fixed timestamps and permissions.  Nothing is
written to the output folder until both FMUs are built: they are made in a temporary folder
beside it and moved in at the end.
"""

from __future__ import annotations

import shutil
import tempfile
import time
import zipfile
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path, PurePosixPath

from orchestrator.export.platforms import Platform, PlatformBuildError, build_platform, zig_command

ZIP_TIME = (2020, 1, 1, 0, 0, 0)  # the timestamp of every entry (as the CMake build's)


@dataclass
class BuildReport:
    """What one ``build-fmus`` wrote: the archives, and seconds per platform (both FMUs)."""

    fmus: list[Path] = field(default_factory=list)
    seconds: dict[str, float] = field(default_factory=dict)
    binary_sizes: dict[tuple[str, str], int] = field(default_factory=dict)  # (fmu, platform)
    total_seconds: float = 0.0

    def sizes(self) -> dict[str, int]:
        """Size in bytes of each FMU built."""
        return {p.name: p.stat().st_size for p in self.fmus}


def installed_fmus(fmi: int = 2) -> list[Path]:
    """The installed plant and controller FMUs and the scenario player of the SSP export
    (``orchestrator.export.signals``) of FMI version ``fmi``, the sources of every build."""
    from controller import controller_fmu
    from orchestrator.export.signals import signals_fmu
    from plant import plant_fmu

    return [plant_fmu(fmi), controller_fmu(fmi), signals_fmu(fmi)]


def _unpack(fmu: Path, into: Path) -> tuple[str, Path]:
    """Extracts the model description and sources of ``fmu``; (model identifier, sources)."""
    with zipfile.ZipFile(fmu) as z:
        names = [n for n in z.namelist() if not n.endswith("/")]
        if "modelDescription.xml" not in names:
            raise PlatformBuildError(f"{fmu}: no modelDescription.xml")
        for n in names:
            parts = PurePosixPath(n).parts
            if n == "modelDescription.xml" or (len(parts) == 2 and parts[0] == "sources"):
                z.extract(n, into)
    sources = into / "sources"
    if not any(sources.glob("*.c")):
        raise PlatformBuildError(f"{fmu} has no sources/: reinstall fullpose (pip install .) "
                                 "to get FMUs that carry their C sources")
    from fmpy import read_model_description

    md = read_model_description(str(into / "modelDescription.xml"))
    return str(md.coSimulation.modelIdentifier), sources


def write_fmu(root: Path, out: Path) -> None:
    """The folder ``root`` as a deterministic FMU archive ``out``."""
    files = sorted(p for p in root.rglob("*") if p.is_file())
    names = sorted((p.relative_to(root).as_posix(), p) for p in files)
    names.sort(key=lambda np: (np[0] != "modelDescription.xml", np[0]))
    with zipfile.ZipFile(out, "w", zipfile.ZIP_DEFLATED) as z:
        for name, path in names:
            info = zipfile.ZipInfo(name, date_time=ZIP_TIME)
            info.compress_type = zipfile.ZIP_DEFLATED
            mode = 0o755 if name.startswith("binaries/") else 0o644
            info.external_attr = (0o100000 | mode) << 16
            info.create_system = 3  # Unix, so the permissions above are read
            z.writestr(info, path.read_bytes())


def build_fmus(platforms: Sequence[Platform], out: Path,
               sources: Sequence[Path] | None = None, fmi: int = 2) -> BuildReport:
    """Writes ``out/<model>.fmu`` for each FMU in ``sources`` (default: the installed plant,
    controller and player FMUs of FMI version ``fmi``) with binaries for ``platforms``."""
    if not platforms:
        raise PlatformBuildError("no platform to build")
    zig_command()  # a missing compiler is said before anything is done
    fmus = list(sources) if sources is not None else installed_fmus(fmi)
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise PlatformBuildError(f"{out} exists and is not a folder")
    report = BuildReport(seconds={p.name: 0.0 for p in platforms})
    start = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="fullpose-build-") as tmp:
        work = Path(tmp)
        archives = []
        for fmu in fmus:
            staged = work / fmu.stem / "fmu"
            model, src = _unpack(fmu, staged)
            built: dict[str, Path] = {}
            for p in platforms:
                lib, seconds = build_platform(p, src, staged / "binaries",
                                              work / fmu.stem / "targets", model, built, fmi)
                report.seconds[p.name] += seconds
                report.binary_sizes[(model, p.name)] = lib.stat().st_size
            archive = work / f"{model}.fmu"
            write_fmu(staged, archive)
            archives.append(archive)
        # both archives are complete: each now goes in whole (copied beside its final name,
        # then renamed over it)
        out.mkdir(parents=True, exist_ok=True)
        for archive in archives:
            final = out / archive.name
            partial = out / f".{archive.name}.partial"
            shutil.copyfile(archive, partial)
            partial.replace(final)
            report.fmus.append(final)
    report.total_seconds = time.perf_counter() - start
    return report
