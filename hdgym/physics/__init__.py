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


def _drop_stale_compiled_cache() -> None:
    """Delete numba's on-disk caches in the hdgym package when a physics source changed.

    Numba keys a cached function on its own file's timestamp, not on the
    modules it imports, while compiled code inlines code and constants across
    modules (lanes from lane_fields, lane_step and kernel; envs, hardware and
    bench from the physics; all from layout, effects and the parameter
    limits). An edit to one of those files would otherwise leave stale machine
    code in the others' caches. One hash over the physics sources decides; every
    ``__pycache__`` of the package then loses its ``.nbi``/``.nbc`` files. A
    read-only install just keeps its cache.
    """
    import hashlib
    from pathlib import Path

    here = Path(__file__).parent
    package = here.parent
    sources = sorted(here.glob("*.py")) + [package / "effects.py",
                                           package / "params" / "validation.py"]
    try:
        digest = hashlib.sha256(b"".join(p.read_bytes() for p in sources)).hexdigest()
        stamp = here / "__pycache__" / "physics-sources.sha256"
        if stamp.is_file() and stamp.read_text() == digest:
            return
        for cache in package.rglob("__pycache__"):
            for f in list(cache.glob("*.nbi")) + list(cache.glob("*.nbc")):
                f.unlink(missing_ok=True)
        stamp.parent.mkdir(exist_ok=True)
        stamp.write_text(digest)
    except OSError:  # read-only or racing another process: numba recompiles as needed
        pass


_drop_stale_compiled_cache()
