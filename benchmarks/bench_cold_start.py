"""Benchmark the cold start: CPU seconds to the first step of each id on an empty Numba cache, against ``import torch``.

Run with ``python -m benchmarks.bench_cold_start [--ids ID ...] [--no-warmup] [--profile] [--repo PATH]``. Each
measurement runs in a fresh subprocess with a fresh, empty ``NUMBA_CACHE_DIR`` (the shared ``__pycache__`` caches
are neither read nor touched), and is the CPU time (user + system, every thread) of that whole process:

- the anchor: ``import torch`` (left out if torch is not installed);
- for each id (default: every id of ``envs.ENV_IDS``): ``import envs``, ``gym.make(id)``, ``reset`` and one ``step``;
- the test suite's warm-up (``tests.numba_warmup.warm_up``): every kernel the tests use, for every robot kind.

The table gives each time and its ratio to the anchor, against the targets (≤ 15 s per id, ≤ 90 s for the
warm-up). With ``--profile``, every compilation of a Numba function in those processes is timed (its own CPU
time, without the functions it compiles in turn) and the table per function and per specialisation (its
argument types: array layouts, read-only flags, tuples) is written to ``docs/results/compile_profile.txt``.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import subprocess
import sys
import tempfile
from collections import defaultdict
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PROFILE_PATH = ROOT / "docs" / "results" / "compile_profile.txt"
#: Targets of the cold start [s of CPU].
TARGET_ID, TARGET_WARMUP = 15.0, 90.0

#: The code each subprocess runs: argv = (what, id, profile). It prints one JSON line with the compilations.
_CHILD = r"""
import json, sys, time
what, env_id, profile = sys.argv[1], sys.argv[2], sys.argv[3] == "1"
records = []
if profile and what != "torch":
    import numba.core.dispatcher as nd
    from numba.core import sigutils
    original, stack = nd.Dispatcher.compile, []

    def compile(self, sig):
        args, _ = sigutils.normalize_signature(sig)
        if tuple(args) in self.overloads:
            return original(self, sig)
        hits = sum(self._cache_hits.values())
        start = time.process_time()
        stack.append(0.0)
        try:
            return original(self, sig)
        finally:
            inner = stack.pop()
            total = time.process_time() - start
            if stack:
                stack[-1] += total
            fn = self.py_func
            records.append({
                "function": f"{fn.__module__}.{fn.__qualname__}",
                "signature": "(" + ", ".join(str(a) for a in args) + ")",
                "own": total - inner,
                "total": total,
                "loaded": sum(self._cache_hits.values()) > hits,
                "parallel": bool(self.targetoptions.get("parallel")),
            })

    nd.Dispatcher.compile = compile
if what == "torch":
    import torch
elif what == "id":
    import gymnasium as gym
    import envs
    env = gym.make(env_id)
    env.reset(seed=0)
    env.action_space.seed(0)
    env.step(env.action_space.sample())
else:
    from tests.numba_warmup import warm_up
    warm_up()
print("RESULT " + json.dumps(records))
"""


def measure(what: str, env_id: str, profile: bool, repo: Path) -> tuple[float, list[dict]]:
    """CPU seconds (user + system) of one fresh subprocess on an empty Numba cache, and its compilations."""
    with tempfile.TemporaryDirectory(prefix="numba-cold-") as cache:
        env = dict(os.environ, NUMBA_CACHE_DIR=cache, PYTHONPATH=str(repo), MPLBACKEND="Agg")
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        done = subprocess.run(
            [sys.executable, "-c", _CHILD, what, env_id, "1" if profile else "0"],
            cwd=repo,
            env=env,
            capture_output=True,
            text=True,
        )
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if done.returncode != 0:
        raise RuntimeError(f"{what} {env_id} failed:\n{done.stderr[-3000:]}")
    line = next(x for x in done.stdout.splitlines() if x.startswith("RESULT "))
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return cpu, json.loads(line[len("RESULT ") :])


def torch_available() -> bool:
    """Whether torch is installed (the anchor is skipped otherwise)."""
    import importlib.util

    return importlib.util.find_spec("torch") is not None


def profile_table(runs: dict[str, list[dict]]) -> str:
    """The compile profile: per function (own CPU time over every run, specialisations), then per specialisation."""
    lines = []
    for name, records in runs.items():
        compiled = [r for r in records if not r["loaded"]]
        own = sum(r["own"] for r in compiled)
        lines.append(f"\n== {name}: {len(compiled)} compilations, {own:.1f} s of CPU in Numba's compile ==")
        per_function: dict[str, list[dict]] = defaultdict(list)
        for r in compiled:
            per_function[r["function"]].append(r)
        ranked = sorted(per_function.items(), key=lambda item: -sum(r["own"] for r in item[1]))
        lines.append(f"{'own s':>7} {'spec':>4}  function (own s of each specialisation: argument types)")
        for function, specs in ranked:
            total = sum(r["own"] for r in specs)
            if total < 0.05 and len(specs) < 2:
                continue
            tag = " [parallel]" if specs[0]["parallel"] else ""
            lines.append(f"{total:7.2f} {len(specs):4d}  {function}{tag}")
            if len(specs) > 1 or total >= 1.0:
                for r in sorted(specs, key=lambda r: -r["own"]):
                    lines.append(f"{'':13}{r['own']:6.2f}  {_short(r['signature'])}")
    return "\n".join(lines)


def _short(signature: str, width: int = 400) -> str:
    """A signature, abbreviated: ``array(float64, 2d, C)`` → ``f8[2d,C]``; cut to ``width`` characters."""
    out = signature
    for long, short in (
        ("readonly array(float64, ", "ro f8["),
        ("readonly array(float32, ", "ro f4["),
        ("array(float64, ", "f8["),
        ("array(float32, ", "f4["),
        ("array(int64, ", "i8["),
        ("array(uint64, ", "u8["),
        ("array(bool, ", "b1["),
        (", C)", ",C]"),
        (", A)", ",A]"),
        (", F)", ",F]"),
        ("UniTuple(", "T("),
        ("Tuple(", "T("),
    ):
        out = out.replace(long, short)
    return out if len(out) <= width else out[: width - 1] + "…"


def summary(rows: list[tuple[str, float, float]], anchor: float | None) -> str:
    """The table of the measurements: CPU seconds, ratio to ``import torch`` and target of each."""
    width = max((len(r[0]) for r in rows), default=22) + 2
    lines = [f"{'measurement':<{width}} {'CPU s':>7} {'× torch':>8} {'target':>8}"]
    if anchor is not None:
        lines.append(f"{'import torch (anchor)':<{width}} {anchor:7.1f} {1.0:8.2f} {'':>8}")
    for name, cpu, target in rows:
        ratio = f"{cpu / anchor:8.2f}" if anchor else f"{'-':>8}"
        verdict = "ok" if cpu <= target else "over"
        limit = f"≤ {target:g} s"
        lines.append(f"{name:<{width}} {cpu:7.1f} {ratio} {limit:>8} {verdict}")
    ids = [r for r in rows if r[0].startswith("first step")]
    if ids:
        worst = max(ids, key=lambda r: r[1])
        lines.append(f"worst first step: {worst[0][len('first step ') :]} {worst[1]:.1f} s")
    return "\n".join(lines)


def _version(package: str) -> str:
    """The installed version of ``package``, or "?"."""
    import importlib.metadata

    try:
        return importlib.metadata.version(package)
    except importlib.metadata.PackageNotFoundError:
        return "?"


def _commit(repo: Path) -> str:
    """The short hash of the checkout measured (with "+" if it has uncommitted changes), or "?"."""
    try:
        head = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=repo, capture_output=True, text=True)
        dirty = subprocess.run(["git", "status", "--porcelain", "envs"], cwd=repo, capture_output=True, text=True)
    except OSError:
        return "?"
    return head.stdout.strip() + ("+" if dirty.stdout.strip() else "") if head.returncode == 0 else "?"


def main(argv: list[str] | None = None) -> None:
    """Measure the anchor, each id and the warm-up in fresh processes; print the table (and the profile)."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--ids", nargs="*", default=None, help="ids to measure (default: every id of envs.ENV_IDS; none: --ids alone)"
    )
    parser.add_argument("--no-warmup", action="store_true", help="skip the test suite's warm-up")
    parser.add_argument("--profile", action="store_true", help=f"write the compile profile to {PROFILE_PATH}")
    parser.add_argument("--profile-out", type=Path, default=PROFILE_PATH, help="where --profile writes its table")
    parser.add_argument("--repo", type=Path, default=ROOT, help="the checkout to measure (default: this one)")
    args = parser.parse_args(argv)
    if args.ids is None:
        sys.path.insert(0, str(args.repo))
        from envs import ENV_IDS

        args.ids = list(ENV_IDS)

    machine = (
        f"{platform.processor() or platform.machine()}, {os.cpu_count()} CPUs, Python {platform.python_version()}, "
        f"numba {_version('numba')}, repo {args.repo}"
    )
    print(f"# cold start: {machine}")
    anchor = measure("torch", "", False, args.repo)[0] if torch_available() else None
    rows, runs = [], {}
    for env_id in args.ids:
        cpu, records = measure("id", env_id, args.profile, args.repo)
        rows.append((f"first step {env_id}", cpu, TARGET_ID))
        runs[f"first step of {env_id}"] = records
        print(f"  {env_id}: {cpu:.1f} s", flush=True)
    if not args.no_warmup:
        cpu, records = measure("warmup", "", args.profile, args.repo)
        rows.append(("warm-up of every id (tests/numba_warmup.py)", cpu, TARGET_WARMUP))
        runs["the test suite's warm-up"] = records
    table = summary(rows, anchor)
    print("\n" + table)
    if args.profile:
        command = " ".join(["python -m benchmarks.bench_cold_start", *(argv if argv is not None else sys.argv[1:])])
        header = (
            f"Numba compile profile of the cold start ({command}; commit {_commit(args.repo)}): own CPU\n"
            "seconds of each compiled function (without the jitted functions it compiles in turn), per\n"
            "specialisation. Inlined functions (inline='always') count in their callers.\n"
            f"Machine: {machine}.\n"
        )
        args.profile_out.parent.mkdir(parents=True, exist_ok=True)
        args.profile_out.write_text(header + "\n" + table + "\n" + profile_table(runs) + "\n")
        print(f"compile profile written to {args.profile_out}")


if __name__ == "__main__":
    main()
