# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
The order of the test files: the longest first.

``make test`` runs the suite on one pytest-xdist worker per CPU, a whole file to a worker, in
the order collected. A long file that starts last runs alone while the other workers idle;
started first, the short files fill in around it. The list is the files over 15 s in a quiet
run (docs/TEAM_NOTES.md); every other file keeps its place. Only the order changes.
"""

from __future__ import annotations

from typing import Any

#: The longest files, longest first (seconds of a quiet run on 2 vCPUs, docs/TEAM_NOTES.md).
LONG_FIRST = ('test_benchmarks_smoke.py', 'test_reliability.py', 'test_node.py',
              'test_demo.py', 'test_check.py', 'test_check_node.py', 'test_properties.py',
              'test_underwater_reference.py', 'test_wide.py', 'test_robot_graph.py')


def pytest_collection_modifyitems(session: Any, config: Any, items: list[Any]) -> None:
    """Move the long files to the front (a stable sort: the rest keep their order)."""
    rank = {name: index for index, name in enumerate(LONG_FIRST)}
    items.sort(key=lambda item: rank.get(item.path.name, len(LONG_FIRST)))
