"""The env docstrings follow Gymnasium's layout and agree with the code (arguments, defaults, spaces, lengths)."""

from __future__ import annotations

import ast
import inspect
import re

import gymnasium as gym
import pytest

from envs import Planar3RPRReachEnv, Planar3RPRTrackEnv

ENV_CLASSES = [Planar3RPRReachEnv, Planar3RPRTrackEnv]

#: The sections of a Gymnasium environment page, in order.
SECTIONS = (
    "Description",
    "Action Space",
    "Observation Space",
    "Rewards",
    "Starting State",
    "Episode End",
    "Arguments",
    "Version History",
)

#: An id registered for each class (the one whose spec and spaces the docstring describes).
DEFAULT_ID = {Planar3RPRReachEnv: "Planar3RPRReach-v0", Planar3RPRTrackEnv: "Planar3RPRTrack-v0"}


def _sections(cls: type) -> dict[str, str]:
    """Markdown sections ``## Name`` of a class docstring, name → body."""
    doc = inspect.getdoc(cls)
    assert doc, f"{cls.__name__} has no docstring"
    parts = re.split(r"^## +(.+?) *$", doc, flags=re.MULTILINE)
    return {name: body for name, body in zip(parts[1::2], parts[2::2])}


def _table(body: str) -> list[list[str]]:
    """Rows (cells stripped) of the first markdown table of a section, header and separator removed."""
    lines = [line.strip() for line in body.splitlines() if line.strip().startswith("|")]
    assert len(lines) >= 3, f"no markdown table in:\n{body}"
    rows = [[cell.strip() for cell in line.strip("|").split("|")] for line in lines]
    assert set("".join(rows[1])) <= set("-: "), f"second row is not a separator: {rows[1]}"
    return [rows[0], *rows[2:]]


def _arguments(cls: type) -> dict[str, str]:
    """Parameter name → Default cell of the Arguments table."""
    header, *rows = _table(_sections(cls)["Arguments"])
    assert header == ["Parameter", "Type", "Default", "Description"], header
    names = [row[0] for row in rows]
    assert len(names) == len(set(names)), f"duplicate rows in {names}"
    out = {}
    for row in rows:
        assert len(row) == 4, row
        name, default = row[0], row[2]
        assert re.fullmatch(r"`\w+`", name), f"parameter cell {name!r} is not a backticked name"
        assert re.fullmatch(r"`[^`]+`", default), f"default cell {default!r} of {name} is not backticked"
        out[name.strip("`")] = default.strip("`")
    return out


@pytest.mark.parametrize("cls", ENV_CLASSES)
def test_docstring_has_gymnasium_sections(cls):
    """The class docstring has every section of a Gymnasium env page, in order."""
    names = list(_sections(cls))
    assert [n for n in names if n in SECTIONS] == list(SECTIONS), names


@pytest.mark.parametrize("cls", ENV_CLASSES)
def test_arguments_table_lists_every_parameter(cls):
    """Every constructor parameter has a row and every row is a constructor parameter."""
    documented = set(_arguments(cls))
    parameters = set(inspect.signature(cls.__init__).parameters) - {"self"}
    assert documented - parameters == set(), f"documented but not accepted: {documented - parameters}"
    assert parameters - documented == set(), f"accepted but not documented: {parameters - documented}"


@pytest.mark.parametrize("cls", ENV_CLASSES)
def test_arguments_table_defaults_match_the_signature(cls):
    """The Default column, read with ast.literal_eval, equals each constructor default."""
    signature = inspect.signature(cls.__init__)
    mismatches = []
    for name, text in _arguments(cls).items():
        if name not in signature.parameters:
            mismatches.append(f"{name}: documented but not a parameter")
            continue
        default = signature.parameters[name].default
        assert default is not inspect.Parameter.empty, f"{name} has no default"
        documented = ast.literal_eval(text)
        if isinstance(default, tuple):
            same = isinstance(documented, tuple) and documented == pytest.approx(default, rel=1e-15, abs=0)
        else:
            same = type(documented) is type(default) and documented == default
        if not same:
            mismatches.append(f"{name}: documented {documented!r}, signature {default!r}")
    assert not mismatches, "\n".join(mismatches)


def _declared_shape(body: str) -> tuple[int, ...]:
    match = re.search(r"`Box\([^`]*?(\(\d+(?:, *\d+)*,?\))[^`]*\)`", body)
    assert match, f"no `Box(..., shape, ...)` in:\n{body}"
    return ast.literal_eval(match.group(1))


@pytest.mark.parametrize("cls", ENV_CLASSES)
def test_documented_spaces_match_the_env(cls, make_env):
    """The Action and Observation Space sections state the real shapes; the table covers every entry once."""
    sections = _sections(cls)
    env = make_env(DEFAULT_ID[cls])
    assert _declared_shape(sections["Action Space"]) == env.action_space.shape
    shape = _declared_shape(sections["Observation Space"])
    assert shape == env.observation_space.shape
    header, *rows = _table(sections["Observation Space"])
    assert header[0] == "Num", header
    covered: list[int] = []
    for row in rows:
        bounds = [int(v) for v in row[0].split("-")]
        covered += range(bounds[0], bounds[-1] + 1)
    assert sorted(covered) == list(range(shape[0])), f"table rows cover {sorted(covered)}"


@pytest.mark.parametrize("cls", ENV_CLASSES)
def test_documented_episode_length_matches_the_registry(cls):
    """The Episode End section's "Truncation after N steps" is the registered max_episode_steps."""
    match = re.search(r"[Tt]runcation after (\d+) steps", _sections(cls)["Episode End"])
    assert match, "Episode End does not state the truncation length"
    assert int(match.group(1)) == gym.spec(DEFAULT_ID[cls]).max_episode_steps
