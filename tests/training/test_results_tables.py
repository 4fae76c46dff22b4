"""The results tables under docs/results are what their commands write from the stored metrics.json files."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from experiments import demo, family_report, geometry_report, plan_free_report

ROOT = Path(__file__).resolve().parents[2]
RESULTS = ROOT / "docs" / "results"

#: ``experiments.family_report`` tables: file → (its evaluation folders as the docs' commands glob them, flags).
FAMILY_REPORT_TABLES = {
    "baselines_cranks/table.md": (["baselines_cranks/*/"], ["--by-env"]),
    "baselines_hexapod/table.md": (["baselines_hexapod/*/"], []),
    "baselines_planar3rpr/table.md": (["baselines_planar3rpr/*/"], []),
    "residual_planar3rpr/table.md": (
        ["residual_planar3rpr/s*/", "baselines_planar3rpr/planner-*/"],
        ["--with-return"],
    ),
    "sweep_planar3rpr_mixed300/table_300_steps.md": (["sweep_planar3rpr_mixed300/eval300/*/"], []),
    "track_planar3rpr/table.md": (["track_planar3rpr/*/"], []),
    "planner_family/table.md": (["planner_family/*/"], ["--by-env"]),
}


def _glob(pattern: str) -> list[str]:
    """A shell's ``docs/results/<pattern>`` (folders, sorted as the C locale sorts them with their slash)."""
    return sorted(f"{path}/" for path in RESULTS.glob(pattern.rstrip("/")) if path.is_dir())


def _copy_metrics(source: Path, target: Path) -> None:
    """Copy the ``<folder>/metrics.json`` files of ``source`` (and nothing else) under ``target``."""
    for path in source.glob("*/metrics.json"):
        (target / path.parent.name).mkdir(parents=True, exist_ok=True)
        shutil.copy(path, target / path.parent.name / "metrics.json")


@pytest.mark.parametrize("table", FAMILY_REPORT_TABLES)
def test_family_report_tables_are_their_metrics(table, tmp_path):
    """``python -m experiments.family_report`` on the stored evaluations writes the stored table, byte for byte."""
    patterns, flags = FAMILY_REPORT_TABLES[table]
    out = tmp_path / "table.md"
    assert family_report.main([str(out), *[f for p in patterns for f in _glob(p)], *flags]) == 0
    assert out.read_text() == (RESULTS / table).read_text()


@pytest.mark.parametrize(
    ("folder", "runs", "env_id", "with_residual", "first_seed"),
    [
        ("plan_free_planar3rpr", "distill-3rpr", "Planar3RPRReach-v0", True, 5000),
        ("plan_free_planar3rpr_damped", "distill-3rpr-damped", "Planar3RPRReach-v0", True, 5000),
        ("plan_free_planar3rpr_finetuned", "ft-3rpr", "Planar3RPRReach-v0", True, 5000),
        ("plan_free_planar3rpr_best", "distill-3rpr-best", "Planar3RPRReach-v0", True, 5000),
        ("plan_free_planar3rrr", "distill-3rrr", "Planar3RRRReach-v0", False, 5000),
        ("force_control/plan_free", "fd-3rpr", "Planar3RPRForceReach-v0", False, 0),
    ],
)
def test_plan_free_tables_are_their_metrics(folder, runs, env_id, with_residual, first_seed, tmp_path):
    """``plan_free_report --from-metrics`` writes the stored table from the stored evaluations, and only that."""
    _copy_metrics(RESULTS / folder, tmp_path)
    run_dirs = [f"runs/{runs}-s{seed}" for seed in range(3)]
    residual = ["--residual", "training/pretrained/ppo-Planar3RPRReachMixed-v0"] if with_residual else []
    argv = ["--runs", *run_dirs, "--env", env_id, *residual, "--seed", str(first_seed), "--out", str(tmp_path)]
    assert plan_free_report.main([*argv, "--from-metrics"]) == 0
    assert (tmp_path / "table.md").read_text() == (RESULTS / folder / "table.md").read_text()
    assert not (tmp_path / "timing.md").exists() and not (tmp_path / "paths_hard.png").exists()


def test_geometry_table_is_its_metrics(tmp_path):
    """``geometry_report --from-metrics`` writes the stored table without loading a run (the runs are absent)."""
    _copy_metrics(RESULTS / "geometry_family", tmp_path)
    runs = {kind: [f"runs/{kind}-s{seed}" for seed in range(3)] for kind in ("family", "nominal")}
    argv = ["--family", *runs["family"], "--nominal", *runs["nominal"], "--out", str(tmp_path), "--from-metrics"]
    assert geometry_report.main(argv) == 0
    assert (tmp_path / "table.md").read_text() == (RESULTS / "geometry_family" / "table.md").read_text()


def test_a_missing_evaluation_is_an_error_with_from_metrics(tmp_path, capsys):
    """--from-metrics never evaluates: a missing metrics.json stops the report and names the file."""
    argv = ["--family", "runs/family-s0", "--nominal", "runs/nominal-s0", "--out", str(tmp_path), "--from-metrics"]
    with pytest.raises(SystemExit):
        geometry_report.main(argv)
    assert "family-s0-family-standard/metrics.json is missing" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        plan_free_report.main(
            ["--runs", "runs/x", "--env", "Planar3RPRReach-v0", "--out", str(tmp_path), "--from-metrics"]
        )
    assert "planner-standard/metrics.json is missing" in capsys.readouterr().err


def test_main_job_reports_are_their_metrics(tmp_path, monkeypatch):
    """``experiments.demo --from-metrics`` writes each stored report of the main job from its stored metrics file."""
    monkeypatch.chdir(ROOT)  # the reports name the shipped runs relative to the checkout
    stored = RESULTS / "demo"
    for path in stored.glob("*metrics.json"):
        shutil.copy(path, tmp_path / path.name)
    assert demo.main(["--from-metrics", "--out", str(tmp_path)]) == 0
    reports = sorted(path.name for path in tmp_path.glob("*.md"))
    assert reports == sorted(path.name for path in stored.glob("*.md"))
    for name in reports:
        assert (tmp_path / name).read_text() == (stored / name).read_text(), name
