# SPDX-License-Identifier: Apache-2.0
"""Executors: ways of turning the engine's steps into robot motion."""
