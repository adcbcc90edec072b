"""Count ``estimation/``'s modules and the import arrows between them, file to file.

An arrow is a module of ``mavsysid.estimation`` naming another in an import (``from A
import b`` counts A, and A.b where that is a module) or in a string (a lazy import);
``__init__`` files are counted apart, as re-exports. Prints the figures and, with
``--list``, every arrow.

    python bench/estimation_imports.py [--list]
"""

from __future__ import annotations

import argparse
import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent / "estimation"


def modules(root: Path = ROOT) -> dict[str, Path]:
    """Dotted module name → file, for every ``.py`` under ``root``."""
    found = {}
    for path in root.rglob("*.py"):
        parts = list(path.relative_to(root).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        found[".".join(["mavsysid.estimation", *parts])] = path
    return found


def arrows(files: dict[str, Path]) -> set[tuple[str, str]]:
    """(importer, imported) pairs between the modules of ``files``."""
    edges = set()
    for name, path in files.items():
        for node in ast.walk(ast.parse(path.read_text())):
            targets: list[str] = []
            if isinstance(node, ast.ImportFrom) and node.module:
                targets = [node.module] + [f"{node.module}.{a.name}" for a in node.names]
            elif isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            elif isinstance(node, ast.Constant) and isinstance(node.value, str):
                targets = [node.value]
            edges.update((name, t) for t in targets if t in files and t != name)
    return edges


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--list", action="store_true", help="print every arrow")
    args = parser.parse_args()
    files = modules()
    edges = arrows(files)
    plain = {n for n, p in files.items() if p.name != "__init__.py"}
    between = sorted((a, b) for a, b in edges if a in plain and b in plain)
    print(f"{len(plain)} modules other than __init__.py; {len(between)} arrows between them; "
          f"{len(edges)} with the __init__ files")
    if args.list:
        for a, b in between:
            print(f"  {a.removeprefix('mavsysid.estimation.')} -> "
                  f"{b.removeprefix('mavsysid.estimation.')}")


if __name__ == "__main__":
    main()
