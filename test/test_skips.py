# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
No test turns a broken or missing module of this package into a skip (issue 29, item 6).

Guards such as ``skipif(find_spec('mechdeconv_ros.optics.glass') is None)`` were left from
before those modules were merged: an ImportError in the module then reads as "skipped", not
as a failure. Skips are for what the test venv lacks by design (launch_ros, optiland); a test
module of this package that is absent must fail. Order-dependent skips ("runs after ...") are
refused too: a test must pass run alone.
"""

from __future__ import annotations

from pathlib import Path
import re

TEST = Path(__file__).resolve().parent

#: What a guard on this package's own modules or parameters looks like.
GUARDS = (re.compile(r'find_spec\(\s*.mechdeconv_ros'),
          re.compile(r'importorskip\(\s*.mechdeconv_ros'),
          re.compile(r'skipif\([^)]*\bin SPECS'),
          re.compile(r'HAVE_(GLASS|DATASHEET)\b'),
          re.compile(r'pytest\.skip\(\s*.runs after'))


def test_no_skip_guards_on_the_package_itself() -> None:
    found = []
    for path in sorted(TEST.glob('*.py')):
        if path.name == Path(__file__).name:
            continue
        for number, line in enumerate(path.read_text().splitlines(), start=1):
            if any(guard.search(line) for guard in GUARDS):
                found.append(f'{path.name}:{number}: {line.strip()}')
    assert not found, '\n'.join(found)
