# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
``mechdeconv plot`` shows the chart as a person should see it: a clean grid, not aliasing.

The image panels show a frame at about a third of its size (1600x1200 px in a panel of about
500 px for Case 1). What is checked is the rendered figure itself, panel by panel:

* the bright pixels of each grid panel form one connected net (lines that alias break into
  dashes and dots: hundreds of pieces);
* in the corrected panel every one of the 21 columns and 19 rows of the chart is there, bright
  on its line and dark in the middle of its boxes (lines that alias vanish or merge).
"""

from __future__ import annotations

from pathlib import Path

import cv2
from mechdeconv_ros.model.model import build_model
from mechdeconv_ros.schema.params import load_params_file
from mechdeconv_ros.tools.plots import make_figure, plot_model
import numpy as np
import pytest

CONFIG = Path(__file__).resolve().parents[1] / 'config'
CELLS_X, CELLS_Y = 20, 18  # grid_image's defaults


def rendered_panels(case: str) -> tuple[list[np.ndarray], list[tuple[float, float]], object]:
    """Render the figure of a config file; return the two grid panels as shown (grey)."""
    import matplotlib.pyplot as plt

    model = build_model(load_params_file(CONFIG / f'{case}.yaml'))
    fig = make_figure(model)
    fig.canvas.draw()
    pixels = np.asarray(fig.canvas.buffer_rgba())[..., :3].mean(axis=2)
    height = pixels.shape[0]
    panels, scales = [], []
    for ax, (w, h) in zip(fig.axes[2:4], ((model.width, model.height),
                                          (model.out_width, model.out_height))):
        box = ax.get_window_extent()
        top, bottom = int(round(height - box.y1)), int(round(height - box.y0))
        panels.append(pixels[top:bottom, int(round(box.x0)):int(round(box.x1))])
        scales.append((box.width / w, box.height / h))
    plt.close(fig)
    return panels, scales, model


@pytest.mark.parametrize('case', ['case1', 'case2'])
def test_grid_panels_are_one_connected_net(case: str) -> None:
    panels, _, _ = rendered_panels(case)
    for panel in panels:
        bright = (panel > 127).astype(np.uint8)
        count, _, stats, _ = cv2.connectedComponentsWithStats(bright, connectivity=8)
        sizes = sorted(stats[1:, cv2.CC_STAT_AREA], reverse=True)
        # One net; at most a few specks where a clipped line ends at the panel's border.
        assert count - 1 >= 1
        assert sum(sizes[1:]) <= 0.01 * sizes[0], (count - 1, sizes[:8])


@pytest.mark.parametrize('case', ['case1', 'case2'])
def test_corrected_panel_shows_every_line_of_the_chart(case: str) -> None:
    panels, scales, model = rendered_panels(case)
    panel = panels[1]
    sx, sy = scales[1]
    w, h = model.out_width, model.out_height
    lines_x = np.linspace(0.04 * w, w - 1 - 0.04 * w, CELLS_X + 1)
    lines_y = np.linspace(0.04 * h, h - 1 - 0.04 * h, CELLS_Y + 1)
    # Median across the other axis: the profile of the lines of one direction only.
    for lines, profile, scale in ((lines_x, np.median(panel, axis=0), sx),
                                  (lines_y, np.median(panel, axis=1), sy)):
        display = (lines + 0.5) * scale - 0.5
        on_line = [profile[max(0, int(p) - 2):int(p) + 3].max() for p in display]
        centres = (display[:-1] + display[1:]) / 2
        in_box = [profile[int(round(c))] for c in centres]
        assert min(on_line) > 150, np.round(on_line)
        assert max(in_box) < 40, np.round(in_box)


def test_plot_model_writes_the_figure(tmp_path: Path) -> None:
    model = build_model(load_params_file(CONFIG / 'case2.yaml'))
    out = tmp_path / 'sub' / 'model.png'
    plot_model(model, out)
    image = cv2.imread(str(out))
    assert image is not None and image.shape[:2] == (900, 1800)
    # The relative-illumination panels (the third column) are drawn: not a blank column.
    assert image[:, 1250:].std() > 10
