"""What ``convert`` (and ``demo``) tell the terminal about a conversion: what was written, the
choices and their fidelity, the warnings and validation issues, and the exit code for
``--fail-on``. Shared by the two commands; not a command itself."""

from __future__ import annotations

from typing import Any

from wrinklepipe.commands._options import SEVERITIES, fails
from wrinklepipe.console import issue_counts, plural
from wrinklepipe.metrics import Budget, Stats


def exit_code(report: dict[str, Any], fail_on: str) -> int:
    """1 when validation found an issue at or above ``fail_on`` (the folder is written), else 0."""
    v = report.get("validation", {})
    return 1 if v.get("status") == "ran" and fails(v.get("counts", {}), fail_on) else 0


def is_problem(line: str) -> bool:
    """A summary line that stays with --quiet: a warning, an error, why the exit code is 1."""
    return line.startswith(("warning", "error", "exit 1"))


def _fmt(f: str) -> str:
    return "none (PNG only)" if f == "png" else f


def _formats_tried(tried: list[dict[str, Any]]) -> list[str]:
    """One line per group: each block format tried, its worst pose inside the active regions
    (p99 / mean degrees) and whether it met the budget."""
    out = []
    for step, label in (("state format", "states"), ("base format", "base")):
        rows = [t for t in tried if t["step"] == step]
        if rows:
            out.append(
                f"formats tried for the {label} (worst pose p99 / mean deg): "
                + ", ".join(
                    f"{t['value']} {t['worst_p99_deg']:.2f} / {t['worst_mean_deg']:.2f}"
                    + ("" if t["ok"] else " over")
                    for t in rows
                )
            )
    return out


def fidelity_table(fid: dict[str, Any], which: str) -> list[str]:
    """The per-pose fidelity table of report.json's ``fidelity`` record (worst first)."""
    part = fid.get(which)
    if not part:
        return []
    budget = fid.get("budget" if which == "png" else "compressed_budget", {})
    limit = ", ".join(f"{k[4:-4]} {v:g}" for k, v in sorted(budget.items()))
    rows = sorted(part["poses"], key=lambda p: -p["p99_deg"])
    width = max([16, *(len(r["pose"]) + 2 for r in rows)])
    out = [f"fidelity ({which}, degrees inside each pose's active region; budget {limit}):"]
    out.append(f"  {'pose':<{width}}{'mean':>7}{'p99':>7}{'max':>8}")
    verdict = Budget.from_dict(budget)
    for r in rows:
        st = Stats(r["mean_deg"], r["p99_deg"], r["max_deg"], r.get("texels", 0), 0.0)
        over = not verdict.ok(st)
        out.append(
            f"  {r['pose']:<{width}}{r['mean_deg']:7.2f}{r['p99_deg']:7.2f}{r['max_deg']:8.2f}"
            + ("  over budget" if over else "")
        )
    b = part.get("base")
    if b:
        out.append(
            f"  {'base (face)':<{width}}{b['mean_deg']:7.2f}{b['p99_deg']:7.2f}{b['max_deg']:8.2f}"
        )
    return out


def color_table(color: dict[str, Any] | None, copies: dict[str, Any] | None = None) -> list[str]:
    """The colour states' size and the per-pose colour fidelity table (CIEDE2000, worst
    first) of report.json's ``color`` record, then the colour copies' block format and their
    worst pose (``copies``: report.json's ``compression.color``); nothing without colour
    states."""
    if not color:
        return []
    return _color_rows(color) + _color_copies(copies)


def _color_copies(copies: dict[str, Any] | None) -> list[str]:
    if not copies:
        return []
    fid = copies.get("fidelity")
    worst = ""
    if fid and fid.get("poses"):
        p = max(fid["poses"], key=lambda p: p["p99_delta_e"])
        worst = f": worst pose {p['pose']} mean {p['mean_delta_e']:.2f}, p99 {p['p99_delta_e']:.2f}"
    return [
        f"colour copies: states {_fmt(copies.get('chosen', 'png'))}, base colour "
        f"{_fmt(copies.get('base', 'png'))}{worst} CIEDE2000"
    ]


def _color_rows(color: dict[str, Any]) -> list[str]:
    b = color["budget"]
    verdict = Budget(b["max_mean_delta_e"], b["max_p99_delta_e"])
    h, w = color["size"]
    rows = sorted(color["fidelity"]["poses"], key=lambda p: -p["p99_delta_e"])
    width = max([16, *(len(r["pose"]) + 2 for r in rows)])
    out = [
        f"colour states {w}x{h} ({color['how']}); colour fidelity (CIEDE2000 inside each pose's "
        f"active region; budget mean {b['max_mean_delta_e']:g}, p99 {b['max_p99_delta_e']:g}):",
        f"  {'pose':<{width}}{'mean':>7}{'p99':>7}{'max':>8}",
    ]
    for r in rows:
        st = Stats(r["mean_delta_e"], r["p99_delta_e"], r["max_delta_e"], r["texels"], 0.0)
        out.append(
            f"  {r['pose']:<{width}}{r['mean_delta_e']:7.2f}{r['p99_delta_e']:7.2f}"
            f"{r['max_delta_e']:8.2f}" + ("" if verdict.ok(st) else "  over budget")
        )
    return out


def _choice_lines(fid: dict[str, Any], prefix: str = "") -> list[str]:
    """The choices made by fidelity and their tables (``prefix``: a UDIM tile's)."""
    if "wrinkle" not in fid:  # another encoding than pd: only the formats are chosen
        out = [
            f"{prefix}chosen: compressed copies: base {_fmt(fid['base_format'])}, states "
            f"{_fmt(fid['state_format'])} (maps at the manifest's sizes)"
        ]
        out += fidelity_table(fid, "compressed")
        out += [f"note: {n}" for n in fid.get("notes", [])]
        return out + _formats_tried(fid.get("tried", []))
    out = [
        f"{prefix}chosen: states {fid['wrinkle']}^2, masks {fid['mask']}^2, pd_scale "
        f"{fid['pd_scale']:g}; compressed copies: base "
        f"{_fmt(fid['base_format'])}, states {_fmt(fid['state_format'])}"
    ]
    out += fidelity_table(fid, "png") + fidelity_table(fid, "compressed")
    return out + [f"note: {n}" for n in fid.get("notes", [])]


def summary_lines(
    rep: dict[str, Any], exit_code: int, where: str = "", fail_on: str = "error"
) -> list[str]:
    """What convert tells the terminal: what it wrote, the choices and their fidelity, every
    warning and validation error or warning, and why the exit code is 1."""
    a = rep["asset"]
    out = [
        f"wrote {where + ' ' if where else ''}({len(rep['outputs']) + 2} files): "
        f"{plural(len(a['states']), 'state')}, "
        f"{plural(len(a['regions']), 'region')}, encoding {a['encoding']} (scale {a['scale']}), "
        f"{a['vertices']} vertices"
    ]
    fid = rep.get("fidelity")
    if fid and "tiles" in fid:  # UDIM: one choice record per tile (the joint choice in each)
        for t, one in sorted(fid["tiles"].items()):
            out += _choice_lines(one, f"tile {t}: ")
    elif fid:
        out += _choice_lines(fid)
    out += color_table(rep.get("color"), rep.get("compression", {}).get("color"))
    out += [f"note: {n}" for n in rep.get("key_notes", [])]
    clipped = rep.get("pd_scale", {}).get("clipped_texels") or {}
    if any(clipped.values()):
        out.append(
            "clipped texels (stored at the end of the PD range): "
            + ", ".join(f"{k} {v}" for k, v in sorted(clipped.items()))
        )
    out += [f"warning: {w}" for w in rep.get("warnings", [])]
    v = rep.get("validation", {})
    if v.get("status") != "ran":
        out.append(f"validation: {v.get('reason', v.get('status', 'skipped'))}")
        return out
    issues = [i for i in v.get("issues", []) if i.get("severity") in ("error", "warning")]
    for i in issues:
        out.append(f"{i['severity']} {i['code']}: {i['message']}")
    counts = v.get("counts", {})
    out.append(f"validation: {issue_counts(counts)} (report.json, validation.html)")
    if exit_code == 1:
        failing = SEVERITIES[: SEVERITIES.index(fail_on) + 1]
        codes = sorted({i["code"] for i in v.get("issues", []) if i["severity"] in failing})
        found = "errors" if fail_on == "error" else f"issues at or above {fail_on}"
        out.append(
            f"exit 1: the output was written but validation found {found} ({', '.join(codes)})"
        )
    return out
