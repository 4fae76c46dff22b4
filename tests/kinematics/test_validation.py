"""Bad inputs give precise errors; failures of the solvers are reported; the robot is immutable."""

from __future__ import annotations

import pickle
import re

import numpy as np
import pytest

from kinematics import ForwardKinematicsResult, Planar3RPR, SingularConfigurationError

X = np.array([0.5, 0.3, 0.1])
Q = Planar3RPR().inverse_kinematics(X)
V = np.array([1.0, 2.0, 3.0])

#: Every public method that takes q, with its other arguments valid: (name, call(robot, q)).
TAKES_Q = {
    "constraints": lambda r, q: r.constraints(q, X),
    "jacobians": lambda r, q: r.jacobians(q, X),
    "forward_jacobian": lambda r, q: r.forward_jacobian(q, X),
    "inverse_jacobian": lambda r, q: r.inverse_jacobian(q, X),
    "homogeneous_jacobian": lambda r, q: r.homogeneous_jacobian(q, X),
    "forward_kinematics": lambda r, q: r.forward_kinematics(q, X),
    "instantaneous_dof": lambda r, q: r.instantaneous_dof(q, X),
    "platform_mobility": lambda r, q: r.platform_mobility(q, X),
    "inverse_condition_number": lambda r, q: r.inverse_condition_number(q, X),
    "raw_condition_number": lambda r, q: r.raw_condition_number(q, X),
    "platform_wrench": lambda r, q: r.platform_wrench(q, X, V),
    "actuator_forces": lambda r, q: r.actuator_forces(q, X, V),
    "assembly_modes": lambda r, q: r.assembly_modes(q),
}

#: Every public method that takes a pose, with its other arguments valid.
TAKES_X = {
    "constraints": lambda r, x: r.constraints(Q, x),
    "jacobians": lambda r, x: r.jacobians(Q, x),
    "forward_jacobian": lambda r, x: r.forward_jacobian(Q, x),
    "inverse_jacobian": lambda r, x: r.inverse_jacobian(Q, x),
    "homogeneous_jacobian": lambda r, x: r.homogeneous_jacobian(Q, x),
    "inverse_kinematics": lambda r, x: r.inverse_kinematics(x),
    "leg_vectors": lambda r, x: r.leg_vectors(x),
    "platform_points_in_base": lambda r, x: r.platform_points_in_base(x),
    "instantaneous_dof": lambda r, x: r.instantaneous_dof(Q, x),
    "platform_mobility": lambda r, x: r.platform_mobility(Q, x),
    "inverse_condition_number": lambda r, x: r.inverse_condition_number(Q, x),
    "raw_condition_number": lambda r, x: r.raw_condition_number(Q, x),
    "platform_wrench": lambda r, x: r.platform_wrench(Q, x, V),
    "actuator_forces": lambda r, x: r.actuator_forces(Q, x, V),
}

#: The other vector arguments: (argument name in messages, call(robot, value)).
OTHER_VECTORS = {
    "x_guess": lambda r, v: r.forward_kinematics(Q, v),
    "tau": lambda r, v: r.platform_wrench(Q, X, v),
    "wrench": lambda r, v: r.actuator_forces(Q, X, v),
}

ALL_VECTORS = (
    [("q", name, call) for name, call in TAKES_Q.items()]
    + [("x", name, call) for name, call in TAKES_X.items()]
    + [(arg, arg, call) for arg, call in OTHER_VECTORS.items()]
)
VECTOR_IDS = [f"{arg}-{name}" for arg, name, _ in ALL_VECTORS]


#: Constructor arguments of a few robots.
ROBOT_ARGUMENTS = {
    "lesson": {},
    "characteristic_length": {"characteristic_length": 0.7},
    "singular_tolerance": {"singular_tolerance": 1e-8},
    "both_scalars": {"characteristic_length": 0.7, "singular_tolerance": 1e-8},
    "geometry": {
        "base": [[0.1, 0.2], [1.5, -0.3], [0.4, 1.1]],
        "platform": [[0.05, 0.0], [-0.1, 0.2], [0.0, -0.15]],
    },
}


# -- vectors: shape, values, types ------------------------------------------------------------------


@pytest.mark.parametrize("shape", [(2,), (4,), (3, 4), (3, 2), ()])
@pytest.mark.parametrize(("arg", "name", "call"), ALL_VECTORS, ids=VECTOR_IDS)
def test_wrong_shape_names_argument_expected_and_actual(arg, name, call, shape, robot):
    """A vector of the wrong shape: ValueError naming the argument, (..., 3) and the actual shape."""
    expected = rf"^{arg} must have shape \(\.\.\., 3\) holding .*, got shape {re.escape(str(shape))}$"
    with pytest.raises(ValueError, match=expected):
        call(robot, np.full(shape, 0.5))


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
@pytest.mark.parametrize(("arg", "name", "call"), ALL_VECTORS, ids=VECTOR_IDS)
def test_non_finite_values_are_rejected(arg, name, call, bad, robot):
    """NaN or ±inf anywhere: ValueError naming the argument, the value and its index."""
    value = np.array([[0.5, 0.6, 0.7], [0.5, 0.6, bad]])
    if name == "assembly_modes":
        value = value[1]
    index = re.escape(str((2,) if name == "assembly_modes" else (1, 2)))
    with pytest.raises(ValueError, match=rf"^{arg} must be finite, got 1 non-finite .*{bad!r}.* {index}"):
        call(robot, value)


@pytest.mark.parametrize("size", [1, 400, 5000])
@pytest.mark.parametrize("bad", [np.nan, -np.inf])
def test_non_finite_values_are_found_in_batches_of_any_size(size, bad, robot):
    """Small and large batches (which take different fast paths) both catch one bad entry."""
    x = np.tile(X, (size, 1))
    x[-1, 0] = bad
    with pytest.raises(ValueError, match=rf"^x must be finite, got 1 non-finite .* at index \({size - 1}, 0\)"):
        robot.inverse_kinematics(x)


@pytest.mark.filterwarnings("ignore:overflow encountered:RuntimeWarning")
@pytest.mark.parametrize("size", [1, 5000])
def test_huge_finite_values_are_not_mistaken_for_non_finite(size, robot):
    """Finite values whose squares overflow are still accepted (the fast check only raises an alarm)."""
    x = np.full((size, 3), 1e160)
    assert np.all(np.isfinite(robot.leg_vectors(x)))


@pytest.mark.parametrize(
    ("value", "message"),
    [
        ("abc", r"must be an array of real numbers, got dtype <U3"),
        (["0.5", "0.6", "0.7"], r"must be an array of real numbers, got dtype <U3"),
        ([0.5, 0.6, 0.7 + 1j], r"must be real, got complex dtype complex128"),
        ([0.5, None, 0.7], r"must be an array of real numbers, got dtype object"),
        ([[0.5, 0.6], [0.7]], r"must be an array of real numbers, got (list|dtype object)"),
        ({"x": 1.0}, r"must be an array of real numbers, got dtype object"),
    ],
    ids=["string", "strings", "complex", "object", "ragged", "dict"],
)
@pytest.mark.parametrize(("arg", "name", "call"), ALL_VECTORS, ids=VECTOR_IDS)
def test_non_real_inputs_raise_type_error(arg, name, call, value, message, robot):
    """Strings, complex numbers and objects: TypeError naming the argument and what it got."""
    with pytest.raises(TypeError, match=rf"^{arg} {message}"):
        call(robot, value)


def test_integer_and_boolean_arrays_are_accepted(robot):
    """Integer arrays are real numbers and are converted to float64."""
    np.testing.assert_array_equal(robot.inverse_kinematics([1, 1, 0]), robot.inverse_kinematics([1.0, 1.0, 0.0]))
    assert robot.constraints(np.array([1, 1, 1]), X).dtype == np.float64


@pytest.mark.parametrize("length", [0.0, -0.3, -1e-300])
@pytest.mark.parametrize("name", sorted(TAKES_Q))
def test_non_positive_leg_length_is_rejected(name, length, robot):
    """A leg length ≤ 0 is not a configuration of the robot: ValueError naming the minimum."""
    q = np.array([[0.6, 0.6, 0.6], [0.6, length, 0.6]])
    if name == "assembly_modes":
        q = q[1]
    with pytest.raises(ValueError, match=rf"^leg lengths q must be > 0 \[m\], got minimum {length!r}"):
        TAKES_Q[name](robot, q)


@pytest.mark.parametrize(
    ("q_shape", "x_shape"),
    [((2, 3), (4, 3)), ((4, 5, 3), (4, 3)), ((3, 3), (2, 1, 2, 3))],
)
@pytest.mark.parametrize("name", sorted(set(TAKES_Q) & set(TAKES_X)))
def test_batch_shapes_that_do_not_broadcast(name, q_shape, x_shape, robot):
    """Batches of q and x that do not broadcast: ValueError naming both batch shapes."""
    q, x = np.broadcast_to(Q, q_shape), np.broadcast_to(X, x_shape)
    extra = (V,) if name in ("platform_wrench", "actuator_forces") else ()
    expected = rf"batch shapes of q {re.escape(str(q_shape[:-1]))} and x {re.escape(str(x_shape[:-1]))}"
    with pytest.raises(ValueError, match=rf"^{expected} do not broadcast"):
        getattr(robot, name)(q, x, *extra)


def test_forward_kinematics_batch_shapes_that_do_not_broadcast(robot):
    """Batches of q and x_guess that do not broadcast: ValueError naming both."""
    with pytest.raises(ValueError, match=r"^batch shapes of q \(2,\) and x_guess \(4,\) do not broadcast"):
        robot.forward_kinematics(np.tile(Q, (2, 1)), np.tile(X, (4, 1)))


@pytest.mark.parametrize(
    ("name", "call"),
    [
        ("tau", lambda r, v: r.platform_wrench(np.tile(Q, (4, 1)), np.tile(X, (4, 1)), v)),
        ("wrench", lambda r, v: r.actuator_forces(np.tile(Q, (4, 1)), np.tile(X, (4, 1)), v)),
    ],
    ids=["tau", "wrench"],
)
def test_tau_and_wrench_batches_that_do_not_broadcast(name, call, robot):
    """A τ or wrench batch that does not broadcast with (q, x): ValueError naming the shapes."""
    with pytest.raises(ValueError, match=rf"^batch shapes of .*{name} \(2,\) do not broadcast"):
        call(robot, np.ones((2, 3)))


# -- the geometry -----------------------------------------------------------------------------------


@pytest.mark.parametrize("kind", ["base", "platform"])
@pytest.mark.parametrize("shape", [(2, 2), (3, 3), (3,), (6,), (1, 3, 2), ()])
def test_geometry_with_wrong_shape(kind, shape):
    """Base anchors and platform points must be (3, 2) arrays."""
    what = "base anchors" if kind == "base" else "platform points"
    with pytest.raises(ValueError, match=rf"^{what} must have shape \(3, 2\), got {re.escape(str(shape))}"):
        Planar3RPR(**{kind: np.ones(shape)})


@pytest.mark.parametrize("kind", ["base", "platform"])
@pytest.mark.parametrize("bad", [np.nan, np.inf])
def test_geometry_with_non_finite_values(kind, bad):
    """NaN or inf in the geometry: ValueError naming the quantity."""
    what = "base anchors" if kind == "base" else "platform points"
    value = np.array(Planar3RPR().base if kind == "base" else Planar3RPR().platform)
    value[2, 1] = bad
    with pytest.raises(ValueError, match=rf"^{what} must be finite, .*at index \(2, 1\)"):
        Planar3RPR(**{kind: value})


@pytest.mark.parametrize("kind", ["base", "platform"])
@pytest.mark.parametrize(
    ("value", "error", "message"),
    [
        ("abc", TypeError, r"must be an array of real numbers"),
        ([[1j, 0], [1, 0], [0, 1]], TypeError, r"must be real, got complex"),
        ([[None, 0], [1, 0], [0, 1]], TypeError, r"must be an array of real numbers, got dtype object"),
    ],
)
def test_geometry_that_is_not_real(kind, value, error, message):
    """Non-real geometry: TypeError naming the quantity."""
    what = "base anchors" if kind == "base" else "platform points"
    with pytest.raises(error, match=rf"^{what} {message}"):
        Planar3RPR(**{kind: value})


@pytest.mark.parametrize(
    ("points", "pair"),
    [
        ([[0.0, 0.0], [0.0, 0.0], [0.5, 0.8]], "1 and 2"),
        ([[0.0, 0.0], [1.0, 0.0], [1.0, 0.0]], "2 and 3"),
        ([[0.3, 0.2], [1.0, 0.0], [0.3, 0.2]], "1 and 3"),
    ],
)
@pytest.mark.parametrize("kind", ["base", "platform"])
def test_coincident_points(kind, points, pair):
    """Two coincident base anchors or platform points: ValueError naming which."""
    what = "base anchors" if kind == "base" else "platform points"
    with pytest.raises(ValueError, match=rf"^{what} must be pairwise distinct: points {pair} are 0 m apart"):
        Planar3RPR(**{kind: points})


@pytest.mark.parametrize(
    "base",
    [
        [[0.0, 0.0], [1.0, 0.0], [2.0, 0.0]],
        [[0.0, 0.0], [1.0, 1.0], [-3.0, -3.0]],
        [[0.0, 0.0], [1.0, 0.0], [0.5, 1e-12]],
    ],
)
def test_collinear_base_anchors(base):
    """Collinear base anchors make no triangle: ValueError stating the area and the bound."""
    with pytest.raises(ValueError, match=r"^base anchors must not be collinear: .* has area .* expected >"):
        Planar3RPR(base=base)


def test_collinear_platform_points_are_allowed():
    """A collinear platform (the lesson's P_2, P_3 and the origin lie on a line) is a valid design."""
    robot = Planar3RPR(platform=[[-0.2, 0.0], [0.0, 0.0], [0.2, 0.0]])
    assert robot.characteristic_length == 0.2


@pytest.mark.parametrize(
    ("value", "error", "message"),
    [
        (0.0, ValueError, r"must be a finite number > 0, got 0\.0"),
        (-0.5, ValueError, r"must be a finite number > 0, got -0\.5"),
        (np.nan, ValueError, r"must be a finite number > 0, got nan"),
        (np.inf, ValueError, r"must be a finite number > 0, got inf"),
        ("0.2", TypeError, r"must be a real number, got str"),
        ([0.2], TypeError, r"must be a real number, got list"),
        (True, TypeError, r"must be a real number, got bool"),
        (0.2 + 0j, TypeError, r"must be a real number, got complex"),
    ],
)
@pytest.mark.parametrize("name", ["characteristic_length", "singular_tolerance"])
def test_invalid_positive_scalars(name, value, error, message):
    """characteristic_length and singular_tolerance must be finite real numbers > 0."""
    with pytest.raises(error, match=rf"^{name} {message}"):
        Planar3RPR(**{name: value})


def test_valid_scalars_are_stored():
    """Integer and NumPy scalars are accepted and stored as floats."""
    robot = Planar3RPR(characteristic_length=np.float32(0.5), singular_tolerance=1)
    assert robot.characteristic_length == 0.5
    assert robot.singular_tolerance == 1.0
    np.testing.assert_array_equal(robot.pose_scale, [1.0, 1.0, 2.0])


# -- forward kinematics: failure is reported, not raised --------------------------------------------


def test_unassemblable_leg_lengths_do_not_converge(robot):
    """Legs far too short to reach the platform: converged False, residual > tolerance, no raise."""
    result = robot.forward_kinematics([0.01, 0.01, 0.01], X)
    assert isinstance(result, ForwardKinematicsResult)
    assert not result.converged
    assert not result
    assert result.residual > 1e-12
    assert result.iterations == 30
    assert np.all(np.isfinite(result.x))
    assert result.residual == pytest.approx(np.max(np.abs(robot.constraints([0.01] * 3, result.x))))


def test_too_few_iterations_do_not_converge(robot):
    """max_iterations=1 from a far guess: reported as not converged after one iteration."""
    result = robot.forward_kinematics(Q, X + np.array([0.2, -0.1, 0.8]), max_iterations=1)
    assert not result.converged
    assert result.iterations == 1
    assert result.residual > 1e-12
    assert result.residual == pytest.approx(np.max(np.abs(robot.constraints(Q, result.x))))


def test_zero_iterations_returns_the_guess(robot):
    """max_iterations=0 returns the guess with its residual."""
    guess = X + 0.01
    result = robot.forward_kinematics(Q, guess, max_iterations=0)
    np.testing.assert_array_equal(result.x, guess)
    assert result.iterations == 0 and not result.converged


def test_batch_reports_failure_per_configuration(robot):
    """In a batch, each configuration's convergence is reported; the good ones are solved."""
    q = np.stack([Q, [0.01, 0.01, 0.01], Q])
    result = robot.forward_kinematics(q, X + 0.01)
    np.testing.assert_array_equal(result.converged, [True, False, True])
    assert not result
    assert result.residual[1] > 1e-12 >= result.residual[0]
    np.testing.assert_allclose(result.x[[0, 2]], [X, X], atol=1e-9)


def test_forward_kinematics_from_a_singular_guess_does_not_raise(robot):
    """A guess where J_x is exactly singular stops that configuration, unconverged, without raising."""
    robot = Planar3RPR(base=[[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]], platform=[[0.0, 0.0], [0.1, 0.0], [0.0, 0.1]])
    guess = np.array([0.0, 0.0, 0.0])  # leg 1 has zero length there: its J_x row vanishes
    result = robot.forward_kinematics([0.5, 0.6, 0.7], guess)
    assert not result.converged
    assert np.all(np.isfinite(result.x))


@pytest.mark.parametrize("tolerance", [0.0, -1e-9, np.nan, np.inf])
def test_invalid_tolerance(tolerance, robot):
    """The tolerance must be a finite number > 0."""
    with pytest.raises(ValueError, match=r"^tolerance must be a finite number > 0, got"):
        robot.forward_kinematics(Q, X, tolerance=tolerance)


@pytest.mark.parametrize("tolerance", ["1e-9", None, [1e-9]])
def test_non_numeric_tolerance(tolerance, robot):
    """A tolerance that is not a number: TypeError naming it."""
    with pytest.raises(TypeError, match=r"^tolerance must be a real number, got"):
        robot.forward_kinematics(Q, X, tolerance=tolerance)


@pytest.mark.parametrize("max_iterations", [-1, 2.5, 10.0, "10", None, True])
def test_invalid_max_iterations(max_iterations, robot):
    """max_iterations must be an integer ≥ 0."""
    with pytest.raises(ValueError, match=r"^max_iterations must be an integer ≥ 0, got"):
        robot.forward_kinematics(Q, X, max_iterations=max_iterations)


# -- assembly modes ---------------------------------------------------------------------------------


def test_assembly_modes_rejects_a_batch(robot):
    """assembly_modes solves one set of leg lengths at a time."""
    with pytest.raises(ValueError, match=r"^assembly_modes takes one set of leg lengths, shape \(3,\), got \(2, 3\)"):
        robot.assembly_modes(np.stack([Q, Q]))


@pytest.mark.parametrize("q", [[0.01, 0.01, 0.01], [5.0, 0.01, 0.01], [0.1, 0.1, 3.0]])
def test_unassemblable_leg_lengths_have_no_assembly_mode(q, robot):
    """Leg lengths that cannot be assembled give an empty (0, 3) array."""
    modes = robot.assembly_modes(q)
    assert modes.shape == (0, 3)
    assert modes.dtype == np.float64


@pytest.mark.parametrize("n_samples", [12, 0, -5, 20.0, "64"])
def test_assembly_modes_rejects_too_few_samples(n_samples, robot):
    """n_samples must be an integer ≥ 13 (the degree-12 polynomial needs 13 coefficients)."""
    with pytest.raises(ValueError, match=r"^n_samples must be an integer ≥ 13, got"):
        robot.assembly_modes(Q, n_samples=n_samples)


# -- the robot object -------------------------------------------------------------------------------


@pytest.mark.parametrize("attribute", ["base", "platform", "pose_scale"])
def test_geometry_arrays_are_read_only(attribute, robot):
    """Writing into the geometry raises ValueError (read-only arrays); attributes cannot be rebound."""
    with pytest.raises(ValueError, match="read-only"):
        getattr(robot, attribute)[0] = 42.0
    with pytest.raises(AttributeError):
        setattr(robot, attribute, np.zeros((3, 2)))


def test_geometry_is_copied_at_construction():
    """Changing the caller's array afterwards does not change the robot."""
    base = np.array(Planar3RPR().base)
    robot = Planar3RPR(base=base)
    base[0, 0] = 42.0
    assert robot.base[0, 0] == 0.0
    assert robot == Planar3RPR()


def test_forward_kinematics_result_is_frozen(robot):
    """The result object cannot be modified by attribute assignment."""
    result = robot.forward_kinematics(Q, X)
    with pytest.raises(AttributeError):
        result.converged = False


@pytest.mark.parametrize("arguments", ROBOT_ARGUMENTS.values(), ids=list(ROBOT_ARGUMENTS))
def test_pickle_round_trip(arguments):
    """A pickled robot comes back equal, with the same hash, results and read-only geometry."""
    robot = Planar3RPR(**arguments)
    clone = pickle.loads(pickle.dumps(robot))
    assert clone == robot and hash(clone) == hash(robot)
    np.testing.assert_array_equal(clone.forward_jacobian(Q, X), robot.forward_jacobian(Q, X))
    for attribute in ("base", "platform", "pose_scale"):
        with pytest.raises(ValueError, match="read-only"):
            getattr(clone, attribute)[0] = 42.0


def test_equality_and_hash():
    """Robots are equal exactly when geometry and tolerances are; not equal to other types."""
    assert Planar3RPR() == Planar3RPR() and hash(Planar3RPR()) == hash(Planar3RPR())
    assert Planar3RPR() != Planar3RPR(characteristic_length=0.3)
    assert Planar3RPR() != Planar3RPR(singular_tolerance=1e-6)
    assert Planar3RPR() != Planar3RPR(platform=[[0.0, -0.1], [0.2, 0.0], [-0.2, 0.0]])
    assert Planar3RPR() != "Planar3RPR()"


@pytest.mark.parametrize("arguments", ROBOT_ARGUMENTS.values(), ids=list(ROBOT_ARGUMENTS))
def test_repr_is_informative_and_can_be_pasted_back(arguments):
    """The repr names the class and the geometry, and evaluates back to an equal robot."""
    robot = Planar3RPR(**arguments)
    text = repr(robot)
    assert text.startswith("Planar3RPR(base=[[")
    for part in (f"base={robot.base.tolist()}", f"platform={robot.platform.tolist()}"):
        assert part in text
    assert f"characteristic_length={robot.characteristic_length!r}" in text
    assert eval(text, {"Planar3RPR": Planar3RPR}) == robot


def test_singular_configuration_error_is_a_value_error():
    """Callers catching ValueError also catch singular configurations."""
    assert issubclass(SingularConfigurationError, ValueError)
