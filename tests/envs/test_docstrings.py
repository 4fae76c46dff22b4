"""The env docstrings follow Gymnasium's layout and agree with the code (arguments, defaults, spaces, lengths)."""

from __future__ import annotations

import ast
import dataclasses
import inspect
import re

import gymnasium as gym
import pytest
from gymnasium.vector import AutoresetMode

from envs import ENV_IDS, FamilyParams, FamilyReachEnv, FamilyTrackEnv, presets
from envs import params as env_params
from envs.arguments import Choice, Range, Vector
from envs.vector import VECTOR_ARGUMENTS, FamilyVectorEnv

ENV_CLASSES = [FamilyReachEnv, FamilyTrackEnv]

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
    """Parameter name → row (Parameter, Type, Default, Description) of the Arguments table, in table order."""
    header, *rows = _table(_sections(cls)["Arguments"])
    assert header == ["Parameter", "Type", "Default", "Description"], header
    for row in rows:
        assert len(row) == 4, f"not 4 cells (a stray '|'?): {row}"
        assert re.fullmatch(r"`(\*\*)?\w+`", row[0]), f"parameter cell {row[0]!r} is not a backticked name"
    names = [row[0] for row in rows]
    assert len(names) == len(set(names)), f"duplicate rows in {names}"
    return {row[0].strip("`"): row for row in rows}


def _default(cell: str) -> tuple[object, bool]:
    """The Default cell read back: (the value, by ``ast.literal_eval``; whether it is marked † per robot)."""
    match = re.fullmatch(r"`([^`]+)`( †)?", cell)
    assert match, f"default cell {cell!r} is not a backticked literal, optionally marked †"
    return ast.literal_eval(match.group(1)), match.group(2) is not None


def _same(documented: object, actual: object) -> bool:
    """Equal and of one type (0.0 is not 0), tuples elementwise to the last bit of a float."""
    if isinstance(actual, tuple):
        return isinstance(documented, tuple) and documented == pytest.approx(actual, rel=1e-15, abs=0)
    return type(documented) is type(actual) and documented == actual


@pytest.mark.parametrize("cls", ENV_CLASSES)
def test_docstring_has_gymnasium_sections(cls):
    """The class docstring has every section of a Gymnasium env page, in order."""
    names = list(_sections(cls))
    assert [n for n in names if n in SECTIONS] == list(SECTIONS), names


@pytest.mark.parametrize("cls", ENV_CLASSES)
def test_every_keyword_argument_has_metadata_and_a_row(cls):
    """The constructor's keywords (named, and every FamilyParams field through **kwargs) = the metadata = the rows."""
    signature = inspect.signature(cls.__init__).parameters
    named = {n for n, p in signature.items() if n != "self" and p.kind is not inspect.Parameter.VAR_KEYWORD}
    assert "kwargs" in signature, "the FamilyParams fields are no longer taken through **kwargs"
    fields = {f.name for f in dataclasses.fields(FamilyParams)}
    accepted = named | fields
    described = [p.name for p in (*cls.named_arguments, *env_params.field_parameters())]
    assert len(described) == len(set(described)), f"described twice: {described}"
    assert accepted - set(described) == set(), f"keywords without metadata: {sorted(accepted - set(described))}"
    assert set(described) - accepted == set(), f"metadata of no keyword: {sorted(set(described) - accepted)}"
    assert list(_argument_rows(cls)) == described, "the Arguments table is not the metadata, in its order"


@pytest.mark.parametrize("cls", ENV_CLASSES)
def test_arguments_table_is_the_metadata(cls):
    """Each row shows its Parameter: the type text, the default (marked † per robot), description, unit and range."""
    rows = _argument_rows(cls)
    mismatches = []
    for p in (*cls.named_arguments, *env_params.field_parameters()):
        _, type_cell, default_cell, description = rows[p.name]
        assert p.description and type_cell, f"{p.name}: no description or type"
        default, per_robot = _default(default_cell)
        if not _same(default, p.default) or per_robot != p.per_robot:
            mismatches.append(f"{p.name}: table {default_cell}, metadata {p.default!r} (per robot: {p.per_robot})")
        if type_cell != p.type_text():
            mismatches.append(f"{p.name}: type {type_cell!r}, metadata {p.type_text()!r}")
        wanted = [p.description] + [f"[{p.unit}]"] * bool(p.unit)
        if isinstance(p.check, (Range, Vector)) and p.check.text:
            wanted.append(p.check.text)
        mismatches += [f"{p.name}: {text!r} not in {description!r}" for text in wanted if text not in description]
    assert not mismatches, "\n".join(mismatches)


@pytest.mark.parametrize("cls", ENV_CLASSES)
def test_arguments_table_defaults_are_what_the_constructor_builds(cls):
    """The Default column: each named argument's signature default, and each field's value in the built params."""
    signature = inspect.signature(cls.__init__).parameters
    params = cls().params  # what the defaults build (the hexapod): the fields of **kwargs
    mismatches = []
    for name, row in _argument_rows(cls).items():
        default, _ = _default(row[2])
        actual = signature[name].default if name in signature else getattr(params, name)
        if not _same(default, actual):
            mismatches.append(f"{name}: documented {default!r}, the constructor {actual!r}")
    assert not mismatches, "\n".join(mismatches)


def test_vector_arguments_table_is_its_metadata_and_signature():
    """The vector env's table: its own arguments (VECTOR_ARGUMENTS, signature defaults), then the single env's."""
    rows = _argument_rows(FamilyVectorEnv)
    signature = inspect.signature(FamilyVectorEnv.__init__).parameters
    named = [n for n, p in signature.items() if n != "self" and p.kind is not inspect.Parameter.VAR_KEYWORD]
    assert [p.name for p in VECTOR_ARGUMENTS] == named
    assert list(rows) == [*named, "**kwargs"]
    for p in VECTOR_ARGUMENTS:
        text = re.fullmatch(r"`([^`]+)`", rows[p.name][2]).group(1)
        default = AutoresetMode[text.split(".")[1]] if text.startswith("AutoresetMode.") else ast.literal_eval(text)
        assert _same(default, signature[p.name].default) and _same(default, p.default), (p.name, text)
        assert rows[p.name][1] == p.type_text() and rows[p.name][3] == p.describe(), rows[p.name]


def test_per_robot_marks_are_the_fields_presets_and_sizes_set():
    """† marks exactly the fields a preset of ROBOT_PRESETS or ``derived_defaults`` (any robot of ROBOTS) sets."""
    set_per_robot = set()
    for preset in presets.ROBOT_PRESETS.values():
        set_per_robot |= set(preset) - {"robot"}
    for robot in presets.ROBOTS.values():
        set_per_robot |= set(presets.derived_defaults(robot()))
    marked = {p.name for p in env_params.field_parameters() if p.per_robot}
    assert marked - set_per_robot == set(), f"marked † but set by no preset: {sorted(marked - set_per_robot)}"
    assert set_per_robot - marked == set(), f"set per robot but not marked †: {sorted(set_per_robot - marked)}"


@pytest.mark.parametrize("cls", ENV_CLASSES)
def test_arguments_table_names_every_choice(cls):
    """The rows of the string-valued choices name every accepted value (render modes, hard kinds, …)."""
    rows = _argument_rows(cls)
    choices = {"render_mode": tuple(cls.metadata["render_modes"])}
    for p in (*cls.named_arguments, *env_params.field_parameters()):
        if isinstance(p.check, Choice):
            choices[p.name] = p.check.values
    assert {"integrator", "hard_kind", "task_region", "track_shape", "observation_source"} <= set(choices)
    missing = []
    for name, values in choices.items():
        missing += [f"{name}: {value!r}" for value in values if f'"{value}"' not in rows[name][3]]
    assert not missing, "values not named in the Arguments table:\n" + "\n".join(missing)


def test_family_params_attributes_are_the_metadata():
    """FamilyParams' docstring has one Attributes entry per field, in field order, its description from the metadata."""
    doc = inspect.getdoc(FamilyParams)
    entries = re.findall(r"^    (\w+): (.*)$", doc.split("Attributes:", 1)[1], flags=re.MULTILINE)
    assert [name for name, _ in entries] == [f.name for f in dataclasses.fields(FamilyParams)]
    for (name, text), p in zip(entries[1:], env_params.field_parameters()):
        assert text.lower().startswith(" ".join(p.describe().split())[:20].lower()), (name, text)


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
