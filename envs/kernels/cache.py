"""Numba's on-disk cache, kept true across modules.

Numba keys a cached function by the source file that defines it, so a kernel that inlines or calls a jitted
function of *another* module keeps its compiled code after that module changes, and runs the old version.
``drop_stale_caches`` closes that gap: it finds the modules a module calls into (the project's modules its
namespace refers to, and theirs in turn), and removes the module's cache files whenever their sources differ from
those its cache was built with.
"""

from __future__ import annotations

import ast
import functools
import hashlib
import sys
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import Any

from numba.core.caching import CompileResultCacheImpl

__all__ = ["cache_folder", "dependencies", "drop_stale_caches"]

#: The package whose modules are followed (the kernels call into no other package's jitted code).
_PACKAGE = "envs."


def _statements(nodes: list[ast.stmt]) -> Iterator[ast.stmt]:
    """Every statement of ``nodes`` and of the blocks nested in them (imports are statements: no expression)."""
    for node in nodes:
        yield node
        for block in ("body", "handlers", "orelse", "finalbody", "cases"):
            yield from _statements(getattr(node, block, None) or [])


@functools.cache
def _imports_of(path: Path) -> frozenset[str]:
    """Every name the source file ``path`` imports at any level, and each ``from`` import's members (parsed once)."""
    names = set()
    for node in _statements(ast.parse(path.read_text(encoding="utf-8")).body):
        if isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            names.add(node.module)
            names.update(f"{node.module}.{alias.name}" for alias in node.names)
        elif isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
    return frozenset(names)


def _imported_modules(path: Path) -> set[str]:
    """Names of the package's modules (not packages) that the source file ``path`` imports at any level."""
    return {
        name
        for name in _imports_of(path.resolve())
        if name.startswith(_PACKAGE)
        and name in sys.modules
        and not str(getattr(sys.modules[name], "__file__", "__init__.py")).endswith("__init__.py")
    }


def dependencies(module_file: str | Path) -> list[Path]:
    """Source files of every module of the package that ``module_file`` imports, and those they import in turn.

    Constants count (the kernels read the packed offsets as compile-time constants), so every import does.

    Args:
        module_file: A module's ``__file__``; its imports must have run (call this after them).
    """
    here = Path(module_file).resolve()
    seen: set[str] = set()
    todo = _imported_modules(here)
    while todo:
        name = todo.pop()
        seen.add(name)
        todo |= _imported_modules(Path(sys.modules[name].__file__)) - seen
    return sorted(p for p in (Path(sys.modules[name].__file__).resolve() for name in seen) if p != here)


def cache_folder(module_file: str | Path) -> Path:
    """The folder where Numba caches the jitted functions of ``module_file``, found as Numba finds it.

    ``NUMBA_CACHE_DIR`` when it is set, else ``__pycache__`` beside the source, or the user-wide cache when that
    cannot be written (Numba's cache locators, tried in its order).
    """
    namespace: dict[str, Any] = {}
    exec(compile("def probe():\n    pass\n", str(module_file), "exec"), namespace)  # a function "of" that file
    return Path(CompileResultCacheImpl(namespace["probe"])._locator.get_cache_path())


def drop_stale_caches(module_file: str | Path, sources: Iterable[str | Path] | None = None) -> bool:
    """Remove the Numba cache of a module if a module it depends on changed since the cache was built.

    The sources of the module's ``dependencies`` are hashed into ``<cache folder>/<module>.deps``; where the hash
    differs (or is missing), the module's ``<module>.*.nbi`` / ``.nbc`` files are deleted, so Numba compiles
    afresh on first use. Call it at import time, after the module's imports and before any of its functions is
    compiled. A cache folder that cannot be written (a read-only install) is left alone.

    Args:
        module_file: The module's ``__file__``.
        sources: The files it depends on (default: its ``dependencies``).

    Returns:
        True if a stale cache was dropped (or there was no record of one).
    """
    here = Path(module_file)
    cache = cache_folder(here)
    digest = hashlib.sha256()
    for path in dependencies(module_file) if sources is None else sorted(Path(p) for p in sources):
        digest.update(path.name.encode() + b"\0" + path.read_bytes())
    stamp = cache / f"{here.stem}.deps"
    try:
        if stamp.read_text() == digest.hexdigest():
            return False
    except OSError:
        pass
    try:
        for stale in (*cache.glob(f"{here.stem}.*.nbi"), *cache.glob(f"{here.stem}.*.nbc")):
            stale.unlink(missing_ok=True)
        cache.mkdir(exist_ok=True)
        stamp.write_text(digest.hexdigest())
    except OSError:
        return False
    return True
