# SPDX-License-Identifier: Apache-2.0
"""benchmarks/RESULTS.md as sections: each script replaces its own, keeps the rest.

A section runs from a ``## `` heading to the next. ``cbp bench`` writes the
file's head and its own sections; the other scripts (``collision.py``,
``cat_periods.py``, ``sweep.py``, ``soak.py``, ``teleop_latency.py``) each put
one section. Re-running a script replaces its section where it stands instead
of appending a second copy, and ``cbp bench`` keeps the other scripts'
sections.
"""

from __future__ import annotations

from pathlib import Path

__all__ = ["keep_other_sections", "publish", "put_section", "sections"]


def sections(text: str) -> tuple[str, list[tuple[str, str]]]:
    """The text before the first heading, and (heading line, section text) pairs."""
    head: list[str] = []
    found: list[tuple[str, list[str]]] = []
    for line in text.splitlines(keepends=True):
        if line.startswith("## "):
            found.append((line.strip(), [line]))
        elif found:
            found[-1][1].append(line)
        else:
            head.append(line)
    return "".join(head), [(h, "".join(body)) for h, body in found]


def put_section(path: Path, text: str) -> None:
    """Put ``text`` (one or more sections) into ``path``, replacing same-named ones.

    A section of ``text`` takes the place of the first section of the file with
    its heading (later copies are dropped); new headings go at the end.
    """
    path = Path(path)
    old_head, old = sections(path.read_text() if path.exists() else "")
    _, new = sections(text)
    replacing = {heading: body for heading, body in new}
    out, placed = [], set()
    for heading, body in old:
        if heading in replacing:
            if heading not in placed:
                out.append(replacing[heading])
                placed.add(heading)
        else:
            out.append(body)
    out += [body for heading, body in new if heading not in placed]
    path.write_text(old_head + "".join(_ending(body) for body in out))


def publish(text: str, path: Path | None) -> None:
    """Print a script's section, and put it into ``path`` (its ``--append``) if given."""
    print(text)
    if path is not None:
        put_section(path, text)


def keep_other_sections(path: Path, text: str) -> str:
    """``text`` followed by the sections of ``path`` whose headings it lacks."""
    if not Path(path).exists():
        return text
    _, mine = sections(text)
    own = {heading for heading, _ in mine}
    _, old = sections(Path(path).read_text())
    kept = [body for heading, body in old if heading not in own]
    return _ending(text) + "".join(_ending(body) for body in kept)


def _ending(body: str) -> str:
    """The section ending in one blank line (sections are joined as they are)."""
    return body.rstrip("\n") + "\n\n"
