"""The env docstrings follow Gymnasium's layout and agree with the code (arguments, defaults, spaces, lengths)."""

from __future__ import annotations

import ast
import dataclasses
import inspect
import re

import gymnasium as gym
import pytest

from envs import ENV_IDS, FamilyParams, FamilyReachEnv, FamilyTrackEnv
from envs import params as env_params

ENV_CLASSES = [FamilyReachEnv, FamilyTrackEnv]

#: Fields of ``FamilyParams`` the Arguments table leaves to its ``**kwargs`` row ("Newton, substeps, margins").
#: Every other field has a row of its own.
KWARGS_ROW_FIELDS = {
    "newton_tolerance",
    "newton_max_iterations",
    "jump_tolerance",
    "max_substep",
    "max_substeps",
    "stroke_margin",
    "segment_spacing",
    "min_distance",
}

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
#: The generic ids, whose kwargs are empty: the class defaults (the hexapod).
DEFAULT_ID = {FamilyReachEnv: "ParallelRobotReach-v0", FamilyTrackEnv: "ParallelRobotTrack-v0"}


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


def _argument_rows(cls: type) -> dict[str, list[str]]:
    """Parameter name → row of the Arguments table (``**kwargs`` included, as "**kwargs")."""
    header, *rows = _table(_sections(cls)["Arguments"])
    assert header == ["Parameter", "Type", "Default", "Description"], header
    names = [row[0] for row in rows]
    assert len(names) == len(set(names)), f"duplicate rows in {names}"
    for row in rows:
        assert len(row) == 4, row
    return {row[0].strip("`"): row for row in rows}


def _arguments(cls: type) -> dict[str, str]:
    """Parameter name → Default cell of the Arguments table (the ``**kwargs`` row left out)."""
    out = {}
    for row in _argument_rows(cls).values():
        name, default = row[0], row[2]
        if name == "`**kwargs`":
            assert default == "", f"the **kwargs row has a default: {default!r}"
            continue
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
    """Every named parameter and every FamilyParams field (but those of the **kwargs row) has a row; no other."""
    documented = set(_argument_rows(cls))
    signature = inspect.signature(cls.__init__).parameters
    named = {n for n, p in signature.items() if n != "self" and p.kind is not inspect.Parameter.VAR_KEYWORD}
    assert "kwargs" in signature and "**kwargs" in documented, "the **kwargs row (FamilyParams fields) is missing"
    fields = {f.name for f in dataclasses.fields(FamilyParams)} - {"robot"}
    assert KWARGS_ROW_FIELDS <= fields, KWARGS_ROW_FIELDS - fields
    accepted = named | fields | {"**kwargs"}
    expected = named | (fields - KWARGS_ROW_FIELDS) | {"**kwargs"}
    assert documented - accepted == set(), f"documented but not accepted: {sorted(documented - accepted)}"
    assert expected - documented == set(), f"accepted but not documented: {sorted(expected - documented)}"


@pytest.mark.parametrize("cls", ENV_CLASSES)
def test_arguments_table_names_every_choice(cls):
    """The rows of the string-valued choices name every accepted value (render modes, hard kinds, …)."""
    rows = _argument_rows(cls)
    choices = {
        "render_mode": tuple(cls.metadata["render_modes"]),
        "integrator": env_params.INTEGRATORS,
        "hard_kind": env_params.HARD_KINDS,
        "task_region": env_params.TASK_REGIONS,
        "track_shape": env_params.TRACK_SHAPES,
    }
    if cls is FamilyReachEnv:
        choices["targets"] = env_params.TARGET_MODES
    missing = []
    for name, values in choices.items():
        description = rows[name][3] if name in rows else ""
        missing += [f"{name}: {value!r}" for value in values if f'"{value}"' not in description]
    assert not missing, "values not named in the Arguments table:\n" + "\n".join(missing)


@pytest.mark.parametrize("cls", ENV_CLASSES)
def test_arguments_table_defaults_match_the_signature(cls):
    """The Default column, read with ast.literal_eval, equals each constructor default (or the params it builds)."""
    signature = inspect.signature(cls.__init__)
    params = cls().params  # what the defaults build: the fields of **kwargs
    mismatches = []
    for name, text in _arguments(cls).items():
        if name in signature.parameters:
            default = signature.parameters[name].default
            assert default is not inspect.Parameter.empty, f"{name} has no default"
        elif name in {f.name for f in dataclasses.fields(FamilyParams)}:
            default = getattr(params, name)
            assert default == FamilyParams.__dataclass_fields__[name].default, (
                f"{name}: the class default is not the field's"
            )
        else:
            mismatches.append(f"{name}: documented but not a parameter")
            continue
        documented = ast.literal_eval(text)
        if isinstance(default, tuple):
            same = isinstance(documented, tuple) and documented == pytest.approx(default, rel=1e-15, abs=0)
        else:
            same = type(documented) is type(default) and documented == default
        if not same:
            mismatches.append(f"{name}: documented {documented!r}, signature {default!r}")
    assert not mismatches, "\n".join(mismatches)


def _declared_size(body: str, symbol: str) -> None:
    """Assert the section declares `Box(..., (symbol,), ...)`."""
    assert re.search(rf"`Box\([^`]*?\({symbol},\)[^`]*\)`", body), f"no `Box(..., ({symbol},), ...)` in:\n{body}"


#: (pose space, an id of that space, an id of it with Track's velocity or None) the Observation Space section sizes.
SIZE_IDS = {
    "spatial": ("StewartGoughReach-v0", "StewartGoughTrack-v0"),
    "planar": ("Planar3RRRReach-v0", None),
    "translational": ("DeltaReach-v0", "DeltaTrack-v0"),
}


def test_documented_spaces_match_the_env(make_env):
    """The Action and Observation Space sections state the real sizes; the table covers every entry once."""
    sections = _sections(FamilyReachEnv)
    _declared_size(sections["Action Space"], "n")
    _declared_size(sections["Observation Space"], "D")
    for env_id in ENV_IDS:
        env = make_env(env_id)
        assert env.action_space.shape == (env.unwrapped.params.robot.n_actuators,), env_id
    text = " ".join(sections["Observation Space"].split())
    sizes = {
        "spatial": re.search(r"spatial robots \(D = (\d+), or (\d+) with Track's velocity\)", text),
        "planar": re.search(r"Planar robots: .*?\(D = (\d+)\)", text),
        "translational": re.search(r"Translational robots .*?\(D = (\d+); (\d+) with Track's velocity\)", text),
    }
    for space, match in sizes.items():
        assert match, f"the Observation Space section does not state D for {space} robots"
        reach_id, track_id = SIZE_IDS[space]
        robot = make_env(reach_id).unwrapped.params.robot
        assert robot.pose_space.name == space
        assert make_env(reach_id).observation_space.shape == (int(match.group(1)),), reach_id
        if track_id is not None:
            assert make_env(track_id).observation_space.shape == (int(match.group(2)),), track_id
            assert int(match.group(2)) == int(match.group(1)) + robot.n_pose
    # The table is the spatial layout, Track's velocity included.
    header, *rows = _table(sections["Observation Space"])
    assert header[0] == "Num", header
    covered: list[int] = []
    for row in rows:
        bounds = [int(v) for v in row[0].split("-")]
        covered += range(bounds[0], bounds[-1] + 1)
    assert sorted(covered) == list(range(int(sizes["spatial"].group(2)))), f"table rows cover {sorted(covered)}"
    track = _sections(FamilyTrackEnv)["Observation Space"]
    assert "plus the target velocity (m values)" in " ".join(track.split())


@pytest.mark.parametrize("cls", ENV_CLASSES)
def test_documented_episode_length_matches_the_registry(cls):
    """The Episode End section's truncation length is the registered max_episode_steps of every id of the class."""
    body = " ".join(_sections(cls)["Episode End"].split())
    match = re.search(r"[Tt]runcation after the registered (\d+) steps|\((\d+) steps\)", body)
    assert match, "Episode End does not state the truncation length"
    length = int(match.group(1) or match.group(2))
    assert length == gym.spec(DEFAULT_ID[cls]).max_episode_steps
    entry_point = f"envs.env:{cls.__name__}"
    for env_id in ENV_IDS:
        if gym.spec(env_id).entry_point == entry_point:
            assert gym.spec(env_id).max_episode_steps == length, env_id
