"""docs/architecture.md's module table ("Packages") names every module of the tree, and
only modules that exist.

Each row is ``| package | modules | purpose |`` (the package cell empty for the rows after
its first); the modules are the backquoted names of the second cell. A subpackage may
instead have one row in its parent's group (``readers/`` in ``mavsysid.estimation``) whose
purpose names each of its modules in backquotes.
"""

from __future__ import annotations

import re
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
DOC = (ROOT / "docs" / "architecture.md").read_text(encoding="utf-8")
SETUPTOOLS = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))["tool"][
    "setuptools"]
PACKAGE_DIR: dict[str, str] = SETUPTOOLS["package-dir"]
PACKAGES: list[str] = SETUPTOOLS["packages"]


def _table() -> dict[str, list[tuple[list[str], str]]]:
    """package → its rows as (module names of the second cell, the whole row)."""
    section = DOC.split("\n## Packages", 1)[1].split("\n## ", 1)[0].split("\n### ", 1)[0]
    rows: dict[str, list[tuple[list[str], str]]] = {}
    package = None
    for line in section.splitlines():
        if not line.startswith("| ") or line.startswith(("| package", "|---")):
            continue
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if cells[0]:
            package = cells[0].strip("`")
        rows.setdefault(package, []).append(
            (re.findall(r"`([A-Za-z0-9_/]+)`", cells[1]), line))
    return rows


def _folder(package: str) -> Path:
    """The checkout folder of an import name (pyproject's package-dir, else a subfolder)."""
    if package in PACKAGE_DIR:
        return ROOT / PACKAGE_DIR[package]
    parent, _, name = package.rpartition(".")
    return _folder(parent) / name


def _named(rows: dict[str, list[tuple[list[str], str]]], package: str, module: str) -> bool:
    """Whether ``module`` of ``package`` has a row, or is named in its parent's folder row."""
    if any(module in names for names, _ in rows.get(package, [])):
        return True
    parent, _, sub = package.rpartition(".")
    return any(f"{sub}/" in names and f"`{module}`" in line
               for names, line in rows.get(parent, []))


def test_every_module_has_a_row() -> None:
    """Every module file of every package is named in the table under its package."""
    rows = _table()
    missing = [f"{package}.{f.stem}" for package in PACKAGES
               for f in sorted(_folder(package).glob("*.py"))
               if f.stem not in ("__init__", "__main__") and not _named(rows, package, f.stem)]
    assert not missing, f"modules missing from docs/architecture.md: {missing}"


def test_every_row_names_existing_modules() -> None:
    """Every module the table names exists in its package's folder."""
    stale = []
    for package, entries in _table().items():
        folder = _folder(package)
        for names, _ in entries:
            stale += [f"{package}.{name}" for name in names
                      if not ((folder / name).is_dir() if name.endswith("/")
                              else (folder / f"{name}.py").exists())]
    assert not stale, f"docs/architecture.md names modules that do not exist: {stale}"


def test_effect_table_names_the_catalogue() -> None:
    """The "Effect names" table has one row per catalogue effect, with its parameters."""
    from mavsysid.vehicle.model_effects import EFFECTS

    section = DOC.split("\n## Effect names", 1)[1].split("\n## ", 1)[0]
    rows = {}
    for line in section.splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if line.startswith("| `") and len(cells) >= 2:
            rows[cells[0].strip("`")] = {n.strip() for group in re.findall(r"`([^`]+)`",
                                                                            cells[1])
                                         for n in group.split(",")}
    assert list(rows) == list(EFFECTS)
    for name, effect in EFFECTS.items():
        assert rows[name] == set(effect.parameter_names()), name
