"""Every speed or duration the docs give says where it comes from: a benchmark report it links, or the date
it was measured on and the machine (a 2-core CPU's speed is a fact of that CPU and that day, not of the
project). A figure's block is its paragraph, list item or table, with the sentence just before a table (its
caption); settings' ranges and defaults are not measurements, and the generated settings pages are skipped."""

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PAGES = ("README.md", "models/README.md", *sorted(str(p.relative_to(ROOT)) for p in (ROOT / "docs").glob("*.md")))
GENERATED = {"docs/settings.md"}

# a number with a unit of speed or time of a machine
FIGURE = re.compile(r"\d[\d,.]*\s?(?:frames/s\b|ms\b|minutes?\b|min\b|h of\b|hours?\b|s of (?:training|CPU)\b|"
                    r"s measured\b)")
SOURCE = re.compile(r"20\d\d-\d\d-\d\d|results/\w+\.md|benchmarks/results/")
# what is set rather than measured: a setting's range or default, a budget, a deadline
SETTING = re.compile(r"(?:under|over|at least|at most|>=|<=|floor|deadline|every|within|after|for|of its first|"
                     r"default) "
                     r"\d[\d,.]*\s?(?:frames/s|ms|minutes?|min|hours?)\b")


def blocks(text: str) -> list[tuple[int, str]]:
    """``text``'s blocks (paragraphs, list items and tables, fenced code left out) with their first line's
    number; a table carries the paragraph before it."""
    text = re.sub(r"<!-- settings table.*?<!-- end of settings table -->", lambda m: "\n" * m[0].count("\n"), text,
                  flags=re.S)
    out: list[tuple[int, str]] = []
    lines = text.splitlines()
    cur: list[str] = []
    start, fenced, prev = 0, False, ""

    def flush() -> None:
        nonlocal prev
        if cur:
            body = "\n".join(cur)
            out.append((start, (prev + "\n" + body) if body.lstrip().startswith("|") else body))
            prev = body
        cur.clear()

    for n, line in enumerate(lines, 1):
        if line.lstrip().startswith("```"):
            flush()
            fenced = not fenced
            continue
        if fenced:
            continue
        item = re.match(r"\s*(?:[-*]|\d+\.) ", line) and not line.startswith("  ")
        if not line.strip() or line.startswith("#") or item:
            flush()
            if line.startswith("#"):
                prev = ""
        if line.strip() and not line.startswith("#"):
            if not cur:
                start = n
            cur.append(line)
    flush()
    return out


def undated(text: str) -> list[tuple[int, str]]:
    """The blocks of ``text`` that give a machine's speed or time without a report or a date."""
    return [(n, b) for n, b in blocks(text)
            if FIGURE.search(SETTING.sub("", b)) and not SOURCE.search(b)]


@pytest.mark.parametrize("page", [p for p in PAGES if p not in GENERATED])
def test_every_speed_in_the_docs_names_its_report_or_its_date_and_machine(page: str):
    bad = undated((ROOT / page).read_text())
    assert not bad, "\n\n".join(f"{page}:{n}: {b[:300]}" for n, b in bad)


def test_an_undated_speed_is_found_and_a_dated_or_reported_one_is_not():
    assert undated("The model runs at 88 frames/s on two cores.\n")
    assert undated("Intro.\n\n| model | ms |\n|---|---|\n| a | 5.3 ms |\n")
    assert not undated("Measured 2026-12-06 on a 2-core Xeon: 88 frames/s.\n")
    assert not undated("See [quant](results/quant.md).\n\n| model | ms |\n|---|---|\n| a | 5.3 ms |\n")
    assert not undated("No valid inference for 0.5 s, or under 8 frames/s, is DEGRADED.\n")
    assert not undated("```text\nbsn-run: 57.8 frames/s\n```\n")
