# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
The layout: layers, no import circles, no module over 800 lines nor function over 80, section 6.

The package is split into subpackages that are layers (:data:`LAYERS`, bottom first): a module
imports only modules of its own subpackage and of the subpackages below it.

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
#: One job per function: none of the package's functions is longer (def to last line).
MAX_FUNCTION_LINES = 80
#: The subpackages of mechdeconv_ros, bottom layer first.
LAYERS = ('schema', 'optics', 'lenses', 'model', 'imaging', 'runtime', 'node', 'tools')
#: Circles that exist and are being removed elsewhere (none: the benchmarks' circle
#: node_latency -> report -> node_latency / speed was removed on branch perf, issue 21).
KNOWN_CIRCLES: set[frozenset[str]] = set()


def modules() -> dict[str, Path]:
    """Return every module of the two packages by dotted name."""
    out = {}
    for package in PACKAGES:
        for path in sorted((REPO / package).rglob('*.py')):
            if path.stem != '__init__':
                parts = path.relative_to(REPO).with_suffix('').parts
                out['.'.join(parts)] = path
    return out


def layer_of(name: str) -> int:
    """Return the layer index of a ``mechdeconv_ros.<subpackage>.<module>`` name."""
    return LAYERS.index(name.split('.')[1])


def short(name: str) -> str:
    """Return ``subpackage/module`` of a dotted ``mechdeconv_ros`` module name."""
    return '/'.join(name.split('.')[1:])


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
    assert 'mechdeconv_ros.lenses.lens_source' in graph['mechdeconv_ros.model.model']
    assert 'mechdeconv_ros.model.model' not in graph['mechdeconv_ros.lenses.lens_source']


def test_every_module_is_in_a_layer():
    """No module sits in the package's top folder: each is in one of the layer subpackages."""
    found = [n for n in modules() if n.startswith('mechdeconv_ros.')]
    assert found
    stray = [n for n in found if len(n.split('.')) != 3 or n.split('.')[1] not in LAYERS]
    assert not stray, f'modules outside the layers {LAYERS}: {stray}'
    folders = {p.name for p in (REPO / 'mechdeconv_ros').iterdir()
               if p.is_dir() and (p / '__init__.py').exists()}
    assert folders == set(LAYERS)


@pytest.mark.parametrize('layer', LAYERS)
def test_each_layer_says_what_it_holds(layer):
    """Each subpackage's __init__ has a docstring saying what it holds and may import."""
    doc = ast.get_docstring(ast.parse((REPO / 'mechdeconv_ros' / layer / '__init__.py')
                                      .read_text()))
    assert doc and 'import' in doc, f'{layer}/__init__.py says nothing of its imports'


def upward_imports(graph: dict[str, set[str]]) -> list[tuple[str, str]]:
    """Return (module, import) pairs where a package module imports a higher layer."""
    return sorted((short(name), short(dep)) for name, deps in graph.items()
                  if name.startswith('mechdeconv_ros.') for dep in deps
                  if dep.startswith('mechdeconv_ros.') and layer_of(dep) > layer_of(name))


def test_a_module_imports_only_its_layer_and_those_below():
    """No upward import: a module's package imports are in its own layer or lower ones."""
    upward = upward_imports(import_graph())
    assert not upward, f'upward imports (module, import): {upward}'


def test_the_layer_rule_finds_an_upward_import():
    """The rule is not vacuous: optics importing the node is an upward import; the reverse not."""
    graph = {'mechdeconv_ros.optics.a': {'mechdeconv_ros.node.b'},
             'mechdeconv_ros.node.b': {'mechdeconv_ros.optics.a'}}
    assert upward_imports(graph) == [('optics/a', 'node/b')]


@pytest.mark.parametrize('name', sorted(n for n in modules() if n.startswith('mechdeconv_ros')))
def test_no_package_module_over_800_lines(name):
    """One job per module: none of the package's modules is longer than 800 lines."""
    lines = len(modules()[name].read_text().splitlines())
    assert lines <= MAX_LINES, f'{name} has {lines} lines'


def long_functions(source: str, limit: int = MAX_FUNCTION_LINES) -> list[tuple[str, int]]:
    """Return ``(name, lines)`` of the functions (and methods) of a source longer than limit."""
    return [(node.name, node.end_lineno - node.lineno + 1)
            for node in ast.walk(ast.parse(source))
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef))
            and node.end_lineno - node.lineno + 1 > limit]


def test_the_function_length_rule_finds_a_long_function():
    """The rule is not vacuous: a function of limit + 1 lines is found, one of limit is not."""
    body = ''.join(f'    x{i} = {i}\n' for i in range(MAX_FUNCTION_LINES - 1))
    short_one = f'def fits():\n{body}'
    long_one = f'def too_long():\n{body}    return 0\n'
    assert long_functions(short_one) == []
    assert long_functions(long_one) == [('too_long', MAX_FUNCTION_LINES + 1)]


@pytest.mark.parametrize('name', sorted(n for n in modules() if n.startswith('mechdeconv_ros')))
def test_no_package_function_over_80_lines(name):
    """One job per function: none is longer than 80 lines (split it into named steps)."""
    found = long_functions(modules()[name].read_text())
    assert not found, f'{name}: functions over {MAX_FUNCTION_LINES} lines: {found}'


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
    package = {name.split('.')[-1] for name in graph if name.startswith('mechdeconv_ros.')}
    for name in sorted(graph):
        if not name.startswith('mechdeconv_ros.'):
            continue
        row = f'{short(name)}.py'
        assert row in table, f'docs/design.md section 6 has no row for {row}'
        listed = set(re.findall(r'\w+', table[row])) & package
        actual = {m.split('.')[-1] for m in graph[name]}
        assert listed == actual, f'{row}: the layout says {sorted(listed)}, ' \
                                 f'the source imports {sorted(actual)}'


def test_the_layout_rows_import_only_rows_above_them():
    """The table runs from the bottom up: each module imports only modules listed before it."""
    table = layout_table()
    order = [name[:-3] for name in table]
    graph = import_graph()
    for name in sorted(graph):
        if not name.startswith('mechdeconv_ros.'):
            continue
        above = set(order[:order.index(short(name))])
        below = sorted(short(m) for m in graph[name] if short(m) not in above)
        assert not below, f'{short(name)}.py imports {below}, listed after it in section 6'


@pytest.mark.parametrize('path', ['node/correct_node.py', 'tools/demo.py'])
def test_the_node_and_the_demo_stay_thin(path):
    """The ROS wiring stays wiring: map policy and logging live in the ROS-free layers."""
    lines = len((REPO / 'mechdeconv_ros' / path).read_text().splitlines())
    assert lines <= 300, f'{path} has {lines} lines (at most 300)'
