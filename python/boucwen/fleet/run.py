"""The Dask driver: one task per record, results stored as they arrive, then the table.

:func:`run_fleet` (and :func:`fit_many`, :func:`diagnose_many` on top of it):

1. lists the source's records and their content hashes (:mod:`boucwen.fleet.source`);
2. skips those whose result is already in ``out`` under the same key
   (:mod:`boucwen.fleet.store`): re-running an interrupted command resumes it;
3. starts a :class:`dask.distributed.LocalCluster` on this machine, or connects to the
   scheduler at ``scheduler``, and submits one task per remaining record
   (:func:`boucwen.fleet.tasks.run_task`);
4. writes each row to ``out/records/<channel>.json`` atomically as soon as it arrives,
   so that an interruption loses at most the records still running;
5. builds the table of every record of the source, flags outliers, writes
   ``results.parquet``, ``results.csv``, ``outliers.csv``, ``fleet.png`` and ``run.json``.

**Workers and threads.** The local cluster runs ``workers`` processes (default: the
number of CPUs) with **one thread each**, and every task fits with one thread
(``TaskOptions.threads``), with ``OMP_NUM_THREADS``, ``OPENBLAS_NUM_THREADS`` and
``MKL_NUM_THREADS`` set to 1 in the workers. The fit's time goes into the Rust
simulator, which holds no lock but needs a core, and into small NumPy/SciPy steps;
records are independent, so one record per core keeps every core busy without any
sharing, whereas the fit's threaded Jacobian (one thread per CPU by default) or a
multi-threaded BLAS inside each of N worker processes would put N × CPUs threads on
CPUs cores and slow every record down. Processes rather than threads also keep the
Python-level parts of the fits from contending for one interpreter lock, and let a
record that crashes its worker take only that worker down.

**Nothing lost, nothing done twice.** When a worker dies, the scheduler runs its
tasks again on another worker (up to ``distributed.scheduler.allowed-failures``
times); the driver receives each task's result once, keyed by record, and writes it
once. A task that never returns becomes a ``"failed"`` row, which a re-run retries.
"""

from __future__ import annotations

import contextlib
import datetime
import importlib.util
import json
import logging
import os
import sys
import time
import uuid
from collections.abc import Iterator
from typing import Any, Callable, TextIO

import pandas as pd
from distributed import Client, LocalCluster, as_completed

from .. import __version__
from .outliers import attention_list, flag_outliers
from .progress import Progress
from .source import PathLike, RecordRef, find_records
from .store import ResultStore, atomic_write, atomic_write_text, file_name, result_key
from .tasks import TaskOptions, empty_row, error_message, run_task

__all__ = ["THREADS_PER_WORKER", "WORKER_ENV", "diagnose_many", "fit_many", "run_fleet", "summary"]

#: Environment of the local cluster's worker processes: single-threaded BLAS/OpenMP.
WORKER_ENV = {"OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}
#: Threads per local worker process (module docs).
THREADS_PER_WORKER = 1
#: Seconds to wait for a remote scheduler to answer.
CONNECT_TIMEOUT_S = 10


# --------------------------------------------------------------------------- cluster


def _check_workers(workers: Any) -> int | None:
    if workers is None:
        return None
    if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
        raise ValueError(f"workers must be an integer >= 1, got {workers!r}")
    return workers


@contextlib.contextmanager
def _cluster(
    scheduler: str | None, workers: int | None, client: Client | None, say: Callable[[str], None]
) -> Iterator[tuple[Client, dict[str, Any]]]:
    """A client to run on: the given one, one connected to ``scheduler``, or a local cluster."""
    if client is not None:
        yield client, _describe(client, "given client")
        return
    if scheduler is not None:
        try:
            remote = Client(scheduler, timeout=CONNECT_TIMEOUT_S)
        except Exception as exc:
            raise OSError(f"cannot connect to the Dask scheduler at {scheduler}: {error_message(exc)}") from None
        try:
            info = _describe(remote, "remote")
            say(f"connected to {scheduler}: {info['workers']} workers, {info['threads']} threads; {_dashboard(info)}")
            yield remote, info
        finally:
            remote.close()
        return
    n = workers or os.cpu_count() or 1
    with_dashboard = importlib.util.find_spec("bokeh") is not None
    cluster = LocalCluster(
        n_workers=n,
        threads_per_worker=THREADS_PER_WORKER,
        processes=True,
        host="127.0.0.1",
        dashboard_address=":0",  # any free port: several runs (or engineers) may share the machine
        silence_logs=logging.ERROR,
        env=dict(WORKER_ENV),
    )
    try:
        local = Client(cluster)
        try:
            info = _describe(local, "local")
            info["dashboard"] = local.dashboard_link if with_dashboard else None
            say(
                f"local Dask cluster: {n} worker process{'es' if n != 1 else ''} × {THREADS_PER_WORKER} thread "
                f"(one record per core, single-threaded fits); {_dashboard(info)}"
            )
            yield local, info
        finally:
            local.close()
    finally:
        cluster.close()


def _describe(client: Client, kind: str) -> dict[str, Any]:
    threads = client.nthreads()
    link = None
    with contextlib.suppress(Exception):
        services = client.scheduler_info().get("services", {})
        link = client.dashboard_link if "dashboard" in services else None
    return {
        "kind": kind,
        "scheduler": getattr(client.scheduler, "address", None),
        "workers": len(threads),
        "threads": sum(threads.values()),
        "dashboard": link,
    }


def _dashboard(info: dict[str, Any]) -> str:
    return f"dashboard: {info['dashboard']}" if info.get("dashboard") else "no dashboard (pip install bokeh for one)"


# --------------------------------------------------------------------------- computing


def _compute(
    client: Client,
    todo: list[RecordRef],
    options: TaskOptions,
    keys: dict[str, str],
    store: ResultStore,
    progress: Progress,
) -> None:
    """Submits one task per record and stores each row as it arrives."""
    # Dask task keys: readable in the dashboard, and new for every run (a key cancelled by an
    # interrupted run may still be known to a shared scheduler).
    run_id = uuid.uuid4().hex[:8]
    pending = {}
    for ref in todo:
        key = f"boucwen-{options.kind}-{file_name(ref.channel)}-{run_id}"
        pending[client.submit(run_task, ref, options, key=key)] = ref
    try:
        for future in as_completed(list(pending)):
            ref = pending.pop(future)
            try:
                row = future.result()
            except Exception as exc:  # the task never returned (e.g. its worker died every time)
                row = empty_row(ref, options)
                row.update(status="failed", error=error_message(exc))
            store.write(row, keys[ref.channel])
            progress.update(error=row["status"] in ("error", "failed"))
            future.release()
    finally:
        if pending:  # interrupted: do not leave work running on a shared cluster
            client.cancel(list(pending))


# --------------------------------------------------------------------------- the run


def run_fleet(
    kind: str,
    source: PathLike,
    out: PathLike,
    *,
    layout: PathLike | None = None,
    scheduler: str | None = None,
    workers: int | None = None,
    client: Client | None = None,
    seed: int = 0,
    figure: bool = True,
    progress: bool | TextIO = True,
) -> pd.DataFrame:
    """Fits or diagnoses every record of a source on Dask; returns the table.

    Args:
        kind: ``"fit"`` (:func:`boucwen.fit`) or ``"diagnose"`` (:func:`boucwen.diagnose`).
        source: a folder or glob of CSV records, or a long table (:mod:`boucwen.fleet.source`).
        out: result folder (created; :mod:`boucwen.fleet.store`).
        layout: optional CSV ``channel,row,col`` placing the records on a grid (for the maps).
        scheduler: address of a running Dask scheduler (e.g. ``tcp://10.0.0.5:8786``);
            None starts a local cluster.
        workers: worker processes of the local cluster (default: the number of CPUs);
            not allowed with ``scheduler`` or ``client``.
        client: an existing :class:`dask.distributed.Client` to run on (left open).
        seed: seed of the fits' random starts (part of each result's key).
        figure: also draw ``out/fleet.png``.
        progress: True prints progress to stderr, False prints nothing, or a text stream.

    Returns:
        One row per record of the source (columns in :mod:`boucwen.fleet.tasks`, plus the
        outlier columns of :func:`boucwen.fleet.outliers.flag_outliers`), in source order;
        ``table.attrs["run"]`` holds the run's counts and timing (also in ``out/run.json``).

    Raises:
        ValueError: bad arguments or a source that cannot be read (bad *records* become
            error rows instead).
        OSError: ``out`` cannot be written, or the scheduler cannot be reached.
    """
    options = TaskOptions(kind=kind, seed=seed)
    workers = _check_workers(workers)
    if workers is not None and (scheduler is not None or client is not None):
        raise ValueError("workers sets the size of the local cluster; a scheduler or client has its own workers")
    if scheduler is not None and client is not None:
        raise ValueError("give a scheduler address or a client, not both")
    stream: TextIO | None = sys.stderr if progress is True else (None if progress is False else progress)
    started = time.perf_counter()
    refs = find_records(source, layout)
    store = ResultStore(out)
    keys = {ref.channel: result_key(ref, options) for ref in refs}
    todo = [ref for ref in refs if not store.is_done(ref.channel, keys[ref.channel])]
    bar = Progress(f"batch {kind}", len(refs), skipped=len(refs) - len(todo), stream=stream)
    info: dict[str, Any] = {
        "kind": kind,
        "source": os.fspath(source),
        "out": os.fspath(out),
        "options": options.to_dict(),
        "records": len(refs),
        "skipped": len(refs) - len(todo),
        "computed": len(todo),
        "started": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
        "boucwen": __version__,
        "cluster": None,
        "startup_s": 0.0,
        "compute_s": 0.0,
        "records_per_s": None,
    }
    if todo:
        cluster_started = time.perf_counter()
        with _cluster(scheduler, workers, client, bar.say) as (dask_client, cluster_info):
            info["cluster"] = cluster_info
            info["startup_s"] = time.perf_counter() - cluster_started
            bar.start()
            _compute(dask_client, todo, options, keys, store, bar)
            info["compute_s"] = bar.elapsed
            info["records_per_s"] = bar.rate or None
    bar.close()

    table = flag_outliers(store.table([ref.channel for ref in refs]))
    store.write_table(table)
    listing = attention_list(table)
    atomic_write(store.root / "outliers.csv", lambda tmp: listing.to_csv(tmp, index=False))
    if figure and len(table):
        from .plots import plot_fleet

        atomic_write(store.root / "fleet.png", lambda tmp: plot_fleet(table, tmp, title=f"batch {kind}"))
    counts = table["status"].value_counts()
    info.update(
        status={str(k): int(v) for k, v in counts.items()},
        outliers=int(table["outlier"].sum()),
        figure=bool(figure and len(table)),
        wall_s=time.perf_counter() - started,
    )
    atomic_write_text(store.root / "run.json", json.dumps(info, indent=2, default=str) + "\n")
    table.attrs["run"] = info
    return table


def fit_many(source: PathLike, out: PathLike, **options: Any) -> pd.DataFrame:
    """Fits every record of a source (:func:`boucwen.fit`, one task each); see :func:`run_fleet`."""
    return run_fleet("fit", source, out, **options)


def diagnose_many(source: PathLike, out: PathLike, **options: Any) -> pd.DataFrame:
    """Diagnoses every record of a source (:func:`boucwen.diagnose`, one task each); see :func:`run_fleet`."""
    return run_fleet("diagnose", source, out, **options)


def summary(table: pd.DataFrame) -> str:
    """A few lines for the terminal: counts, rate, and the records to look at."""
    info = table.attrs.get("run", {})
    status = info.get("status", {})
    lines = [
        f"{len(table)} records: "
        + ", ".join(f"{v} {k.replace('_', ' ')}" for k, v in sorted(status.items()))
        + f" ({info.get('skipped', 0)} already done, {info.get('computed', 0)} computed"
        + (f", {info['records_per_s']:.2f} records/s" if info.get("records_per_s") else "")
        + ")"
    ]
    listing = attention_list(table)
    if len(listing):
        lines.append(f"to look at ({len(listing)}):")
        for item in listing.itertuples(index=False):
            where = f" (row {item.row}, col {item.col})" if pd.notna(item.row) else ""
            lines.append(f"  {item.channel}{where}: {item.flag}: {item.reason}")
    else:
        lines.append("no outlier, no error")
    out = info.get("out")
    if out:
        figure = ", fleet.png" if info.get("figure") else ""
        lines.append(f"wrote {out}: results.parquet, results.csv, outliers.csv{figure}, records/*.json, run.json")
    return "\n".join(lines)
