"""Test harness, run by Blender 5's Python (``bpy``): several scripts in one Blender session.

    .venv-blender/bin/python tests/blender_session.py -- JOBS.json

JOBS.json is a list of ``{"name", "script", "args", "stdout", "stderr"}``. Each script starts
from Blender's factory settings (``wm.read_factory_settings``: the state ``--factory-startup``
gives a fresh process), runs as ``__main__`` with ``sys.argv`` ending in ``-- ARGS`` as on the
command line, and writes its output (Python's and Blender's own, file descriptors 1 and 2) to
its ``stdout`` / ``stderr`` files. ``JOBS.json.results.json`` gets ``{name: {"exit_code",
"traceback"}}``: 0 when the script returned, 1 when it raised (``--python-exit-code 1``), a
``sys.exit`` code as given. One Blender start instead of one per script.
"""

from __future__ import annotations

import json
import os
import runpy
import sys
import traceback

import bpy


def run(job: dict) -> dict:
    bpy.ops.wm.read_factory_settings(use_empty=False)
    sys.stdout.flush()
    sys.stderr.flush()
    saved = os.dup(1), os.dup(2)
    code, tb = 0, ""
    with open(job["stdout"], "w") as out, open(job["stderr"], "w") as err:
        os.dup2(out.fileno(), 1)
        os.dup2(err.fileno(), 2)
        sys.argv = ["blender", job["script"], *(["--", *job["args"]] if job["args"] else [])]
        try:
            runpy.run_path(job["script"], run_name="__main__")
        except SystemExit as exc:
            code = exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 1)
        except Exception:  # noqa: BLE001 - reported per script, as --python-exit-code 1 does
            code, tb = 1, traceback.format_exc()
            sys.stderr.write(tb)
        finally:
            sys.stdout.flush()
            sys.stderr.flush()
            os.dup2(saved[0], 1)
            os.dup2(saved[1], 2)
            os.close(saved[0])
            os.close(saved[1])
    return {"exit_code": code, "traceback": tb}


def main() -> None:
    path = sys.argv[sys.argv.index("--") + 1]
    with open(path, encoding="utf-8") as f:
        jobs = json.load(f)
    results = {job["name"]: run(job) for job in jobs}
    with open(path + ".results.json", "w", encoding="utf-8") as f:
        json.dump(results, f)


main()
