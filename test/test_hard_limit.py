# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""The suite's hard per-test limit (:mod:`hard_limit`) ends a test that hangs holding the GIL."""

from __future__ import annotations

import os
from pathlib import Path
import subprocess
import sys
import time

from hard_limit import ENV

HERE = Path(__file__).resolve().parent

#: Catastrophic backtracking: the regex engine runs for ages without releasing the GIL, as
#: the C call that hung in CI did.
HANGS = """
import re


def test_hangs():
    re.match(r'(a+)+$', 'a' * 64 + 'b')
"""


def test_a_test_that_hangs_holding_the_gil_is_ended_with_its_stack(tmp_path: Path) -> None:
    (tmp_path / 'test_hang.py').write_text(HANGS)
    env = dict(os.environ, PYTHONPATH=str(HERE), **{ENV: '1'})
    start = time.monotonic()
    result = subprocess.run(
        [sys.executable, '-m', 'pytest', '-p', 'hard_limit', '-p', 'no:cacheprovider', '-q',
         str(tmp_path / 'test_hang.py')],
        env=env, cwd=tmp_path, capture_output=True, text=True, timeout=120)
    assert result.returncode == 1, result.stdout + result.stderr
    assert time.monotonic() - start < 60
    assert 'Timeout (0:00:01)!' in result.stderr, result.stderr
    assert 'in test_hangs' in result.stderr, result.stderr
