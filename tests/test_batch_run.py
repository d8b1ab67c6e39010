"""``wrinklepipe batch`` end to end: 8 demo variants (sizes, encodings, policies, a second
manifest name, per-asset options), one real mesh from ../shared and one broken manifest.

One sequence, because each step builds on the last:

1. ``--jobs 1`` with a cold cache: the good ones convert and validate, the broken one fails
   alone (its message in the JSON summary and the JUnit report; JUnit checked against the
   Jenkins junit-10.xsd, SARIF against the OASIS SARIF 2.1.0 schema); exit code 2 (the worst).
2. Rerun: every asset comes from the cache; the engine is handed no job at all; the output
   folders are byte-identical.
3. One byte of one manifest changes (a comment letter): exactly that asset is reconverted; so
   is the asset whose mesh ``.bin`` (named by its ``.gltf``) gets one byte changed.
4. The same batch on a ``distributed.LocalCluster`` (2 worker processes on loopback, started and
   stopped here), no cache: every output byte-identical to step 1's ``--jobs 1`` outputs.
"""

from __future__ import annotations

import hashlib
import json
import shutil
import xml.etree.ElementTree as ET
from pathlib import Path

import jsonschema
import pytest
import xmlschema

from wrinklepipe.batch import Cache, DaskEngine, LocalEngine, plan_batch, run_plan
from wrinklepipe.batch.fingerprint import input_files
from wrinklepipe.batch.publish import publish
from wrinklepipe.cli import main
from wrinklepipe.console import err
from wrinklepipe.demo.studio import VARIANTS, write_studio
from wrinklepipe.paths import SCHEMAS_DIR

SCHEMAS = Path(__file__).parent / "schemas"
SHARED = Path(__file__).resolve().parents[2] / "shared" / "data"
MIRROR = SHARED / "gltf-samples" / "NormalTangentMirrorTest" / "glTF"
GOOD = [
    "chars/ada/manifest",
    "chars/bo/manifest",
    "chars/cy/manifest",
    "chars/di/manifest",
    "chars/ed/manifest",
    "chars/fay/manifest",
    "npc/gus/manifest",
    "npc/hal/lod1",
]
BROKEN = "chars/broken/manifest"


class Recording:
    """An engine that records which jobs it was handed, then runs them on ``inner``."""

    def __init__(self, inner):
        self.inner = inner
        self.description = inner.description
        self.handed: list[str] = []

    def run(self, jobs, on_stage):
        self.handed += [j.id for j in jobs]
        yield from self.inner.run(jobs, on_stage)


def _tree(folder: Path) -> dict[str, bytes]:
    return {
        p.relative_to(folder).as_posix(): p.read_bytes()
        for p in sorted(folder.rglob("*"))
        if p.is_file()
    }


BATCH_FILE = """\
schema = "wrinklepipe/batch@1"
output = "../out"

[defaults]
render = false          # the validator's rules run; its GPU pass runs for one asset below
png_level = 6

[[assets]]
manifest = "chars/ada/manifest.toml"
render = true

[[assets]]
manifest = "chars/cy/manifest.toml"
glb = true

[[assets]]
manifest = "npc/*/manifest.toml"
compress = false
"""


@pytest.fixture(scope="module")
def studio(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("studio") / "repo"
    write_studio(root, sizes=[32, 64])
    broken = root / "chars" / "broken" / "manifest.toml"
    broken.parent.mkdir(parents=True)
    broken.write_text(
        'schema = "wrinklepipe/manifest@1"\nname = "broken"\nbase = "base_normal.png"\n'
        'mesh = "head.glb"\n[[states]]\nname = "s"\nmap = "missing.png"\n'
        '[[regions]]\nname = "r"\nmask = "r.png"\n',
        encoding="utf-8",
    )
    (root / "studio-batch.toml").write_text(BATCH_FILE, encoding="utf-8")
    return root


def test_studio_variants_differ():
    encodings = {v[1] for v in VARIANTS}
    policies = {v[2] for v in VARIANTS}
    assert len(VARIANTS) == 8 and len(encodings) == 4 and len(policies) == 5


def test_batch_isolation_reports_cache_and_localcluster(studio, tmp_path):
    batch_file = studio / "studio-batch.toml"
    cache = Cache(tmp_path / "cache")

    # -- 1. cold, --jobs 1 ------------------------------------------------------------------
    plan = plan_batch([str(batch_file)])
    assert [j.id for j in plan.jobs] == sorted([*GOOD, BROKEN])
    opts = {j.id: j.options for j in plan.jobs}
    assert (
        opts["chars/ada/manifest"].render
        and opts["chars/cy/manifest"].glb
        and not opts["chars/bo/manifest"].render
    )
    assert not opts["npc/gus/manifest"].compress and opts["chars/ada/manifest"].compress
    engine = Recording(LocalEngine(jobs=1))
    run = run_plan(plan, engine, cache)
    assert sorted(engine.handed) == sorted(GOOD)  # the broken one fails while being hashed
    by_id = {r.id: r for r in run.results}
    for job_id in GOOD:
        r = by_id[job_id]
        assert (r.status, r.source, r.validation) == ("passed", "converted", "ran"), r
        report = json.loads((plan.output / job_id / "report.json").read_text())
        assert report["validation"]["status"] == "ran"
        assert report["validation"]["counts"]["error"] == 0
    assert (plan.output / "chars/cy/manifest" / "cy.glb").is_file()
    assert not (plan.output / "npc/gus/manifest" / "compressed").exists()
    assert (plan.output / "chars/ada/manifest" / "compressed").is_dir()
    broken = by_id[BROKEN]
    assert broken.status == "error" and broken.exit_code == 2
    assert any("missing.png" in p["message"] for p in broken.problems)
    assert not (plan.output / BROKEN).exists()
    assert run.exit_code == 2
    first = {j: _tree(plan.output / j) for j in GOOD}

    reports = tmp_path / "reports"
    doc = publish(
        run,
        plan,
        command="batch",
        engine=engine.description,
        console=err,
        summary_path=str(reports / "summary.json"),
        junit_path=str(reports / "junit.xml"),
        sarif_path=str(reports / "wrinkles.sarif"),
    )
    summary = json.loads((reports / "summary.json").read_text())
    assert summary == json.loads(json.dumps(doc))
    jsonschema.validate(
        summary, json.loads((SCHEMAS_DIR / "batch-summary.schema.json").read_text())
    )
    assert summary["exit_code"] == 2 and summary["counts"]["error"] == 1
    assert summary["counts"]["passed"] == 8
    [row] = [a for a in summary["assets"] if a["id"] == BROKEN]
    assert any("missing.png" in p["message"] for p in row["problems"])

    xmlschema.XMLSchema(SCHEMAS / "junit-10.xsd").validate(reports / "junit.xml")
    suite = ET.parse(reports / "junit.xml").getroot().find("testsuite")
    assert suite.get("tests") == "9" and suite.get("errors") == "1" and suite.get("failures") == "0"
    cases = {c.get("name"): c for c in suite.iter("testcase")}
    assert set(cases) == {*GOOD, BROKEN}
    error = cases[BROKEN].find("error")
    assert error is not None and "missing.png" in error.text
    assert all(cases[g].find("error") is None and cases[g].find("failure") is None for g in GOOD)

    sarif = json.loads((reports / "wrinkles.sarif").read_text())
    jsonschema.Draft4Validator(
        json.loads((SCHEMAS / "sarif-schema-2.1.0.json").read_text())
    ).validate(sarif)
    [sarif_run] = sarif["runs"]
    notes = sarif_run["invocations"][0]["toolExecutionNotifications"]
    assert sarif_run["invocations"][0]["executionSuccessful"] is False
    assert any("missing.png" in n["message"]["text"] for n in notes)
    issues = sum(len(r.issues) for r in run.results)
    assert len(sarif_run["results"]) == issues > 0
    rule_ids = [r["id"] for r in sarif_run["tool"]["driver"]["rules"]]
    for res in sarif_run["results"]:
        assert rule_ids[res["ruleIndex"]] == res["ruleId"]

    # -- validate-asset over the folder of outputs (a copy, one asset's texture damaged) --------
    outs = tmp_path / "outs"
    shutil.copytree(plan.output, outs)
    damaged = outs / "chars/bo/manifest/textures/base_normal.png"
    damaged.write_bytes(damaged.read_bytes()[:100])  # a truncated PNG
    v = tmp_path / "v"
    code = main(
        ["validate-asset", str(outs), "--no-render", "--jobs", "2", "--report", str(v / "s.json")]
        + ["--junit", str(v / "j.xml"), "--sarif", str(v / "v.sarif")]
    )
    assert code == 2  # the worst asset's: the damaged one could not be read
    vs = {a["id"]: a for a in json.loads((v / "s.json").read_text())["assets"]}
    assert set(vs) == set(GOOD)
    assert vs["chars/bo/manifest"]["status"] == "error"
    [problem] = vs["chars/bo/manifest"]["problems"]
    assert problem["file"].startswith("chars/bo/manifest/bo.gltf")  # relative to the folder
    assert "cannot decode image" in problem["message"]
    assert {vs[g]["status"] for g in GOOD if g != "chars/bo/manifest"} == {"passed"}
    assert {vs[g]["source"] for g in GOOD if g != "chars/bo/manifest"} == {"validated"}
    xmlschema.XMLSchema(SCHEMAS / "junit-10.xsd").validate(v / "j.xml")
    jsonschema.Draft4Validator(
        json.loads((SCHEMAS / "sarif-schema-2.1.0.json").read_text())
    ).validate(json.loads((v / "v.sarif").read_text()))

    # -- 2. rerun: everything from the cache, nothing converted ------------------------------
    plan2 = plan_batch([str(batch_file)], force=True)
    engine2 = Recording(LocalEngine(jobs=2))
    run2 = run_plan(plan2, engine2, cache)
    assert engine2.handed == []
    assert {r.id: r.source for r in run2.results if r.id in GOOD} == dict.fromkeys(GOOD, "cache")
    assert run2.cache.hits == 8 and run2.cache.misses == 0
    for j in GOOD:
        assert _tree(plan.output / j) == first[j], j
    assert [r.status for r in run2.results] == [r.status for r in run.results]

    # -- 3. one byte of one manifest -> exactly that asset ------------------------------------
    manifest = studio / "chars" / "di" / "manifest.toml"
    text = manifest.read_bytes()
    assert text.startswith(b"# wrinklepipe")
    manifest.write_bytes(b"# Wrinklepipe" + text[len(b"# wrinklepipe") :])
    try:
        engine3 = Recording(LocalEngine(jobs=2))
        run3 = run_plan(plan_batch([str(batch_file)], force=True), engine3, cache)
        assert engine3.handed == ["chars/di/manifest"]
        assert {r.id: r.source for r in run3.results}["chars/di/manifest"] == "converted"
        # the comment changes no texel: only the reports (which hash the inputs) differ
        again = _tree(plan.output / "chars/di/manifest")
        changed = {f for f in again if again[f] != first["chars/di/manifest"].get(f)}
        assert changed == {"report.json", "report.html"}
        rows = json.loads(again["report.json"])["inputs"]
        [row] = [r for r in rows if r["file"] == "manifest.toml"]
        assert row["sha256"] == hashlib.sha256(manifest.read_bytes()).hexdigest()
    finally:
        manifest.write_bytes(text)

    # -- 4. the same batch on a Dask LocalCluster: byte-identical to --jobs 1 -----------------
    import dask
    from distributed import LocalCluster

    out4 = tmp_path / "dask-out"
    plan4 = plan_batch([str(batch_file)], out4)
    # the worker processes fork from the multiprocessing fork server that step 1's LocalEngine
    # started (wrinklepipe imported once), instead of each spawning an interpreter that imports
    # distributed and wrinklepipe again (~2.5 s CPU each)
    forkserver = {"distributed.worker.multiprocessing-method": "forkserver"}
    with (
        dask.config.set(forkserver),
        LocalCluster(
            n_workers=2,
            threads_per_worker=1,
            processes=True,
            host="127.0.0.1",
            dashboard_address=None,
        ) as cluster,
    ):
        run4 = run_plan(plan4, DaskEngine(cluster.scheduler_address), None)
    by_id4 = {r.id: r for r in run4.results}
    assert by_id4[BROKEN].status == "error"
    assert any("missing.png" in p["message"] for p in by_id4[BROKEN].problems)
    for j in GOOD:
        assert by_id4[j].status == "passed" and by_id4[j].source == "converted"
        assert _tree(out4 / j) == first[j], f"{j}: LocalCluster output differs from --jobs 1"


@pytest.mark.skipif(not MIRROR.is_dir(), reason="../shared/data is absent")
def test_real_gltf_mesh_with_external_buffer_is_keyed_and_reconverted(studio, tmp_path):
    """A character on Khronos's NormalTangentMirrorTest mesh (a .gltf with an external .bin and
    images): the key covers the .bin, so changing one byte of it reconverts the asset."""
    src = tmp_path / "real" / "mirror"
    shutil.copytree(studio / "chars" / "ada", src)
    mesh = src / "mesh"
    shutil.copytree(MIRROR, mesh)
    for p in mesh.iterdir():
        p.chmod(0o644)
    m = src / "manifest.toml"
    m.write_text(
        m.read_text().replace('mesh = "head.glb"', 'mesh = "mesh/NormalTangentMirrorTest.gltf"'),
        encoding="utf-8",
    )
    files = {p.relative_to(src).as_posix() for p in input_files(m)}
    assert {"mesh/NormalTangentMirrorTest.gltf", "mesh/NormalTangentMirrorTest.bin"} <= files
    assert "mesh/NormalTangentTest_Normal.png" in files  # images the .gltf names
    out = tmp_path / "out"
    cache = tmp_path / "cache"
    args = [str(tmp_path / "real"), "-o", str(out), "--cache", str(cache), "--jobs", "1"]
    args += ["--no-render", "--report", str(tmp_path / "s.json")]

    def row() -> dict:
        [asset] = json.loads((tmp_path / "s.json").read_text())["assets"]
        return asset

    # The demo's masks were painted for the demo head's UVs: on this mesh's layout the left
    # regions land on the right, and validation says so (the asset fails, exit 1).
    assert main(["batch", *args]) == 1
    first = row()
    assert (first["id"], first["source"], first["status"]) == (
        "mirror/manifest",
        "converted",
        "failed",
    )
    assert "WP-MASK-005" in {i["code"] for i in first["issues"] if i["severity"] == "error"}
    assert main(["batch", *args, "--force"]) == 1  # the failed output is cached like any other
    assert (row()["source"], row()["issues"]) == ("cache", first["issues"])
    data = bytearray((mesh / "NormalTangentMirrorTest.bin").read_bytes())
    data[-1] ^= 1  # the lowest bit of the last byte of the buffer
    (mesh / "NormalTangentMirrorTest.bin").write_bytes(bytes(data))
    assert main(["batch", *args, "--force"]) == 1
    assert row()["source"] == "converted"
