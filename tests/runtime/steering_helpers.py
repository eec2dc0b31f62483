"""Shared helpers of the steering tests (test_steering_config, test_steering_gateway): the
shipped swerve and Ackermann configurations."""

from __future__ import annotations

from tests.conftest import CONFIG_DIR

SWERVE = CONFIG_DIR / "swerve.yaml"
ACKERMANN = CONFIG_DIR / "ackermann.yaml"
