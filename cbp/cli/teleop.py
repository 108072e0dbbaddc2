# SPDX-License-Identifier: Apache-2.0
"""``cbp teleop``: drive the robot from the browser or a device."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import TYPE_CHECKING

from cbp.cli.command import Command, add_set, missing_extra, read_overrides
from cbp.errors import CbpError

if TYPE_CHECKING:
    from cbp.teleop.profiles import InputProfile

__all__ = ["TELEOP"]


def _arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "scenario",
        type=Path,
        nargs="+",
        help="a scenario; or velocity-executor configurations of one robot to "
        "switch between (orbit and pan object)",
    )
    parser.add_argument(
        "--method", default="cat", help="cat, ik, mp or hybrid (switchable live)"
    )
    parser.add_argument("--port", type=int, default=8080)
    parser.add_argument(
        "--host", default="127.0.0.1", help="address to serve on (default: localhost)"
    )
    parser.add_argument(
        "--out",
        type=Path,
        default=None,
        help="output folder (default out/<name>_teleop)",
    )
    parser.add_argument(
        "--device",
        choices=("gamepad", "spacemouse"),
        default=None,
        help="drive with a gamepad or a 6-DOF mouse, read by the page, through its "
        "shipped input profile (hold the deadman to move)",
    )
    parser.add_argument(
        "--profile",
        default=None,
        help="an input profile file (mapping, dead band, deadman) or a shipped "
        "profile's name; implies its device",
    )
    parser.add_argument(
        "--hid",
        action="store_true",
        help="read the 6-DOF mouse in this process (hidapi, the hid extra) instead "
        "of in the page (WebHID); its deadman must be one of its buttons",
    )
    add_set(parser, "override a scenario value (as for run)")


def _teleop(args: argparse.Namespace) -> int:
    overrides = read_overrides(args.set)
    if overrides is None or missing_extra("teleop", "viewer"):
        return 2
    from cbp.teleop.serve import serve_teleop

    ok, profile = _input_profile(args.device, args.profile)
    if not ok:
        return 2
    return serve_teleop(
        args.scenario,
        args.method,
        args.host,
        args.port,
        args.out,
        overrides,
        profile,
        args.hid,
    )


def _input_profile(
    device: str | None, name: str | None
) -> tuple[bool, InputProfile | None]:
    """``cbp teleop``'s input profile (None without a device); False on an error."""
    from cbp.teleop.profiles import load_profile

    if device is None and name is None:
        return True, None
    try:
        profile = load_profile(name or str(device))
    except CbpError as exc:
        print(exc, file=sys.stderr)
        return False, None
    if device is not None and profile.device != device:
        print(
            f"--profile {name} is a {profile.device} profile, not a {device} one",
            file=sys.stderr,
        )
        return False, None
    return True, profile


TELEOP = Command(
    "teleop",
    "drive the robot from the browser (prints the page's URL)",
    _teleop,
    _arguments,
)
