# SPDX-License-Identifier: Apache-2.0
"""Settings of the trajectory executors, as written under ``method:``."""

from __future__ import annotations

from dataclasses import dataclass, field

from cbp.errors import ConfigError

__all__ = ["CatSettings", "ExecutorTiming"]


@dataclass(frozen=True, kw_only=True)
class ExecutorTiming:
    """Command period, time budget and trajectory limits of a trajectory executor."""

    period: float = 1.0 / 30.0
    """Nominal command period [s] (the paper: 30 Hz for CAT and IK, 4 Hz for MP)."""
    min_period: float | None = None
    """Shortest adaptive period [s] (default: the nominal period)."""
    max_period: float | None = None
    """Longest adaptive period [s] (default: 4x the nominal period)."""
    growth: float = 1.5
    """The period is multiplied by this after a missed deadline."""
    shrink: float = 0.9
    """... and by this after a period that used less than half its time."""
    time_budget: float = 0.8
    """Fraction of the period the planner may use (the rest is margin)."""
    velocity_scale: float = 0.5
    """Trajectories use this fraction of the robot's velocity limits."""
    acceleration_scale: float = 0.5
    """... and this fraction of its acceleration limits."""

    def __post_init__(self) -> None:
        """Positive times, sensible factors."""
        if not self.period > 0:
            raise ConfigError(f"must be > 0, got {self.period}", "period")
        lo, hi = self.bounds()
        if not 0 < lo <= self.period <= hi:
            raise ConfigError(
                f"need 0 < min_period <= period <= max_period, got {lo}, "
                f"{self.period}, {hi}",
                "min_period",
            )
        if not self.growth >= 1:
            raise ConfigError(f"must be >= 1, got {self.growth}", "growth")
        if not 0 < self.shrink <= 1:
            raise ConfigError(f"must be in (0, 1], got {self.shrink}", "shrink")
        for name in ("time_budget", "velocity_scale", "acceleration_scale"):
            if not 0 < getattr(self, name) <= 1:
                raise ConfigError(f"must be in (0, 1], got {getattr(self, name)}", name)

    def bounds(self) -> tuple[float, float]:
        """Shortest and longest period [s]."""
        lo = self.min_period if self.min_period is not None else self.period
        hi = self.max_period if self.max_period is not None else 4.0 * self.period
        return lo, hi


@dataclass(frozen=True, kw_only=True)
class CatSettings:
    """The ``method.cat:`` section."""

    timing: ExecutorTiming = field(default_factory=ExecutorTiming)
    """Command period, budget and trajectory limits."""
    step_dt: float = 0.01
    """Duration the engine assigns to one QP step [s]: the ``joint_velocity``
    constraint bounds each step by v_max * step_dt."""
    max_steps: int = 2000
    """At most this many QP steps per period (the time budget usually ends it)."""
    converged_step: float = 1e-5
    """A step whose largest joint change is below this [rad] counts as still;
    three in a row end the period's computation (time was spare)."""
    max_rejections: int = 3
    """Consecutive rejected steps that end the period's path."""

    def __post_init__(self) -> None:
        """Positive values."""
        if not self.step_dt > 0:
            raise ConfigError(f"must be > 0, got {self.step_dt}", "step_dt")
        if self.max_steps < 1:
            raise ConfigError(f"must be >= 1, got {self.max_steps}", "max_steps")
        if not self.converged_step >= 0:
            raise ConfigError(
                f"must be >= 0, got {self.converged_step}", "converged_step"
            )
        if self.max_rejections < 1:
            raise ConfigError(
                f"must be >= 1, got {self.max_rejections}", "max_rejections"
            )
