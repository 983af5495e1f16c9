"""Fleets of records: fit or diagnose every actuator of a mirror or a production line on Dask.

The public entry is :mod:`boucwen.batch` (``fit_many``, ``diagnose_many``) and the
``boucwen batch fit|diagnose`` command. The modules, in the order a run uses them:

- :mod:`~boucwen.fleet.source`: a folder or glob of CSV records, or one long table
  (CSV or Parquet) with a ``channel`` column, turned into :class:`RecordRef` s with a
  content hash, and a reference turned back into a :class:`boucwen.io.Record`;
- :mod:`~boucwen.fleet.tasks`: the per-record task, a pure function returning one row;
- :mod:`~boucwen.fleet.store`: the result folder: per-record JSON keyed by content
  hash (what makes a re-run resume), atomic writes, the table;
- :mod:`~boucwen.fleet.progress`: records done / total, rate and time left;
- :mod:`~boucwen.fleet.run`: the Dask driver (local cluster or a scheduler address);
- :mod:`~boucwen.fleet.outliers`: robust z-scores of parameters and errors;
- :mod:`~boucwen.fleet.plots`: the fleet figure (distributions, errors, mirror maps);
- :mod:`~boucwen.fleet.generate`: a generated 32 × 32 mirror with known defects.

Everything but :mod:`~boucwen.fleet.generate` needs the ``fleet`` extra
(``pip install boucwen[fleet]``: Dask distributed, pandas, pyarrow).
"""
