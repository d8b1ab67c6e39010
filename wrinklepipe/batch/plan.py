"""Which manifests a batch converts, with which options, into which folders.

Sources are manifests, folders (searched for ``.toml`` files that declare
``schema = "wrinklepipe/manifest@1"``), glob patterns (``chars/**/manifest.toml``) or one batch
file (``schema = "wrinklepipe/batch@1"``, ``schemas/batch.schema.json``) that lists them with
per-asset options. Every asset's output folder is its manifest's path relative to the batch root
without ``.toml`` (``chars/ada/manifest.toml`` -> ``OUT/chars/ada/manifest``,
``chars/ada/lod1.toml`` -> ``OUT/chars/ada/lod1``, as ``ci/asset_conversion.sh`` has done), so
outputs are unique by construction; where an override or a layout still makes two outputs meet
(the same folder, or one inside the other: ``a.toml`` beside ``a/manifest.toml``) the plan
refuses to start and names both.
Every problem is reported at once, before anything runs.
"""

from __future__ import annotations

import fnmatch
import glob
import json
import os
import re
from dataclasses import dataclass, field
from functools import cache
from pathlib import Path, PurePosixPath
from typing import Any

import jsonschema

from wrinklepipe.batch.options import OPTION_KEYS, AssetOptions
from wrinklepipe.errors import InputError, ProblemList
from wrinklepipe.io.confine import current_roots
from wrinklepipe.io.json_safe import loads_toml
from wrinklepipe.paths import SCHEMAS_DIR

BATCH_SCHEMA = "wrinklepipe/batch@1"
_DECLARES_MANIFEST = re.compile(r'^\s*schema\s*=\s*["\']wrinklepipe/manifest@', re.M)
_DECLARES_BATCH = re.compile(r'^\s*schema\s*=\s*["\']wrinklepipe/batch@', re.M)
_GLOB_MAGIC = re.compile(r"[*?[]")


@dataclass(frozen=True)
class Job:
    """One asset: its manifest (absolute), its output folder (absolute) and options.

    ``id`` is the output folder relative to the batch output (posix), unique in a plan;
    ``manifest_rel`` the manifest relative to the batch root."""

    id: str
    manifest: Path
    manifest_rel: str
    output: Path
    options: AssetOptions
    force: bool = False
    kind: str = "convert"  # "convert" | "validate"
    params: dict[str, Any] = field(default_factory=dict, hash=False, compare=False)
    #: the folders ``--allow-root`` allowed where the job was planned: the worker process
    #: reads under them too (a context variable does not cross processes)
    roots: tuple[Path, ...] = field(default_factory=current_roots, hash=False, compare=False)


@dataclass
class BatchPlan:
    """The jobs of a batch, in a stable order (by id)."""

    root: Path
    output: Path
    jobs: list[Job] = field(default_factory=list)
    batch_file: Path | None = None


@cache
def batch_schema() -> dict[str, Any]:
    """The batch file's JSON Schema (``schemas/batch.schema.json``)."""
    return json.loads((SCHEMAS_DIR / "batch.schema.json").read_text(encoding="utf-8"))


def _head(path: Path) -> str:
    try:
        with open(path, "rb") as f:
            return f.read(65536).decode("utf-8", "replace")
    except OSError:
        return ""


def declares_manifest(path: Path) -> bool:
    """True when the TOML file says ``schema = "wrinklepipe/manifest@..."``."""
    return bool(_DECLARES_MANIFEST.search(_head(path)))


def declares_batch(path: Path) -> bool:
    """True when the TOML file says ``schema = "wrinklepipe/batch@..."``."""
    return bool(_DECLARES_BATCH.search(_head(path)))


def _inside(path: Path, folder: Path) -> bool:
    return path == folder or folder in path.parents


def find_manifests(folder: Path, skip: tuple[Path, ...] = ()) -> list[Path]:
    """Every manifest under ``folder`` (sorted), leaving out hidden folders and ``skip``."""
    found = []
    for dirpath, dirnames, filenames in os.walk(folder):
        here = Path(dirpath)
        dirnames[:] = sorted(
            d
            for d in dirnames
            if not d.startswith(".") and not any(_inside(here / d, s) for s in skip)
        )
        for name in sorted(filenames):
            p = here / name
            if name.endswith(".toml") and not name.startswith(".") and declares_manifest(p):
                found.append(p)
    return found


def _glob(pattern: str, base: Path) -> list[Path]:
    full = pattern if os.path.isabs(pattern) else str(base / pattern)
    return sorted(Path(p) for p in glob.glob(full, recursive=True) if Path(p).is_file())


def _abs(p: Path) -> Path:
    return Path(os.path.abspath(p))


def default_output(rel: PurePosixPath) -> PurePosixPath:
    """The manifest's path relative to the root without ``.toml``: ``chars/ada/manifest.toml``
    -> ``chars/ada/manifest``, ``chars/ada/lod1.toml`` -> ``chars/ada/lod1``."""
    return rel.with_suffix("")


# ------------------------------------------------------------------------------------------------
# batch files


@dataclass
class BatchFile:
    """A loaded, schema-checked batch file (paths absolute)."""

    path: Path
    root: Path
    output: Path | None
    include: list[str]
    exclude: list[str]
    defaults: dict[str, Any]
    assets: list[dict[str, Any]]


def _key(parts: Any) -> str:
    out = ""
    for part in parts:
        out += f"[{part}]" if isinstance(part, int) else (f".{part}" if out else str(part))
    return out


def load_batch_file(path: str | Path) -> BatchFile:
    """Read and check a batch file; one :class:`InputError` lists every problem."""
    path = _abs(Path(path))
    file = str(path)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise InputError("batch file not found", path) from None
    except UnicodeDecodeError:
        raise InputError("batch file is not UTF-8 text", path) from None
    data = loads_toml(text, path)
    problems = ProblemList()
    validator = jsonschema.Draft202012Validator(batch_schema())
    for error in sorted(
        validator.iter_errors(data), key=lambda e: (list(map(str, e.path)), e.message)
    ):
        key = _key(error.absolute_path)
        if error.validator in ("additionalProperties", "unevaluatedProperties"):
            allowed = set(error.schema.get("properties", {})) | set(OPTION_KEYS)
            for name in sorted(set(error.instance) - allowed):
                problems.add(file, "unknown key", f"{key}.{name}" if key else name)
        elif error.validator == "required":
            missing = error.message.split("'")[1] if "'" in error.message else error.message
            problems.add(file, "missing required key", f"{key}.{missing}" if key else missing)
        else:
            desc = error.schema.get("description") if isinstance(error.schema, dict) else None
            message = f"invalid value {error.instance!r}: {desc}" if desc else error.message
            problems.add(file, message, key)
    problems.raise_if_any()
    here = path.parent
    return BatchFile(
        path=path,
        root=_abs(here / data.get("root", ".")),
        output=_abs(here / data["output"]) if "output" in data else None,
        include=list(data.get("include", [])),
        exclude=list(data.get("exclude", [])),
        defaults=dict(data.get("defaults", {})),
        assets=[dict(a) for a in data.get("assets", [])],
    )


# ------------------------------------------------------------------------------------------------
# the plan


def _safe_rel(text: str) -> PurePosixPath | None:
    rel = PurePosixPath(text.replace("\\", "/"))
    if rel.is_absolute() or ".." in rel.parts or str(rel) in ("", "."):
        return None
    return rel


def _nonempty_dir(p: Path) -> bool:
    return p.is_dir() and any(p.iterdir())


def plan_batch(
    sources: list[str],
    output: str | Path | None = None,
    *,
    root: str | Path | None = None,
    defaults: AssetOptions | None = None,
    cli_options: dict[str, Any] | None = None,
    force: bool = False,
) -> BatchPlan:
    """Resolve ``sources`` into jobs. ``defaults`` are the options before the batch file's
    ``[defaults]``; ``cli_options`` (options given explicitly on the command line) win over both
    and over per-asset entries. Raises one :class:`InputError` naming every problem."""
    problems = ProblemList()
    cwd = _abs(Path.cwd())
    batch: BatchFile | None = None
    batch_sources = [s for s in sources if s.endswith(".toml") and Path(s).is_file()]
    batch_sources = [s for s in batch_sources if declares_batch(Path(s))]
    if batch_sources:
        if len(sources) != 1:
            raise InputError(
                "a batch file must be the only source (list the rest in it)", batch_sources[0]
            )
        batch = load_batch_file(batch_sources[0])
    out_dir = _abs(Path(output)) if output is not None else (batch.output if batch else None)
    if out_dir is None:
        raise InputError("no output folder: give -o OUT (or `output` in a batch file)", "batch")
    dirs = [s for s in sources if not _GLOB_MAGIC.search(s) and Path(s).is_dir()]
    if root is not None:
        root_dir = _abs(Path(root))
    elif batch is not None:
        root_dir = batch.root
    elif len(sources) == 1 and dirs:
        root_dir = _abs(Path(dirs[0]))
    else:
        root_dir = cwd

    manifests = _listed_manifests(sources, batch, root_dir, cwd, (out_dir,), problems)

    by_rel: dict[PurePosixPath, Path] = {}
    for m in manifests:
        rel = _rel_under(m, root_dir)
        if rel is None:
            problems.add(m, f"lies outside the batch root {root_dir} (use --root)")
            continue
        by_rel.setdefault(rel, _abs(m))
    if batch is not None and batch.exclude:
        by_rel = {
            r: m
            for r, m in by_rel.items()
            if not any(fnmatch.fnmatch(str(r), x) for x in batch.exclude)
        }

    base = defaults or AssetOptions()
    try:
        base = base.updated(batch.defaults if batch else {})
    except KeyError as exc:  # the schema lists the same keys; defensive only
        problems.add(batch.path if batch else "batch", str(exc), "defaults")
    per_asset, out_override = _asset_entries(batch, root_dir, by_rel, problems)
    problems.raise_if_any()

    jobs: list[Job] = []
    for rel, path in sorted(by_rel.items()):
        out_rel = out_override.get(rel, (default_output(rel), ""))[0]
        options = base.updated({**per_asset.get(rel, {}), **(cli_options or {})})
        jobs.append(
            Job(
                id=out_rel.as_posix(),
                manifest=path,
                manifest_rel=rel.as_posix(),
                output=_abs(out_dir / out_rel),
                options=options,
                force=force,
            )
        )
    if not jobs:
        raise InputError("no manifests to convert", " ".join(sources) or "batch")
    _check_outputs(jobs, out_dir, force, problems)
    problems.raise_if_any()
    return BatchPlan(
        root=root_dir,
        output=out_dir,
        jobs=sorted(jobs, key=lambda j: j.id),
        batch_file=batch.path if batch else None,
    )


def _listed_manifests(
    sources: list[str],
    batch: BatchFile | None,
    root_dir: Path,
    cwd: Path,
    skip: tuple[Path, ...],
    problems: ProblemList,
) -> list[Path]:
    """The manifests the sources name: the batch file's ``include`` patterns (else every
    manifest under the root), or each source as a glob, a folder or a file; a source that
    names none is a problem."""
    manifests: list[Path] = []
    if batch is not None:
        if batch.include:
            for pattern in batch.include:
                hits = [p for p in _glob(pattern, root_dir) if declares_manifest(p)]
                if not hits:
                    problems.add(
                        batch.path, f"no manifests match {pattern!r} under {root_dir}", "include"
                    )
                manifests += hits
        else:
            manifests += find_manifests(root_dir, skip)
    else:
        for s in sources:
            p = Path(s)
            if _GLOB_MAGIC.search(s):
                hits = [q for q in _glob(s, cwd) if q.suffix == ".toml" and declares_manifest(q)]
                if not hits:
                    problems.add(s, "no manifests match this pattern")
                manifests += hits
            elif p.is_dir():
                hits = find_manifests(_abs(p), skip)
                if not hits:
                    problems.add(
                        s, "no manifests (.toml declaring wrinklepipe/manifest@1) in this folder"
                    )
                manifests += hits
            elif p.is_file():
                manifests.append(p)
            else:
                problems.add(s, "not found")

    return manifests


def _rel_under(p: Path, root_dir: Path) -> PurePosixPath | None:
    """``p`` relative to the batch root, or None when it lies outside it."""
    r = os.path.relpath(_abs(p), root_dir)
    return None if r == ".." or r.startswith(".." + os.sep) else PurePosixPath(Path(r).as_posix())


def _asset_entries(
    batch: BatchFile | None,
    root_dir: Path,
    by_rel: dict[PurePosixPath, Path],
    problems: ProblemList,
) -> tuple[dict[PurePosixPath, dict[str, Any]], dict[PurePosixPath, tuple[PurePosixPath, str]]]:
    """The batch file's ``[[assets]]``: each entry's options per manifest and its output
    folder (a manifest an entry names is added to ``by_rel``)."""
    per_asset: dict[PurePosixPath, dict[str, Any]] = {}
    out_override: dict[PurePosixPath, tuple[PurePosixPath, str]] = {}
    for i, entry in enumerate(batch.assets if batch else []):
        key = f"assets[{i}]"
        pattern = str(entry["manifest"])
        if _GLOB_MAGIC.search(pattern):
            for p in _glob(pattern, root_dir):
                r = _rel_under(p, root_dir)
                if r is not None and declares_manifest(p):
                    by_rel.setdefault(r, _abs(p))
            hits = [r for r in by_rel if fnmatch.fnmatch(str(r), pattern)]
        else:
            p = root_dir / pattern
            r = _rel_under(p, root_dir)
            if not p.is_file() or r is None:
                problems.add(batch.path, f"manifest not found: {p}", f"{key}.manifest")
                continue
            by_rel.setdefault(r, _abs(p))
            hits = [r]
        if not hits:
            problems.add(batch.path, f"no manifests match {pattern!r}", f"{key}.manifest")
        opts = {k: v for k, v in entry.items() if k in OPTION_KEYS}
        for r in hits:
            per_asset.setdefault(r, {}).update(opts)
        if "output" in entry:
            out_rel = _safe_rel(str(entry["output"]))
            if out_rel is None:
                problems.add(
                    batch.path,
                    "output must be a relative path inside the batch output",
                    f"{key}.output",
                )
            elif len(hits) > 1:
                problems.add(
                    batch.path,
                    f"output given for a pattern matching {len(hits)} manifests",
                    f"{key}.output",
                )
            else:
                for r in hits:
                    out_override[r] = (out_rel, f"{batch.path} [{key}.output]")
    return per_asset, out_override


def _check_outputs(jobs: list[Job], out_dir: Path, force: bool, problems: ProblemList) -> None:
    """Two outputs may not meet (nor differ only in case: on macOS and Windows they are one
    folder); no output may hold an input; existing outputs need ``force``."""
    by_id: dict[str, Job] = {}
    for j in jobs:
        other = by_id.get(j.id.casefold())
        if other is not None:
            same = "is also" if other.id == j.id else f"differs only in case from {other.id!r},"
            problems.add(
                j.manifest_rel,
                f"output {j.id!r} {same} the output of {other.manifest_rel}"
                + ("" if other.id == j.id else " (one folder on macOS and Windows)")
                + "; give one of them another `output` in a batch file",
            )
        else:
            by_id[j.id.casefold()] = j
    for j in jobs:
        for parent in PurePosixPath(j.id).parents:
            other = by_id.get(parent.as_posix().casefold())
            if other is not None and other is not j:
                problems.add(
                    j.manifest_rel,
                    f"output {j.id!r} lies inside {other.id!r}, the output of "
                    f"{other.manifest_rel}; give one of them another `output` in a batch file",
                )
    folders = sorted({j.manifest.parent for j in jobs})
    for j in jobs:
        for f in folders:
            if _inside(f, j.output):
                problems.add(j.manifest_rel, f"output {j.output} would hold the input folder {f}")
                break
        if not force and _nonempty_dir(j.output):
            problems.add(j.manifest_rel, f"output {j.output} exists and is not empty (use --force)")
        if j.output.exists() and not j.output.is_dir():
            problems.add(j.manifest_rel, f"output {j.output} exists and is not a folder")
    if out_dir.exists() and not out_dir.is_dir():
        problems.add(out_dir, "the batch output exists and is not a folder")
