"""One seam for every fan-out: materials in ``run``, datasets in ``fit-many``, SBC replicates, discovery-benchmark
runs.

A fan-out is a list of :class:`Unit` (a stable key, a top-level function and its arguments). :func:`run_units`
sends each unit to an *executor*, anything with ``concurrent.futures``' ``submit(fn, *args) -> Future``, and
returns one :class:`Outcome` per unit in the order given, whatever order they finished in. The callers hold no
queue, claim file or worker process of their own, so the same units run

- here, one after another (``executor=None``: no process, no pickling; the default of one job);
- in local worker processes (:func:`make_executor` with ``jobs > 1``, or one job with ``processes``: spawned,
  since JAX must not be forked; their thread pools are left as they are: on two cores, two workers ran SBC
  replicates 5 % faster than with one XLA thread each, because each worker's serial Python phases leave a core
  the other can use, ``experiments/bench_scale.py``);
- on a Dask cluster (``scheduler="local:N"`` starts a ``LocalCluster`` of N one-thread worker processes;
  ``scheduler="tcp://HOST:8786"`` joins a running one; ``$PEANO_BAYES_SCHEDULER`` sets it for every command).

**The units' contract.** A unit is idempotent and resumable: run twice it gives the same value, and a unit that
stopped part way (a lost worker) continues from what it saved (a fit resumes from its sampler state, saved per
chunk). Dask re-runs the unit of a lost worker on another one (``distributed.scheduler.allowed-failures``, 3 by
default); a local process pool cannot survive a killed worker (``BrokenProcessPool``: the remaining units are
reported failed, and a rerun resumes them). Results go to files the unit writes itself (a shared directory past
one machine) or come back as the unit's return value.

Each unit runs under :func:`_execute`: it switches on the parent's persistent compilation cache in the worker,
keeps the unit's printed output in ``log_dir/<key>.log`` when a log folder is given, and records which worker ran
it and for how long (:class:`Outcome`), the provenance :func:`provenance` collects. Importing this module does
not import JAX or Dask.
"""

from __future__ import annotations

import concurrent.futures as cf
import contextlib
import io
import multiprocessing
import os
import re
import socket
import sys
import threading
import time
import traceback
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path

from ..errors import PeanoBayesError, PeanoBayesInputError

#: Seconds between refreshes of the progress bar's running count while no unit finishes.
POLL_S = 10.0
#: The address schemes of Dask's communication layer (``distributed.comm``): a scheduler address uses one.
DASK_SCHEMES = ("tcp", "tls", "inproc", "ucx", "ws", "wss")
#: Seconds a TCP connection to a named scheduler may take before it counts as unreachable (Dask itself waits
#: ``distributed.comm.timeouts.connect``, 30 s, and retries a refused connection all that time).
CONNECT_PROBE_S = 5.0
#: Environment variable that names the scheduler when no ``--scheduler`` is given.
SCHEDULER_ENV = "PEANO_BAYES_SCHEDULER"
#: XLA flags of a Dask worker process: one compute thread, so a node's N workers use N cores.
ONE_THREAD_XLA_FLAGS = "--xla_cpu_multi_thread_eigen=false intra_op_parallelism_threads=1"
#: Environment of a Dask worker process (started by ``local:N``), capping its thread pools at one thread; local
#: process pools are not capped (see the module docstring), :func:`cap_threads` applies it to any process.
WORKER_ENV = {
    "XLA_FLAGS": ONE_THREAD_XLA_FLAGS,
    "OMP_NUM_THREADS": "1",
    "OPENBLAS_NUM_THREADS": "1",
    "MKL_NUM_THREADS": "1",
}


@dataclass(frozen=True)
class Unit:
    """One unit of work: ``fn(*args, **kwargs)``. ``key`` names it in logs, progress and outcomes (unique within
    a fan-out; a file-name-safe form of it names its log file). ``fn`` must be importable by a worker (defined at
    a module's top level) and its arguments picklable."""

    key: str
    fn: Callable
    args: tuple = ()
    kwargs: dict = field(default_factory=dict)


@dataclass(frozen=True)
class Outcome:
    """What became of one :class:`Unit`: its ``value`` (``None`` if it failed), ``error`` (``None``, or the
    exception's type and message), the worker that ran it (``host:pid``), and its ``seconds`` there (``nan`` when
    the worker was lost before it reported)."""

    key: str
    value: object = None
    error: str | None = None
    traceback: str | None = None
    worker: str | None = None
    seconds: float = float("nan")

    @property
    def ok(self) -> bool:
        return self.error is None


@dataclass(frozen=True)
class _Context:
    """What a worker needs from the parent: its compilation-cache folder and where unit logs go."""

    cache_dir: str | None = None
    log_dir: str | None = None


class _Tee(io.TextIOBase):
    """A text stream that writes to two others (the worker's own stream and the unit's log file)."""

    def __init__(self, *streams):
        self.streams = streams

    def write(self, text):
        for stream in self.streams:
            stream.write(text)
        return len(text)

    def flush(self):
        for stream in self.streams:
            stream.flush()


def log_name(key: str) -> str:
    """The log file name of a unit: its key with anything but letters, digits, ``.``, ``_`` and ``-`` replaced."""
    return re.sub(r"[^A-Za-z0-9._-]+", "_", key) + ".log"


def _execute(unit: Unit, context: _Context) -> Outcome:
    """Run ``unit`` in this process (a worker, or the parent when serial) and report where and how long."""
    if context.cache_dir:
        from ..jax_config import enable_compilation_cache

        enable_compilation_cache(context.cache_dir)
    worker = f"{socket.gethostname()}:{os.getpid()}"
    start = time.perf_counter()
    with contextlib.ExitStack() as stack:
        if context.log_dir:
            Path(context.log_dir).mkdir(parents=True, exist_ok=True)
            log = stack.enter_context(open(Path(context.log_dir) / log_name(unit.key), "a", encoding="utf-8"))
            stamp = time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())
            log.write(f"{stamp} {unit.key}: started on {worker}\n")  # a retried unit's log names every worker
            log.flush()
            stack.enter_context(contextlib.redirect_stdout(_Tee(sys.stdout, log)))
            stack.enter_context(contextlib.redirect_stderr(_Tee(sys.stderr, log)))
        value = unit.fn(*unit.args, **unit.kwargs)
    return Outcome(unit.key, value, worker=worker, seconds=time.perf_counter() - start)


def _current_cache_dir() -> str | None:
    """The persistent compilation cache this process uses, if JAX is imported and one is set."""
    jax = sys.modules.get("jax")
    if jax is None:
        return None
    return jax.config.jax_compilation_cache_dir or None


def _failed(key: str, err: BaseException) -> Outcome:
    return Outcome(
        key,
        error=f"{type(err).__name__}: {err}",
        traceback="".join(traceback.format_exception(err)),
    )


def _settle_arviz_stamp() -> None:
    """Import arviz once here before worker processes start. On its first import of a day arviz 0.23 writes a
    stamp file in the user's cache through one fixed temporary name, so workers importing it at the same moment
    race, and the loser dies with FileNotFoundError (seen with two test workers just after midnight)."""
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", FutureWarning)
        import arviz  # noqa: F401


def run_units(
    units: Sequence[Unit],
    executor: cf.Executor | None = None,
    *,
    on_result: Callable[[Outcome], None] | None = None,
    log: Callable[[str], None] | None = None,
    progress: bool = False,
    desc: str = "work units",
    log_dir: str | os.PathLike | None = None,
) -> list[Outcome]:
    """Run ``units`` through ``executor`` (``None``: here, in order) and return their outcomes in the order of
    ``units``.

    A unit that raises does not stop the others: its outcome carries the error (and traceback), and the caller
    decides. ``on_result(outcome)`` is called in this process as each unit finishes (in finishing order), so a
    caller can append results to one file as they come (one writer, whatever the number of workers). ``log``
    gets one line per finished unit: key, worker, time, the counts done / running / failed / not finished and the
    time left; ``progress`` shows a bar with the same counts. ``log_dir``: each unit's printed output is also kept
    in ``log_dir/<key>.log``, which a worker creates when it starts the unit, so the running count (units started
    and not finished) is known only with a ``log_dir`` that this process can read.
    """
    keys = [u.key for u in units]
    if len(set(keys)) != len(keys):
        dup = sorted({k for k in keys if keys.count(k) > 1})
        raise PeanoBayesInputError(f"work units need distinct keys; repeated: {', '.join(dup)}")
    context = _Context(_current_cache_dir(), None if log_dir is None else str(log_dir))
    outcomes: dict[str, Outcome] = {}
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=len(units), desc=desc, unit="unit")
    start = time.perf_counter()

    def running() -> int | None:
        """Units started (their log file exists: a worker opened it) and not finished; ``None`` without logs."""
        if log_dir is None:
            return None
        return sum(1 for k in keys if k not in outcomes and (Path(log_dir) / log_name(k)).exists())

    def counts() -> str:
        failed = sum(not o.ok for o in outcomes.values())
        now = running()
        busy = "" if now is None else f", {now} running"
        return f"{len(outcomes) - failed} done{busy}, {failed} failed, {len(units) - len(outcomes)} not finished"

    def finished(outcome: Outcome) -> None:
        outcomes[outcome.key] = outcome
        done = len(outcomes)
        if bar is not None:
            bar.update(1)
            bar.set_postfix_str(counts(), refresh=False)
        if log is not None:
            elapsed = time.perf_counter() - start
            eta = elapsed / done * (len(units) - done)
            where = f" on {outcome.worker}" if outcome.worker else ""
            status = f"done in {outcome.seconds:.0f} s{where}" if outcome.ok else f"FAILED ({outcome.error})"
            left = f", about {eta / 60:.0f} min to go" if done < len(units) else ""
            log(f"{outcome.key}: {status}; {counts()}{left}")
        if on_result is not None:
            on_result(outcome)

    try:
        if executor is None:
            for unit in units:
                try:
                    outcome = _execute(unit, context)
                except Exception as err:  # noqa: BLE001 - reported in the outcome, like a worker's failure
                    outcome = _failed(unit.key, err)
                finished(outcome)
        else:
            futures = {executor.submit(_execute, unit, context): unit for unit in units}
            pending = set(futures)
            while pending:  # woken by each finished unit, and every POLL_S to refresh the running count
                done, pending = cf.wait(pending, timeout=POLL_S, return_when=cf.FIRST_COMPLETED)
                for future in done:
                    try:
                        outcome = future.result()
                    except Exception as err:  # noqa: BLE001 - the unit's error, or its worker's loss
                        outcome = _failed(futures[future].key, err)
                    finished(outcome)
                if bar is not None and not done:
                    bar.set_postfix_str(counts())
    finally:
        if bar is not None:
            bar.close()
    return [outcomes[k] for k in keys]


def raise_failures(outcomes: Sequence[Outcome], what: str = "work unit") -> None:
    """Raise one error naming every failed outcome and its error (the tracebacks stay in the outcomes)."""
    failed = [o for o in outcomes if not o.ok]
    if failed:
        from ..errors import PeanoBayesError

        lines = "; ".join(f"{o.key}: {o.error}" for o in failed)
        raise PeanoBayesError(f"{len(failed)} of {len(outcomes)} {what}(s) failed: {lines}")


def xla_flags_with(flags: str) -> str:
    """This process's ``XLA_FLAGS`` with ``flags`` (space-separated) appended, those it has already not
    repeated: JAX's persistent cache keys on the flag list, so a process and the workers or subprocesses it
    starts with these flags build programs under one key and read each other's."""
    present = os.environ.get("XLA_FLAGS", "").split()
    missing = [flag for flag in flags.split() if flag not in present]
    return " ".join(present + missing)


def _one_thread_env() -> dict[str, str]:
    """:data:`WORKER_ENV`, its XLA flags appended to any this process already has (:func:`xla_flags_with`)."""
    return {**WORKER_ENV, "XLA_FLAGS": xla_flags_with(ONE_THREAD_XLA_FLAGS)}


def cap_threads() -> None:
    """Cap this process's thread pools at one thread (:data:`WORKER_ENV`); call it before JAX starts its backend
    (e.g. as a process pool's initializer)."""
    os.environ.update(_one_thread_env())


def parse_scheduler(spec: str | None) -> tuple[str, int | str | None]:
    """``(kind, detail)`` of a scheduler specification: ``("processes", None)`` for none (local processes, or
    serial with one job), ``("local", N)`` for ``local:N``, ``("address", URL)`` for ``tcp://HOST:PORT`` (a scheme of
    :data:`DASK_SCHEMES`). Anything else is an input error naming the accepted forms."""
    if spec is None or not spec.strip():
        return "processes", None
    spec = spec.strip()
    m = re.fullmatch(r"local:(\d+)", spec)
    if m:
        n = int(m.group(1))
        if n < 1:
            raise PeanoBayesInputError(f"scheduler {spec!r}: a LocalCluster needs at least 1 worker")
        return "local", n
    m = re.fullmatch(r"([a-z][a-z0-9+.-]*)://\S+", spec)
    if m and m.group(1) in DASK_SCHEMES:
        return "address", spec
    raise PeanoBayesInputError(
        f"scheduler {spec!r} is not understood; expected 'local:N' (a Dask LocalCluster of N workers) or a Dask "
        f"scheduler address such as 'tcp://HOST:8786' (schemes: {', '.join(DASK_SCHEMES)}; from --scheduler or "
        f"${SCHEDULER_ENV})"
    )


def _dask():
    try:
        import distributed
    except ImportError as err:
        raise PeanoBayesInputError(
            "a Dask scheduler was asked for, but dask.distributed is not installed; install it with "
            "pip install 'peano-bayes[dask]' (or 'dask[distributed]')"
        ) from err
    return distributed


@dataclass(frozen=True)
class ExecutorInfo:
    """How a fan-out ran: ``kind`` (``serial``, ``processes``, ``dask-local``, ``dask``), ``workers`` (``None``
    when a remote cluster decides) and the scheduler ``address`` of a Dask cluster."""

    kind: str
    workers: int | None = None
    address: str | None = None

    def describe(self) -> str:
        return {
            "serial": "this process, one unit after another",
            "processes": f"{self.workers} local worker processes",
            "dask-local": f"a Dask LocalCluster of {self.workers} workers at {self.address}",
            "dask": f"the Dask scheduler at {self.address}",
        }[self.kind]


@contextlib.contextmanager
def make_executor(
    scheduler: str | None = None, jobs: int = 1, *, processes: bool = False
) -> Iterator[tuple[cf.Executor | None, ExecutorInfo]]:
    """``(executor, info)`` for :func:`run_units`, closed when the block ends.

    ``scheduler`` (default ``$PEANO_BAYES_SCHEDULER``):
    - none: ``jobs`` spawned local worker processes (``None``, i.e. here and in order, for one job unless
      ``processes``);
    - ``local:N``: a Dask ``LocalCluster`` of N one-thread worker processes;
    - ``tcp://HOST:PORT``: the Dask cluster of that scheduler (its workers must have peano_bayes installed and
      see the output folder).

    ``processes`` (local worker processes only): the units run in ``jobs`` spawned workers, one job too, that
    live until the block ends. A worker keeps every program it compiled for as long as it lives, so a long
    fan-out of units with different models grows without bound (the discovery benchmark's two workers reached
    22 GB of the machine's 24 in 2.5 h; one job run in the calling process, 20.8 GB in 1 h 40 min), while a new
    worker spends most of a short unit tracing its programs again (the benchmark's runs took about 130 s each in
    a new worker and 40-60 s in one that had run others). A caller with many short units therefore recycles its
    workers by opening one block per batch of units. Not the pool's own recycling (``max_tasks_per_child``): with
    K > 1, Python 3.11's pool stops replacing the workers that leave and waits for ever (CPython gh-115634).
    """
    if jobs < 1:
        raise PeanoBayesInputError(f"jobs must be >= 1, got {jobs}")
    kind, detail = parse_scheduler(scheduler if scheduler is not None else os.environ.get(SCHEDULER_ENV))
    if kind == "processes":
        if jobs == 1 and not processes:
            yield None, ExecutorInfo("serial", 1)
            return
        _settle_arviz_stamp()
        ctx = multiprocessing.get_context("spawn")
        with cf.ProcessPoolExecutor(max_workers=jobs, mp_context=ctx) as pool:
            yield pool, ExecutorInfo("processes", jobs)
        return
    distributed = _dask()
    if kind == "local":
        with (
            distributed.LocalCluster(
                n_workers=detail,
                threads_per_worker=1,
                processes=True,
                dashboard_address=None,
                env=_one_thread_env(),
            ) as cluster,
            distributed.Client(cluster) as client,
        ):
            yield client.get_executor(pure=False), ExecutorInfo("dask-local", detail, cluster.scheduler_address)
        return
    _check_reachable(detail)
    with distributed.Client(detail) as client:
        yield client.get_executor(pure=False), ExecutorInfo("dask", None, detail)


def _check_reachable(address: str, timeout_s: float = CONNECT_PROBE_S) -> None:
    """Open and close one TCP connection to the scheduler at a ``tcp://`` or ``tls://`` ``address``, so that a
    scheduler that is not running (connection refused) or a host that does not answer is reported at once, not
    after Dask's 30 s of retries. The whole probe, the host name's lookup too, gets ``timeout_s`` seconds (a
    socket's timeout does not bound the lookup). Other schemes are left to Dask."""
    scheme, _, rest = address.partition("://")
    if scheme not in ("tcp", "tls"):
        return
    host, _, port = rest.split("/")[0].rpartition(":")
    if not (port.isdigit() and 1 <= int(port) <= 65535):
        raise PeanoBayesInputError(f"scheduler {address!r}: expected {scheme}://HOST:PORT, PORT 1 to 65535")
    failure: list[str] = []

    def probe() -> None:
        try:
            socket.create_connection((host.strip("[]") or "localhost", int(port)), timeout=timeout_s).close()
        except OSError as err:
            failure.append(err.strerror or str(err))

    prober = threading.Thread(target=probe, name="scheduler-probe", daemon=True)  # daemon: a hung lookup is left
    prober.start()
    prober.join(timeout_s)
    if prober.is_alive():
        failure.append(f"no answer within {timeout_s:g} s")
    if failure:
        raise PeanoBayesError(
            f"cannot reach the Dask scheduler at {address} ({failure[0]}); is it running, and is the address right?"
        )


def provenance(info: ExecutorInfo, outcomes: Sequence[Outcome], **extra) -> dict:
    """A JSON-ready record of a fan-out: the executor, the package versions, ``extra`` (seeds, settings) and per
    unit its worker, seconds and error."""
    from importlib import metadata

    versions = {}
    for name in ("peano-bayes", "jax", "jaxlib", "numpy", "emcee", "optimistix", "arviz", "distributed"):
        try:
            versions[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            versions[name] = None
    return {
        "executor": {"kind": info.kind, "workers": info.workers, "address": info.address},
        "python": sys.version.split()[0],
        "packages": versions,
        **extra,
        "units": {o.key: {"worker": o.worker, "seconds": o.seconds, "error": o.error} for o in outcomes},
    }


__all__ = [
    "SCHEDULER_ENV",
    "ExecutorInfo",
    "Outcome",
    "WORKER_ENV",
    "cap_threads",
    "Unit",
    "make_executor",
    "parse_scheduler",
    "provenance",
    "raise_failures",
    "run_units",
]
