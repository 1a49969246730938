# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
The layout: no import circles, no module over 800 lines, docs/design.md section 6 is true.

The imports are read from the source (AST), every ``import``/``from ... import`` of a
``mechdeconv_ros`` or ``benchmarks`` module, at module level or inside a function (a lazy
import still ties the two modules together).
"""

from __future__ import annotations

import ast
from pathlib import Path
import re

import pytest

REPO = Path(__file__).resolve().parents[1]
PACKAGES = ('mechdeconv_ros', 'benchmarks')
MAX_LINES = 800
#: Circles that exist and are being removed elsewhere (none: the benchmarks' circle
#: node_latency -> report -> node_latency / speed was removed on branch perf, issue 21).
KNOWN_CIRCLES: set[frozenset[str]] = set()


def modules() -> dict[str, Path]:
    """Return every module of the two packages by dotted name."""
    out = {}
    for package in PACKAGES:
        for path in sorted((REPO / package).glob('*.py')):
            if path.stem != '__init__':
                out[f'{package}.{path.stem}'] = path
    return out


def imports_of(path: Path, known: set[str]) -> set[str]:
    """Return the package modules a source file imports (anywhere in it)."""
    out: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            out.update(alias.name for alias in node.names if alias.name in known)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            if node.module in known:
                out.add(node.module)
            out.update(f'{node.module}.{alias.name}' for alias in node.names
                       if f'{node.module}.{alias.name}' in known)
    return out


def import_graph() -> dict[str, set[str]]:
    """Return module -> the package modules it imports."""
    found = modules()
    return {name: imports_of(path, set(found)) - {name} for name, path in found.items()}


def circles(graph: dict[str, set[str]]) -> list[frozenset[str]]:
    """Return the strongly connected components with more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    out: list[frozenset[str]] = []

    def visit(node: str) -> None:
        index[node] = low[node] = len(index)
        stack.append(node)
        on_stack.add(node)
        for nxt in sorted(graph[node]):
            if nxt not in index:
                visit(nxt)
                low[node] = min(low[node], low[nxt])
            elif nxt in on_stack:
                low[node] = min(low[node], index[nxt])
        if low[node] == index[node]:
            component = set()
            while True:
                top = stack.pop()
                on_stack.discard(top)
                component.add(top)
                if top == node:
                    break
            if len(component) > 1:
                out.append(frozenset(component))

    for node in sorted(graph):
        if node not in index:
            visit(node)
    return out


def test_the_circle_finder_finds_a_circle():
    """A two-module circle and a three-module one are found; a chain is not a circle."""
    graph = {'a': {'b'}, 'b': {'a'}, 'c': {'d'}, 'd': {'e'}, 'e': {'c'}, 'f': {'a'}}
    assert sorted(map(sorted, circles(graph))) == [['a', 'b'], ['c', 'd', 'e']]


def test_no_import_circles():
    """No module of mechdeconv_ros or benchmarks reaches itself through its imports."""
    found = [sorted(c) for c in circles(import_graph()) if c not in KNOWN_CIRCLES]
    assert not found, f'import circles: {found}'


def test_the_package_imports_what_the_layout_needs():
    """The graph is read from the real sources: model imports the seam, the seam no model."""
    graph = import_graph()
    assert 'mechdeconv_ros.lens_source' in graph['mechdeconv_ros.model']
    assert 'mechdeconv_ros.model' not in graph['mechdeconv_ros.lens_source']


@pytest.mark.parametrize('name', sorted(n for n in modules() if n.startswith('mechdeconv_ros')))
def test_no_package_module_over_800_lines(name):
    """One job per module: none of the package's modules is longer than 800 lines."""
    lines = len(modules()[name].read_text().splitlines())
    assert lines <= MAX_LINES, f'{name} has {lines} lines'


def layout_table() -> dict[str, str]:
    """Return the imports column of docs/design.md section 6's table, by module file, in order."""
    text = (REPO / 'docs' / 'design.md').read_text()
    section = text.split('## 6. Layout', 1)[1].split('\n## ', 1)[0]
    rows = re.findall(r'^\| `([\w/.]+\.py)` \|.*\| ([^|]*) \|$', section, flags=re.M)
    return dict(rows)


def test_the_layout_section_lists_every_module_with_its_imports():
    """Section 6 has a row per package module whose imports are the package ones it has."""
    table = layout_table()
    graph = import_graph()
    package = {name.split('.', 1)[1] for name in graph if name.startswith('mechdeconv_ros.')}
    for name in sorted(graph):
        if not name.startswith('mechdeconv_ros.'):
            continue
        short = name.split('.', 1)[1]
        assert f'{short}.py' in table, f'docs/design.md section 6 has no row for {short}.py'
        listed = set(re.findall(r'\w+', table[f'{short}.py'])) & package
        actual = {m.split('.', 1)[1] for m in graph[name]}
        assert listed == actual, f'{short}.py: the layout says {sorted(listed)}, ' \
                                 f'the source imports {sorted(actual)}'


def test_the_layout_rows_import_only_rows_above_them():
    """The table runs from the bottom up: each module imports only modules listed before it."""
    table = layout_table()
    order = [name[:-3] for name in table]
    graph = import_graph()
    for name in sorted(graph):
        if not name.startswith('mechdeconv_ros.'):
            continue
        short = name.split('.', 1)[1]
        above = set(order[:order.index(short)])
        below = sorted(m.split('.', 1)[1] for m in graph[name]
                       if m.split('.', 1)[1] not in above)
        assert not below, f'{short}.py imports {below}, listed after it in section 6'
