"""The registries: completeness, naming, sorting, and user plugins."""

from __future__ import annotations

import sys
import textwrap
from pathlib import Path

import pytest

from cbp.errors import ConfigError, UnknownPluginError
from cbp.plugins.constraints import CONSTRAINTS
from cbp.plugins.tasks import TASKS
from tests.plugin_cases import PLUGIN_CASES

PLUGINS_DIR = Path(__file__).resolve().parent.parent / "plugins"


def test_every_registered_plugin_has_a_case() -> None:
    """The generic tests cover exactly the registered plugins."""
    assert {c.type_name for c in PLUGIN_CASES} == set(TASKS.names()) | set(
        CONSTRAINTS.names()
    )


@pytest.mark.parametrize(
    ("kind", "registry"), [("task", TASKS), ("constraint", CONSTRAINTS)]
)
def test_every_module_is_registered_under_its_file_name(kind: str, registry) -> None:
    """Each plugins/<kind>s/<thing>_<kind>.py holds the registered type <thing>."""
    stems = sorted(p.stem for p in (PLUGINS_DIR / f"{kind}s").glob(f"*_{kind}.py"))
    assert [s.removesuffix(f"_{kind}") for s in stems] == registry.names()
    for cls in registry:
        assert cls.__module__ == f"cbp.plugins.{kind}s.{cls.type_name}_{kind}"


def test_unknown_type_lists_names_and_nearest() -> None:
    """An unknown name suggests the nearest and lists every available one."""
    with pytest.raises(
        UnknownPluginError,
        match=r"unknown task type 'postur'; did you mean 'posture'\? Available: camera_velocity, goal_pose, joint_step, posture",
    ):
        TASKS.get("postur")


def test_dotted_path_loads_a_plugin_file_beside_the_scenario(tmp_path: Path) -> None:
    """'module:Class' imports module.py from the search folder."""
    (tmp_path / "my_plugins.py").write_text(
        textwrap.dedent(
            """
            from cbp.plugins.tasks.posture_task import PostureTask

            class MyPosture(PostureTask):
                type_name = "my_posture"
            """
        )
    )
    cls = TASKS.get("my_plugins:MyPosture", search_dirs=[tmp_path])
    assert cls.type_name == "my_posture"
    with pytest.raises(
        ConfigError, match="has no 'MyPostur'; did you mean 'MyPosture'"
    ):
        TASKS.get("my_plugins:MyPostur", search_dirs=[tmp_path])


def test_dotted_path_to_a_non_plugin_is_rejected() -> None:
    """A class that is not a Task is refused with a reason."""
    with pytest.raises(ConfigError, match=r"Path is not a task: subclass cbp\.Task"):
        TASKS.get("pathlib:Path")


def test_entry_point_of_an_installed_distribution(tmp_path: Path, monkeypatch) -> None:
    """A distribution declaring group cbp.constraints adds a constraint by name."""
    package = tmp_path / "extra_plugins.py"
    package.write_text(
        textwrap.dedent(
            """
            from cbp.plugins.constraints.joint_limits_constraint import JointLimitsConstraint

            class WideLimits(JointLimitsConstraint):
                type_name = "wide_limits"
            """
        )
    )
    dist = tmp_path / "extra_plugins-1.0.dist-info"
    dist.mkdir()
    (dist / "METADATA").write_text(
        "Metadata-Version: 2.1\nName: extra-plugins\nVersion: 1.0\n"
    )
    (dist / "entry_points.txt").write_text(
        "[cbp.constraints]\nwide_limits = extra_plugins:WideLimits\n"
    )
    monkeypatch.syspath_prepend(str(tmp_path))
    assert "wide_limits" in CONSTRAINTS.entry_point_names()
    assert CONSTRAINTS.get("wide_limits").type_name == "wide_limits"
    sys.modules.pop("extra_plugins", None)
