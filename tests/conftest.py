"""Fixtures several test files share (each built once per test session and worker).

How the suite shares out on ``pytest -n 2`` (the CI machine: 2 cores):

``pyproject.toml`` runs xdist with ``--dist loadfile --no-loadscope-reorder``: every test module
goes whole to one worker, so a module-scoped fixture (a conversion, a browser page) is built
once, not once on each worker that happens to run one of its tests (the three.js page test built
its ~30 s page twice under ``--dist load``).

With whole modules as the units, the two longest modules must not start last: a worker that
picks up a long module at the end leaves the other idle. So under xdist the modules below go
first, longest first (the rest follow in file order; they are a few seconds each). The list is
the modules' share of the summed test durations in two ``-n 2`` runs on main 4e4b5d2 with
../shared/data present (2026-12-02 14:43 and 15:00 UTC, 1134 tests; the mean of the two
shares, the machine shared, load 3-5); refresh it from such a run when a module's cost
changes a lot. The order changes nothing but
when a test starts; ``-n 0`` runs keep file order.
"""

from __future__ import annotations

import gc
import os
from pathlib import Path
from typing import Any

import pytest
from hypothesis import settings
from threadpoolctl import threadpool_limits

# The property tests are part of a test command that must give the same verdict every run, on a
# loaded machine too: no wall-clock deadline (a slow example is not a failure; speed is measured
# by the benchmarks) and the same examples each run (derandomized, no example database). Set
# HYPOTHESIS_PROFILE=explore to draw fresh examples when hunting for new failures.
settings.register_profile("deterministic", deadline=None, derandomize=True, database=None)
settings.register_profile("explore", deadline=None)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "deterministic"))

#: Libraries' own thread pools that read their size from the environment (OpenBLAS when numpy
#: loads it, llvmpipe when a GL context is made), for the worker's tests and the processes they
#: start.
_POOL_ENV = ("OPENBLAS_NUM_THREADS", "LP_NUM_THREADS")


def pytest_configure(config: pytest.Config) -> None:
    """Under xdist each worker gets its share of the cores for the libraries' thread pools
    (OpenBLAS, llvmpipe, USD's work threads, OpenImageIO's), as ``wrinklepipe batch --jobs N``
    gives each of its workers (``batch.worker.limit_threads``): two workers on the CI
    machine's two cores, each with OpenBLAS and llvmpipe on two threads, made four threads
    that wait on each other (the suite 153 -> 142 s with one each). An explicit setting in the
    environment wins. wrinklepipe's own pools keep their default, so the tests still run them
    on several threads."""
    if not hasattr(config, "workerinput"):
        return
    # deferred: the xdist controller, which runs no test, loads this file too
    import OpenImageIO
    from pxr import Work

    share = max(1, (os.cpu_count() or 1) // int(config.workerinput["workercount"]))
    for name in _POOL_ENV:
        os.environ.setdefault(name, str(share))
    threadpool_limits(limits=int(os.environ["OPENBLAS_NUM_THREADS"]), user_api="blas")
    Work.SetConcurrencyLimit(share)  # USD's work threads (they spin while they wait)
    OpenImageIO.attribute("threads", share)


def pytest_collection(session: pytest.Session) -> None:
    """No cyclic garbage collection while the test modules load: importing ~100 modules and
    their libraries makes millions of long-lived objects, and each full collection in between
    walked them all again (1.2 s of a worker's 6 s collection)."""
    gc.disable()


def pytest_collection_finish(session: pytest.Session) -> None:
    """Collect once, then freeze what collection made (modules, functions, the items): they live
    to the end of the session, so the tests' full collections no longer walk them. The tests'
    own objects are collected as before."""
    gc.collect()
    gc.freeze()
    gc.enable()


def pytest_unconfigure(config: pytest.Config) -> None:
    """Frozen objects back to the collector before the interpreter ends, so that shutdown frees
    them as usual (nanobind, OpenImageIO's binding, reports every object it is not given back)."""
    gc.unfreeze()


@pytest.fixture(scope="session")
def robot_converted(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict[str, Any]]:
    """RobotExpressive converted once (:func:`wrinkle_setups.write_robot_setup`; .gltf + .glb,
    validation without the render pass): (output folder, report). Read only."""
    # Deferred on purpose: the xdist controller loads this file too and runs no test; importing
    # convert there costs ~1.4 s CPU while the two workers start and collect.
    from wrinkle_setups import ROBOT, write_robot_setup

    from wrinklepipe.io.confine import allowed_roots
    from wrinklepipe.jobs.convert import ConvertOptions, convert

    if not ROBOT.is_file():
        pytest.skip("../shared/data is absent")
    root = tmp_path_factory.mktemp("robot")
    manifest = write_robot_setup(root / "src")
    with allowed_roots([ROBOT.parent]):
        res = convert(manifest, root / "out", ConvertOptions(glb=True, render=False))
    assert res.exit_code == 0
    return root / "out", res.report


LONGEST_FIRST = [  # share of the summed test durations in those runs
    "test_docs_examples.py",  # every shell example of the README and docs/ (a few converts)
    "test_help_examples.py",  # every example of every command's --help
    "test_cli_progress.py",  # a 1024² convert, piped, and two interrupted ones
    "test_report_pictures.py",  # chromium: report.html, validation.html, the viewer
    "test_batch_run.py",  # 9 % (the isolation test: converts, a LocalCluster)
    "test_safety_faults.py",  # 7.9 % (22 killed CLI runs and their reruns)
    "test_viewer.py",  # 5.6 % (one browser page in one piece)
    "test_blender.py",  # ~30 s alone (issue 46, not in those runs): one Blender 5 process
    "test_materialx.py",  # ~20 s alone (issue 46): MaterialX GLSL renders, RobotExpressive
    "test_capture_cli.py",  # 5.4 %
    "test_batch_ci.py",  # 5.1 % (the CI script: three batch runs in their own processes)
    "test_convert_fidelity.py",  # 4.3 % (one CesiumMan convert at 1024)
    "test_safety_fuzz.py",  # 3.9 %
    "test_validate_render.py",  # 3.3 %
    "test_document_convert.py",  # 3.2 %
    "test_convert_formats.py",  # 3 %
    "test_export_engines.py",  # 3 % (whole characters: avatar + RobotExpressive, 4 engines)
    "test_validate_cli.py",  # 3 %
    "test_face_fixture.py",  # 2.3 %
    "test_safety_outputs.py",  # 2.3 %
    "test_batch_bench.py",  # 2.2 %
    "test_usd_scene_skin.py",  # 2.1 %
    "test_engine_shaders.py",  # 2 %
    "test_validate_corpus.py",  # 2 %
    "test_normals_bc4.py",  # 1.9 %
    "test_document_read.py",  # 1.5 %
]


@pytest.hookimpl(tryfirst=True)
def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    if not hasattr(config, "workerinput"):  # not an xdist worker: keep file order
        return
    rank = {name: i for i, name in enumerate(LONGEST_FIRST)}
    items.sort(key=lambda item: rank.get(item.path.name, len(rank)))  # stable: file order kept
