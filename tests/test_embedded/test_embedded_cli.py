"""What the embedded commands say when they cannot run: no toolchain, no image, a file that is
not one, an FMI 3.0 scenario (no Arm tools or QEMU needed: these run in the fast tier).
Each is one line naming the file or tool and the reason, exit status 2, no results folder."""

from __future__ import annotations

from pathlib import Path

import pytest

from orchestrator.cli import main


def _fails(argv: list[str], capsys: pytest.CaptureFixture[str]) -> str:
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err
    return err


def test_build_without_the_toolchain_says_what_to_install(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    monkeypatch.setenv("PATH", str(tmp_path))  # no arm-none-eabi-gcc, no cmake
    err = _fails(["build-embedded", "--out", str(tmp_path / "m7")], capsys)
    assert "arm-none-eabi-gcc" in err and "apt-get install gcc-arm-none-eabi" in err
    assert not (tmp_path / "m7").exists()


@pytest.mark.parametrize("content, reason", [
    (None, "no such controller image"),
    (b"\x7fELF\x02\x01" + bytes(14), "is not an Arm ELF executable"),  # 64-bit: a host ELF
    (b"text, not an image\n", "is not an Arm ELF executable"),
])
def test_run_pil_refuses_what_is_not_an_image(
        content: bytes | None, reason: str, tmp_path: Path,
        capsys: pytest.CaptureFixture[str]) -> None:
    image = tmp_path / "fpc_pil.elf"
    if content is not None:
        image.write_bytes(content)
    err = _fails(["run", "hover", "--duration", "0.1", "--pil", str(image), "--out",
                  str(tmp_path / "r"), "--no-plots"], capsys)
    assert reason in err and str(image) in err
    assert not (tmp_path / "r").exists()


def test_run_pil_refuses_fmi3(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    err = _fails(["run", "hover", "--fmi", "3", "--pil", str(tmp_path / "x.elf"), "--out",
                  str(tmp_path / "r")], capsys)
    assert "--pil" in err and "--fmi 3" in err
