"""The installed distributions as pins for constraints.txt: ``pip freeze`` without the project
itself and without local version labels (``torch==2.13.0+cpu`` pins ``torch==2.13.0``, so the
same file serves a CPU and a CUDA build)."""

from __future__ import annotations

import subprocess
import sys

HEADER = ("# Versions the suite passed with (bash .ci/run --latest --pin writes this file).\n"
          "# pip install -c constraints.txt ... installs exactly these.")


def pins(freeze: str) -> list[str]:
    out = []
    for line in freeze.splitlines():
        line = line.strip()
        if not line or line.startswith(("#", "-e", "bsn-edge")) or "==" not in line:
            continue
        name, version = line.split("==", 1)
        out.append(f"{name}=={version.split('+', 1)[0]}")
    return sorted(out, key=str.lower)


def main() -> int:
    freeze = subprocess.run([sys.executable, "-m", "pip", "freeze", "--exclude-editable"], check=True,
                            capture_output=True, text=True).stdout
    print(HEADER)
    print("\n".join(pins(freeze)))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
