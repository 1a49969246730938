# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""
The parameter schema: every parameter, its type, range, unit and check (layer 0).

One module, ``params``: the single source of truth for the node's declarations, the CLI, the
config YAML files and the README table. It imports no other module of the package (only the
standard library and PyYAML), so every layer above may use it.
"""
