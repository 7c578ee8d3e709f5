"""``fullpose build-fmus``: bad input and failures are one clear line with nothing written;
the archives are deterministic.  (What the binaries are worth:
tests/test_orchestrator/test_platforms.py.)"""

import importlib.util
import shutil
import zipfile

import pytest

import controller
import plant
from orchestrator.cli import main
from orchestrator.export.fmu_build import ZIP_TIME, write_fmu
from orchestrator.export.macho import universal_binary
from orchestrator.export.platforms import PLATFORMS, parse_platforms


def build(args, capsys):
    status = main(["build-fmus", *map(str, args)])
    captured = capsys.readouterr()
    assert "Traceback" not in captured.err
    return status, captured.out, captured.err


def test_platform_names_all_host_and_fmi2_folders():
    assert [p.name for p in parse_platforms("all")] == [p.name for p in PLATFORMS]
    assert [p.folder for p in parse_platforms("win64, linux64,win64")] == ["linux64", "win64"]
    assert len(parse_platforms("host")) == 1
    assert [p.folder for p in parse_platforms("aarch64-darwin,x86_64-darwin")] == [
        "darwin64", "aarch64-darwin"]


@pytest.mark.parametrize("spec,message", [
    ("x86_64-linux,sparc-solaris", "unknown platform 'sparc-solaris' (known: x86_64-linux, "),
    (" , ", "--platforms is empty"),
])
def test_bad_platforms_are_refused_before_anything_is_written(tmp_path, capsys, spec,
                                                              message):
    status, _, err = build(["--platforms", spec, "--out", tmp_path / "out"], capsys)
    assert status == 2 and err.startswith("fullpose: error: ") and message in err
    assert not (tmp_path / "out").exists()


def test_missing_zig_is_said_plainly(tmp_path, capsys, monkeypatch):
    real = importlib.util.find_spec

    def without_zig(name, *args):
        return None if name == "ziglang" else real(name, *args)

    monkeypatch.setattr(importlib.util, "find_spec", without_zig)
    status, _, err = build(["--platforms", "all", "--out", tmp_path / "out"], capsys)
    assert status == 2 and "Zig cross compiler is not installed" in err
    assert "pip install 'fullpose[platforms]'" in err
    assert not (tmp_path / "out").exists()


def fmus_folder(tmp_path, plant_edit=None):
    """The installed FMUs copied to a folder FULLPOSE_BUILD_DIR can point at; the plant's
    archive rewritten entry by entry through ``plant_edit(name, data) -> data | None``."""
    from orchestrator.export.signals import signals_fmu

    folder = tmp_path / "fmus"
    folder.mkdir()
    shutil.copy(controller.controller_fmu(), folder)
    shutil.copy(signals_fmu(), folder)
    with zipfile.ZipFile(plant.plant_fmu()) as src, \
            zipfile.ZipFile(folder / "MultirotorPlant.fmu", "w") as dst:
        for name in src.namelist():
            data = src.read(name)
            data = plant_edit(name, data) if plant_edit else data
            if data is not None:
                dst.writestr(name, data)
    return folder


def test_an_fmu_without_sources_is_refused(tmp_path, capsys, monkeypatch):
    folder = fmus_folder(tmp_path, lambda n, d: None if n.startswith("sources/") else d)
    monkeypatch.setenv("FULLPOSE_BUILD_DIR", str(folder))
    status, _, err = build(["--platforms", "host", "--out", tmp_path / "out"], capsys)
    assert status == 2 and "MultirotorPlant.fmu has no sources/" in err
    assert not (tmp_path / "out").exists()


def test_a_failing_compile_names_the_target_and_leaves_the_output_untouched(tmp_path, capsys,
                                                                            monkeypatch):
    pytest.importorskip("ziglang", reason="the Zig cross compiler (pip install -e '.[test]')")

    def broken(name, data):
        return data + b"\n#error broken on purpose\n" if name == "sources/plant.c" else data

    monkeypatch.setenv("FULLPOSE_BUILD_DIR", str(fmus_folder(tmp_path, broken)))
    out = tmp_path / "out"
    out.mkdir()
    (out / "MultirotorPlant.fmu").write_bytes(b"the previous build")
    status, _, err = build(["--platforms", "aarch64-linux", "--out", out], capsys)
    assert status == 2
    assert "MultirotorPlant for aarch64-linux: zig cc -target aarch64-linux-gnu.2.17 failed" in err
    assert "broken on purpose" in err
    assert sorted(p.name for p in out.iterdir()) == ["MultirotorPlant.fmu"]
    assert (out / "MultirotorPlant.fmu").read_bytes() == b"the previous build"


@pytest.mark.platforms
def test_host_build_prints_times_and_sizes_and_is_byte_for_byte_reproducible(tmp_path, capsys):
    pytest.importorskip("ziglang", reason="the Zig cross compiler (pip install -e '.[test]')")
    archives = []
    for run in ("a", "b"):
        status, text, _ = build(["--platforms", "host", "--out", tmp_path / run], capsys)
        assert status == 0
        host = parse_platforms("host")[0]
        assert any(line.startswith(host.name) and line.endswith("KiB")
                   for line in text.splitlines())
        assert f"wrote {tmp_path / run / 'FullPoseController.fmu'} (" in text
        archives.append({p.name: p.read_bytes() for p in (tmp_path / run).iterdir()})
    assert sorted(archives[0]) == ["FullPoseController.fmu", "MultirotorPlant.fmu",
                                   "ScenarioSignals.fmu"]
    assert archives[0] == archives[1]
    with zipfile.ZipFile(tmp_path / "a" / "MultirotorPlant.fmu") as z:
        names = z.namelist()
        assert names[0] == "modelDescription.xml" and names[1:] == sorted(names[1:])
        assert f"binaries/{host.folder}/MultirotorPlant{host.suffix}" in names
        assert {i.date_time for i in z.infolist()} == {ZIP_TIME}


def test_archive_writer_depends_on_content_only(tmp_path):
    root = tmp_path / "fmu"
    (root / "sources").mkdir(parents=True)
    (root / "sources" / "b.c").write_text("int b;\n")
    (root / "modelDescription.xml").write_text("<x/>\n")
    write_fmu(root, tmp_path / "1.fmu")
    (root / "sources" / "b.c").touch()  # a new timestamp, the same content
    write_fmu(root, tmp_path / "2.fmu")
    assert (tmp_path / "1.fmu").read_bytes() == (tmp_path / "2.fmu").read_bytes()


def test_universal_binary_refuses_what_is_not_two_thin_slices():
    with pytest.raises(ValueError, match="not a thin 64-bit"):
        universal_binary([b"\x7fELF" + bytes(60)])
    arm64 = (0xFEEDFACF).to_bytes(4, "little") + (0x0100000C).to_bytes(4, "little") + bytes(24)
    with pytest.raises(ValueError, match="same CPU type"):
        universal_binary([arm64, arm64])
