# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
Pictures of a LensModel: distortion, a grid before and after, relative illumination.

Panels: the distortion curve, the displacement field, a grid before and after the
correction, and the relative illumination (curve and raw attenuation map).

Matplotlib with the Agg backend (no display needed). The grid is rendered in the ideal
(corrected) image and pushed through the forward model to make what the camera would see, so
the "after" panel shows the correction undoing the lens.

The two image panels show a frame of ``W x H`` px in a panel of about 500 display px, i.e.
scaled by ``s = min(panel_w / W, panel_h / H)`` (0.3 for a 1600x1200 sensor). A chart of
1 or 2 px lines, shown at that scale by nearest-neighbour sampling, aliases: lines vanish,
break into dashes and beat against the display grid. So the chart's lines are drawn
``LINE_DISPLAY_PX / s`` image px wide (about ``LINE_DISPLAY_PX`` px once shown), and each panel
is reduced to its display size with ``cv2.INTER_AREA`` (an area average, which low-passes
before it samples) before matplotlib shows it nearly pixel for pixel.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import cv2
from mechdeconv_ros.model.model import LensModel
import numpy as np

#: Width of the chart's lines once shown in a panel, display px.
LINE_DISPLAY_PX = 2.0
#: Resolution of the figure, dots per inch (display px per inch of the 12 x 9 in figure).
DPI = 100


def grid_image(width: int, height: int, cells_x: int = 20, cells_y: int = 18,
               line_px: int = 2) -> np.ndarray:
    """
    Draw a box grid (the paper's 20 x 18 target), white lines on black.

    :param width: image width in px.
    :param height: image height in px.
    :param cells_x: boxes across.
    :param cells_y: boxes down.
    :param line_px: line width in px.
    :return: ``(height, width)`` uint8.
    """
    image = np.zeros((height, width), np.uint8)
    margin_x, margin_y = 0.04 * width, 0.04 * height
    for x in np.linspace(margin_x, width - 1 - margin_x, cells_x + 1):
        image[:, max(0, int(round(x)) - line_px // 2):int(round(x)) + (line_px + 1) // 2] = 255
    for y in np.linspace(margin_y, height - 1 - margin_y, cells_y + 1):
        image[max(0, int(round(y)) - line_px // 2):int(round(y)) + (line_px + 1) // 2, :] = 255
    return image


def display_scale(ax: Any, width: int, height: int) -> float:
    """
    Return the display px per image px of a ``width x height`` image shown in ``ax``.

    With ``aspect='equal'`` matplotlib shrinks the axes box to the image's aspect, so the
    scale is the smaller of the two ratios. Call it after the figure's layout is final.

    :param ax: the matplotlib axes.
    :param width: image width in px.
    :param height: image height in px.
    :return: the scale ``s`` (< 1 when the image is reduced).
    """
    box = ax.get_window_extent()
    return min(box.width / width, box.height / height)


def to_display(image: np.ndarray, scale: float) -> np.ndarray:
    """
    Reduce an image to the size it is shown at, by area averaging.

    :param image: the image, ``(H, W)`` or ``(H, W, C)``.
    :param scale: display px per image px (:func:`display_scale`); >= 1 leaves it as it is.
    :return: the image at ``round(W s) x round(H s)`` px (at least 1 x 1).
    """
    if scale >= 1.0:
        return image
    height, width = image.shape[:2]
    size = (max(1, round(width * scale)), max(1, round(height * scale)))
    return cv2.resize(image, size, interpolation=cv2.INTER_AREA)


def make_figure(model: LensModel) -> Any:
    """
    Draw the six panels: curve, displacement field, raw grid, corrected grid, RI, RI map.

    :param model: the lens model.
    :return: the matplotlib figure (Agg); the image panels are ``fig.axes[2:4]`` in the order
        raw, corrected (``fig.axes`` also holds the twin axis, the colour bar and the two
        relative-illumination panels after them).
    """
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    from mechdeconv_ros.imaging.remap import distort_image, Rectifier

    fig = plt.figure(figsize=(18, 9), dpi=DPI)
    layout = fig.add_gridspec(2, 3)
    # The four original panels first, so fig.axes[2:4] stay the raw and corrected images.
    axes = np.array([[fig.add_subplot(layout[r, c]) for c in range(2)] for r in range(2)])
    _curve_panel(model, axes[0, 0])
    _displacement_panel(model, axes[0, 1], fig)

    panels = ((axes[1, 0], 'what the camera sees (grid through the lens)'),
              (axes[1, 1], 'corrected'))
    for ax, title in panels:
        ax.set_title(title)
        ax.set_axis_off()
    illumination_panels(model, fig.add_subplot(layout[0, 2]), fig.add_subplot(layout[1, 2]),
                        fig)
    values = model.values
    if values['lens.surfaces.radius_mm']:
        stop = f"{len(values['lens.surfaces.radius_mm'])} surfaces, stop surface " \
            f"{values['lens.stop_surface']}"
    else:
        stop = f"stop offset {values['lens.stop_offset_mm']:g} mm"
    distance = values['scene.distance_mm']
    scene = f'scene at {distance:g} mm' if distance else 'scene at infinity'
    fig.suptitle(f'f = {model.focal_length_mm:.4g} mm, {stop}, {scene}, '
                 f'{model.width}x{model.height} px')
    # The layout first: the panels' size in display px sets how wide the chart's lines are.
    fig.tight_layout()
    scale = min(display_scale(axes[1, 0], model.width, model.height),
                display_scale(axes[1, 1], model.out_width, model.out_height))
    line_px = max(2, math.ceil(LINE_DISPLAY_PX / min(scale, 1.0)))
    grid = grid_image(model.out_width, model.out_height, line_px=line_px)
    raw = distort_image(model, grid)
    corrected = Rectifier(model).correct(raw)
    for (ax, _), image in zip(panels, (raw, corrected)):
        ax.imshow(to_display(image, scale), cmap='gray', vmin=0, vmax=255,
                  interpolation='bilinear', extent=(-0.5, image.shape[1] - 0.5,
                                                    image.shape[0] - 0.5, -0.5))
    return fig


def _curve_panel(model: LensModel, ax: Any) -> None:
    """Draw the traced radial distortion: real - ideal in px, and in percent on a twin axis."""
    pitch = min(model.pixel_mm)
    ideal, real = model.curve.ideal_mm, model.curve.real_mm
    ax.plot(ideal, (real - ideal) / pitch, color='tab:blue')
    ideal_name = ('ideal (pinhole, v tan theta)' if model.projection == 'pinhole'
                  else 'ideal (equidistant, v theta)')
    ax.set_xlabel(f'{ideal_name} image height [mm]')
    ax.set_ylabel('real - ideal [px]', color='tab:blue')
    corner = model.half_diagonal_mm
    ax.axvline(float(model.curve.ideal_from_real(np.array(min(corner, real[-1])))),
               color='grey', ls='--', lw=0.8, label='raw image corner')
    ax.set_title(f'traced radial distortion ({model.distortion_model}: max error '
                 f'{model.equivalent_max_error_px:.2g} px)')
    ax.legend(loc='lower left')
    ax2 = ax.twinx()
    with np.errstate(invalid='ignore', divide='ignore'):
        ax2.plot(ideal[1:], 100.0 * (real[1:] / ideal[1:] - 1.0), color='tab:orange')
    ax2.set_ylabel('distortion [%]', color='tab:orange')


def _displacement_panel(model: LensModel, ax: Any, fig: Any) -> None:
    """Draw where each raw pixel belongs on the ideal sensor (arrows, in raw px)."""
    nx, ny = 24, 18
    u, v = np.meshgrid(np.linspace(0, model.width - 1, nx), np.linspace(0, model.height - 1, ny))
    # Where each raw pixel belongs on the ideal sensor, in raw pixels: the real radius
    # scaled by ideal / real along the same direction.
    x_mm = (u - model.K[0, 2]) * model.pixel_mm[0]
    y_mm = (v - model.K[1, 2]) * model.pixel_mm[1]
    rho = np.hypot(x_mm, y_mm)
    with np.errstate(invalid='ignore', divide='ignore'):
        gain = np.where(rho > 0, model.curve.ideal_from_real(rho) / rho, 1.0) - 1.0
    du, dv = x_mm * gain / model.pixel_mm[0], y_mm * gain / model.pixel_mm[1]
    magnitude = np.hypot(du, dv)
    quiver = ax.quiver(u, v, du, dv, magnitude, angles='xy', cmap='viridis')
    fig.colorbar(quiver, ax=ax, label='displacement [px]')
    ax.set_xlim(0, model.width - 1)
    ax.set_ylim(model.height - 1, 0)
    ax.set_aspect('equal')
    ax.set_title(f'raw -> ideal displacement (max {model.max_displacement_px:.2f} px)')


def illumination_panels(model: LensModel, curve_ax: Any, map_ax: Any, fig: Any) -> None:
    """
    Draw the relative illumination panels.

    RI and the pupil pass fraction over the real image height, and the attenuation at each
    raw pixel (what ``mechdeconv vignetting --png`` writes).

    :param model: the lens model.
    :param curve_ax: axes for the curves.
    :param map_ax: axes for the raw attenuation map.
    :param fig: the figure (for the colour bar).
    """
    from mechdeconv_ros.optics.illumination import raw_attenuation

    try:
        curve = model.illumination()
    except ValueError as err:
        curve_ax.set_title(f'relative illumination: {err}', fontsize=8)
        return
    curve_ax.plot(curve.height_mm, curve.ri, color='tab:blue', label='relative illumination')
    if curve.pupil_pass_fraction is not None:
        curve_ax.plot(curve.height_mm, curve.pupil_pass_fraction, color='tab:green', ls='--',
                      label="share of the stop's beam passing the other apertures")
    gain = float(model.values['output.max_vignetting_gain'])
    curve_ax.axhline(1.0 / gain, color='tab:red', lw=0.8, ls=':',
                     label=f'1 / max gain ({gain:g}): corrected field ends below')
    curve_ax.axvline(curve.corner_height_mm, color='grey', ls='--', lw=0.8,
                     label='raw image corner')
    curve_ax.set_ylim(0.0, 1.05)
    curve_ax.set_xlabel('real image height on the sensor [mm]')
    curve_ax.set_ylabel('sensor irradiance / on axis')
    curve_ax.set_title(f'traced relative illumination (corner {curve.corner_ri:.3f})')
    curve_ax.legend(loc='lower left', fontsize=8)
    image = map_ax.imshow(raw_attenuation(model, curve), cmap='magma', vmin=0.0, vmax=1.0,
                          interpolation='bilinear')
    fig.colorbar(image, ax=map_ax, label='relative illumination')
    map_ax.set_title('attenuation at each raw pixel (vignette map)')
    map_ax.set_axis_off()


def plot_model(model: LensModel, path: Path) -> None:
    """
    Write a six-panel PNG: curve, displacement field, raw grid, corrected grid, RI, RI map.

    :param model: the lens model.
    :param path: the PNG to write.
    """
    import matplotlib.pyplot as plt

    fig = make_figure(model)
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=DPI)
    plt.close(fig)
