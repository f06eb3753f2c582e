"""Without the training install, every command that needs it says so in one line naming the install, and
none shows a traceback. Each runs in a Python of its own in which torch, onnx and matplotlib cannot be
imported (as on a base or wheel install)."""

import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

from bsn_edge.cli.full import FULL_MODULES, missing_full_module

ROOT = Path(__file__).resolve().parents[2]
HIDE = "import sys\nfor m in ('torch', 'onnx', 'matplotlib'): sys.modules[m] = None\n"


def _run(entry: str, argv: list[str]) -> subprocess.CompletedProcess:
    code = HIDE + f"import bsn_edge.cli.full as f\nsys.argv = ['x', *{argv!r}]\nsys.exit(f.{entry}())\n"
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, cwd=ROOT)


@pytest.mark.parametrize(("entry", "argv"), [
    ("train", ["--data", "d", "--out", "o"]), ("eval", ["--run", "r", "--data", "d", "--out", "o.json"]),
    ("adapt", ["--run", "r", "--video", "v.mp4", "--out", "o"]),
    ("export", ["--checkpoint", "runs/x", "--out", "x.onnx"]), ("bench", ["--only", "vanishing"]),
])
def test_a_command_of_the_full_install_names_the_install_when_torch_is_missing(entry: str, argv: list[str]):
    r = _run(entry, argv)
    assert r.returncode == 2, (r.stdout, r.stderr)
    assert "Traceback" not in r.stderr
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"bsn-{entry}: error: this needs the training install")
    # the package is on no index: the hint names where an install comes from, the wheel or the clone
    assert "bsn-edge[full]" not in lines[0] and "whl[full]" in lines[0] and '-e ".[full]"' in lines[0]


@pytest.mark.parametrize("entry", ["train", "eval", "export", "adapt", "bench", "label"])
def test_every_command_shows_its_help_without_the_training_install(entry: str):
    """Once bsn-train, bsn-eval and bsn-adapt answered --help with the install hint (exit 2)."""
    r = _run(entry, ["--help"])
    assert r.returncode == 0 and "Traceback" not in r.stderr, r.stderr
    assert r.stdout.startswith("usage: "), r.stdout[:200]


def test_every_command_that_may_need_the_full_install_starts_behind_the_guard():
    scripts = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["scripts"]
    for cmd in ("bsn-train", "bsn-eval", "bsn-export", "bsn-adapt", "bsn-bench", "bsn-label"):
        assert scripts[cmd] == f"bsn_edge.cli.full:{cmd[4:]}"
    full = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["optional-dependencies"]["full"]
    named = {d.split("=")[0].split(">")[0].replace("-", "_") for d in full}
    assert named == FULL_MODULES


def test_another_missing_module_is_not_taken_for_the_full_install():
    assert missing_full_module(ModuleNotFoundError("x", name="torch.nn")) == "torch"
    assert missing_full_module(ModuleNotFoundError("x", name="torchvision")) is None
    assert missing_full_module(ModuleNotFoundError("x", name="cv2")) is None
