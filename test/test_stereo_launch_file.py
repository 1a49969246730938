# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
launch/stereo.launch.py's content, read without launch_ros (as test_launch_file.py).

Its arguments and defaults (the default params file is config/stereo.yaml and loads), that
every ``LaunchConfiguration`` it reads is declared and documented, the one Node (the
``stereo_node`` console script of setup.py, its name and namespace, the params file and both
sides' ``image_transport``), and the Fast DDS profile set in the node's scoped group only
when ``use_fastdds_profile`` is true. A broken copy is rejected. The default params file is
keyed so rcl hands it to the node in any namespace, and the CLI reads every such key.
"""

from __future__ import annotations

import ast
from pathlib import Path
import re

from mechdeconv_ros.schema.params import IMAGE_TRANSPORTS
from mechdeconv_ros.schema.stereo_params import load_stereo_params_file
import pytest
from test_launch_file import _calls, _config_name, _kw
import yaml

REPO = Path(__file__).resolve().parents[1]
LAUNCH = REPO / 'launch' / 'stereo.launch.py'


def check_stereo_launch_file(text: str) -> None:
    """Assert the launch file's arguments, node and parameters (module doc)."""
    tree = ast.parse(text)
    declared = {ast.literal_eval(c.args[0]): c for c in _calls(tree, 'DeclareLaunchArgument')}
    assert sorted(declared) == ['image_transport', 'namespace', 'params_file',
                                'use_fastdds_profile']
    assert ast.literal_eval(_kw(declared['image_transport'], 'choices')) == \
        list(IMAGE_TRANSPORTS)
    parts = [ast.literal_eval(a) for a in _kw(declared['params_file'], 'default_value').args[1:]]
    assert parts == ['config', 'stereo.yaml']
    load_stereo_params_file(REPO.joinpath(*parts))
    read = {_config_name(node) for node in ast.walk(tree)} - {None}
    assert read <= set(declared), f'undeclared launch arguments read: {read - set(declared)}'
    documented = set(re.findall(r'^\* ``(\w+)``', ast.get_docstring(tree) or '', re.M))
    assert documented == set(declared)
    (node,) = _calls(tree, 'Node')
    assert ast.literal_eval(_kw(node, 'executable')) == 'stereo_node'
    assert 'stereo_node = mechdeconv_ros.node.entry:stereo_node' in (
        REPO / 'setup.py').read_text()
    assert ast.literal_eval(_kw(node, 'name')) == 'stereo_node'
    assert _config_name(_kw(node, 'namespace')) == 'namespace'
    params = _kw(node, 'parameters').elts
    assert _config_name(params[0]) == 'params_file'
    assert [ast.literal_eval(k) for k in params[1].keys] == ['left.image_transport',
                                                             'right.image_transport']
    assert {_config_name(v) for v in params[1].values} == {'image_transport'}
    (group,) = _calls(tree, 'GroupAction')
    assert ast.literal_eval(_kw(group, 'scoped')) is True
    inside = _kw(group, 'actions').elts
    assert node in inside
    (setter,) = [c for c in inside if getattr(c.func, 'id', '') == 'SetEnvironmentVariable']
    assert getattr(setter.args[0], 'id', '') == 'PROFILE_VAR'
    condition = _kw(setter, 'condition')
    assert _config_name(condition.args[0]) == 'use_fastdds_profile'


def test_the_stereo_launch_file_declares_and_passes_what_the_node_takes() -> None:
    check_stereo_launch_file(LAUNCH.read_text())


@pytest.mark.parametrize('old, new', [
    ("'right.image_transport': LaunchConfiguration('image_transport')",
     "'right.image_transport': LaunchConfiguration('transport')"),
    ("executable='stereo_node'", "executable='correct_node'"),
], ids=['undeclared-argument', 'wrong-executable'])
def test_the_check_rejects_a_broken_stereo_launch_file(old: str, new: str) -> None:
    text = LAUNCH.read_text()
    assert old in text
    with pytest.raises(AssertionError):
        check_stereo_launch_file(text.replace(old, new))


def test_the_default_params_file_reaches_the_node_in_any_namespace() -> None:
    """
    Key config/stereo.yaml so that rcl hands it to stereo_node in every namespace.

    rcl gives a params-file section to a node when its key is ``/**``, ``/**/<name>`` or the
    node's full name; a bare ``stereo_node:`` is ``/stereo_node`` and is silently ignored by
    the node in ``namespace:=stereo`` (which then fails on its empty sensor size).
    """
    document = yaml.safe_load(REPO.joinpath('config', 'stereo.yaml').read_text())
    assert set(document) <= {'/**', '/**/stereo_node'}, sorted(document)


@pytest.mark.parametrize('key', ['/**/stereo_node', 'stereo_node', '/stereo_node', '/**'],
                         ids=['any-namespace', 'bare', 'root', 'wildcard'])
def test_every_key_rcl_gives_the_node_is_read_by_the_cli(key: str, tmp_path: Path) -> None:
    path = tmp_path / 'stereo.yaml'
    path.write_text(yaml.safe_dump({key: {'ros__parameters': {'rig': {'baseline_mm': 75.0}}}}))
    assert load_stereo_params_file(path)['rig.baseline_mm'] == 75.0
