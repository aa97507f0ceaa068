"""Linear algebra on one thread unless the user says otherwise.

numpy's BLAS reads its thread count from the environment once, when numpy
is first imported, so the variables must be set before that. This module
imports nothing heavy: ``poise`` (:func:`controller_server.cli.main`) and the
test suite (``tests/conftest.py``) call :func:`default_to_single_threaded_blas`
first thing. On a busy 2-core machine the test suite took 78 minutes with the
default BLAS threads and 31 with one; ``poise demo --controller prioritized``
timed out at 15 minutes and finished in 137 s.
"""

from __future__ import annotations

import os

__all__ = ["BLAS_THREAD_VARIABLES", "default_to_single_threaded_blas"]

BLAS_THREAD_VARIABLES = {
    "OMP_NUM_THREADS": "1",
    "OPENBLAS_NUM_THREADS": "1",
    "MKL_NUM_THREADS": "1",
    "BLIS_NUM_THREADS": "1",
    "VECLIB_MAXIMUM_THREADS": "1",
    "NUMEXPR_NUM_THREADS": "1",
}
"""One thread for every BLAS numpy may use (the server's workers get the same set,
:data:`controller_server.config.SINGLE_THREADED_BLAS`, even if the user set others)."""


def default_to_single_threaded_blas() -> None:
    """Set each variable of :data:`BLAS_THREAD_VARIABLES` that is not set already.

    Call it before numpy is imported; a value the user set is kept (e.g.
    ``OPENBLAS_NUM_THREADS=4 poise …``). Child processes inherit the setting.
    """
    for name, value in BLAS_THREAD_VARIABLES.items():
        os.environ.setdefault(name, value)
