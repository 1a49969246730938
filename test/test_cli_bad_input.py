# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
Every command and option of ``mechdeconv`` refuses bad input in one line, never a traceback.

A sweep over the command line (in this process, so it is fast): each case is a command with
one bad option value or file, and the test asserts exit status 2 and one stderr line that
starts ``mechdeconv: error:`` and names what is at fault (``import`` may print its progress
line first). An exception escaping ``main``
fails the test with its traceback, which is what the sweep guards against.
"""

from __future__ import annotations

from pathlib import Path
import re

import cv2
from mechdeconv_ros.tools.cli import main
import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
CASE2 = str(ROOT / 'config' / 'case2.yaml')
ZOOM_TEXT = (ROOT / 'config' / 'zoom.yaml').read_text()
ZMX = str(ROOT / 'test' / 'data' / 'zmx' / 'edmund_55278.zmx')


def _zoom_short_table() -> str:
    """Return config/zoom.yaml with its zoom thickness table one value short."""
    head, tail = ZOOM_TEXT.split('      zoom:\n', 1)
    short = re.sub(r'(thickness_mm: \[.*), [^,\]]+\]', r'\1]', tail, count=1)
    return head + '      zoom:\n' + short


#: Files the cases refer to by name (written into the test's folder).
FILES = {
    'short.yaml': _zoom_short_table(),
    'unordered.yaml': ZOOM_TEXT.replace('positions: [0.0, 0.0625, 0.125',
                                        'positions: [0.0, 0.125, 0.0625'),
    'gap.yaml': ZOOM_TEXT.replace('surfaces: [4, 9, 12]', 'surfaces: [4, 9, 40]'),
    'bad.yaml': 'a: [\n',
    'list.yaml': '- 1\n- 2\n',
    'garbage.zmx': 'hello\nSURF x\n',
    'garbage.csv': 'a,b\nc,d\n',
    'a_file': 'x',
    'stereo.yaml': ('stereo_node:\n  ros__parameters:\n    left: {scene: {distance_mm: 0.0}}\n'
                    '    right: {scene: {distance_mm: 0.0}}\n'),
}

#: (command line with file names relative to the test folder, words the error names).
CASES = [
    # --lens-state with a malformed moving-group table (issue 28's example), every command.
    (['info', '--params', 'short.yaml', '--lens-state', 'zoom=0.5'],
     'lens.zoom.thickness_mm: has 50 values'),
    (['info', '--params', 'unordered.yaml', '--lens-state', 'zoom=0.5', '--json'],
     'lens.zoom.positions: must be strictly increasing'),
    (['info', '--params', 'gap.yaml', '--lens-state', 'zoom=0.5'],
     'lens.zoom.surfaces: 40 is not an index'),
    (['camera-info', '--params', 'short.yaml', '--lens-state', 'zoom=0.5'],
     'lens.zoom.thickness_mm'),
    (['correct', '--params', 'gap.yaml', '--lens-state', 'zoom=0.5', 'in.png', 'out.png'],
     'lens.zoom.surfaces'),
    (['plot', '--params', 'unordered.yaml', '--lens-state', 'zoom=0.5', 'out.png'],
     'lens.zoom.positions'),
    (['vignetting', '--params', 'gap.yaml', '--lens-state', 'zoom=0.5', '--lensfun'],
     'lens.zoom.surfaces'),
    # The same tables without --lens-state (the route that was already clean).
    (['info', '--params', 'short.yaml'], 'lens.zoom.thickness_mm'),
    # --lens-state itself.
    (['info', '--params', 'gap.yaml', '--lens-state', 'zoom=0.5,zoom=0.6'], 'given twice'),
    (['info', '--params', CASE2, '--lens-state', 'zoom=0.5'], 'zoom does not move'),
    (['info', '--params', 'gap.yaml', '--lens-state', ',,'], 'expected zoom=X'),
    # -p / --param.
    (['info', '--params', CASE2, '-p', 'lens.stop_offset_mm=['], 'the value is not YAML'),
    (['info', '--params', CASE2, '-p', 'lens.stop_offset_mm=abc'], 'lens.stop_offset_mm'),
    (['info', '--params', CASE2, '-p', 'lens.surfaces.radius_mm=[1, "a"]'],
     'lens.surfaces.radius_mm[1]'),
    (['info', '--params', CASE2, '-p', 'no.such_parameter=1'], 'known parameter name'),
    (['info', '--params', CASE2, '-p', 'lens.stop_offset_mm'], 'expected NAME=VALUE'),
    # --params.
    (['info', '--params', 'bad.yaml'], 'not valid YAML'),
    (['info', '--params', 'list.yaml'], 'expected a ROS 2 params file'),
    (['info', '--params', 'a_folder'], '--params: cannot read a_folder'),
    (['info', '--params', 'missing.yaml'], '--params: cannot read missing.yaml'),
    # --width / --height.
    (['info', '--params', CASE2, '--width', '100000', '--height', '100'], 'sensor.width_px'),
    (['camera-info', '--params', CASE2, '--width', '-3'], '--width must be a positive'),
    (['plot', '--params', CASE2, '--height', '0', 'out.png'], '--height must be a positive'),
    # correct: inputs and outputs.
    (['correct', '--params', CASE2, 'in.png', 'out.xyz'], "suffix '.xyz'"),
    (['correct', '--params', CASE2, 'in.png', 'no_folder/out.png'], 'cannot write the image'),
    (['correct', '--params', CASE2, 'images', 'a_file'], 'cannot make the output folder'),
    (['correct', '--params', CASE2, 'a_folder', 'out'], 'no images'),
    (['correct', '--params', CASE2, 'garbage.csv', 'out.png'], 'not a readable image'),
    (['correct', '--params', CASE2, 'int8.tif', 'out.tif'], 'int8 pixels'),
    (['correct', '--params', CASE2, '--bayer', 'rggb', 'in.png', 'out.png'],
     'needs a one-channel 8- or 16-bit raw mosaic'),
    (['correct', '--params', CASE2, '--bayer', 'rggb', 'odd.png', 'out.png'],
     'even width and height'),
    # plot and vignetting outputs.
    (['plot', '--params', CASE2, 'out.xyz'], "suffix '.xyz'"),
    (['plot', '--params', CASE2, 'a_file/out.png'], 'cannot write the figure there'),
    (['vignetting', '--params', CASE2], 'give --png OUT.png, --lensfun or both'),
    (['vignetting', '--params', CASE2, '--png', 'out.xyz'], '--png out.xyz: OpenCV writes no'),
    # import.
    (['import', 'missing.zmx', '-o', 'o.yaml'], 'missing.zmx: cannot read it'),
    (['import', 'a_folder', '-o', 'o.yaml'], 'a_folder: cannot read it'),
    (['import', 'garbage.zmx', '-o', 'o.yaml'], "garbage.zmx: line 2: SURF: 'x'"),
    (['import', 'garbage.csv', '-o', 'o.yaml', '--focal-length-mm', '4'], 'garbage.csv: line 2'),
    (['import', 'garbage.csv', '-o', 'o.yaml'], 'needs --focal-length-mm'),
    (['import', 'garbage.csv', '-o', 'o.yaml', '--focal-length-mm', 'nan'],
     '--focal-length-mm nan'),
    (['import', ZMX, '-o', 'o.yaml', '--focal-length-mm', '4'], 'is for a datasheet table'),
    (['import', ZMX, '-o', 'o.yaml', '--wavelength-nm', 'nan'], 'wavelength nan nm'),
    (['import', ZMX, '-o', 'a_folder'], 'a_folder: cannot write there'),
    # stereo (issue 38): a pair's params, its images and its output folder.
    (['stereo', '--params', CASE2, 'in.png', 'in.png', '-o', 'out'],
     "unknown parameter 'lens."),
    (['stereo', '--params', 'missing.yaml', 'in.png', 'in.png', '-o', 'out'],
     '--params: cannot read missing.yaml'),
    (['stereo', '--params', 'stereo.yaml', '-p', 'rig.baseline_mm=0', 'in.png', 'in.png',
      '-o', 'out'], 'rig.baseline_mm: must be > 0'),
    (['stereo', '--params', 'stereo.yaml', '-p', 'left.lens.r1_mm=[', 'in.png', 'in.png',
      '-o', 'out'], 'the value is not YAML'),
    (['stereo', '--params', 'stereo.yaml', '-p', 'lens.r1_mm=5', 'in.png', 'in.png', '-o',
      'out'], 'known pair parameter name'),
    (['stereo', '--params', 'stereo.yaml', '-p', 'right.lens.thickness_mm=30', 'in.png',
      'in.png', '-o', 'out'], 'right.lens.'),
    (['stereo', '--params', 'stereo.yaml', '-p', 'left.sensor.width_px=100', 'in.png',
      'in.png', '-o', 'out'], 'LEFT: the image is 64x48'),
    (['stereo', '--params', 'stereo.yaml', 'in.png', 'garbage.csv', '-o', 'out'],
     'garbage.csv: not a readable image'),
    (['stereo', '--params', 'stereo.yaml', 'in.png', 'in.png', '-o', 'a_file'],
     'cannot make the output folder'),
]


def _case_id(case: tuple[list[str], str]) -> str:
    argv, words = case
    return f"{argv[0]}-{re.sub(r'[^a-z0-9]+', '_', words.lower()).strip('_')[:40]}"


@pytest.fixture(scope='module')
def folder(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Return a folder with the cases' files in it."""
    root = tmp_path_factory.mktemp('cli_bad_input')
    for name, text in FILES.items():
        (root / name).write_text(text)
    (root / 'a_folder').mkdir()
    (root / 'images').mkdir()
    cv2.imwrite(str(root / 'images' / 'a.png'), np.zeros((48, 64), np.uint8))
    cv2.imwrite(str(root / 'in.png'), np.zeros((48, 64, 3), np.uint8))
    cv2.imwrite(str(root / 'odd.png'), np.zeros((47, 64), np.uint8))
    cv2.imwrite(str(root / 'int8.tif'), np.zeros((48, 64), np.int8))
    return root


@pytest.mark.parametrize(('argv', 'words'), CASES, ids=[_case_id(c) for c in CASES])
def test_bad_input_is_refused_in_one_line(folder: Path, monkeypatch: pytest.MonkeyPatch,
                                          capsys: pytest.CaptureFixture[str],
                                          argv: list[str], words: str) -> None:
    monkeypatch.chdir(folder)
    status = main(argv)
    out, err = capsys.readouterr()
    assert status == 2, (out, err)
    lines = err.strip().splitlines()
    # One error line, last; before it at most progress lines ('mechdeconv: importing ...').
    assert lines[-1].startswith('mechdeconv: error: '), err
    assert all(line.startswith('mechdeconv: ') and 'error' not in line
               for line in lines[:-1]), err
    assert words in lines[-1]
    assert not (folder / 'o.yaml').exists()


def test_the_short_table_fixture_is_one_value_short() -> None:
    """The malformed table differs from the shipped one by exactly its last value."""
    def table(text: str) -> list[str]:
        zoom = text.split('      zoom:\n', 1)[1]
        return re.search(r'thickness_mm: \[(.*)\]', zoom).group(1).split(', ')

    assert table(_zoom_short_table()) == table(ZOOM_TEXT)[:-1]


def test_argparse_refusals_exit_2_with_usage(capsys: pytest.CaptureFixture[str]) -> None:
    """Unknown commands, options and choices are argparse's: status 2, usage, no traceback."""
    for argv in (['nope'], ['info', '--nope'], ['info', '--width', 'wide'],
                 ['correct', '--bayer', 'rgbg', 'a.png', 'b.png'], ['import', 'x.zmx'],
                 ['import', 'x.csv', '-o', 'o.yaml', '--focal-length-mm', 'f'],
                 ['stereo', 'l.png', 'r.png', '-o', 'out'], ['stereo', '--params', 'p.yaml']):
        with pytest.raises(SystemExit) as exit_info:
            main(argv)
        assert exit_info.value.code == 2, argv
        err = capsys.readouterr().err
        assert 'usage: mechdeconv' in err and 'Traceback' not in err, argv
