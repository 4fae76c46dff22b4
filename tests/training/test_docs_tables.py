"""experiments.docs_tables: the documentation's tables are their files, never typed."""

from __future__ import annotations

from pathlib import Path

import pytest

from experiments import docs_tables

ROOT = Path(__file__).resolve().parents[2]


def test_every_generated_block_of_the_docs_is_its_file():
    """README.md and docs/*.md hold exactly the files their generated blocks name (``experiments.docs_tables``)."""
    assert docs_tables.refresh(ROOT, check=True) == []


def test_a_stale_block_is_found_and_refreshed(tmp_path):
    """--check names a stale block; a refresh writes the file in (title dropped, pictures re-rooted)."""
    (tmp_path / "docs" / "results" / "run").mkdir(parents=True)
    source = tmp_path / "docs" / "results" / "run" / "report.md"
    source.write_text("# Sweep report\n\n| a | b |\n|---|---|\n| 1 | 2 |\n\n![profile](performance_profile.png)\n")
    page = tmp_path / "docs" / "results.md"
    page.write_text(
        "Intro.\n\n<!-- generated: docs/results/run/report.md -->\n| typed |\n<!-- end generated -->\n\nEnd.\n"
    )
    assert docs_tables.main(["--root", str(tmp_path), "--check"]) == 1
    assert docs_tables.main(["--root", str(tmp_path)]) == 0
    text = page.read_text()
    assert "| typed |" not in text and "# Sweep report" not in text
    assert "| 1 | 2 |\n\n![profile](results/run/performance_profile.png)\n<!-- end generated -->" in text
    assert text.startswith("Intro.") and text.endswith("End.\n")
    assert docs_tables.main(["--root", str(tmp_path), "--check"]) == 0


def test_a_block_naming_a_missing_file_is_an_error(tmp_path, capsys):
    """The block's file must exist; the error names the page and the file."""
    (tmp_path / "docs").mkdir()
    (tmp_path / "docs" / "page.md").write_text("<!-- generated: docs/nowhere.md -->\n<!-- end generated -->\n")
    with pytest.raises(SystemExit):
        docs_tables.main(["--root", str(tmp_path), "--check"])
    assert "docs/page.md: generated block names" in capsys.readouterr().err
