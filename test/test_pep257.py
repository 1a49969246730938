# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""ament_pep257 over the package (the rclpy docstring house style)."""

from pathlib import Path

from ament_pep257.main import main
import pytest

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.linter
@pytest.mark.pep257
def test_pep257():
    paths = [str(ROOT / name) for name in ('mechdeconv_ros', 'test', 'tools', 'benchmarks',
                                           'launch')
             if (ROOT / name).exists()]
    rc = main(argv=paths)
    assert rc == 0, 'Found code style errors / warnings'
