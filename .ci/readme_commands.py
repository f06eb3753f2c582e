"""The README's runnable commands, as CI runs them: every ```bash block of README.md, in order.

    python3 .ci/readme_commands.py [--latest]

prints one shell script that times each block. ``--latest`` drops the ``-c constraints.txt`` pins from
the pip commands, so the same commands install the newest versions the registries serve.
"""

from __future__ import annotations

import re
import sys
from pathlib import Path

BLOCK = re.compile(r"^```bash\n(.*?)^```", re.S | re.M)
PIN = " -c constraints.txt"


def commands(readme: str, latest: bool = False) -> list[str]:
    blocks = [b.strip() for b in BLOCK.findall(readme)]
    return [b.replace(PIN, "") for b in blocks] if latest else blocks


def main(argv: list[str]) -> int:
    readme = (Path(__file__).resolve().parent.parent / "README.md").read_text()
    for i, block in enumerate(commands(readme, "--latest" in argv), 1):
        # each block timed, so the README's durations can be checked against what CI measured
        print(f"echo '== README command block {i}'\nstart=$SECONDS\n{block}\n"
              f"echo \"== README command block {i} took $((SECONDS - start)) s\"\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
