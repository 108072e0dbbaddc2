# SPDX-License-Identifier: Apache-2.0
"""The loader refuses what it cannot read: located errors, never a traceback.

Two property-based tests damage the shipped scenarios, one in their structure
(values replaced by other types, sizes and strings; keys removed and added) and
one in their bytes (tokens YAML treats specially, random bytes, cut lines), and
require every load to succeed or raise :class:`~cbp.errors.CbpError` within
5 s. The examples are derandomized (the same ones every CI run);
``make fuzz`` runs 10,000 of each with fresh randomness. A failing document is
written to ``out/fuzz/``; add it to ``tests/engine/fuzz_cases/`` with the
fix, where :func:`test_regression_cases` keeps it refused.
"""

from __future__ import annotations

import copy
import hashlib
import os
import shutil
import signal
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from cbp.errors import CbpError, ScenarioError
from cbp.scenario import load_scenario

ROOT = Path(__file__).resolve().parents[2]
CASES = Path(__file__).parent / "fuzz_cases"
EXAMPLES = int(os.environ.get("CBP_FUZZ_EXAMPLES", "120"))
FUZZ = settings(
    max_examples=EXAMPLES,
    derandomize="CBP_FUZZ_EXAMPLES" not in os.environ,
    deadline=None,
    database=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture],
)
#: A load taking more CPU time than this is a hang [s].
HANG = 5

SOURCES = sorted((ROOT / "scenarios").glob("*.yaml"))


@pytest.fixture(scope="module")
def folder(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A copy of ``scenarios/``, so that relative includes and files resolve.

    Each scenario is loaded once first, outside the hang watchdog: a first
    load compiles the kernels it needs (seconds of CPU on a cold numba cache,
    as on a fresh clone when this module runs first), which is no hang.
    """
    target = tmp_path_factory.mktemp("fuzz") / "scenarios"
    shutil.copytree(ROOT / "scenarios", target)
    for source in SOURCES:
        load_scenario(target / source.name)
    return target


class HangError(Exception):
    """A load took longer than HANG."""


def _alarm(signum: int, frame: object) -> None:
    raise HangError


def refused_or_loaded(
    path: Path, load: Callable[[Path], object], hang: float, kind: str
) -> None:
    """``load(path)``; anything but success or a CbpError within ``hang`` s fails.

    ``hang`` is CPU time, not wall time: a loaded machine does not make a load
    hang. A failing file is saved to ``out/fuzz/`` (named ``{kind}_`` and its
    hash; scenarios by the hash alone), and the message says where.
    """
    previous = signal.signal(signal.SIGPROF, _alarm)
    signal.setitimer(signal.ITIMER_PROF, hang)
    try:
        load(path)
    except CbpError:
        pass
    except BaseException as exc:
        saved = ROOT / "out" / "fuzz"
        saved.mkdir(parents=True, exist_ok=True)
        data = path.read_bytes()
        prefix = "" if kind == "scenario" else f"{kind}_"
        case = saved / f"{prefix}{hashlib.sha256(data).hexdigest()[:12]}.yaml"
        case.write_bytes(data)
        what = "hang" if isinstance(exc, HangError) else type(exc).__name__
        raise AssertionError(
            f"{what} loading a fuzzed {kind}, saved as {case}"
        ) from exc
    finally:
        signal.setitimer(signal.ITIMER_PROF, 0)
        signal.signal(signal.SIGPROF, previous)


def load_or_refuse(path: Path) -> None:
    """Load ``path``; anything but success or a CbpError within HANG s fails."""
    refused_or_loaded(path, load_scenario, HANG, "scenario")


# ---------------------------------------------------------------- structure

TRICKY = [
    None,
    0,
    -1,
    1e308,
    -1e-300,
    10**30,
    float("nan"),
    float("inf"),
    "",
    "x" * 300,
    [],
    {},
    [[[]]],
    [0.1] * 7,
    True,
    "panda_hand",
    "box",
    "0.4 + 0.01/(t - 1)",
    "log(2 - t)",
    "9**9**9",
    "/dev/zero",
    "../robots",
    "cat",
]
values = st.one_of(
    st.sampled_from(TRICKY),
    st.integers(-(10**6), 10**6),
    st.floats(allow_nan=True, allow_infinity=True),
    st.text(max_size=12),
    st.lists(st.floats(-10, 10), max_size=8),
    st.dictionaries(st.text(max_size=6), st.integers(), max_size=2),
)
EXTRA_KEYS = ["extra", "size", "params", "frame", "file", "cameras", "include", "name"]


def _paths(value: Any, path: tuple[Any, ...] = ()) -> Iterator[tuple[Any, ...]]:
    if path:
        yield path
    if isinstance(value, dict):
        for k, v in value.items():
            yield from _paths(v, (*path, k))
    elif isinstance(value, list):
        for i, v in enumerate(value):
            yield from _paths(v, (*path, i))


def _parent(doc: Any, path: tuple[Any, ...]) -> Any:
    for key in path[:-1]:
        doc = doc[key]
    return doc


def damage_structure(data: st.DataObject, doc: Any, keys: list[str]) -> Any:
    """A copy of ``doc`` with 1-3 values replaced, keys removed, or ``keys`` added."""
    doc = copy.deepcopy(doc)
    for _ in range(data.draw(st.integers(1, 3), label="edits")):
        path = data.draw(st.sampled_from(list(_paths(doc))), label="path")
        parent = _parent(doc, path)
        action = data.draw(st.sampled_from(["replace", "remove", "add"]), label="edit")
        # Copies: a drawn list or mapping put in twice must not come to contain
        # itself (the walk over the document would never end).
        if action == "replace":
            parent[path[-1]] = copy.deepcopy(data.draw(values, label="value"))
        elif action == "remove" and isinstance(parent, dict):
            del parent[path[-1]]
        elif isinstance(parent, dict):
            key = data.draw(st.sampled_from(keys), label="key")
            parent[key] = copy.deepcopy(data.draw(values, label="value"))
    return doc


def damage_bytes(data: st.DataObject, text: bytes, tokens: list[bytes]) -> bytes:
    """``text`` with 1-3 spans replaced by one of ``tokens`` or random bytes."""
    damaged = bytearray(text)
    for _ in range(data.draw(st.integers(1, 3), label="edits")):
        at = data.draw(st.integers(0, len(damaged) - 1), label="at")
        length = data.draw(st.integers(0, 12), label="length")
        new = data.draw(st.one_of(st.sampled_from(tokens), st.binary(max_size=6)))
        damaged[at : at + length] = new
    return bytes(damaged)


@FUZZ
@given(data=st.data())
def test_damaged_structure_is_refused_or_loaded(
    folder: Path, data: st.DataObject
) -> None:
    source = data.draw(st.sampled_from(SOURCES), label="scenario")
    doc = damage_structure(data, yaml.safe_load(source.read_text()), EXTRA_KEYS)
    case = folder / "fuzz_case.yaml"
    case.write_text(yaml.safe_dump(doc, allow_unicode=True))
    load_or_refuse(case)


# ---------------------------------------------------------------- bytes

TOKENS = [
    b"!!float abc",
    b"!custom x",
    b"<<: *a",
    b"&a ",
    b"*a",
    b"9**9**9",
    b".inf",
    b"1e-300",
    b"\x00",
    b"\xff\xfe",
    b"\x07",
    b"[" * 200,
    b"9" * 400,
    b"include: /dev/zero\n",
    b"!!binary aGk=",
    b"2001-13-45",
    b"!!set {a}",
    b"\t",
    b"%YAML 1.1\n---\n",
    b"? [a]\n",
    b"\xe2\x80\xae",
]


@FUZZ
@given(data=st.data())
def test_damaged_bytes_are_refused_or_loaded(folder: Path, data: st.DataObject) -> None:
    source = data.draw(st.sampled_from(SOURCES), label="scenario")
    case = folder / "fuzz_case.yaml"
    case.write_bytes(damage_bytes(data, source.read_bytes(), TOKENS))
    load_or_refuse(case)


# ---------------------------------------------------------------- regressions


@pytest.mark.parametrize("case", sorted(CASES.glob("*.yaml")), ids=lambda p: p.stem)
def test_regression_cases(case: Path, folder: Path) -> None:
    """Each saved case is refused with a located message naming the problem."""
    cases = folder / "fuzz_cases"
    if not cases.exists():
        shutil.copytree(CASES, cases)
    copied = cases / case.name
    expected = case.with_suffix(".expected").read_text().strip()
    with pytest.raises(ScenarioError) as info:
        load_scenario(copied)
    assert expected in str(info.value)
