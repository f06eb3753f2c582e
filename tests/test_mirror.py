"""The tests mirror the package: a folder of tests for each of its packages, named as it is, and no folder of tests
that is not one (the top-level modules' tests and the cross-cutting ones sit at the top)."""

from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def packages(root: Path) -> set[str]:
    """The package's own packages (folders with an ``__init__.py``), by name."""
    return {p.parent.name for p in (root / "bsn_edge").glob("*/__init__.py")}


def folders_of_tests(root: Path) -> set[str]:
    """The folders of tests (with an ``__init__.py`` or a test in them)."""
    return {p.name for p in (root / "tests").iterdir()
            if p.is_dir() and not p.name.startswith((".", "_")) and (any(p.glob("test_*.py")) or
                                                                   (p / "__init__.py").is_file())}


def test_every_package_has_its_folder_of_tests_and_every_folder_of_tests_a_package():
    pkgs, tests = packages(ROOT), folders_of_tests(ROOT)
    assert pkgs - tests == set(), f"packages without tests/<name>: {sorted(pkgs - tests)}"
    assert tests - pkgs == set(), f"folders of tests that are no package: {sorted(tests - pkgs)}"
    assert all(any((ROOT / "tests" / p).glob("test_*.py")) for p in pkgs), "each folder holds tests"


def test_the_check_sees_a_package_without_tests(tmp_path):
    (tmp_path / "bsn_edge" / "newpkg").mkdir(parents=True)
    (tmp_path / "bsn_edge" / "newpkg" / "__init__.py").write_text("")
    (tmp_path / "tests" / "stray").mkdir(parents=True)
    (tmp_path / "tests" / "stray" / "test_x.py").write_text("")
    assert packages(tmp_path) - folders_of_tests(tmp_path) == {"newpkg"}
    assert folders_of_tests(tmp_path) - packages(tmp_path) == {"stray"}
