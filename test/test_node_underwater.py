# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
The live node behind a flat port in seawater (issue 27): a salinity change rebuilds it.

ONE node start-up (module fixture, test/test_node.py's harness): config/case2.yaml with a flat
PMMA port 5 mm in front of the lens, seawater at 0 PSU. ``ros2 param set scene.salinity_psu
35.0`` through the real ``/correct_node/set_parameters`` service rebuilds the model like any
lens change: image_rect and both CameraInfos follow the in-process model of the new values,
and every output frame is consistent with one model (its camera_info's D and its pixels),
never a mix; /diagnostics reports the non-central error. Then the port tilted 1 deg and the
scene set to infinity (``scene.distance_mm`` 0): both sets are accepted and rebuild the model
(traced exactly through the tilted port at infinity), image_rect and both CameraInfos follow.
"""

from __future__ import annotations

from typing import Iterator

from mechdeconv_ros.imaging.remap import Rectifier
from mechdeconv_ros.node.image_msgs import image_to_array
from mechdeconv_ros.schema.params import load_params_file
import numpy as np
import numpy.testing as npt
import pytest
from ros_helpers import make_image, next_domain_id, node_command, running_node
import test_node as base

pytestmark = pytest.mark.ros

UNDERWATER = {'scene.medium': 'seawater', 'scene.salinity_psu': 0.0, 'port.type': 'flat',
              'port.distance_mm': 5.0, 'port.glass': 'PMMA'}


@pytest.fixture(scope='module')
def harness(tmp_path_factory: pytest.TempPathFactory) -> Iterator[base.Harness]:
    tmp = tmp_path_factory.mktemp('node_underwater')
    params = base.case2_params(tmp)
    overrides = [f'{k}:={v}' for k, v in UNDERWATER.items()]
    values = load_params_file(params)
    values.update({'sensor.width_px': 0, 'sensor.height_px': 0, **UNDERWATER})
    with running_node(node_command(params, *base.FOLLOW_IMAGES, *overrides), next_domain_id(),
                      tmp) as (proc, client):
        yield base.Harness(proc, client, values)


def test_salinity_change_rebuilds_image_rect_and_both_camera_infos(
        harness: base.Harness) -> None:
    width, height = base.SMALL
    src = base.test_pattern(width, height)
    msg = make_image(src, 'mono8')
    outputs = base.Outputs(harness.client)
    harness.wait_subscribed()
    try:
        fresh_model = base.expected_model(harness.values, width, height)
        first = harness.exchange(outputs, msg)
        base.assert_camera_infos(first, fresh_model)
        npt.assert_array_equal(image_to_array(first['image'])[0],
                               Rectifier(fresh_model).correct(src))
        # The lens summary (the model report) is computed in the background: wait for it.
        for _ in range(20):
            diag = harness.diag()
            if 'noncentral_error_px_half' in diag:
                break
        assert float(diag['noncentral_error_px_half']) > 0.0
        revision = harness.revision()

        results = harness.client.set_parameters(base.double('scene.salinity_psu', 35.0))
        assert [r.successful for r in results] == [True], results[0].reason
        harness.values['scene.salinity_psu'] = 35.0
        sea_model = base.expected_model(harness.values, width, height)
        # The water's index rises by ~0.0064: the in-water focal length by ~0.5 %.
        assert sea_model.K[0, 0] / fresh_model.K[0, 0] == pytest.approx(1.0047, abs=0.0015)
        new = base._exchange_until_model(harness, outputs, msg, sea_model)
        base.assert_camera_infos(new, sea_model)
        npt.assert_array_equal(image_to_array(new['image'])[0],
                               Rectifier(sea_model).correct(src))
        assert harness.revision() == revision + 1
        # No frame mixes the models: each output's pixels are those of its camera_info's model.
        images = [Rectifier(m).correct(src) for m in (fresh_model, sea_model)]
        for stamp, parts in outputs.by_stamp.items():
            if len(parts) < 3:
                continue
            which = int(np.allclose(parts['info'].d, sea_model.D, rtol=1e-9))
            model = (fresh_model, sea_model)[which]
            npt.assert_allclose(parts['info'].k, model.K.ravel(), rtol=1e-9)
            npt.assert_allclose(parts['info_rect'].k, model.K_new.ravel(), rtol=1e-9)
            npt.assert_array_equal(image_to_array(parts['image'])[0], images[which])
        # A refused value (outside Quan & Fry's range) leaves the model as it was.
        refused = harness.client.set_parameters(base.double('scene.salinity_psu', 40.0))
        assert not refused[0].successful and 'scene.salinity_psu' in refused[0].reason
        assert harness.revision() == revision + 1
    finally:
        outputs.close()


def test_a_scene_at_infinity_behind_a_tilted_port_is_traced(harness: base.Harness) -> None:
    # scene.distance_mm 0 (infinity) behind a tilted flat port: accepted and rebuilt (the
    # rebuild once read the 0 as a distance and failed after the set had been accepted).
    width, height = base.SMALL
    src = base.test_pattern(width, height)
    msg = make_image(src, 'mono8')
    outputs = base.Outputs(harness.client)
    harness.wait_subscribed()
    try:
        revision = harness.revision()
        for name, value in (('port.tilt_x_deg', 1.0), ('scene.distance_mm', 0.0)):
            results = harness.client.set_parameters(base.double(name, value))
            assert [r.successful for r in results] == [True], results[0].reason
            harness.values[name] = value
        model = base.expected_model(harness.values, width, height)
        new = base._exchange_until_model(harness, outputs, msg, model, timeout=20.0)
        base.assert_camera_infos(new, model)
        npt.assert_array_equal(image_to_array(new['image'])[0], Rectifier(model).correct(src))
        assert harness.revision() == revision + 2
    finally:
        outputs.close()
