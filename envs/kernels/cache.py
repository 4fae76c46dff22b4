"""Numba's on-disk cache, kept true across modules.

Numba keys a cached function by the source file that defines it, so a kernel that inlines or calls a jitted
function of *another* module keeps its compiled code after that module changes, and runs the old version.
``drop_stale_caches`` closes that gap: a module that calls into others names them, and its cache files are
removed whenever their sources differ from those its cache was built with.
"""

from __future__ import annotations

import hashlib
from collections.abc import Iterable
from pathlib import Path

__all__ = ["drop_stale_caches"]


def drop_stale_caches(module_file: str | Path, dependencies: Iterable[str | Path]) -> bool:
    """Remove the Numba cache of ``module_file`` if a file it depends on changed since the cache was built.

    The sources of ``module_file``'s dependencies are hashed into ``__pycache__/<module>.deps``; where the hash
    differs (or is missing), the module's ``<module>.*.nbi`` / ``.nbc`` files are deleted, so Numba compiles
    afresh on first use. Call it at import time, before any of the module's functions is compiled. A cache
    folder that cannot be written (a read-only install) is left alone.

    Args:
        module_file: The module's ``__file__``.
        dependencies: Source files of the modules whose jitted functions it calls.

    Returns:
        True if a stale cache was dropped (or there was no record of one).
    """
    here = Path(module_file)
    cache = here.parent / "__pycache__"
    digest = hashlib.sha256()
    for path in sorted(Path(p) for p in dependencies):
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
