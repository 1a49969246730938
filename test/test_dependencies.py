# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
Every third-party module the installed package imports is declared, and nothing else is.

The imports are derived from the source that gets installed: every ``import`` / ``from ...
import`` statement anywhere in ``mechdeconv_ros/**/*.py`` (module level or inside a function,
optional or not) and in the launch files ``launch/*.py``, found with :mod:`ast`. Standard
library modules (:data:`sys.stdlib_module_names`) and the package itself are left out.

Two declarations are held against them:

* ``package.xml`` ``exec_depend``: the rosdep key of every import. Python libraries map to
  their ``python3-*`` keys (:data:`ROSDEP_KEYS`); a ROS package (``rclpy``, ``launch``,
  ``launch_ros``, ``ament_index_python``, every ``*_msgs`` / ``*_interfaces``) is its own key.
* ``setup.py`` ``install_requires``: the pip name of every Python library (:data:`PIP_NAMES`),
  each also pinned in ``requirements.txt``. ROS packages are NOT listed there: on a ROS
  install they come from the distribution (apt / rosdep), are not pip-installable under these
  names, and a console script checking them would fail. The PyPI route installs them from the
  ``ros-jazzy-*`` wheels pinned in ``requirements.txt``; package.xml is their one declaration.

Both ways are checked: an import without a declaration fails (a user's colcon install breaks
on ``mechdeconv correct`` without tqdm), and so does a declaration no import needs.
"""

from __future__ import annotations

import ast
from pathlib import Path
import re
import sys
import xml.etree.ElementTree as ElementTree

import pytest

REPO = Path(__file__).resolve().parents[1]
PACKAGE = 'mechdeconv_ros'

#: Import name -> rosdep key, for Python libraries (not ROS packages).
ROSDEP_KEYS = {
    'cv2': 'python3-opencv',
    'numpy': 'python3-numpy',
    'yaml': 'python3-yaml',
    'matplotlib': 'python3-matplotlib',
    'tqdm': 'python3-tqdm',
}

#: Import name -> pip distribution name, for the same libraries.
PIP_NAMES = {
    'cv2': 'opencv-python-headless',
    'numpy': 'numpy',
    'yaml': 'PyYAML',
    'matplotlib': 'matplotlib',
    'tqdm': 'tqdm',
}

#: ROS packages imported by name (their rosdep key is the name); message and service packages
#: are recognised by their suffix.
ROS_PACKAGES = {'rclpy', 'launch', 'launch_ros', 'ament_index_python'}
ROS_SUFFIXES = ('_msgs', '_interfaces', '_srvs')

#: install_requires entries that are not imports: the ament_python template's setuptools.
PIP_ALLOWED_EXTRA = {'setuptools'}


def installed_sources() -> list[Path]:
    """Return the Python files that get installed: the package and the launch files."""
    files = sorted((REPO / PACKAGE).rglob('*.py')) + sorted((REPO / 'launch').glob('*.py'))
    assert files, 'no source found'
    return files


def third_party_imports() -> dict[str, set[str]]:
    """Return top-level third-party module -> the files importing it."""
    found: dict[str, set[str]] = {}
    for path in installed_sources():
        tree = ast.parse(path.read_text(), filename=str(path))
        for node in ast.walk(tree):
            if isinstance(node, ast.Import):
                names = [alias.name for alias in node.names]
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                names = [node.module]
            else:
                continue
            for name in names:
                top = name.split('.')[0]
                if top in sys.stdlib_module_names or top in (PACKAGE, '__future__'):
                    continue
                found.setdefault(top, set()).add(str(path.relative_to(REPO)))
    return found


def is_ros_package(module: str) -> bool:
    """Return True when the module is a ROS package (its own rosdep key, not on pip)."""
    return module in ROS_PACKAGES or module.endswith(ROS_SUFFIXES)


def exec_depends() -> set[str]:
    """Return the ``exec_depend`` (and ``depend``) keys of package.xml."""
    root = ElementTree.parse(REPO / 'package.xml').getroot()
    return {(e.text or '').strip() for e in root if e.tag in ('exec_depend', 'depend')}


def install_requires() -> list[str]:
    """Return setup.py's ``install_requires`` (a literal list in the setup() call)."""
    tree = ast.parse((REPO / 'setup.py').read_text())
    for node in ast.walk(tree):
        if isinstance(node, ast.keyword) and node.arg == 'install_requires':
            return list(ast.literal_eval(node.value))
    pytest.fail('setup.py has no install_requires')


def pip_key(requirement: str) -> str:
    """Return the normalised distribution name of a requirement ('PyYAML>=6' -> 'pyyaml')."""
    name = re.split(r'[<>=!~;\[ ]', requirement.strip(), maxsplit=1)[0]
    return re.sub(r'[-_.]+', '-', name).lower()


def test_every_import_is_known_to_this_test() -> None:
    unknown = {m: sorted(f) for m, f in third_party_imports().items()
               if not is_ros_package(m) and m not in ROSDEP_KEYS}
    assert not unknown, (f'third-party imports without a rosdep key / pip name here: {unknown}; '
                         'add them to ROSDEP_KEYS and PIP_NAMES (and declare them)')
    assert set(ROSDEP_KEYS) == set(PIP_NAMES)


def test_package_xml_declares_every_import_and_nothing_more() -> None:
    imports = third_party_imports()
    needed = {m if is_ros_package(m) else ROSDEP_KEYS[m]: m for m in imports
              if is_ros_package(m) or m in ROSDEP_KEYS}
    declared = exec_depends()
    missing = {key: sorted(imports[module]) for key, module in needed.items()
               if key not in declared}
    assert not missing, f'package.xml lacks <exec_depend> for (key: importing files) {missing}'
    unused = declared - set(needed)
    assert not unused, f'package.xml declares exec_depends nothing imports: {sorted(unused)}'


def test_setup_py_requires_every_python_library_and_no_ros_package() -> None:
    imports = third_party_imports()
    requires = {pip_key(r) for r in install_requires()}
    needed = {pip_key(PIP_NAMES[m]): m for m in imports if m in PIP_NAMES}
    missing = {PIP_NAMES[module]: sorted(imports[module]) for key, module in needed.items()
               if key not in requires}
    assert not missing, f'setup.py install_requires lacks (pip name: importing files) {missing}'
    extra = requires - set(needed) - {pip_key(p) for p in PIP_ALLOWED_EXTRA}
    assert not extra, (f'setup.py install_requires lists {sorted(extra)}, which no installed '
                       'module imports (ROS packages belong in package.xml only)')


def test_requirements_txt_pins_every_python_library() -> None:
    pins = {}
    for line in (REPO / 'requirements.txt').read_text().splitlines():
        line = line.split('#', 1)[0].strip()
        if line and not line.startswith('-'):
            pins[pip_key(line)] = line
    for module in third_party_imports():
        if module in PIP_NAMES:
            key = pip_key(PIP_NAMES[module])
            assert key in pins, f'requirements.txt does not pin {PIP_NAMES[module]}'
            assert '==' in pins[key], f'requirements.txt does not pin {pins[key]} exactly'


def test_the_scan_sees_imports_inside_functions() -> None:
    # cli.py imports tqdm inside the command that uses it: the scan must still count it.
    assert 'cli.py' in {Path(f).name for f in third_party_imports().get('tqdm', ())}
