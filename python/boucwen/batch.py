"""Fleets of records on Dask: :func:`fit_many` and :func:`diagnose_many`.

A piezo deformable mirror has hundreds to thousands of actuators, a production line
tests every stack it makes, and each record takes seconds to fit or diagnose. These
functions run one task per record on a Dask cluster, a local one by default::

    import boucwen.batch

    table = boucwen.batch.fit_many("records/", "results/", layout="layout.csv")
    table = boucwen.batch.diagnose_many("mirror.parquet", "diagnosis/", scheduler="tcp://head:8786")

Each returns a :class:`pandas.DataFrame` with one row per record (parameters, errors
before and after, effects, status and error message, elapsed time, robust z-scores and
an ``outlier`` flag) and writes the table, per-record JSON, the outlier list and the
fleet figure into the result folder; re-running the same call skips the records whose
results are already there. See :mod:`boucwen.fleet` for the parts and
:func:`boucwen.fleet.run.run_fleet` for every option. The command line is
``boucwen batch fit|diagnose SOURCE --out DIR``.

Needs the ``fleet`` extra: ``pip install boucwen[fleet]`` (Dask distributed, pandas,
pyarrow); the rest of boucwen does not.
"""

from __future__ import annotations

__all__ = ["diagnose_many", "fit_many", "run_fleet", "summary"]

try:
    import dask  # noqa: F401
    import distributed  # noqa: F401
    import pandas  # noqa: F401
    import pyarrow  # noqa: F401
except ImportError as exc:
    raise ImportError(
        f"boucwen.batch needs the fleet extra, which is not installed (missing: {exc.name or exc}); "
        "install it with: pip install boucwen[fleet]"
    ) from exc

from .fleet.run import diagnose_many, fit_many, run_fleet, summary
