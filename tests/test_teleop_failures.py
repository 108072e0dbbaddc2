# SPDX-License-Identifier: Apache-2.0
import logging

import pytest

from cbp.teleop.failures import Guarded


def test_a_repeated_failure_is_logged_once_and_again_after_a_success(
    caplog: pytest.LogCaptureFixture,
) -> None:
    """The same error warns once; a new error or one after a success warns again."""
    errors = iter(
        [ValueError("a"), ValueError("a"), KeyError("b"), None, KeyError("b")]
    )

    def step() -> None:
        error = next(errors)
        if error is not None:
            raise error

    guarded = Guarded(logging.getLogger("cbp.test"), "device step")
    with caplog.at_level(logging.WARNING, logger="cbp.test"):
        for _ in range(5):
            guarded.call(step)
    assert [r.getMessage() for r in caplog.records] == [
        "device step failed: ValueError: a",
        "device step failed: KeyError: 'b'",
        "device step failed: KeyError: 'b'",
    ]
