"""envs.kernels.cache: a module's Numba cache is dropped when a module it calls into changes."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

from envs.kernels import step
from envs.kernels.cache import cache_folder, dependencies, drop_stale_caches


def test_a_changed_dependency_drops_the_cache_and_an_unchanged_one_keeps_it(tmp_path):
    """Cache files of the module go when a dependency's source changes, and only then; other modules' stay."""
    module, dependency = tmp_path / "mine.py", tmp_path / "theirs.py"
    module.write_text("x = 1\n")
    dependency.write_text("def f(): return 1\n")
    cache = cache_folder(module)  # beside the source, or under NUMBA_CACHE_DIR where that is set
    cache.mkdir(parents=True, exist_ok=True)
    mine = [cache / "mine.f-3.py311.nbi", cache / "mine.f-3.py311.1.nbc"]
    other = cache / "theirs.f-1.py311.nbi"
    for path in (*mine, other):
        path.write_bytes(b"compiled")
    assert drop_stale_caches(module, [dependency])  # no record yet: dropped
    assert not any(p.exists() for p in mine) and other.exists()
    for path in mine:
        path.write_bytes(b"compiled")
    assert not drop_stale_caches(module, [dependency])  # unchanged: kept
    assert all(p.exists() for p in mine)
    dependency.write_text("def f(): return 2\n")
    assert drop_stale_caches(module, [dependency])  # changed: dropped
    assert not any(p.exists() for p in mine) and other.exists()


def test_imports_are_found_in_every_nested_block(tmp_path):
    """``dependencies``' statement walk finds the imports of every nested block, as ``ast.walk`` does.

    Functions, classes, try/except/else/finally, if/else, loops, with and match; not text that looks like one.
    """
    from envs.kernels.cache import _imports_of

    source = tmp_path / "nested.py"
    source.write_text(
        "import a0\n"
        "def f():\n    import a1\n"
        "class C:\n    def g(self):\n        from a2 import b2\n"
        "try:\n    import a3\nexcept ImportError:\n    import a4\nelse:\n    import a5\nfinally:\n    import a6\n"
        "if x:\n    import a7\nelse:\n    import a8\n"
        "for i in y:\n    import a9\nelse:\n    import a10\n"
        "while z:\n    import a11\n"
        "with w:\n    import a12\n"
        "match v:\n    case 1:\n        import a13\n"
        "text = 'import a14'\n"
    )
    expected = {f"a{i}" for i in range(14) if i != 2} | {"a2", "a2.b2"}
    assert _imports_of(source) == expected


def _direct_imports(path: Path) -> set[str]:
    """File names of the project modules a source file imports, read with a regular expression (not ``ast``)."""
    names = set()
    text = path.read_text(encoding="utf-8")
    for package, imported in re.findall(r"^from (envs[.\w]*) import \(?([^)\n]*(?:\n[^)]*)*?)\)?$", text, re.M):
        for name in re.findall(r"\w+", imported):
            if f"{package}.{name}" in sys.modules:
                names.add(f"{package}.{name}")
        if package in sys.modules and not sys.modules[package].__file__.endswith("__init__.py"):
            names.add(package)
    return {Path(sys.modules[name].__file__).name for name in names}


def test_a_kernel_module_depends_on_every_module_it_imports_and_theirs_in_turn():
    """``dependencies`` of the step holds what it imports, what those import, and so on (the closure)."""
    found = {path.name: path for path in dependencies(step.__file__)}
    assert {"layout.py", "paths.py", "three.py", "linalg.py", "constraints.py", "evaluation.py"} <= set(found)
    for path in [Path(step.__file__), *found.values()]:
        missing = _direct_imports(path) - set(found) - {"step.py"}
        assert not missing, f"{path.name} imports {missing}, which step's dependencies leave out"


#: Run in a subprocess: the first step of an id, then the number of kernels Numba compiled (not loaded from its
#: on-disk cache) on the way, and their names.
_FIRST_STEP = r"""
import sys
import numba.core.dispatcher as nd
from numba.core import sigutils

compiled, original = [], nd.Dispatcher.compile

def compile(self, sig):
    args, _ = sigutils.normalize_signature(sig)
    if tuple(args) in self.overloads:
        return original(self, sig)
    hits = sum(self._cache_hits.values())
    try:
        return original(self, sig)
    finally:
        if sum(self._cache_hits.values()) == hits and (self.py_func.__module__ or "").startswith("envs"):
            compiled.append(self.py_func.__qualname__)

nd.Dispatcher.compile = compile
import gymnasium as gym
import envs

env = gym.make(sys.argv[1])
env.reset(seed=0)
env.step(env.action_space.sample())
print(len(compiled), sorted(set(compiled)))
"""


def test_a_second_process_loads_every_kernel_of_the_first_step_from_the_cache():
    """``cache=True`` holds across processes: a process that steps an id compiles nothing an earlier one compiled.

    The process runs on the project's cache (in the suite, the warm-up filled it); if it had to compile (a cold
    or stale cache), a second process must load all of it, the entry kernels too (closures over the robot's row
    path, which Numba caches under its value).
    """
    import os
    import subprocess
    import sys
    from pathlib import Path

    root = Path(__file__).resolve().parents[2]
    env = dict(os.environ, PYTHONPATH=str(root))
    for _ in range(2):
        run = subprocess.run(
            [sys.executable, "-c", _FIRST_STEP, "DeltaReach-v0"], cwd=root, env=env, capture_output=True, text=True
        )
        assert run.returncode == 0, run.stderr[-2000:]
        compiled = run.stdout.strip().splitlines()[-1]
        if compiled.startswith("0 "):
            return
    raise AssertionError(f"compiled again in a second process: {compiled}")


def test_every_path_kernel_has_its_own_cache_index():
    """Each path's entry kernels (the step's, the certificate's, the samplers') keep their own Numba cache index file.

    Closures of one name share an index, and Numba's index is read, extended and rewritten without a lock: two
    processes compiling two robots' paths at once (two pytest workers, two Ray workers) would then overwrite each
    other's entries, and a later process could load the machine code of one path for another.
    """
    from envs.kernels import step
    from envs.tasks import certificate, samplers

    kernels = {  # by identity: a register path's one-thread step is its multi-core kernel
        id(kernel): kernel
        for table in (step._PATH_KERNELS, certificate._CERTIFICATE_KERNELS, samplers._SAMPLER_KERNELS)
        for kernels in table.values()
        for kernel in kernels
    }
    names = [kernel._cache._cache_file._index_name for kernel in kernels.values()]
    assert len(set(names)) == len(names), sorted(name for name in names if names.count(name) > 1)


_CACHED_MODULE = """
import numba

@numba.njit(cache=True)
def twice(x):
    return 2 * x

twice(1.0)
"""


@pytest.mark.parametrize("user_folder", [False, True])
def test_the_cache_folder_is_where_numba_writes_the_cache(tmp_path, user_folder):
    """``cache_folder`` finds the folder Numba itself writes a module's cache to, with or without NUMBA_CACHE_DIR."""
    module = tmp_path / "src" / "mine.py"
    module.parent.mkdir()
    module.write_text(_CACHED_MODULE)
    env = {**os.environ, "PYTHONPATH": str(module.parent)}
    env.pop("NUMBA_CACHE_DIR", None)
    if user_folder:
        env["NUMBA_CACHE_DIR"] = str(tmp_path / "numba")
    script = "import mine, sys; from envs.kernels.cache import cache_folder; print(cache_folder(sys.argv[1]))"
    done = subprocess.run([sys.executable, "-c", script, str(module)], env=env, capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    folder = Path(done.stdout.strip())
    assert sorted(p.name.split(".")[0] for p in folder.glob("*.nbi")) == ["mine"]
    assert folder.is_relative_to(tmp_path / ("numba" if user_folder else "src"))
