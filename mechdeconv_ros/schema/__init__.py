# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
The parameter schema: every parameter, its type, range, unit and check (layer 0).

``params``: the single source of truth for the node's declarations, the CLI, the config YAML
files and the README table; ``stereo_params``: a stereo pair's parameters, built from it. It
imports no other layer of the package (only the standard library and PyYAML), so every layer
above may use it.
"""
