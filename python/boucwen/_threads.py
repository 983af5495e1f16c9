"""One BLAS thread unless the environment says otherwise (imported before NumPy).

The fits solve tall, narrow least-squares problems (one row per sample, a dozen
columns) while their simulations run in threads (:mod:`boucwen.lsq`): a threaded BLAS
brings nothing there and, on a machine whose cores are busy, slows every step of the
optimiser many times over. Set ``OPENBLAS_NUM_THREADS``, ``OMP_NUM_THREADS`` or
``MKL_NUM_THREADS`` before importing boucwen to choose otherwise.
"""

import os

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")
