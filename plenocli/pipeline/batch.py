"""Batches: one pipeline template run over many captures, in parallel processes or on Dask.

The template is an ordinary config whose per-capture steps name their input ``{capture}`` and their
outputs under ``{name}`` (see :mod:`plenocli.pipeline.config`). A batch runs the shared steps
(white image, calibration) once in this process, then one task per capture: the per-capture steps
through the make-style runner, so a rerun only redoes what is missing or out of date. A task never
raises: a failed capture becomes a :class:`CaptureResult` with its reason and the others go on.

Engines: in this process (``jobs=1``), a pool of worker processes on this machine (``jobs>1``),
or a ``dask.distributed`` scheduler (``scheduler=ADDRESS``; paths must then be visible to every
worker, e.g. on a shared file system).
"""

from __future__ import annotations

import contextlib
import ctypes
import logging
import multiprocessing
import os
import re
import signal
import socket
import sys
import threading
import time
from collections.abc import Iterator, Sequence
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass
from multiprocessing import connection
from pathlib import Path

from plenocli.errors import (
    ConfigError,
    InputError,
    OptionError,
    PlenocliError,
    note_interrupt,
    raise_terminated,
)
from plenocli.io.atomic import process_alive
from plenocli.pipeline.captures import capture_path
from plenocli.pipeline.config import Template, read_template
from plenocli.pipeline.runner import Decision, plan, run_pipeline
from plenocli.pipeline.validators import MAX_TIMEOUT_S
from plenocli.progress import log, printable, progress

# Each worker gets one thread: the parallelism is across captures (no oversubscription).
THREAD_ENV = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS",
              "NUMBA_NUM_THREADS", "VECLIB_MAXIMUM_THREADS")
DASK_CONNECT_TIMEOUT = "20s"
DASK_PROBE_SECONDS = 10  # a scheduler that does not accept a connection in this is not there
ALONE = "plenocli batch CONFIG --inputs CAPTURE -j 1"  # in this process (run refuses templates)
CRASHED = ("the worker process died while processing it (a crash in a decoder, or out of "
           f"memory); run it alone, in the batch's own process ({ALONE} --debug), to see more")
WATCH_SECONDS = 0.25  # how often a worker checks that the batch still runs
GRACE_SECONDS = 10.0  # after a stop request, how long a worker may take to clean up
EXIT_OVERRAN = 128 + signal.SIGALRM  # a worker stopped by its watchdog past the time limit


class CaptureTimeout(BaseException):
    """A capture ran past its time limit (BaseException: no stage may swallow it)."""


def timed_out(seconds: float) -> str:
    return (f"ran past --timeout {seconds:g} s and was stopped; give a larger --timeout, or "
            f"run it alone without one ({ALONE})")


@dataclass(frozen=True)
class CaptureResult:
    """What happened to one capture: status "done", "skipped" (up to date), "would run"
    (dry run) or "failed"; ``detail`` lists the steps run or the reason of the failure."""

    capture: str
    name: str
    status: str
    detail: str
    seconds: float = 0.0


@dataclass(frozen=True)
class BatchReport:
    shared: list[Decision]
    results: list[CaptureResult]  # in the order of the captures

    @property
    def failed(self) -> list[CaptureResult]:
        return [r for r in self.results if r.status == "failed"]


def run_capture(config: str, capture: str, *, overrides: Sequence[str] = (),
                out: str | None = None, force: bool = False, dry_run: bool = False,
                upstream: Sequence[str] = ()) -> CaptureResult:
    """Run the per-capture steps of ``config`` on one capture; never raises for a bad capture.

    Arguments are plain strings so that the call can be sent to another process or machine.
    ``upstream``: shared outputs being remade in this batch (for dry runs).
    """
    name = Path(capture).stem
    start = time.monotonic()
    previous = log.level
    if not log.isEnabledFor(logging.DEBUG):
        log.setLevel(logging.WARNING)  # the batch's table reports per capture, not per step
    try:
        steps = read_template(config, overrides).steps(capture=capture, out=out,
                                                       only="per-capture")
        if dry_run:
            decisions = plan(steps, force=force, upstream=[Path(p) for p in upstream])
        else:
            decisions = run_pipeline(steps, force=force)
    except PlenocliError as err:
        return CaptureResult(capture, name, "failed", str(err), time.monotonic() - start)
    except MemoryError:
        return CaptureResult(capture, name, "failed", "out of memory",
                             time.monotonic() - start)
    except Exception as err:  # a bug in a stage must not stop the other captures
        return CaptureResult(capture, name, "failed",
                             f"internal error: {type(err).__name__}: {err}",
                             time.monotonic() - start)
    finally:
        log.setLevel(previous)
    ran = [d.step.name for d in decisions if d.run]
    if not ran:
        status = "skipped"
    else:
        status = "would run" if dry_run else "done"
    return CaptureResult(capture, name, status, ", ".join(ran) or "up to date",
                         time.monotonic() - start)


def run_batch(config: str | Path, captures: Sequence[str | Path], *,
              overrides: Sequence[str] = (), out: str | Path | None = None,
              force: bool = False, dry_run: bool = False, jobs: int = 1,
              scheduler: str | None = None, timeout: float | None = None) -> BatchReport:
    """Run the template ``config`` over ``captures``: shared steps once, then every capture.

    ``jobs``: worker processes on this machine (1 runs in this process unless ``timeout`` is
    given); ``scheduler``: the address of a dask.distributed scheduler (then ``jobs`` is not
    used); ``timeout``: seconds one capture may take in a worker before it is stopped and
    reported as failed. Raises only for problems of the whole batch (bad config, a shared step
    failing, no Dask); a capture's failure is in its :class:`CaptureResult`.
    """
    if jobs < 1:
        raise ConfigError(f"--jobs {jobs}: give 1 or more worker processes")
    if timeout is not None and not (0 < timeout < MAX_TIMEOUT_S):  # also refuses NaN
        raise OptionError(f"--timeout {timeout:g}: give a number of seconds above 0 and under "
                          f"{MAX_TIMEOUT_S:.0f}")
    if timeout is not None and scheduler:
        raise OptionError("--timeout limits local worker processes; with --scheduler set the "
                          "Dask workers' own limits instead")
    if scheduler:
        check_scheduler(scheduler)
    template = read_template(config, overrides)
    if not template.per_capture_steps():
        raise ConfigError(f"{config}: no step uses {{capture}} or {{name}}, so there is nothing "
                          "to run per capture; run it with plenocli run, or name a step's "
                          'input "{capture}"')
    if not captures:
        raise InputError("no captures given; pass --inputs 'FOLDER/*.dng'")
    # where this process runs: a Dask worker runs in its own folder, perhaps on another machine
    config = str(Path(config).resolve())
    captures = [str(capture_path(c)) for c in captures]  # a link's name, not its target's
    out = None if out is None else str(Path(out).resolve())
    template.steps(capture=captures[0], out=out)  # config errors once, not once per capture
    template.check_captures_apart(captures, out=out)

    shared = _run_shared(template, out=out, force=force, dry_run=dry_run)
    upstream = [str(p) for d in shared if d.run for p in d.step.output_paths()]
    kwargs = dict(overrides=list(overrides), out=out, force=force, dry_run=dry_run,
                  upstream=upstream)
    elsewhere: list[str] = []  # on an interruption: captures the Dask cluster still runs
    if scheduler:
        results = _dask_results(scheduler, config, captures, kwargs, elsewhere)
    elif (jobs == 1 or len(captures) == 1) and timeout is None:
        results = (run_capture(config, c, **kwargs) for c in captures)
    else:
        results = _pool_results(min(jobs, len(captures)), config, captures, kwargs,
                                timeout)
    try:
        by_capture = _collect(results, len(captures))
    except KeyboardInterrupt as interrupt:
        if elsewhere:
            note_interrupt(interrupt, f"{', '.join(elsewhere)} had started on the Dask "
                           "cluster, which does not stop a running task: they finish there "
                           "and their outputs land, whole, after this exit (the pending "
                           "captures were cancelled); rerun the batch once they are done: it "
                           "skips them")
        raise
    return BatchReport(shared, [by_capture[c] for c in captures])


def _collect(results: Iterator[CaptureResult], total: int) -> dict[str, CaptureResult]:
    """Every result by capture. An interruption while a result is being handled closes the
    results here, so a pool stops its workers now: left to the interpreter's exit, the pool
    would wait for them to finish."""
    with contextlib.closing(results):
        return {r.capture: r for r in progress(results, "captures", total=total)}


def _run_shared(template: Template, *, out, force: bool, dry_run: bool) -> list[Decision]:
    steps = template.steps(out=out, only="shared")
    if not steps:
        return []
    if dry_run:
        decisions = plan(steps, force=force)
        for d in decisions:
            log.info("%-9s %-16s (shared) %s", "would run" if d.run else "skip", d.step.name,
                     d.reason)
        return decisions
    try:  # two batches of one shoot: the second waits for the first's shared steps
        return run_pipeline(steps, force=force, locked=True)
    except PlenocliError as err:
        raise type(err)(f"shared {err} (no capture was processed)") from err


# ---------------------------------------------------------------- worker processes (this machine)

_busy = False  # in a worker: is a capture being processed (then SIGTERM must clean up)
_hard_stop = float("inf")  # in a worker: monotonic time after which it exits, cleaned up or not
PR_SET_PDEATHSIG = 1


def _init_worker(batch_pid: int) -> None:
    """Worker set-up: Ctrl-C is the parent's business; SIGTERM unwinds a running capture so
    that atomic writes remove their temporary files, then the worker exits. A worker never
    outlives the batch: the kernel sends it SIGTERM when its parent (the fork server, which
    exits with the batch) dies, and a watchdog thread checks the batch process itself."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, _on_sigterm)
    signal.signal(signal.SIGALRM, _on_alarm)
    if sys.platform.startswith("linux"):
        with contextlib.suppress(OSError, AttributeError):
            libc = ctypes.CDLL(None, use_errno=True)
            libc.prctl(PR_SET_PDEATHSIG, signal.SIGTERM, 0, 0, 0)
    threading.Thread(target=_watchdog, args=(batch_pid, os.getppid()), daemon=True,
                     name="plenocli-watchdog").start()


def _watchdog(batch_pid: int, parent_pid: int) -> None:
    """Stop this worker when the batch process is gone, or when a capture overran its time
    limit and its stage did not unwind (stuck in compiled code)."""
    global _hard_stop
    while True:
        time.sleep(WATCH_SECONDS)
        if time.monotonic() > _hard_stop:
            os._exit(EXIT_OVERRAN)
        if os.getppid() != parent_pid or not process_alive(batch_pid):
            _hard_stop = min(_hard_stop, time.monotonic() + GRACE_SECONDS)
            os.kill(os.getpid(), signal.SIGTERM)


def _on_sigterm(signum, frame) -> None:
    if _busy:
        raise_terminated()  # atomic_path deletes its .part file on the way up
    os._exit(128 + signum)


def _on_alarm(signum, frame) -> None:
    if _busy:
        raise CaptureTimeout


def _worker_task(config: str, capture: str, kwargs: dict,
                 timeout: float | None = None) -> CaptureResult:
    global _busy, _hard_stop
    _busy = True
    start = time.monotonic()
    if timeout is not None:
        _hard_stop = start + timeout + GRACE_SECONDS
        signal.setitimer(signal.ITIMER_REAL, timeout)
    try:
        return run_capture(config, capture, **kwargs)
    except CaptureTimeout:
        return CaptureResult(capture, Path(capture).stem, "failed", timed_out(timeout),
                             time.monotonic() - start)
    except KeyboardInterrupt:
        os._exit(128 + signal.SIGTERM)
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        _busy = False
        _hard_stop = float("inf")


@contextlib.contextmanager
def _one_thread_per_worker() -> Iterator[None]:
    """Workers inherit the environment: BLAS, OpenMP and numba start with one thread each."""
    saved = {k: os.environ.get(k) for k in THREAD_ENV}
    os.environ.update({k: "1" for k in THREAD_ENV})
    try:
        yield
    finally:
        for key, value in saved.items():
            if value is None:
                os.environ.pop(key, None)
            else:
                os.environ[key] = value


# Imported once by the fork server, so that each worker starts without re-importing them.
PRELOAD = ["plenocli.pipeline.batch", "numpy", "scipy.ndimage", "tifffile",
           "plenocli.pipeline.stages.decode", "plenocli.pipeline.stages.bias",
           "plenocli.pipeline.stages.flat"]


def _context():
    if "forkserver" not in multiprocessing.get_all_start_methods():
        return multiprocessing.get_context("spawn")
    context = multiprocessing.get_context("forkserver")
    context.set_forkserver_preload(PRELOAD)  # no effect once the server runs: that is fine
    return context


def _pool_results(jobs: int, config: str, captures: list[str], kwargs: dict,
                  timeout: float | None = None) -> Iterator[CaptureResult]:
    """Results as they complete. Captures caught in a crashed pool are retried, then run one
    worker at a time so that a capture that kills its worker fails alone."""
    crashed, _ = yield from _pool_round(jobs, config, captures, kwargs, timeout)
    for capture in crashed:  # alone now, so that a crash is attributed to the right capture
        again, overran = yield from _pool_round(1, config, [capture], kwargs, timeout)
        if again:
            yield CaptureResult(capture, Path(capture).stem, "failed",
                                timed_out(timeout) if overran else CRASHED)


def _pool_round(jobs: int, config: str, captures: list[str], kwargs: dict,
                timeout: float | None) -> Iterator[CaptureResult]:
    """One process pool over ``captures``; yields results, returns (the crashed captures,
    whether a worker was stopped by its watchdog for running past the time limit)."""
    crashed: list[str] = []
    with _one_thread_per_worker():
        pool = ProcessPoolExecutor(max_workers=jobs, mp_context=_context(),
                                   initializer=_init_worker, initargs=(os.getpid(),))
        try:
            futures = {pool.submit(_worker_task, config, c, kwargs, timeout): c
                       for c in captures}
            workers = list((pool._processes or {}).values())  # started on submit
            remaining = set(futures)
            while remaining:
                finished, remaining = wait(remaining, return_when=FIRST_COMPLETED)
                for future in finished:
                    try:
                        yield future.result()
                    except BrokenProcessPool:
                        crashed.append(futures[future])
                    except CaptureTimeout:  # the alarm rang as the capture finished
                        capture = futures[future]
                        yield CaptureResult(capture, Path(capture).stem, "failed",
                                            timed_out(timeout))
        except BaseException:  # Ctrl-C or the consumer stopped: no worker may outlive us
            _terminate(pool)
            raise
        pool.shutdown(wait=True)
    for worker in workers if crashed else ():
        worker.join(GRACE_SECONDS)
    return crashed, any(w.exitcode == EXIT_OVERRAN for w in workers if crashed)


def _terminate(pool: ProcessPoolExecutor) -> None:
    """Stop the workers now; each one removes its half-written temporary file first.

    The pool's manager thread reaps the workers. Exits are watched on the workers' sentinels,
    and reaping is left to that thread and waited for: two threads joining one process race
    for its exit status, and the loser sees a dead worker as still running."""
    processes = list((pool._processes or {}).values())  # no public API for the worker list
    manager = pool._executor_manager_thread
    pool.shutdown(wait=False, cancel_futures=True)
    for proc in processes:
        proc.terminate()
    running = {proc.sentinel: proc for proc in processes}
    deadline = time.monotonic() + 10.0
    again = None
    try:
        while running and (left := deadline - time.monotonic()) > 0:
            for sentinel in connection.wait(list(running), left):
                del running[sentinel]
    except KeyboardInterrupt as interrupt:   # a second Ctrl-C: the grace time is over
        again = interrupt
    for proc in running.values():
        proc.kill()
    if manager is not None:
        manager.join(10.0)
    for proc in processes:  # reaped already, unless the manager thread hung
        proc.join(1.0)
    if again is not None:
        raise again


# ---------------------------------------------------------------- dask.distributed

def _require_dask() -> None:
    try:
        import distributed  # noqa: F401
    except ImportError as err:
        raise PlenocliError("--scheduler needs dask.distributed, which is not installed; "
                            "install it with: pip install 'plenocli[dask]'") from err


def check_scheduler(address: str) -> None:
    """Before any work: ``address`` is HOST:PORT (optionally tcp:// or tls://) and something
    listens there. A Dask client built on a bad address waits, then complains while Python
    shuts down; a plain socket says at once."""
    _require_dask()
    match = re.fullmatch(r"(?:(tcp|tls)://)?(\[[0-9a-fA-F:.]+\]|[^\s:/\[\]]+):(\d{1,5})",
                         address.strip())
    if match is None:
        raise ConfigError(f"--scheduler {address!r}: give the scheduler's address as "
                          "tcp://HOST:PORT (e.g. tcp://10.0.0.5:8786)")
    host, port = match.group(2).strip("[]"), int(match.group(3))
    try:
        with socket.create_connection((host, port), timeout=DASK_PROBE_SECONDS):
            pass
    except OSError as err:
        raise PlenocliError(f"cannot reach the Dask scheduler at {address!r} "
                            f"({err.strerror or err}); check the address and that it "
                            "runs") from err


def _dask_results(address: str, config: str, captures: list[str], kwargs: dict,
                  elsewhere: list[str]) -> Iterator[CaptureResult]:
    """Each capture a Dask task. Stopped before the end (an interruption), the pending tasks
    are cancelled; a running one cannot be (Dask does not stop a task's thread, and its
    worker may serve others), so its capture's name goes to ``elsewhere``: it still lands."""
    _require_dask()
    from distributed import Client, as_completed

    try:
        client = Client(address, timeout=DASK_CONNECT_TIMEOUT, set_as_default=False)
    except (OSError, TimeoutError, ValueError) as err:
        raise PlenocliError(f"cannot reach the Dask scheduler at {address!r} ({err}); "
                            "check the address (e.g. tcp://host:8786) and that it runs") from err
    futures, capture_of = [], {}
    try:
        futures = [client.submit(run_capture, config, c, **kwargs, pure=False,
                                 key=f"plenocli-{Path(c).stem}-{os.getpid()}-{k}")
                   for k, c in enumerate(captures)]
        capture_of = {f.key: c for f, c in zip(futures, captures, strict=True)}
        for future in as_completed(futures, loop=client.loop):
            try:
                yield future.result()
            except Exception as err:  # e.g. KilledWorker: the capture's worker kept dying
                capture = capture_of[future.key]
                yield CaptureResult(capture, Path(capture).stem, "failed",
                                    f"Dask: {type(err).__name__}: {err}")
    finally:
        left = [f for f in futures if not f.done()]
        if left:
            client.cancel(left)  # first: a task that starts after the question still runs
            elsewhere.extend(_still_running(client, left, capture_of))
        client.close()


def _still_running(client, futures: list, capture_of: dict[str, str]) -> list[str]:
    """The names of the captures whose tasks a worker is executing (cancelled ones included:
    a cancelled task that had started runs to its end)."""
    try:
        executing = {key for keys in client.run(_executing_keys).values() for key in keys}
        unsure = ""
    except Exception:  # noqa: BLE001 - no answer (a worker of another plenocli): any may run
        executing, unsure = {f.key for f in futures}, " (perhaps)"
    return [Path(capture_of[f.key]).stem + unsure for f in futures
            if f.key in executing and f.key in capture_of]


def _executing_keys(dask_worker) -> list[str]:
    """On a Dask worker: the keys of the tasks its threads are running."""
    return [str(task.key) for task in dask_worker.state.executing]


# ---------------------------------------------------------------- report

def format_summary(report: BatchReport, *, width: int = 100) -> str:
    """A plain-text table: one line per capture, then the counts."""
    results = report.results
    names = [printable(r.name) for r in results]  # a name's bytes as a terminal shows them
    name_w = max([len("capture")] + [len(n) for n in names])
    lines = [f"{'capture':<{name_w}}  {'status':<9}  {'time':>7}  detail"]
    for r, name in zip(results, names, strict=True):
        detail = r.detail if len(r.detail) <= width else r.detail[: width - 3] + "..."
        lines.append(f"{name:<{name_w}}  {r.status:<9}  {r.seconds:>5.1f} s  {detail}")
    counts = {s: sum(r.status == s for r in results)
              for s in ("done", "would run", "skipped", "failed")}
    tail = (f"{len(results)} capture{'' if len(results) == 1 else 's'}: {counts['done']} done, "
            f"{counts['skipped']} skipped "
            f"(up to date), {counts['failed']} failed")
    if counts["would run"]:
        tail += f", {counts['would run']} would run"
    shared_run = [d.step.name for d in report.shared if d.run]
    if report.shared:
        tail += f"; shared steps run: {', '.join(shared_run) or 'none (up to date)'}"
    return "\n".join([*lines, tail])

