"""The make-style runner: run the steps of a config in order, skipping up-to-date ones.

A step is up to date when all its outputs exist, each has a record (written with it, see
:mod:`plenocli.pipeline.records`) saying it was made by this stage with the step's fully
resolved parameters now (defaults included, so removing a key from a config reruns the step
when its default differs) from its inputs as they are now, the output itself unchanged since;
and no step before it in this run was (or would be) rerun to make one of its inputs. An output
without a readable record (made by another program, or by an older plenocli) reruns its step.
"""

from __future__ import annotations

import os
import time
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

from plenocli.errors import ConfigError, InputError, PlenocliError, not_a_file, os_error_message
from plenocli.io.atomic import check_names_fit, check_outputs
from plenocli.io.folderlock import folders_locked
from plenocli.pipeline.config import Step
from plenocli.pipeline.kinds import Planned, check_kinds, planned_outputs
from plenocli.progress import log


@dataclass(frozen=True)
class Decision:
    step: Step
    run: bool
    reason: str


def plan(steps: list[Step], *, force: bool = False,
         upstream: Iterable[Path] = ()) -> list[Decision]:
    """Decide, without running anything, which steps must run and why.

    ``upstream``: files that steps outside ``steps`` will (re)make before these run, e.g. the
    outputs of a batch's shared steps.
    """
    check_inputs(steps, upstream)
    decisions: list[Decision] = []
    will_make: set[Path] = {Path(p).resolve() for p in upstream}
    for step in steps:
        reason = "forced" if force else _stale(step, will_make)
        if reason:
            will_make.update(p.resolve() for p in step.output_paths())
        decisions.append(Decision(step, bool(reason), reason or "up to date"))
    return decisions


def check_inputs(steps: list[Step], upstream: Iterable[Path] = ()) -> None:
    """Every input of every step exists or is made by an earlier step (or is in ``upstream``),
    and is of a kind its stage takes (an earlier step's output as that step will make it):
    what ``run``, ``--dry-run`` and ``--print-make`` check before any work (ConfigError)."""
    made: set[Path] = {Path(p).resolve() for p in upstream}
    planned: dict[Path, Planned | None] = {Path(p).absolute(): None for p in upstream}
    for step in steps:
        for p in step.input_paths():
            if not p.exists() and not _within(p, made):
                if os.path.islink(p):  # a loop, or a link to nothing: say where it leads
                    raise ConfigError(f"step {step.name!r}: {not_a_file(p)}")
                raise ConfigError(f"step {step.name!r}: input {p} does not exist and no earlier "
                                  "step makes it")
            if p.exists() and not (p.is_file() or p.is_dir()) and not _within(p, made):
                raise ConfigError(f"step {step.name!r}: {not_a_file(p)}")
        inputs = step.stage.by_role(step.params, step.stage.inputs)
        try:
            check_kinds(step.stage.name, inputs, planned)
        except InputError as err:
            raise ConfigError(f"step {step.name!r}: {err}") from err
        for out in step.output_paths():
            try:
                check_names_fit(out)
            except InputError as err:
                raise ConfigError(f"step {step.name!r}: {err}") from err
        made.update(p.resolve() for p in step.output_paths())
        planned.update(planned_outputs(step.stage.name, step.stage.by_role(
            step.params, step.stage.outputs), inputs, planned))


def _within(path: Path, made: set[Path]) -> bool:
    """Whether ``path`` is one of ``made`` or inside one of them (a folder output)."""
    try:
        resolved = path.resolve()
    except (OSError, RuntimeError):  # a symbolic-link loop: nothing a step makes
        return False
    return resolved in made or any(parent in made for parent in resolved.parents)


def run_pipeline(steps: list[Step], *, force: bool = False, dry_run: bool = False,
                 locked: bool = False) -> list[Decision]:
    """Run what :func:`plan` says must run; return the decisions. ``locked``: plan and run
    holding the lock of every folder the steps write into (another run writing there waits,
    then finds what this one made up to date)."""
    if locked and not dry_run:
        try:
            _check_writable(steps)
        except InputError:
            # a made project on a read-only file system (an archive, a snapshot) is up to
            # date, as make says: nothing to write, nothing to lock; else the steps that must
            # run say what they cannot write
            _check_writable([d.step for d in plan(steps, force=force) if d.run])
            return run_pipeline(steps, force=force)
        with folders_locked([p for step in steps for p in step.output_paths()]):
            return run_pipeline(steps, force=force)
    decisions = plan(steps, force=force)
    for d in decisions:
        if dry_run:
            log.info("%-9s %-16s (%s) %s", "would run" if d.run else "skip", d.step.name,
                     d.step.stage.name, d.reason)
            continue
        if not d.run:
            log.info("skip     %-16s up to date", d.step.name)
            continue
        log.info("run      %-16s (%s: %s)", d.step.name, d.step.stage.name, d.reason)
        start = time.monotonic()
        try:
            # checks that read an input an earlier step made could not see it when the config
            # was loaded: they hold now, as when the next run loads the config (ConfigError)
            try:
                d.step.stage.check(d.step.params, d.step.given)
            except PlenocliError as err:
                raise ConfigError(str(err)) from err
            with d.step.stage.guard(d.step.params):
                d.step.stage.run(**d.step.params)
        except PlenocliError as err:
            raise type(err)(f"step {d.step.name!r}: {err}") from err
        except OSError as err:
            raise InputError(f"step {d.step.name!r}: {os_error_message(err)}") from err
        log.debug("         %-16s %.2f s", d.step.name, time.monotonic() - start)
    return decisions


def _check_writable(steps: list[Step]) -> None:
    """InputError for the first output of ``steps`` that cannot be written, as each step's
    guard says it."""
    for step in steps:
        folders = step.stage.paths(step.params, step.stage.folder_outputs)
        check_outputs([p for p in step.output_paths() if p not in folders], folders=folders)


def _stale(step: Step, will_make: set[Path]) -> str | None:
    outputs = step.output_paths()
    if not outputs:
        return "it writes no file"  # nothing to vouch for: it only reports, every time
    missing = [p for p in outputs if not p.exists()]
    if missing:
        return f"{missing[0].name} missing"
    for p in step.input_paths():
        if _within(p, will_make):
            return f"{p.name} is being remade"
    return step.stage.why_stale(step.params)
