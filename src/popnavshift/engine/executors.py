"""Executors: run batches in local worker processes or as Ray tasks.

Both yield ``(batch id, runs, pedestrians, runs simulated)`` as batches finish, keep at
most ``2 × workers`` batches in flight (bounded memory), and produce identical
tables: the simulation of a batch depends only on the batch and the context.
Processes, not threads: Python behaviours hold the GIL. :func:`execute` is the
one batch executor of ``popnavshift run`` and ``popnavshift evaluate``: it runs
the batches and stores each one's shards as it finishes.
"""

from __future__ import annotations

import importlib.util
import multiprocessing as mp
import os
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait

from ..errors import ConfigError, UnknownNameError
from ..progress import run_progress
from .batches import Batch
from .store import RunStore
from .worker import Context, init_worker, run_batch

Result = tuple[str, object, object, int]


def run_local(batches: Sequence[Batch], context: Context, workers: int,
              task: Callable[..., Result] = run_batch) -> Iterator[Result]:
    """Worker processes (spawned, so nothing of the parent's state leaks in) running
    ``task`` on each batch (with ``context`` in one process, the worker's otherwise).

    Interrupted (Ctrl-C, an error, the consumer gone), the batches in flight are
    abandoned at once: their workers are terminated rather than waited for. Workers only
    compute, the parent stores each finished batch, so nothing of a stored batch is lost
    and a resumed run simulates the abandoned ones again."""
    if workers <= 1:
        for b in batches:
            yield task(b, context)
        return
    ctx = mp.get_context("spawn")
    with ProcessPoolExecutor(
        workers, mp_context=ctx, initializer=init_worker, initargs=(context, os.getpid())
    ) as pool:
        pending: set[Future] = set()
        todo: Iterator[Batch] = iter(batches)
        try:
            while True:
                while len(pending) < 2 * workers:
                    nxt = next(todo, None)
                    if nxt is None:
                        break
                    pending.add(pool.submit(task, nxt))
                if not pending:
                    return
                done, pending = wait(pending, return_when=FIRST_COMPLETED)
                for fut in done:
                    yield fut.result()
        except BaseException:
            _abandon(pool)
            raise


def _abandon(pool: ProcessPoolExecutor) -> None:
    """Shut ``pool`` down without waiting: queued batches cancelled, running ones'
    workers terminated (the pool's own exit would wait for each to finish)."""
    workers = list((getattr(pool, "_processes", None) or {}).values())  # no public handle
    pool.shutdown(wait=False, cancel_futures=True)
    for proc in workers:
        proc.terminate()
    for proc in workers:
        proc.join(timeout=5)


def run_ray(
    batches: Sequence[Batch], context: Context, workers: int, address: str | None = None
) -> Iterator[Result]:
    """Ray tasks: ``address`` joins an existing cluster, else a local instance with
    ``workers`` CPUs is started."""
    try:
        import ray
    except ImportError:
        raise ConfigError(
            "the ray executor needs Ray", hint="pip install 'popnavshift[ray]'"
        ) from None
    started_here = not ray.is_initialized()
    if started_here:
        kwargs = (  # a local instance listens on the loopback only
            {"address": address} if address else
            {"num_cpus": workers, "include_dashboard": False, "_node_ip_address": "127.0.0.1"}
        )
        try:
            ray.init(log_to_driver=False, **kwargs)
        except Exception as exc:
            raise ConfigError(
                f"could not start or join Ray at {address or 'local'}: {exc}"
            ) from None
    remote = ray.remote(num_cpus=1)(_run_batch_ray)
    ctx_ref = [ray.put(context)]  # in a list: Ray then passes the reference, not the value
    limit = 2 * max(1, int(ray.available_resources().get("CPU", workers)))
    todo = iter(batches)
    pending: list = []
    try:
        while True:
            while len(pending) < limit:
                b = next(todo, None)
                if b is None:
                    break
                pending.append(remote.remote(b, ctx_ref))
            if not pending:
                return
            done, pending = ray.wait(pending, num_returns=1)
            yield ray.get(done[0])
    finally:
        for ref in pending:
            ray.cancel(ref, force=True)
        if started_here:
            ray.shutdown()


_RAY_CONTEXT: tuple[str, Context] | None = None


def _run_batch_ray(batch: Batch, context_ref: list) -> Result:
    """:func:`run_batch` in a Ray worker, with the context fetched once per worker
    process: the worker's caches (:func:`.worker._members`) are kept per context
    object, and Ray would otherwise deserialise a new one for every task."""
    import ray

    global _RAY_CONTEXT
    ref = context_ref[0]
    if _RAY_CONTEXT is None or _RAY_CONTEXT[0] != ref.hex():
        _RAY_CONTEXT = (ref.hex(), ray.get(ref))
    return run_batch(batch, _RAY_CONTEXT[1])


EXECUTORS: dict[str, Callable[..., Iterator[Result]]] = {"local": run_local, "ray": run_ray}


def check_executor(name: str) -> None:
    """Fail before any stage runs on an unknown executor or a missing optional package
    (UnknownNameError / ConfigError), instead of after the persona and probe stages."""
    if name not in EXECUTORS:
        raise UnknownNameError("executor", name, EXECUTORS)
    if name == "ray" and importlib.util.find_spec("ray") is None:
        raise ConfigError("--executor ray needs Ray, which is not installed",
                          hint="pip install 'popnavshift[ray]'")


def execute(todo: Sequence[Batch], store: RunStore, context: Context, workers: int, *,
            executor_name: str = "local", address: str | None = None,
            show_progress: bool = True) -> tuple[int, int]:
    """Run the ``todo`` batches with the executor ``executor_name`` (``address``: a Ray
    cluster), writing each batch's shards to ``store`` as it finishes (an interrupted
    call loses only the batches in flight); returns the number of runs executed and
    how many of them were simulated (the others repeated an identical run of their
    batch, see :class:`.worker.RunMemo`)."""
    if executor_name not in EXECUTORS:
        raise UnknownNameError("executor", executor_name, EXECUTORS)
    kwargs = {"address": address} if executor_name == "ray" else {}
    by_id = {b.id: b for b in todo}
    executed = simulated = 0
    with run_progress(sum(len(b.runs) for b in todo), show_progress) as advance:
        for batch_id, runs, peds, n_simulated in EXECUTORS[executor_name](todo, context, workers,
                                                                           **kwargs):
            batch = by_id[batch_id]
            store.write_batch(batch, runs, peds)
            executed += len(batch.runs)
            simulated += n_simulated
            advance(len(batch.runs))
    return executed, simulated
