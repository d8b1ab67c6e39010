"""``validate-asset`` over a folder of outputs (a batch's ``OUT``, a build tree): every convert
output beneath it becomes a validation job, run on the batch engines and reported with the
batch's JSON summary, JUnit and SARIF."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

from wrinklepipe.batch.options import AssetOptions
from wrinklepipe.batch.plan import BatchPlan, Job
from wrinklepipe.batch.results import AssetResult, counts_of, status_for
from wrinklepipe.readers.registry import PACKAGE_SUFFIXES


def is_asset_folder(folder: Path) -> bool:
    """A folder ``validate-asset`` reads as one asset: it holds a glTF/USD file or a manifest."""
    try:
        names = os.listdir(folder)
    except OSError:
        return False
    return any(n.lower().endswith(PACKAGE_SUFFIXES) for n in names) or "manifest.toml" in names


def output_folders(folder: Path) -> list[Path]:
    """The asset folders under ``folder`` (not descending into one once found; hidden folders
    skipped), sorted; empty when ``folder`` is itself an asset."""
    if is_asset_folder(folder):
        return []
    found = []
    for dirpath, dirnames, _ in os.walk(folder):
        here = Path(dirpath)
        keep = []
        for d in sorted(dirnames):
            if d.startswith("."):
                continue
            if is_asset_folder(here / d):
                found.append(here / d)
            else:
                keep.append(d)
        dirnames[:] = keep
    return sorted(found)


def plan_validation(
    folder: Path, folders: list[Path], options: AssetOptions, params: dict[str, Any]
) -> BatchPlan:
    """One validation job per asset folder; ids are the folders relative to ``folder``."""
    root = Path(os.path.abspath(folder))
    jobs = [
        Job(
            id=Path(os.path.relpath(os.path.abspath(f), root)).as_posix(),
            manifest=Path(os.path.abspath(f)),
            manifest_rel="",
            output=Path(os.path.abspath(f)),
            options=options,
            kind="validate",
            params=dict(params),
        )
        for f in folders
    ]
    return BatchPlan(root=root, output=root, jobs=jobs)


def single_result(
    issues: list[dict[str, Any]], path: Path, name: str, fail_on: str, seconds: float
) -> tuple[AssetResult, BatchPlan]:
    """One validated asset as a result and a one-job plan, for the same CI reports (issue
    pointers made relative to the asset's folder)."""
    p = Path(os.path.abspath(path))
    parent = p.parent
    base = p if p.is_dir() else parent
    issues = [
        {k: (v.replace(str(base), ".") if isinstance(v, str) else v) for k, v in i.items()}
        for i in issues
    ]
    result = AssetResult(
        id=p.name,
        manifest="",
        output=p.name if p.is_dir() else ".",
        status=status_for(issues, fail_on),
        source="validated",
        name=name,
        fail_on=fail_on,
        seconds=round(seconds, 4),
        issues=issues,
        counts=counts_of(issues),
        validation="ran",
    )
    job = Job(p.name, p, "", p, AssetOptions(fail_on=fail_on), kind="validate")
    return result, BatchPlan(root=parent, output=parent, jobs=[job])
