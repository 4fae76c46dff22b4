"""envs.kernels.cache: a module's Numba cache is dropped when a module it calls into changes."""

from __future__ import annotations

from envs.kernels.cache import drop_stale_caches


def test_a_changed_dependency_drops_the_cache_and_an_unchanged_one_keeps_it(tmp_path):
    """Cache files of the module go when a dependency's source changes, and only then; other modules' stay."""
    module, dependency = tmp_path / "mine.py", tmp_path / "theirs.py"
    module.write_text("x = 1\n")
    dependency.write_text("def f(): return 1\n")
    cache = tmp_path / "__pycache__"
    cache.mkdir()
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
