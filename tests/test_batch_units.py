"""``wrinklepipe batch`` parts without a conversion: the plan (sources, batch files, output
collisions), the cache protocol, the local engine's crash isolation, the reports' schemas."""

from __future__ import annotations

import json
import os
import signal
import time
import xml.etree.ElementTree as ET
from pathlib import Path

import jsonschema
import pytest
import xmlschema

from wrinklepipe.batch import AssetResult, Cache, LocalEngine, plan_batch
from wrinklepipe.batch.cache import CacheMiss, parse_size
from wrinklepipe.batch.plan import Job, default_output
from wrinklepipe.batch.reports import junit_xml, sarif_log
from wrinklepipe.batch.results import AssetResult as Result
from wrinklepipe.batch.results import worst_exit_code
from wrinklepipe.cli import main
from wrinklepipe.errors import InputError
from wrinklepipe.normals import compress

SCHEMAS = Path(__file__).parent / "schemas"
MANIFEST = 'schema = "wrinklepipe/manifest@1"\nname = "x"\n'


def _tree(root: Path, files: dict[str, str]) -> Path:
    for rel, text in files.items():
        p = root / rel
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_text(text, encoding="utf-8")
    return root


# ------------------------------------------------------------------------------------------------
# plan


def test_output_folder_is_the_manifest_path_relative_to_the_root():
    from pathlib import PurePosixPath as P

    assert default_output(P("chars/ada/manifest.toml")) == P("chars/ada/manifest")
    assert default_output(P("chars/ada/lod1.toml")) == P("chars/ada/lod1")
    assert default_output(P("manifest.toml")) == P("manifest")


def test_folder_source_finds_declared_manifests_only(tmp_path):
    root = _tree(
        tmp_path / "repo",
        {
            "chars/ada/manifest.toml": MANIFEST,
            "chars/bo/manifest.toml": MANIFEST,
            "chars/bo/notes.toml": 'title = "not a manifest"\n',
            ".hidden/manifest.toml": MANIFEST,
            "build/old/manifest.toml": MANIFEST,  # inside the output folder: skipped
        },
    )
    plan = plan_batch([str(root)], root / "build")
    assert [j.id for j in plan.jobs] == ["chars/ada/manifest", "chars/bo/manifest"]
    assert plan.jobs[0].output == root / "build" / "chars" / "ada" / "manifest"
    assert plan.jobs[0].manifest_rel == "chars/ada/manifest.toml"


def test_glob_sources_are_relative_to_the_working_folder(tmp_path, monkeypatch):
    _tree(tmp_path, {"a/x/manifest.toml": MANIFEST, "a/y/other.toml": MANIFEST})
    monkeypatch.chdir(tmp_path)
    plan = plan_batch(["a/**/*.toml"], "out")
    assert [j.id for j in plan.jobs] == ["a/x/manifest", "a/y/other"]
    with pytest.raises(InputError, match="no manifests match"):
        plan_batch(["nothing/**/*.toml"], "out")


def test_outputs_that_meet_are_refused_before_anything_runs(tmp_path):
    root = _tree(
        tmp_path,
        {
            "chars/ada.toml": MANIFEST,  # -> chars/ada, which holds chars/ada/manifest
            "chars/ada/manifest.toml": MANIFEST,
            "chars/bo/manifest.toml": MANIFEST,
            "chars/cy/manifest.toml": MANIFEST,
            "batch.toml": 'schema = "wrinklepipe/batch@1"\noutput = "out"\n'
            '[[assets]]\nmanifest = "chars/cy/manifest.toml"\noutput = "chars/bo/manifest"\n',
        },
    )
    with pytest.raises(InputError) as exc:
        plan_batch([str(root / "batch.toml")])
    text = str(exc.value)
    assert "'chars/ada/manifest' lies inside 'chars/ada', the output of chars/ada.toml" in text
    assert "'chars/bo/manifest' is also the output of chars/bo/manifest.toml" in text
    assert not (root / "out").exists()


def test_existing_outputs_need_force_and_outputs_may_not_hold_inputs(tmp_path):
    root = _tree(tmp_path / "repo", {"chars/ada/manifest.toml": MANIFEST})
    _tree(tmp_path / "out", {"chars/ada/manifest/keep.txt": "mine"})
    with pytest.raises(InputError, match="exists and is not empty"):
        plan_batch([str(root)], tmp_path / "out")
    assert plan_batch([str(root)], tmp_path / "out", force=True).jobs[0].force
    # an output over the sources: chars/ada's output would hold chars/ada itself
    (root / "batch.toml").write_text(
        'schema = "wrinklepipe/batch@1"\noutput = ".."\n'
        '[[assets]]\nmanifest = "chars/ada/manifest.toml"\noutput = "repo"\n'
    )
    with pytest.raises(InputError, match="would hold the input folder"):
        plan_batch([str(root / "batch.toml")], force=True)


def test_manifest_outside_the_root_is_refused(tmp_path):
    _tree(tmp_path, {"a/manifest.toml": MANIFEST, "b/manifest.toml": MANIFEST})
    with pytest.raises(InputError, match="outside the batch root"):
        plan_batch([str(tmp_path / "a/manifest.toml")], tmp_path / "out", root=tmp_path / "b")


def test_batch_file_options_layer_defaults_assets_and_command_line(tmp_path):
    root = _tree(
        tmp_path,
        {
            "c/a/manifest.toml": MANIFEST,
            "c/b/manifest.toml": MANIFEST,
            "npc/n/manifest.toml": MANIFEST,
            "wip/w/manifest.toml": MANIFEST,
            "batch.toml": 'schema = "wrinklepipe/batch@1"\noutput = "out"\n'
            'exclude = ["wip/**"]\n'
            "[defaults]\nbits = 16\npng_level = 3\n"
            '[[assets]]\nmanifest = "c/a/manifest.toml"\nglb = true\nbits = 8\n'
            '[[assets]]\nmanifest = "npc/*/manifest.toml"\nfail_on = "warning"\n',
        },
    )
    plan = plan_batch([str(root / "batch.toml")], cli_options={"png_level": 9})
    opts = {j.id: j.options for j in plan.jobs}
    a, b, n = "c/a/manifest", "c/b/manifest", "npc/n/manifest"
    assert list(opts) == [a, b, n]
    assert (opts[a].glb, opts[a].bits, opts[b].bits) == (True, 8, 16)
    assert opts[n].fail_on == "warning" and opts[b].fail_on == "error"
    assert {o.png_level for o in opts.values()} == {9}  # the command line wins
    assert plan.output == root / "out"


def test_batch_file_problems_are_all_reported_with_their_keys(tmp_path):
    bad = tmp_path / "batch.toml"
    bad.write_text(
        'schema = "wrinklepipe/batch@1"\ncolour = 1\n[defaults]\nbits = 12\nfoo = 1\n'
        '[[assets]]\noutput = "x"\n',
        encoding="utf-8",
    )
    with pytest.raises(InputError) as exc:
        plan_batch([str(bad)], tmp_path / "out")
    got = {(p.key, p.message.split(":")[0]) for p in exc.value.problems}
    assert ("colour", "unknown key") in got
    assert ("defaults.foo", "unknown key") in got
    assert ("assets[0].manifest", "missing required key") in got
    assert any(k == "defaults.bits" and "8 or 16" in str(exc.value) for k, _ in got)
    assert all(p.file == str(bad) for p in exc.value.problems)


def test_cli_plan_error_exits_2_and_writes_nothing(tmp_path, capsys):
    root = _tree(tmp_path, {"a/manifest.toml": MANIFEST, "a.toml": MANIFEST})
    assert main(["batch", str(root), "-o", str(tmp_path / "out")]) == 2
    assert "lies inside" in capsys.readouterr().err
    assert not (tmp_path / "out").exists()


# ------------------------------------------------------------------------------------------------
# cache


def _folder(root: Path, files: dict[str, bytes]) -> Path:
    for rel, data in files.items():
        (root / rel).parent.mkdir(parents=True, exist_ok=True)
        (root / rel).write_bytes(data)
    return root


def test_cache_put_restore_and_an_altered_entry(tmp_path):
    cache = Cache(tmp_path / "c")
    src = _folder(tmp_path / "out1", {"a.gltf": b"{}", "textures/t.png": b"\x89PNG..."})
    key = "ab" + "0" * 62
    entry = cache.put(key, src, {"issues": []})
    assert entry is not None and cache.lookup(key).meta["bytes"] == 2 + 7
    cache.restore(entry, tmp_path / "restored", force=False, inputs=[])
    assert (tmp_path / "restored/textures/t.png").read_bytes() == b"\x89PNG..."
    # a second put of the same key (another batch got there first) keeps the first entry
    other = _folder(tmp_path / "out2", {"a.gltf": b"other"})
    assert cache.put(key, other, {}).meta["files"][0]["bytes"] == 2
    assert list((tmp_path / "c" / "tmp").iterdir()) == []
    # altered bytes in the entry: a miss, and the output folder is left as it was
    (entry.folder / "files" / "a.gltf").write_bytes(b"{!")
    with pytest.raises(CacheMiss, match="altered"):
        cache.restore(entry, tmp_path / "restored", force=True, inputs=[])
    assert (tmp_path / "restored/a.gltf").read_bytes() == b"{}"
    # an entry evicted while being read: a miss too
    import shutil

    shutil.rmtree(entry.folder / "files")
    with pytest.raises(CacheMiss, match="went away"):
        cache.restore(entry, tmp_path / "restored2", force=False, inputs=[])
    assert not (tmp_path / "restored2").exists()


def test_cache_evicts_least_recently_used_first(tmp_path):
    cache = Cache(tmp_path / "c", max_bytes=250)
    keys = [f"{i:02x}" + "1" * 62 for i in range(4)]
    for i, key in enumerate(keys):
        cache.put(key, _folder(tmp_path / f"o{i}", {"f": bytes(100)}), {})
        t = time.time() - 1000 + 10 * i
        os.utime(cache.lookup(key).folder / "entry.json", (t, t))
    # a hit on the oldest makes it the most recent
    cache.restore(cache.lookup(keys[0]), tmp_path / "r", force=False, inputs=[])
    removed = cache.evict()
    assert removed == [keys[1], keys[2]]
    assert cache.lookup(keys[0]) is not None and cache.lookup(keys[3]) is not None
    assert cache.size() == 200


def test_parse_size():
    assert parse_size("500M") == 500 << 20 and parse_size("1.5G") == 3 << 29
    assert parse_size("20GiB") == 20 << 30 and parse_size("123") == 123
    with pytest.raises(InputError):
        parse_size("lots")


def test_the_longest_assets_start_first_by_the_caches_record(tmp_path, monkeypatch):
    from wrinklepipe.batch import AssetOptions, run
    from wrinklepipe.batch.plan import BatchPlan

    seconds = {"a": 2.0, "b": 9.0, "c": 0.5, "d": 4.0}
    salt = ["1"]  # a new salt: every input "changed", every asset converts again
    monkeypatch.setattr(
        run, "asset_key", lambda m, o, out: (format(abs(hash((out.name, salt[0]))), "064x"), 0)
    )

    class Timed:  # an engine that "converts" in the order it is given
        def __init__(self):
            self.order = []

        def run(self, jobs, on_stage):
            for job in jobs:
                self.order.append(job.id)
                job.output.mkdir(parents=True, exist_ok=True)
                (job.output / "f.txt").write_text(job.id)
                yield Result(
                    job.id, job.manifest_rel, job.id, "passed", "converted", seconds=seconds[job.id]
                )

    jobs = [
        Job(n, tmp_path / "m.toml", "m.toml", tmp_path / "out" / n, AssetOptions(), force=True)
        for n in "abcd"
    ]
    cache = Cache(tmp_path / "cache")
    plan = BatchPlan(tmp_path, tmp_path / "out", jobs)
    first = Timed()
    run.run_plan(plan, first, cache)
    assert first.order == list("abcd")  # nothing known: plan order
    assert [cache.last_seconds(n) for n in "abcd"] == [2.0, 9.0, 0.5, 4.0]
    salt[0] = "2"
    seconds["e"] = 1.0  # a new asset: never timed, so it goes first
    plan.jobs = [
        *jobs,
        Job("e", tmp_path / "m.toml", "m.toml", tmp_path / "out" / "e", AssetOptions(), force=True),
    ]
    second = Timed()
    got = run.run_plan(plan, second, cache)
    assert second.order == ["e", "b", "d", "a", "c"]
    assert [r.id for r in got.results] == list("abcde")  # reported in plan order
    assert run.longest_first(plan.jobs, None) == plan.jobs  # no cache, no record
    (cache.root / "times").rename(cache.root / "gone")
    assert cache.last_seconds("b") is None


# ------------------------------------------------------------------------------------------------
# the local engine: one crash fails one asset


def _crashing_child(job, conn, threads=None):
    """Runs in a worker process: the job named 'crash' dies by SIGSEGV, 'hang' sleeps. The
    others send their result as their first message: the watchdog's clock starts at an asset's
    first message, so it never runs for them, however long the machine makes them wait."""
    if job.id in ("crash", "hang"):
        conn.send(("stage", "working"))
    if job.id == "crash":
        os.kill(os.getpid(), signal.SIGSEGV)
    if job.id == "hang":
        time.sleep(60)
    conn.send(("done", Result(job.id, job.manifest_rel, job.id, "passed", "converted")))
    conn.close()


def test_a_dying_worker_fails_only_its_asset(tmp_path):
    from wrinklepipe.batch import AssetOptions

    jobs = [
        Job(name, tmp_path / "m.toml", "m.toml", tmp_path / name, AssetOptions())
        for name in ("a", "crash", "b", "hang", "c")
    ]
    stages = []
    # 1 s: the clock starts at a job's first message; a, b and c send 'done' as their first
    engine = LocalEngine(jobs=2, timeout=1, target=_crashing_child)
    results = {r.id: r for r in engine.run(jobs, lambda j, s: stages.append((j, s)))}
    assert set(results) == {"a", "crash", "b", "hang", "c"}
    assert [results[k].status for k in "abc"] == ["passed"] * 3
    assert results["crash"].status == "error"
    assert "killed by SIGSEGV" in results["crash"].problems[0]["message"]
    assert "timeout" in results["hang"].problems[0]["message"]
    assert ("hang", "working") in stages and ("crash", "working") in stages


def test_a_worker_limits_every_thread_pool_to_its_share():
    import subprocess
    import sys

    code = (
        "from threadpoolctl import threadpool_info\n"
        "from wrinklepipe.batch.worker import limit_threads\n"
        "from wrinklepipe.normals import _chunks\n"
        "from wrinklepipe import reuse\n"
        "import OpenImageIO, os\n"
        "from pxr import Work\n"
        "limit_threads(1)\n"
        "blas = {p['num_threads'] for p in threadpool_info() if p['user_api'] == 'blas'}\n"
        "print(*blas, _chunks.threads(), reuse.thread_budget(), os.environ['LP_NUM_THREADS'],"
        " OpenImageIO.get_int_attribute('threads'), Work.GetConcurrencyLimit())\n"
    )
    env = {k: v for k, v in os.environ.items() if k != "WRINKLEPIPE_THREADS"}
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True, env=env
    )
    # every OpenBLAS loaded (numpy's, scipy's) at 1, then wrinklepipe's pools, llvmpipe, OIIO, USD
    assert out.stdout.split() == ["1", "1", "1", "1", "1", "1"]


# ------------------------------------------------------------------------------------------------
# reports


def _results() -> list[AssetResult]:
    ok = Result(
        "chars/ada", "chars/ada/manifest.toml", "chars/ada", "passed", "cache", key="f" * 64
    )
    ok.issues = [
        {"code": "WP-TEX-007", "severity": "info", "message": "5 textures", "pointer": "./ada.gltf"}
    ]
    bad = Result(
        "chars/bo", "chars/bo/manifest.toml", "chars/bo", "failed", "converted", seconds=12.5
    )
    bad.issues = [
        {
            "code": "WP-MAP-004",
            "severity": "error",
            "message": "45 texels <clipped> & \x01 odd",
            "pointer": "./bo.gltf#/materials/0",
            "fix": "raise pd_scale",
        },
        {"code": "WP-TEX-006", "severity": "warning", "message": "w", "pointer": "<source>/x.png"},
    ]
    err = Result("chars/cy", "chars/cy/manifest.toml", "chars/cy", "error", "none")
    err.problems = [
        {"file": "chars/cy/manifest.toml", "key": "base", "message": "file not found: b.png"}
    ]
    return [ok, bad, err]


def test_junit_matches_the_jenkins_schema_and_carries_codes(tmp_path):
    path = tmp_path / "junit.xml"
    path.write_bytes(junit_xml(_results(), suite="wrinklepipe batch", seconds=1234.5678))
    xmlschema.XMLSchema(SCHEMAS / "junit-10.xsd").validate(path)
    suite = ET.parse(path).getroot().find("testsuite")
    assert (suite.get("tests"), suite.get("failures"), suite.get("errors")) == ("3", "1", "1")
    assert suite.get("time") == "1234.568"
    cases = {c.get("name"): c for c in suite.iter("testcase")}
    failure = cases["chars/bo"].find("failure")
    assert failure.get("type") == "WP-MAP-004"
    assert "1 validation issue at or above error: WP-MAP-004" == failure.get("message")
    assert "error WP-MAP-004 ./bo.gltf#/materials/0: 45 texels <clipped> & ? odd" in failure.text
    assert "fix: raise pd_scale" in failure.text
    assert "WP-TEX-006" in cases["chars/bo"].find("system-out").text  # below fail_on: listed
    error = cases["chars/cy"].find("error")
    assert error.get("message") == "chars/cy/manifest.toml [base]: file not found: b.png"
    assert "restored from the cache" in cases["chars/ada"].find("system-out").text


def test_sarif_matches_the_oasis_schema(tmp_path):
    log = sarif_log(_results(), root=tmp_path / "repo", output=tmp_path / "out", command="batch")
    schema = json.loads((SCHEMAS / "sarif-schema-2.1.0.json").read_text())
    jsonschema.Draft4Validator(schema).validate(log)
    results = log["runs"][0]["results"]
    assert [r["ruleId"] for r in results] == ["WP-TEX-007", "WP-MAP-004", "WP-TEX-006"]
    assert [r["level"] for r in results] == ["note", "error", "warning"]
    loc = results[1]["locations"][0]["physicalLocation"]["artifactLocation"]
    assert loc == {"uri": "chars/bo/manifest.toml", "uriBaseId": "SRCROOT"}
    rel = results[1]["relatedLocations"][0]["physicalLocation"]["artifactLocation"]
    assert rel == {"uri": "chars/bo/bo.gltf", "uriBaseId": "OUTPUT"}
    [note] = log["runs"][0]["invocations"][0]["toolExecutionNotifications"]
    assert "file not found: b.png" in note["message"]["text"]


def test_exit_code_is_the_worst_assets():
    assert worst_exit_code(_results()) == 2
    assert worst_exit_code(_results()[:2]) == 1
    assert worst_exit_code(_results()[:1]) == 0 and worst_exit_code([]) == 0


def test_bench_limit_against_a_second_reference():
    from wrinklepipe.bench import BenchResult, BenchRow

    r = BenchResult("b", "d", baseline="one")
    r.rows = [BenchRow("one", 10.0), BenchRow("two", 5.0), BenchRow("cached", 0.4)]
    r.limits_to = {"cached": ("two", 0.05)}
    r.finish()
    assert r.ratio_to("cached", "two") == pytest.approx(0.08)
    assert r.failures() == ["b: cached is 0.08x two > 0.05x"]
    assert r.limit_text("cached") == "<= 0.05x two (is 0.08x)"
    r.rows[2].median_s = 0.2
    assert r.failures() == []


def _exit_with_kept_encoders() -> None:
    """In a process forked by the batch fork server: exit 0 when every quicktex encoder is
    already built (inherited from the server), 3 otherwise."""
    kept = all(compress._QUICKTEX_FREE.get((f, lv)) for f in ("bc1", "bc3nm") for lv in (5, 0))
    os._exit(0 if kept else 3)


def test_an_assets_process_starts_with_quicktex_encoders_built():
    """The fork server builds quicktex's encoder tables once (~0.1 s an asset otherwise) and
    every asset's process inherits them (that a kept encoder gives a new one's bytes is
    test_normals_compress's)."""
    assert set(compress.QUICKTEX_LEVELS) == {5, 0}
    proc = LocalEngine._context().Process(target=_exit_with_kept_encoders)
    proc.start()
    proc.join()
    assert proc.exitcode == 0
