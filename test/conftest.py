# Copyright 2026 The mechdeconv_ros Authors.
# SPDX-License-Identifier: Apache-2.0
"""The suite's plugins: :mod:`hard_limit` (a hung test ends its process with every stack)."""

pytest_plugins = ('hard_limit',)
