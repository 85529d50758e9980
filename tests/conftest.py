"""Shared pytest configuration: headless rendering by default."""

import os

os.environ.setdefault("MUJOCO_GL", "egl")
