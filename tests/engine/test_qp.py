"""QP assembly and the solver backends."""

from __future__ import annotations

import numpy as np
import pytest

from cbp.engine import Engine
from cbp.errors import ConfigError, PluginOutputError, SolveError
from cbp.plugins.constraints.joint_acceleration_constraint import (
    JointAccelerationConstraint,
    JointAccelerationParams,
)
from cbp.plugins.constraints.joint_limits_constraint import (
    JointLimitsConstraint,
    JointLimitsParams,
)
from cbp.plugins.constraints.joint_velocity_constraint import (
    JointVelocityConstraint,
    JointVelocityParams,
)
from cbp.plugins.tasks.goal_pose_task import GoalPoseParams, GoalPoseTask
from cbp.plugins.tasks.joint_step_task import JointStepParams, JointStepTask
from cbp.plugins.tasks.posture_task import PostureParams, PostureTask
from cbp.qp import Entry
from cbp.solvers import SOLVERS, make_solver
from cbp.state import RobotState
from cbp.testing import sample_configurations


def _entries(robot, rng, *, goal_priority="soft", velocity_priority="hard"):
    goal = GoalPoseTask(
        GoalPoseParams(frame="panda_hand", max_step_translation=0.05), robot
    )
    position = rng.uniform([0.3, -0.4, 0.1], [0.7, 0.4, 0.7])
    goal.set_target(position, np.diag([1.0, -1.0, -1.0]))
    return [
        Entry.make(goal, priority=goal_priority, weight=[1, 1, 1, 0.3, 0.3, 0.3]),
        Entry.make(JointStepTask(JointStepParams(), robot), weight=1e-3),
        Entry.make(PostureTask(PostureParams(), robot), weight=1e-4, gain=0.1),
        Entry.make(JointLimitsConstraint(JointLimitsParams(margin=0.02), robot)),
        Entry.make(
            JointVelocityConstraint(JointVelocityParams(scale=0.5), robot),
            priority=velocity_priority,
            weight=10.0,
        ),
    ]


@pytest.mark.parametrize("velocity_priority", ["hard", "soft"])
def test_backends_agree_on_engine_built_problems(
    robots, rng, velocity_priority
) -> None:
    """daqp, piqp and cvxpy find the same step on random engine-built QPs."""
    robot = robots["panda"]
    for q in sample_configurations(robot, rng, n=6, margin=0.05):
        entries = _entries(robot, rng, velocity_priority=velocity_priority)
        engine = Engine(robot, entries, solver="daqp")
        reference, problem, _, _ = engine.step(q, 0.01)
        full = make_solver("daqp").solve(problem)
        for name in SOLVERS:
            x = make_solver(name).solve(problem)
            # The same optimum: equal cost and feasible. (Steps agree to ~1e-5;
            # with soft bounds the cost is flat along some directions, so each
            # solver's stopping tolerance shows in the step more than in the cost.)
            np.testing.assert_allclose(
                x[: robot.nv], reference, atol=5e-5, err_msg=name
            )
            best = _cost(problem, full)
            assert _cost(problem, x) <= best + 1e-5 * abs(best) + 1e-12, name
            assert problem.violation(x) < 1e-6


def test_hard_task_is_met_exactly(robots, rng) -> None:
    """A hard goal_pose becomes six equalities J dq = -k f (clipped)."""
    robot = robots["panda"]
    entries = _entries(robot, rng, goal_priority="hard")
    q = robot.home()
    engine = Engine(robot, entries)
    dq = engine.step(q, 0.1).dq
    goal = entries[0].plugin
    state = RobotState(robot, q)
    value, J = goal.linearize(state)
    np.testing.assert_allclose(J.dot(dq), goal.limit_step(-value), atol=1e-9)


def test_joint_limit_rows_reproduce_cat_eq4(robots) -> None:
    """With gain 1, q + dq stays within the limits even when the goal pulls out."""
    robot = robots["panda"]
    q = robot.home()
    q[3] = robot.lower_limits[3] + 0.01
    posture = PostureTask(PostureParams(target={"panda_joint4": -4.0}), robot)
    limits = JointLimitsConstraint(JointLimitsParams(), robot)
    engine = Engine(robot, [Entry.make(posture, gain=1.0), Entry.make(limits)])
    dq = engine.step(q, 1.0).dq  # slow enough for the step guard
    assert q[3] + dq[3] == pytest.approx(robot.lower_limits[3], abs=1e-9)


def test_infeasible_problem_names_the_conflicting_entries(robots) -> None:
    """Hard entries that cannot all hold, even eased, give a SolveError naming them.

    A joint moving at 2 rad/s cannot slow to a tenth of its velocity limit in
    one step: acceleration rows are a physical limit, never eased.
    """
    robot = robots["panda"]
    q = robot.home()
    posture = PostureTask(PostureParams(target={"panda_joint1": 2.0}), robot, "reach")
    velocity = JointVelocityConstraint(JointVelocityParams(scale=0.1), robot, "slow")
    acceleration = JointAccelerationConstraint(
        JointAccelerationParams(), robot, "brakes"
    )
    step = JointStepTask(JointStepParams(), robot, "small")
    engine = Engine(
        robot,
        [
            Entry.make(posture, priority="hard", gain=1.0),
            Entry.make(velocity),
            Entry.make(acceleration),
            Entry.make(step, weight=1e-3),
        ],
    )
    v = np.zeros(robot.nv)
    v[0] = 2.0
    for name in SOLVERS:
        engine.solver = make_solver(name)
        with pytest.raises(SolveError, match=r"cannot all be met: ") as info:
            engine.step(q, 0.01, v)
        assert "brakes" in info.value.conflicting
        assert "slow" in info.value.conflicting
        assert info.value.problem is not None


def test_zero_gain_keeps_infinite_bounds_inactive(robots) -> None:
    """K = 0 makes finite bounds 0 (contact form) and leaves infinite ones open."""
    robot = robots["panda"]
    q = robot.home()
    limits = JointLimitsConstraint(JointLimitsParams(), robot)
    step = JointStepTask(JointStepParams(), robot)
    posture = PostureTask(PostureParams(target={"panda_joint1": 1.0}), robot)
    engine = Engine(
        robot,
        [
            Entry.make(limits, gain=0.0),
            Entry.make(step, weight=1e-3),
            Entry.make(posture),
        ],
    )
    problem = engine.step(q, 0.01).problem
    assert problem is not None
    np.testing.assert_array_equal(problem.lower[:7], np.zeros(7))
    np.testing.assert_array_equal(problem.upper[:7], np.zeros(7))


def test_nan_output_is_named(robots) -> None:
    """A plugin returning NaN raises PluginOutputError naming it; nothing moves."""
    robot = robots["panda"]

    class Broken(PostureTask):
        def compute_value(self, state):  # type: ignore[no-untyped-def]
            return np.full(self.dim, np.nan)

        def value_into(self, state, value):  # type: ignore[no-untyped-def]
            value[:] = self.compute_value(state)

    engine = Engine(
        robot,
        [
            Entry.make(Broken(PostureParams(), robot, "broken")),
            Entry.make(JointStepTask(JointStepParams(), robot), weight=1e-3),
        ],
    )
    with pytest.raises(
        PluginOutputError, match=r"broken \(broken\): value or Jacobian is not finite"
    ):
        engine.step(robot.home(), 0.01)


def test_wrong_shape_output_is_named(robots) -> None:
    """A plugin returning the wrong shape is named with expected shapes."""
    robot = robots["panda"]

    class Short(PostureTask):
        def compute_value(self, state):  # type: ignore[no-untyped-def]
            return super().compute_value(state)[:3]

    engine = Engine(robot, [Entry.make(Short(PostureParams(), robot, "short"))])
    with pytest.raises(
        PluginOutputError, match=r"short \(short\): value has shape \(3,\)"
    ):
        engine.step(robot.home(), 0.01)


def test_entry_settings_are_checked(robots) -> None:
    """Weight length, gain range and priority name are validated with locations."""
    robot = robots["panda"]
    goal = GoalPoseTask(GoalPoseParams(frame="panda_hand"), robot)
    with pytest.raises(
        ConfigError, match=r"weight has 4 entries, expected 1 or 6 \(dim of goal_pose\)"
    ):
        Entry.make(goal, weight=[1, 1, 1, 1])
    with pytest.raises(ConfigError, match=r"gain 2.0 is outside \[0, 1\]"):
        Entry.make(goal, gain=2.0)
    with pytest.raises(ConfigError, match="unknown solver 'daq'; did you mean 'daqp'"):
        make_solver("daq")


def _cost(problem, x):
    return 0.5 * x.dot(problem.H).dot(x) + problem.g.dot(x)


@pytest.mark.parametrize("velocity_priority", ["hard", "soft"])
def test_constant_jacobians_are_folded_without_changing_the_problem(
    robots, rng, velocity_priority
) -> None:
    """Linearizing constant-Jacobian entries once builds the same QPs, step after step."""
    robot = robots["panda"]
    entries = _entries(robot, rng, velocity_priority=velocity_priority)
    assert all(e.plugin.constant_jacobian for e in entries[1:])
    plain = _entries(robot, rng, velocity_priority=velocity_priority)
    plain[0].plugin.set_target(
        entries[0].plugin.target.translation, entries[0].plugin.target.rotation
    )
    for entry in plain:
        entry.plugin.constant_jacobian = False
    folded_engine = Engine(robot, entries, solver="daqp")
    plain_engine = Engine(robot, plain, solver="daqp")
    for q in sample_configurations(robot, rng, n=5, margin=0.05):
        folded_step = folded_engine.step(q, 0.01)
        plain_step = plain_engine.step(q, 0.01)
        np.testing.assert_allclose(folded_step.dq, plain_step.dq, atol=1e-9)
        folded, reference = folded_step.problem, plain_step.problem
        for name in ("H", "g", "A", "lower", "upper"):
            np.testing.assert_allclose(
                getattr(folded, name), getattr(reference, name), atol=1e-12
            )


def _reference_problem(entries, state, nv, regularization):
    """The QP of the assembler's docstring, written out with plain numpy."""
    soft_tasks = [e for e in entries if e.priority == "soft" and _is_task(e)]
    rows = [e for e in entries if e not in soft_tasks]
    H = regularization * np.eye(nv)
    g = np.zeros(nv)
    for e in soft_tasks:
        value, J = e.plugin.linearize(state)
        desired = e.plugin.limit_step(-e.gain * value)
        H += J.T @ np.diag(e.weight) @ J
        g -= J.T @ (e.weight * desired)
    A, lower, upper, soft = [], [], [], []
    for e in rows:
        value, J = e.plugin.linearize(state)
        if _is_task(e):
            lo = up = e.plugin.limit_step(-e.gain * value)
        else:
            lo, up = e.plugin.compute_bounds(state)
            with np.errstate(invalid="ignore"):
                lo = np.where(np.isinf(lo) & (e.gain == 0), lo, e.gain * (lo - value))
                up = np.where(np.isinf(up) & (e.gain == 0), up, e.gain * (up - value))
        A.append(J)
        lower.append(lo)
        upper.append(up)
        soft.append(np.full(e.plugin.dim, e.priority == "soft"))
    return (
        H,
        g,
        np.vstack(A),
        np.concatenate(lower),
        np.concatenate(upper),
        (np.concatenate(soft)),
    )


class _ClippedPosture(PostureTask):
    def limit_step(self, desired):  # type: ignore[no-untyped-def]
        return np.clip(desired, -0.01, 0.01)


def _is_task(entry):
    from cbp.plugin import Task

    return isinstance(entry.plugin, Task)


def test_assembled_problem_matches_its_definition(robots, rng) -> None:
    """H, g, A and the bounds are the documented ones, slack rows included."""
    robot = robots["panda"]
    nv = robot.nv
    for q in sample_configurations(robot, rng, n=4, margin=0.05):
        entries = _entries(robot, rng, velocity_priority="soft")
        entries[3] = Entry.make(entries[3].plugin, gain=0.5)
        hard = PostureTask(PostureParams(target={"panda_joint2": 0.3}), robot, "hard")
        open_limits = JointLimitsConstraint(JointLimitsParams(), robot, "open")
        clipped = _ClippedPosture(PostureParams(), robot, "clipped")
        assert clipped.constant_jacobian  # a limited step among the folded tasks
        entries += [
            Entry.make(hard, priority="hard", gain=0.2),
            Entry.make(open_limits, gain=0.0),
            Entry.make(clipped, weight=0.1, gain=0.5),
        ]
        # Not solved: the zero-gain limits pin every joint against the hard task.
        engine = Engine(robot, entries, regularization=1e-7)
        state = RobotState(robot, q)
        for e in entries:
            e.plugin.prepare(state, 0.01)
        for _ in range(2):  # the first assembly folds the constant Jacobians
            problem = engine.assembler.assemble(state)
        H, g, A, lower, upper, soft = _reference_problem(entries, state, nv, 1e-7)
        m, ns = A.shape[0], int(soft.sum())
        np.testing.assert_allclose(problem.H[:nv, :nv], H, atol=1e-12)
        np.testing.assert_allclose(problem.g[:nv], g, atol=1e-12)
        np.testing.assert_allclose(problem.A[:m, :nv], A, atol=1e-15)
        np.testing.assert_allclose(problem.A[m : m + ns, :nv], A[soft], atol=1e-15)
        np.testing.assert_allclose(problem.lower[:m], lower, atol=1e-15)
        np.testing.assert_allclose(problem.upper[m : m + ns], upper[soft], atol=1e-15)
        np.testing.assert_array_equal(problem.upper[:m][soft], np.inf)
        np.testing.assert_allclose(problem.upper[:m][~soft], upper[~soft], atol=1e-15)
        np.testing.assert_array_equal(problem.equality, problem.lower == problem.upper)
        assert problem.equality[:m].sum() >= hard.dim


@pytest.mark.parametrize("broken", ["value", "jacobian", "bound"])
def test_non_finite_constraint_output_is_named(robots, broken) -> None:
    """A constraint's NaN value, Jacobian or bound raises, naming the constraint."""
    robot = robots["panda"]

    class Broken(JointLimitsConstraint):
        def compute_value(self, state):  # type: ignore[no-untyped-def]
            value = super().compute_value(state).copy()
            value[2] = np.nan if broken == "value" else value[2]
            return value

        def compute_jacobian(self, state):  # type: ignore[no-untyped-def]
            J = super().compute_jacobian(state).copy()
            J[1, 1] = np.inf if broken == "jacobian" else J[1, 1]
            return J

        def compute_bounds(self, state):  # type: ignore[no-untyped-def]
            lower, upper = super().compute_bounds(state)
            if broken == "bound":
                upper = np.where(np.arange(self.dim) == 4, np.nan, upper)
            return lower, upper

    plugin = Broken(JointLimitsParams(), robot, "broken")
    plugin.constant_jacobian = False
    engine = Engine(
        robot,
        [Entry.make(plugin), Entry.make(JointStepTask(JointStepParams(), robot))],
    )
    expected = "bounds must" if broken == "bound" else "value or Jacobian is not"
    with pytest.raises(PluginOutputError, match=rf"broken \(broken\): {expected}"):
        engine.step(robot.home(), 0.01)


def test_assembly_pass_compiles_once(robots, rng) -> None:
    """Every layout of blocks (empty or not, slacks or not) shares one signature."""
    from cbp.qp import fill_qp

    robot = robots["panda"]
    q = robot.home()
    for velocity_priority in ("hard", "soft"):
        Engine(robot, _entries(robot, rng, velocity_priority=velocity_priority)).step(
            q, 0.01
        )
    Engine(robot, [Entry.make(PostureTask(PostureParams(), robot))]).step(q, 1.0)
    limits = JointLimitsConstraint(JointLimitsParams(), robot)
    Engine(robot, [Entry.make(limits)]).step(q, 0.01)
    assert len(fill_qp.signatures) == 1


def test_rows_asking_for_more_than_the_limits_allow_are_eased(robots) -> None:
    """A joint far past its limit: back out at the velocity bound's pace, no error."""
    robot = robots["panda"]
    q = robot.home()
    q[3] = robot.lower_limits[3] - 0.3  # 0.3 rad past: one step cannot undo it
    limits = JointLimitsConstraint(JointLimitsParams(), robot, "limits")
    velocity = JointVelocityConstraint(JointVelocityParams(), robot, "velocity")
    engine = Engine(
        robot,
        [
            Entry.make(PostureTask(PostureParams(), robot), weight=1e-3),
            Entry.make(limits, gain=1.0),
            Entry.make(velocity),
        ],
    )
    dt = 0.01
    result = engine.step(q, dt)
    assert result.eased is not None
    assert "limits" in result.eased.description
    assert "eased" in result.eased.description
    assert result.eased.scale is None  # capped (backing out), not scaled
    dq = result.dq
    bound = robot.velocity_limits[3] * dt
    # Backing out (toward the range), at half the bound, and no further than it.
    assert 0.5 * bound - 1e-9 <= dq[3] <= bound + 1e-9
    assert engine.step(q, dt).eased == result.eased  # the same easing again
    # Within the range again, the step is solved as assembled.
    assert engine.step(robot.home(), dt).eased is None


def test_an_eased_step_does_not_name_conflicts(robots, monkeypatch) -> None:
    """Naming the conflicts is a second solve, spent only on a step that fails.

    Where obstacles pressed the arm, diagnosing every first solve that the
    easing then answered took a fifth of the step's time.
    """
    import cbp.solvers

    calls: list[int] = []
    diagnose = cbp.solvers.diagnose_infeasibility

    def counted(problem, tol=1e-7):  # type: ignore[no-untyped-def]
        calls.append(1)
        return diagnose(problem, tol)

    monkeypatch.setattr(cbp.solvers, "diagnose_infeasibility", counted)
    robot = robots["panda"]
    q = robot.home()
    q[3] = robot.lower_limits[3] - 0.3
    engine = Engine(
        robot,
        [
            Entry.make(PostureTask(PostureParams(), robot), weight=1e-3),
            Entry.make(JointLimitsConstraint(JointLimitsParams(), robot), gain=1.0),
            Entry.make(JointVelocityConstraint(JointVelocityParams(), robot)),
        ],
    )
    assert engine.step(q, 0.01).eased is not None
    assert calls == []
    assert engine.solver.diagnose  # as it was before the step


def test_rows_follow_the_bounds_however_a_constraint_returns_them(robots) -> None:
    """Fixed arrays, the same arrays changed in place, new arrays: rows follow."""
    robot = robots["panda"]

    class Settable(JointLimitsConstraint):
        bounds: tuple[np.ndarray, np.ndarray] = (np.zeros(0), np.zeros(0))

        def compute_bounds(self, state):  # type: ignore[no-untyped-def]
            return self.bounds

    def fixed(values: np.ndarray) -> np.ndarray:
        values = np.array(values, dtype=float)
        values.flags.writeable = False
        return values

    plugin = Settable(JointLimitsParams(), robot)
    assembler = Engine(robot, [Entry.make(plugin)]).assembler
    q = robot.home()
    state = RobotState(robot, q)
    n = plugin.dim
    writeable = np.full(n, 0.5)
    steps = [
        (fixed(robot.lower_limits), fixed(robot.upper_limits)),
        None,  # the same fixed arrays again
        (fixed(robot.lower_limits + 0.1), fixed(robot.upper_limits - 0.1)),
        (-writeable, writeable),
        "in place",  # the same writeable arrays, changed
    ]
    for bounds in steps:
        if bounds == "in place":
            plugin.bounds[1][:] = 0.25
        elif bounds is not None:
            plugin.bounds = bounds
        problem = assembler.assemble(state)
        lower, upper = plugin.bounds
        np.testing.assert_allclose(problem.lower[:n], lower - q, atol=1e-12)
        np.testing.assert_allclose(problem.upper[:n], upper - q, atol=1e-12)


def test_demands_that_cannot_all_be_met_are_met_as_nearly_as_they_allow() -> None:
    """Two inequality rows push a point both ways: it moves, it is not held.

    Along s = x0 + x1 (|x0|, |x1| <= 0.5) the demands s >= 0.6 and s <= -0.2
    are scaled by one factor (5/6, so that neither asks more than half of
    the reach, 1) and widened by their least violation: the step backs away
    from the larger demand (the nearer obstacle) as far as the smaller one
    lets it, s = (0.5 - 1/6) / 2. Scaling every demand to "no further" held
    it at 0 while the obstacles came on.
    """
    from cbp.engine.recovery import NEAREST, ease
    from cbp.qp import QPProblem

    problem = QPProblem(
        H=np.eye(2) * 1e-3,
        g=np.zeros(2),
        A=np.array([[1.0, 0.0], [0.0, 1.0], [1.0, 1.0], [-1.0, -1.0]]),
        lower=np.array([-0.5, -0.5, 0.6, 0.2]),
        upper=np.array([0.5, 0.5, np.inf, np.inf]),
        equality=np.zeros(4, dtype=bool),
        row_entry=np.array([0, 0, 1, 1]),
        entry_names=["velocity", "contacts"],
        nv=2,
    )
    solver = make_solver("daqp")
    with pytest.raises(SolveError) as raised:
        solver.solve(problem)
    with solver.trials():
        x, easing = ease(
            problem, raised.value, 0.01, solver, np.array([True, True]), np.zeros(2)
        )
    assert easing.description.endswith(NEAREST)
    assert easing.scale is None
    assert x[0] + x[1] == pytest.approx(1.0 / 6.0, abs=1e-6)
    assert problem.violation(x) <= 1e-8  # within the widened bounds it answers
