"""Run a plan: serve what the cache holds, send the rest to an engine, store what it converts.

For every convert job, with a cache: hash the inputs (:func:`asset_key`); a complete entry is
restored into the output folder (hashes checked) and the asset never reaches an engine. The
others run on the engine, the longest first by the cache's record of their last conversion
(:func:`longest_first`); each one that was written (exit 0 or 1) is stored, unless its inputs
changed while it ran (the key is taken again afterwards). Then the cache is trimmed to its cap.
An asset that cannot be hashed (a broken manifest) fails on its own, like any other.

Nothing stops a batch half-way: a cache that cannot be written is used read-only from then on
(one warning, :attr:`CacheStats.warning`); an entry that cannot be restored is converted again
and replaced; an engine that fails (a scheduler gone) fails the assets it had not reported,
each with the reason. Every asset of the plan gets a result, so the reports are always written.
"""

from __future__ import annotations

import contextlib
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from wrinklepipe.batch.cache import Cache, CacheMiss, Entry
from wrinklepipe.batch.fingerprint import asset_key
from wrinklepipe.batch.plan import BatchPlan, Job
from wrinklepipe.batch.results import AssetResult, counts_of, status_for, worst_exit_code
from wrinklepipe.errors import InputError, input_error

_CACHED_FIELDS = ("name", "issues", "validation", "stages", "seconds", "worker")


@dataclass
class CacheStats:
    folder: str
    hits: int = 0
    misses: int = 0
    stored: int = 0
    unusable: int = 0  # entries that went away or were altered while being restored
    evicted: int = 0
    bytes: int = 0
    max_bytes: int | None = None
    warning: str = ""  # why the cache could not be written, when it could not

    def to_json(self) -> dict[str, Any]:
        return dict(self.__dict__)


@dataclass
class BatchRun:
    """The results in plan order, the batch's exit code, wall time and the cache's numbers."""

    results: list[AssetResult]
    seconds: float
    cache: CacheStats | None = None
    submitted: list[str] = field(default_factory=list)  # job ids an engine ran

    @property
    def exit_code(self) -> int:
        return worst_exit_code(self.results)


def _error(job: Job, exc: BaseException) -> AssetResult:
    if isinstance(exc, InputError):
        problems = [{"file": p.file, "key": p.key, "message": p.message} for p in exc.problems]
    else:
        problems = [
            {
                "file": job.manifest_rel,
                "key": "",
                "message": f"could not hash the inputs ({type(exc).__name__}: {exc})",
            }
        ]
    return AssetResult.could_not_run(job, problems)


def _from_entry(job: Job, entry: Entry, seconds: float) -> AssetResult:
    stored = entry.result
    issues = list(stored.get("issues", []))
    return AssetResult(
        id=job.id,
        manifest=job.manifest_rel,
        output=job.id,
        status=status_for(issues, job.options.fail_on),
        source="cache",
        name=str(stored.get("name", "")),
        fail_on=job.options.fail_on,
        seconds=round(seconds, 4),
        issues=issues,
        counts=counts_of(issues),
        key=entry.key,
        validation=str(stored.get("validation", "")),
    )


def longest_first(jobs: list[Job], cache: Cache | None) -> list[Job]:
    """The order the engine gets the jobs in: those the cache never saw converted first (in
    plan order: their cost is unknown, so they are not left for the end), then the others by
    their last conversion time, longest first, so the batch does not end on one long asset
    while the other workers idle. Results are reported in plan order whatever the order."""
    if cache is None:
        return list(jobs)
    last = {j.id: cache.last_seconds(j.id) if j.kind == "convert" else None for j in jobs}
    return sorted(jobs, key=lambda j: (last[j.id] is not None, -(last[j.id] or 0.0)))


def _engine_failed(job: Job, exc: BaseException) -> AssetResult:
    if isinstance(exc, InputError):
        reason = "; ".join(p.message for p in exc.problems)
    else:
        reason = f"{type(exc).__name__}: {str(exc).strip().splitlines()[0] if str(exc) else ''}"
    return AssetResult.could_not_run(
        job, [{"file": job.manifest_rel, "key": "", "message": f"did not run: {reason}"}]
    )


def run_plan(
    plan: BatchPlan,
    engine: Any,
    cache: Cache | None = None,
    on_stage: Callable[[str, str], None] | None = None,
    on_done: Callable[[AssetResult], None] | None = None,
    on_warning: Callable[[str], None] | None = None,
) -> BatchRun:
    """Run every job of ``plan`` (see the module docstring); ``on_warning`` is told, once,
    when the cache cannot be written. The output folder is made here, before any asset, and
    removed again if it is still empty at the end (every asset failed): the assets' processes,
    racing to make it, each thought another had made it, and an empty folder stayed."""
    made = _make_output(plan.output)
    try:
        return _run_plan(plan, engine, cache, on_stage, on_done, on_warning)
    finally:
        for folder in made:  # deepest first; only if still empty
            with contextlib.suppress(OSError):
                folder.rmdir()


def _make_output(folder: Path) -> list[Path]:
    """Make ``folder`` and its missing parents; the ones made, deepest first (none when it
    cannot be made: each asset then says why)."""
    missing = [p for p in (folder, *folder.parents) if not p.exists()]
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError:
        return []
    return missing


def _run_plan(
    plan: BatchPlan,
    engine: Any,
    cache: Cache | None,
    on_stage: Callable[[str, str], None] | None,
    on_done: Callable[[AssetResult], None] | None,
    on_warning: Callable[[str], None] | None,
) -> BatchRun:
    t0 = time.perf_counter()
    stage = on_stage or (lambda _job, _stage: None)
    warned: list[str] = []

    def done(result: AssetResult) -> None:
        if cache is not None and cache.unwritable and not warned:
            warned.append(cache.unwritable)
            if on_warning is not None:
                on_warning(cache.unwritable)
        if on_done is not None:
            on_done(result)

    results: dict[str, AssetResult] = {}
    keys: dict[str, str] = {}
    damaged: set[str] = set()  # keys whose entry could not be restored: replaced when stored
    stats = CacheStats(str(cache.root), max_bytes=cache.max_bytes) if cache else None
    to_run: list[Job] = []
    for job in plan.jobs:
        if cache is None or job.kind != "convert":
            to_run.append(job)
            continue
        t1 = time.perf_counter()
        stage(job.id, "hashing inputs")
        try:
            key, _ = asset_key(job.manifest, job.options, job.output)
        except (KeyboardInterrupt, SystemExit):
            raise
        except Exception as exc:  # noqa: BLE001 - a manifest that cannot be read fails alone
            results[job.id] = _error(job, exc)
            done(results[job.id])
            continue
        keys[job.id] = key
        entry = cache.lookup(key)
        if entry is not None:
            try:
                stage(job.id, "restoring from the cache")
                cache.restore(entry, job.output, force=job.force, inputs=[job.manifest.parent])
            except CacheMiss:
                stats.unusable += 1
                damaged.add(key)
            except InputError as exc:
                results[job.id] = _error(job, exc)
                done(results[job.id])
                continue
            except OSError as exc:  # writing the output folder failed
                results[job.id] = _error(
                    job,
                    input_error(job.output, f"could not write the output ({exc.strerror or exc})"),
                )
                done(results[job.id])
                continue
            else:
                stats.hits += 1
                results[job.id] = _from_entry(job, entry, time.perf_counter() - t1)
                done(results[job.id])
                continue
        stats.misses += 1
        to_run.append(job)

    to_run = longest_first(to_run, cache)
    by_id = {j.id: j for j in to_run}
    try:
        for result in engine.run(to_run, stage):
            job = by_id[result.id]
            if cache is not None and result.source == "converted" and job.kind == "convert":
                cache.remember_seconds(job.id, result.seconds)
            key = keys.get(job.id)
            if cache is not None and key and result.status != "error":
                result.key = key
                try:
                    same = asset_key(job.manifest, job.options, job.output)[0] == key
                except Exception:  # noqa: BLE001 - inputs vanished meanwhile: do not store
                    same = False
                if same:
                    fields = {f: getattr(result, f) for f in _CACHED_FIELDS}
                    if cache.store(key, job.output, fields, replace=key in damaged):
                        stats.stored += 1
            results[result.id] = result
            done(result)
    except (KeyboardInterrupt, SystemExit):
        raise
    except Exception as exc:  # noqa: BLE001 - the engine failed: the assets it left fail
        for job in to_run:
            if job.id not in results:
                results[job.id] = _engine_failed(job, exc)
                done(results[job.id])
    if cache is not None:
        stats.evicted = len(cache.evict(keep=keys.values()))
        stats.bytes = cache.size()
        stats.warning = cache.unwritable or ""
        if cache.unwritable and not warned and on_warning is not None:
            on_warning(cache.unwritable)
    ordered = [results[j.id] for j in plan.jobs]
    return BatchRun(ordered, time.perf_counter() - t0, stats, [j.id for j in to_run])
