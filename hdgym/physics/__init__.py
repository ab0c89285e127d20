"""The joint's physics: parameter/state layouts and the compiled steps."""

import os

import numba as nb

# Threads for the compiled batch steps: Intel TBB (a dependency) starts a
# parallel region in about 5 us and lets idle workers sleep. Numba's fallback
# work-queue layer took about 200 us per region (more than a 1,024-env step's
# physics on one core), and its OpenMP layer busy-waits between regions, which
# slowed the threaded steps beside torch's own OpenMP threads. A layer chosen by
# the user (NUMBA_THREADING_LAYER) is kept. This runs before any compiled module
# is imported.
if "NUMBA_THREADING_LAYER" not in os.environ:
    nb.config.THREADING_LAYER = "default"
    nb.config.THREADING_LAYER_PRIORITY = ["tbb", "workqueue", "omp"]
