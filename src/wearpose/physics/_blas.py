"""Limit the threads of numpy's bundled OpenBLAS (process-wide).

The physics step multiplies many small dense matrices (75-150 wide). OpenBLAS splits such
products over all cores; on a loaded 2-core machine the worker hand-offs cost 10-50 ms per step
instead of < 1 ms single-threaded (measured here). ``OPENBLAS_NUM_THREADS`` only works before
numpy is imported, so this calls OpenBLAS's own setter through ctypes.
"""

from __future__ import annotations

import ctypes
import glob
import os

import numpy as np

_SETTERS = ("scipy_openblas_set_num_threads64_", "scipy_openblas_set_num_threads", "openblas_set_num_threads64_",
            "openblas_set_num_threads")
_done: dict[int, bool] = {}


def limit_blas_threads(n: int = 1) -> bool:
    """Set numpy's OpenBLAS to ``n`` threads. Returns False when no OpenBLAS setter is found
    (e.g. numpy built against another BLAS), in which case nothing changes."""
    if n in _done:
        return _done[n]
    libdir = os.path.join(os.path.dirname(os.path.dirname(np.__file__)), "numpy.libs")
    ok = False
    for path in sorted(glob.glob(os.path.join(libdir, "*openblas*.so*"))):
        try:
            lib = ctypes.CDLL(path)
        except OSError:
            continue
        for name in _SETTERS:
            fn = getattr(lib, name, None)
            if fn is not None:
                fn(ctypes.c_int(n))
                ok = True
                break
        if ok:
            break
    _done[n] = ok
    return ok
