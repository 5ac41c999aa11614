"""Shared fixtures. Simulation fixtures are module-scoped: building an env costs ~1 s and a camera's
first capture ~5 s on lavapipe, so each test module builds what it needs once."""

from __future__ import annotations

import os

os.environ.setdefault("OMP_NUM_THREADS", "1")
