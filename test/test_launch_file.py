# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
launch/correct.launch.py's content, read without launch_ros (issue 29, item 6).

The PyPI route of ``make test`` has no launch packages, so test_launch.py (which RUNS the file
with ``launch.LaunchService``) skips there. This test parses the launch file with :mod:`ast`
and checks what it declares and passes, against the package itself: the four arguments and
their defaults and choices (``image_transport``'s are the schema's), that every
``LaunchConfiguration`` it reads is declared, the one Node (package, the console-script
executable, name, namespace, parameters: the params file and image_transport), and the Fast
DDS profile variable set in the node's scoped group only when ``use_fastdds_profile`` is true.
The same checks run on two broken copies of the file, which they must reject.
"""

from __future__ import annotations

import ast
from pathlib import Path
import re
from typing import Any

from mechdeconv_ros.node.process_env import FASTDDS_PROFILE_NAME, PROFILE_VAR
from mechdeconv_ros.schema.params import IMAGE_TRANSPORTS
import pytest

REPO = Path(__file__).resolve().parents[1]
LAUNCH = REPO / 'launch' / 'correct.launch.py'


def _calls(tree: ast.AST, name: str) -> list[ast.Call]:
    return [node for node in ast.walk(tree) if isinstance(node, ast.Call) and
            getattr(node.func, 'id', getattr(node.func, 'attr', None)) == name]


def _kw(call: ast.Call, name: str) -> Any:
    for keyword in call.keywords:
        if keyword.arg == name:
            return keyword.value
    return None


def _config_name(node: Any) -> str | None:
    """Return X of ``LaunchConfiguration('X')``, else None."""
    if isinstance(node, ast.Call) and getattr(node.func, 'id', '') == 'LaunchConfiguration':
        return ast.literal_eval(node.args[0])
    return None


def check_launch_file(text: str) -> None:
    """Assert the launch file's arguments, node and parameters (module doc)."""
    tree = ast.parse(text)
    declared = {}
    for call in _calls(tree, 'DeclareLaunchArgument'):
        name = ast.literal_eval(call.args[0])
        choices = _kw(call, 'choices')
        declared[name] = (_kw(call, 'default_value'),
                          ast.literal_eval(choices) if choices is not None else None)
    assert sorted(declared) == ['image_transport', 'namespace', 'params_file',
                                'use_fastdds_profile']
    assert ast.literal_eval(declared['namespace'][0]) == ''
    assert ast.literal_eval(declared['image_transport'][0]) == 'raw'
    assert declared['image_transport'][1] == list(IMAGE_TRANSPORTS)
    assert ast.literal_eval(declared['use_fastdds_profile'][0]) == 'true'
    assert declared['use_fastdds_profile'][1] == ['true', 'false']
    # The default params file: os.path.join(share, 'config', 'case2.yaml'), and it exists.
    parts = [ast.literal_eval(a) for a in declared['params_file'][0].args[1:]]
    assert parts == ['config', 'case2.yaml'] and (REPO.joinpath(*parts)).is_file()
    read = {_config_name(node) for node in ast.walk(tree)} - {None}
    assert read <= set(declared), f'undeclared launch arguments read: {read - set(declared)}'
    # The documented arguments are the declared ones.
    documented = set(re.findall(r'^\* ``(\w+)``', ast.get_docstring(tree) or '', re.M))
    assert documented == set(declared)

    nodes = _calls(tree, 'Node')
    assert len(nodes) == 1
    node = nodes[0]
    assert ast.literal_eval(_kw(node, 'executable')) == 'correct_node'
    assert 'correct_node = mechdeconv_ros.node.entry:correct_node' in (
        REPO / 'setup.py').read_text()
    assert ast.literal_eval(_kw(node, 'name')) == 'correct_node'
    assert _config_name(_kw(node, 'namespace')) == 'namespace'
    params = _kw(node, 'parameters').elts
    assert _config_name(params[0]) == 'params_file'
    assert len(params) == 2 and isinstance(params[1], ast.Dict)
    assert [ast.literal_eval(k) for k in params[1].keys] == ['image_transport']
    assert _config_name(params[1].values[0]) == 'image_transport'

    # The profile variable: set in a scoped group holding the node, under the argument.
    groups = _calls(tree, 'GroupAction')
    assert len(groups) == 1 and ast.literal_eval(_kw(groups[0], 'scoped')) is True
    inside = _kw(groups[0], 'actions').elts
    assert node in inside
    setters = [c for c in inside if getattr(c.func, 'id', '') == 'SetEnvironmentVariable']
    assert len(setters) == 1
    setter = setters[0]
    assert getattr(setter.args[0], 'id', '') == 'PROFILE_VAR'
    assert PROFILE_VAR == 'FASTRTPS_DEFAULT_PROFILES_FILE'
    path = setter.args[1]
    assert ast.literal_eval(path.args[1]) == 'config'
    assert getattr(path.args[2], 'id', '') == 'FASTDDS_PROFILE_NAME'
    assert (REPO / 'config' / FASTDDS_PROFILE_NAME).is_file()
    condition = _kw(setter, 'condition')
    assert isinstance(condition, ast.Call) and getattr(condition.func, 'id', '') == 'IfCondition'
    assert _config_name(condition.args[0]) == 'use_fastdds_profile'


def test_the_launch_file_declares_and_passes_what_the_node_takes() -> None:
    check_launch_file(LAUNCH.read_text())


@pytest.mark.parametrize('old, new', [
    ("{'image_transport': LaunchConfiguration('image_transport')}",
     "{'image_transport': LaunchConfiguration('transport')}"),
    ("condition=IfCondition(LaunchConfiguration('use_fastdds_profile'))", 'condition=None'),
], ids=['undeclared-argument', 'unconditional-profile'])
def test_the_check_rejects_a_broken_launch_file(old: str, new: str) -> None:
    text = LAUNCH.read_text()
    assert old in text
    with pytest.raises(AssertionError):
        check_launch_file(text.replace(old, new))
