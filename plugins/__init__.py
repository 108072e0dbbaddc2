# SPDX-License-Identifier: Apache-2.0
"""The in-tree task and constraint plugins of cbp."""
