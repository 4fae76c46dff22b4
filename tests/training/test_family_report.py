"""experiments.family_report: tables made from evaluation metrics, grouped over seeds."""

from __future__ import annotations

import json

from experiments import family_report


def _metrics(label: str, success: float, rms: float | None = None) -> dict:
    stat = {"mean": 1.0, "std": 0.0, "median": 1.0}
    m = {
        "label": label,
        "episodes": 10,
        "success_rate": success,
        "final_position_error_mm": stat,
        "final_orientation_error_deg": stat,
        "min_inverse_condition": {**stat, "min": 0.5},
        "singularity_terminations": 1,
        "cost_fraction": stat,
    }
    if rms is not None:
        keys = ("rms_position_mm", "max_position_mm", "rms_orientation_deg", "cost_fraction", "lag_s")
        m["tracking"] = {"settling_s": 1.0, **{k: {"mean": rms, "std": 0.0, "median": rms} for k in keys}}
    return m


def test_seeds_are_grouped_and_tracking_is_tabulated(tmp_path):
    """Two seeds of one agent make one row (mean ± std); Track metrics get their own table; others do not."""
    folders = []
    for i, (label, success, rms) in enumerate(
        [("ppo (run-s0) @ track", 1.0, 0.5), ("ppo (run-s1) @ track", 0.8, 0.7), ("resolved-rate @ hard", 0.1, None)]
    ):
        folder = tmp_path / f"e{i}"
        folder.mkdir()
        (folder / "metrics.json").write_text(json.dumps(_metrics(label, success, rms)))
        folders.append(str(folder))
    out = tmp_path / "table.md"
    assert family_report.main([str(out), *folders]) == 0
    text = out.read_text()
    assert "| ppo @ track | 2 | 90.0 ± 14.1 % |" in text
    assert "| resolved-rate @ hard | 1 | 10.0 % |" in text
    tracking = text.split("Tracking:")[1]
    assert "| ppo @ track | 2 | 0.60 ± 0.14 |" in tracking
    assert "resolved-rate" not in tracking
    assert "The planner's plans" not in text


def test_the_return_column_is_optional(tmp_path):
    """--with-return adds the episode return (mean ± std over runs); without it the table is unchanged."""
    folders = []
    for i, ret in enumerate((-10.0, -20.0)):
        folder = tmp_path / f"e{i}"
        folder.mkdir()
        m = _metrics(f"ppo (run-s{i}) @ hard", 1.0)
        m["return"] = {"mean": ret, "std": 1.0, "median": ret}
        (folder / "metrics.json").write_text(json.dumps(m))
        folders.append(str(folder))
    plain, with_return = tmp_path / "plain.md", tmp_path / "return.md"
    family_report.main([str(plain), *folders])
    family_report.main([str(with_return), *folders, "--with-return"])
    assert "return" not in plain.read_text()
    text = with_return.read_text()
    assert "| return (mean) |" in text
    assert text.splitlines()[2].endswith("| 1.000 | -15.0 ± 7.1 |")


def test_by_recipe_groups_the_seeds_of_each_run_name(tmp_path):
    """--by-recipe: runs named R-sN make one row per R; without it every ppo run is one row."""
    folders = []
    for i, (label, success) in enumerate(
        [("ppo (a-lrd-s0) @ hard", 1.0), ("ppo (a-lrd-s1) @ hard", 0.8), ("ppo (a-cap-s0) @ hard", 0.5)]
    ):
        folder = tmp_path / f"e{i}"
        folder.mkdir()
        (folder / "metrics.json").write_text(json.dumps(_metrics(label, success)))
        folders.append(str(folder))
    out = tmp_path / "table.md"
    family_report.main([str(out), *folders, "--by-recipe"])
    text = out.read_text()
    assert "| ppo (a-lrd) @ hard | 2 | 90.0 ± 14.1 % |" in text
    assert "| ppo (a-cap) @ hard | 1 | 50.0 % |" in text
    family_report.main([str(out), *folders])
    assert "| ppo @ hard | 3 | 76.7 ± 25.2 % |" in out.read_text()
