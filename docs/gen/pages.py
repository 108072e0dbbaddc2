"""Write the generated reference pages at build time (run by mkdocs-gen-files).

Nothing written here is committed: the pages are made from the code on every
build (``reference.py`` beside this file), and ``benchmarks/RESULTS.md`` is
copied in as it is.
"""

import sys
from pathlib import Path

import mkdocs_gen_files

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
sys.path.insert(0, str(HERE))

import reference  # noqa: E402

PAGES = {
    "reference/cli.md": reference.cli_page,
    "reference/scenario.md": reference.scenario_page,
    "reference/robot-yaml.md": reference.robot_page,
    "reference/input-profile.md": reference.input_profile_page,
    "reference/plugins.md": reference.plugins_page,
}

for path, make in PAGES.items():
    with mkdocs_gen_files.open(path, "w") as page:
        page.write(make())
    mkdocs_gen_files.set_edit_path(path, "gen/reference.py")

with mkdocs_gen_files.open("reference/api.md", "w") as page:
    page.write(reference.api_page())

results = (ROOT / "benchmarks" / "RESULTS.md").read_text(encoding="utf-8")
with mkdocs_gen_files.open("measurements/benchmarks.md", "w") as page:
    page.write(results)
