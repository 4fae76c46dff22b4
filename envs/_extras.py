"""Optional dependencies: import one where it is used, or fail with the extra of the package that installs it.

``pip install parallel-robot-gym`` installs what ``import envs`` and ``gym.make`` need (numpy, numba, gymnasium,
scipy, pillow); the planner, training and sweeps are extras (``[planner]``, ``[train]``, ``[sweep]``, ``[all]``;
see pyproject.toml). A feature that needs a missing one raises ``ModuleNotFoundError`` naming the extra, as
Gymnasium does for ``gymnasium[mujoco]``.
"""

from __future__ import annotations

import importlib
import importlib.util
from collections.abc import Iterable
from types import ModuleType

__all__ = ["DISTRIBUTION", "missing_extra", "require", "require_all"]

#: The name ``pip install`` knows the project by.
DISTRIBUTION = "parallel-robot-gym"


def missing_extra(feature: str, modules: Iterable[str], extra: str) -> ModuleNotFoundError:
    """The error of a ``feature`` that needs ``modules`` (top-level names), none installed: it names the extra."""
    names = ", ".join(modules)
    first = names.partition(",")[0]
    return ModuleNotFoundError(f"{feature} needs {names}: pip install '{DISTRIBUTION}[{extra}]'", name=first)


def require(module: str, extra: str, feature: str) -> ModuleType:
    """Import ``module``; if it (or its top-level package) is not installed, say which extra installs it.

    Args:
        module: Dotted module name, e.g. ``"ompl.base"``.
        extra: The extra of ``parallel-robot-gym`` that installs it, e.g. ``"planner"``.
        feature: What needs it, for the message, e.g. ``"the planner"``.

    Returns:
        The module.

    Raises:
        ModuleNotFoundError: If the module's top-level package is missing; the message reads
            ``<feature> needs <package>: pip install 'parallel-robot-gym[<extra>]'``. A module missing *inside*
            an installed package (a broken install) is re-raised as it is.
    """
    try:
        return importlib.import_module(module)
    except ModuleNotFoundError as exc:
        top = module.partition(".")[0]
        if exc.name is not None and exc.name.partition(".")[0] != top:
            raise
        raise missing_extra(feature, [top], extra) from exc


def require_all(modules: Iterable[str], extra: str, feature: str) -> None:
    """Check, without importing them, that the top-level ``modules`` are installed; else name the extra.

    Raises:
        ModuleNotFoundError: Naming every missing module and ``pip install 'parallel-robot-gym[<extra>]'``.
    """
    absent = [m for m in modules if _find_spec(m) is None]
    if absent:
        raise missing_extra(feature, absent, extra)


def _find_spec(module: str) -> object | None:
    try:
        return importlib.util.find_spec(module)
    except (ImportError, ValueError):  # a finder that refuses the name; a module whose __spec__ is None
        return None
