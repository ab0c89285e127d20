"""The joint's physics: parameter/state layouts and the compiled steps."""

import os

import numba as nb

# Numba's default OpenMP layer busy-waits between parallel regions; on a shared
# machine (or beside torch's own OpenMP threads during RL training) that made
# the threaded steps 3-8x slower than one thread. The work-queue layer sleeps
# instead. A layer chosen by the user (NUMBA_THREADING_LAYER) is kept. This sits
# here so that it is set before any of the compiled modules is imported.
if "NUMBA_THREADING_LAYER" not in os.environ:
    nb.config.THREADING_LAYER = "workqueue"
