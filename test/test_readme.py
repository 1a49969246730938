# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
The README stays true: its parameters table is the schema's, its commands exist, configs load.

The table between ``<!-- params:start -->`` and ``<!-- params:end -->`` must equal what
``tools/gen_readme_params.py`` generates from :data:`mechdeconv_ros.schema.params.SCHEMA`, and so
must docs/parameters.md (run that tool after changing the schema). Every ``config/*.yaml`` must
load through the same loader the CLI uses, and the paper's case files must build a lens model.
"""

from __future__ import annotations

import importlib.util
from pathlib import Path
import re
from types import ModuleType

from mechdeconv_ros.model.model import build_model
from mechdeconv_ros.schema.params import load_params_file, SCHEMA
import pytest

REPO = Path(__file__).resolve().parents[1]
README = REPO / 'README.md'
#: The single cameras' params files; config/stereo*.yaml are stereo_node's (test_stereo.py).
CONFIGS = sorted(p for p in (REPO / 'config').glob('*.yaml') if not p.name.startswith('stereo'))
CASES = sorted((REPO / 'config').glob('case*.yaml'))


def load_generator() -> ModuleType:
    """Import tools/gen_readme_params.py (tools/ is not a package)."""
    spec = importlib.util.spec_from_file_location('gen_readme_params',
                                                  REPO / 'tools' / 'gen_readme_params.py')
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope='module')
def readme() -> str:
    return README.read_text(encoding='utf-8')


def test_parameters_table_is_generated_from_the_schema(readme: str) -> None:
    gen = load_generator()
    assert gen.table_in(readme) == gen.params_table(), (
        'README parameters table is out of date: run python tools/gen_readme_params.py')
    assert gen.update(readme) == readme


def test_parameters_page_is_generated_from_the_schema() -> None:
    gen = load_generator()
    page = (REPO / 'docs' / 'parameters.md').read_text(encoding='utf-8')
    assert page == gen.parameters_page(), (
        'docs/parameters.md is out of date: run python tools/gen_readme_params.py')
    for spec in SCHEMA:
        assert spec.description in page, spec.name


def test_parameters_table_has_one_row_per_parameter(readme: str) -> None:
    gen = load_generator()
    rows = gen.table_in(readme).splitlines()[2:]
    # The asphere terms a4 ... a16 share one row (`lens.surfaces.asphere_a4` ... `_a16`).
    names = [re.match(r'\| `([^`]+)`( \.\.\. `_a16`)? \|', row).group(1) for row in rows]
    assert names == gen.readme_row_names()
    # Folded groups (`lens.tolerance.*`) stand for every member; none is left out.
    for spec in SCHEMA:
        assert spec.name in names or spec.name in gen.ASPHERE_FOLDED or any(
            label.endswith('*') and spec.name.startswith(label[:-1]) for label in names), spec.name


def test_generator_refuses_a_readme_without_markers() -> None:
    gen = load_generator()
    with pytest.raises(ValueError, match='params:start'):
        gen.update('# no table here\n')


@pytest.mark.parametrize('command', ['make demo', 'make test'], ids=['demo', 'test'])
def test_readme_documents_the_two_commands(readme: str, command: str) -> None:
    assert f'`{command}`' in readme
    assert re.search(rf'^{command}$', readme, re.MULTILINE), f'no code line "{command}"'


def test_the_two_commands_are_makefile_targets() -> None:
    makefile = (REPO / 'Makefile').read_text(encoding='utf-8')
    for target in ('demo', 'test'):
        assert re.search(rf'^{target}:', makefile, re.MULTILINE), target


def test_readme_mentions_every_config_file(readme: str) -> None:
    for path in sorted((REPO / 'config').iterdir()):
        assert f'config/{path.name}' in readme, path.name


@pytest.mark.parametrize('path', CONFIGS, ids=[p.name for p in CONFIGS])
def test_config_file_loads(path: Path) -> None:
    values = load_params_file(path)
    assert set(values) == {spec.name for spec in SCHEMA}


@pytest.mark.parametrize('path', CASES, ids=[p.name for p in CASES])
def test_case_file_builds_a_model(path: Path) -> None:
    values = load_params_file(path)
    model = build_model(values)
    assert model.width == values['sensor.width_px'] > 0
    assert model.height == values['sensor.height_px'] > 0
    assert model.focal_length_mm > 0.0
    assert model.max_displacement_px > 0.0
