"""The reports CI systems read: a JSON summary, JUnit XML and SARIF 2.1.0.

* **JSON** (``schemas/batch-summary.schema.json``): every asset's result, counts, the cache.
* **JUnit XML** (as Jenkins, GitLab and GitHub test reporters read it; checked against the Jenkins
  xunit plugin's ``junit-10.xsd``): one ``<testcase>`` per asset, named by its output folder; an
  asset whose validation found issues at or above ``fail_on`` has a ``<failure>`` whose ``type``
  is the first rule code and whose text lists every issue (severity, code, where, message, fix);
  one that could not run has an ``<error>`` with every problem (file, key, message).
* **SARIF 2.1.0** (GitHub code scanning, GitLab, VS Code's SARIF viewer): one result per
  validation issue, with the rule from the catalogue (code, title, description, fix, default
  level), located at the asset's manifest (relative to the batch root, ``%SRCROOT%``) with the
  output file as a related location (``OUTPUT``); assets that could not run are tool execution
  notifications.
"""

from __future__ import annotations

import re
import socket
import time
import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Any
from urllib.parse import quote

from wrinklepipe import __version__
from wrinklepipe.batch.results import AssetResult, worst_exit_code
from wrinklepipe.validate.catalogue import RULES

SUMMARY_SCHEMA = "wrinklepipe/batch-summary@1"
SARIF_SCHEMA_URI = "https://json.schemastore.org/sarif-2.1.0.json"
_SARIF_LEVEL = {"error": "error", "warning": "warning", "info": "note"}
_INVALID_XML = re.compile("[\x00-\x08\x0b\x0c\x0e-\x1f\ufffe\uffff]")


def summary(
    results: list[AssetResult],
    *,
    command: str,
    root: Path,
    output: Path,
    engine: str,
    seconds: float,
    cache: dict[str, Any] | None = None,
) -> dict[str, Any]:
    """The JSON summary (``schemas/batch-summary.schema.json``)."""
    counts = {"assets": len(results)}
    for status in ("passed", "failed", "error"):
        counts[status] = sum(r.status == status for r in results)
    for source in ("converted", "cache", "validated"):
        counts[source] = sum(r.source == source for r in results)
    return {
        "schema": SUMMARY_SCHEMA,
        "tool": {"name": f"wrinklepipe {command}", "version": __version__},
        "root": str(root),
        "output": str(output),
        "engine": engine,
        "exit_code": worst_exit_code(results),
        "seconds": round(seconds, 3),
        "counts": counts,
        "cache": cache,
        "assets": [r.to_json() for r in results],
    }


# ------------------------------------------------------------------------------------------------
# JUnit


def _xml_text(text: str) -> str:
    return _INVALID_XML.sub("?", text)


def _seconds(s: float) -> str:
    return f"{max(s, 0.0):.3f}"


def _issue_line(i: dict[str, Any]) -> str:
    fix = f"\n    fix: {i['fix']}" if i.get("fix") else ""
    return (
        f"{i.get('severity')} {i.get('code')} {i.get('pointer', '')}: {i.get('message', '')}{fix}"
    )


def _problem_line(p: dict[str, str]) -> str:
    key = f" [{p['key']}]" if p.get("key") else ""
    return f"{p.get('file', '')}{key}: {p.get('message', '')}"


def _testcase(r: AssetResult, classname: str) -> ET.Element:
    case = ET.Element("testcase", classname=classname, name=r.id, time=_seconds(r.seconds))
    if r.status == "error":
        first = r.problems[0] if r.problems else {"message": "could not run"}
        el = ET.SubElement(
            case, "error", type="could-not-run", message=_xml_text(_problem_line(first))
        )
        el.text = _xml_text("\n".join(_problem_line(p) for p in r.problems))
    elif r.status == "failed":
        bad = r.failing_issues()
        codes = sorted({i["code"] for i in bad})
        n = len(bad)
        el = ET.SubElement(
            case,
            "failure",
            type=codes[0] if codes else "validation",
            message=_xml_text(
                f"{n} validation issue{'s' if n != 1 else ''} at or above {r.fail_on}: "
                + ", ".join(codes)
            ),
        )
        el.text = _xml_text("\n".join(_issue_line(i) for i in bad))
    how = {
        "converted": "converted",
        "cache": f"restored from the cache (key {r.key[:16]})",
        "validated": "validated",
        "none": "not written",
    }[r.source]
    lines = [f"manifest: {r.manifest}" if r.manifest else f"output: {r.output}", how]
    if r.stages:
        lines.append("stages: " + ", ".join(f"{k} {v:.2f} s" for k, v in r.stages.items()))
    others = [i for i in r.issues if i not in r.failing_issues()]
    lines += [_issue_line(i) for i in others]
    out = ET.SubElement(case, "system-out")
    out.text = _xml_text("\n".join(lines))
    return case


def junit_xml(results: list[AssetResult], *, suite: str, seconds: float) -> bytes:
    """JUnit XML: ``<testsuites>`` with one ``<testsuite>`` of one ``<testcase>`` per asset."""
    tests = str(len(results))
    failures = str(sum(r.status == "failed" for r in results))
    errors = str(sum(r.status == "error" for r in results))
    root = ET.Element(
        "testsuites",
        name=suite,
        tests=tests,
        failures=failures,
        errors=errors,
        time=_seconds(seconds),
    )
    ts = ET.SubElement(
        root,
        "testsuite",
        name=suite,
        tests=tests,
        failures=failures,
        errors=errors,
        skipped="0",
        time=_seconds(seconds),
        timestamp=time.strftime("%Y-%m-%dT%H:%M:%S", time.gmtime()),
        hostname=socket.gethostname(),
    )
    props = ET.SubElement(ts, "properties")
    ET.SubElement(props, "property", name="wrinklepipe.version", value=__version__)
    classname = suite.replace(" ", ".")
    for r in results:
        ts.append(_testcase(r, classname))
    ET.indent(root)
    return ET.tostring(root, encoding="utf-8", xml_declaration=True) + b"\n"


# ------------------------------------------------------------------------------------------------
# SARIF


def _pointer_file(pointer: str) -> str:
    """``./demo_head.gltf#/materials/0`` -> ``demo_head.gltf``; ``<source>/m.toml [x]`` -> ''."""
    head = re.split(r"[#<\[ ]", pointer, maxsplit=1)[0]
    if head.startswith("./"):
        return head[2:]
    return "" if head.startswith("<") or Path(head).is_absolute() else head


def _location(uri: str, base: str, message: str = "") -> dict[str, Any]:
    loc: dict[str, Any] = {
        "physicalLocation": {"artifactLocation": {"uri": quote(uri, safe="/"), "uriBaseId": base}}
    }
    if message:
        loc["message"] = {"text": message}
    return loc


def sarif_log(results: list[AssetResult], *, root: Path, output: Path, command: str) -> dict:
    """A SARIF 2.1.0 log of every validation issue of every asset."""
    rules = [
        {
            "id": r.code,
            "name": re.sub(r"[^A-Za-z0-9]+", " ", r.title).title().replace(" ", ""),
            "shortDescription": {"text": r.title},
            "fullDescription": {"text": r.description},
            "help": {"text": r.fix or r.description},
            "defaultConfiguration": {"level": _SARIF_LEVEL[r.severity]},
        }
        for r in RULES
    ]
    index = {r["id"]: i for i, r in enumerate(rules)}
    out_results = []
    notifications = []
    for a in results:
        src = a.manifest or ""
        for issue in a.issues:
            code = str(issue.get("code", ""))
            pointer = str(issue.get("pointer", ""))
            text = str(issue.get("message", ""))
            if pointer:
                text += f" (at {pointer} in {a.output})"
            res: dict[str, Any] = {
                "ruleId": code,
                "level": _SARIF_LEVEL.get(str(issue.get("severity")), "note"),
                "message": {"text": text},
                "properties": {"asset": a.id, "pointer": pointer},
            }
            if code in index:
                res["ruleIndex"] = index[code]
            if issue.get("fix"):
                res["properties"]["fix"] = str(issue["fix"])
            target = _pointer_file(pointer)
            out_uri = f"{a.output}/{target}" if target else f"{a.output}/"
            if src:
                res["locations"] = [_location(src, "SRCROOT")]
                res["relatedLocations"] = [
                    {**_location(out_uri, "OUTPUT", "the output the issue was found in"), "id": 1}
                ]
            else:
                res["locations"] = [_location(out_uri, "OUTPUT")]
            out_results.append(res)
        if a.status == "error":
            for p in a.problems:
                notifications.append(
                    {
                        "level": "error",
                        "message": {"text": f"{a.id}: {_problem_line(p)}"},
                        "locations": [
                            _location(src or f"{a.output}/", "SRCROOT" if src else "OUTPUT")
                        ],
                    }
                )
    return {
        "$schema": SARIF_SCHEMA_URI,
        "version": "2.1.0",
        "runs": [
            {
                "tool": {
                    "driver": {
                        "name": "wrinklepipe",
                        "version": __version__,
                        "semanticVersion": __version__,
                        "rules": rules,
                    }
                },
                "originalUriBaseIds": {
                    "SRCROOT": {"uri": root.as_uri() + "/"},
                    "OUTPUT": {"uri": output.as_uri() + "/"},
                },
                "invocations": [
                    {
                        "executionSuccessful": not notifications,
                        "commandLine": f"wrinklepipe {command}",
                        "toolExecutionNotifications": notifications,
                    }
                ],
                "results": out_results,
                "columnKind": "unicodeCodePoints",
            }
        ],
    }
