"""What the wheel carries: the default model and its card inside the package, declared as package data,
and found by the commands without a checkout."""

import tomllib
from pathlib import Path

import pytest

import bsn_edge
from bsn_edge.cli import demo, run
from bsn_edge.default_model import DEFAULT_MODEL

ROOT = Path(__file__).resolve().parents[1]


def test_the_commands_run_the_default_without_being_told():
    assert run.build_parser().parse_args(["--source", "x.mp4"]).model == str(DEFAULT_MODEL)
    assert demo.build_parser().parse_args([]).model == str(DEFAULT_MODEL)


def test_the_version_is_the_projects():
    assert bsn_edge.__version__ == tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["version"]


def test_bsn_export_help_needs_none_of_the_training_stack():
    """``bsn-export --help`` answers without importing torch, onnx or onnxruntime's quantization tools."""
    import subprocess
    import sys

    code = ("import sys, contextlib, io\nfrom bsn_edge.cli import export\n"
            "with contextlib.suppress(SystemExit), contextlib.redirect_stdout(io.StringIO()):\n"
            "    export.main(['--help'])\n"
            "print(sorted({m.split('.')[0] for m in sys.modules} & {'torch', 'onnx', 'onnxruntime'}))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"


def test_the_runtime_settings_file_is_package_data_and_the_checkouts_copy_is_it(capsys):
    from bsn_edge.runtime.config_file import DEFAULTS_FILE, load_runtime_config
    from bsn_edge.runtime.settings import RuntimeConfig

    pkg = Path(bsn_edge.__file__).resolve().parent / "runtime"
    assert DEFAULTS_FILE.parent == pkg and DEFAULTS_FILE.is_file() and not DEFAULTS_FILE.is_symlink()
    tool = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]
    assert "runtime.toml" in tool["package-data"]["bsn_edge.runtime"]
    assert (ROOT / "configs" / "runtime.toml").resolve() == DEFAULTS_FILE.resolve()
    # every data folder under the package is a declared package: setuptools warns of (and drops) the rest
    for folder in {p.parent for p in pkg.parent.rglob("*") if p.is_file() and "__pycache__" not in p.parts}:
        name = ".".join(folder.relative_to(pkg.parent.parent).parts)
        assert name in tool["packages"], name
    # --print-config prints it, and it loads to the defaults the runtime runs with
    with pytest.raises(SystemExit) as done:
        run.build_parser().parse_args(["--print-config"])
    assert done.value.code == 0
    printed = capsys.readouterr().out
    assert tomllib.loads(printed) == tomllib.loads(DEFAULTS_FILE.read_text())    # with each key's range beside it
    assert load_runtime_config(DEFAULTS_FILE) == RuntimeConfig()
