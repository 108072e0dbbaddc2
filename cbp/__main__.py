# SPDX-License-Identifier: Apache-2.0
"""``python -m cbp``: the same as the ``cbp`` command."""

from cbp.cli import main

raise SystemExit(main())
