"""Refresh the generated blocks of the documentation from the files they are generated from.

A block in a Markdown page reads

    <!-- generated: docs/results/<run>/table.md -->
    ...
    <!-- end generated -->

and holds that file (a table of ``experiments.family_report``, a sweep's ``report.md``, the main job's report)
without its title line, with its pictures' paths made relative to the page. ``python -m experiments.docs_tables``
rewrites every block of ``README.md`` and ``docs/*.md`` from its file, and ``--check`` fails (exit 1, naming
the blocks) where a page differs from its files: the tables are never typed.
"""

from __future__ import annotations

import argparse
import os
import re
import sys
from pathlib import Path

__all__ = ["block_text", "main", "refresh"]

_BLOCK = re.compile(r"(<!-- generated: (?P<path>\S+) -->\n)(?P<body>.*?)(<!-- end generated -->)", re.S)
_PICTURE = re.compile(r"\]\((?!https?:|/)(?P<path>[^)]+\.(?:png|gif|svg))\)")


def block_text(source: Path, page: Path) -> str:
    """The text a block of ``page`` holds for ``source``: the file without its ``# `` title, pictures re-rooted."""
    lines = source.read_text().splitlines()
    if lines and lines[0].startswith("# "):
        lines = lines[1:]
    while lines and not lines[0].strip():
        lines = lines[1:]
    text = "\n".join(lines).rstrip() + "\n"
    folder = Path(os.path.relpath(source.parent, page.parent))
    return _PICTURE.sub(lambda m: f"]({(folder / m.group('path')).as_posix()})", text)


def refresh(root: Path, check: bool = False) -> list[str]:
    """Rewrite (or, with ``check``, only compare) the generated blocks under ``root``; the stale ones' names.

    Raises:
        FileNotFoundError: If a block names a file that does not exist.
    """
    stale = []
    for page in [root / "README.md", *sorted((root / "docs").glob("*.md"))]:
        if not page.is_file():
            continue
        text = page.read_text()

        def replace(match: re.Match, page: Path = page) -> str:
            source = root / match.group("path")
            if not source.is_file():
                raise FileNotFoundError(f"{page.relative_to(root)}: generated block names {source}, which is missing")
            body = block_text(source, page)
            if body != match.group("body"):
                stale.append(f"{page.relative_to(root)}: {match.group('path')}")
            return match.group(1) + body + match.group(4)

        new = _BLOCK.sub(replace, text)
        if new != text and not check:
            page.write_text(new)
    return stale


def main(argv: list[str] | None = None) -> int:
    """Entry point of ``python -m experiments.docs_tables``; returns the exit status."""
    parser = argparse.ArgumentParser(prog="python -m experiments.docs_tables", description=__doc__.split("\n")[0])
    parser.add_argument("--root", default=".", help="the checkout (default: the working directory)")
    parser.add_argument("--check", action="store_true", help="change nothing; exit 1 if a block is stale")
    args = parser.parse_args(argv)
    try:
        stale = refresh(Path(args.root), check=args.check)
    except FileNotFoundError as exc:
        parser.error(str(exc))
    for name in stale:
        print(("stale: " if args.check else "refreshed: ") + name)
    return 1 if (args.check and stale) else 0


if __name__ == "__main__":
    sys.exit(main())
