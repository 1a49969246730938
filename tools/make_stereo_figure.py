# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
Draw docs/stereo_frames.png: the stereo rig's frames, t, R and the rectified frame (section 8).

The rig is drawn with exaggerated angles (a real rig is turned by tenths of a degree) and
computed by the package itself (:func:`mechdeconv_ros.model.stereo.rig_rotation`,
:func:`~mechdeconv_ros.model.stereo.rectifying_rotations`), so the figure cannot drift from
the code. Usage::

    python tools/make_stereo_figure.py [OUT.png]
"""

from __future__ import annotations

from pathlib import Path
import sys

import matplotlib
matplotlib.use('Agg')
import matplotlib.pyplot as plt  # noqa: E402 - after the backend

REPO = Path(__file__).resolve().parents[1]
if str(REPO) not in sys.path:
    sys.path.insert(0, str(REPO))

from mechdeconv_ros.model.stereo import rectifying_rotations, Rig  # noqa: E402
import numpy as np  # noqa: E402

#: The drawn rig: mm and deg, exaggerated to be visible.
RIG = Rig(baseline_mm=120.0, offset_y_mm=12.0, offset_z_mm=-25.0, rotation_x_deg=8.0,
          rotation_y_deg=-18.0, rotation_z_deg=10.0)
AXIS_MM = 45.0
COLOURS = ('tab:red', 'tab:green', 'tab:blue')
NAMES = ('X', 'Y', 'Z')


def _frames(ax, view: tuple[int, int] | None) -> None:
    """Draw both cameras' axes, t and the rectified axes; ``view`` None = top view (X, Z)."""
    r1, _ = rectifying_rotations(RIG)
    t = RIG.t_mm

    def line(p, q, **style):
        if view is None:
            ax.plot([p[0], q[0]], [p[2], q[2]], **style)
        else:
            ax.plot([p[0], q[0]], [p[2], q[2]], [-p[1], -q[1]], **style)

    def label(p, text, **style):
        if view is None:
            ax.text(p[0], p[2], text, **style)
        else:
            ax.text(p[0], p[2], -p[1], text, **style)

    for origin, axes, who in ((np.zeros(3), np.eye(3), 'left'), (t, RIG.R, 'right')):
        for k in range(3):
            tip = origin + AXIS_MM * axes[:, k]
            line(origin, tip, color=COLOURS[k], lw=2.5)
            label(tip, f'{NAMES[k]}$_{{{who[0]}}}$', color=COLOURS[k], fontsize=10)
        for k in range(3):
            # Rectified axes, the same for both cameras: R1^T e_k in the left frame.
            tip = origin + 0.8 * AXIS_MM * r1[k]
            line(origin, tip, color=COLOURS[k], lw=1.2, ls='--')
        label(origin + [-8.0, 8.0, -12.0], f'{who} E', fontsize=10)
    line(np.zeros(3), t, color='black', lw=1.5)
    label(0.5 * t + [0.0, 0.0, -14.0], 't', fontsize=12)
    if view is None:
        ax.set_xlabel('X (mm, right)')
        ax.set_ylabel('Z (mm, ahead)')
        ax.set_aspect('equal')
        ax.grid(alpha=0.3)
        ax.set_title('top view (Y down, into the page)')
    else:
        ax.set_xlabel('X (mm)')
        ax.set_ylabel('Z (mm)')
        ax.set_zlabel('-Y (mm, up)')
        ax.view_init(*view)
        ax.set_box_aspect((1.7, 1.0, 0.9))
        ax.set_title("in the left camera's optical frame")


def main(argv: list[str]) -> int:
    """Write the figure (default docs/stereo_frames.png)."""
    out = Path(argv[0]) if argv else REPO / 'docs' / 'stereo_frames.png'
    fig = plt.figure(figsize=(12, 5.8))
    _frames(fig.add_subplot(1, 2, 1, projection='3d'), (22, -60))
    _frames(fig.add_subplot(1, 2, 2), None)
    t = ', '.join(f'{x:g}' for x in RIG.t_mm)
    fig.suptitle('Stereo rig: the right entrance pupil E at t = (baseline, offset_y, offset_z), '
                 'its axes the columns of R = R_x R_y R_z; X_r = R^T (X_l - t).\n'
                 'Solid: the camera axes; dashed: the rectified axes both cameras share '
                 '(d_rect = R1 d_l = R2 d_r, rectified X along t).\n'
                 f'Drawn exaggerated: t = ({t}) mm, rotations x, y, z = '
                 f'{RIG.rotation_x_deg:g}, {RIG.rotation_y_deg:g}, {RIG.rotation_z_deg:g} deg',
                 fontsize=10)
    fig.tight_layout()
    fig.savefig(out, dpi=110)
    print(out)
    return 0


if __name__ == '__main__':
    sys.exit(main(sys.argv[1:]))
