# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
Published benchmark numbers come from the results files (issue 29, item 5).

The README's results table, results/README_tables.md and docs/benchmarks.md must be exactly
what ``python -m benchmarks.regenerate`` makes of the committed results/*.json: a number
typed by hand, or left from an older run, fails here. Each block of the docs page names its
results file and the run that wrote it.
"""

from __future__ import annotations

import json
from pathlib import Path
import re

from benchmarks import regenerate
from benchmarks.report import machine_line
from benchmarks.run_all import docs_page

REPO = Path(__file__).resolve().parents[1]
RESULTS = REPO / 'results'


def test_readme_results_table_is_generated_from_the_results_files() -> None:
    text = (REPO / 'README.md').read_text()
    assert regenerate.BEGIN in text and regenerate.END in text
    start = text.index(regenerate.BEGIN)
    end = text.index(regenerate.END) + len(regenerate.END)
    assert text[start:end] == regenerate.readme_block(regenerate.load(RESULTS))
    # Every row names the file(s) it is read from, and they exist.
    for row in regenerate.readme_rows(regenerate.load(RESULTS)):
        assert all((RESULTS / name.strip()).is_file() for name in row[-1].split(','))


def test_docs_page_and_readme_tables_are_the_results_files() -> None:
    docs = regenerate.load(RESULTS)
    summary = json.loads((RESULTS / 'run_all.json').read_text())
    body = regenerate.blocks(docs, summary)
    page = REPO / 'docs' / 'benchmarks.md'
    machine = machine_line(summary['machine'])
    assert page.read_text() == docs_page(body, machine, float(summary['load_at_start']),
                                         RESULTS, page)
    tables = (RESULTS / 'README_tables.md').read_text()
    assert all(line in tables for line in body if line.startswith('_Source:'))
    # One source line per results file present.
    sources = re.findall(r'_Source: `results/([a-z_]+\.json)`', page.read_text())
    assert sorted(sources) == sorted(regenerate.RESULT_FILES[name] for name in docs)
