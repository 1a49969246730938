# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
Benchmarks of mechdeconv_ros against the paper and the peers (``make bench``).

``python -m benchmarks.run_all`` runs, in order:

* :mod:`benchmarks.accuracy`: radii mean error (paper eq. 35-37) of the mechanistic model and
  of a Brown model calibrated once by Gauss-Newton, against optiland's ground truth, as the
  stop offset and the lens thickness change (paper Figs. 6-7);
* :mod:`benchmarks.speed`: per-frame correction and model/map rebuild against OpenCV's best
  remap configuration, a frame copy, image_geometry's Python way and lensfunpy;
* :mod:`benchmarks.node_latency`: the ROS 2 node's throughput and latency against a
  pass-through node, with and without the shared-memory Fast DDS profile, and the time from a
  parameter set to the first frame of the new model;
* :mod:`benchmarks.stages`: one frame's time stage by stage, from a Python relay to
  correct_node, adding one of the node's stages at a time (the stage clock,
  ``MECHDECONV_STAGE_TIMES``);
* :mod:`benchmarks.wide`, :mod:`benchmarks.vignetting`, :mod:`benchmarks.compressed_input`:
  wide-angle and aspheric lenses, vignetting correction, compressed input.

Every figure is measured in the run and written to ``results/*.json`` with the machine it ran
on; ``results/README_tables.md`` holds the tables for the README.
"""
