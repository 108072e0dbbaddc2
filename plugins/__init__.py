# SPDX-License-Identifier: Apache-2.0
"""The in-tree task and constraint plugins of cbp, imported as ``cbp.plugins``.

The repository keeps them at its top (``plugins/tasks``, ``plugins/constraints``);
``cbp/plugins`` links here, and the wheel installs them under ``cbp``.
"""
